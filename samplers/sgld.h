// Copyright 2026 The tactfunc Authors.
//
// Sgld: Stochastic Gradient Langevin Dynamics over a frame's latent code (Sec. III-C of
// "Tactile Functasets"; Welling & Teh 2011). With the trunk f_theta frozen, the
// posterior of the latent z in R^d of one tactile frame is p(z | y) ~ exp(-U(z)), U the
// frame's LatentProblem (estimation/fitting/latent_problem.h: without a robust loss
//
//   U(z) = sum_j w_j ||f_theta(x_j; z) - y_j||^2 / (2 sigma^2) + ||z||^2 / (2 sigma_z^2)
//
// over its valid pixels j with weight w_j), whose mode is LatentFitter's MAP latent for the
// same problem. The chain
//
//   z_{t+1} = z_t - eta_t P grad U(z_t) + sqrt(2 eta_t) P^{1/2} xi_t,   xi_t ~ N(0, I)
//
// is the Euler-Maruyama discretisation of the Langevin diffusion whose stationary law is
// p(z | y). P = I is the paper's update (its Eq. 7); a FIXED preconditioner P (computed
// once, at the start) keeps the chain a valid discretisation of the preconditioned
// diffusion dz = -P grad U dt + sqrt(2 P) dW, which has the same stationary law:
//   kDiagonal  P = diag(H_GN(z0))^-1, the inverse Gauss-Newton diagonal of U at the start
//              (Li et al. 2016 adapt it per step; a fixed one needs no correction term);
//   kDense     P = H_GN(z0)^-1 (Cholesky), which makes eta dimensionless in EVERY
//              direction: for a Gaussian posterior each direction then contracts by
//              (1 - eta) per step, so eta ~ 0.3-0.5 mixes in a few steps.
// H_GN = J^T W J / sigma^2 + I / sigma_z^2 with J = d f / d z over the pixels
// (LatentProblem::GaussNewtonHessian).
// With P = I, eta is in latent^2 per nat of U; with a preconditioner it is dimensionless.
//
// Discretisation bias. With a constant eta the chain samples a slightly wrong law:
// for a Gaussian U = (z - m)^T Lambda (z - m) / 2 its mean is exact but its covariance
// S solves S = M S M^T + 2 eta P, M = I - eta P Lambda (so S = Lambda^-1 (1 - eta/2)^-1
// when P = Lambda^-1): O(eta) too wide. A decaying StepSizeSchedule removes it
// asymptotically; the Metropolis correction (MALA) is not part of SGLD.
//
// Chains. num_chains chains start at z0 (e.g. the Ceres or meta-SGD fit) plus optional
// jitter N(0, initial_jitter^2 P) and run independently, in parallel threads; chain c
// draws all its noise (jitter, xi, minibatches) from boost::random::mt19937_64 seeded
// with DeriveSeed(seed, c) (models/core/seed.h), so the samples do not depend on the thread
// count. Each chain takes burn_in + num_samples_per_chain * thinning steps and keeps
// every thinning-th state after the burn-in.
//
// Minibatches. With minibatch_size n > 0 (and n < N, the number of valid pixels), every
// step draws n of the N data terms without replacement and uses
//   grad U_hat = (N / n) sum_{j in batch} grad u_j + z / sigma_z^2,
// an unbiased estimate of grad U. Its extra covariance, eta^2 (N^2 / n)(1 - n / N) V_j
// per step (V_j the per-pixel gradient covariance), adds to the injected 2 eta P noise:
// the chain is approximately right only while eta N^2 V_j / n << 2 (Welling & Teh
// 2011, Sec. 4) -- small steps, or full batches. The per-sample U reported is then the
// minibatch estimate (N / n) sum_batch u_j + prior, unbiased but noisy.
//
// Control variate (Options::control_variate, on by default; Baker, Fearnhead, Fox and
// Nemeth 2019, "Control variates for stochastic gradient MCMC"). The plain estimate's
// noise does not shrink near the mode: V_j is the spread of the pixels' gradients, large
// even where their sum is zero. Anchored at z0 (the fit's mode), the estimate
//   grad U_hat(z) = grad U(z0) + (N / n) sum_{j in batch} (grad u_j(z) - grad u_j(z0))
// is still unbiased, exact at z0, and its V_j is the spread of grad u_j(z) - grad u_j(z0)
// ~ H_j (z - z0), which is small wherever the posterior puts its mass. In the dense
// preconditioner's metric, with a_j = H^-1/2 J_j^T / sigma (sum_j a_j a_j^T ~ I, so
// |a_j|^2 ~ d / N) and u = H^1/2 (z - z0) (|u|^2 ~ d), the extra variance per step and
// direction is about eta^2 N / n E[|a_j|^2 (a_j^T u)^2] ~ eta^2 d / n against the 2 eta
// injected: a relative widening of eta d / (2 n), 1% for eta = 0.3, d = 64, n = 1024.
// U_hat is anchored the same way. It costs one pass over every pixel at z0, shared by
// the chains (LatentPotential::DataTerms: each term's value and gradient from one latent
// Jacobian, which also gives the dense preconditioner's H_GN), and one minibatch pass
// per step; a potential without DataTerms pays a second minibatch pass at z0 instead.
//
// Diagnostics (over all chains that did not diverge, per latent dimension):
//   ESS    effective sample size of Vehtari et al. 2021 (Stan): the chains are split
//          in halves; rho_t = 1 - (W - mean_m acov_m(t)) / var+; Geyer's initial
//          positive sequence (pairs rho_2k + rho_2k+1 summed while positive, made
//          monotone); tau = -1 + 2 sum pairs; ESS = M N / tau.
//   R-hat  split R-hat (Gelman et al. 2013, BDA3 Sec. 11.4): the chains split in halves,
//          R = sqrt(var+ / W), var+ = (N - 1) / N W + B / N, B / N the variance of the
//          half-chain means, W the mean half-chain variance. ~1 when converged; > 1.01
//          (Vehtari) or > 1.1 (BDA3) says run longer. Not rank-normalised.
//
// Outcomes (tier 2 of docs/ARCHITECTURE.md, Conventions: never thrown): a chain whose state or U becomes non-finite,
// or whose U rises more than divergence_potential_increase * d above its start, has
// DIVERGED: it stops and its samples are dropped; the run ends kDiverged (samples from
// the other chains, possibly none). If the diffusion a run could achieve,
// sqrt(2 sum_t eta_t P_kk H_kk) conditional posterior standard deviations in some
// dimension k, is below min_diffusion, the step is too small for the chains to forget
// their start: kStepSizeTooSmall (samples returned, but they are not posterior draws).
// Bad options throw std::invalid_argument from the constructor; a z0 of the wrong
// size or non-finite throws std::invalid_argument from Sample.
//
// Thread safety: Sample is const; LatentPotential implementations must be safe to call
// concurrently (TrunkPotential is).
#ifndef TACTFUNC_SAMPLERS_SGLD_H_
#define TACTFUNC_SAMPLERS_SGLD_H_

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "estimation/fitting/latent_problem.h"
#include "samplers/step_size_schedule.h"

