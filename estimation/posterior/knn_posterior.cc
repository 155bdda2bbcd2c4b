// Copyright 2026 The tactfunc Authors.
#include "estimation/posterior/knn_posterior.h"

#include <chrono>
#include <cmath>
#include <sstream>
#include <stdexcept>

#include "models/core/internal/elapsed.h"

namespace tactfunc {

const char* ToString(KnnPosteriorTermination termination) {
  switch (termination) {
    case KnnPosteriorTermination::kSuccess:
      return "SUCCESS";
    case KnnPosteriorTermination::kNoLabelledNeighbors:
      return "NO_LABELLED_NEIGHBORS";
  }
  return "UNKNOWN";
}

const char* ToString(KnnPosterior::Weighting weighting) {
  switch (weighting) {
    case KnnPosterior::Weighting::kGaussianKernel:
      return "gaussian_kernel";
    case KnnPosterior::Weighting::kInverseDistance:
      return "inverse_distance";
  }
  return "unknown";
}

bool KnnPosterior::Options::IsValid(std::string* error) const {
  std::ostringstream m;
  if (k < 1) {
    m << "KnnPosterior::Options::k must be >= 1, got " << k;
  } else if (search_k != 0 && search_k < k) {
    m << "KnnPosterior::Options::search_k must be 0 or >= k (" << k << "), got " << search_k;
  } else {
    return true;
  }
  if (error != nullptr) *error = m.str();
  return false;
}

std::string KnnPosterior::Summary::BriefReport() const {
  std::ostringstream s;
  s << "k-NN posterior: " << ToString(termination_type) << ", " << labels.size()
    << " neighbours";
  if (!distances.empty()) {
    s << " at distances " << distances.front() << " .. " << distances.back();
  }
  if (num_unlabelled_skipped > 0) s << ", " << num_unlabelled_skipped << " unlabelled skipped";
  s << ", " << total_time_ms << " ms";
  return s.str();
}

KnnPosterior::KnnPosterior(const KnnIndex& index, std::vector<std::optional<SE2d>> poses,
                           const Options& options)
    : index_(&index), poses_(std::move(poses)), options_(options) {
  std::string error;
  if (!options_.IsValid(&error)) throw std::invalid_argument(error);
  if (static_cast<std::int64_t>(poses_.size()) != index.size()) {
    throw std::invalid_argument("KnnPosterior: expected one pose per index entry (" +
                                std::to_string(index.size()) + "), got " +
                                std::to_string(poses_.size()));
  }
}

std::vector<std::optional<SE2d>> KnnPosterior::PosesOf(const Functaset& functaset,
                                                       SensorKind sensor,
                                                       std::optional<Split> split) {
  std::vector<std::optional<SE2d>> poses;
  for (const FunctasetEntry& entry : functaset.entries(sensor)) {
    if (split && entry.split != *split) continue;
    if (entry.label) {
      poses.push_back(entry.label->sensor_T_object);
    } else {
      poses.emplace_back(std::nullopt);
    }
  }
  return poses;
}

KnnPosterior::Summary KnnPosterior::Posterior(const Eigen::VectorXd& query,
                                              std::optional<PoseDistribution>* posterior) const {
  const auto start = std::chrono::steady_clock::now();
  if (posterior == nullptr) {
    throw std::invalid_argument("KnnPosterior::Posterior: posterior must not be null");
  }
  if (query.size() != index_->dim()) {
    throw std::invalid_argument("KnnPosterior::Posterior: expected a query of size " +
                                std::to_string(index_->dim()) + ", got " +
                                std::to_string(query.size()));
  }
  posterior->reset();
  Summary summary;
  const int search_k = options_.search_k > 0 ? options_.search_k : options_.k;
  std::vector<float> squared(search_k);
  std::vector<std::int64_t> labels(search_k);
  const Eigen::VectorXf q = query.cast<float>();
  if (index_->size() > 0) index_->Search(q.data(), 1, search_k, squared.data(), labels.data());
  std::vector<SE2d> samples;
  for (int i = 0; i < search_k && static_cast<int>(summary.labels.size()) < options_.k; ++i) {
    if (labels[i] < 0 || !std::isfinite(squared[i])) break;
    if (!poses_[labels[i]]) {
      ++summary.num_unlabelled_skipped;
      continue;
    }
    summary.labels.push_back(labels[i]);
    summary.distances.push_back(std::sqrt(std::max(0.0, static_cast<double>(squared[i]))));
    samples.push_back(*poses_[labels[i]]);
  }
  const int n = static_cast<int>(samples.size());
  if (n == 0) {
    summary.termination_type = KnnPosteriorTermination::kNoLabelledNeighbors;
    summary.message = index_->size() == 0
                          ? "the k-NN index is empty"
                          : "none of the " + std::to_string(search_k) +
                                " nearest entries has a pose label (or the query is not finite)";
    summary.total_time_ms = internal::MsSince(start);
    return summary;
  }
  std::vector<double> w(n);
  const double farthest = summary.distances.back();
  if (options_.weighting == Weighting::kGaussianKernel) {
    summary.bandwidth = farthest;
    for (int i = 0; i < n; ++i) {
      w[i] = farthest > 0 ? std::exp(-0.5 * std::pow(summary.distances[i] / farthest, 2)) : 1.0;
    }
  } else {
    const double tiny = 1e-12 * std::max(farthest, 1e-300);
    bool exact = false;
    for (int i = 0; i < n; ++i) exact = exact || summary.distances[i] <= tiny;
    for (int i = 0; i < n; ++i) {
      w[i] = exact ? (summary.distances[i] <= tiny ? 1.0 : 0.0) : 1.0 / summary.distances[i];
    }
  }
  double total = 0;
  for (double x : w) total += x;
  for (double& x : w) x /= total;
  summary.weights = w;
  posterior->emplace(std::move(samples), std::move(w));
  summary.termination_type = KnnPosteriorTermination::kSuccess;
  summary.message = std::to_string(n) + " labelled neighbours, " + ToString(options_.weighting) +
                    " weights";
  summary.total_time_ms = internal::MsSince(start);
  return summary;
}

}  // namespace tactfunc
