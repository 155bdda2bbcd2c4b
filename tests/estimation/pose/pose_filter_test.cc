// Copyright 2026 The tactfunc Authors.
//
// SE2ParticleFilter on synthetic measurements with known statistics: per frame, a centre
// c_t = T_t * Exp(e_t), e_t ~ N(0, R) (the per-frame estimator's error) and M samples
// s_j = c_t * Exp(eta_j), eta_j ~ N(0, R) (its posterior spread: a calibrated posterior),
// all drawn with fixed seeds.
//
// Where the tolerances come from. For small errors each tangent axis behaves as a scalar
// Kalman filter (Gaussian prior from the particles, Gaussian-like kernel likelihood):
//   * the measurement the filter sees is the sample mean, whose error variance is
//     r_true = r (1 + 1/M) -- also the per-frame estimator's mean squared error;
//   * the kernel density of M samples of spread r is ~N(c, r_eff), r_eff = (1 + h^2) r +
//     floor, h the bandwidth factor (header comment of estimation/pose/pose_filter.h);
//   * a random walk of per-frame variance q gives the steady-state gain
//     K = P- / (P- + r_eff), P- = (q + sqrt(q^2 + 4 q r_eff)) / 2, and for a truth moving
//     v per frame the error obeys e' = (1 - K)(e - v) + K n, so in steady state its mean
//     square is K^2 r_true / (1 - (1 - K)^2) + ((1 - K) v / K)^2.
// The Monte Carlo error of an RMSE over T frames of an AR(1) error with coefficient a is
// about (1/2) sqrt(2 / T_eff), T_eff = T (1 - a^2) / (1 + a^2) (the squared errors'
// correlation is a^2k). Tests allow 3 of those standard errors (4 for single draws), never
// a figure read off a run.
#include "estimation/pose/pose_filter.h"

#include <algorithm>
#include <boost/random/mersenne_twister.hpp>
#include <boost/random/normal_distribution.hpp>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "Eigen/Cholesky"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "models/core/internal/checks.h"
#include "models/simulator/tool.h"

namespace tactfunc {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;
using ::testing::HasSubstr;
using internal::kPi;
constexpr double kDeg = kPi / 180;
constexpr double kMm = 1e-3;

Matrix3d Diagonal(double sx, double sy, double syaw) {
  return Vector3d(sx * sx, sy * sy, syaw * syaw).asDiagonal();
}

// Draws the synthetic per-frame measurements of the header comment.
class MeasurementSource {
 public:
  MeasurementSource(const Matrix3d& r, int num_samples, std::uint64_t seed)
      : l_(r.llt().matrixL()), num_samples_(num_samples), rng_(seed) {}
  Vector3d Noise() { return l_ * Vector3d(normal_(rng_), normal_(rng_), normal_(rng_)); }
  // Samples around truth * Exp(e), e ~ N(0, R).
  PoseDistribution Around(const SE2d& truth) { return Centred(truth * SE2d::Exp(Noise())); }
  // Samples around `centre` exactly (no per-frame error).
  PoseDistribution Centred(const SE2d& centre) {
    std::vector<SE2d> samples;
    for (int j = 0; j < num_samples_; ++j) samples.push_back(centre * SE2d::Exp(Noise()));
    return PoseDistribution(samples);
  }
  // The two half-turn images of one cloud: s_j and s_j * Rot(pi), the posterior of a
  // frame whose face looks the same after a half turn.
  PoseDistribution HalfTurnPair(const SE2d& truth) {
    const SE2d centre = truth * SE2d::Exp(Noise());
    std::vector<SE2d> samples;
    for (int j = 0; j < num_samples_; ++j) {
      const SE2d s = centre * SE2d::Exp(Noise());
      samples.push_back(s);
      samples.push_back(s * SE2d::Rot(kPi));
    }
    return PoseDistribution(samples);
  }

