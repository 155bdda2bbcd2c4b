// Copyright 2026 The tactfunc Authors.
#include "estimation/knn/knn_index.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <limits>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "estimation/knn/internal/flann_include.h"  // FLANN, only here
#include "models/core/atomic_file.h"
#include "models/core/internal/json_numbers.h"
#include "models/core/tensor_file.h"
#include "models/core/text_limits.h"
#include "nlohmann/json.hpp"

namespace tactfunc {

// ---- FLANN's seeded "random_device" (see internal/flann_include.h) ----------------------
namespace internal {
namespace {
std::uint64_t g_flann_device_state = 0;
}  // namespace

std::uint64_t NextFlannDeviceValue() {
  // splitmix64: a well-mixed sequence from a counter, so seed s and s + 1 differ.
  std::uint64_t z = (g_flann_device_state += 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

void SeedFlann(std::uint32_t seed) {
  flann::seed_random(seed);
  g_flann_device_state = seed;
}

std::mutex& FlannBuildLock() {
  static std::mutex lock;
  return lock;
}
}  // namespace internal

namespace {

constexpr const char* kFormat = "tactfunc-knn-index";
constexpr int kVersion = 1;
constexpr float kInf = std::numeric_limits<float>::infinity();

using RowMatrixXf = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

bool RowIsFinite(const float* row, int d) {
  for (int c = 0; c < d; ++c) {
    if (!std::isfinite(row[c])) return false;
  }
  return true;
}

void PadRow(float* distances, std::int64_t* labels, int from, int k) {
  for (int j = from; j < k; ++j) {
    distances[j] = kInf;
    labels[j] = -1;
  }
}

}  // namespace

// ---- KnnIndex ----------------------------------------------------------------------------

KnnIndex::KnnIndex(int dim) : dim_(dim) {
  if (dim < 1) {
    throw std::invalid_argument("KnnIndex: dim must be >= 1, found " + std::to_string(dim));
  }
}

KnnIndex::~KnnIndex() = default;

void KnnIndex::Add(const float* vectors, std::int64_t n) {
  if (n < 0) throw std::invalid_argument("KnnIndex::Add: n must be >= 0, found " + std::to_string(n));
  if (n == 0) return;
  if (vectors == nullptr) throw std::invalid_argument("KnnIndex::Add: vectors is null with n > 0");
  for (std::int64_t i = 0; i < n; ++i) {
    for (int c = 0; c < dim_; ++c) {
      if (!std::isfinite(vectors[i * dim_ + c])) {
        throw std::invalid_argument("KnnIndex::Add: vectors (" + std::to_string(n) + " x " +
                                    std::to_string(dim_) + ") has a non-finite entry at row " +
                                    std::to_string(i) + ", column " + std::to_string(c));
      }
    }
  }
  const std::int64_t first = size();
  data_.insert(data_.end(), vectors, vectors + n * dim_);
  squared_norms_.resize(size());
  for (std::int64_t i = first; i < size(); ++i) {
    squared_norms_[i] = Eigen::Map<const Eigen::VectorXf>(data_.data() + i * dim_, dim_).squaredNorm();
  }
  OnAdd(first);
}

int KnnIndex::CheckSearch(const float* queries, std::int64_t n, int k, float* distances,
                          std::int64_t* labels) const {
  if (k < 1) throw std::invalid_argument("KnnIndex::Search: k must be >= 1, found " + std::to_string(k));
  if (n < 0) throw std::invalid_argument("KnnIndex::Search: n must be >= 0, found " + std::to_string(n));
  if (n > 0 && (queries == nullptr || distances == nullptr || labels == nullptr)) {
    throw std::invalid_argument("KnnIndex::Search: queries (" + std::to_string(n) + " x " +
                                std::to_string(dim_) + "), distances and labels (" +
                                std::to_string(n) + " x " + std::to_string(k) +
                                ") must not be null");
  }
  const int available = static_cast<int>(std::min<std::int64_t>(k, size()));
  for (std::int64_t i = 0; i < n; ++i) PadRow(distances + i * k, labels + i * k, available, k);
  return available;
}

void KnnIndex::Save(const std::string& path) const {
  TensorFile file("knn_index");
  nlohmann::json meta;
  meta["format"] = kFormat;
  meta["version"] = kVersion;
  meta["type"] = TypeName();
  meta["dim"] = dim_;
  meta["size"] = size();
  meta["params"] = nlohmann::json::parse(ParamsJson());
  file.set_meta_json(meta.dump());
  file.Add("vectors", TensorFile::DType::kFloat32, {size(), dim_},
           std::vector<double>(data_.begin(), data_.end()));
  WriteFileAtomically(path, file.Serialize());
}

std::unique_ptr<KnnIndex> KnnIndex::Load(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw TensorFileError(path + ": cannot open (does it exist?)");
  std::ostringstream buffer;
  buffer << in.rdbuf();
  return Parse(buffer.str(), path);
}

std::unique_ptr<KnnIndex> KnnIndex::Parse(const std::string& bytes, const std::string& path) {
  const TensorFile file = TensorFile::Parse(bytes, path, "knn_index");
  file.CheckFormat(kFormat, kVersion);
  std::string field = "meta";
  try {
    const nlohmann::json meta = nlohmann::json::parse(file.meta_json());
    field = "dim";
    int dim = 0;
    // Bounds far above any index: a hostile file must not make the reader allocate
    // or build beyond its own payload.
    if (!internal::JsonInt(meta.at("dim"), 1, 1 << 20, &dim)) {
      throw TensorFileError(path + ": field 'dim': expected an integer in [1, 2^20], got " +
                            Excerpt(meta.at("dim").dump()));
    }
    field = "size";
    std::int64_t size = 0;
    if (!internal::JsonInteger(meta.at("size"), 0, std::int64_t{1} << 40, &size)) {
      throw TensorFileError(path + ": field 'size': expected an integer in [0, 2^40], got " +
                            Excerpt(meta.at("size").dump()));
    }
    const TensorFile::Tensor& vectors = file.Get("vectors", {size, dim});
    field = "type";
    const std::string type = meta.at("type").get<std::string>();
    std::unique_ptr<KnnIndex> index;
    if (type == "brute_force") {
      index = std::make_unique<BruteForceKnnIndex>(dim);
    } else if (type == "flann") {
      field = "params";
      index = FlannKnnIndex::FromParamsJson(dim, meta.at("params").dump(), path);
    } else {
      throw TensorFileError(path + ": field 'type': expected \"brute_force\" or \"flann\", got \"" +
                            Excerpt(type) + "\"");
    }
    const std::vector<float> values(vectors.values.begin(), vectors.values.end());
    try {
      index->Add(values.data(), size);
    } catch (const std::invalid_argument& e) {
      throw TensorFileError(path + ": tensor 'vectors': " + e.what());
    }
    return index;
  } catch (const nlohmann::json::exception& e) {
    throw TensorFileError(path + ": field '" + field + "' is missing or has the wrong type (" +
                          Excerpt(e.what()) + ")");
  }
}

// ---- BruteForceKnnIndex -------------------------------------------------------------------

BruteForceKnnIndex::BruteForceKnnIndex(int dim) : KnnIndex(dim) {}

std::string BruteForceKnnIndex::Describe() const {
  return "brute_force (exact), " + std::to_string(size()) + " x " + std::to_string(dim());
}

void BruteForceKnnIndex::Search(const float* queries, std::int64_t n, int k, float* distances,
                                std::int64_t* labels) const {
  const int kk = CheckSearch(queries, n, k, distances, labels);
  ExactSearch(queries, n, k, kk, distances, labels);
}

void KnnIndex::ExactSearch(const float* queries, std::int64_t n, int k, int kk, float* distances,
                           std::int64_t* labels) const {
  if (kk == 0 || n == 0) return;
  const std::int64_t m = size();
  const int d = dim();
  const Eigen::Map<const RowMatrixXf> X(data_.data(), m, d);
  const float max_norm = *std::max_element(squared_norms_.begin(), squared_norms_.end());
  // Queries per GEMM: the block x m distance matrix stays within about 64 MB.
  const std::int64_t block =
      std::clamp<std::int64_t>((std::int64_t{16} << 20) / std::max<std::int64_t>(m, 1), 1, 256);
  RowMatrixXf dots;
  std::vector<std::int64_t> order(m);
  std::vector<std::pair<double, std::int64_t>> exact;
  for (std::int64_t b0 = 0; b0 < n; b0 += block) {
    const std::int64_t bn = std::min(block, n - b0);
    const Eigen::Map<const RowMatrixXf> Q(queries + b0 * d, bn, d);
    dots.resize(bn, m);
    dots.noalias() = Q * X.transpose();
    for (std::int64_t i = 0; i < bn; ++i) {
      const float* q = queries + (b0 + i) * d;
      float* out_d = distances + (b0 + i) * k;
      std::int64_t* out_l = labels + (b0 + i) * k;
      if (!RowIsFinite(q, d)) {
        PadRow(out_d, out_l, 0, k);
        continue;
      }
      const float q_norm = Q.row(i).squaredNorm();
      auto approx = [&](std::int64_t j) {
        return q_norm - 2.0f * dots(i, j) + squared_norms_[j];
      };
      std::iota(order.begin(), order.end(), std::int64_t{0});
      std::nth_element(order.begin(), order.begin() + (kk - 1), order.end(),
                       [&](std::int64_t a, std::int64_t b) { return approx(a) < approx(b); });
      // The expansion loses about eps * (||q||^2 + ||x||^2) to cancellation: every
      // vector within that band of the k-th approximate distance is a candidate, and
      // the candidates' distances are recomputed directly.
      const float slack = 64.0f * std::numeric_limits<float>::epsilon() *
                          (q_norm + max_norm + std::abs(approx(order[kk - 1])));
      const float threshold = approx(order[kk - 1]) + slack;
      exact.clear();
      for (std::int64_t j = 0; j < m; ++j) {
        if (approx(j) > threshold) continue;
        const float* x = data_.data() + j * d;
        double sum = 0;
        for (int c = 0; c < d; ++c) {
          const double diff = static_cast<double>(q[c]) - x[c];
          sum += diff * diff;
        }
        exact.emplace_back(sum, j);
      }
      const int take = std::min<int>(kk, static_cast<int>(exact.size()));
      std::partial_sort(exact.begin(), exact.begin() + take, exact.end());
      for (int j = 0; j < take; ++j) {
        out_d[j] = static_cast<float>(exact[j].first);
        out_l[j] = exact[j].second;
      }
      PadRow(out_d, out_l, take, k);
    }
  }
}

// ---- FlannKnnIndex ----------------------------------------------------------------------

const char* ToString(FlannKnnIndex::Algorithm algorithm) {
  switch (algorithm) {
    case FlannKnnIndex::Algorithm::kKdForest:
      return "kd_forest";
    case FlannKnnIndex::Algorithm::kKMeans:
      return "kmeans";
    case FlannKnnIndex::Algorithm::kAutotuned:
      return "autotuned";
    case FlannKnnIndex::Algorithm::kLinear:
      return "linear";
  }
  return "unknown";
}

bool FlannAlgorithmFromString(const std::string& name, FlannKnnIndex::Algorithm* algorithm) {
  for (auto a : {FlannKnnIndex::Algorithm::kKdForest, FlannKnnIndex::Algorithm::kKMeans,
                 FlannKnnIndex::Algorithm::kAutotuned, FlannKnnIndex::Algorithm::kLinear}) {
    if (name == ToString(a)) {
      *algorithm = a;
      return true;
    }
  }
  return false;
}

bool FlannKnnIndex::Options::IsValid(std::string* error) const {
  std::ostringstream message;
  if (algorithm != Algorithm::kKdForest && algorithm != Algorithm::kKMeans &&
      algorithm != Algorithm::kAutotuned && algorithm != Algorithm::kLinear) {
    message << "algorithm is not an Algorithm, found " << static_cast<int>(algorithm);
  } else if (trees < 1) {
    message << "trees must be >= 1, found " << trees;
  } else if (branching < 2) {
    message << "branching must be >= 2, found " << branching;
  } else if (kmeans_iterations < -1) {
    message << "kmeans_iterations must be >= -1 (-1: until convergence), found "
            << kmeans_iterations;
  } else if (!(cb_index > 0.0f && cb_index <= 1.0f)) {
    message << "cb_index must be in (0, 1], found " << cb_index;
  } else if (!(target_precision > 0.0f && target_precision <= 1.0f)) {
    message << "target_precision must be in (0, 1], found " << target_precision;
  } else if (!(build_weight >= 0.0f) || !std::isfinite(build_weight)) {
    message << "build_weight must be finite and >= 0, found " << build_weight;
  } else if (!(memory_weight >= 0.0f) || !std::isfinite(memory_weight)) {
    message << "memory_weight must be finite and >= 0, found " << memory_weight;
  } else if (!(sample_fraction > 0.0f && sample_fraction <= 1.0f)) {
    message << "sample_fraction must be in (0, 1], found " << sample_fraction;
  } else {
    return true;
  }
  if (error != nullptr) *error = "FlannKnnIndex::Options::" + message.str();
  return false;
}

bool FlannKnnIndex::SearchParams::IsValid(std::string* error) const {
  std::ostringstream message;
  if (checks < 1 && checks != -1) {
    message << "checks must be >= 1 or -1 (unlimited), found " << checks;
  } else if (!(eps >= 0.0f) || !std::isfinite(eps)) {
    message << "eps must be finite and >= 0, found " << eps;
  } else {
    return true;
  }
  if (error != nullptr) *error = "FlannKnnIndex::SearchParams::" + message.str();
  return false;
}

struct FlannKnnIndex::Impl {
  std::unique_ptr<flann::Index<flann::L2<float>>> index;
  // The concrete algorithm built (never kAutotuned) and, after autotuning, the checks
  // it chose (-1 otherwise).
  Options resolved;
  int tuned_checks = -1;
};

FlannKnnIndex::FlannKnnIndex(int dim, const Options& options, const SearchParams& search_params)
    : KnnIndex(dim), options_(options), search_params_(search_params),
      impl_(std::make_unique<Impl>()) {
  std::string error;
  if (!options_.IsValid(&error)) throw std::invalid_argument(error);
  if (!search_params_.IsValid(&error)) throw std::invalid_argument(error);
  impl_->resolved = options_;
}

FlannKnnIndex::FlannKnnIndex(int dim, const Options& options)
    : FlannKnnIndex(dim, options, SearchParams()) {}

FlannKnnIndex::~FlannKnnIndex() = default;

void FlannKnnIndex::set_search_params(const SearchParams& params) {
  std::string error;
  if (!params.IsValid(&error)) throw std::invalid_argument(error);
  search_params_ = params;
}

namespace {

flann::IndexParams ConcreteParams(const FlannKnnIndex::Options& o) {
  switch (o.algorithm) {
    case FlannKnnIndex::Algorithm::kKdForest:
      return flann::KDTreeIndexParams(o.trees);
    case FlannKnnIndex::Algorithm::kKMeans:
      return flann::KMeansIndexParams(o.branching, o.kmeans_iterations, flann::FLANN_CENTERS_RANDOM,
                                      o.cb_index);
    case FlannKnnIndex::Algorithm::kLinear:
      return flann::LinearIndexParams();
    case FlannKnnIndex::Algorithm::kAutotuned:
      return flann::AutotunedIndexParams(o.target_precision, o.build_weight, o.memory_weight,
                                         o.sample_fraction);
  }
  return flann::LinearIndexParams();
}

template <typename T>
T ParamOr(const flann::IndexParams& params, const char* name, T fallback) {
  try {
    return flann::get_param<T>(params, name, fallback);
  } catch (...) {
    return fallback;
  }
}

}  // namespace

void FlannKnnIndex::OnAdd(std::int64_t /*first_new_row*/) {
  const std::int64_t m = size();
  flann::Matrix<float> dataset(data_.data(), static_cast<size_t>(m), static_cast<size_t>(dim()));
  std::lock_guard<std::mutex> lock(internal::FlannBuildLock());
  Options resolved = options_;
  // A reloaded autotuned index (FromParamsJson) keeps the checks it was tuned to.
  int tuned_checks = options_.algorithm == Algorithm::kAutotuned ? -1 : impl_->tuned_checks;
  if (options_.algorithm == Algorithm::kAutotuned) {
    // Tune, then keep only the chosen parameters: the index is rebuilt from them below
    // exactly as Load will rebuild it.
    internal::SeedFlann(options_.seed);
    flann::Index<flann::L2<float>> tuner(dataset, ConcreteParams(options_));
    tuner.buildIndex();
    const flann::IndexParams best = tuner.getParameters();
    const auto algorithm =
        ParamOr<flann::flann_algorithm_t>(best, "algorithm", flann::FLANN_INDEX_LINEAR);
    switch (algorithm) {
      case flann::FLANN_INDEX_KDTREE:
        resolved.algorithm = Algorithm::kKdForest;
        resolved.trees = ParamOr<int>(best, "trees", options_.trees);
        break;
      case flann::FLANN_INDEX_KMEANS:
        resolved.algorithm = Algorithm::kKMeans;
        resolved.branching = ParamOr<int>(best, "branching", options_.branching);
        resolved.kmeans_iterations = ParamOr<int>(best, "iterations", options_.kmeans_iterations);
        resolved.cb_index = ParamOr<float>(best, "cb_index", options_.cb_index);
        break;
      default:
        resolved.algorithm = Algorithm::kLinear;
        break;
    }
    tuned_checks = ParamOr<flann::SearchParams>(best, "search_params", flann::SearchParams(-1))
                       .checks;
    if (tuned_checks < 1) tuned_checks = -1;
  }
  internal::SeedFlann(options_.seed);
  auto index = std::make_unique<flann::Index<flann::L2<float>>>(dataset, ConcreteParams(resolved));
  index->buildIndex();
  impl_->index = std::move(index);
  impl_->resolved = resolved;
  impl_->tuned_checks = tuned_checks;
}

void FlannKnnIndex::Search(const float* queries, std::int64_t n, int k, float* distances,
                           std::int64_t* labels) const {
  Search(queries, n, k, distances, labels, search_params_);
}

void FlannKnnIndex::Search(const float* queries, std::int64_t n, int k, float* distances,
                           std::int64_t* labels, const SearchParams& params) const {
  std::string error;
  if (!params.IsValid(&error)) throw std::invalid_argument(error);
  const int kk = CheckSearch(queries, n, k, distances, labels);
  if (kk == 0 || n == 0 || !impl_->index) return;
  if (params.checks == -1 && impl_->tuned_checks <= 0) {
    ExactSearch(queries, n, k, kk, distances, labels);
    return;
  }
  const int d = dim();
  const std::int64_t m = size();
  // Only finite queries go to FLANN; the others keep their -1 / inf padding.
  std::vector<std::int64_t> rows;
  rows.reserve(n);
  for (std::int64_t i = 0; i < n; ++i) {
    if (RowIsFinite(queries + i * d, d)) rows.push_back(i);
    else PadRow(distances + i * k, labels + i * k, 0, k);
  }
  if (rows.empty()) return;
  std::vector<float> packed;
  const float* q = queries;
  if (static_cast<std::int64_t>(rows.size()) != n) {
    packed.resize(rows.size() * d);
    for (size_t r = 0; r < rows.size(); ++r) {
      std::copy(queries + rows[r] * d, queries + (rows[r] + 1) * d, packed.begin() + r * d);
    }
    q = packed.data();
  }
  const size_t nq = rows.size();
  std::vector<size_t> found_labels(nq * kk, static_cast<size_t>(-1));
  std::vector<float> found_distances(nq * kk, kInf);
  flann::Matrix<float> query_matrix(const_cast<float*>(q), nq, d);
  flann::Matrix<size_t> label_matrix(found_labels.data(), nq, kk);
  flann::Matrix<float> distance_matrix(found_distances.data(), nq, kk);
  flann::SearchParams flann_params(params.checks, params.eps, /*sorted=*/true);
  if (impl_->tuned_checks > 0) flann_params.checks = impl_->tuned_checks;
  impl_->index->knnSearch(query_matrix, label_matrix, distance_matrix, kk, flann_params);
  for (size_t r = 0; r < nq; ++r) {
    float* out_d = distances + rows[r] * k;
    std::int64_t* out_l = labels + rows[r] * k;
    int filled = 0;
    for (int j = 0; j < kk; ++j) {
      const size_t label = found_labels[r * kk + j];
      const float dist = found_distances[r * kk + j];
      if (label >= static_cast<size_t>(m) || !(dist < std::numeric_limits<float>::max())) continue;
      out_d[filled] = dist;
      out_l[filled] = static_cast<std::int64_t>(label);
      ++filled;
    }
    PadRow(out_d, out_l, filled, k);
  }
}

std::string FlannKnnIndex::ResolvedParamsJson() const {
  const Options& r = impl_->resolved;
  nlohmann::json j;
  j["algorithm"] = ToString(r.algorithm);
  j["requested_algorithm"] = ToString(options_.algorithm);
  j["trees"] = r.trees;
  j["branching"] = r.branching;
  j["kmeans_iterations"] = r.kmeans_iterations;
  j["cb_index"] = r.cb_index;
  j["target_precision"] = r.target_precision;
  j["build_weight"] = r.build_weight;
  j["memory_weight"] = r.memory_weight;
  j["sample_fraction"] = r.sample_fraction;
  j["seed"] = r.seed;
  j["tuned_checks"] = impl_->tuned_checks;
  j["search"] = {{"checks", search_params_.checks}, {"eps", search_params_.eps}};
  return j.dump();
}

std::string FlannKnnIndex::Describe() const {
  std::ostringstream out;
  const Options& r = impl_->resolved;
  out << "flann " << ToString(r.algorithm);
  if (options_.algorithm == Algorithm::kAutotuned) out << " (autotuned, target " << options_.target_precision << ")";
  if (r.algorithm == Algorithm::kKdForest) out << ", trees " << r.trees;
  if (r.algorithm == Algorithm::kKMeans) {
    out << ", branching " << r.branching << ", iterations " << r.kmeans_iterations;
  }
  out << ", checks " << (impl_->tuned_checks > 0 ? impl_->tuned_checks : search_params_.checks)
      << ", seed " << r.seed << ", " << size() << " x " << dim();
  return out.str();
}

std::unique_ptr<FlannKnnIndex> FlannKnnIndex::FromParamsJson(int dim, const std::string& json,
                                                             const std::string& source) {
  const nlohmann::json j = nlohmann::json::parse(json);
  Options options;
  const std::string algorithm = j.at("algorithm").get<std::string>();
  if (!FlannAlgorithmFromString(algorithm, &options.algorithm) ||
      options.algorithm == Algorithm::kAutotuned) {
    throw TensorFileError(source + ": field 'params.algorithm': expected kd_forest, kmeans or linear, got \"" +
                          Excerpt(algorithm) + "\"");
  }
  // Each parameter within bounds before it is converted (no out-of-range casts) and
  // before FLANN builds anything (no hostile file asks for a billion trees).
  auto integer = [&](const nlohmann::json& value, const char* name, int lo, int hi) {
    int out = 0;
    if (!internal::JsonInt(value, lo, hi, &out)) {
      throw TensorFileError(source + ": field 'params." + name + "': expected an integer in [" +
                            std::to_string(lo) + ", " + std::to_string(hi) + "], got " +
                            Excerpt(value.dump()));
    }
    return out;
  };
  auto real = [&](const nlohmann::json& value, const char* name) {
    double out = 0;
    if (!internal::JsonReal(value, -1e30, 1e30, &out)) {
      throw TensorFileError(source + ": field 'params." + name +
                            "': expected a finite number, got " + Excerpt(value.dump()));
    }
    return static_cast<float>(out);
  };
  options.trees = integer(j.at("trees"), "trees", 1, 1024);
  options.branching = integer(j.at("branching"), "branching", 2, 1 << 16);
  options.kmeans_iterations = integer(j.at("kmeans_iterations"), "kmeans_iterations", -1, 1 << 20);
  options.cb_index = real(j.at("cb_index"), "cb_index");
  options.target_precision = real(j.at("target_precision"), "target_precision");
  options.build_weight = real(j.at("build_weight"), "build_weight");
  options.memory_weight = real(j.at("memory_weight"), "memory_weight");
  options.sample_fraction = real(j.at("sample_fraction"), "sample_fraction");
  std::int64_t seed = 0;
  if (!internal::JsonInteger(j.at("seed"), 0, std::numeric_limits<std::uint32_t>::max(), &seed)) {
    throw TensorFileError(source + ": field 'params.seed': expected an integer in [0, 2^32), got " +
                          Excerpt(j.at("seed").dump()));
  }
  options.seed = static_cast<std::uint32_t>(seed);
  SearchParams search;
  search.checks = integer(j.at("search").at("checks"), "search.checks", -2, 1 << 30);
  search.eps = real(j.at("search").at("eps"), "search.eps");
  std::string error;
  if (!options.IsValid(&error)) throw TensorFileError(source + ": params: " + error);
  if (!search.IsValid(&error)) throw TensorFileError(source + ": params.search: " + error);
  auto index = std::make_unique<FlannKnnIndex>(dim, options, search);
  // An autotuned index reloads as the index the tuning chose, with the tuned checks.
  index->impl_->tuned_checks = integer(j.at("tuned_checks"), "tuned_checks", -2, 1 << 30);
  return index;
}

// ---- Recall --------------------------------------------------------------------------------

double Recall(const KnnIndex& approx, const KnnIndex& exact, const float* queries,
              std::int64_t n, int k) {
  if (approx.dim() != exact.dim() || approx.size() != exact.size()) {
    throw std::invalid_argument("Recall: the indexes differ: approx " +
                                std::to_string(approx.size()) + " x " +
                                std::to_string(approx.dim()) + ", exact " +
                                std::to_string(exact.size()) + " x " +
                                std::to_string(exact.dim()));
  }
  if (n == 0) return 1.0;
  std::vector<float> da(n * k), de(n * k);
  std::vector<std::int64_t> la(n * k), le(n * k);
  approx.Search(queries, n, k, da.data(), la.data());
  exact.Search(queries, n, k, de.data(), le.data());
  std::int64_t hits = 0, total = 0;
  for (std::int64_t i = 0; i < n; ++i) {
    for (int j = 0; j < k; ++j) {
      const std::int64_t label = le[i * k + j];
      if (label < 0) continue;
      ++total;
      const auto* begin = la.data() + i * k;
      if (std::find(begin, begin + k, label) != begin + k) ++hits;
    }
  }
  return total == 0 ? 1.0 : static_cast<double>(hits) / static_cast<double>(total);
}

// ---- Construction -------------------------------------------------------------------

bool KnnIndexOptions::IsValid(std::string* error) const {
  FlannKnnIndex::Algorithm algorithm;
  if (type != "brute_force" && !FlannAlgorithmFromString(type, &algorithm)) {
    if (error != nullptr) {
      *error = "KnnIndexOptions::type: expected brute_force, kd_forest, kmeans, autotuned or "
               "linear, got '" + type + "'";
    }
    return false;
  }
  return flann.IsValid(error) && search.IsValid(error);
}

std::unique_ptr<KnnIndex> BuildKnnIndex(const KnnVectors& vectors,
                                        const KnnIndexOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  const int dim = static_cast<int>(vectors.cols());
  std::unique_ptr<KnnIndex> index;
  if (options.type == "brute_force") {
    index = std::make_unique<BruteForceKnnIndex>(dim);
  } else {
    FlannKnnIndex::Options flann = options.flann;
    FlannAlgorithmFromString(options.type, &flann.algorithm);
    index = std::make_unique<FlannKnnIndex>(dim, flann, options.search);
  }
  index->Add(vectors.data(), vectors.rows());
  return index;
}

std::string WhyKnnIndexIsStale(const KnnIndex& index, const KnnVectors& vectors,
                               const KnnIndexOptions& options) {
  if (index.dim() != vectors.cols() || index.size() != vectors.rows()) {
    return "it holds " + std::to_string(index.size()) + " x " + std::to_string(index.dim()) +
           " vectors, the functaset " + std::to_string(vectors.rows()) + " x " +
           std::to_string(vectors.cols());
  }
  const std::size_t bytes = static_cast<std::size_t>(vectors.size()) * sizeof(float);
  if (Crc32(index.data(), bytes) != Crc32(vectors.data(), bytes)) {
    return "its vectors differ from the functaset's latents (CRC-32)";
  }
  const auto* flann = dynamic_cast<const FlannKnnIndex*>(&index);
  const std::string found =
      flann != nullptr ? ToString(flann->options().algorithm) : "brute_force";
  if (found != options.type) return "it is a " + found + " index, " + options.type + " was asked for";
  if (flann != nullptr) {
    const FlannKnnIndex::Options& wanted = options.flann;
    const FlannKnnIndex::Options& o = flann->options();
    if (o.trees != wanted.trees || o.branching != wanted.branching ||
        o.kmeans_iterations != wanted.kmeans_iterations || o.cb_index != wanted.cb_index ||
        o.seed != wanted.seed) {
      return "it was built with other parameters (" + index.Describe() + ")";
    }
  }
  return "";
}

std::unique_ptr<KnnIndex> LoadOrBuildKnnIndex(const std::string& path, const KnnVectors& vectors,
                                              const KnnIndexOptions& options,
                                              KnnIndexCacheSummary* summary) {
  KnnIndexCacheSummary local;
  KnnIndexCacheSummary& s = summary != nullptr ? *summary : local;
  s = KnnIndexCacheSummary();
  s.path = path;
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  s.why_rebuilt = "it does not exist";
  std::error_code ec;
  if (std::filesystem::exists(path, ec)) {
    try {
      std::unique_ptr<KnnIndex> index = KnnIndex::Load(path);
      s.why_rebuilt = WhyKnnIndexIsStale(*index, vectors, options);
      if (s.why_rebuilt.empty()) {
        if (auto* flann = dynamic_cast<FlannKnnIndex*>(index.get())) {
          FlannKnnIndex::SearchParams search = flann->search_params();
          search.checks = options.search.checks;
          flann->set_search_params(search);
        }
        return index;
      }
    } catch (const std::exception& e) {
      s.why_rebuilt = std::string("it cannot be read (") + e.what() + ")";
    }
  }
  std::unique_ptr<KnnIndex> index = BuildKnnIndex(vectors, options);
  s.rebuilt = true;
  try {
    index->Save(path);  // atomic (models/core/atomic_file.h)
  } catch (const std::exception& e) {
    s.save_error = e.what();
  }
  return index;
}

}  // namespace tactfunc
