// Copyright 2026 The tactfunc Authors.
//
// KnnIndex: the brute-force index against a naive loop, FLANN against the brute force
// (as faiss checks its indexes against IndexFlat), determinism given a seed, and the
// file round trip.
//
// Recall thresholds. On 3,000 vectors of d = 32 lying near an 8-dimensional subspace in
// 30 clusters (ClusteredNearSubspace below), at 32 checks, recall@8 over data and index
// seeds 0-9 measured 0.859-0.899 (mean 0.886, sd 0.012) for a 4-tree kd-forest and
// 0.894-0.958 (mean 0.933, sd 0.018) for a k-means tree (branching 32); the thresholds,
// 0.8 and 0.85, sit about 5 standard deviations below the means and far above what a
// broken index scores. (At 256 checks both are 1.000 on this data: too easy to tell.)
#include "estimation/knn/knn_index.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "gtest/gtest.h"
#include "models/core/tensor_file.h"
#include "tests/support/test_dir.h"

namespace tactfunc {
namespace {

// Deterministic uniform numbers in [0, 1) and standard normals (Box-Muller).
class Rng {
 public:
  explicit Rng(std::uint64_t seed) : state_(seed * 0x9E3779B97F4A7C15ull + 1) {}
  double Uniform() {
    state_ = state_ * 6364136223846793005ull + 1442695040888963407ull;
    return static_cast<double>(state_ >> 11) / static_cast<double>(1ull << 53);
  }
  double Normal() {
    const double u = std::max(Uniform(), 1e-300), v = Uniform();
    return std::sqrt(-2.0 * std::log(u)) * std::cos(6.283185307179586 * v);
  }

 private:
  std::uint64_t state_;
};

std::vector<float> Gaussian(std::int64_t n, int d, std::uint64_t seed) {
  Rng rng(seed);
  std::vector<float> out(n * d);
  for (float& x : out) x = static_cast<float>(rng.Normal());
  return out;
}

// n vectors of dimension d near a `sub`-dimensional subspace, in `clusters` clusters:
// x = B (c_k + 0.3 u) + 0.05 e, with B a random d x sub basis, c_k ~ N(0, I), u, e ~ N(0, I).
std::vector<float> ClusteredNearSubspace(std::int64_t n, int d, int sub, int clusters,
                                         std::uint64_t seed) {
  Rng rng(seed);
  std::vector<double> basis(static_cast<size_t>(d) * sub), centres(static_cast<size_t>(clusters) * sub);
  for (double& b : basis) b = rng.Normal() / std::sqrt(sub);
  for (double& c : centres) c = rng.Normal();
  std::vector<float> out(n * d);
  std::vector<double> coefficients(sub);
  for (std::int64_t i = 0; i < n; ++i) {
    const int k = static_cast<int>(rng.Uniform() * clusters);
    for (int s = 0; s < sub; ++s) coefficients[s] = centres[k * sub + s] + 0.3 * rng.Normal();
    for (int c = 0; c < d; ++c) {
      double x = 0.05 * rng.Normal();
      for (int s = 0; s < sub; ++s) x += basis[c * sub + s] * coefficients[s];
      out[i * d + c] = static_cast<float>(x);
    }
  }
  return out;
}

struct Result {
  std::vector<float> distances;
  std::vector<std::int64_t> labels;
};

Result SearchAll(const KnnIndex& index, const std::vector<float>& queries, int k) {
  const std::int64_t n = static_cast<std::int64_t>(queries.size()) / index.dim();
  Result r{std::vector<float>(n * k), std::vector<std::int64_t>(n * k)};
  index.Search(queries.data(), n, k, r.distances.data(), r.labels.data());
  return r;
}

// The exact k nearest by a naive double loop, ties broken by label.
Result NaiveSearch(const std::vector<float>& data, const std::vector<float>& queries, int d, int k) {
  const std::int64_t m = static_cast<std::int64_t>(data.size()) / d;
  const std::int64_t n = static_cast<std::int64_t>(queries.size()) / d;
  Result r{std::vector<float>(n * k), std::vector<std::int64_t>(n * k)};
  std::vector<std::pair<double, std::int64_t>> all(m);
  for (std::int64_t i = 0; i < n; ++i) {
    for (std::int64_t j = 0; j < m; ++j) {
      double sum = 0;
      for (int c = 0; c < d; ++c) {
        const double diff = static_cast<double>(queries[i * d + c]) - data[j * d + c];
        sum += diff * diff;
      }
      all[j] = {sum, j};
    }
    std::sort(all.begin(), all.end());
    for (int j = 0; j < k; ++j) {
      r.distances[i * k + j] = static_cast<float>(all[j].first);
      r.labels[i * k + j] = all[j].second;
    }
  }
  return r;
}

TEST(FlannKnnIndexOptions, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(FlannKnnIndex::Options().IsValid(&error)) << error;
  EXPECT_TRUE(FlannKnnIndex::SearchParams().IsValid(&error)) << error;
}

TEST(FlannKnnIndexOptions, BadOptionsNameTheField) {
  std::string error;
  FlannKnnIndex::Options options;
  options.trees = 0;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("trees"), std::string::npos) << error;
  options = FlannKnnIndex::Options();
  options.target_precision = 1.5f;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("target_precision"), std::string::npos) << error;
  FlannKnnIndex::SearchParams params;
  params.checks = 0;
  EXPECT_FALSE(params.IsValid(&error));
  EXPECT_NE(error.find("checks"), std::string::npos) << error;
  options = FlannKnnIndex::Options();
  options.branching = 1;
  EXPECT_THROW(FlannKnnIndex(4, options), std::invalid_argument);
}

