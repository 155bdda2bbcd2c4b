// Copyright 2026 The tactfunc Authors.
//
// PoseDistribution against distributions with known moments: samples x = mu * Exp(e),
// e ~ N(0, Sigma) (the header's concentrated Gaussian), drawn with a fixed seed.
//
// Tolerances come from the Monte Carlo error, never from a run:
//   * mean: N e^T Sigma^-1 e <= chi-square(3) 0.999-quantile (16.27), e = Log(mu^-1 m);
//   * covariance entry (j, k): |S_jk - Sigma_jk| <= 4 sqrt((Sigma_jj Sigma_kk +
//     Sigma_jk^2) / N), the standard error of a Gaussian sample covariance;
//   * coverage: a fresh draw falls in the p-region of T independent posteriors with a
//     frequency within p +- 2.576 sqrt(p (1 - p) / T) (binomial 99%).
#include "estimation/pose/pose_distribution.h"

#include <boost/math/distributions/chi_squared.hpp>
#include <boost/random/chi_squared_distribution.hpp>
#include <boost/random/mersenne_twister.hpp>
#include <boost/random/normal_distribution.hpp>
#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "Eigen/Cholesky"
#include "Eigen/LU"
#include "gtest/gtest.h"
#include "models/core/internal/checks.h"
#include "models/simulator/tool.h"

namespace tactfunc {
namespace {

using Eigen::Matrix3d;
using Eigen::Vector3d;
using internal::kPi;

// Draws mu * Exp(L z), z ~ N(0, I) (or a multivariate Student-t when dof > 0).
class TangentGaussian {
 public:
  TangentGaussian(const SE2d& mu, const Matrix3d& sigma, std::uint64_t seed, double dof = 0)
      : mu_(mu), l_(sigma.llt().matrixL()), rng_(seed), dof_(dof) {}
  SE2d Draw() {
    Vector3d z(normal_(rng_), normal_(rng_), normal_(rng_));
    if (dof_ > 0) {
      boost::random::chi_squared_distribution<double> chi2(dof_);
      z *= std::sqrt(dof_ / chi2(rng_));
    }
    return mu_ * SE2d::Exp(l_ * z);
  }
  std::vector<SE2d> Draw(int n) {
    std::vector<SE2d> samples;
    for (int i = 0; i < n; ++i) samples.push_back(Draw());
    return samples;
  }

