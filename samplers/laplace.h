// Copyright 2026 The tactfunc Authors.
//
// LaplaceSampler: the Laplace approximation of a frame's latent posterior -- the fast
// end of the speed/accuracy trade of docs/SAMPLERS.md. Around the mode z* of a frame's
// U(z) (its LatentProblem, estimation/fitting/latent_problem.h) the posterior is
// approximated by the Gaussian
//   p(z | y) ~ N(z*, Sigma),   Sigma = H^-1,   H = H_GN(z*) = J^T W J / sigma^2 + I / sigma_z^2
// (without a robust loss), with J = d f / d z (N*C x d, the trunk's analytic latent
// Jacobian) at z*: the Gauss-Newton Hessian of U, exact for a model linear in z (then the
// approximation is the exact posterior). Samples z_i = z* + L^-T xi_i, xi_i ~ N(0, I) (Boost.Random
// mt19937_64, normal_distribution) with H = P^T L D L^T P from Eigen's LDLT -- so
// Cov(z_i) = H^-1 without forming the inverse -- in fact z_i = z* + P^T L^-T D^-1/2 xi.
// The mode is given (any fit), or found by a LatentFitter (a Ceres strategy: the
// Laplace approximation is only meaningful at a true mode, not after K meta-SGD steps).
//
// Near-singular H (tier 2, never thrown): H is positive definite in exact arithmetic
// (the prior adds I / sigma_z^2), but a huge sigma_z with directions the pixels do not
// constrain, or overflow, can make it numerically singular. If the smallest LDLT pivot
// is below min_relative_pivot times the largest (condition number above ~1 /
// min_relative_pivot), or any pivot is not positive and finite, the Summary reports
// kIllConditioned / kNotPositiveDefinite and no samples are drawn.
//
// Thread safety: Sample is const and may run concurrently.
#ifndef TACTFUNC_SAMPLERS_LAPLACE_H_
#define TACTFUNC_SAMPLERS_LAPLACE_H_

#include <chrono>
#include <cstdint>
#include <string>

#include <Eigen/Core>

#include "estimation/fitting/latent_fitter.h"
#include "samplers/sgld.h"

namespace tactfunc {

enum class LaplaceTermination {
  kSuccess,               // samples drawn from N(mode, H^-1)
  kIllConditioned,        // smallest / largest LDLT pivot below min_relative_pivot
  kNotPositiveDefinite,   // a pivot <= 0 or not finite (or no Gauss-Newton Hessian)
  kFitFailed,             // the LatentFitter found no usable mode
};
// "SUCCESS", "ILL_CONDITIONED", "NOT_POSITIVE_DEFINITE", "FIT_FAILED".
const char* ToString(LaplaceTermination termination);

class LaplaceSampler {
 public:
  struct Options {
    // Samples drawn. >= 1. 100: the paper's N (Sec. IV-C).
    int num_samples = 100;
    // Seed of the normal draws (mt19937_64).
    std::uint64_t seed = 0;
    // Smallest acceptable ratio of the smallest to the largest LDLT pivot, in (0, 1).
    // 1e-12: below it the inverse loses all digits a double has beyond ~4.
    double min_relative_pivot = 1e-12;
    bool IsValid(std::string* error) const;
  };

  struct Summary {
    LaplaceTermination termination_type = LaplaceTermination::kNotPositiveDefinite;
    std::string message;
    // The LatentFitter's summary when Sample ran a fit (fit_ran), else default.
    bool fit_ran = false;
    LatentFitter::Summary fit_summary;
    int num_samples = 0;
    int dim = 0;
    Eigen::VectorXd mode;        // z*
    Eigen::MatrixXd covariance;  // H^-1, d x d (empty unless kSuccess)
    double potential_at_mode = 0;       // U(z*)
    double log_det_covariance = 0;      // log det H^-1
    double min_relative_pivot = 0;      // smallest / largest LDLT pivot
    double fit_time_ms = 0;
    double hessian_time_ms = 0;         // Jacobian and J^T J (and U(z*) with them)
    double factor_time_ms = 0;          // LDLT, inverse
    double sample_time_ms = 0;
    double total_time_ms = 0;
    bool IsSolutionUsable() const { return termination_type == LaplaceTermination::kSuccess; }
    std::string BriefReport() const;
    std::string FullReport() const;
  };

  // Throws std::invalid_argument (IsValid's message) for bad options.
  explicit LaplaceSampler(const Options& options);
  const Options& options() const { return options_; }

  // Samples from N(mode, H(mode)^-1): *samples num_samples x d (0 x d unless kSuccess).
  // Throws std::invalid_argument for a null samples, or a mode of the wrong size or
  // not finite.
  Summary Sample(const LatentPotential& potential, const Eigen::VectorXd& mode,
                 Eigen::MatrixXd* samples) const;
  // The same where U(mode) and H_GN(mode) are already known -- a LatentFitter::Summary's
  // final_cost and gauss_newton_hessian -- without a pass over the pixels (then
  // hessian_time_ms is 0). Throws std::invalid_argument for a null samples, a Hessian
  // that is not square and non-empty, or a mode of another size or not finite.
  Summary SampleWithHessian(const Eigen::VectorXd& mode, double potential_at_mode,
                            const Eigen::MatrixXd& hessian, Eigen::MatrixXd* samples) const;
  // At the result `mode` of a fit whose summary is `fit`: SampleWithHessian with the fit's
  // final cost and Gauss-Newton Hessian when it formed one, else Sample(potential, ...).
  Summary SampleAtFit(const LatentPotential& potential, const LatentFitter::Summary& fit,
                      const Eigen::VectorXd& mode, Eigen::MatrixXd* samples) const;
  // The same for a frame's LatentProblem at the mode `fitter` finds for it (so the
  // Gaussian is centred at U's mode by construction), with the fit's H_GN when it has one.
  Summary Sample(const LatentProblem& problem, const LatentFitter& fitter,
                 Eigen::MatrixXd* samples) const;

 private:
  // Factors `hessian` and draws; `summary` carries dim, mode and potential_at_mode.
  Summary FromHessian(std::chrono::steady_clock::time_point start,
                      const Eigen::MatrixXd& hessian, Summary summary,
                      Eigen::MatrixXd* samples) const;

  Options options_;
};

}  // namespace tactfunc

#endif  // TACTFUNC_SAMPLERS_LAPLACE_H_
