// Copyright 2026 The tactfunc Authors.
//
// A photometric trunk's latent (models/trunk/photometric_trunk.h) fitted as least squares
// in Ceres: Levenberg-Marquardt over the d latent values from a start (a warm-start
// neighbour's latent), residuals
//
//   r_{j,c}(z) = sqrt(w_j) (y_{j,c}(z) - t_{j,c})
//
// over a fixed subset of the frame's valid pixels (evenly spaced in grid order, or all of
// them), with the trunk's exact Jacobian (PhotometricTrunk::ForwardAndLatentJacobian: a
// few batched SIREN passes over the pixels' positions) as the cost function's analytic
// Jacobian. It minimises the trunk's weighted MSE, as the Adam fit does
// (estimation/training/photometric_trainer.h), without a prior: a Gauss-Newton step uses
// the curvature Adam only estimates, so a few iterations go where tens of Adam steps go
// (docs/REPRESENTATION.md measures the trade).
//
// Thread safety: the function may run concurrently on one trunk.
#ifndef TACTFUNC_ESTIMATION_FITTING_PHOTOMETRIC_CERES_FIT_H_
#define TACTFUNC_ESTIMATION_FITTING_PHOTOMETRIC_CERES_FIT_H_

#include <string>

#include <Eigen/Core>

#include "estimation/data/trunk_targets.h"
#include "models/trunk/photometric_trunk.h"

namespace tactfunc {

struct PhotometricCeresOptions {
  int iterations = 5;  // Ceres' max_num_iterations, >= 1
  // The residuals' pixels: this many of the frame's valid pixels, evenly spaced in grid
  // order (all of them if there are fewer). 0 (default): every valid pixel. A subset
  // costs less per iteration but its fit is worse for the same time
  // (docs/REPRESENTATION.md, "A photometric latent fitted in Ceres").
  int pixels = 0;
  // The frame's own markers (PhotometricTrunk::MakeMarkers of its reference; not owned,
  // must outlive the fit), or null for the trunk's own reference.
  const PhotometricTrunk::Markers* markers = nullptr;
  bool IsValid(std::string* error) const;
};

struct PhotometricCeresFit {
  Eigen::VectorXd latent;
  double initial_cost = 0;  // Ceres' cost (half the sum of squared residuals) at the start
  double final_cost = 0;
  int iterations = 0;       // Ceres' iterations, the start's evaluation included
  std::string message;      // Ceres' termination message
};

// Throws std::invalid_argument for invalid options, targets of another grid or channel
// count than the trunk's, or a start that is not d finite values. A frame without valid
// pixels returns the start.
PhotometricCeresFit FitPhotometricLatentCeres(const PhotometricTrunk& trunk,
                                              const TrunkTargets& frame,
                                              const Eigen::VectorXd& start,
                                              const PhotometricCeresOptions& options);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_FITTING_PHOTOMETRIC_CERES_FIT_H_