 private:
  SE2d mu_;
  Matrix3d l_;
  boost::random::mt19937_64 rng_;
  boost::random::normal_distribution<double> normal_;
  double dof_;
};

// sigma_x = 2 mm, sigma_y = 1 mm, sigma_yaw = 0.2 rad, correlated.
Matrix3d ExampleSigma() {
  const Vector3d stddev(2e-3, 1e-3, 0.2);
  Matrix3d correlation;
  correlation << 1.0, 0.3, -0.4, 0.3, 1.0, 0.2, -0.4, 0.2, 1.0;
  return stddev.asDiagonal() * correlation * stddev.asDiagonal();
}

double Chi2Quantile(int dof, double p) {
  return boost::math::quantile(boost::math::chi_squared(dof), p);
}

void ExpectMeanWithinMonteCarloError(const SE2d& estimate, const SE2d& truth, const Matrix3d& sigma,
                                     double n) {
  const Vector3d e = (truth.Inverse() * estimate).Log();
  EXPECT_LE(n * e.dot(sigma.inverse() * e), Chi2Quantile(3, 0.999))
      << "estimate " << estimate << " truth " << truth;
}

void ExpectCovarianceWithinMonteCarloError(const Matrix3d& estimate, const Matrix3d& sigma,
                                           double n) {
  for (int j = 0; j < 3; ++j) {
    for (int k = 0; k < 3; ++k) {
      const double se = std::sqrt((sigma(j, j) * sigma(k, k) + sigma(j, k) * sigma(j, k)) / n);
      EXPECT_NEAR(estimate(j, k), sigma(j, k), 4 * se) << "entry (" << j << ", " << k << ")";
    }
  }
}

// ---- Options and inputs ---------------------------------------------------------------

TEST(PoseDistribution, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(PoseDistribution::MeanOptions().IsValid(&error)) << error;
  EXPECT_TRUE(PoseDistribution::RegionOptions().IsValid(&error)) << error;
  EXPECT_TRUE(PoseDistribution::ModeOptions().IsValid(&error)) << error;
}

TEST(PoseDistribution, BadOptionsNameTheField) {
  std::string error;
  PoseDistribution::MeanOptions mean;
  mean.max_iterations = 0;
  EXPECT_FALSE(mean.IsValid(&error));
  EXPECT_NE(error.find("max_iterations"), std::string::npos) << error;
  mean = {};
  mean.angle_tolerance = -1;
  EXPECT_FALSE(mean.IsValid(&error));
  EXPECT_NE(error.find("angle_tolerance"), std::string::npos) << error;
  PoseDistribution::ModeOptions modes;
  modes.yaw_bandwidth = 4.0;
  EXPECT_FALSE(modes.IsValid(&error));
  EXPECT_NE(error.find("yaw_bandwidth"), std::string::npos) << error;
  modes = {};
  modes.translation_bandwidth = 0;
  EXPECT_FALSE(modes.IsValid(&error));
  EXPECT_NE(error.find("translation_bandwidth"), std::string::npos) << error;
  PoseDistribution::RegionOptions region;
  region.mean.translation_tolerance = std::nan("");
  EXPECT_FALSE(region.IsValid(&error));
  EXPECT_NE(error.find("mean"), std::string::npos) << error;
  // Functions taking options throw with the same message.
  const PoseDistribution d({SE2d(), SE2d::Trans(1, 0)});
  EXPECT_THROW(d.Modes(modes), std::invalid_argument);
}

TEST(PoseDistribution, WeightsAreNormalisedAndEffectiveSampleSizeIsKish) {
  const PoseDistribution d({SE2d(), SE2d::Trans(1, 0), SE2d::Trans(2, 0)}, {1.0, 1.0, 2.0});
  EXPECT_DOUBLE_EQ(d.weights()[0], 0.25);
  EXPECT_DOUBLE_EQ(d.weights()[2], 0.5);
  EXPECT_DOUBLE_EQ(d.EffectiveSampleSize(), 1.0 / (0.0625 + 0.0625 + 0.25));
  EXPECT_DOUBLE_EQ(PoseDistribution(std::vector<SE2d>(7)).EffectiveSampleSize(), 7.0);
}

TEST(PoseDistribution, RejectsEmptyNonFiniteAndBadlyWeightedInputs) {
  auto message_of = [](auto&& make) {
    try {
      make();
    } catch (const std::invalid_argument& e) {
      return std::string(e.what());
    }
    return std::string("no exception");
  };
  EXPECT_NE(message_of([] { PoseDistribution({}); }).find("at least one sample"),
            std::string::npos);
  const std::string nan_message = message_of([] {
    PoseDistribution({SE2d(), SE2d(), SE2d::FromXYYaw(std::nan(""), 0, 0)});
  });
  EXPECT_NE(nan_message.find("sample 2"), std::string::npos) << nan_message;
  EXPECT_NE(nan_message.find("x=nan"), std::string::npos) << nan_message;
  EXPECT_NE(message_of([] { PoseDistribution({SE2d::Rot(std::nan(""))}); }).find("sample 0"),
            std::string::npos);
  EXPECT_NE(message_of([] {
              PoseDistribution({SE2d(), SE2d()}, {0.0, 0.0});
            }).find("all be zero"),
            std::string::npos);
  EXPECT_NE(message_of([] {
              PoseDistribution({SE2d(), SE2d()}, {1.0, -1.0});
            }).find("weight 1"),
            std::string::npos);
  EXPECT_NE(message_of([] {
              PoseDistribution({SE2d(), SE2d()}, {1.0, std::nan("")});
            }).find("weight 1"),
            std::string::npos);
  EXPECT_NE(message_of([] {
              PoseDistribution({SE2d(), SE2d()}, {1.0});
            }).find("expected 2"),
            std::string::npos);
  const PoseDistribution d({SE2d(), SE2d::Trans(1, 0)});
  for (double p : {0.0, -0.5, 1.5, std::nan("")}) {
    EXPECT_THROW(d.Contains(SE2d(), p), std::invalid_argument) << p;
  }
  EXPECT_THROW(d.FoldedBySymmetry(-1), std::invalid_argument);
}

// ---- Mean and covariance -----------------------------------------------------------

TEST(PoseDistribution, MeanOfTangentGaussianSamplesRecoversMuWithinMonteCarloError) {
  const SE2d mu = SE2d::FromXYYaw(0.01, -0.02, 0.7);
  const Matrix3d sigma = ExampleSigma();
  const int n = 4000;
  TangentGaussian draw(mu, sigma, /*seed=*/1);
  const PoseDistribution d(draw.Draw(n));
  PoseDistribution::MeanSummary summary;
  const SE2d mean = d.Mean(PoseDistribution::MeanOptions(), &summary);
  EXPECT_TRUE(summary.converged()) << summary.BriefReport();
  EXPECT_LE(summary.iterations, 10) << summary.BriefReport();
  ExpectMeanWithinMonteCarloError(mean, mu, sigma, n);
  // The barycentre condition holds at the result.
  Vector3d residual = Vector3d::Zero();
  for (int i = 0; i < d.size(); ++i)
    residual += d.weights()[i] * (mean.Inverse() * d.samples()[i]).Log();
  EXPECT_LE(residual.head<2>().norm(), 1e-10);
  EXPECT_LE(std::abs(residual[2]), 1e-10);
}

TEST(PoseDistribution, CovarianceOfTangentGaussianSamplesRecoversSigmaWithinMonteCarloError) {
  const SE2d mu = SE2d::FromXYYaw(-0.03, 0.005, -2.0);
  const Matrix3d sigma = ExampleSigma();
  const int n = 4000;
  TangentGaussian draw(mu, sigma, /*seed=*/2);
  const PoseDistribution d(draw.Draw(n));
  ExpectCovarianceWithinMonteCarloError(d.Covariance(), sigma, n);
}

TEST(PoseDistribution, WeightsActAsRepetitions) {
  TangentGaussian draw(SE2d::FromXYYaw(0.1, 0.2, 0.3), ExampleSigma(), /*seed=*/3);
  const std::vector<SE2d> s = draw.Draw(3);
  const PoseDistribution weighted({s[0], s[1], s[2]}, {2.0, 1.0, 1.0});
  const PoseDistribution repeated({s[0], s[0], s[1], s[2]});
  EXPECT_TRUE(weighted.Mean().IsApprox(repeated.Mean(), 1e-14));
  // The covariances differ only by the unbiased correction: 1 - sum w^2 is 5/8 vs 3/4.
  EXPECT_TRUE(
      (weighted.Covariance() * 5.0 / 8.0).isApprox(repeated.Covariance() * 3.0 / 4.0, 1e-12));
}

TEST(PoseDistribution, ZeroWeightSamplesAreIgnored) {
  TangentGaussian draw(SE2d::FromXYYaw(0.1, 0.2, 0.3), ExampleSigma(), /*seed=*/4);
  std::vector<SE2d> s = draw.Draw(50);
  const PoseDistribution without(s);
  s.push_back(SE2d::FromXYYaw(5.0, -5.0, -3.0));
  std::vector<double> w(50, 1.0);
  w.push_back(0.0);
  const PoseDistribution with(s, w);
  EXPECT_TRUE(with.Mean().IsApprox(without.Mean(), 1e-14));
  EXPECT_TRUE(with.Covariance().isApprox(without.Covariance(), 1e-12));
}

TEST(PoseDistribution, MeanOfSamplesAroundPiStaysNearPi) {
  for (double yaw : {kPi - 0.01, kPi, -kPi + 0.02}) {
    const SE2d mu = SE2d::FromXYYaw(0.0, 0.0, yaw);
    Matrix3d sigma = Vector3d(1e-3, 1e-3, 0.1).cwiseAbs2().asDiagonal();
    const int n = 2000;
    TangentGaussian draw(mu, sigma, /*seed=*/5);
    const PoseDistribution d(draw.Draw(n));
    const SE2d mean = d.Mean();
    EXPECT_GT(std::abs(mean.yaw()), 3.0) << "yaw " << yaw << " -> " << mean;
    ExpectMeanWithinMonteCarloError(mean, mu, sigma, n);
  }
}

TEST(PoseDistribution, NonConvergenceIsReportedNotThrown) {
  TangentGaussian draw(SE2d::FromXYYaw(0.1, 0.2, 0.3), ExampleSigma(), /*seed=*/6);
  const PoseDistribution d(draw.Draw(100));
  PoseDistribution::MeanOptions options;
  options.max_iterations = 1;
  options.translation_tolerance = 0;
  options.angle_tolerance = 0;
  PoseDistribution::MeanSummary summary;
  d.Mean(options, &summary);
  EXPECT_FALSE(summary.converged());
  EXPECT_EQ(summary.iterations, 1);
  EXPECT_NE(summary.BriefReport().find("NO_CONVERGENCE"), std::string::npos);
}

// ---- Degenerate inputs -------------------------------------------------------------

TEST(PoseDistribution, OneSampleIsAPointMass) {
  const SE2d pose = SE2d::FromXYYaw(0.01, -0.02, 3.1);
  const PoseDistribution d({pose});
  EXPECT_TRUE(d.Mean().IsApprox(pose, 1e-15));
  EXPECT_TRUE(d.Covariance().isZero(0.0));
  EXPECT_TRUE(d.Contains(pose, 0.5));
  EXPECT_TRUE(d.Contains(pose, 0.5, {PoseDistribution::RegionMethod::kGaussian, {}}));
  EXPECT_FALSE(d.Contains(pose * SE2d::Trans(1e-6, 0), 0.99));
  EXPECT_EQ(d.Modes().size(), 1u);
  EXPECT_DOUBLE_EQ(d.Modes()[0].weight, 1.0);
}

TEST(PoseDistribution, IdenticalSamplesAreAPointMass) {
  const SE2d pose = SE2d::FromXYYaw(0.3, 0.1, -kPi + 1e-3);
  const PoseDistribution d(std::vector<SE2d>(25, pose));
  PoseDistribution::MeanSummary summary;
  EXPECT_TRUE(d.Mean({}, &summary).IsApprox(pose, 1e-14));
  EXPECT_TRUE(summary.converged());
  EXPECT_LE(d.Covariance().cwiseAbs().maxCoeff(), 1e-28);
  const auto region = d.Region(0.9);
  EXPECT_EQ(region.rank(), 0);
  EXPECT_TRUE(region.Contains(pose));
  EXPECT_FALSE(region.Contains(pose * SE2d::Rot(1e-6)));
}

// ---- Credible regions ----------------------------------------------------------------

// Frequency with which a fresh draw lies in the p-region of `trials` posteriors, each
// of `n` samples from the same distribution as the draw.
double Coverage(double p, PoseDistribution::RegionMethod method, double dof, int trials, int n,
                std::uint64_t seed) {
  const SE2d mu = SE2d::FromXYYaw(0.02, -0.01, 2.5);
  TangentGaussian draw(mu, ExampleSigma(), seed, dof);
  int inside = 0;
  for (int t = 0; t < trials; ++t) {
    const PoseDistribution d(draw.Draw(n));
    inside += d.Contains(draw.Draw(), p, {method, {}}) ? 1 : 0;
  }
  return static_cast<double>(inside) / trials;
}

double BinomialHalfWidth99(double p, int trials) { return 2.576 * std::sqrt(p * (1 - p) / trials); }

TEST(PoseDistribution, SampleQuantileRegionHasItsNominalCoverage) {
  const int trials = 2000, n = 500;
  for (double p : {0.5, 0.9}) {
    const double frequency =
        Coverage(p, PoseDistribution::RegionMethod::kSampleQuantile, 0, trials, n, 7);
    EXPECT_NEAR(frequency, p, BinomialHalfWidth99(p, trials)) << "p = " << p;
  }
}

TEST(PoseDistribution, GaussianRegionHasItsNominalCoverageForGaussianPosteriors) {
  const int trials = 2000, n = 500;
  const double p = 0.9;
  const double frequency = Coverage(p, PoseDistribution::RegionMethod::kGaussian, 0, trials, n, 8);
  EXPECT_NEAR(frequency, p, BinomialHalfWidth99(p, trials));
}

TEST(PoseDistribution, SampleQuantileRegionStaysCalibratedForHeavyTails) {
  // A Student-t posterior (3 degrees of freedom): the sample-quantile region keeps its
  // coverage; the chi-square one does not (it over-covers at p = 0.5), which is why
  // kSampleQuantile is the default.
  const int trials = 2000, n = 500;
  const double p = 0.5;
  const double sample =
      Coverage(p, PoseDistribution::RegionMethod::kSampleQuantile, 3, trials, n, 9);
  EXPECT_NEAR(sample, p, BinomialHalfWidth99(p, trials));
  const double gaussian = Coverage(p, PoseDistribution::RegionMethod::kGaussian, 3, trials, n, 9);
  EXPECT_GT(std::abs(gaussian - p), BinomialHalfWidth99(p, trials)) << gaussian;
}

TEST(PoseDistribution, RegionThresholdIsTheWeightedQuantileOfSampleDistances) {
  TangentGaussian draw(SE2d::FromXYYaw(0.1, 0.2, 0.3), ExampleSigma(), /*seed=*/10);
  const PoseDistribution d(draw.Draw(200));
  const auto region = d.Region(0.8);
  int inside = 0;
  for (const SE2d& s : d.samples()) inside += region.Contains(s) ? 1 : 0;
  EXPECT_EQ(inside, 160);  // exactly 80 % of 200 equally weighted samples
  EXPECT_TRUE(
      std::isinf(d.Region(1.0, {PoseDistribution::RegionMethod::kGaussian, {}}).threshold()));
  int all = 0;
  const auto full = d.Region(1.0);
  for (const SE2d& s : d.samples()) all += full.Contains(s) ? 1 : 0;
  EXPECT_EQ(all, 200);
}

// ---- Modes --------------------------------------------------------------------------

TEST(PoseDistribution, HalfTurnSymmetricPosteriorShowsTwoModesWithEqualWeights) {
  // A rod (C_2) at yaw 0.3: the posterior puts equal mass on 0.3 and 0.3 - pi.
  const SE2d a = SE2d::FromXYYaw(0.004, -0.002, 0.3);
  const SE2d b = SE2d::FromXYYaw(0.004, -0.002, 0.3 - kPi);
  const Matrix3d sigma = Vector3d(5e-4, 5e-4, 0.05).cwiseAbs2().asDiagonal();
  const int n = 300;
  TangentGaussian draw_a(a, sigma, 11), draw_b(b, sigma, 12);
  std::vector<SE2d> samples = draw_a.Draw(n);
  for (const SE2d& s : draw_b.Draw(n)) samples.push_back(s);
  const PoseDistribution d(samples);
  const std::vector<PoseMode> modes = d.Modes();
  ASSERT_EQ(modes.size(), 2u);
  // Well separated: every sample goes to its own mode, so weights are exactly 1/2.
  EXPECT_NEAR(modes[0].weight, 0.5, 1e-12);
  EXPECT_NEAR(modes[1].weight, 0.5, 1e-12);
  EXPECT_EQ(modes[0].num_samples, n);
  const bool first_is_a = std::abs(modes[0].mean.yaw() - 0.3) < 1.0;
  ExpectMeanWithinMonteCarloError(modes[first_is_a ? 0 : 1].mean, a, sigma, n);
  ExpectMeanWithinMonteCarloError(modes[first_is_a ? 1 : 0].mean, b, sigma, n);
  ExpectCovarianceWithinMonteCarloError(modes[0].covariance, sigma, n);
  // The plain mean of such a set is meaningless; folded by the symmetry it is one mode.
  const PoseDistribution folded = d.FoldedBySymmetry(GetTool("rod").symmetry_order());
  ASSERT_EQ(folded.Modes().size(), 1u);
  EXPECT_LE(YawErrorModuloSymmetry(folded.Mean().yaw(), 0.3, 2), 4 * 0.05 / std::sqrt(2.0 * n));
}

TEST(PoseDistribution, SingleModeIsFoundAsOne) {
  const SE2d mu = SE2d::FromXYYaw(0.01, 0.0, kPi - 0.05);  // straddles +-pi
  const Matrix3d sigma = Vector3d(1e-3, 2e-3, 0.1).cwiseAbs2().asDiagonal();
  const int n = 800;
  TangentGaussian draw(mu, sigma, 13);
  const PoseDistribution d(draw.Draw(n));
  const std::vector<PoseMode> modes = d.Modes();
  ASSERT_EQ(modes.size(), 1u);
  EXPECT_NEAR(modes[0].weight, 1.0, 1e-12);  // a sum of n weights 1/n
  EXPECT_EQ(modes[0].num_samples, n);
  ExpectMeanWithinMonteCarloError(modes[0].mean, mu, sigma, n);
}

TEST(PoseDistribution, SeedSubsetFindsTheSameModes) {
  const Matrix3d sigma = Vector3d(5e-4, 5e-4, 0.05).cwiseAbs2().asDiagonal();
  TangentGaussian draw_a(SE2d::FromXYYaw(0, 0, 1.0), sigma, 14);
  TangentGaussian draw_b(SE2d::FromXYYaw(0.02, 0, 1.0), sigma, 15);
  std::vector<SE2d> samples = draw_a.Draw(200);
  for (const SE2d& s : draw_b.Draw(100)) samples.push_back(s);
  PoseDistribution::ModeOptions options;
  options.max_seeds = 30;
  const std::vector<PoseMode> modes = PoseDistribution(samples).Modes(options);
  ASSERT_EQ(modes.size(), 2u);
  EXPECT_NEAR(modes[0].weight, 2.0 / 3.0, 1e-12);
  EXPECT_NEAR(modes[1].weight, 1.0 / 3.0, 1e-12);
}

// ---- Symmetry -----------------------------------------------------------------------

TEST(PoseDistribution, FoldYawMapsIntoTheFundamentalInterval) {
  EXPECT_NEAR(FoldYaw(kPi / 2 + 0.1, 2), -kPi / 2 + 0.1, 1e-15);
  EXPECT_NEAR(FoldYaw(0.1 + kPi, 2), 0.1, 1e-15);
  EXPECT_NEAR(FoldYaw(2 * kPi / 3 + 0.2, 3), 0.2, 1e-15);
  EXPECT_NEAR(FoldYaw(kPi, 1), -kPi, 1e-15);  // [-pi, pi)
  EXPECT_NEAR(FoldYaw(-0.3, 1), -0.3, 1e-15);
  EXPECT_EQ(FoldYaw(1.234, 0), 0.0);
  for (int n : {1, 2, 3, 4}) {
    for (double yaw = -10; yaw < 10; yaw += 0.37) {
      const double f = FoldYaw(yaw, n);
      EXPECT_GE(f, -kPi / n);
      EXPECT_LT(f, kPi / n);
      EXPECT_NEAR(YawErrorModuloSymmetry(f, yaw, n), 0.0, 1e-12);
    }
  }
  EXPECT_THROW(FoldYaw(0.0, -1), std::invalid_argument);
}

TEST(PoseDistribution, FoldingKeepsACloudAtTheFoldBoundaryTogether) {
  // A square (C_4) near yaw pi/4, the boundary of [-pi/4, pi/4): folding onto fixed
  // intervals would split it; folding about the circular mean of 4 yaw does not.
  const SE2d mu = SE2d::FromXYYaw(0.0, 0.0, kPi / 4);
  const Matrix3d sigma = Vector3d(1e-3, 1e-3, 0.05).cwiseAbs2().asDiagonal();
  const int n = 1000;
  TangentGaussian draw(mu, sigma, 16);
  std::vector<SE2d> samples = draw.Draw(n);
  for (std::size_t i = 0; i < samples.size(); i += 3) samples[i] = samples[i] * SE2d::Rot(kPi / 2);
  const PoseDistribution folded = PoseDistribution(samples).FoldedBySymmetry(4);
  EXPECT_EQ(folded.Modes().size(), 1u);
  EXPECT_LE(YawErrorModuloSymmetry(folded.Mean().yaw(), kPi / 4, 4), 4 * 0.05 / std::sqrt(n));
  // Folding changes yaw only (the symmetry axis is the object origin).
  for (int i = 0; i < n; ++i) {
    EXPECT_EQ(folded.samples()[i].x(), samples[i].x());
    EXPECT_NEAR(YawErrorModuloSymmetry(folded.samples()[i].yaw(), samples[i].yaw(), 4), 0, 1e-12);
  }
}

TEST(PoseDistribution, ContinuousSymmetryZeroesTheYaw) {
  TangentGaussian draw(SE2d::FromXYYaw(0.01, 0.0, 1.0), ExampleSigma(), 17);
  const PoseDistribution folded =
      PoseDistribution(draw.Draw(100)).FoldedBySymmetry(GetTool("hemisphere").symmetry_order());
  for (const SE2d& s : folded.samples()) EXPECT_EQ(s.yaw(), 0.0);
  const Matrix3d c = folded.Covariance();
  EXPECT_EQ(c(2, 2), 0.0);
  EXPECT_GT(c(0, 0), 0.0);
}

// ---- ROS ----------------------------------------------------------------------------

TEST(PoseDistribution, RosCovarianceUsesIndices015AndTheParentFrame) {
  Matrix3d sigma;
  sigma << 4.0, 0.5, 0.1, 0.5, 1.0, 0.2, 0.1, 0.2, 0.09;
  const SE2d mean = SE2d::FromXYYaw(1.0, 2.0, kPi / 2);
  const auto body = ToRosPoseCovariance(mean, sigma, RosCovarianceFrame::kBody, 7.0);
  EXPECT_EQ(body[0], 4.0);
  EXPECT_EQ(body[1], 0.5);
  EXPECT_EQ(body[5], 0.1);
  EXPECT_EQ(body[6 * 5 + 1], 0.2);
  EXPECT_EQ(body[35], 0.09);
  EXPECT_EQ(body[14], 7.0);
  EXPECT_EQ(body[21], 7.0);
  EXPECT_EQ(body[28], 7.0);
  EXPECT_EQ(body[2], 0.0);
  // Turned by 90 deg, body x is parent y: the x and y variances swap.
  const auto parent = ToRosPoseCovariance(mean, sigma);
  EXPECT_NEAR(parent[0], 1.0, 1e-15);
  EXPECT_NEAR(parent[7], 4.0, 1e-15);
  EXPECT_NEAR(parent[1], -0.5, 1e-15);
  EXPECT_NEAR(parent[5], -0.2, 1e-15);  // parent x = -body y
  EXPECT_NEAR(parent[11], 0.1, 1e-15);  // parent y = body x
  EXPECT_EQ(parent[35], 0.09);
  EXPECT_EQ(parent[14], 0.0);
}

}  // namespace
}  // namespace tactfunc