namespace tactfunc {

// ---- Potentials ------------------------------------------------------------------------

// U(z) = -log p(z | data) + const over a d-dimensional latent, for the samplers.
// Implementations must be safe to call concurrently (const, no mutable state).
class LatentPotential {
 public:
  virtual ~LatentPotential();
  // d, >= 1.
  virtual int dim() const = 0;
  // U(z) and, if gradient is not null, grad U(z) (size d).
  virtual double Evaluate(const Eigen::VectorXd& z, Eigen::VectorXd* gradient) const = 0;

  // Number N of data terms a minibatch subsamples (pixels); 0 = no minibatches.
  virtual int NumDataTerms() const { return 0; }
  // The unbiased minibatch estimate of U (and its gradient): data terms `indices`
  // (distinct, in [0, NumDataTerms())) scaled by N / n, plus the exact prior.
  // Default: Evaluate (no data terms to subsample).
  virtual double EvaluateMinibatch(const Eigen::VectorXd& z, const std::vector<int>& indices,
                                   Eigen::VectorXd* gradient) const {
    return Evaluate(z, gradient);
  }
  // The Gauss-Newton Hessian of U at z, d x d symmetric positive (semi)definite
  // (J^T W J / sigma^2 + I / sigma_z^2 for least squares; the exact Hessian for a
  // Gaussian). Returns false if this potential cannot provide it.
  virtual bool GaussNewtonHessian(const Eigen::VectorXd& z, Eigen::MatrixXd* hessian) const {
    return false;
  }
  // U(z) into *potential and the Gauss-Newton Hessian at z, for a potential that gets
  // both from one pass (its U then agrees with Evaluate's up to the last bits of the
  // trunk's float passes). Default: Evaluate, then GaussNewtonHessian.
  virtual bool PotentialAndGaussNewtonHessian(const Eigen::VectorXd& z, double* potential,
                                              Eigen::MatrixXd* hessian) const {
    *potential = Evaluate(z, nullptr);
    return GaussNewtonHessian(z, hessian);
  }
  // Its diagonal (size d). Default: the diagonal of GaussNewtonHessian.
  virtual bool GaussNewtonDiagonal(const Eigen::VectorXd& z, Eigen::VectorXd* diagonal) const;
  // Each data term at z: values u_j (size NumDataTerms()) and gradients (N x d, row j =
  // grad u_j), so that U = sum_j u_j + prior; and, if hessian is not null, the
  // Gauss-Newton Hessian from the same pass. Returns false if this potential cannot
  // provide them (the default); the control variate then evaluates each minibatch at
  // the anchor instead.
  virtual bool DataTerms(const Eigen::VectorXd& z, Eigen::VectorXd* values,
                         Eigen::MatrixXd* gradients, Eigen::MatrixXd* hessian) const {
    return false;
  }
};

// U(z) = (z - mean)^T precision (z - mean) / 2: a Gaussian N(mean, precision^-1), the
// reference the tests check the samplers against (and a linear-Gaussian stand-in).
class GaussianPotential : public LatentPotential {
 public:
  // precision: d x d symmetric positive definite. Throws std::invalid_argument if the
  // sizes disagree or the entries are not finite.
  GaussianPotential(Eigen::VectorXd mean, Eigen::MatrixXd precision);
  int dim() const override { return static_cast<int>(mean_.size()); }
  double Evaluate(const Eigen::VectorXd& z, Eigen::VectorXd* gradient) const override;
  bool GaussNewtonHessian(const Eigen::VectorXd& z, Eigen::MatrixXd* hessian) const override;
  const Eigen::VectorXd& mean() const { return mean_; }
  const Eigen::MatrixXd& precision() const { return precision_; }

