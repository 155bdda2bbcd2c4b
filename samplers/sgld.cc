// Copyright 2026 The tactfunc Authors.
#include "samplers/sgld.h"

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <iomanip>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <thread>

#include <Eigen/Cholesky>
#include <boost/random/mersenne_twister.hpp>
#include <boost/random/normal_distribution.hpp>
#include <boost/random/uniform_int_distribution.hpp>

#include "models/core/internal/elapsed.h"
#include "models/core/parallel_for.h"
#include "models/core/seed.h"

namespace tactfunc {
namespace {

using internal::MsSince;

bool AllFinite(const Eigen::VectorXd& v) { return v.allFinite(); }

}  // namespace

// ---- LatentPotential ----------------------------------------------------------------

LatentPotential::~LatentPotential() = default;

bool LatentPotential::GaussNewtonDiagonal(const Eigen::VectorXd& z,
                                          Eigen::VectorXd* diagonal) const {
  Eigen::MatrixXd hessian;
  if (!GaussNewtonHessian(z, &hessian)) return false;
  *diagonal = hessian.diagonal();
  return true;
}

// ---- GaussianPotential --------------------------------------------------------------

GaussianPotential::GaussianPotential(Eigen::VectorXd mean, Eigen::MatrixXd precision)
    : mean_(std::move(mean)), precision_(std::move(precision)) {
  if (mean_.size() < 1 || precision_.rows() != mean_.size() ||
      precision_.cols() != mean_.size()) {
    throw std::invalid_argument("GaussianPotential: expected a mean of size d >= 1 and a d x d "
                                "precision, got mean " + std::to_string(mean_.size()) +
                                " and precision " + std::to_string(precision_.rows()) + " x " +
                                std::to_string(precision_.cols()));
  }
  if (!mean_.allFinite() || !precision_.allFinite()) {
    throw std::invalid_argument("GaussianPotential: mean and precision must be finite");
  }
}

double GaussianPotential::Evaluate(const Eigen::VectorXd& z, Eigen::VectorXd* gradient) const {
  const Eigen::VectorXd e = z - mean_;
  const Eigen::VectorXd g = precision_ * e;
  if (gradient != nullptr) *gradient = g;
  return 0.5 * e.dot(g);
}

bool GaussianPotential::GaussNewtonHessian(const Eigen::VectorXd& /*z*/,
                                           Eigen::MatrixXd* hessian) const {
  *hessian = precision_;
  return true;
}

// ---- TrunkPotential -------------------------------------------------------------------

TrunkPotential::TrunkPotential(const LatentProblem& problem) : problem_(&problem) {}

int TrunkPotential::dim() const { return problem_->dim(); }

double TrunkPotential::Evaluate(const Eigen::VectorXd& z, Eigen::VectorXd* gradient) const {
  return problem_->Evaluate(z, gradient);
}

double TrunkPotential::EvaluateMinibatch(const Eigen::VectorXd& z,
                                         const std::vector<int>& indices,
                                         Eigen::VectorXd* gradient) const {
  return problem_->EvaluateMinibatch(z, indices, gradient);
}

bool TrunkPotential::GaussNewtonHessian(const Eigen::VectorXd& z,
                                        Eigen::MatrixXd* hessian) const {
  problem_->GaussNewtonHessian(z, hessian);
  return true;
}

bool TrunkPotential::DataTerms(const Eigen::VectorXd& z, Eigen::VectorXd* values,
                               Eigen::MatrixXd* gradients, Eigen::MatrixXd* hessian) const {
  problem_->DataTerms(z, values, gradients, hessian);
  return true;
}

// ---- Diagnostics ---------------------------------------------------------------------

namespace {

// Each chain in halves of floor(n / 2) draws (the middle draw of an odd chain dropped).
// Empty if the chains are shorter than 4 or of unequal lengths.
std::vector<Eigen::VectorXd> SplitChains(const std::vector<Eigen::VectorXd>& chains) {
  std::vector<Eigen::VectorXd> halves;
  if (chains.empty()) return halves;
  const Eigen::Index n = chains[0].size();
  for (const auto& c : chains) {
    if (c.size() != n) return {};
  }
  if (n < 4) return {};
  const Eigen::Index h = n / 2;
  for (const auto& c : chains) {
    halves.push_back(c.head(h));
    halves.push_back(c.tail(h));
  }
  return halves;
}

double Variance(const Eigen::VectorXd& x) {  // unbiased
  const double mean = x.mean();
  return (x.array() - mean).square().sum() / static_cast<double>(x.size() - 1);
}

}  // namespace

double SplitRhat(const std::vector<Eigen::VectorXd>& chains) {
  const std::vector<Eigen::VectorXd> halves = SplitChains(chains);
  if (halves.empty()) return std::numeric_limits<double>::quiet_NaN();
  const int m = static_cast<int>(halves.size());
  const double n = static_cast<double>(halves[0].size());
  Eigen::VectorXd means(m), variances(m);
  for (int i = 0; i < m; ++i) {
    means[i] = halves[i].mean();
    variances[i] = Variance(halves[i]);
  }
  const double w = variances.mean();
  const double b_over_n = Variance(means);
  if (!(w > 0)) {
    return b_over_n > 0 ? std::numeric_limits<double>::infinity() : 1.0;
  }
  return std::sqrt(((n - 1) / n * w + b_over_n) / w);
}

// Follows Stan's compute_effective_sample_size (stan/analyze/mcmc), on split chains.
double EffectiveSampleSize(const std::vector<Eigen::VectorXd>& chains, int* max_lag) {
  if (max_lag != nullptr) *max_lag = 0;
  const std::vector<Eigen::VectorXd> halves = SplitChains(chains);
  if (halves.empty()) return std::numeric_limits<double>::quiet_NaN();
  const int m = static_cast<int>(halves.size());
  const long n = static_cast<long>(halves[0].size());
  std::vector<Eigen::VectorXd> centred(m);
  Eigen::VectorXd means(m);
  for (int i = 0; i < m; ++i) {
    means[i] = halves[i].mean();
    centred[i] = halves[i].array() - means[i];
  }
  // Mean over chains of the biased (1/N) autocovariance at `lag`.
  auto mean_acov = [&](long lag) {
    double sum = 0;
    for (int i = 0; i < m; ++i) {
      sum += centred[i].head(n - lag).dot(centred[i].tail(n - lag));
    }
    return sum / (static_cast<double>(n) * m);
  };
  const double total = static_cast<double>(m) * n;
  const double mean_var = mean_acov(0) * n / (n - 1.0);
  double var_plus = mean_var * (n - 1.0) / n;
  if (m > 1) var_plus += Variance(means);
  if (!(var_plus > 0)) return total;  // every draw identical
  auto rho = [&](long lag) { return 1.0 - (mean_var - mean_acov(lag)) / var_plus; };

  Eigen::VectorXd rho_s = Eigen::VectorXd::Zero(n + 2);
  double rho_even = 1.0;
  rho_s[0] = rho_even;
  double rho_odd = rho(1);
  rho_s[1] = rho_odd;
  // Geyer's initial positive sequence; the last pair is left as a bias term (Stan).
  long s = 1;
  while (s < n - 4 && rho_even + rho_odd > 0) {
    rho_even = rho(s + 1);
    rho_odd = rho(s + 2);
    if (rho_even + rho_odd >= 0) {
      rho_s[s + 1] = rho_even;
      rho_s[s + 2] = rho_odd;
    }
    s += 2;
  }
  const long max_s = s;
  if (rho_even > 0) rho_s[max_s + 1] = rho_even;
  // Initial monotone sequence.
  for (long t = 1; t <= max_s - 3; t += 2) {
    if (rho_s[t + 1] + rho_s[t + 2] > rho_s[t - 1] + rho_s[t]) {
      rho_s[t + 1] = (rho_s[t - 1] + rho_s[t]) / 2;
      rho_s[t + 2] = rho_s[t + 1];
    }
  }
  const double tau = -1.0 + 2.0 * rho_s.head(max_s).sum() + rho_s[max_s + 1];
  if (max_lag != nullptr) *max_lag = static_cast<int>(max_s);
  return std::min(total / tau, total * std::log10(total));
}

// ---- Sgld -------------------------------------------------------------------------------

Sgld::Options::Options() {
  step_size.type = StepSizeSchedule::Type::kConstant;
  step_size.initial = 0.3;
}

bool Sgld::Options::IsValid(std::string* error) const {
  std::ostringstream m;
  std::string schedule_error;
  if (num_chains < 1) {
    m << "Sgld::Options::num_chains must be >= 1, got " << num_chains;
  } else if (num_samples_per_chain < 1) {
    m << "Sgld::Options::num_samples_per_chain must be >= 1, got " << num_samples_per_chain;
  } else if (burn_in < 0) {
    m << "Sgld::Options::burn_in must be >= 0, got " << burn_in;
  } else if (thinning < 1) {
    m << "Sgld::Options::thinning must be >= 1, got " << thinning;
  } else if (!step_size.IsValid(&schedule_error)) {
    m << "Sgld::Options::step_size: " << schedule_error;
  } else if (!(initial_jitter >= 0) || !std::isfinite(initial_jitter)) {
    m << "Sgld::Options::initial_jitter must be finite and >= 0, got " << initial_jitter;
  } else if (minibatch_size < 0) {
    m << "Sgld::Options::minibatch_size must be >= 0, got " << minibatch_size;
  } else if (num_threads < 0) {
    m << "Sgld::Options::num_threads must be >= 0, got " << num_threads;
  } else if (!(divergence_potential_increase > 0) ||
             std::isnan(divergence_potential_increase)) {
    m << "Sgld::Options::divergence_potential_increase must be > 0, got "
      << divergence_potential_increase;
  } else if (!(min_diffusion >= 0) || !std::isfinite(min_diffusion)) {
    m << "Sgld::Options::min_diffusion must be finite and >= 0, got " << min_diffusion;
  } else {
    return true;
  }
  if (error != nullptr) *error = m.str();
  return false;
}

Sgld::Sgld(const Options& options) : options_(options) {
  std::string error;
  if (!options_.IsValid(&error)) throw std::invalid_argument(error);
}

const char* ToString(SgldTermination termination) {
  switch (termination) {
    case SgldTermination::kCompleted:
      return "COMPLETED";
    case SgldTermination::kDiverged:
      return "DIVERGED";
    case SgldTermination::kStepSizeTooSmall:
      return "STEP_SIZE_TOO_SMALL";
  }
  return "UNKNOWN";
}

const char* ToString(Sgld::Preconditioner preconditioner) {
  switch (preconditioner) {
    case Sgld::Preconditioner::kNone:
      return "none";
    case Sgld::Preconditioner::kDiagonal:
      return "diagonal";
    case Sgld::Preconditioner::kDense:
      return "dense";
  }
  return "unknown";
}

bool Sgld::Summary::IsSolutionUsable() const { return num_samples > 0; }

std::string Sgld::Summary::BriefReport() const {
  std::ostringstream s;
  s << "SGLD: " << ToString(termination_type) << ", " << num_samples << " samples from "
    << num_chains << " chains (d = " << dim << ", " << ToString(preconditioner)
    << " preconditioner, eta " << initial_step_size << "), min ESS " << std::setprecision(3)
    << min_effective_sample_size << ", max split R-hat " << max_split_rhat << ", "
    << num_gradient_evaluations << " gradients, " << total_time_ms << " ms";
  return s.str();
}

std::string Sgld::Summary::FullReport() const {
  std::ostringstream s;
  s << BriefReport() << "\n";
  if (!message.empty()) s << "  " << message << "\n";
  s << "  step size " << initial_step_size << " -> " << final_step_size
    << "; achievable diffusion " << min_diffusion << " conditional std devs (least dimension)\n";
  s << "  data terms " << num_data_terms << ", per gradient "
    << (minibatched ? std::to_string(minibatch_size) +
                          (control_variate ? " (control variate at z0)" : "")
                    : std::string("all"))
    << "\n";
  s << "  U(z0) = " << potential_at_start << "; time: preconditioner "
    << preconditioner_time_ms << " ms, sampling " << sampling_time_ms << " ms\n";
  for (size_t c = 0; c < chains.size(); ++c) {
    s << "  chain " << c << ": " << (chains[c].diverged ? "DIVERGED" : "ok") << ", "
      << chains[c].steps << " steps, U " << chains[c].initial_potential << " -> "
      << chains[c].final_potential;
    if (!chains[c].message.empty()) s << " (" << chains[c].message << ")";
    s << "\n";
  }
  return s.str();
}

namespace {

// The fixed preconditioner P and its square root C (C C^T = P).
struct Preconditioning {
  Sgld::Preconditioner type = Sgld::Preconditioner::kNone;
  Eigen::VectorXd diagonal;              // kDiagonal: P's diagonal
  Eigen::VectorXd sqrt_diagonal;         // kDiagonal
  Eigen::LLT<Eigen::MatrixXd> hessian;   // kDense: H = L L^T, P = H^-1, C = L^-T