TEST(FlannKnnIndex, AlgorithmNamesRoundTrip) {
  for (auto a : {FlannKnnIndex::Algorithm::kKdForest, FlannKnnIndex::Algorithm::kKMeans,
                 FlannKnnIndex::Algorithm::kAutotuned, FlannKnnIndex::Algorithm::kLinear}) {
    FlannKnnIndex::Algorithm parsed;
    ASSERT_TRUE(FlannAlgorithmFromString(ToString(a), &parsed));
    EXPECT_EQ(parsed, a);
  }
  FlannKnnIndex::Algorithm parsed;
  EXPECT_FALSE(FlannAlgorithmFromString("hnsw", &parsed));
}

TEST(BruteForceKnnIndex, MatchesANaiveLoopExactly) {
  const int d = 12, k = 5;
  // Offset far from the origin, where ||q||^2 - 2 q.x + ||x||^2 cancels badly in float.
  std::vector<float> data = Gaussian(700, d, 1), queries = Gaussian(40, d, 2);
  for (float& x : data) x += 30.0f;
  for (float& x : queries) x += 30.0f;
  BruteForceKnnIndex index(d);
  index.Add(data.data(), 300);  // in two batches: labels continue across Add calls
  index.Add(data.data() + 300 * d, 400);
  ASSERT_EQ(index.size(), 700);
  ASSERT_EQ(index.dim(), d);
  const Result got = SearchAll(index, queries, k);
  const Result want = NaiveSearch(data, queries, d, k);
  EXPECT_EQ(got.labels, want.labels);
  for (size_t i = 0; i < got.distances.size(); ++i) {
    EXPECT_FLOAT_EQ(got.distances[i], want.distances[i]) << i;
  }
}

TEST(BruteForceKnnIndex, DistancesAreSquaredAndAscending) {
  const float data[] = {0, 0, 3, 4, 1, 0};
  BruteForceKnnIndex index(2);
  index.Add(data, 3);
  const float query[] = {0, 0};
  float distances[3];
  std::int64_t labels[3];
  index.Search(query, 1, 3, distances, labels);
  EXPECT_EQ(labels[0], 0);
  EXPECT_EQ(labels[1], 2);
  EXPECT_EQ(labels[2], 1);
  EXPECT_FLOAT_EQ(distances[0], 0.0f);
  EXPECT_FLOAT_EQ(distances[1], 1.0f);
  EXPECT_FLOAT_EQ(distances[2], 25.0f);
}

TEST(BruteForceKnnIndex, MoreNeighboursThanVectorsArePaddedWithMinusOneAndInfinity) {
  const float data[] = {1, 1, 2, 2};
  BruteForceKnnIndex index(2);
  index.Add(data, 2);
  const float query[] = {0, 0};
  float distances[4];
  std::int64_t labels[4];
  index.Search(query, 1, 4, distances, labels);
  EXPECT_EQ(labels[0], 0);
  EXPECT_EQ(labels[1], 1);
  EXPECT_EQ(labels[2], -1);
  EXPECT_EQ(labels[3], -1);
  EXPECT_TRUE(std::isinf(distances[2]) && std::isinf(distances[3]));
}

