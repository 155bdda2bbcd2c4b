// Copyright 2026 The tactfunc Authors.
//
// PhotometricPotential: the latent posterior of one frame under a frozen photometric
// trunk (models/trunk/photometric_trunk.h), for the samplers (samplers/sgld.h,
// samplers/laplace.h). With the frame's valid pixels j (weight w_j > 0), its C channels
// and the trunk's outputs y_j(z):
//
//   U(z) = sum_j w_j ||y_j(z) - t_j||^2 / (2 sigma^2) + ||z||^2 / (2 sigma_z^2)
//
// the LatentProblem's U (estimation/fitting/latent_problem.h) without a robust loss,
// over every valid pixel. grad U comes from the trunk's reverse pass; the Gauss-Newton
// Hessian J^T W J / sigma^2 + I / sigma_z^2 takes the latent Jacobian J from the trunk's
// exact Jacobian (PhotometricTrunk::ForwardAndLatentJacobian: 2 + C batched SIREN passes
// over the frame's positions, where central differences took 2 d whole-frame forward
// passes). The pose values (t_0, t_1, phi) are latent values like the others, so
// the prior also holds the contact near the frame's centre at sigma_z; at sigma_z = 1
// (two working-frame heights) that says almost nothing.
//
// Thread safety: const members may be called concurrently; the trunk and targets must
// outlive the potential.
#ifndef TACTFUNC_SAMPLERS_PHOTOMETRIC_POTENTIAL_H_
#define TACTFUNC_SAMPLERS_PHOTOMETRIC_POTENTIAL_H_

#include <vector>

#include <Eigen/Core>

#include "estimation/data/trunk_targets.h"
#include "models/trunk/photometric_trunk.h"
#include "samplers/sgld.h"

namespace tactfunc {

class PhotometricPotential : public LatentPotential {
 public:
  // Throws std::invalid_argument for targets that are not rows * cols x C of the
  // trunk's grid and channels, weights of another size or negative, or sigma, sigma_z
  // not finite and > 0.
  // `markers` (may be null: the trunk's own reference) are the frame's own reference's
  // (PhotometricTrunk::MakeMarkers) and must outlive the potential.
  PhotometricPotential(const PhotometricTrunk& trunk, const TrunkTargets& targets, double sigma,
                       double sigma_z, const PhotometricTrunk::Markers* markers = nullptr);

  int dim() const override { return trunk_->latent_dim(); }
  // U from the outputs of the Jacobian's own pass (no second forward pass).
  bool PotentialAndGaussNewtonHessian(const Eigen::VectorXd& z, double* potential,
                                      Eigen::MatrixXd* hessian) const override;
  double Evaluate(const Eigen::VectorXd& z, Eigen::VectorXd* gradient) const override;
  // The valid pixels are the data terms.
  int NumDataTerms() const override { return static_cast<int>(pixels_.size()); }
  double EvaluateMinibatch(const Eigen::VectorXd& z, const std::vector<int>& indices,
                           Eigen::VectorXd* gradient) const override;
  bool GaussNewtonHessian(const Eigen::VectorXd& z, Eigen::MatrixXd* hessian) const override;

 private:
  // U's data part over `pixels` (grid indices) with their targets and weights, scaled
  // by `scale`, plus the prior; gradient as Evaluate's.
  double EvaluateOn(const Eigen::VectorXd& z, const std::vector<int>& pixels,
                    const Eigen::MatrixXf& values, const Eigen::VectorXf& weights,
                    double scale, Eigen::VectorXd* gradient) const;

  // GaussNewtonHessian, and U(z) from the same pass if potential is not null.
  bool HessianPass(const Eigen::VectorXd& z, double* potential, Eigen::MatrixXd* hessian) const;

  const PhotometricTrunk* trunk_;
  const PhotometricTrunk::Markers* markers_;
  std::vector<int> pixels_;   // the valid pixels, in grid order
  Eigen::MatrixXf values_;    // their targets, pixels_.size() x C
  Eigen::VectorXf weights_;   // their weights
  double sigma_;
  double sigma_z_;
};

}  // namespace tactfunc

#endif  // TACTFUNC_SAMPLERS_PHOTOMETRIC_POTENTIAL_H_
