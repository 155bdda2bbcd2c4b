// Copyright 2026 The tactfunc Authors.
//
// PoseMlp::Parse and its provenance (PoseModelProvenance::FromJson): a .tpm pose model
// (checksum made valid); a parsed one predicts a pose for a zero latent.
#include <cstddef>
#include <cstdint>
#include <stdexcept>

#include "models/pose/pose_mlp.h"
#include "models/pose/pose_model_provenance.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tactfunc;
  try {
    const PoseMlp mlp = PoseMlp::Parse(fuzz::WithValidChecksum(data, size), "fuzz.tpm");
    try {
      PoseModelProvenance::FromJson(mlp.info_json(), "fuzz.tpm");
    } catch (const std::invalid_argument& e) {
      fuzz::CheckMessage(e.what(), "fuzz.tpm");
    }
    if (mlp.input_dim() <= 4096) (void)mlp.Predict(Eigen::VectorXd::Zero(mlp.input_dim()));
  } catch (const TensorFileError& e) {
    fuzz::CheckMessage(e.what(), "fuzz.tpm");
  }
  return 0;
}