TEST(BruteForceKnnIndex, AnEmptyIndexAndANanQueryFindNothing) {
  BruteForceKnnIndex empty(3);
  const float query[] = {0, 0, 0};
  float distance;
  std::int64_t label;
  empty.Search(query, 1, 1, &distance, &label);
  EXPECT_EQ(label, -1);
  BruteForceKnnIndex index(3);
  index.Add(query, 1);
  const float nan_query[] = {0, std::numeric_limits<float>::quiet_NaN(), 0};
  index.Search(nan_query, 1, 1, &distance, &label);
  EXPECT_EQ(label, -1);
  EXPECT_TRUE(std::isinf(distance));
}

TEST(BruteForceKnnIndex, BadArgumentsThrowQuotingTheShapes) {
  BruteForceKnnIndex index(2);
  const float bad[] = {0, std::numeric_limits<float>::infinity()};
  try {
    index.Add(bad, 1);
    FAIL() << "expected a throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("row 0, column 1"), std::string::npos) << e.what();
  }
  const float good[] = {0, 0};
  index.Add(good, 1);
  float distance;
  std::int64_t label;
  EXPECT_THROW(index.Search(good, 1, 0, &distance, &label), std::invalid_argument);
  EXPECT_THROW(index.Search(good, -1, 1, &distance, &label), std::invalid_argument);
  EXPECT_THROW(index.Add(good, -1), std::invalid_argument);
  EXPECT_THROW(BruteForceKnnIndex(0), std::invalid_argument);
}

TEST(FlannKnnIndex, LinearIndexEqualsBruteForce) {
  const int d = 16, k = 6;
  const std::vector<float> data = Gaussian(1000, d, 3), queries = Gaussian(50, d, 4);
  BruteForceKnnIndex exact(d);
  exact.Add(data.data(), 1000);
  FlannKnnIndex::Options options;
  options.algorithm = FlannKnnIndex::Algorithm::kLinear;
  FlannKnnIndex linear(d, options);
  linear.Add(data.data(), 1000);
  const Result a = SearchAll(linear, queries, k), b = SearchAll(exact, queries, k);
  EXPECT_EQ(a.labels, b.labels);
  for (size_t i = 0; i < a.distances.size(); ++i) {
    EXPECT_NEAR(a.distances[i], b.distances[i], 1e-5 * b.distances[i]) << i;
  }
  EXPECT_DOUBLE_EQ(Recall(linear, exact, queries.data(), 50, k), 1.0);
}

TEST(FlannKnnIndex, KdForestRecallOnClusteredDataIsHigh) {
  const int d = 32, k = 8, n = 3000, nq = 200;
  const std::vector<float> all = ClusteredNearSubspace(n + nq, d, 8, 30, 5);
  const std::vector<float> data(all.begin(), all.begin() + n * d);
  const std::vector<float> queries(all.begin() + n * d, all.end());
  BruteForceKnnIndex exact(d);
  exact.Add(data.data(), n);
  FlannKnnIndex::Options options;  // 4 trees
  FlannKnnIndex::SearchParams params;
  params.checks = 32;
  FlannKnnIndex forest(d, options, params);
  forest.Add(data.data(), n);
  EXPECT_GT(Recall(forest, exact, queries.data(), nq, k), 0.8);
  // More checks cannot lose much: unlimited checks search every leaf (exact).
  FlannKnnIndex::SearchParams all_leaves;
  all_leaves.checks = -1;
  forest.set_search_params(all_leaves);
  EXPECT_DOUBLE_EQ(Recall(forest, exact, queries.data(), nq, k), 1.0);
}

TEST(FlannKnnIndex, KMeansRecallOnClusteredDataIsHigh) {
  const int d = 32, k = 8, n = 3000, nq = 200;
  const std::vector<float> all = ClusteredNearSubspace(n + nq, d, 8, 30, 6);
  const std::vector<float> data(all.begin(), all.begin() + n * d);
  const std::vector<float> queries(all.begin() + n * d, all.end());
  BruteForceKnnIndex exact(d);
  exact.Add(data.data(), n);
  FlannKnnIndex::Options options;
  options.algorithm = FlannKnnIndex::Algorithm::kKMeans;
  FlannKnnIndex::SearchParams params;
  params.checks = 32;
  FlannKnnIndex tree(d, options, params);
  tree.Add(data.data(), n);
  EXPECT_GT(Recall(tree, exact, queries.data(), nq, k), 0.85);
}

