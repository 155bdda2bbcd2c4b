// Copyright 2026 The tactfunc Authors.
//
// LatentFitter: inference over a tactile functaset (Sec. III-C of "Tactile Functasets"):
// with the meta-learned trunk f_theta frozen, find the latent z of a new frame: the mode
// z* = argmin_z U(z) of the frame's LatentProblem (estimation/fitting/latent_problem.h,
// where U, its pixels, sigma, sigma_z and the robust loss are defined once; docs/FITTING.md
// writes it out), i.e. the MAP latent under Gaussian pixel noise (the paper's Eq. 5 plus a
// prior). Ceres solves it with Levenberg-Marquardt (or dogleg) over the d-dimensional z,
// with the whole Jacobian (N*C x d) from ONE batched pass per channel
// (estimation/fitting/latent_costs.h); a ceres::Jet autodiff version is the reference.
//
// Strategies (FitStrategy; strings as the CLI takes them):
//   meta_sgd:K      K steps of the trunk's meta-SGD inner loop (LatentProblem::MetaSgdSteps,
//                   models/trunk/meta_sgd.h), the paper's Eq. 6 with the learned
//                   per-dimension rates alpha, from the problem's StartLatent (z = 0,
//                   or a readout branch's projection) or the warm start. K = the
//                   trunk's inner_steps is what it was trained for. It descends the
//                   trunk's own weighted MSE (+ its latent_l2_weight), not U.
//   ceres:N         at most N Ceres iterations from the StartLatent (or the warm start).
//   knn             the paper's k-NN estimate: z = sum_i w_i z_i over the k nearest
//                   functaset latents z_i of a query latent, w_i proportional to
//                   1 / ||q - z_i|| (normalised; an exact match takes all the weight).
//                   The query is the warm start if one is given, else the meta-SGD latent
//                   after the trunk's K steps: a frame must be mapped into latent space
//                   before latents can be compared, and K meta-SGD steps are the cheapest
//                   map the trunk was trained to make good (about 3 gradient passes).
//   knn+meta_sgd:K, knn+ceres:N
//                   the same refinements started from the k-NN estimate (the paper's
//                   "initialize z_new close to known solutions").
//   adam:N, knn+adam:N
//                   the photometric trunk's fits (not LatentFitter's: FitPhotometricLatent,
//                   estimation/training/photometric_trainer.h): N Adam steps per start from
//                   the contact's moment pose and its turn by pi, or from the best of the
//                   trunk's warm-start table's neighbours
//                   (estimation/training/photometric_warm_start.h); knn alone takes that
//                   neighbour's latent as it is, and knn+ceres:N refines it by at most N
//                   Levenberg-Marquardt iterations on every valid pixel
//                   (FitPhotometricLatentCeres, estimation/fitting/photometric_ceres_fit.h).
//
// Errors (docs/ARCHITECTURE.md, three tiers): a bad Options, or a knn strategy without an
// index, throws std::invalid_argument from the constructor; a problem of another latent
// size, or a warm start of the wrong size or not finite, throws std::invalid_argument from
// Fit (bad targets already threw from LatentProblem's constructor); everything that can
// happen while fitting (no valid pixel, the solver failing, a step producing NaN) comes back
// in the Summary's termination type and message -- Fit never returns a NaN latent.
//
// A ceres strategy without knn or warm start begins at z = 0, where the trunk's outputs and
// latent Jacobian do not depend on the frame: the fitter computes them once per frame size
// (StartPass, estimation/fitting/latent_problem.h) and every such fit takes its start's
// cost and first Jacobian from them, with no trunk pass.
//
// Thread safety: Fit is const and may run concurrently on one LatentFitter.
#ifndef TACTFUNC_ESTIMATION_FITTING_LATENT_FITTER_H_
#define TACTFUNC_ESTIMATION_FITTING_LATENT_FITTER_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "ceres/solver.h"
#include "estimation/fitting/latent_problem.h"
#include "estimation/knn/knn_index.h"
#include "models/trunk/functa_model.h"

