// Copyright 2026 The tactfunc Authors.
//
// Metropolis-Hastings samplers of a small d-dimensional log density log p(x) (known up to
// a constant, with its gradient), preconditioned by a fixed covariance Sigma = L L^T
// (L its Cholesky factor; typically a Laplace approximation's covariance):
//
//   MALA (Metropolis-adjusted Langevin, Roberts & Tweedie 1996):
//     x' = x + (eps^2 / 2) Sigma grad log p(x) + eps L xi,   xi ~ N(0, I),
//     q(x' | x) = N(x'; x + (eps^2 / 2) Sigma grad log p(x), eps^2 Sigma),
//     accepted with probability min(1, p(x') q(x | x') / (p(x) q(x' | x)));
//   RWM (random-walk Metropolis):
//     x' = x + eps L xi, symmetric, accepted with probability min(1, p(x') / p(x)).
//
// A log density of -inf (outside the support, e.g. a bound) rejects the proposal without
// anything else; a non-finite gradient rejects it too. Each iteration costs one call of
// the density at the proposal (with the gradient for MALA; the current point's is kept).
//
// Angles. Coordinates listed in Options::angles are wrapped to (-pi, pi] after every
// move. The proposal densities then are wrapped Gaussians; the MH ratio uses the
// differences x' - mean wrapped to (-pi, pi], i.e. the nearest copy only, which is exact
// up to the far copies' terms (< 1e-9 relative while eps L's angular standard deviation
// is below 0.5 rad).
//
// Step size. eps is adapted during the burn-in toward target_acceptance (0.574 for
// MALA, 0.234 for RWM: Roberts & Rosenthal 2001) by Robbins-Monro on log eps with the
// per-step acceptance probability alpha_t: log eps += (alpha_t - target) / (t + 1)^0.6;
// at the end of the burn-in it is frozen at exp(mean of log eps over the burn-in's
// second half), so the kept samples come from a fixed, valid kernel. Each chain adapts
// its own eps.
//
// Mode jumps. A multimodal density (a pose whose yaw is ambiguous between two faces of
// a tool) traps a local kernel in the mode it starts in. With Options::jumps (a Gaussian
// mixture q, typically the Laplace components at the modes an optimiser found), each
// iteration instead proposes, with probability jump_probability, an INDEPENDENT draw
// x' ~ q, accepted with min(1, p(x') q(x) / (p(x) q(x'))). Each of the two kernels
// leaves p invariant and the choice between them does not depend on the state, so the
// mixture kernel does too (Tierney 1994). q's angle coordinates are wrapped Gaussians;
// their density sums the copies shifted by 2 pi m, |m| <= 2 (exact to e^-30 for angular
// standard deviations up to pi / 2). Only local moves adapt eps and count in
// `acceptance`; jumps are counted apart. With jumps, chain c starts at component
// c mod K (plus jitter) instead of x0, so the chains start over-dispersed across modes.
//
// Chains. num_chains chains start at x0 + initial_jitter L xi_0 (over-dispersed starts
// for split R-hat) and run one after another; chain c draws all its randomness from
// boost::random::mt19937_64 seeded with DeriveSeed(seed, c) (models/core/seed.h), so the
// samples are a function of the seed alone.
//
// Diagnostics per coordinate over the kept samples: EffectiveSampleSize and SplitRhat
// of samplers/sgld.h. Angles enter them folded to within angle_fold / 2 of x0's angle
// (angle_fold = 2 pi / n for a density with n-fold symmetry in that angle), so a chain
// crossing the wrap or hopping to a symmetric copy does not count as unmixed.
//
// Errors: bad options, or a start / covariance of the wrong size, non-finite or not
// positive definite, throw std::invalid_argument. The density is called from one thread.
#ifndef TACTFUNC_SAMPLERS_METROPOLIS_H_
#define TACTFUNC_SAMPLERS_METROPOLIS_H_

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

