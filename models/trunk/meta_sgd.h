// Copyright 2026 The tactfunc Authors.
//
// MetaSgd: the bi-level objective that meta-learns the SIREN trunk (Sec. III-B of
// "Tactile Functasets"; functa, Dupont et al. 2022, Sec. 3; Meta-SGD, Li et al. 2017).
//
// For one frame (coords, targets, weights) and the trunk theta, the inner loop fits
// the latent from zero with K steps of gradient descent with per-dimension rates
// alpha (the paper's Eq. 6 with a learned, per-coordinate eta):
//
//   z_0     = 0   (LatentModulatedSiren::StartLatent: the readout branch's projection
//                  for a trunk with that branch)
//   g_k     = d/dz [ L(theta, z_k) + lambda ||z_k||^2 ]
//   z_{k+1} = z_k - alpha (*) g_k                       ((*): element-wise)
//
// with L the weighted MSE of LatentModulatedSiren (see its header). The outer loss is
// L(theta, z_K) (no L2 term), and this class returns it with its EXACT gradient w.r.t.
// theta and alpha: the reverse pass runs back through the K steps, where each step
// needs the latent Hessian and the mixed Hessian applied to u = alpha (*) v:
//
//   v_K = dL/dz_K;   for k = K-1 .. 0:
//     dL/dalpha -= v_{k+1} (*) g_k
//     dL/dtheta -= d/dtheta (g_k . u_k),    u_k = alpha (*) v_{k+1}
//     v_k        = v_{k+1} - d/dz (g_k . u_k)
//
// Both products come from one LatentModulatedSiren::HessianProduct call (an R-operator
// pass) that reads the tape the inner step's LossAndGradient at z_k recorded (its
// forward pass and reverse pass, kept instead of repeated), so an exact meta-gradient
// costs K + 1 gradient passes and K tangent passes: per pixel and square hidden layer
// 6 K + 3 products of width^2 multiply-adds (2 per inner step, 3 for the outer gradient,
// 4 per Hessian-vector product), as reverse-mode autograd through the inner loop
// (docs/BENCHMARKS.md). The K tapes hold about K (3 L + 1) width N values for N pixels
// (L sine layers) until the call returns.
//
// first_order = true drops the Hessian terms (v_k = v_K, no d/dtheta of g_k), as
// first-order MAML does: cheaper (K + 1 gradient passes), biased.
#ifndef TACTFUNC_MODELS_TRUNK_META_SGD_H_
#define TACTFUNC_MODELS_TRUNK_META_SGD_H_

#include <string>

#include "Eigen/Core"
#include "models/trunk/latent_modulated_siren.h"

namespace tactfunc {

class MetaSgd {
 public:
  template <typename Scalar>
  using MatrixX = LatentModulatedSiren::MatrixX<Scalar>;
  template <typename Scalar>
  using VectorX = LatentModulatedSiren::VectorX<Scalar>;

  struct Options {
    // Inner gradient steps K from z = 0. >= 0. 3 in the paper and in functa.
    int inner_steps = 3;
    // lambda, weight of ||z||^2 in the inner loss (not in the outer loss). >= 0.
    // 0 in functa; small values keep latents from drifting during long fits.
    double latent_l2_weight = 0.0;
    // Drop the second-order terms (first-order MAML). Default: exact gradients.
    bool first_order = false;

    bool IsValid(std::string* error) const;
  };

  template <typename Scalar>
  struct Result {
    Scalar loss_at_zero = 0;    // L(theta, 0): the "initial image" error of Fig. 3
    Scalar loss = 0;            // outer loss L(theta, z_K)
    VectorX<Scalar> latent;     // z_K, size d
    VectorX<Scalar> dL_dtheta;  // size NumParameters(), the trunk's flat layout
    VectorX<Scalar> dL_dalpha;  // size d
  };

  // Throws std::invalid_argument if !options.IsValid().
  explicit MetaSgd(const Options& options);
  const Options& options() const { return options_; }

  // The outer loss of one frame and its gradient w.r.t. theta and alpha (exact unless
  // first_order). coords N x 2, targets N x C, weights N or empty, alpha size d
  // (per-dimension inner rates; any sign is accepted). The inner loop fits `targets`;
  // the outer loss compares z_K's output with `outer_targets` if given (N x C; e.g. the
  // frame's noise-free copy, so that the trunk and rates learn fits that do not follow
  // the noise), else with `targets`. Throws std::invalid_argument on wrong shapes.
  // Scalar = float or double.
  template <typename Scalar>
  Result<Scalar> OuterLossAndGradient(const LatentModulatedSiren& siren,
                                      const MatrixX<Scalar>& coords,
                                      const MatrixX<Scalar>& targets,
                                      const VectorX<Scalar>& weights,
                                      const VectorX<Scalar>& alpha,
                                      const MatrixX<Scalar>* outer_targets = nullptr) const;

  // Only z_K (the inner loop, as used to fit latents at test time), and optionally
  // the loss at z_K: InnerLoop from z = 0 with options().inner_steps steps.
  template <typename Scalar>
  VectorX<Scalar> FitLatent(const LatentModulatedSiren& siren,
                            const MatrixX<Scalar>& coords, const MatrixX<Scalar>& targets,
                            const VectorX<Scalar>& weights, const VectorX<Scalar>& alpha,
                            Scalar* loss = nullptr) const;

  // The inner loop's update z <- z - alpha (*) d/dz [L(theta, z) + lambda ||z||^2],
  // `steps` (>= 0) times from z0 (size d): the one implementation of the inner loop, also
  // used to continue a fit from any start (LatentProblem::MetaSgdSteps). If
  // outputs_at_start is not null it receives the trunk's outputs at z0 over coords (N x
  // C), from the first step's own forward pass (one forward pass when steps = 0). Throws
  // std::invalid_argument on wrong shapes.
  template <typename Scalar>
  VectorX<Scalar> InnerLoop(const LatentModulatedSiren& siren, const MatrixX<Scalar>& coords,
                            const MatrixX<Scalar>& targets, const VectorX<Scalar>& weights,
                            const VectorX<Scalar>& alpha, const VectorX<Scalar>& z0, int steps,
                            MatrixX<Scalar>* outputs_at_start = nullptr) const;

 private:
  Options options_;
};

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_TRUNK_META_SGD_H_
