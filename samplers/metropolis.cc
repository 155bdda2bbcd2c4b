// Copyright 2026 The tactfunc Authors.
#include "samplers/metropolis.h"

#include <chrono>
#include <cmath>
#include <algorithm>
#include <limits>
#include <memory>
#include <stdexcept>

#include <Eigen/Cholesky>
#include <boost/random/mersenne_twister.hpp>
#include <boost/random/normal_distribution.hpp>
#include <boost/random/uniform_01.hpp>

#include "models/core/internal/checks.h"
#include "models/core/internal/elapsed.h"
#include "models/core/internal/log_sum_exp.h"
#include "models/core/seed.h"
#include "samplers/sgld.h"

namespace tactfunc {
namespace {

using internal::kPi;

double WrapAngle(double a) {
  if (a > -kPi && a <= kPi) return a;
  a = std::remainder(a, 2 * kPi);  // in [-pi, pi]
  return a <= -kPi ? a + 2 * kPi : a;
}

// v wrapped to (-period / 2, period / 2] around centre.
double FoldNear(double v, double centre, double period) {
  return centre + period * std::remainder((v - centre) / period, 1.0);
}

struct State {
  Eigen::VectorXd x, gradient;
  double log_p = -std::numeric_limits<double>::infinity();
};

// The mode-jump proposal q: a mixture of Gaussians whose angle coordinates are wrapped
// (header comment).
class JumpMixture {
 public:
  JumpMixture(const std::vector<JumpComponent>& components, const std::vector<int>& angles)
      : angles_(angles) {
    double total = 0;
    for (const JumpComponent& c : components) total += c.weight;
    for (const JumpComponent& c : components) {
      Part part;
      part.mean = c.mean;
      part.L = Eigen::LLT<Eigen::MatrixXd>(0.5 * (c.covariance + c.covariance.transpose()))
                   .matrixL();
      part.log_weight = std::log(c.weight / total) - part.L.diagonal().array().log().sum();
      parts_.push_back(std::move(part));
      cumulative_.push_back((cumulative_.empty() ? 0.0 : cumulative_.back()) + c.weight / total);
    }
    // Every combination of copy shifts m in [-2, 2] over the angle coordinates.
    const int copies = angles_.empty() ? 1 : (angles_.size() == 1 ? 5 : 25);
    for (int i = 0; i < copies; ++i) {
      Eigen::VectorXd shift = Eigen::VectorXd::Zero(parts_.front().mean.size());
      int code = i;
      for (int a : angles_) {
        shift[a] = 2 * kPi * (code % 5 - 2);
        code /= 5;
      }
      shifts_.push_back(std::move(shift));
    }
  }
  int num_components() const { return static_cast<int>(parts_.size()); }
  const Eigen::VectorXd& mean(int k) const { return parts_[k].mean; }
  // Component index for a uniform draw u in [0, 1).
  int Pick(double u) const {
    for (std::size_t k = 0; k + 1 < cumulative_.size(); ++k) {
      if (u < cumulative_[k]) return static_cast<int>(k);
    }
    return num_components() - 1;
  }
  // mean_k + L_k xi (angles not yet wrapped).
  Eigen::VectorXd Draw(int k, const Eigen::VectorXd& xi) const {
    return parts_[k].mean + parts_[k].L * xi;
  }
  // log q(x) up to the constant -d/2 log(2 pi), which cancels in the MH ratio.
  double LogDensity(const Eigen::VectorXd& x) const {
    std::vector<double> terms;
    terms.reserve(parts_.size() * shifts_.size());
    for (const Part& part : parts_) {
      for (const Eigen::VectorXd& shift : shifts_) {
        const Eigen::VectorXd diff = x + shift - part.mean;
        terms.push_back(part.log_weight -
                        0.5 * part.L.triangularView<Eigen::Lower>().solve(diff).squaredNorm());
      }
    }
    return internal::LogSumExp(terms);
  }

