// Copyright 2026 The tactfunc Authors.
#include "estimation/pose/pose_distribution.h"

#include <algorithm>
#include <boost/math/distributions/chi_squared.hpp>
#include <cmath>
#include <cstdio>
#include <limits>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "Eigen/Eigenvalues"
#include "models/core/internal/checks.h"

namespace tactfunc {
namespace {

using internal::Check;
using internal::kPi;
using internal::Num;
// Eigenvalues of a covariance at or below this are zero-variance directions (standard
// deviation 1e-10 m or rad), along which displacements up to kPointMassSlack are free.
constexpr double kZeroVariance = 1e-20;
constexpr double kPointMassSlack = 1e-10;

void CheckProbability(double p) {
  Check(std::isfinite(p) && p > 0 && p <= 1,
        "PoseDistribution: probability p must be in (0, 1], got " + Num(p));
}

// Weighted circular mean of yaw and weighted mean of the translations.
SE2d ChordalMean(const std::vector<SE2d>& samples, const std::vector<double>& weights) {
  double c = 0, s = 0, x = 0, y = 0;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    c += weights[i] * std::cos(samples[i].yaw());
    s += weights[i] * std::sin(samples[i].yaw());
    x += weights[i] * samples[i].x();
    y += weights[i] * samples[i].y();
  }
  return SE2d::FromXYYaw(x, y, std::atan2(s, c));
}

}  // namespace

const char* ToString(PoseDistribution::MeanTermination termination) {
  switch (termination) {
    case PoseDistribution::MeanTermination::kConverged:
      return "CONVERGED";
    case PoseDistribution::MeanTermination::kNoConvergence:
      return "NO_CONVERGENCE";
  }
  return "UNKNOWN";
}

const char* ToString(PoseDistribution::RegionMethod method) {
  switch (method) {
    case PoseDistribution::RegionMethod::kSampleQuantile:
      return "sample_quantile";
    case PoseDistribution::RegionMethod::kGaussian:
      return "gaussian";
  }
  return "unknown";
}

// ---- Options ------------------------------------------------------------------------

bool PoseMeanOptions::IsValid(std::string* error) const {
  std::string message;
  if (max_iterations < 1) {
    message = "PoseMeanOptions.max_iterations must be >= 1, got " + std::to_string(max_iterations);
  } else if (!(translation_tolerance >= 0) || !std::isfinite(translation_tolerance)) {
    message = "PoseMeanOptions.translation_tolerance must be finite and >= 0 (metres), got " +
              Num(translation_tolerance);
  } else if (!(angle_tolerance >= 0) || !std::isfinite(angle_tolerance)) {
    message = "PoseMeanOptions.angle_tolerance must be finite and >= 0 (rad), got " +
              Num(angle_tolerance);
  }
  if (error != nullptr) *error = message;
  return message.empty();
}

bool CredibleRegionOptions::IsValid(std::string* error) const {
  std::string message;
  if (method != CredibleRegionMethod::kSampleQuantile &&
      method != CredibleRegionMethod::kGaussian) {
    message = "CredibleCredibleRegionOptions.method is not a CredibleRegionMethod";
  } else if (!mean.IsValid(&message)) {
    message = "CredibleRegionOptions.mean: " + message;
  }
  if (error != nullptr) *error = message;
  return message.empty();
}

bool PoseModeOptions::IsValid(std::string* error) const {
  std::string message;
  if (!(translation_bandwidth > 0) || !std::isfinite(translation_bandwidth)) {
    message = "PoseModeOptions.translation_bandwidth must be finite and > 0 (metres), got " +
              Num(translation_bandwidth);
  } else if (!(yaw_bandwidth > 0 && yaw_bandwidth <= kPi)) {
    message = "PoseModeOptions.yaw_bandwidth must be in (0, pi] (rad), got " + Num(yaw_bandwidth);
  } else if (max_iterations < 1) {
    message = "PoseModeOptions.max_iterations must be >= 1, got " + std::to_string(max_iterations);
  } else if (!(tolerance > 0) || !std::isfinite(tolerance)) {
    message =
        "PoseModeOptions.tolerance must be finite and > 0 (bandwidths), got " + Num(tolerance);
  } else if (!(merge_distance > 0) || !std::isfinite(merge_distance)) {
    message = "PoseModeOptions.merge_distance must be finite and > 0 (bandwidths), got " +
              Num(merge_distance);
  } else if (!(min_mode_weight >= 0 && min_mode_weight < 1)) {
    message = "PoseModeOptions.min_mode_weight must be in [0, 1), got " + Num(min_mode_weight);
  } else if (max_seeds < 1) {
    message = "PoseModeOptions.max_seeds must be >= 1, got " + std::to_string(max_seeds);
  }
  if (error != nullptr) *error = message;
  return message.empty();
}