TEST(FlannKnnIndex, TheSameSeedBuildsTheSameIndex) {
  // Few checks, so that results depend on the trees' random structure.
  const int d = 16, k = 8, n = 2000, nq = 100;
  const std::vector<float> data = Gaussian(n, d, 7), queries = Gaussian(nq, d, 8);
  for (auto algorithm : {FlannKnnIndex::Algorithm::kKdForest, FlannKnnIndex::Algorithm::kKMeans}) {
    FlannKnnIndex::Options options;
    options.algorithm = algorithm;
    options.seed = 42;
    FlannKnnIndex::SearchParams params;
    params.checks = 16;
    FlannKnnIndex a(d, options, params), b(d, options, params);
    a.Add(data.data(), n);
    b.Add(data.data(), n);
    const Result ra = SearchAll(a, queries, k), rb = SearchAll(b, queries, k);
    EXPECT_EQ(ra.labels, rb.labels) << ToString(algorithm);
    EXPECT_EQ(ra.distances, rb.distances) << ToString(algorithm);
  }
}

TEST(KnnIndex, SaveAndLoadGiveTheSameResults) {
  const int d = 16, k = 5, n = 1500, nq = 60;
  const std::vector<float> data = ClusteredNearSubspace(n, d, 6, 12, 9);
  const std::vector<float> queries = Gaussian(nq, d, 10);
  const testing_util::TestDir test_dir;
  const std::string dir = test_dir.path();
  std::vector<std::unique_ptr<KnnIndex>> indexes;
  indexes.push_back(std::make_unique<BruteForceKnnIndex>(d));
  for (auto algorithm : {FlannKnnIndex::Algorithm::kKdForest, FlannKnnIndex::Algorithm::kKMeans}) {
    FlannKnnIndex::Options options;
    options.algorithm = algorithm;
    options.seed = 3;
    FlannKnnIndex::SearchParams params;
    params.checks = 24;
    indexes.push_back(std::make_unique<FlannKnnIndex>(d, options, params));
  }
  int i = 0;
  for (const auto& index : indexes) {
    index->Add(data.data(), n);
    const std::string path = dir + "/knn_" + std::to_string(i++) + ".tfi";
    index->Save(path);
    const std::unique_ptr<KnnIndex> loaded = KnnIndex::Load(path);
    EXPECT_EQ(loaded->TypeName(), index->TypeName());
    EXPECT_EQ(loaded->size(), n);
    EXPECT_EQ(loaded->dim(), d);
    const Result a = SearchAll(*index, queries, k), b = SearchAll(*loaded, queries, k);
    EXPECT_EQ(a.labels, b.labels) << index->Describe() << " vs " << loaded->Describe();
    EXPECT_EQ(a.distances, b.distances) << index->Describe();
  }
}

TEST(FlannKnnIndex, AnAutotunedIndexReloadsAsTheIndexItChose) {
  // Small, because tuning is slow (78 s for 30,000 x 64, docs/FITTING.md).
  const int d = 8, k = 4, n = 400, nq = 40;
  const std::vector<float> data = ClusteredNearSubspace(n, d, 4, 8, 12);
  const std::vector<float> queries = Gaussian(nq, d, 13);
  FlannKnnIndex::Options options;
  options.algorithm = FlannKnnIndex::Algorithm::kAutotuned;
  FlannKnnIndex index(d, options);
  index.Add(data.data(), n);
  const testing_util::TestDir test_dir;
  const std::string path = test_dir / "autotuned.tfi";
  index.Save(path);
  const std::unique_ptr<KnnIndex> loaded = KnnIndex::Load(path);
  const Result a = SearchAll(index, queries, k), b = SearchAll(*loaded, queries, k);
  EXPECT_EQ(a.labels, b.labels) << index.Describe() << " vs " << loaded->Describe();
  EXPECT_EQ(a.distances, b.distances);
}