 private:
  Eigen::VectorXd mean_;
  Eigen::MatrixXd precision_;
};

// The latent posterior of one frame under a frozen trunk: exp(-U) of its LatentProblem
// (estimation/fitting/latent_problem.h, where U, grad U and H_GN are defined). Minibatches
// draw from the problem's selected pixels.
class TrunkPotential : public LatentPotential {
 public:
  // `problem` must outlive the potential.
  explicit TrunkPotential(const LatentProblem& problem);

  int dim() const override;
  double Evaluate(const Eigen::VectorXd& z, Eigen::VectorXd* gradient) const override;
  int NumDataTerms() const override { return problem_->num_pixels(); }
  double EvaluateMinibatch(const Eigen::VectorXd& z, const std::vector<int>& indices,
                           Eigen::VectorXd* gradient) const override;
  bool GaussNewtonHessian(const Eigen::VectorXd& z, Eigen::MatrixXd* hessian) const override;
  bool DataTerms(const Eigen::VectorXd& z, Eigen::VectorXd* values, Eigen::MatrixXd* gradients,
                 Eigen::MatrixXd* hessian) const override;

  const LatentProblem& problem() const { return *problem_; }

 private:
  const LatentProblem* problem_;
};

// ---- Diagnostics -------------------------------------------------------------------

// Effective sample size of one scalar quantity over chains (each a series of draws,
// all of the same length >= 4), as defined in the header comment (Vehtari et al. 2021,
// split chains, Geyer's initial monotone sequence). In (0, M N log10(M N)] (Stan's
// cap). *max_lag (optional) receives the last autocorrelation lag summed, which sets
// the estimator's own variance (Sokal 1997: var(tau) ~ 2 (2 max_lag + 1) / (M N) tau^2).
// Returns NaN for chains shorter than 4 draws or of unequal lengths, and M N when every
// draw is identical.
double EffectiveSampleSize(const std::vector<Eigen::VectorXd>& chains, int* max_lag = nullptr);

// Split R-hat (header comment) over chains of equal length >= 4. NaN otherwise; 1 when
// every draw is identical.
double SplitRhat(const std::vector<Eigen::VectorXd>& chains);

// ---- The sampler ---------------------------------------------------------------------

enum class SgldTermination {
  kCompleted,          // every chain ran all its steps
  kDiverged,           // at least one chain diverged (dropped); see the message
  kStepSizeTooSmall,   // the chains cannot have moved far from their start
};
// "COMPLETED", "DIVERGED", "STEP_SIZE_TOO_SMALL".
const char* ToString(SgldTermination termination);

class Sgld {
 public:
  enum class Preconditioner {
    kNone,      // P = I (the paper's update)
    kDiagonal,  // P = diag(H_GN(z0))^-1
    kDense,     // P = H_GN(z0)^-1
  };