namespace tactfunc {

// log p(x) + const; fills *gradient (size d) when it is not null. -inf outside the support.
using LogDensityFunction = std::function<double(const Eigen::VectorXd& x, Eigen::VectorXd* gradient)>;

enum class MetropolisKernel {
  kMala,        // Metropolis-adjusted Langevin
  kRandomWalk,  // random-walk Metropolis
};
// "mala", "rwm".
const char* ToString(MetropolisKernel kernel);
// Parses "mala" or "rwm"; false otherwise.
bool ParseMetropolisKernel(const std::string& name, MetropolisKernel* kernel);

// One Gaussian component of the mode-jump proposal (header comment).
struct JumpComponent {
  double weight = 1;         // > 0; the weights are normalised
  Eigen::VectorXd mean;      // size d
  Eigen::MatrixXd covariance;  // d x d, symmetric positive definite
};

struct MetropolisOptions {
  MetropolisKernel kernel = MetropolisKernel::kMala;
  int num_chains = 4;               // >= 1 (>= 2 for a meaningful R-hat)
  int burn_in = 200;                // adapted iterations per chain, discarded, >= 0
  int num_samples_per_chain = 300;  // kept iterations per chain, >= 4 (split diagnostics)
  // Initial eps, > 0; 0 = 1.0 (with Sigma the target's covariance the optimal eps is
  // about 2.38 / sqrt(d) for RWM and 1.65 d^(-1/6) for MALA: ~1.2 and ~1.3 at d = 4).
  double initial_step_size = 0;
  // In (0, 1); 0 = the kernel's optimum (header comment).
  double target_acceptance = 0;
  bool adapt = true;                // false: eps stays initial_step_size
  double initial_jitter = 1.0;      // start spread, in units of L, >= 0
  std::vector<int> angles;          // coordinates wrapped to (-pi, pi]
  double angle_fold = 2 * 3.14159265358979323846;  // > 0 (header comment)
  std::uint64_t seed = 0;
  // Mode-jump proposal (header comment): empty = none. At most 2 angle coordinates.
  std::vector<JumpComponent> jumps;
  double jump_probability = 0.1;  // in [0, 1), used only with jumps
  bool IsValid(int dim, std::string* error) const;
  double EffectiveTargetAcceptance() const;
};

struct MetropolisResult {
  MetropolisKernel kernel = MetropolisKernel::kMala;
  // Per chain: num_samples_per_chain x d kept states (angles wrapped to (-pi, pi]).
  std::vector<Eigen::MatrixXd> chains;
  std::vector<double> acceptance;   // per chain: accepted share of the kept local moves
  // Per chain, kept iterations: mode jumps proposed and accepted (0 without jumps).
  std::vector<int> jumps_proposed, jumps_accepted;
  std::vector<double> step_size;    // per chain: the frozen eps
  Eigen::VectorXd effective_sample_size;  // per coordinate, over all chains
  Eigen::VectorXd split_rhat;             // per coordinate
  long num_evaluations = 0;  // density calls (proposals outside the support included)
  double time_ms = 0;        // wall clock
  double MeanAcceptance() const;
  // Accepted share of all kept jump proposals (NaN when none was proposed).
  double JumpAcceptance() const;
  double MaxSplitRhat() const;
  // All kept samples, chain-major: (num_chains * num_samples_per_chain) x d.
  Eigen::MatrixXd Stacked() const;
};

// Samples log_density from x0 (size d) with the kernel of options, preconditioned by
// covariance (d x d, symmetric positive definite). Throws std::invalid_argument (header).
MetropolisResult SampleMetropolis(const LogDensityFunction& log_density, const Eigen::VectorXd& x0,
                                  const Eigen::MatrixXd& covariance,
                                  const MetropolisOptions& options);

}  // namespace tactfunc

#endif  // TACTFUNC_SAMPLERS_METROPOLIS_H_
