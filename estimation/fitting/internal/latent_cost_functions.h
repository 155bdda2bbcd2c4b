// Copyright 2026 The tactfunc Authors.
//
// The Ceres cost functions of LatentFitter (estimation/fitting/latent_fitter.h; the problem is
// written out in docs/FITTING.md):
//
//   data residuals   r_{j,c}(z) = s_j (f_theta(x_j; z)_c - y_{j,c}),  s_j = sqrt(w_j) / sigma
//                    over the selected valid pixels j and channels c, residual j*C + c
//   prior residuals  r_k(z) = z_k / sigma_z,  k = 0 .. d-1
//
// with the trunk theta frozen. The data residuals come in two interchangeable forms:
//   AnalyticLatentCost<Scalar>  one batched forward pass and one reverse pass per output
//                               channel (LatentModulatedSiren::ForwardAndLatentJacobian),
//                               evaluated in Scalar (float or double), accumulated by
//                               Ceres in double;
//   MakeAutoDiffLatentCost      the reference: ceres::DynamicAutoDiffCostFunction over the
//                               templated one-pixel LatentModulatedSiren::Evaluate<Jet>.
// RobustifiedCost applies a ceres::LossFunction to EACH residual of a batched block (Ceres
// itself applies a loss to a block's squared norm, which for one block of all pixels would
// robustify the frame, not the pixels).
#ifndef TACTFUNC_ESTIMATION_FITTING_INTERNAL_LATENT_COST_FUNCTIONS_H_
#define TACTFUNC_ESTIMATION_FITTING_INTERNAL_LATENT_COST_FUNCTIONS_H_

#include <memory>
#include <vector>

#include <Eigen/Core>

#include "ceres/cost_function.h"
#include "ceres/loss_function.h"
#include "estimation/data/trunk_targets.h"
#include "models/trunk/latent_modulated_siren.h"

namespace tactfunc {
namespace internal {

// The pixels one fit uses, whitened. Buffers: n = number of selected pixels, C channels.
struct LatentResidualData {
  Eigen::MatrixXd coords;         // n x 2, the trunk's coordinates of the pixels
  Eigen::MatrixXf coords_float;   // the same in float
  Eigen::MatrixXd targets;        // n x C
  Eigen::MatrixXf targets_float;  // n x C
  Eigen::VectorXf weights_float;  // n, w_j (for the meta-SGD steps, which use the trunk's
                                  // own weighted MSE)
  Eigen::VectorXd residual_scale; // n*C, s_j repeated for every channel of pixel j
  int channels = 1;
  int num_valid_pixels = 0;       // in the whole frame, before subsampling
  int num_pixels() const { return static_cast<int>(coords.rows()); }
  int num_residuals() const { return num_pixels() * channels; }
};

// Selects the valid pixels (w_j > 0) of `targets`, every `stride`-th of them, then at most
// `max_pixels` evenly spaced ones (0 = no limit), and whitens them with `sigma`.
// Throws std::invalid_argument, quoting shapes, if targets.values is not
// (rows*cols) x C for the trunk's C, weights do not have rows*cols entries, rows or cols
// < 1, a weight is negative or non-finite, or a valid pixel's value is not finite.
LatentResidualData SelectPixels(const LatentModulatedSiren& siren, const TrunkTargets& targets,
                                double sigma, int stride, int max_pixels);

// (b) The analytic batched data residuals. Both pointers must outlive the object.
template <typename Scalar>
class AnalyticLatentCost : public ceres::CostFunction {
 public:
  // One batched trunk pass per evaluation (the trunk blocks its passes internally).
  AnalyticLatentCost(const LatentModulatedSiren* siren, const LatentResidualData* data);
  // Returns false (Ceres then rejects the step) if a residual or Jacobian entry is not finite.
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  const LatentModulatedSiren* siren_;
  const LatentResidualData* data_;
  // The data's coords in Scalar, num_pixels x 2.
  LatentModulatedSiren::MatrixX<Scalar> coords_;
};

// (a) The autodiff reference. `stride` is the Jet width of DynamicAutoDiffCostFunction
// (one of 4, 8, 16, 32, 64): Ceres runs the functor ceil(d / stride) times per Jacobian.
// 0 = automatic: the smallest of them >= d (64 for d > 64), i.e. one pass when possible,
// which measured fastest for d = 64 (stride 64: 338 ms, 32: 392 ms, 16: 502 ms at 32x32,
// width 128; docs/FITTING.md).
std::unique_ptr<ceres::CostFunction> MakeAutoDiffLatentCost(const LatentModulatedSiren* siren,
                                                            const LatentResidualData* data,
                                                            int stride = 0);

// The prior residuals z / sigma_z (Jacobian I / sigma_z).
class LatentPriorCost : public ceres::CostFunction {
 public:
  LatentPriorCost(int latent_dim, double sigma_z);
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  double inverse_sigma_z_;
};

// Per-residual robustification of `inner` (not owned) by `loss` (not owned):
//   r'_i = sign(r_i) sqrt(rho(r_i^2)),   d r'_i / dz = rho'(r_i^2) |r_i| / sqrt(rho(r_i^2)) dr_i/dz
// so that 1/2 sum r'^2 = 1/2 sum rho(r_i^2), the robust cost, exactly, and Gauss-Newton
// runs on the transformed residuals (dr'/dr -> 1 as r -> 0).
class RobustifiedCost : public ceres::CostFunction {
 public:
  RobustifiedCost(const ceres::CostFunction* inner, const ceres::LossFunction* loss);
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  const ceres::CostFunction* inner_;
  const ceres::LossFunction* loss_;
};

// The trunk's weighted MSE over the data's pixels (LatentModulatedSiren::Loss: sum w r^2 /
// (C sum w)) and its gradient w.r.t. z, in Scalar. For the meta-SGD steps.
template <typename Scalar>
Scalar DataLossAndGradient(const LatentModulatedSiren& siren, const LatentResidualData& data,
                           const LatentModulatedSiren::VectorX<Scalar>& z,
                           LatentModulatedSiren::VectorX<Scalar>* dL_dz);

// 1/2 sum of squared residuals of `cost` at z (one parameter block); NaN if the
// evaluation fails.
double HalfSquaredNorm(const ceres::CostFunction& cost, const double* z);

}  // namespace internal
}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_FITTING_INTERNAL_LATENT_COST_FUNCTIONS_H_