std::string PoseMeanSummary::BriefReport() const {
  return std::string("Mean: ") + ToString(termination) + " in " + std::to_string(iterations) +
         " iterations (last step " + Num(final_step_translation) + " m, " + Num(final_step_angle) +
         " rad)" + (message.empty() ? "" : ": " + message);
}

// ---- Construction -------------------------------------------------------------------

PoseDistribution::PoseDistribution(std::vector<SE2d> samples, std::vector<double> weights)
    : samples_(std::move(samples)) {
  Check(!samples_.empty(), "PoseDistribution: expected at least one sample, got none");
  for (std::size_t i = 0; i < samples_.size(); ++i) {
    const SE2d& s = samples_[i];
    Check(std::isfinite(s.x()) && std::isfinite(s.y()) && std::isfinite(s.yaw()),
          "PoseDistribution: sample " + std::to_string(i) + " is not finite (x=" + Num(s.x()) +
              ", y=" + Num(s.y()) + ", yaw=" + Num(s.yaw()) + "); expected finite poses");
  }
  if (weights.empty()) weights.assign(samples_.size(), 1.0);
  Check(weights.size() == samples_.size(),
        "PoseDistribution: expected " + std::to_string(samples_.size()) +
            " weights (one per sample) or none, got " + std::to_string(weights.size()));
  double total = 0;
  for (std::size_t i = 0; i < weights.size(); ++i) {
    Check(std::isfinite(weights[i]) && weights[i] >= 0,
          "PoseDistribution: weight " + std::to_string(i) + " must be finite and >= 0, got " +
              Num(weights[i]));
    total += weights[i];
  }
  Check(total > 0 && std::isfinite(total),
        "PoseDistribution: the weights must not all be zero (sum " + Num(total) + ")");
  for (double& w : weights) w /= total;
  weights_ = std::move(weights);
}

double PoseDistribution::EffectiveSampleSize() const {
  double sum_sq = 0;
  for (double w : weights_) sum_sq += w * w;
  return 1.0 / sum_sq;
}

// ---- Mean and covariance ------------------------------------------------------------

SE2d PoseDistribution::Mean(const MeanOptions& options, MeanSummary* summary) const {
  std::string error;
  Check(options.IsValid(&error), error);
  MeanSummary local;
  MeanSummary& s = summary != nullptr ? *summary : local;
  s = MeanSummary();
  SE2d mean = ChordalMean(samples_, weights_);
  s.initial = mean;
  for (int it = 0; it < options.max_iterations; ++it) {
    const SE2d mean_inv = mean.Inverse();
    Eigen::Vector3d delta = Eigen::Vector3d::Zero();
    for (std::size_t i = 0; i < samples_.size(); ++i) {
      if (weights_[i] == 0) continue;
      delta += weights_[i] * (mean_inv * samples_[i]).Log();
    }
    mean = mean * SE2d::Exp(delta);
    s.iterations = it + 1;
    s.final_step_translation = delta.head<2>().norm();
    s.final_step_angle = std::abs(delta[2]);
    if (s.final_step_translation <= options.translation_tolerance &&
        s.final_step_angle <= options.angle_tolerance) {
      s.termination = MeanTermination::kConverged;
      return mean;
    }
  }
  s.termination = MeanTermination::kNoConvergence;
  s.message = "max_iterations (" + std::to_string(options.max_iterations) +
              ") reached; the samples may be multimodal or spread over more than pi in yaw "
              "(see Modes(), FoldedBySymmetry())";
  return mean;
}