  struct Options {
    Options();  // sets step_size's defaults documented below
    // Chains run independently (in parallel). >= 1. 4: enough for split R-hat (8 halves)
    // while 4 x 25 = the paper's 100 samples (Sec. IV-C).
    int num_chains = 4;
    // Samples kept per chain after the burn-in. >= 1 (>= 2 for R-hat and ESS, which
    // need 4 draws per chain to split).
    int num_samples_per_chain = 25;
    // Steps discarded per chain before the first kept sample. >= 0. 20: with the dense
    // preconditioner and eta = 0.3 a Gaussian posterior forgets a start 1 posterior
    // standard deviation away by a factor (1 - 0.3)^20 ~ 1e-3.
    int burn_in = 20;
    // Keep every thinning-th state after the burn-in. >= 1.
    int thinning = 1;
    // eta_t (see samplers/step_size_schedule.h). Defaults set here: constant, 0.3 --
    // dimensionless with a preconditioner; the discretisation widens a Gaussian
    // posterior by (1 - eta / 2)^-1/2 = 8% in standard deviation at 0.3 (header
    // comment). With kNone it is in latent^2 per nat and must be set by the user.
    StepSizeSchedule::Options step_size;
    // See the header comment. kDense: needs GaussNewtonHessian (else falls back to
    // kNone, with a note in the Summary), costs one latent Jacobian at z0 plus a d x d
    // Cholesky. kDense is the default because the trunk's latent posterior is strongly
    // correlated (diagonal preconditioning leaves its condition number large).
    Preconditioner preconditioner = Preconditioner::kDense;
    // Standard deviation of the starting jitter N(0, initial_jitter^2 P) around z0, in
    // units of the preconditioned metric (conditional posterior standard deviations;
    // latent units with kNone). >= 0. 1: over-dispersed starts make R-hat meaningful.
    double initial_jitter = 1.0;
    // Data terms (pixels) per stochastic gradient, >= 0; 0, or >= N, = full batch. See
    // the header comment for the extra variance.
    int minibatch_size = 0;
    // With minibatches: anchor the estimate at z0 (header comment, "Control variate").
    // No effect on full batches.
    bool control_variate = true;
    // Seed of every chain's stream (DeriveSeed(seed, chain)).
    std::uint64_t seed = 0;
    // Threads running chains, >= 0; 0 = min(num_chains, hardware threads).
    int num_threads = 0;
    // A chain has diverged when U rises more than this many nats PER LATENT DIMENSION
    // above its starting value (or anything becomes non-finite). > 0. 1e3: at
    // equilibrium U - U_min ~ chi2_d / 2 ~ d / 2, so a rise of 1000 d is no fluctuation.
    double divergence_potential_increase = 1e3;
    // kStepSizeTooSmall below this many conditional posterior standard deviations of
    // achievable diffusion in the least-moved dimension. >= 0 (0 disables). 1: a chain
    // that cannot diffuse one standard deviation still remembers its start.
    double min_diffusion = 1.0;
    bool IsValid(std::string* error) const;
  };

  struct ChainSummary {
    bool diverged = false;
    int steps = 0;               // steps taken (fewer than planned if diverged)
    double initial_potential = 0;
    double final_potential = 0;  // U at the last finite state
    std::string message;         // why it diverged
  };

  struct Summary {
    SgldTermination termination_type = SgldTermination::kCompleted;
    std::string message;
    Preconditioner preconditioner = Preconditioner::kNone;  // the one used
    int num_chains = 0;
    int num_samples = 0;             // rows of the samples returned
    int dim = 0;
    long num_gradient_evaluations = 0;
    bool minibatched = false;
    bool control_variate = false;    // minibatch estimates anchored at z0
    int minibatch_size = 0;          // n used (N when full batch)
    int num_data_terms = 0;          // N
    double initial_step_size = 0, final_step_size = 0;
    double min_diffusion = 0;        // achieved bound, conditional std devs (NaN if unknown)
    std::vector<ChainSummary> chains;
    // Per latent dimension over the kept samples of the healthy chains (NaN if too few).
    Eigen::VectorXd effective_sample_size;
    Eigen::VectorXd split_rhat;
    double min_effective_sample_size = 0;
    double max_split_rhat = 0;
    double potential_at_start = 0;  // U(z0)
    double preconditioner_time_ms = 0;  // with the control variate's anchor pass
    double sampling_time_ms = 0;
    double total_time_ms = 0;
    // True unless kDiverged left no samples.
    bool IsSolutionUsable() const;
    std::string BriefReport() const;  // one line
    std::string FullReport() const;   // options used, per chain, diagnostics
  };

  // Throws std::invalid_argument (with IsValid's message) on bad options.
  explicit Sgld(const Options& options);
  const Options& options() const { return options_; }

  // Runs the chains from z0 (size potential.dim(), finite). *samples receives the kept
  // states, num_samples x d, chain-major (chain 0's samples in order, then chain 1's, ...
  // of the chains that did not diverge); *potentials (optional) U at each (num_samples).
  // Throws std::invalid_argument for a bad z0 or null samples.
  Summary Sample(const LatentPotential& potential, const Eigen::VectorXd& z0,
                 Eigen::MatrixXd* samples, Eigen::VectorXd* potentials = nullptr) const;

 private:
  Options options_;
};

const char* ToString(Sgld::Preconditioner preconditioner);  // "none", "diagonal", "dense"

}  // namespace tactfunc

#endif  // TACTFUNC_SAMPLERS_SGLD_H_