namespace tactfunc {

// What a fit does; see the header comment. Parsed from and printed as
// "knn", "meta_sgd:K", "ceres:N", "knn+meta_sgd:K", "knn+ceres:N", "adam:N", "knn+adam:N".
struct FitStrategy {
  enum class Refinement {
    kNone,     // knn alone
    kMetaSgd,  // K meta-SGD steps
    kCeres,    // at most N Ceres iterations
    kAdam,     // N Adam steps per start: the photometric trunk's fit
               // (FitPhotometricLatent, estimation/training/photometric_trainer.h)
  };
  bool knn = false;
  Refinement refinement = Refinement::kCeres;
  // K (meta_sgd, >= 0) or N (ceres, adam, >= 1); unused for kNone.
  int steps = 20;

  // Parses `text`; on failure returns false and sets *error to a message that quotes the
  // text and lists the accepted forms.
  static bool Parse(const std::string& text, FitStrategy* strategy, std::string* error);
  // Parse that throws std::invalid_argument with that message.
  static FitStrategy FromString(const std::string& text);
  std::string ToString() const;
  bool IsValid(std::string* error) const;
};

// How a fit ended.
enum class FitTermination {
  kCompleted,      // a fixed-step strategy (knn, meta_sgd:K) ran all its steps
  kConvergence,    // Ceres met a tolerance (function, gradient or parameter)
  kNoConvergence,  // Ceres used its N iterations; the latent is the best it found
  kNoValidPixels,  // no pixel with weight > 0: the latent is the prior mean, 0
  kFailure,        // numerical failure (non-finite step, linear solver); the latent is
                   // the last finite estimate (see the message)
};
// "COMPLETED", "CONVERGENCE", "NO_CONVERGENCE", "NO_VALID_PIXELS", "FAILURE".
const char* ToString(FitTermination termination);

class LatentFitter {
 public:
  enum class JacobianMode { kAnalytic, kAutoDiff };
  // How the ceres stage hands U to Ceres (estimation/fitting/latent_costs.h,
  // estimation/fitting/square_root_cost.h).
  enum class ResidualForm {
    kSquareRoot,  // one block of d + 1 residuals, U's square-root information form: the
                  // same steps as kPerPixel up to rounding, without Ceres forming the
                  // normal equations of N C rows (the default; about 1.7x faster fits
                  // on the 70x88 Soft Bubble, docs/FITTING.md)
    kPerPixel,    // the N C data residuals and the d prior residuals as two blocks
  };

  struct Options {
    Options();  // sets the solver_options defaults documented below

    // The strategy; see the header comment. Default ceres:10: needs no functaset, and LM
    // converged in 5-7 iterations on the 70x88 measurement frames (docs/FITTING.md).
    FitStrategy strategy;
    // Data-term Jacobian: analytic (batched, the default) or ceres::Jet autodiff (the
    // reference; 60-150x slower than analytic at d = 64, for checks).
    JacobianMode jacobian = JacobianMode::kAnalytic;
    // kSquareRoot applies with the analytic Jacobian; the autodiff reference, and
    // solver_options.check_gradients (which differentiates the residual vector, defined
    // per pixel only), always use kPerPixel.
    ResidualForm residual_form = ResidualForm::kSquareRoot;
    // k of the knn strategies, >= 1. 8: the paper does not give k; 8 neighbours average
    // out the query's error while staying in one cluster of a 30,000-frame functaset.
    int knn_k = 8;
    // Passed to ceres::Solve, except max_num_iterations (set from ceres:N). Defaults set
    // here: LEVENBERG_MARQUARDT (trust_region_strategy_type = DOGLEG for dogleg),
    // DENSE_NORMAL_CHOLESKY (one d-dimensional block; faster than DENSE_QR, docs/BUILD.md),
    // num_threads 1 (parallelise over frames), logging SILENT, function_tolerance 1e-6,
    // gradient_tolerance 1e-10, parameter_tolerance 1e-8 (Ceres' defaults).
    ceres::Solver::Options solver_options;

    // True if every field is valid (including solver_options.IsValid); otherwise false
    // and *error names the field.
    bool IsValid(std::string* error) const;
  };

  // One stage of a fit, in order: "start", then "knn", "meta_sgd", "ceres" as run.
  struct Stage {
    std::string name;
    double cost = 0;     // the objective (Summary::final_cost's definition) after it
    double time_ms = 0;
    int iterations = 0;  // meta-SGD steps or Ceres iterations
  };