 private:
  struct Part {
    Eigen::VectorXd mean;
    Eigen::MatrixXd L;
    double log_weight = 0;  // log normalised weight - log det L
  };
  std::vector<int> angles_;
  std::vector<Part> parts_;
  std::vector<double> cumulative_;
  std::vector<Eigen::VectorXd> shifts_;
};

}  // namespace

const char* ToString(MetropolisKernel kernel) {
  return kernel == MetropolisKernel::kMala ? "mala" : "rwm";
}

bool ParseMetropolisKernel(const std::string& name, MetropolisKernel* kernel) {
  if (name == "mala") {
    *kernel = MetropolisKernel::kMala;
  } else if (name == "rwm") {
    *kernel = MetropolisKernel::kRandomWalk;
  } else {
    return false;
  }
  return true;
}

bool MetropolisOptions::IsValid(int dim, std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error != nullptr) *error = "MetropolisOptions: " + m;
    return false;
  };
  if (num_chains < 1) return fail("num_chains must be >= 1");
  if (burn_in < 0) return fail("burn_in must be >= 0");
  if (num_samples_per_chain < 4) return fail("num_samples_per_chain must be >= 4");
  if (!(initial_step_size >= 0) || !std::isfinite(initial_step_size)) {
    return fail("initial_step_size must be finite and >= 0 (0 = 1.0)");
  }
  if (!(target_acceptance >= 0 && target_acceptance < 1)) {
    return fail("target_acceptance must be in (0, 1) (0 = the kernel's optimum)");
  }
  if (!(initial_jitter >= 0) || !std::isfinite(initial_jitter)) {
    return fail("initial_jitter must be finite and >= 0");
  }
  if (!(angle_fold > 0) || !std::isfinite(angle_fold)) return fail("angle_fold must be > 0");
  if (!jumps.empty()) {
    if (!(jump_probability >= 0 && jump_probability < 1)) {
      return fail("jump_probability must be in [0, 1)");
    }
    if (angles.size() > 2) return fail("mode jumps support at most 2 angle coordinates");
    for (std::size_t k = 0; k < jumps.size(); ++k) {
      const JumpComponent& c = jumps[k];
      const std::string name = "jump component " + std::to_string(k);
      if (!(c.weight > 0) || !std::isfinite(c.weight)) return fail(name + ": weight must be > 0");
      if (c.mean.size() != dim || !c.mean.allFinite()) {
        return fail(name + ": the mean must be finite with " + std::to_string(dim) + " entries");
      }
      if (c.covariance.rows() != dim || c.covariance.cols() != dim || !c.covariance.allFinite()) {
        return fail(name + ": the covariance must be finite and " + std::to_string(dim) + " x " +
                    std::to_string(dim));
      }
      if (Eigen::LLT<Eigen::MatrixXd>(0.5 * (c.covariance + c.covariance.transpose())).info() !=
          Eigen::Success) {
        return fail(name + ": the covariance is not positive definite");
      }
    }
  }
  for (int a : angles) {
    if (a < 0 || a >= dim) {
      return fail("angle coordinate " + std::to_string(a) + " is outside [0, " +
                  std::to_string(dim) + ")");
    }
  }
  return true;
}

double MetropolisOptions::EffectiveTargetAcceptance() const {
  if (target_acceptance > 0) return target_acceptance;
  return kernel == MetropolisKernel::kMala ? 0.574 : 0.234;
}

double MetropolisResult::MeanAcceptance() const {
  double sum = 0;
  for (double a : acceptance) sum += a;
  return acceptance.empty() ? 0 : sum / acceptance.size();
}

double MetropolisResult::JumpAcceptance() const {
  long proposed = 0, accepted = 0;
  for (int p : jumps_proposed) proposed += p;
  for (int a : jumps_accepted) accepted += a;
  return proposed == 0 ? std::numeric_limits<double>::quiet_NaN()
                       : static_cast<double>(accepted) / proposed;
}

double MetropolisResult::MaxSplitRhat() const {
  return split_rhat.size() == 0 ? std::numeric_limits<double>::quiet_NaN() : split_rhat.maxCoeff();
}