 private:
  Matrix3d l_;
  int num_samples_;
  boost::random::mt19937_64 rng_;
  boost::random::normal_distribution<double> normal_;
};

double SilvermanFactor(double ess, int dim) {
  return std::pow(4.0 / ((dim + 2) * ess), 1.0 / (dim + 4));
}

// Steady-state scalar Kalman figures of the header comment.
struct SteadyState {
  double gain = 0;
  double mean_square = 0;  // of the filtered error
};
SteadyState SteadyStateError(double q, double r_eff, double r_true, double v) {
  const double p_prior = (q + std::sqrt(q * q + 4 * q * r_eff)) / 2;
  SteadyState s;
  s.gain = p_prior / (p_prior + r_eff);
  const double a = 1 - s.gain;
  s.mean_square = s.gain * s.gain * r_true / (1 - a * a) + std::pow(a * v / s.gain, 2);
  return s;
}

double RelativeRmseStandardError(double num_frames, double a) {
  const double t_eff = num_frames * (1 - a * a) / (1 + a * a);
  return 0.5 * std::sqrt(2 / t_eff);
}

double PositionError(const SE2d& estimate, const SE2d& truth) {
  return std::hypot(estimate.x() - truth.x(), estimate.y() - truth.y());
}

TEST(SE2ParticleFilterOptions, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(SE2ParticleFilter::Options().IsValid(&error)) << error;
  EXPECT_TRUE(error.empty());
}

TEST(SE2ParticleFilterOptions, InvalidOptionsNameTheField) {
  auto message = [](auto change) {
    SE2ParticleFilter::Options options;
    change(options);
    std::string error;
    EXPECT_FALSE(options.IsValid(&error));
    EXPECT_THROW(SE2ParticleFilter filter(options), std::invalid_argument);
    return error;
  };
  EXPECT_THAT(message([](auto& o) { o.num_particles = 0; }), HasSubstr("num_particles"));
  EXPECT_THAT(message([](auto& o) { o.symmetry_order = -1; }), HasSubstr("symmetry_order"));
  EXPECT_THAT(message([](auto& o) { o.process_covariance(0, 0) = -1e-6; }),
              HasSubstr("process_covariance is not positive semi-definite"));
  EXPECT_THAT(message([](auto& o) { o.process_covariance(0, 1) = 1e-7; }),
              HasSubstr("process_covariance is not symmetric"));
  EXPECT_THAT(message([](auto& o) { o.floor_covariance.setZero(); }),
              HasSubstr("floor_covariance is not positive definite"));
  EXPECT_THAT(message([](auto& o) { o.bandwidth_factor = -1; }), HasSubstr("bandwidth_factor"));
  EXPECT_THAT(message([](auto& o) { o.resample_threshold = 1.5; }),
              HasSubstr("resample_threshold"));
  EXPECT_THAT(message([](auto& o) { o.gate_squared_mahalanobis = 0; }),
              HasSubstr("gate_squared_mahalanobis"));
  EXPECT_THAT(message([](auto& o) { o.max_consecutive_rejections = -1; }),
              HasSubstr("max_consecutive_rejections"));
  EXPECT_THAT(message([](auto& o) { o.modes.yaw_bandwidth = 0; }), HasSubstr("modes:"));
  EXPECT_THAT(message([](auto& o) {
                o.velocity_process_covariance(2, 2) = std::numeric_limits<double>::quiet_NaN();
              }),
              HasSubstr("velocity_process_covariance has non-finite entries"));
}

TEST(SystematicResample, CopiesEachParticleFloorOrCeilOfItsExpectedCount) {
  const std::vector<double> weights = {0.05, 0.0, 0.30, 0.125, 0.025, 0.5};
  const int n = static_cast<int>(weights.size());
  for (double u0 : {0.0, 0.1, 0.37, 0.5, 0.999}) {
    const std::vector<int> index = SystematicResample(weights, u0);
    ASSERT_EQ(static_cast<int>(index.size()), n);
    EXPECT_TRUE(std::is_sorted(index.begin(), index.end()));
    for (int i = 0; i < n; ++i) {
      const int count = static_cast<int>(std::count(index.begin(), index.end(), i));
      EXPECT_GE(count, std::floor(n * weights[i])) << "u0 " << u0 << ", particle " << i;
      EXPECT_LE(count, std::ceil(n * weights[i])) << "u0 " << u0 << ", particle " << i;
    }
  }
  EXPECT_THROW(SystematicResample({}, 0.5), std::invalid_argument);
  EXPECT_THROW(SystematicResample({0.0, 0.0}, 0.5), std::invalid_argument);
  EXPECT_THROW(SystematicResample({0.5, 0.5}, 1.0), std::invalid_argument);
  EXPECT_THROW(SystematicResample({0.5, -0.5}, 0.1), std::invalid_argument);
}

// A tool slipping in the grasp: 3 mm in x, -2 mm in y and 20 deg of yaw at a steady rate
// over 100 frames, seen through noisy per-frame posteriors (0.3 mm, 3 deg). The filter's
// RMSE must be below the per-frame RMSE by the margin the scalar Kalman analysis predicts
// (header comment), up to three Monte Carlo standard errors.
TEST(SE2ParticleFilter, TracksASlippingToolBetterThanThePerFrameEstimates) {
  const int kFrames = 100, kBurnIn = 10, kRuns = 3, kSamples = 50;
  const double sxy = 0.3 * kMm, syaw = 3 * kDeg;
  const Matrix3d r = Diagonal(sxy, sxy, syaw);
  SE2ParticleFilter::Options options;
  options.num_particles = 1000;
  options.process_covariance = Diagonal(0.15 * kMm, 0.15 * kMm, 1.5 * kDeg);

  auto truth_at = [&](int t) {
    const double s = static_cast<double>(t) / kFrames;
    return SE2d::FromXYYaw(1 * kMm + 3 * kMm * s, -2 * kMm * s, 0.2 + 20 * kDeg * s);
  };
  // The largest per-frame body-frame motion on each axis (the lag term's v).
  Vector3d v = Vector3d::Zero();
  for (int t = 0; t + 1 < kFrames; ++t) {
    v = v.cwiseMax(SE2d::Between(truth_at(t), truth_at(t + 1)).Log().cwiseAbs());
  }

  double frame_sq_pos = 0, frame_sq_yaw = 0, filter_sq_pos = 0, filter_sq_yaw = 0;
  int counted = 0;
  for (int run = 0; run < kRuns; ++run) {
    options.seed = 100 + run;
    SE2ParticleFilter filter(options);
    MeasurementSource source(r, kSamples, 7 + run);
    for (int t = 0; t < kFrames; ++t) {
      const SE2d truth = truth_at(t);
      const PoseDistribution measurement = source.Around(truth);
      filter.Predict();
      const SE2ParticleFilter::UpdateSummary s = filter.Update(measurement);
      ASSERT_NE(s.type, PoseFilterUpdateType::kRejected)
          << "frame " << t << ": " << s.BriefReport();
      ASSERT_NE(s.type, PoseFilterUpdateType::kReinitialized) << "frame " << t;
      if (t < kBurnIn) continue;
      const SE2d per_frame = measurement.Mean();
      const SE2d filtered = filter.CurrentEstimate().mean;
      frame_sq_pos += std::pow(PositionError(per_frame, truth), 2);
      frame_sq_yaw += std::pow(SE2d::NormalizeAngle(per_frame.yaw() - truth.yaw()), 2);
      filter_sq_pos += std::pow(PositionError(filtered, truth), 2);
      filter_sq_yaw += std::pow(SE2d::NormalizeAngle(filtered.yaw() - truth.yaw()), 2);
      ++counted;
    }
    EXPECT_EQ(filter.summary().num_rejected, 0);
  }
  const double frame_rmse_pos = std::sqrt(frame_sq_pos / counted);
  const double frame_rmse_yaw = std::sqrt(frame_sq_yaw / counted);
  const double filter_rmse_pos = std::sqrt(filter_sq_pos / counted);
  const double filter_rmse_yaw = std::sqrt(filter_sq_yaw / counted);

  // The prediction, per axis (x, y: position; yaw).
  const double h = SilvermanFactor(kSamples, 3);
  const Vector3d floor = options.floor_covariance.diagonal();
  const Vector3d q = options.process_covariance.diagonal();
  SteadyState axis[3];
  Vector3d r_true;
  for (int k = 0; k < 3; ++k) {
    r_true[k] = r(k, k) * (1 + 1.0 / kSamples);
    axis[k] = SteadyStateError(q[k], (1 + h * h) * r(k, k) + floor[k], r_true[k], v[k]);
  }
  const double ratio_pos =
      std::sqrt((axis[0].mean_square + axis[1].mean_square) / (r_true[0] + r_true[1]));
  const double ratio_yaw = std::sqrt(axis[2].mean_square / r_true[2]);
  // Standard errors: the filtered errors are AR(1) with a = 1 - K, the per-frame ones
  // independent; position pools two axes.
  const double a = 1 - std::min({axis[0].gain, axis[1].gain, axis[2].gain});
  const double se_pos = std::hypot(RelativeRmseStandardError(2.0 * counted, a),
                                   RelativeRmseStandardError(2.0 * counted, 0));
  const double se_yaw =
      std::hypot(RelativeRmseStandardError(counted, a), RelativeRmseStandardError(counted, 0));
  const double bound_pos = ratio_pos * (1 + 3 * se_pos);
  const double bound_yaw = ratio_yaw * (1 + 3 * se_yaw);
  std::printf(
      "[ figures  ] per-frame RMSE %.3f mm %.2f deg; filtered %.3f mm %.2f deg; ratio "
      "%.3f (predicted %.3f, bound %.3f), %.3f (predicted %.3f, bound %.3f)\n",
      frame_rmse_pos / kMm, frame_rmse_yaw / kDeg, filter_rmse_pos / kMm, filter_rmse_yaw / kDeg,
      filter_rmse_pos / frame_rmse_pos, ratio_pos, bound_pos, filter_rmse_yaw / frame_rmse_yaw,
      ratio_yaw, bound_yaw);
  // The test means something only if the bound is below 1.
  ASSERT_LT(bound_pos, 0.9);
  ASSERT_LT(bound_yaw, 0.9);
  EXPECT_LT(filter_rmse_pos, bound_pos * frame_rmse_pos)
      << "per-frame " << frame_rmse_pos / kMm << " mm, filtered " << filter_rmse_pos / kMm
      << " mm, predicted ratio " << ratio_pos;
  EXPECT_LT(filter_rmse_yaw, bound_yaw * frame_rmse_yaw)
      << "per-frame " << frame_rmse_yaw / kDeg << " deg, filtered " << filter_rmse_yaw / kDeg
      << " deg, predicted ratio " << ratio_yaw;
  // The per-frame RMSE itself is what the noise says (sanity of the set-up).
  EXPECT_NEAR(frame_rmse_pos, std::sqrt(r_true[0] + r_true[1]),
              3 * RelativeRmseStandardError(2.0 * counted, 0) * std::sqrt(r_true[0] + r_true[1]));
}

// A tool that does not move: with a small random walk the posterior narrows like an
// average of the frames. Scalar Kalman recursion per axis from the initial spread r_eff
// (particles drawn from the first kernel density): P- = P + q, K = P- / (P- + r_eff),
// P = (1 - K) P-, and the error variance V = (1 - K)^2 V + K^2 r_true.
TEST(SE2ParticleFilter, ConvergesOnAConstantPose) {
  const int kFrames = 40, kSamples = 100;
  const double sxy = 0.3 * kMm, syaw = 3 * kDeg;
  const Matrix3d r = Diagonal(sxy, sxy, syaw);
  SE2ParticleFilter::Options options;
  options.num_particles = 2000;
  options.seed = 3;
  options.process_covariance = Diagonal(0.01 * kMm, 0.01 * kMm, 0.1 * kDeg);
  SE2ParticleFilter filter(options);
  MeasurementSource source(r, kSamples, 11);
  const SE2d truth = SE2d::FromXYYaw(1 * kMm, -2 * kMm, 0.4);
  double initial_trace = 0;
  for (int t = 0; t < kFrames; ++t) {
    filter.Predict();
    const SE2ParticleFilter::UpdateSummary s = filter.Update(source.Around(truth));
    ASSERT_EQ(s.type, t == 0 ? PoseFilterUpdateType::kInitialized : PoseFilterUpdateType::kUpdated);
    if (t == 0) initial_trace = filter.CurrentEstimate().covariance.trace();
  }
  const SE2ParticleFilter::Estimate estimate = filter.CurrentEstimate();
  EXPECT_TRUE(estimate.mean_summary.converged());
  const Vector3d error = SE2d::Between(truth, estimate.mean).Log();  // tangent at truth
  const double h = SilvermanFactor(kSamples, 3);
  for (int k = 0; k < 3; ++k) {
    const double r_eff = (1 + h * h) * r(k, k) + options.floor_covariance(k, k);
    const double r_true = r(k, k) * (1 + 1.0 / kSamples);
    const double q = options.process_covariance(k, k);
    double p = r_eff, var = r_true;
    for (int t = 1; t < kFrames; ++t) {
      const double prior = p + q;
      const double gain = prior / (prior + r_eff);
      p = (1 - gain) * prior;
      var = (1 - gain) * (1 - gain) * var + gain * gain * r_true;
    }
    EXPECT_LT(std::abs(error[k]), 4 * std::sqrt(var)) << "axis " << k;
    // The particles' spread is the Kalman posterior's, within the Monte Carlo error of a
    // variance from >= 1000 effective particles (and the Gaussian approximation).
    EXPECT_GT(estimate.covariance(k, k), 0.5 * p) << "axis " << k;
    EXPECT_LT(estimate.covariance(k, k), 2.0 * p) << "axis " << k;
  }
  EXPECT_LT(estimate.covariance.trace(), 0.1 * initial_trace);
}

// The posterior of an asymmetric tool whose face looks alike after a half turn has two
// modes, yaw and yaw - pi, of equal height. The filter keeps both (their weights move only
// by the Monte Carlo error: a systematic resampling adds a variance <= 0.25 / N per
// resampling, and the two clusters' likelihoods differ by their sampling error) until a
// frame resolves the ambiguity; then the wrong mode's likelihood ratio is about
// exp(-pi^2 / (2 * 0.07^2)) = 0, so its mass vanishes.
TEST(SE2ParticleFilter, KeepsBothHalfTurnHypothesesUntilAUnimodalMeasurementArrives) {
  const int kSamples = 50;
  const Matrix3d r = Diagonal(0.3 * kMm, 0.3 * kMm, 3 * kDeg);
  SE2ParticleFilter::Options options;
  options.num_particles = 2000;
  options.seed = 5;
  SE2ParticleFilter filter(options);
  MeasurementSource source(r, kSamples, 13);
  const SE2d truth = SE2d::FromXYYaw(0.5 * kMm, 1 * kMm, 0.3);
  // A mode's yaw error is at most that of one frame's estimate (the filter averages
  // frames): 4 standard deviations of it, 4 * 3 deg * sqrt(1 + 1/M).
  const double yaw_tolerance = 4 * 3 * kDeg * std::sqrt(1 + 1.0 / kSamples);
  auto mass_near = [&](double yaw) {
    const PoseDistribution posterior = filter.Posterior();
    double mass = 0;
    for (int i = 0; i < posterior.size(); ++i) {
      if (std::abs(SE2d::NormalizeAngle(posterior.samples()[i].yaw() - yaw)) < kPi / 2) {
        mass += posterior.weights()[i];
      }
    }
    return mass;
  };
  for (int t = 0; t < 6; ++t) {
    filter.Predict();
    const SE2ParticleFilter::UpdateSummary s = filter.Update(source.HalfTurnPair(truth));
    EXPECT_EQ(s.measurement_modes, 2) << "frame " << t;
    const std::vector<PoseMode> modes = filter.Posterior().Modes();
    ASSERT_EQ(modes.size(), 2u) << "frame " << t;
    for (const PoseMode& mode : modes) {
      EXPECT_NEAR(mode.weight, 0.5, 0.15) << "frame " << t;
      EXPECT_LT(YawErrorModuloSymmetry(mode.mean.yaw(), truth.yaw(), 2), yaw_tolerance);
    }
    EXPECT_NEAR(mass_near(truth.yaw()), 0.5, 0.15);
  }
  filter.Predict();
  const SE2ParticleFilter::UpdateSummary s = filter.Update(source.Around(truth));
  EXPECT_EQ(s.type, PoseFilterUpdateType::kUpdated);
  EXPECT_EQ(s.measurement_modes, 1);
  EXPECT_GT(mass_near(truth.yaw()), 1 - 1e-9);
  const std::vector<PoseMode> modes = filter.Posterior().Modes();
  ASSERT_EQ(modes.size(), 1u);
  EXPECT_LT(std::abs(SE2d::NormalizeAngle(modes[0].mean.yaw() - truth.yaw())), yaw_tolerance);
}

// For a tool with C_2 symmetry the same measurements are one hypothesis modulo pi.
TEST(SE2ParticleFilter, TreatsHalfTurnModesOfAHalfTurnSymmetricToolAsOneHypothesis) {
  const Matrix3d r = Diagonal(0.3 * kMm, 0.3 * kMm, 3 * kDeg);
  SE2ParticleFilter::Options options;
  options.num_particles = 1000;
  options.symmetry_order = 2;
  SE2ParticleFilter filter(options);
  MeasurementSource source(r, 50, 17);
  const SE2d truth = SE2d::FromXYYaw(0.5 * kMm, 1 * kMm, 1.5);  // near the fold at pi/2
  for (int t = 0; t < 5; ++t) {
    filter.Predict();
    const SE2ParticleFilter::UpdateSummary s = filter.Update(source.HalfTurnPair(truth));
    EXPECT_EQ(s.measurement_modes, 1);
    EXPECT_NE(s.type, PoseFilterUpdateType::kRejected);
  }
  const std::vector<PoseMode> modes = filter.Posterior().Modes();
  ASSERT_EQ(modes.size(), 1u);
  EXPECT_LT(YawErrorModuloSymmetry(filter.CurrentEstimate().mean.yaw(), truth.yaw(), 2),
            4 * 3 * kDeg * std::sqrt(1 + 1.0 / 50));  // 4 sd of one frame's yaw error
}

// A hemisphere (n = 0): yaw is ignored, the position is still tracked.
TEST(SE2ParticleFilter, IgnoresYawForAToolWithContinuousSymmetry) {
  const Matrix3d r = Diagonal(0.3 * kMm, 0.3 * kMm, 3 * kDeg);
  SE2ParticleFilter::Options options;
  options.symmetry_order = 0;
  SE2ParticleFilter filter(options);
  MeasurementSource source(r, 50, 19);
  const SE2d truth = SE2d::FromXYYaw(-1 * kMm, 2 * kMm, 0.0);
  for (int t = 0; t < 10; ++t) {
    filter.Predict();
    // Yaw anywhere: the measurement carries none.
    const SE2ParticleFilter::UpdateSummary s =
        filter.Update(source.Around(truth * SE2d::Rot(0.7 * t)));
    EXPECT_NE(s.type, PoseFilterUpdateType::kRejected);
    EXPECT_EQ(s.kernel_covariance(2, 2), 0);
  }
  const SE2ParticleFilter::Estimate e = filter.CurrentEstimate();
  EXPECT_EQ(e.mean.yaw(), 0);
  // Ten frames of 0.3 mm per axis: the error is ~0.1 mm per axis; 4 of those.
  EXPECT_LT(PositionError(e.mean, truth), 4 * std::sqrt(2.0) * 0.3 * kMm / std::sqrt(10.0));
}

// A steady slip faster than the random walk's lag: a random-walk filter trails the truth
// by (1 - K) v / K per axis in steady state; the constant-velocity model learns v and
// does not.
TEST(SE2ParticleFilter, ConstantVelocityModelFollowsASteadySlipWithoutLag) {
  const int kFrames = 60, kTail = 20;
  const Matrix3d r = Diagonal(0.1 * kMm, 0.1 * kMm, 1 * kDeg);
  const Vector3d velocity(0.2 * kMm, 0.0, 1 * kDeg);  // body frame, per frame
  auto run = [&](bool constant_velocity) {
    SE2ParticleFilter::Options options;
    options.seed = 23;
    options.process_covariance = Diagonal(0.05 * kMm, 0.05 * kMm, 0.2 * kDeg);
    options.constant_velocity = constant_velocity;
    SE2ParticleFilter filter(options);
    MeasurementSource source(r, 50, 29);
    SE2d truth = SE2d::FromXYYaw(0, 0, 0.1);
    double sq = 0;
    for (int t = 0; t < kFrames; ++t) {
      truth = truth * SE2d::Exp(velocity);
      filter.Predict();
      filter.Update(source.Around(truth));
      if (t >= kFrames - kTail)
        sq += std::pow(PositionError(filter.CurrentEstimate().mean, truth), 2);
    }
    return std::sqrt(sq / kTail);
  };
  const double h = SilvermanFactor(50, 3);
  const SteadyState x =
      SteadyStateError(std::pow(0.05 * kMm, 2), (1 + h * h) * r(0, 0) + std::pow(0.1 * kMm, 2),
                       r(0, 0), velocity[0]);
  const double lag = (1 - x.gain) * velocity[0] / x.gain;
  ASSERT_GT(lag, 3 * 0.1 * kMm);  // the lag dominates the noise
  const double random_walk = run(false), constant_velocity = run(true);
  EXPECT_GT(random_walk, 0.7 * lag);
  // The constant-velocity filter's error is noise only: below the per-frame noise,
  // sqrt(2) * 0.1 mm, with 4 standard errors of a 20-frame RMSE.
  EXPECT_LT(constant_velocity, std::sqrt(2.0) * 0.1 * kMm * (1 + 4 * 0.5 * std::sqrt(2.0 / kTail)));
  EXPECT_LT(constant_velocity, 0.5 * random_walk);
}

TEST(SE2ParticleFilter, IsDeterministicGivenTheSeed) {
  const Matrix3d r = Diagonal(0.3 * kMm, 0.3 * kMm, 3 * kDeg);
  auto run = [&](std::uint64_t seed) {
    SE2ParticleFilter::Options options;
    options.num_particles = 300;
    options.seed = seed;
    options.constant_velocity = true;
    SE2ParticleFilter filter(options);
    MeasurementSource source(r, 40, 31);  // the same measurements for every filter seed
    for (int t = 0; t < 8; ++t) {
      filter.Predict();
      filter.Update(source.Around(SE2d::FromXYYaw(0.1 * kMm * t, 0, 0.02 * t)));
    }
    return std::make_pair(filter.particles(), filter.weights());
  };
  const auto a = run(42), b = run(42), c = run(43);
  ASSERT_EQ(a.first.size(), b.first.size());
  for (std::size_t i = 0; i < a.first.size(); ++i) {
    EXPECT_EQ(a.first[i].x(), b.first[i].x());
    EXPECT_EQ(a.first[i].y(), b.first[i].y());
    EXPECT_EQ(a.first[i].yaw(), b.first[i].yaw());
    EXPECT_EQ(a.second[i], b.second[i]);
  }
  int same = 0;
  for (std::size_t i = 0; i < a.first.size(); ++i) same += a.first[i].x() == c.first[i].x();
  EXPECT_EQ(same, 0);
}

TEST(SE2ParticleFilter, RejectsAMeasurementWithNoSamples) {
  PoseDistribution measurement({SE2d::FromXYYaw(0, 0, 0)});
  const PoseDistribution taken = std::move(measurement);  // leaves `measurement` empty
  SE2ParticleFilter filter;
  try {
    filter.Update(measurement);  // NOLINT(bugprone-use-after-move): the point of the test
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("the measurement has no samples"));
  }
  EXPECT_THROW(filter.Initialize(measurement), std::invalid_argument);
  EXPECT_FALSE(filter.initialized());
  EXPECT_EQ(taken.size(), 1);
}

