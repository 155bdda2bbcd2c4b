// Copyright 2026 The tactfunc Authors.
//
// The Ceres cost functions of a LatentProblem (estimation/fitting/latent_problem.h, where
// U(z) is written out) seen as a least-squares problem over z: what LatentFitter solves,
// and what a caller adds to a Ceres problem of its own to estimate a latent jointly with
// other parameters,
//
//   data residuals   r'_{j,c}(z), the problem's (robustified) whitened residuals,
//                    residual j*C + c over the selected pixels
//   prior residuals  r_k(z) = z_k / sigma_z,  k = 0 .. d-1
//
// with the trunk frozen. The data residuals come in two interchangeable forms:
//   AnalyticLatentCost       LatentProblem::ResidualsAndJacobian: one batched forward pass
//                            and one reverse pass per output channel, in the problem's
//                            precision, accumulated by Ceres in double;
//   MakeAutoDiffLatentCost   the reference: ceres::DynamicAutoDiffCostFunction over the
//                            templated one-pixel LatentModulatedSiren::Evaluate<Jet>, in
//                            double, robustified by the same LatentProblem::Robustify.
// The robust loss acts on EACH residual of the batched block (Ceres itself applies a loss
// to a block's squared norm, which for one block of all pixels would robustify the frame,
// not the pixels), so no ceres::LossFunction is given to the Problem.
#ifndef TACTFUNC_ESTIMATION_FITTING_LATENT_COSTS_H_
#define TACTFUNC_ESTIMATION_FITTING_LATENT_COSTS_H_

#include <memory>

#include "ceres/cost_function.h"
#include "estimation/fitting/latent_problem.h"

namespace tactfunc {

// The analytic batched data residuals. `problem` must outlive the object.
class AnalyticLatentCost : public ceres::CostFunction {
 public:
  // With `start` (not owned; problem->CanUse(*start)), evaluations at exactly z = 0 come
  // from it without a trunk pass.
  explicit AnalyticLatentCost(const LatentProblem* problem, const StartPass* start = nullptr);
  // Returns false (Ceres then rejects the step) if a residual or Jacobian entry is not finite.
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

  // The trunk's outputs over the selected pixels (N x C) from the last Jacobian
  // evaluation's pass if it was at exactly z (d values), else null: the cost at a solver's
  // result (LatentProblem::DataCostOfOutputs) without a pass of its own. The record makes
  // one object serve one solve at a time.
  const Eigen::MatrixXd* OutputsAt(const double* z) const;

 private:
  const LatentProblem* problem_;
  const StartPass* start_;
  mutable Eigen::VectorXd last_z_;
  mutable Eigen::MatrixXd last_outputs_;
};

// The autodiff reference. `stride` is the Jet width of DynamicAutoDiffCostFunction
// (one of 4, 8, 16, 32, 64): Ceres runs the functor ceil(d / stride) times per Jacobian.
// 0 = automatic: the smallest of them >= d (64 for d > 64), i.e. one pass when possible,
// which measured fastest for d = 64 (stride 64: 338 ms, 32: 392 ms, 16: 502 ms at 32x32,
// width 128; docs/FITTING.md). `problem` must outlive the cost.
std::unique_ptr<ceres::CostFunction> MakeAutoDiffLatentCost(const LatentProblem* problem,
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

// 1/2 sum of squared residuals of `cost` at z (one parameter block); NaN if the
// evaluation fails.
double HalfSquaredNorm(const ceres::CostFunction& cost, const double* z);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_FITTING_LATENT_COSTS_H_
