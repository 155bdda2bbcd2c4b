// Copyright 2026 The tactfunc Authors.
//
// KnnIndex::Parse: a cached k-NN index (<functaset>.<sensor>.knn; checksum made valid),
// rebuilt from its stored vectors and parameters; a parsed one answers a query.
#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <vector>

#include "estimation/knn/knn_index.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tactfunc;
  try {
    const std::unique_ptr<KnnIndex> index =
        KnnIndex::Parse(fuzz::WithValidChecksum(data, size), "fuzz.knn");
    const int k = static_cast<int>(std::min<std::int64_t>(3, index->size()));
    const std::vector<float> query(index->dim(), 0.5f);
    std::vector<float> distances(std::max(k, 1));
    std::vector<std::int64_t> labels(std::max(k, 1));
    if (k > 0) index->Search(query.data(), 1, k, distances.data(), labels.data());
  } catch (const TensorFileError& e) {
    fuzz::CheckMessage(e.what(), "fuzz.knn");
  }
  return 0;
}
