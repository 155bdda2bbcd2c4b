// Copyright 2026 The tactfunc Authors.
#include "estimation/pose/pose_filter.h"

#include <algorithm>
#include <boost/random/normal_distribution.hpp>
#include <boost/random/uniform_01.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <stdexcept>
#include <utility>

#include "Eigen/Cholesky"
#include "Eigen/Eigenvalues"
#include "models/core/internal/checks.h"
#include "models/core/internal/elapsed.h"
#include "models/core/internal/log_sum_exp.h"
#include "models/core/seed.h"
#include "models/simulator/tool.h"

namespace tactfunc {
namespace {

using internal::Check;
using internal::kPi;
using internal::Num;
constexpr double kInf = std::numeric_limits<double>::infinity();

using internal::LogSumExp;

std::string MatrixText(const Eigen::Matrix3d& m) {
  std::string s = "[";
  for (int r = 0; r < 3; ++r) {
    for (int c = 0; c < 3; ++c) s += Num(m(r, c)) + (c < 2 ? " " : "");
    s += r < 2 ? "; " : "]";
  }
  return s;
}

// "" if `m` is a finite symmetric matrix whose eigenvalues are >= 0 (positive_definite:
// > 0), else what is wrong with it. Symmetry and the sign of the eigenvalues are judged
// relative to the largest entry, so that covariances in m^2 (~1e-8) are not flattered by
// an absolute tolerance.
std::string CovarianceProblem(const Eigen::Matrix3d& m, bool positive_definite) {
  if (!m.allFinite()) return "has non-finite entries: " + MatrixText(m);
  const double scale = m.cwiseAbs().maxCoeff();
  if ((m - m.transpose()).cwiseAbs().maxCoeff() > 1e-12 * scale) {
    return "is not symmetric: " + MatrixText(m);
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(m);
  const double smallest = eig.eigenvalues().minCoeff();
  if (positive_definite ? !(smallest > 1e-14 * scale) || scale == 0 : smallest < -1e-12 * scale) {
    return std::string("is not positive ") + (positive_definite ? "definite" : "semi-definite") +
           " (smallest eigenvalue " + Num(smallest) + "): " + MatrixText(m);
  }
  return "";
}

// The symmetric square root of a PSD matrix (negative rounding-level eigenvalues as 0).
Eigen::Matrix3d PsdSqrt(const Eigen::Matrix3d& m) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig(m);
  return eig.eigenvectors() * eig.eigenvalues().cwiseMax(0).cwiseSqrt().asDiagonal() *
         eig.eigenvectors().transpose();
}

// The representative of `particle` modulo the tool's symmetry closest to `sample`'s yaw
// (the symmetry axis is the object frame's origin: a yaw change only). n = 0: the
// sample's own yaw, so the residual's yaw is exactly 0.
SE2d Representative(const SE2d& particle, const SE2d& sample, int n) {
  if (n == 1) return particle;
  if (n == 0) return SE2d(sample.yaw(), particle.translation());
  return SE2d(FoldYawNear(particle.yaw(), sample.yaw(), n), particle.translation());
}

using Clock = std::chrono::steady_clock;
using internal::MsSince;

}  // namespace

namespace internal {
// SystematicResample with `num` pointers (u0 + k) / num instead of weights.size().
std::vector<int> SystematicDraw(const std::vector<double>& weights, int num, double u0);
}  // namespace internal

const char* ToString(PoseFilterUpdateType type) {
  switch (type) {
    case PoseFilterUpdateType::kInitialized:
      return "INITIALIZED";
    case PoseFilterUpdateType::kUpdated:
      return "UPDATED";
    case PoseFilterUpdateType::kRejected:
      return "REJECTED";
    case PoseFilterUpdateType::kReinitialized:
      return "REINITIALIZED";
  }
  return "UNKNOWN";
}

const char* ToString(PoseFilterKernelCovariance source) {
  switch (source) {
    case PoseFilterKernelCovariance::kWithinModes:
      return "within_modes";
    case PoseFilterKernelCovariance::kWhole:
      return "whole";
  }
  return "unknown";
}

// ---- Options and summaries ----------------------------------------------------------

bool SE2ParticleFilter::Options::IsValid(std::string* error) const {
  std::string message, problem;
  const std::string prefix = "SE2ParticleFilter::Options.";
  if (num_particles < 1) {
    message = prefix + "num_particles must be >= 1, got " + std::to_string(num_particles);
  } else if (symmetry_order < 0) {
    message = prefix + "symmetry_order must be >= 0 (1 = asymmetric, 0 = continuous), got " +
              std::to_string(symmetry_order);
  } else if (!(problem = CovarianceProblem(process_covariance, false)).empty()) {
    message = prefix + "process_covariance " + problem;
  } else if (!(problem = CovarianceProblem(velocity_process_covariance, false)).empty()) {
    message = prefix + "velocity_process_covariance " + problem;
  } else if (!(problem = CovarianceProblem(initial_velocity_covariance, false)).empty()) {
    message = prefix + "initial_velocity_covariance " + problem;
  } else if (kernel_covariance != PoseFilterKernelCovariance::kWithinModes &&
             kernel_covariance != PoseFilterKernelCovariance::kWhole) {
    message = prefix + "kernel_covariance is not a PoseFilterKernelCovariance";
  } else if (!modes.IsValid(&problem)) {
    message = prefix + "modes: " + problem;
  } else if (!(bandwidth_factor >= 0) || !std::isfinite(bandwidth_factor)) {
    message = prefix + "bandwidth_factor must be finite and >= 0 (0 = Silverman), got " +
              Num(bandwidth_factor);
  } else if (!(problem = CovarianceProblem(floor_covariance, true)).empty()) {
    message = prefix + "floor_covariance " + problem;
  } else if (!(resample_threshold >= 0 && resample_threshold <= 1)) {
    message = prefix + "resample_threshold must be in [0, 1], got " + Num(resample_threshold);
  } else if (!(gate_squared_mahalanobis > 0)) {
    message = prefix + "gate_squared_mahalanobis must be > 0 (+inf: never reject), got " +
              Num(gate_squared_mahalanobis);
  } else if (max_consecutive_rejections < 0) {
    message = prefix + "max_consecutive_rejections must be >= 0, got " +
              std::to_string(max_consecutive_rejections);
  } else if (!mean.IsValid(&problem)) {
    message = prefix + "mean: " + problem;
  }
  if (error != nullptr) *error = message;
  return message.empty();
}

std::string SE2ParticleFilter::UpdateSummary::BriefReport() const {
  char buffer[320];
  std::snprintf(buffer, sizeof(buffer),
                "Update: %s, ESS %.1f -> %.1f%s, log evidence %.4g, min d^2 %.3g, kernel sd "
                "%.3g mm %.3g mm %.3g deg (h %.3g, %d mode%s, %d samples), %.2f ms",
                ToString(type), ess_before_resampling, ess, resampled ? " (resampled)" : "",
                log_evidence, min_squared_mahalanobis, 1e3 * std::sqrt(kernel_covariance(0, 0)),
                1e3 * std::sqrt(kernel_covariance(1, 1)),
                180 / kPi * std::sqrt(kernel_covariance(2, 2)), bandwidth_factor, measurement_modes,
                measurement_modes == 1 ? "" : "s", measurement_samples, time_ms);
  return std::string(buffer) + (message.empty() ? "" : ": " + message);
}

std::string SE2ParticleFilter::Summary::BriefReport(int num_particles) const {
  char buffer[320];
  std::snprintf(buffer, sizeof(buffer),
                "SE2ParticleFilter: %d updates (%d initialisation%s, %d rejected, %d "
                "reinitialisation%s), %d predictions, %d resamples, ESS %.0f / %d (min %.0f "
                "before resampling), %.2f ms per update",
                num_updates, num_initializations, num_initializations == 1 ? "" : "s", num_rejected,
                num_reinitializations, num_reinitializations == 1 ? "" : "s", num_predictions,
                num_resamples, last_ess, num_particles,
                std::isfinite(min_ess_before_resampling) ? min_ess_before_resampling : 0.0,
                num_updates > 0 ? total_update_time_ms / num_updates : 0.0);
  return buffer;
}

// ---- The measurement kernel ---------------------------------------------------------

struct SE2ParticleFilter::Kernel {
  std::vector<SE2d> samples;          // folded by the symmetry order
  std::vector<SE2d> inverse_samples;  // s_j^-1
  std::vector<double> log_weights;    // log w_j; -inf for a zero weight
  std::vector<double> weights;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // K (yaw row/col 0 for n = 0)
  Eigen::Matrix3d sqrt = Eigen::Matrix3d::Zero();        // L, L L^T = K
  Eigen::Matrix3d whiten = Eigen::Matrix3d::Zero();      // L^-1 (yaw row/col 0 for n = 0)
  double log_normalizer = 0;                             // -log sqrt(det(2 pi K))
  double bandwidth = 0;
  int modes = 0;
};

SE2ParticleFilter::Kernel SE2ParticleFilter::MakeKernel(const PoseDistribution& measurement) const {
  Check(measurement.size() > 0,
        "SE2ParticleFilter: the measurement has no samples (expected a PoseDistribution with "
        "at least one; a moved-from one has none)");
  const int n = options_.symmetry_order;
  const PoseDistribution folded = n == 1 ? measurement : measurement.FoldedBySymmetry(n);
  const int dim = n == 0 ? 2 : 3;

  Kernel k;
  Eigen::Matrix3d sigma = Eigen::Matrix3d::Zero();
  if (options_.kernel_covariance == PoseFilterKernelCovariance::kWhole) {
    sigma = folded.Covariance(options_.mean);
    k.modes = 1;
  } else {
    const std::vector<PoseMode> modes = folded.Modes(options_.modes);
    for (const PoseMode& mode : modes) sigma += mode.weight * mode.covariance;
    k.modes = static_cast<int>(modes.size());
  }
  k.bandwidth = options_.bandwidth_factor > 0
                    ? options_.bandwidth_factor
                    : std::pow(4.0 / ((dim + 2) * folded.EffectiveSampleSize()), 1.0 / (dim + 4));
  k.covariance = k.bandwidth * k.bandwidth * sigma + options_.floor_covariance;
  k.covariance = 0.5 * (k.covariance + k.covariance.transpose()).eval();
  if (dim == 2) {
    k.covariance.row(2).setZero();
    k.covariance.col(2).setZero();
  }
  const Eigen::LLT<Eigen::MatrixXd> llt(k.covariance.topLeftCorner(dim, dim));
  Check(llt.info() == Eigen::Success && k.covariance.allFinite(),
        "SE2ParticleFilter: the measurement's kernel covariance is not positive definite: " +
            MatrixText(k.covariance));
  const Eigen::MatrixXd l = llt.matrixL();
  k.sqrt.topLeftCorner(dim, dim) = l;
  k.whiten.topLeftCorner(dim, dim) =
      l.triangularView<Eigen::Lower>().solve(Eigen::MatrixXd::Identity(dim, dim));
  k.log_normalizer = -0.5 * dim * std::log(2 * kPi) - l.diagonal().array().log().sum();

  k.samples = folded.samples();
  k.weights = folded.weights();
  k.inverse_samples.reserve(k.samples.size());
  k.log_weights.reserve(k.samples.size());
  for (std::size_t j = 0; j < k.samples.size(); ++j) {
    k.inverse_samples.push_back(k.samples[j].Inverse());
    k.log_weights.push_back(k.weights[j] > 0 ? std::log(k.weights[j]) : -kInf);
  }
  return k;
}

// ---- Construction and initialisation ------------------------------------------------

SE2ParticleFilter::SE2ParticleFilter(const Options& options)
    : options_(options), rng_(DeriveSeed(options.seed, 0)) {
  std::string error;
  Check(options_.IsValid(&error), error);
  process_sqrt_ = PsdSqrt(options_.process_covariance);
  velocity_process_sqrt_ = PsdSqrt(options_.velocity_process_covariance);
  initial_velocity_sqrt_ = PsdSqrt(options_.initial_velocity_covariance);
}

SE2ParticleFilter::SE2ParticleFilter() : SE2ParticleFilter(Options()) {}

void SE2ParticleFilter::Reset() {
  particles_.clear();
  log_weights_.clear();
  velocities_.clear();
  summary_ = Summary();
}

void SE2ParticleFilter::DrawVelocities() {
  velocities_.assign(particles_.size(), Eigen::Vector3d::Zero());
  if (!options_.constant_velocity) return;
  boost::random::normal_distribution<double> normal(0.0, 1.0);
  for (Eigen::Vector3d& v : velocities_) {
    const Eigen::Vector3d xi(normal(rng_), normal(rng_), normal(rng_));
    v = initial_velocity_sqrt_ * xi;
  }
}

void SE2ParticleFilter::Initialize(const SE2d& mean, const Eigen::Matrix3d& covariance) {
  Check(std::isfinite(mean.x()) && std::isfinite(mean.y()) && std::isfinite(mean.yaw()),
        "SE2ParticleFilter::Initialize: the mean must be finite, got x = " + Num(mean.x()) +
            ", y = " + Num(mean.y()) + ", yaw = " + Num(mean.yaw()));
  const std::string problem = CovarianceProblem(covariance, false);
  Check(problem.empty(), "SE2ParticleFilter::Initialize: the covariance " + problem);
  const Eigen::Matrix3d root = PsdSqrt(covariance);
  boost::random::normal_distribution<double> normal(0.0, 1.0);
  const int num = options_.num_particles;
  particles_.resize(num);
  for (SE2d& p : particles_) {
    const Eigen::Vector3d xi(normal(rng_), normal(rng_), normal(rng_));
    p = mean * SE2d::Exp(root * xi);
  }
  log_weights_.assign(num, -std::log(static_cast<double>(num)));
  DrawVelocities();
  ++summary_.num_initializations;
  summary_.consecutive_rejections = 0;
  summary_.last_ess = num;
}

void SE2ParticleFilter::InitializeFromKernel(const Kernel& kernel) {
  const int num = options_.num_particles;
  boost::random::uniform_01<double> uniform;
  const std::vector<int> index = internal::SystematicDraw(kernel.weights, num, uniform(rng_));
  boost::random::normal_distribution<double> normal(0.0, 1.0);
  particles_.resize(num);
  for (int k = 0; k < num; ++k) {
    const Eigen::Vector3d xi(normal(rng_), normal(rng_), normal(rng_));
    particles_[k] = kernel.samples[index[k]] * SE2d::Exp(kernel.sqrt * xi);
  }
  log_weights_.assign(num, -std::log(static_cast<double>(num)));
  DrawVelocities();
  summary_.consecutive_rejections = 0;
  summary_.last_ess = num;
}

void SE2ParticleFilter::Initialize(const PoseDistribution& measurement) {
  InitializeFromKernel(MakeKernel(measurement));
  ++summary_.num_initializations;
}

void SE2ParticleFilter::Initialize(std::vector<SE2d> particles, std::vector<double> weights) {
  Check(!particles.empty(),
        "SE2ParticleFilter::Initialize: expected at least one particle, got none");
  Check(weights.empty() || weights.size() == particles.size(),
        "SE2ParticleFilter::Initialize: expected 0 or " + std::to_string(particles.size()) +
            " weights (one per particle), got " + std::to_string(weights.size()));
  for (std::size_t i = 0; i < particles.size(); ++i) {
    const SE2d& p = particles[i];
    Check(std::isfinite(p.x()) && std::isfinite(p.y()) && std::isfinite(p.yaw()),
          "SE2ParticleFilter::Initialize: particle " + std::to_string(i) + " is not finite: x = " +
              Num(p.x()) + ", y = " + Num(p.y()) + ", yaw = " + Num(p.yaw()));
  }
  double total = 0;
  for (std::size_t i = 0; i < weights.size(); ++i) {
    Check(std::isfinite(weights[i]) && weights[i] >= 0,
          "SE2ParticleFilter::Initialize: weight " + std::to_string(i) +
              " must be finite and >= 0, got " + Num(weights[i]));
    total += weights[i];
  }
  Check(weights.empty() || total > 0,
        "SE2ParticleFilter::Initialize: the weights must not all be zero");
  const std::size_t num = particles.size();
  particles_ = std::move(particles);
  log_weights_.resize(num);
  for (std::size_t i = 0; i < num; ++i) {
    log_weights_[i] = weights.empty() ? -std::log(static_cast<double>(num))
                                      : (weights[i] > 0 ? std::log(weights[i] / total) : -kInf);
  }
  DrawVelocities();
  ++summary_.num_initializations;
  summary_.consecutive_rejections = 0;
  summary_.last_ess = EffectiveSampleSize();
}

// ---- Predict ------------------------------------------------------------------------

void SE2ParticleFilter::Predict(double dt) {
  Check(std::isfinite(dt) && dt >= 0,
        "SE2ParticleFilter::Predict: dt must be finite and >= 0 (frames), got " + Num(dt));
  ++summary_.num_predictions;
  if (dt == 0) return;
  const double root_dt = std::sqrt(dt);
  boost::random::normal_distribution<double> normal(0.0, 1.0);
  for (std::size_t i = 0; i < particles_.size(); ++i) {
    if (options_.constant_velocity) {
      const Eigen::Vector3d u(normal(rng_), normal(rng_), normal(rng_));
      velocities_[i] += root_dt * (velocity_process_sqrt_ * u);
    }
    const Eigen::Vector3d w(normal(rng_), normal(rng_), normal(rng_));
    particles_[i] = particles_[i] * SE2d::Exp(dt * velocities_[i] + root_dt * (process_sqrt_ * w));
  }
}

// ---- Update -------------------------------------------------------------------------

void SE2ParticleFilter::NormalizeLogWeights() {
  const double total = LogSumExp(log_weights_);
  for (double& l : log_weights_) l -= total;
}

void SE2ParticleFilter::ResampleIfNeeded(UpdateSummary* summary) {
  const int num = num_particles();
  summary->ess_before_resampling = EffectiveSampleSize();
  summary_.min_ess_before_resampling =
      std::min(summary_.min_ess_before_resampling, summary->ess_before_resampling);
  summary->resampled = summary->ess_before_resampling < options_.resample_threshold * num;
  if (summary->resampled) {
    boost::random::uniform_01<double> uniform;
    const std::vector<int> index = SystematicResample(weights(), uniform(rng_));
    std::vector<SE2d> particles(num);
    std::vector<Eigen::Vector3d> velocities(num);
    for (int k = 0; k < num; ++k) {
      particles[k] = particles_[index[k]];
      velocities[k] = velocities_[index[k]];
    }
    particles_ = std::move(particles);
    velocities_ = std::move(velocities);
    log_weights_.assign(num, -std::log(static_cast<double>(num)));
    ++summary_.num_resamples;
  }
  summary->ess = EffectiveSampleSize();
}

SE2ParticleFilter::UpdateSummary SE2ParticleFilter::Update(const PoseDistribution& measurement) {
  const Clock::time_point start = Clock::now();
  const Kernel kernel = MakeKernel(measurement);  // throws for an empty measurement
  UpdateSummary s;
  s.kernel_covariance = kernel.covariance;
  s.bandwidth_factor = kernel.bandwidth;
  s.measurement_modes = kernel.modes;
  s.measurement_samples = static_cast<int>(kernel.samples.size());
  ++summary_.num_updates;
  auto finish = [&]() {
    s.time_ms = MsSince(start);
    summary_.total_update_time_ms += s.time_ms;
    summary_.last_ess = s.ess;
    return s;
  };

  if (!initialized()) {
    InitializeFromKernel(kernel);
    ++summary_.num_initializations;
    s.type = PoseFilterUpdateType::kInitialized;
    s.message = "no particles yet: drawn from the measurement's kernel density";
    s.ess_before_resampling = s.ess = num_particles();
    return finish();
  }

  // log p(z | x_i) = log sum_j w_j N(r_ij; 0, K), the largest term factored out.
  const int num = num_particles();
  const int m = static_cast<int>(kernel.samples.size());
  const int n = options_.symmetry_order;
  std::vector<double> log_likelihood(num);
  std::vector<double> terms(m);
  double min_d2 = kInf;
  for (int i = 0; i < num; ++i) {
    const bool alive = std::isfinite(log_weights_[i]);
    for (int j = 0; j < m; ++j) {
      if (!std::isfinite(kernel.log_weights[j])) {
        terms[j] = -kInf;
        continue;
      }
      const SE2d x = Representative(particles_[i], kernel.samples[j], n);
      const Eigen::Vector3d r = (kernel.inverse_samples[j] * x).Log();
      double d2 = (kernel.whiten * r).squaredNorm();
      if (!std::isfinite(d2)) d2 = kInf;  // NaN-safe: an unusable pair counts as infinitely far
      if (alive) min_d2 = std::min(min_d2, d2);
      terms[j] = kernel.log_weights[j] - 0.5 * d2;
    }
    log_likelihood[i] = LogSumExp(terms) + kernel.log_normalizer;
  }
  s.min_squared_mahalanobis = min_d2;

  if (!(min_d2 <= options_.gate_squared_mahalanobis)) {
    char buffer[200];
    std::snprintf(buffer, sizeof(buffer),
                  "no particle within the gate (min d^2 = %.4g > %.4g) of any sample", min_d2,
                  options_.gate_squared_mahalanobis);
    s.message = buffer;
    s.log_evidence = -kInf;
    if (summary_.consecutive_rejections >= options_.max_consecutive_rejections) {
      InitializeFromKernel(kernel);
      ++summary_.num_reinitializations;
      s.type = PoseFilterUpdateType::kReinitialized;
      s.message += "; " + std::to_string(options_.max_consecutive_rejections) +
                   " rejected in a row before it: re-initialised from this measurement";
      s.log_evidence = 0;
      s.ess_before_resampling = s.ess = num;
    } else {
      ++summary_.consecutive_rejections;
      ++summary_.num_rejected;
      s.type = PoseFilterUpdateType::kRejected;
      s.message += ": prior weights kept";
      s.ess_before_resampling = s.ess = EffectiveSampleSize();
    }
    return finish();
  }

  summary_.consecutive_rejections = 0;
  std::vector<double> joint(num);
  for (int i = 0; i < num; ++i) joint[i] = log_weights_[i] + log_likelihood[i];
  s.log_evidence = LogSumExp(joint);  // the prior log-weights are normalised
  log_weights_ = std::move(joint);
  NormalizeLogWeights();
  s.type = PoseFilterUpdateType::kUpdated;
  ResampleIfNeeded(&s);
  return finish();
}

// ---- Estimates ----------------------------------------------------------------------

std::vector<double> SE2ParticleFilter::weights() const {
  std::vector<double> w(log_weights_.size());
  for (std::size_t i = 0; i < w.size(); ++i) w[i] = std::exp(log_weights_[i]);
  return w;
}

double SE2ParticleFilter::EffectiveSampleSize() const {
  if (log_weights_.empty()) return 0;
  double sum = 0, sum_sq = 0;
  for (double l : log_weights_) {
    const double w = std::exp(l);
    sum += w;
    sum_sq += w * w;
  }
  return sum * sum / sum_sq;
}

PoseDistribution SE2ParticleFilter::Posterior() const {
  if (!initialized()) {
    throw std::logic_error(
        "SE2ParticleFilter::Posterior: the filter has no particles yet "
        "(call Initialize() or Update() first)");
  }
  PoseDistribution d(particles_, weights());
  return options_.symmetry_order == 1 ? d : d.FoldedBySymmetry(options_.symmetry_order);
}

SE2ParticleFilter::Estimate SE2ParticleFilter::CurrentEstimate() const {
  if (!initialized()) {
    throw std::logic_error(
        "SE2ParticleFilter::CurrentEstimate: the filter has no particles "
        "yet (call Initialize() or Update() first)");
  }
  const PoseDistribution posterior = Posterior();
  Estimate e;
  e.mean = posterior.Mean(options_.mean, &e.mean_summary);
  e.covariance = posterior.CovarianceAbout(e.mean);
  e.effective_sample_size = EffectiveSampleSize();
  const std::vector<double> w = posterior.weights();
  for (std::size_t i = 0; i < velocities_.size(); ++i) e.mean_velocity += w[i] * velocities_[i];
  return e;
}

// ---- Systematic resampling ----------------------------------------------------------

namespace internal {

std::vector<int> SystematicDraw(const std::vector<double>& weights, int num, double u0) {
  Check(!weights.empty(), "SystematicResample: expected at least one weight, got none");
  Check(num >= 1, "SystematicResample: expected at least one draw, got " + std::to_string(num));
  Check(u0 >= 0 && u0 < 1, "SystematicResample: u0 must be in [0, 1), got " + Num(u0));
  double total = 0;
  for (std::size_t i = 0; i < weights.size(); ++i) {
    Check(std::isfinite(weights[i]) && weights[i] >= 0,
          "SystematicResample: weight " + std::to_string(i) + " must be finite and >= 0, got " +
              Num(weights[i]));
    total += weights[i];
  }
  Check(total > 0, "SystematicResample: the weights must not all be zero");
  // Pointers scaled by the actual total, so that rounding in the caller's normalisation
  // cannot push the last pointer past the end of the cumulative sum. `<=` so that a
  // zero weight is never chosen (a pointer on a boundary goes to the next positive one).
  const int m = static_cast<int>(weights.size());
  std::vector<int> index(num);
  double cumulative = weights[0];
  int j = 0;
  for (int k = 0; k < num; ++k) {
    const double pointer = (u0 + k) / num * total;
    while (cumulative <= pointer && j < m - 1) cumulative += weights[++j];
    int chosen = j;
    while (weights[chosen] == 0 && chosen > 0) --chosen;  // a trailing zero weight, by rounding
    index[k] = chosen;
  }
  return index;
}

}  // namespace internal

std::vector<int> SystematicResample(const std::vector<double>& weights, double u0) {
  return internal::SystematicDraw(weights, static_cast<int>(weights.size()), u0);
}

}  // namespace tactfunc
