// Copyright 2026 The tactfunc Authors.
//
// Functaset::Parse: a .tfs functaset (checksum made valid); a parsed one hands out its
// latents (dequantising b-bit codes) and serializes again.
#include <cstddef>
#include <cstdint>

#include "estimation/functaset/functaset.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tactfunc;
  Functaset functaset;
  try {
    functaset = Functaset::Parse(fuzz::WithValidChecksum(data, size), "fuzz.tfs");
  } catch (const TensorFileError& e) {
    fuzz::CheckMessage(e.what(), "fuzz.tfs");
    return 0;
  }
  for (SensorKind sensor : functaset.sensors()) {
    (void)functaset.Latents(sensor);
    (void)functaset.BytesPerFrame(sensor);
  }
  const Functaset again = Functaset::Parse(functaset.Serialize(), "again.tfs");
  if (again.size() != functaset.size()) fuzz::Finding("round trip changed the entry count");
  return 0;
}