Eigen::Matrix3d PoseDistribution::CovarianceAbout(const SE2d& reference_T_mean) const {
  double sum_sq = 0;
  for (double w : weights_) sum_sq += w * w;
  const double denominator = 1.0 - sum_sq;
  // A single sample carries (numerically) all the weight: a point mass.
  if (denominator <= 1e-12) return Eigen::Matrix3d::Zero();
  const SE2d mean_inv = reference_T_mean.Inverse();
  Eigen::Matrix3d sigma = Eigen::Matrix3d::Zero();
  for (std::size_t i = 0; i < samples_.size(); ++i) {
    if (weights_[i] == 0) continue;
    const Eigen::Vector3d r = (mean_inv * samples_[i]).Log();
    sigma.noalias() += weights_[i] * r * r.transpose();
  }
  // Exactly symmetric (not only to rounding), as EKF consumers assume.
  return (0.5 / denominator) * (sigma + sigma.transpose());
}

Eigen::Matrix3d PoseDistribution::Covariance(const MeanOptions& options) const {
  return CovarianceAbout(Mean(options));
}

// ---- Credible regions ---------------------------------------------------------------

PoseCredibleRegion::PoseCredibleRegion(const SE2d& mean, const Eigen::Matrix3d& covariance,
                                       double p, CredibleRegionMethod method, double threshold)
    : mean_(mean),
      mean_inverse_(mean.Inverse()),
      covariance_(covariance),
      p_(p),
      method_(method),
      threshold_(threshold) {
  Check(covariance.allFinite(), "CredibleRegion: the covariance must be finite");
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eigen(0.5 *
                                                             (covariance + covariance.transpose()));
  eigenvectors_ = eigen.eigenvectors();
  rank_ = 0;
  for (int k = 0; k < 3; ++k) {
    const double lambda = eigen.eigenvalues()[k];
    inverse_eigenvalues_[k] = lambda > kZeroVariance ? 1.0 / lambda : 0.0;
    if (lambda > kZeroVariance) ++rank_;
  }
}

double PoseCredibleRegion::SquaredMahalanobis(const SE2d& pose) const {
  const Eigen::Vector3d r = (mean_inverse_ * pose).Log();
  if (!r.allFinite()) return std::numeric_limits<double>::infinity();
  const Eigen::Vector3d u = eigenvectors_.transpose() * r;
  double d2 = 0;
  for (int k = 0; k < 3; ++k) {
    if (inverse_eigenvalues_[k] > 0) {
      d2 += u[k] * u[k] * inverse_eigenvalues_[k];
    } else if (std::abs(u[k]) > kPointMassSlack) {
      return std::numeric_limits<double>::infinity();
    }
  }
  return d2;
}

PoseDistribution::CredibleRegion PoseDistribution::Region(double p,
                                                          const RegionOptions& options) const {
  CheckProbability(p);
  std::string error;
  Check(options.IsValid(&error), error);
  const SE2d mean = Mean(options.mean);
  CredibleRegion region(mean, CovarianceAbout(mean), p, options.method, 0.0);
  if (options.method == RegionMethod::kGaussian) {
    if (region.rank() == 0 || p == 1) {
      region.threshold_ = p == 1 ? std::numeric_limits<double>::infinity() : 0.0;
    } else {
      region.threshold_ = boost::math::quantile(boost::math::chi_squared(region.rank()), p);
    }
    return region;
  }
  // Weighted p-quantile of the samples' own squared distances.
  std::vector<std::pair<double, double>> d2(samples_.size());
  for (std::size_t i = 0; i < samples_.size(); ++i) {
    d2[i] = {region.SquaredMahalanobis(samples_[i]), weights_[i]};
  }
  std::sort(d2.begin(), d2.end());
  double cumulative = 0;
  region.threshold_ = d2.back().first;
  for (const auto& [distance, weight] : d2) {
    cumulative += weight;
    // The slack absorbs rounding in the running sum (p = 1 must reach the last one).
    if (cumulative >= p - 1e-12) {
      region.threshold_ = distance;
      break;
    }
  }
  return region;
}

bool PoseDistribution::Contains(const SE2d& pose, double p, const RegionOptions& options) const {
  return Region(p, options).Contains(pose);
}

// ---- Modes --------------------------------------------------------------------------