  struct Summary {
    FitStrategy strategy;
    FitTermination termination_type = FitTermination::kFailure;
    std::string message;
    // The Ceres summary of the ceres stage (ceres_ran = false: default-constructed).
    bool ceres_ran = false;
    ceres::Solver::Summary solver_summary;
    // The form Ceres saw U in (kSquareRoot: its d + 1 residuals are solver_summary's).
    ResidualForm ceres_residual_form = ResidualForm::kPerPixel;
    // H_GN at the returned latent (d x d; LatentProblem::GaussNewtonHessian's matrix,
    // accumulated in double from the problem's Jacobian) when the fit formed it anyway:
    // a ceres stage in square-root form whose last Jacobian evaluation was at the
    // result. Empty otherwise. A Laplace approximation at the result takes it as it is
    // (samplers/laplace.h) instead of a Jacobian pass of its own.
    Eigen::MatrixXd gauss_newton_hessian;
    std::vector<Stage> stages;
    // The objective U(z) = 1/2 sum rho(r^2) + 1/2 ||z / sigma_z||^2 over the selected
    // pixels (LatentProblem), at the starting latent (0 or the warm start) and at the
    // result. Finite unless the warm start itself overflowed.
    double initial_cost = 0;
    double final_cost = 0;
    // PSNR (estimation/data/trunk_targets.h, THE definition) in dB of f_theta(.; z) over all
    // valid pixels of the frame (evaluated in the problem's precision). +inf for an exact fit; 0 when
    // the frame has no valid pixel.
    double psnr = 0;
    int iterations = 0;  // meta-SGD steps + Ceres iterations
    double total_time_ms = 0;
    int num_valid_pixels = 0;  // in the frame
    int num_pixels_used = 0;   // after subsampling
    int num_residuals = 0;     // data residuals (pixels x channels) + d prior residuals
    double sigma = 0;          // the problem's sigma (after the automatic choice)
    double sigma_z = 0;
    // The knn stage's neighbours (labels, squared distances, weights), nearest first.
    std::vector<std::int64_t> neighbor_labels;
    std::vector<float> neighbor_squared_distances;
    std::vector<double> neighbor_weights;

    // True unless kFailure or kNoValidPixels.
    bool IsSolutionUsable() const;
    // One line: strategy, termination, cost before -> after, PSNR, iterations, time.
    std::string BriefReport() const;
    // Several lines: the options used, every stage, and Ceres' FullReport (its timings).
    std::string FullReport() const;
  };

  // `trunk` must outlive the fitter and not change while it lives (the fitter keeps its
  // passes at z = 0). Throws std::invalid_argument if !options.IsValid or
  // the strategy needs k-NN (use the other constructor).
  LatentFitter(const SensorTrunk& trunk, const Options& options);
  // For knn strategies: `index` over the functaset latents (dim() == latent_dim) and
  // `latents` (M x d, M == index->size(); label i -> row i). Both must outlive the fitter.
  // Throws std::invalid_argument quoting the shapes if they disagree.
  LatentFitter(const SensorTrunk& trunk, const Options& options, const KnnIndex* index,
               const Eigen::MatrixXf* latents);

  const Options& options() const { return options_; }

  // Fits the latent of one frame: the mode of `problem` (whose latent size must be the
  // fitter's trunk's). *latent receives z (size d, always finite).
  Summary Fit(const LatentProblem& problem, Eigen::VectorXd* latent) const;
  // The same from a warm start (size d, finite): ceres/meta_sgd start there; knn
  // strategies use it as the query.
  Summary Fit(const LatentProblem& problem, const Eigen::VectorXd& initial_latent,
              Eigen::VectorXd* latent) const;

  // The trunk's pass at z = 0 over the problem's frame size that a fit of `problem` from
  // z = 0 takes its start from (made on first use, kept for a few sizes), or null if
  // such a fit cannot use one (another trunk, double precision, the autodiff Jacobian, a
  // frame too large to keep its Jacobian). E.g. for timing a fit's steps as it runs them.
  const StartPass* StartPassFor(const LatentProblem& problem) const;

 private:
  Summary FitImpl(const LatentProblem& problem, const Eigen::VectorXd* initial,
                  Eigen::VectorXd* latent) const;

  struct StartPasses;  // the cache behind StartPassFor, shared by copies of the fitter
  std::shared_ptr<StartPasses> start_passes_;
  const SensorTrunk* trunk_;
  Options options_;
  const KnnIndex* index_ = nullptr;
  const Eigen::MatrixXf* latents_ = nullptr;
};

const char* ToString(LatentFitter::JacobianMode jacobian);  // "analytic", "autodiff"

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_FITTING_LATENT_FITTER_H_