TEST(SE2ParticleFilter, RejectsBadInitialStatesAndSteps) {
  SE2ParticleFilter filter;
  EXPECT_THROW(filter.Initialize(SE2d(), -Matrix3d::Identity()), std::invalid_argument);
  EXPECT_THROW(filter.Initialize(std::vector<SE2d>{}), std::invalid_argument);
  EXPECT_THROW(filter.Initialize({SE2d(), SE2d()}, {1.0}), std::invalid_argument);
  EXPECT_THROW(filter.Initialize({SE2d(), SE2d()}, {0.0, 0.0}), std::invalid_argument);
  EXPECT_THROW(filter.Posterior(), std::logic_error);
  EXPECT_THROW(filter.Predict(-1), std::invalid_argument);
  EXPECT_THROW(filter.Predict(std::numeric_limits<double>::quiet_NaN()), std::invalid_argument);
}

// A measurement 10 cm from every particle: its likelihood underflows everywhere the filter
// believes the tool may be. The update is refused, the weights stay as they were, nothing
// becomes NaN, and the summary counts it; a persistent disagreement re-initialises.
TEST(SE2ParticleFilter, KeepsThePriorWhenAMeasurementIsFarFromEveryParticle) {
  const Matrix3d r = Diagonal(0.3 * kMm, 0.3 * kMm, 3 * kDeg);
  SE2ParticleFilter::Options options;
  options.num_particles = 500;
  options.max_consecutive_rejections = 2;
  SE2ParticleFilter filter(options);
  MeasurementSource source(r, 50, 37);
  const SE2d truth = SE2d::FromXYYaw(0, 0, 0);
  for (int t = 0; t < 3; ++t) {
    filter.Predict();
    filter.Update(source.Around(truth));
  }
  const std::vector<double> before = filter.weights();
  const std::vector<SE2d> particles = filter.particles();
  const SE2d far_away = SE2d::FromXYYaw(0.1, -0.1, 2.0);
  for (int k = 0; k < 2; ++k) {
    const SE2ParticleFilter::UpdateSummary s = filter.Update(source.Around(far_away));
    EXPECT_EQ(s.type, PoseFilterUpdateType::kRejected) << s.BriefReport();
    EXPECT_THAT(s.message, HasSubstr("prior weights kept"));
    EXPECT_GT(s.min_squared_mahalanobis, options.gate_squared_mahalanobis);
    EXPECT_EQ(s.log_evidence, -std::numeric_limits<double>::infinity());
    EXPECT_EQ(filter.weights(), before);
    EXPECT_EQ(filter.particles().size(), particles.size());
    EXPECT_EQ(filter.summary().num_rejected, k + 1);
  }
  for (double w : filter.weights()) ASSERT_TRUE(std::isfinite(w));
  const SE2ParticleFilter::Estimate e = filter.CurrentEstimate();
  EXPECT_TRUE(e.mean.translation().allFinite() && std::isfinite(e.mean.yaw()));
  EXPECT_TRUE(e.covariance.allFinite());
  EXPECT_LT(PositionError(e.mean, truth), 1 * kMm);
  // The third in a row: the data win.
  const SE2ParticleFilter::UpdateSummary s = filter.Update(source.Around(far_away));
  EXPECT_EQ(s.type, PoseFilterUpdateType::kReinitialized) << s.BriefReport();
  EXPECT_EQ(filter.summary().num_reinitializations, 1);
  EXPECT_EQ(filter.summary().num_rejected, 2);
  EXPECT_LT(PositionError(filter.CurrentEstimate().mean, far_away), 1 * kMm);
  // An agreeing measurement resets the run of rejections.
  filter.Predict();
  EXPECT_EQ(filter.Update(source.Around(far_away)).type, PoseFilterUpdateType::kUpdated);
  EXPECT_EQ(filter.summary().consecutive_rejections, 0);
}