std::vector<PoseMode> PoseDistribution::Modes(const ModeOptions& options) const {
  std::string error;
  Check(options.IsValid(&error), error);
  const int n = size();
  // Features: translation in bandwidths, yaw on a circle of radius 1 / h_yaw.
  Eigen::Matrix<double, 4, Eigen::Dynamic> features(4, n);
  for (int i = 0; i < n; ++i) {
    const SE2d& s = samples_[i];
    features.col(i) << s.x() / options.translation_bandwidth, s.y() / options.translation_bandwidth,
        std::cos(s.yaw()) / options.yaw_bandwidth, std::sin(s.yaw()) / options.yaw_bandwidth;
  }
  const Eigen::Map<const Eigen::VectorXd> w(weights_.data(), n);

  // Seeds: every positive-weight sample, or an evenly spaced subset of them.
  std::vector<int> candidates;
  for (int i = 0; i < n; ++i) {
    if (weights_[i] > 0) candidates.push_back(i);
  }
  std::vector<int> seeds;
  const int num_candidates = static_cast<int>(candidates.size());
  if (num_candidates <= options.max_seeds) {
    seeds = candidates;
  } else {
    for (int k = 0; k < options.max_seeds; ++k) {
      seeds.push_back(candidates[static_cast<std::size_t>(static_cast<long long>(k) *
                                                          num_candidates / options.max_seeds)]);
    }
  }

  // Climb. Kernel weights are relative to the nearest sample (log-sum-exp) so that a
  // seed far from every other sample cannot underflow to 0 / 0.
  std::vector<Eigen::Vector4d> maxima;  // distinct maxima
  std::vector<int> mode_of(n, -1);
  Eigen::VectorXd d2(n), k(n);
  for (int seed : seeds) {
    Eigen::Vector4d y = features.col(seed);
    for (int it = 0; it < options.max_iterations; ++it) {
      d2 = (features.colwise() - y).colwise().squaredNorm().transpose();
      double min_d2 = std::numeric_limits<double>::infinity();
      for (int j = 0; j < n; ++j) {
        if (weights_[j] > 0) min_d2 = std::min(min_d2, d2[j]);
      }
      k = (w.array() * (-0.5 * (d2.array() - min_d2)).exp()).matrix();
      const Eigen::Vector4d next = features * k / k.sum();
      const double step = (next - y).norm();
      y = next;
      if (step < options.tolerance) break;
    }
    int found = -1;
    for (std::size_t m = 0; m < maxima.size(); ++m) {
      if ((maxima[m] - y).norm() <= options.merge_distance) {
        found = static_cast<int>(m);
        break;
      }
    }
    if (found < 0) {
      maxima.push_back(y);
      found = static_cast<int>(maxima.size()) - 1;
    }
    mode_of[seed] = found;
  }

  auto nearest = [&](int i, const std::vector<bool>& alive) {
    int best = -1;
    double best_d2 = std::numeric_limits<double>::infinity();
    for (std::size_t m = 0; m < maxima.size(); ++m) {
      if (!alive[m]) continue;
      const double dd = (maxima[m] - features.col(i)).squaredNorm();
      if (dd < best_d2) {
        best_d2 = dd;
        best = static_cast<int>(m);
      }
    }
    return best;
  };
  std::vector<bool> alive(maxima.size(), true);
  for (int i = 0; i < n; ++i) {
    if (mode_of[i] < 0) mode_of[i] = nearest(i, alive);
  }
  // Light modes give their samples to the nearest heavier one, lightest first.
  while (true) {
    std::vector<double> mass(maxima.size(), 0.0);
    for (int i = 0; i < n; ++i) mass[mode_of[i]] += weights_[i];
    int lightest = -1;
    int num_alive = 0;
    for (std::size_t m = 0; m < maxima.size(); ++m) {
      if (!alive[m]) continue;
      ++num_alive;
      if (lightest < 0 || mass[m] < mass[lightest]) lightest = static_cast<int>(m);
    }
    if (num_alive <= 1 || mass[lightest] >= options.min_mode_weight) break;
    alive[lightest] = false;
    for (int i = 0; i < n; ++i) {
      if (mode_of[i] == lightest) mode_of[i] = nearest(i, alive);
    }
  }

  std::vector<PoseMode> modes;
  for (std::size_t m = 0; m < maxima.size(); ++m) {
    if (!alive[m]) continue;
    std::vector<SE2d> members;
    std::vector<double> member_weights;
    double mass = 0;
    for (int i = 0; i < n; ++i) {
      if (mode_of[i] != static_cast<int>(m)) continue;
      members.push_back(samples_[i]);
      member_weights.push_back(weights_[i]);
      mass += weights_[i];
    }
    if (mass <= 0) continue;
    const PoseDistribution part(std::move(members), std::move(member_weights));
    PoseMode mode;
    mode.weight = mass;
    mode.mean = part.Mean();
    mode.covariance = part.CovarianceAbout(mode.mean);
    mode.num_samples = part.size();
    modes.push_back(mode);
  }
  std::sort(modes.begin(), modes.end(),
            [](const PoseMode& a, const PoseMode& b) { return a.weight > b.weight; });
  return modes;
}