TEST(KnnIndex, LoadingAForeignOrCorruptFileThrowsNamingTheFile) {
  const testing_util::TestDir test_dir;
  const std::string dir = test_dir.path();
  BruteForceKnnIndex index(2);
  const float data[] = {1, 2, 3, 4};
  index.Add(data, 2);
  const std::string path = dir + "/knn_corrupt.tfi";
  index.Save(path);
  TensorFile file = TensorFile::Read(path);
  std::string bytes = file.Serialize();
  bytes[bytes.size() / 2] ^= 0x5A;
  {
    std::FILE* f = std::fopen(path.c_str(), "wb");
    ASSERT_NE(f, nullptr);
    std::fwrite(bytes.data(), 1, bytes.size(), f);
    std::fclose(f);
  }
  try {
    KnnIndex::Load(path);
    FAIL() << "expected TensorFileError";
  } catch (const TensorFileError& e) {
    EXPECT_NE(std::string(e.what()).find(path), std::string::npos) << e.what();
  }
  TensorFile model("model");
  model.Write(path);
  EXPECT_THROW(KnnIndex::Load(path), TensorFileError);
}

TEST(KnnIndex, RecallOfAnIndexAgainstItselfIsOneAndMismatchesThrow) {
  const std::vector<float> data = Gaussian(100, 4, 11);
  BruteForceKnnIndex a(4), b(4), small(4);
  a.Add(data.data(), 100);
  b.Add(data.data(), 100);
  small.Add(data.data(), 10);
  EXPECT_DOUBLE_EQ(Recall(a, b, data.data(), 20, 3), 1.0);
  EXPECT_THROW(Recall(a, small, data.data(), 20, 3), std::invalid_argument);
}

TEST(BuildKnnIndex, BuildsTheRequestedTypeOverTheVectors) {
  KnnVectors vectors = KnnVectors::Random(40, 4);
  const std::unique_ptr<KnnIndex> exact = BuildKnnIndex(vectors, KnnIndexOptions());
  EXPECT_EQ(exact->TypeName(), "brute_force");
  EXPECT_EQ(exact->size(), 40);
  KnnIndexOptions options;
  options.type = "kd_forest";
  options.flann.trees = 2;
  options.search.checks = 7;
  const std::unique_ptr<KnnIndex> flann = BuildKnnIndex(vectors, options);
  const auto& f = dynamic_cast<const FlannKnnIndex&>(*flann);
  EXPECT_EQ(f.options().algorithm, FlannKnnIndex::Algorithm::kKdForest);
  EXPECT_EQ(f.options().trees, 2);
  EXPECT_EQ(f.search_params().checks, 7);
  options.type = "octree";
  std::string error;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("type"), std::string::npos) << error;
  EXPECT_THROW(BuildKnnIndex(vectors, options), std::invalid_argument);
}

TEST(LoadOrBuildKnnIndex, ReusesACurrentFileAndRebuildsAStaleOne) {
  const testing_util::TestDir test_dir;
  const std::string path = test_dir / "latents.knn";
  KnnVectors vectors = KnnVectors::Random(30, 3);
  KnnIndexCacheSummary summary;
  LoadOrBuildKnnIndex(path, vectors, KnnIndexOptions(), &summary);
  EXPECT_TRUE(summary.rebuilt);
  EXPECT_EQ(summary.why_rebuilt, "it does not exist");
  EXPECT_TRUE(summary.save_error.empty()) << summary.save_error;
  std::unique_ptr<KnnIndex> index = LoadOrBuildKnnIndex(path, vectors, KnnIndexOptions(), &summary);
  EXPECT_FALSE(summary.rebuilt);
  EXPECT_EQ(index->size(), 30);
  vectors(4, 1) += 1.0f;  // other vectors: the CRC differs
  LoadOrBuildKnnIndex(path, vectors, KnnIndexOptions(), &summary);
  EXPECT_TRUE(summary.rebuilt);
  EXPECT_NE(summary.why_rebuilt.find("CRC-32"), std::string::npos) << summary.why_rebuilt;
  KnnIndexOptions kd;
  kd.type = "kd_forest";
  kd.search.checks = 11;
  LoadOrBuildKnnIndex(path, vectors, kd, &summary);
  EXPECT_TRUE(summary.rebuilt);  // another type was asked for
  index = LoadOrBuildKnnIndex(path, vectors, kd, &summary);
  EXPECT_FALSE(summary.rebuilt);
  EXPECT_EQ(dynamic_cast<const FlannKnnIndex&>(*index).search_params().checks, 11);
  kd.flann.trees = 8;
  LoadOrBuildKnnIndex(path, vectors, kd, &summary);
  EXPECT_TRUE(summary.rebuilt);  // other build parameters
}

}  // namespace
}  // namespace tactfunc