// Identical samples (a k-NN posterior whose nearest neighbour holds all the weight) have
// zero covariance; the floor keeps the kernel a proper density.
TEST(SE2ParticleFilter, UsesTheFloorCovarianceForACollapsedMeasurement) {
  SE2ParticleFilter::Options options;
  options.num_particles = 500;
  SE2ParticleFilter filter(options);
  const SE2d pose = SE2d::FromXYYaw(1 * kMm, 1 * kMm, -0.5);
  filter.Initialize(pose, Diagonal(0.5 * kMm, 0.5 * kMm, 5 * kDeg));
  const PoseDistribution collapsed(std::vector<SE2d>(20, pose * SE2d::Exp(Vector3d(2e-4, 0, 0))));
  const SE2ParticleFilter::UpdateSummary s = filter.Update(collapsed);
  EXPECT_EQ(s.type, PoseFilterUpdateType::kUpdated);
  EXPECT_TRUE(s.kernel_covariance.isApprox(options.floor_covariance, 1e-12));
  EXPECT_TRUE(std::isfinite(s.log_evidence));
  for (double w : filter.weights()) ASSERT_TRUE(std::isfinite(w));
  EXPECT_GT(filter.EffectiveSampleSize(), 1.0);
}

TEST(SE2ParticleFilter, ReportsTheEffectiveSampleSizeAndResamplesBelowTheThreshold) {
  SE2ParticleFilter::Options options;
  options.num_particles = 1000;
  options.resample_threshold = 0.5;
  SE2ParticleFilter filter(options);
  const SE2d pose = SE2d::FromXYYaw(0, 0, 0);
  // A wide prior and a sharp measurement: most particles lose their weight.
  filter.Initialize(pose, Diagonal(2 * kMm, 2 * kMm, 20 * kDeg));
  EXPECT_NEAR(filter.EffectiveSampleSize(), 1000, 1e-9 * 1000);
  MeasurementSource source(Diagonal(0.1 * kMm, 0.1 * kMm, 1 * kDeg), 50, 41);
  const SE2ParticleFilter::UpdateSummary s = filter.Update(source.Centred(pose));
  EXPECT_LT(s.ess_before_resampling, 500);
  EXPECT_TRUE(s.resampled);
  EXPECT_NEAR(s.ess, 1000, 1e-9 * 1000);
  EXPECT_EQ(filter.summary().num_resamples, 1);
  EXPECT_NEAR(filter.summary().last_ess, 1000, 1e-9 * 1000);
  // A broad measurement agreeing with the (now narrow) particles keeps most of the weight:
  // for a Gaussian prior P and likelihood R per axis, ESS / N = sqrt(R (2P + R)) / (P + R),
  // 0.97 over three axes at P / R ~ 0.2.
  filter.Predict(0);
  MeasurementSource broad(Diagonal(0.3 * kMm, 0.3 * kMm, 3 * kDeg), 50, 43);
  const SE2ParticleFilter::UpdateSummary t =
      filter.Update(broad.Centred(filter.CurrentEstimate().mean));
  EXPECT_GT(t.ess_before_resampling, 500);
  EXPECT_FALSE(t.resampled);
}

}  // namespace
}  // namespace tactfunc