// ---- Symmetry -----------------------------------------------------------------------

double FoldYaw(double yaw, int symmetry_order) {
  Check(symmetry_order >= 0,
        "FoldYaw: symmetry order must be >= 0, got " + std::to_string(symmetry_order));
  if (symmetry_order == 0) return 0.0;
  const double period = 2 * kPi / symmetry_order;
  double folded = yaw - period * std::floor((yaw + 0.5 * period) / period);
  if (folded >= 0.5 * period) folded -= period;
  if (folded < -0.5 * period) folded += period;
  return folded;
}

PoseDistribution PoseDistribution::FoldedBySymmetry(int symmetry_order) const {
  Check(symmetry_order >= 0,
        "PoseDistribution::FoldedBySymmetry: symmetry order must be >= 0, got " +
            std::to_string(symmetry_order));
  std::vector<SE2d> folded = samples_;
  if (symmetry_order == 1) return *this;
  if (symmetry_order == 0) {
    for (SE2d& s : folded) s = SE2d::FromXYYaw(s.x(), s.y(), 0.0);
    return PoseDistribution(std::move(folded), weights_);
  }
  const double n = symmetry_order;
  double c = 0, s = 0;
  for (std::size_t i = 0; i < samples_.size(); ++i) {
    c += weights_[i] * std::cos(n * samples_[i].yaw());
    s += weights_[i] * std::sin(n * samples_[i].yaw());
  }
  const double reference = std::hypot(c, s) > 1e-12 ? std::atan2(s, c) / n : 0.0;
  for (SE2d& p : folded) {
    p = SE2d::FromXYYaw(p.x(), p.y(), reference + FoldYaw(p.yaw() - reference, symmetry_order));
  }
  return PoseDistribution(std::move(folded), weights_);
}

// ---- ROS ----------------------------------------------------------------------------

std::array<double, 36> ToRosPoseCovariance(const SE2d& reference_T_mean,
                                           const Eigen::Matrix3d& covariance,
                                           RosCovarianceFrame frame, double unobserved_variance) {
  Eigen::Matrix3d c = covariance;
  if (frame == RosCovarianceFrame::kParent) {
    Eigen::Matrix3d j = Eigen::Matrix3d::Identity();
    j.topLeftCorner<2, 2>() = reference_T_mean.Rotation();
    c = j * covariance * j.transpose();
  }
  std::array<double, 36> ros{};
  constexpr int kIndex[3] = {0, 1, 5};  // x, y, yaw in (x, y, z, roll, pitch, yaw)
  for (int r = 0; r < 3; ++r) {
    for (int col = 0; col < 3; ++col) ros[6 * kIndex[r] + kIndex[col]] = c(r, col);
  }
  for (int k : {2, 3, 4}) ros[6 * k + k] = unobserved_variance;
  return ros;
}

std::pair<double, double> BinomialInterval99(int n, double p) {
  if (n <= 0) return {0.0, 1.0};
  double cdf = 0;
  int lo = -1, hi = n;
  for (int k = 0; k <= n; ++k) {
    const double log_pmf = std::lgamma(n + 1.0) - std::lgamma(k + 1.0) - std::lgamma(n - k + 1.0) +
                           k * std::log(p) + (n - k) * std::log1p(-p);
    cdf += std::exp(log_pmf);
    if (lo < 0 && cdf >= 0.005) lo = k;
    if (cdf >= 0.995) {
      hi = k;
      break;
    }
  }
  return {static_cast<double>(std::max(lo, 0)) / n, static_cast<double>(hi) / n};
}

}  // namespace tactfunc
