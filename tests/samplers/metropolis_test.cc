// Copyright 2026 The tactfunc Authors.
//
// The Metropolis kernels (samplers/metropolis.h) on targets with known moments: a
// correlated 4-d Gaussian sampled with a mismatched preconditioner, a banana (whose x2
// mean and variance a wrong proposal-density ratio biases), a von Mises angle centred
// next to the wrap, and the seed contract. Tolerances are Monte Carlo errors from the
// sampler's own ESS (5 standard errors). With MALA's proposal-density ratio left out, or
// inverted, the Gaussian and banana tests fail (checked when they were written).
#include "samplers/metropolis.h"

#include <cmath>
#include <vector>

#include <Eigen/Dense>
#include <boost/math/special_functions/bessel.hpp>
#include <gtest/gtest.h>

#include "samplers/sgld.h"

namespace tactfunc {
namespace {

const MetropolisKernel kKernels[] = {MetropolisKernel::kMala, MetropolisKernel::kRandomWalk};

MetropolisOptions LongRun(MetropolisKernel kernel) {
  MetropolisOptions o;
  o.kernel = kernel;
  o.burn_in = 500;
  o.num_samples_per_chain = 4000;
  o.seed = 7;
  return o;
}

TEST(MetropolisTest, GaussianMomentsMatchWithAMismatchedPreconditioner) {
  Eigen::Vector4d mean(1.0, -2.0, 0.5, 3.0);
  Eigen::Matrix4d a;
  a << 1.0, 0.0, 0.0, 0.0, 0.8, 0.6, 0.0, 0.0, -0.3, 0.2, 0.5, 0.0, 0.1, -0.4, 0.3, 2.0;
  const Eigen::Matrix4d cov = a * a.transpose();
  const Eigen::Matrix4d precision = cov.inverse();
  const LogDensityFunction log_p = [&](const Eigen::VectorXd& x, Eigen::VectorXd* g) {
    const Eigen::Vector4d d = x - mean;
    if (g != nullptr) *g = -precision * d;
    return -0.5 * d.dot(precision * d);
  };
  // Preconditioner: the diagonal of the covariance, doubled (ignores the correlations).
  const Eigen::MatrixXd pre = Eigen::Matrix4d(2 * cov.diagonal().asDiagonal());
  for (MetropolisKernel kernel : kKernels) {
    SCOPED_TRACE(ToString(kernel));
    const MetropolisResult r = SampleMetropolis(log_p, Eigen::Vector4d::Zero(), pre, LongRun(kernel));
    const Eigen::MatrixXd s = r.Stacked();
    const Eigen::Vector4d m = s.colwise().mean();
    const Eigen::MatrixXd c = s.rowwise() - m.transpose();
    const Eigen::Matrix4d sample_cov = c.transpose() * c / (s.rows() - 1);
    const double ess = r.effective_sample_size.minCoeff();
    EXPECT_GT(ess, 300);
    EXPECT_LT(r.MaxSplitRhat(), 1.05);
    const double target = kernel == MetropolisKernel::kMala ? 0.574 : 0.234;
    EXPECT_NEAR(r.MeanAcceptance(), target, 0.1);
    for (int i = 0; i < 4; ++i) {
      EXPECT_NEAR(m[i], mean[i], 5 * std::sqrt(cov(i, i) / r.effective_sample_size[i])) << i;
      for (int j = 0; j < 4; ++j) {
        const double se = std::sqrt((cov(i, i) * cov(j, j) + cov(i, j) * cov(i, j)) / ess);
        EXPECT_NEAR(sample_cov(i, j), cov(i, j), 5 * se) << i << ", " << j;
      }
    }
  }
}

// x1 ~ N(0, 1), x2 | x1 ~ N(b (x1^2 - 1), 1), b = 1: E x2 = 0, var x2 = 1 + 2 b^2 = 3,
// E x1^2 = 1; x3, x4 ~ N(0, 1) beside. Strongly non-Gaussian: the MALA drift differs
// a lot between x and x', so a wrong ratio q(x | x') / q(x' | x) shows in these moments.
TEST(MetropolisTest, BananaMomentsMatch) {
  const LogDensityFunction log_p = [](const Eigen::VectorXd& x, Eigen::VectorXd* g) {
    const double u = x[1] - (x[0] * x[0] - 1);
    if (g != nullptr) {
      *g = Eigen::Vector4d(-x[0] + 2 * x[0] * u, -u, -x[2], -x[3]);
    }
    return -0.5 * (x[0] * x[0] + u * u + x[2] * x[2] + x[3] * x[3]);
  };
  for (MetropolisKernel kernel : kKernels) {
    SCOPED_TRACE(ToString(kernel));
    MetropolisOptions o = LongRun(kernel);
    o.num_samples_per_chain = 10000;
    const MetropolisResult r =
        SampleMetropolis(log_p, Eigen::Vector4d::Zero(), Eigen::Matrix4d::Identity(), o);
    const Eigen::MatrixXd s = r.Stacked();
    const double ess = r.effective_sample_size.head<2>().minCoeff();
    EXPECT_GT(ess, 300);
    const double m2 = s.col(1).mean();
    const double v2 = (s.col(1).array() - m2).square().mean();
    const double x1sq = s.col(0).array().square().mean();
    EXPECT_NEAR(m2, 0.0, 5 * std::sqrt(3 / ess));
    EXPECT_NEAR(v2, 3.0, 5 * std::sqrt(66 / ess));  // var(x2^2) = E x2^4 - 9 = 66
    EXPECT_NEAR(x1sq, 1.0, 5 * std::sqrt(2 / ess));
  }
}

// A von Mises angle, kappa = 2, centred at 3.0 rad (the wrap at pi is 0.14 rad away):
// E cos(theta - mu) = I1(kappa) / I0(kappa), E sin(theta - mu) = 0.
TEST(MetropolisTest, VonMisesAngleAcrossTheWrap) {
  const double kappa = 2, mu = 3.0;
  const LogDensityFunction log_p = [&](const Eigen::VectorXd& x, Eigen::VectorXd* g) {
    if (g != nullptr) *g = Eigen::VectorXd::Constant(1, -kappa * std::sin(x[0] - mu));
    return kappa * std::cos(x[0] - mu);
  };
  const double expected_cos =
      boost::math::cyl_bessel_i(1, kappa) / boost::math::cyl_bessel_i(0, kappa);
  for (MetropolisKernel kernel : kKernels) {
    SCOPED_TRACE(ToString(kernel));
    MetropolisOptions o = LongRun(kernel);
    o.angles = {0};
    const MetropolisResult r = SampleMetropolis(log_p, Eigen::VectorXd::Constant(1, mu),
                                                Eigen::MatrixXd::Constant(1, 1, 1 / kappa), o);
    const Eigen::MatrixXd s = r.Stacked();
    EXPECT_GT(s.col(0).maxCoeff(), 3.1);   // both sides of the wrap are visited
    EXPECT_LT(s.col(0).minCoeff(), -3.1);
    EXPECT_LE(s.col(0).maxCoeff(), M_PI);
    EXPECT_GT(s.col(0).minCoeff(), -M_PI);
    const double ess = r.effective_sample_size[0];
    EXPECT_GT(ess, 300);
    EXPECT_LT(r.split_rhat[0], 1.05);  // folded near mu: the wrap is no jump
    const double c = (s.col(0).array() - mu).cos().mean();
    const double sn = (s.col(0).array() - mu).sin().mean();
    EXPECT_NEAR(c, expected_cos, 5 * std::sqrt(0.5 / ess));
    EXPECT_NEAR(sn, 0.0, 5 * std::sqrt(0.5 / ess));
  }
}

// Two well separated modes (weights 0.3 and 0.7) over (angle, x): mode A centred at
// angle 3.0, across the wrap, mode B at -1.2, each 0.15 rad wide, so local moves never
// cross between them. Mode jumps from a proposal whose weights are wrong on purpose
// (0.8 / 0.2) and whose means and widths are off must still give each mode its mass:
// the MH ratio with q's density corrects q. Dropping q's ratio gives ~0.8 / 0.2.
TEST(MetropolisTest, ModeJumpsGiveEachModeItsMass) {
  const double wa = 0.3, wb = 0.7, s = 0.15;
  const Eigen::Vector2d ma(3.0, 1.0), mb(-1.2, -1.0);
  auto wrap = [](double a) { return std::remainder(a, 2 * M_PI); };
  auto log_normal = [&](const Eigen::VectorXd& x, const Eigen::Vector2d& m, Eigen::Vector2d* g) {
    const Eigen::Vector2d d(wrap(x[0] - m[0]), x[1] - m[1]);
    if (g != nullptr) *g = -d / (s * s);
    return -0.5 * d.squaredNorm() / (s * s);
  };
  const LogDensityFunction log_p = [&](const Eigen::VectorXd& x, Eigen::VectorXd* g) {
    Eigen::Vector2d ga, gb;
    const double la = std::log(wa) + log_normal(x, ma, &ga);
    const double lb = std::log(wb) + log_normal(x, mb, &gb);
    const double top = std::max(la, lb);
    const double pa = std::exp(la - top), pb = std::exp(lb - top);
    if (g != nullptr) *g = (pa * ga + pb * gb) / (pa + pb);
    return top + std::log(pa + pb);
  };
  const Eigen::MatrixXd cov = Eigen::Matrix2d::Identity() * s * s;
  for (MetropolisKernel kernel : kKernels) {
    SCOPED_TRACE(ToString(kernel));
    MetropolisOptions o = LongRun(kernel);
    o.angles = {0};
    // Without jumps every chain stays in the mode it starts in (B).
    const MetropolisResult local = SampleMetropolis(log_p, mb, cov, o);
    const Eigen::MatrixXd sl = local.Stacked();
    EXPECT_EQ(((sl.col(1).array() > 0).cast<double>()).sum(), 0.0);

    o.jump_probability = 0.2;
    o.jumps = {{0.8, Eigen::Vector2d(3.1, 0.9), cov * 3.0},
               {0.2, Eigen::Vector2d(-1.1, -1.1), cov * 2.0}};
    const MetropolisResult r = SampleMetropolis(log_p, mb, cov, o);
    std::vector<Eigen::VectorXd> in_a;
    for (const Eigen::MatrixXd& chain : r.chains) {
      in_a.push_back((chain.col(1).array() > 0).cast<double>().matrix());
    }
    const double ess = EffectiveSampleSize(in_a);
    const Eigen::MatrixXd all = r.Stacked();
    const double share = (all.col(1).array() > 0).cast<double>().mean();
    EXPECT_GT(ess, 200);
    EXPECT_NEAR(share, wa, 5 * std::sqrt(wa * wb / ess));
    EXPECT_GT(r.JumpAcceptance(), 0.05);
    // Both modes keep their own spread: mode A's angles straddle the wrap.
    EXPECT_GT(all.col(0).maxCoeff(), 3.1);
    EXPECT_LT(all.col(0).minCoeff(), -3.1);
  }
}

TEST(MetropolisTest, SameSeedSameSamples) {
  const LogDensityFunction log_p = [](const Eigen::VectorXd& x, Eigen::VectorXd* g) {
    if (g != nullptr) *g = -x;
    return -0.5 * x.squaredNorm();
  };
  for (MetropolisKernel kernel : kKernels) {
    MetropolisOptions o;
    o.kernel = kernel;
    o.burn_in = 50;
    o.num_samples_per_chain = 50;
    o.seed = 3;
    const Eigen::MatrixXd cov = Eigen::Matrix2d::Identity();
    const MetropolisResult a = SampleMetropolis(log_p, Eigen::Vector2d::Zero(), cov, o);
    const MetropolisResult b = SampleMetropolis(log_p, Eigen::Vector2d::Zero(), cov, o);
    EXPECT_EQ(a.Stacked(), b.Stacked());
    o.seed = 4;
    const MetropolisResult c = SampleMetropolis(log_p, Eigen::Vector2d::Zero(), cov, o);
    EXPECT_NE(a.Stacked(), c.Stacked());
  }
}

TEST(MetropolisTest, RejectsBadInputsNamingThem) {
  const LogDensityFunction log_p = [](const Eigen::VectorXd& x, Eigen::VectorXd*) { return 0.0; };
  MetropolisOptions o;
  o.num_samples_per_chain = 2;
  EXPECT_THROW(SampleMetropolis(log_p, Eigen::Vector2d::Zero(), Eigen::Matrix2d::Identity(), o),
               std::invalid_argument);
  o = MetropolisOptions();
  o.angles = {5};
  EXPECT_THROW(SampleMetropolis(log_p, Eigen::Vector2d::Zero(), Eigen::Matrix2d::Identity(), o),
               std::invalid_argument);
  EXPECT_THROW(SampleMetropolis(log_p, Eigen::Vector2d::Zero(), -Eigen::Matrix2d::Identity(),
                                MetropolisOptions()),
               std::invalid_argument);
  MetropolisKernel k;
  EXPECT_FALSE(ParseMetropolisKernel("hmc", &k));
  EXPECT_TRUE(ParseMetropolisKernel("rwm", &k));
  EXPECT_EQ(k, MetropolisKernel::kRandomWalk);
}

}  // namespace
}  // namespace tactfunc
