// Copyright 2026 The tactfunc Authors.
//
// TensorFile::Parse, the container under every model, functaset, pose model and k-NN
// index file. Any parsed file must serialize and parse back to the same tensors.
#include <cstddef>
#include <cstdint>

#include "models/core/tensor_file.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tactfunc;
  const std::string bytes = fuzz::WithValidChecksum(data, size);
  TensorFile file;
  try {
    file = TensorFile::Parse(bytes, "fuzz.tfm");
  } catch (const TensorFileError& e) {
    fuzz::CheckMessage(e.what(), "fuzz.tfm");
    return 0;
  }
  // What was read can be written and read again.
  const TensorFile again = TensorFile::Parse(file.Serialize(), "again.tfm");
  if (again.tensors().size() != file.tensors().size()) fuzz::Finding("round trip lost tensors");
  for (const TensorFile::Tensor& t : file.tensors()) {
    const TensorFile::Tensor& u = again.Get(t.name, t.shape);
    for (std::size_t i = 0; i < t.values.size(); ++i) {
      const bool both_nan = t.values[i] != t.values[i] && u.values[i] != u.values[i];
      if (!both_nan && t.values[i] != u.values[i]) fuzz::Finding("round trip changed " + t.name);
    }
  }
  try {
    file.CheckFormat("tactfunc-model", 1);
  } catch (const TensorFileError& e) {
    fuzz::CheckMessage(e.what(), "fuzz.tfm");
  }
  return 0;
}
