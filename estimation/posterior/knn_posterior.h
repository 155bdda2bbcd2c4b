// Copyright 2026 The tactfunc Authors.
//
// KnnPosterior: the k-NN pose posterior of "Tactile Functasets" (Sec. III-C): the
// stored pose labels of the k functaset entries whose latents are nearest (Euclidean,
// estimation/knn/knn_index.h) to a cheap latent estimate q of the new frame, returned as a
// weighted PoseDistribution -- a Nadaraya-Watson estimate of p(pose | q) with no trunk
// or pose-MLP evaluation at all: the fastest sampler, limited to poses that were seen.
//
// Weights (decision). For neighbours i = 1..k at distances d_1 <= ... <= d_k:
//   kGaussianKernel (default)  w_i = exp(-d_i^2 / (2 h^2)),  h = d_k  (the k-th distance:
//                              the adaptive "balloon" bandwidth of k-NN density
//                              estimation). Weights lie in [exp(-1/2), 1]: every
//                              neighbour counts and the nearest counts at most 1.65x the
//                              farthest. If d_k = 0 (k exact duplicates) all are equal.
//   kInverseDistance           w_i = 1 / d_i, the paper's weights for the latent average
//                              (and LatentFitter's knn strategy); an exact match (d_i <
//                              1e-12 relative to d_k) takes all the weight, shared among
//                              such matches.
// The Gaussian kernel is the default because inverse distances collapse onto one pose
// whenever the query is (nearly) a functaset entry -- exactly when the frame is most
// familiar -- and give a point-mass posterior with zero covariance, i.e. an overconfident
// filter update. The k-NN spread is a spread of TRAINING poses near q, not a calibrated
// posterior: its width is set by the functaset's density, not the frame's noise.
//
// Labels. poses[i] is the pose of index label i (the functaset entry in row i of the
// latents the index was built from), or nullopt for an unlabelled entry; unlabelled
// neighbours are skipped (the k nearest labelled ones are NOT searched further: more
// neighbours are asked for, search_k). PosesOf() builds the vector in
// Functaset::Latents(sensor, split) row order.
//
// Thread safety: Posterior is const and may run concurrently (KnnIndex::Search is).
#ifndef TACTFUNC_ESTIMATION_POSTERIOR_KNN_POSTERIOR_H_
#define TACTFUNC_ESTIMATION_POSTERIOR_KNN_POSTERIOR_H_

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "estimation/functaset/functaset.h"
#include "estimation/knn/knn_index.h"
#include "estimation/pose/pose_distribution.h"
#include "models/core/se2.h"

namespace tactfunc {

enum class KnnPosteriorTermination {
  kSuccess,               // a distribution over >= 1 labelled neighbour
  kNoLabelledNeighbors,   // the index is empty, the query is NaN, or no neighbour has a pose
};
// "SUCCESS", "NO_LABELLED_NEIGHBORS".
const char* ToString(KnnPosteriorTermination termination);

class KnnPosterior {
 public:
  enum class Weighting { kGaussianKernel, kInverseDistance };

  struct Options {
    // Neighbours k in the distribution. >= 1. 8, as LatentFitter::Options::knn_k (the
    // paper does not give k).
    int k = 8;
    // Neighbours asked of the index, >= k (0 = k): unlabelled ones are skipped, so ask
    // for more when the functaset has unlabelled frames.
    int search_k = 0;
    // See the header comment.
    Weighting weighting = Weighting::kGaussianKernel;
    bool IsValid(std::string* error) const;
  };

  struct Summary {
    KnnPosteriorTermination termination_type = KnnPosteriorTermination::kNoLabelledNeighbors;
    std::string message;
    // The neighbours used, nearest first: index labels, Euclidean (not squared)
    // distances, normalised weights (sum 1).
    std::vector<std::int64_t> labels;
    std::vector<double> distances;
    std::vector<double> weights;
    int num_unlabelled_skipped = 0;
    double bandwidth = 0;  // h of the Gaussian kernel (0 for inverse distance)
    double total_time_ms = 0;
    bool IsSolutionUsable() const {
      return termination_type == KnnPosteriorTermination::kSuccess;
    }
    std::string BriefReport() const;
  };

  // `index` must outlive this object; poses has index.size() entries (label i -> pose
  // i). Throws std::invalid_argument for bad options or a size mismatch.
  KnnPosterior(const KnnIndex& index, std::vector<std::optional<SE2d>> poses,
               const Options& options);

  // The poses of functaset entries of `sensor` (optionally one split) as sensor_T_object
  // SE2d(x_m, y_m, yaw_rad), in Functaset::Latents(sensor, split) row order.
  static std::vector<std::optional<SE2d>> PosesOf(const Functaset& functaset, SensorKind sensor,
                                                  std::optional<Split> split = std::nullopt);

  // The posterior for a query latent (size index.dim()). *posterior receives the
  // distribution (nullopt unless kSuccess). Throws std::invalid_argument for a query of
  // the wrong size or a null posterior.
  Summary Posterior(const Eigen::VectorXd& query, std::optional<PoseDistribution>* posterior) const;

  const Options& options() const { return options_; }

 private:
  const KnnIndex* index_;
  std::vector<std::optional<SE2d>> poses_;
  Options options_;
};

const char* ToString(KnnPosterior::Weighting weighting);  // "gaussian_kernel", "inverse_distance"

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_POSTERIOR_KNN_POSTERIOR_H_