Eigen::MatrixXd MetropolisResult::Stacked() const {
  if (chains.empty()) return Eigen::MatrixXd();
  const Eigen::Index n = chains.front().rows();
  Eigen::MatrixXd all(n * static_cast<Eigen::Index>(chains.size()), chains.front().cols());
  for (std::size_t c = 0; c < chains.size(); ++c) all.middleRows(c * n, n) = chains[c];
  return all;
}

MetropolisResult SampleMetropolis(const LogDensityFunction& log_density, const Eigen::VectorXd& x0,
                                  const Eigen::MatrixXd& covariance,
                                  const MetropolisOptions& options) {
  const int d = static_cast<int>(x0.size());
  std::string error;
  if (!options.IsValid(d, &error)) throw std::invalid_argument(error);
  if (d < 1 || !x0.allFinite()) {
    throw std::invalid_argument("SampleMetropolis: the start must be non-empty and finite");
  }
  if (covariance.rows() != d || covariance.cols() != d || !covariance.allFinite()) {
    throw std::invalid_argument("SampleMetropolis: the covariance must be finite and " +
                                std::to_string(d) + " x " + std::to_string(d));
  }
  const Eigen::LLT<Eigen::MatrixXd> llt(0.5 * (covariance + covariance.transpose()));
  if (llt.info() != Eigen::Success) {
    throw std::invalid_argument("SampleMetropolis: the covariance is not positive definite");
  }
  const Eigen::MatrixXd L = llt.matrixL();
  const bool mala = options.kernel == MetropolisKernel::kMala;
  const double target = options.EffectiveTargetAcceptance();
  const auto t0 = std::chrono::steady_clock::now();

  MetropolisResult result;
  result.kernel = options.kernel;
  std::unique_ptr<JumpMixture> jumps;
  if (!options.jumps.empty()) jumps = std::make_unique<JumpMixture>(options.jumps, options.angles);
  auto wrap = [&](Eigen::VectorXd* x) {
    for (int a : options.angles) (*x)[a] = WrapAngle((*x)[a]);
  };
  auto evaluate = [&](State* s) {
    ++result.num_evaluations;
    s->gradient.setZero(d);
    s->log_p = log_density(s->x, mala ? &s->gradient : nullptr);
    if (std::isnan(s->log_p) || (mala && !s->gradient.allFinite())) {
      s->log_p = -std::numeric_limits<double>::infinity();
    }
  };
  // The MALA drift (eps^2 / 2) Sigma grad log p(x).
  auto drift = [&](const State& s, double eps) -> Eigen::VectorXd {
    if (!mala) return Eigen::VectorXd::Zero(d);
    return 0.5 * eps * eps * (L * (L.transpose() * s.gradient));
  };
  // log q(to | from) up to the constant shared by both directions.
  auto log_q = [&](const State& to, const State& from, double eps) {
    Eigen::VectorXd diff = to.x - from.x - drift(from, eps);
    for (int a : options.angles) diff[a] = WrapAngle(diff[a]);
    return -0.5 * L.triangularView<Eigen::Lower>().solve(diff).squaredNorm() / (eps * eps);
  };

  for (int c = 0; c < options.num_chains; ++c) {
    boost::random::mt19937_64 rng(DeriveSeed(options.seed, static_cast<std::uint64_t>(c)));
    boost::random::normal_distribution<double> normal(0.0, 1.0);
    boost::random::uniform_01<double> uniform;
    auto noise = [&]() {
      Eigen::VectorXd xi(d);
      for (int k = 0; k < d; ++k) xi[k] = normal(rng);
      return xi;
    };
    State current;
    // Over-dispersed start (chain c at jump component c mod K with jumps); a few redraws
    // if it lands outside the support, else x0.
    const Eigen::VectorXd centre = jumps ? jumps->mean(c % jumps->num_components()) : x0;
    for (int attempt = 0; attempt < 20; ++attempt) {
      current.x = centre + options.initial_jitter * (L * noise());
      wrap(&current.x);
      evaluate(&current);
      if (std::isfinite(current.log_p)) break;
    }
    if (!std::isfinite(current.log_p)) {
      current.x = x0;
      wrap(&current.x);
      evaluate(&current);
    }
    double log_eps = std::log(options.initial_step_size > 0 ? options.initial_step_size : 1.0);
    double log_eps_sum = 0;
    int log_eps_count = 0;
    Eigen::MatrixXd kept(options.num_samples_per_chain, d);
    int accepted = 0, local_moves = 0, jumps_proposed = 0, jumps_accepted = 0;
    const int total = options.burn_in + options.num_samples_per_chain;
    for (int t = 0; t < total; ++t) {
      // The kernel of this iteration is drawn first, independently of the state.
      if (jumps && options.jump_probability > 0 && uniform(rng) < options.jump_probability) {
        State proposal;
        proposal.x = jumps->Draw(jumps->Pick(uniform(rng)), noise());
        wrap(&proposal.x);
        evaluate(&proposal);
        double log_ratio = -std::numeric_limits<double>::infinity();
        if (std::isfinite(proposal.log_p)) {
          log_ratio = std::isfinite(current.log_p)
                          ? proposal.log_p - current.log_p + jumps->LogDensity(current.x) -
                                jumps->LogDensity(proposal.x)
                          : 0.0;
        }
        const bool accept = log_ratio >= 0 || uniform(rng) < std::exp(log_ratio);
        if (accept) current = std::move(proposal);
        if (t >= options.burn_in) {
          ++jumps_proposed;
          jumps_accepted += accept;
          kept.row(t - options.burn_in) = current.x.transpose();
        }
        continue;
      }
      const double eps = std::exp(log_eps);
      State proposal;
      proposal.x = current.x + drift(current, eps) + eps * (L * noise());
      wrap(&proposal.x);
      evaluate(&proposal);
      double log_ratio = -std::numeric_limits<double>::infinity();
      if (std::isfinite(proposal.log_p) && std::isfinite(current.log_p)) {
        log_ratio = proposal.log_p - current.log_p;
        if (mala) log_ratio += log_q(current, proposal, eps) - log_q(proposal, current, eps);
      } else if (std::isfinite(proposal.log_p)) {
        log_ratio = 0;  // a start outside the support: move to any point inside it
      }
      const double alpha = log_ratio >= 0 ? 1.0 : std::exp(log_ratio);
      const bool accept = uniform(rng) < alpha;
      if (accept) current = std::move(proposal);
      if (t < options.burn_in) {
        if (options.adapt) {
          log_eps += (alpha - target) / std::pow(t + 1.0, 0.6);
          if (2 * t >= options.burn_in) {
            log_eps_sum += log_eps;
            ++log_eps_count;
          }
          if (t + 1 == options.burn_in && log_eps_count > 0) log_eps = log_eps_sum / log_eps_count;
        }
      } else {
        accepted += accept;
        ++local_moves;
        kept.row(t - options.burn_in) = current.x.transpose();
      }
    }
    result.chains.push_back(std::move(kept));
    result.acceptance.push_back(local_moves == 0 ? 0.0 : static_cast<double>(accepted) / local_moves);
    result.jumps_proposed.push_back(jumps_proposed);
    result.jumps_accepted.push_back(jumps_accepted);
    result.step_size.push_back(std::exp(log_eps));
  }

  // Diagnostics, angles folded near x0's (header comment).
  result.effective_sample_size.resize(d);
  result.split_rhat.resize(d);
  for (int k = 0; k < d; ++k) {
    bool angle = false;
    for (int a : options.angles) angle = angle || a == k;
    std::vector<Eigen::VectorXd> series;
    for (const Eigen::MatrixXd& chain : result.chains) {
      Eigen::VectorXd s = chain.col(k);
      if (angle) {
        for (Eigen::Index i = 0; i < s.size(); ++i) s[i] = FoldNear(s[i], x0[k], options.angle_fold);
      }
      series.push_back(std::move(s));
    }
    result.effective_sample_size[k] = EffectiveSampleSize(series);
    result.split_rhat[k] = SplitRhat(series);
  }
  result.time_ms = internal::MsSince(t0);
  return result;
}

}  // namespace tactfunc