  Eigen::VectorXd Apply(const Eigen::VectorXd& g) const {
    switch (type) {
      case Sgld::Preconditioner::kNone:
        return g;
      case Sgld::Preconditioner::kDiagonal:
        return diagonal.cwiseProduct(g);
      case Sgld::Preconditioner::kDense:
        return hessian.solve(g);
    }
    return g;
  }
  Eigen::VectorXd ApplySqrt(const Eigen::VectorXd& xi) const {
    switch (type) {
      case Sgld::Preconditioner::kNone:
        return xi;
      case Sgld::Preconditioner::kDiagonal:
        return sqrt_diagonal.cwiseProduct(xi);
      case Sgld::Preconditioner::kDense:
        return hessian.matrixU().solve(xi);
    }
    return xi;
  }
};

struct ChainResult {
  Sgld::ChainSummary summary;
  Eigen::MatrixXd samples;     // kept x d
  Eigen::VectorXd potentials;  // kept
  long gradients = 0;
};

}  // namespace

Sgld::Summary Sgld::Sample(const LatentPotential& potential, const Eigen::VectorXd& z0,
                           Eigen::MatrixXd* samples, Eigen::VectorXd* potentials) const {
  const auto start = std::chrono::steady_clock::now();
  const int d = potential.dim();
  if (samples == nullptr) throw std::invalid_argument("Sgld::Sample: samples must not be null");
  if (z0.size() != d || !z0.allFinite()) {
    throw std::invalid_argument("Sgld::Sample: expected a finite initial latent of size " +
                                std::to_string(d) + ", got size " + std::to_string(z0.size()) +
                                (z0.allFinite() ? "" : " with non-finite entries"));
  }
  Summary summary;
  summary.dim = d;
  summary.num_chains = options_.num_chains;
  const StepSizeSchedule schedule(options_.step_size);
  const long num_steps =
      static_cast<long>(options_.burn_in) +
      static_cast<long>(options_.num_samples_per_chain) * options_.thinning;
  summary.initial_step_size = schedule(0);
  summary.final_step_size = schedule(num_steps - 1);
  const int num_data = potential.NumDataTerms();
  summary.num_data_terms = num_data;
  summary.minibatched = options_.minibatch_size > 0 && options_.minibatch_size < num_data;
  summary.minibatch_size = summary.minibatched ? options_.minibatch_size : num_data;
  summary.control_variate = summary.minibatched && options_.control_variate;
  std::string notes;
  const auto precondition_start = std::chrono::steady_clock::now();
  // The control variate's anchor at z0: every data term's value and gradient (then
  // also H_GN for the dense preconditioner), or, from a potential without DataTerms, U
  // and grad U, each minibatch then evaluated at z0 too.
  bool anchor_terms = false;
  double anchor_sum = 0;                   // sum_j u_j(z0), or U(z0)
  Eigen::VectorXd anchor_values;           // u_j(z0)
  Eigen::MatrixXd anchor_gradients_t;      // d x N, column j = grad u_j(z0)
  Eigen::VectorXd anchor_gradient;         // sum_j grad u_j(z0), or grad U(z0)
  Eigen::MatrixXd anchor_hessian;          // H_GN(z0) from the same pass
  if (summary.control_variate) {
    Eigen::MatrixXd gradients;
    anchor_terms = potential.DataTerms(
        z0, &anchor_values, &gradients,
        options_.preconditioner == Preconditioner::kDense ? &anchor_hessian : nullptr);
    anchor_terms = anchor_terms && anchor_values.size() == num_data &&
                   gradients.rows() == num_data && gradients.cols() == d;
    if (anchor_terms) {
      anchor_gradients_t = gradients.transpose();
      anchor_gradient = anchor_gradients_t.rowwise().sum();
      anchor_sum = anchor_values.sum();
    } else {
      anchor_hessian.resize(0, 0);
      anchor_sum = potential.Evaluate(z0, &anchor_gradient);
    }
  }

  // The fixed preconditioner, and the Gauss-Newton diagonal for the step-size check.
  Preconditioning pre;
  Eigen::VectorXd gn_diagonal;
  bool have_diagonal = false;
  if (options_.preconditioner == Preconditioner::kDense) {
    Eigen::MatrixXd hessian = std::move(anchor_hessian);
    const bool have_hessian =
        hessian.rows() == d || potential.GaussNewtonHessian(z0, &hessian);
    if (have_hessian && hessian.allFinite()) {
      gn_diagonal = hessian.diagonal();
      have_diagonal = true;
      pre.hessian.compute(hessian);
      if (pre.hessian.info() == Eigen::Success) {
        pre.type = Preconditioner::kDense;
      } else {
        notes += "the Gauss-Newton Hessian at z0 is not positive definite; ";
      }
    } else {
      notes += "the potential gives no finite Gauss-Newton Hessian; ";
    }
  }
  if (!have_diagonal && (options_.preconditioner != Preconditioner::kNone ||
                         options_.min_diffusion > 0)) {
    have_diagonal = potential.GaussNewtonDiagonal(z0, &gn_diagonal) && gn_diagonal.allFinite();
  }
  if (options_.preconditioner != Preconditioner::kNone && pre.type == Preconditioner::kNone) {
    if (have_diagonal && (gn_diagonal.array() > 0).all()) {
      pre.type = Preconditioner::kDiagonal;
      pre.diagonal = gn_diagonal.cwiseInverse();
      pre.sqrt_diagonal = pre.diagonal.cwiseSqrt();
    } else {
      notes += "no positive Gauss-Newton diagonal at z0 either; ";
    }
    if (pre.type != options_.preconditioner) {
      notes += std::string("preconditioner ") + ToString(options_.preconditioner) +
               " fell back to " + ToString(pre.type) + ". ";
    }
  }
  summary.preconditioner = pre.type;
  // Diffusion over the run in conditional posterior standard deviations 1/sqrt(H_kk).
  summary.min_diffusion = std::numeric_limits<double>::quiet_NaN();
  if (have_diagonal && (gn_diagonal.array() > 0).all()) {
    double sum_eta = 0;
    for (long t = 0; t < num_steps; ++t) sum_eta += schedule(t);
    Eigen::VectorXd p_kk;
    switch (pre.type) {
      case Preconditioner::kNone:
        p_kk = Eigen::VectorXd::Ones(d);
        break;
      case Preconditioner::kDiagonal:
        p_kk = pre.diagonal;
        break;
      case Preconditioner::kDense:
        p_kk = pre.hessian.solve(Eigen::MatrixXd::Identity(d, d)).diagonal();
        break;
    }
    summary.min_diffusion =
        std::sqrt(2.0 * sum_eta * p_kk.cwiseProduct(gn_diagonal).minCoeff());
  }
  summary.preconditioner_time_ms = MsSince(precondition_start);

  // The chains.
  const auto sampling_start = std::chrono::steady_clock::now();
  std::vector<ChainResult> results(options_.num_chains);
  const double max_rise = options_.divergence_potential_increase * d;
  auto run_chain = [&](int c) {
    ChainResult& r = results[c];
    boost::random::mt19937_64 rng(DeriveSeed(options_.seed, static_cast<std::uint64_t>(c)));
    boost::random::normal_distribution<double> normal(0.0, 1.0);
    auto draw = [&]() {
      Eigen::VectorXd xi(d);
      for (int k = 0; k < d; ++k) xi[k] = normal(rng);
      return xi;
    };
    std::vector<int> permutation, batch;
    if (summary.minibatched) {
      permutation.resize(num_data);
      for (int i = 0; i < num_data; ++i) permutation[i] = i;
      batch.resize(options_.minibatch_size);
    }
    auto evaluate = [&](const Eigen::VectorXd& z, Eigen::VectorXd* g) {
      ++r.gradients;
      if (!summary.minibatched) return potential.Evaluate(z, g);
      // Partial Fisher-Yates: n distinct terms, sorted for memory locality.
      for (int i = 0; i < options_.minibatch_size; ++i) {
        boost::random::uniform_int_distribution<int> pick(i, num_data - 1);
        std::swap(permutation[i], permutation[pick(rng)]);
      }
      std::copy(permutation.begin(), permutation.begin() + options_.minibatch_size,
                batch.begin());
      std::sort(batch.begin(), batch.end());
      const double u = potential.EvaluateMinibatch(z, batch, g);
      if (!summary.control_variate) return u;
      // U_hat(z) = U(z0) + [minibatch estimate at z - the same at z0]; the prior's
      // part cancels when the anchor comes as data terms.
      if (anchor_terms) {
        const double scale = static_cast<double>(num_data) / options_.minibatch_size;
        double batch_sum = 0;
        for (int j : batch) batch_sum += anchor_values[j];
        if (g != nullptr) {
          Eigen::VectorXd at_anchor = Eigen::VectorXd::Zero(d);
          for (int j : batch) at_anchor += anchor_gradients_t.col(j);
          *g += anchor_gradient - scale * at_anchor;
        }
        return u + anchor_sum - scale * batch_sum;
      }
      Eigen::VectorXd g_at_anchor;
      const double u_at_anchor =
          potential.EvaluateMinibatch(z0, batch, g != nullptr ? &g_at_anchor : nullptr);
      if (g != nullptr) *g += anchor_gradient - g_at_anchor;
      return anchor_sum + (u - u_at_anchor);
    };
    Eigen::VectorXd z = z0;
    if (options_.initial_jitter > 0) z += options_.initial_jitter * pre.ApplySqrt(draw());
    r.samples.resize(options_.num_samples_per_chain, d);
    r.potentials.resize(options_.num_samples_per_chain);
    int kept = 0;
    Eigen::VectorXd gradient;
    double u_start = 0;
    for (long s = 0;; ++s) {
      const double u = evaluate(z, &gradient);
      if (s == 0) {
        u_start = u;
        r.summary.initial_potential = u;
      }
      if (!std::isfinite(u) || !AllFinite(gradient) || !AllFinite(z)) {
        r.summary.diverged = true;
        r.summary.message = "non-finite potential or gradient after " + std::to_string(s) +
                            " steps";
        break;
      }
      if (u - u_start > max_rise) {
        std::ostringstream m;
        m << "U rose from " << u_start << " to " << u << " after " << s
          << " steps (limit: +" << max_rise << ")";
        r.summary.diverged = true;
        r.summary.message = m.str();
        break;
      }
      r.summary.final_potential = u;
      r.summary.steps = static_cast<int>(s);
      if (s > options_.burn_in && (s - options_.burn_in) % options_.thinning == 0) {
        r.samples.row(kept) = z.transpose();
        r.potentials[kept] = u;
        ++kept;
      }
      if (s == num_steps) break;
      const double eta = schedule(s);
      z += -eta * pre.Apply(gradient) + std::sqrt(2.0 * eta) * pre.ApplySqrt(draw());
    }
  };
  int num_threads = options_.num_threads;
  if (num_threads == 0) {
    num_threads = std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
  }
  num_threads = std::min(num_threads, options_.num_chains);
  internal::ParallelFor(options_.num_chains, num_threads, run_chain);
  summary.sampling_time_ms = MsSince(sampling_start);

  // Gather the healthy chains, then the diagnostics.
  std::vector<int> healthy;
  std::ostringstream diverged;
  for (int c = 0; c < options_.num_chains; ++c) {
    summary.chains.push_back(results[c].summary);
    summary.num_gradient_evaluations += results[c].gradients;
    if (results[c].summary.diverged) {
      diverged << " chain " << c << ": " << results[c].summary.message << ";";
    } else {
      healthy.push_back(c);
    }
  }
  summary.potential_at_start = summary.control_variate && !anchor_terms
                                  ? anchor_sum
                                  : potential.Evaluate(z0, nullptr);
  const int per_chain = options_.num_samples_per_chain;
  summary.num_samples = static_cast<int>(healthy.size()) * per_chain;
  samples->resize(summary.num_samples, d);
  if (potentials != nullptr) potentials->resize(summary.num_samples);
  for (size_t i = 0; i < healthy.size(); ++i) {
    samples->middleRows(i * per_chain, per_chain) = results[healthy[i]].samples;
    if (potentials != nullptr) {
      potentials->segment(i * per_chain, per_chain) = results[healthy[i]].potentials;
    }
  }
  summary.effective_sample_size.setConstant(d, std::numeric_limits<double>::quiet_NaN());
  summary.split_rhat.setConstant(d, std::numeric_limits<double>::quiet_NaN());
  if (!healthy.empty() && per_chain >= 4) {
    std::vector<Eigen::VectorXd> series(healthy.size());
    for (int k = 0; k < d; ++k) {
      for (size_t i = 0; i < healthy.size(); ++i) series[i] = results[healthy[i]].samples.col(k);
      summary.effective_sample_size[k] = EffectiveSampleSize(series);
      summary.split_rhat[k] = SplitRhat(series);
    }
    summary.min_effective_sample_size = summary.effective_sample_size.minCoeff();
    summary.max_split_rhat = summary.split_rhat.maxCoeff();
  } else {
    summary.min_effective_sample_size = std::numeric_limits<double>::quiet_NaN();
    summary.max_split_rhat = std::numeric_limits<double>::quiet_NaN();
  }

  std::ostringstream message;
  if (!healthy.empty() && healthy.size() < results.size()) {
    summary.termination_type = SgldTermination::kDiverged;
    message << (results.size() - healthy.size()) << " of " << results.size()
            << " chains diverged and were dropped (reduce step_size.initial):" << diverged.str();
  } else if (healthy.empty()) {
    summary.termination_type = SgldTermination::kDiverged;
    message << "every chain diverged, no samples (reduce step_size.initial):" << diverged.str();
  } else if (options_.min_diffusion > 0 && summary.min_diffusion < options_.min_diffusion) {
    summary.termination_type = SgldTermination::kStepSizeTooSmall;
    message << "step size too small: over " << num_steps << " steps the chains can diffuse only "
            << summary.min_diffusion
            << " conditional posterior standard deviations in the least-moved dimension (need "
            << options_.min_diffusion
            << "); the samples still remember z0. Increase step_size.initial or the steps.";
  } else {
    summary.termination_type = SgldTermination::kCompleted;
    message << "all " << results.size() << " chains ran " << num_steps << " steps";
  }
  if (!notes.empty()) message << " Note: " << notes;
  summary.message = message.str();
  summary.total_time_ms = MsSince(start);
  return summary;
}

}  // namespace tactfunc
