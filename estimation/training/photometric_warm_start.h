// Copyright 2026 The tactfunc Authors.
//
// PhotometricWarmStart: a start for a photometric latent's fit (FitPhotometricLatent,
// estimation/training/photometric_trainer.h) looked up among the training frames' latents,
// so that a few Adam steps can replace two cold starts of a few hundred.
//
// A photometric latent is a contact frame (t_0, t_1, phi) and a code. Frames of one tool
// pressed at different places and angles differ by that frame, so neighbours are looked
// for in each frame's own MOMENT frame (MomentPose: the centroid and principal axis of the
// difference energy), where they differ by shape and depth alone:
//
//   descriptor(frame) = the frame's targets averaged over the G x G cells of a square of
//                       half-width `extent` (the trunk's isotropic units) centred at t and
//                       turned by phi (K x K bilinear samples per cell, zero outside the
//                       frame), G * G * C values, cell (a, b) at index (a * G + b) * C + c.
//
// A training frame n stores its descriptor and its latent with the contact frame
// expressed in its moment frame M_n: D_n = M_n^-1 Z_n (SE(2), models/core/se2.h), code
// unchanged. A new frame with moment frame M looks up its descriptor and the descriptor
// of M turned by pi (the principal axis has no direction; turning the square by pi
// reverses the cell order), and each neighbour found gives the start (M D_n, code_n) or
// (M Rot(pi) D_n, code_n). The neighbours are searched with FLANN (exact, LinearIndex;
// the table holds a few thousand rows, estimation/knn/knn_index.h) by Euclidean distance.
//
// Tables are built by `train --head photometric` from the trainer's latents and stored in
// the model (models/trunk/functa_model.h, WarmStartTable). docs/REPRESENTATION.md ("A
// warm start from the training latents") measured the fit from it.
//
// Thread safety: const methods are safe to call concurrently.
#ifndef TACTFUNC_ESTIMATION_TRAINING_PHOTOMETRIC_WARM_START_H_
#define TACTFUNC_ESTIMATION_TRAINING_PHOTOMETRIC_WARM_START_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "estimation/data/trunk_targets.h"
#include "estimation/training/photometric_trainer.h"
#include "models/trunk/functa_model.h"
#include "models/trunk/photometric_trunk.h"

namespace tactfunc {

class KnnIndex;

class PhotometricWarmStart {
 public:
  struct Options {
    int grid = 16;         // G, cells per side, in [1, 64]
    double extent = 1.0;   // half-width of the square (isotropic units), > 0
    int supersample = 3;   // K, bilinear samples per cell and side, in [1, 8]
    bool IsValid(std::string* error) const;
  };

  // Builds the table of `frames` and their fitted `latents` (one row per frame, the
  // trunk's d columns: PhotometricTrainer::Result::latents). Throws std::invalid_argument
  // for invalid options, no frames, or latents of another shape.
  static WarmStartTable BuildTable(const PhotometricTrunk& trunk,
                                   const std::vector<TrunkTargets>& frames,
                                   const Eigen::MatrixXd& latents, const Options& options,
                                   int threads = 1);

  // Searches `table`, which must belong to `trunk` (its latent size and descriptor size
  // are checked; std::invalid_argument naming both otherwise). `trunk` must outlive this.
  PhotometricWarmStart(const PhotometricTrunk& trunk, std::shared_ptr<const WarmStartTable> table);
  ~PhotometricWarmStart();
  PhotometricWarmStart(PhotometricWarmStart&&) noexcept;
  PhotometricWarmStart& operator=(PhotometricWarmStart&&) noexcept;

  // The descriptor of the header comment in the moment frame `moment` (t_0, t_1, phi).
  static Eigen::VectorXf Descriptor(const PhotometricTrunk& trunk, const TrunkTargets& frame,
                                    const Eigen::Vector3d& moment, const Options& options);

  // Up to k starts for `frame`, nearest neighbour first (over both turns of the moment
  // frame); none for a descriptor that is not finite. k >= 1. Throws
  // std::invalid_argument for a frame of another size.
  std::vector<Eigen::VectorXd> Starts(const TrunkTargets& frame, int k) const;

  // The start of Starts(frame, k) with the lowest loss on `pixels` of the frame's pixels
  // evenly spaced (one forward pass of them per start; k = 1 passes none); the moment
  // pose and a zero code where Starts finds none. `markers`: the frame's own
  // (PhotometricTrunk::MakeMarkers), or null for the trunk's own reference.
  static constexpr int kScoredPixels = 512;
  Eigen::VectorXd BestStart(const TrunkTargets& frame, int k, int pixels = kScoredPixels,
                            const PhotometricTrunk::Markers* markers = nullptr) const;

  // The fit from BestStart(frame, k): options.steps Adam steps from it with one start
  // and no full-frame scoring (options' flipped_start and score are overridden), or
  // that start as it is for options.steps == 0. `seed` draws the pixel subsets; the
  // start is scored against options.markers, as the fit runs.
  PhotometricFit Fit(const TrunkTargets& frame, int k, PhotometricFitOptions options,
                     std::uint64_t seed) const;

  const WarmStartTable& table() const { return *table_; }

 private:
  const PhotometricTrunk* trunk_;
  std::shared_ptr<const WarmStartTable> table_;
  Options options_;
  std::unique_ptr<KnnIndex> index_;
};

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_TRAINING_PHOTOMETRIC_WARM_START_H_
