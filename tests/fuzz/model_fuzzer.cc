// Copyright 2026 The tactfunc Authors.
//
// FunctaModel::Parse: a .tfm model file (checksum made valid, so that mutations reach
// the header and the trunks).
#include <cstddef>
#include <cstdint>

#include "models/trunk/functa_model.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tactfunc;
  try {
    const FunctaModel model = FunctaModel::Parse(fuzz::WithValidChecksum(data, size), "fuzz.tfm");
    (void)model.ParameterBytes();
    for (SensorKind sensor : model.sensors()) (void)model.Trunk(sensor).siren.NumParameters();
  } catch (const TensorFileError& e) {
    fuzz::CheckMessage(e.what(), "fuzz.tfm");
  }
  return 0;
}
