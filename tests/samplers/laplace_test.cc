// Copyright 2026 The tactfunc Authors.
#include "samplers/laplace.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include <Eigen/Dense>
#include <boost/random/mersenne_twister.hpp>
#include <boost/random/normal_distribution.hpp>
#include <gtest/gtest.h>

#include "tests/support/sampler_test_util.h"

namespace tactfunc {
namespace {

using testing_util::kSigmas;

// A linear-Gaussian model through the LatentPotential interface: residuals
// r(z) = (A z - y) / sigma, prior N(0, sigma_z^2 I). Its posterior is exactly Gaussian.
class LinearPotential : public LatentPotential {
 public:
  LinearPotential(Eigen::MatrixXd A, Eigen::VectorXd y, double sigma, double sigma_z)
      : A_(std::move(A)), y_(std::move(y)), sigma_(sigma), sigma_z_(sigma_z) {}
  int dim() const override { return static_cast<int>(A_.cols()); }
  double Evaluate(const Eigen::VectorXd& z, Eigen::VectorXd* gradient) const override {
    const Eigen::VectorXd r = (A_ * z - y_) / sigma_;
    if (gradient != nullptr) *gradient = A_.transpose() * r / sigma_ + z / (sigma_z_ * sigma_z_);
    return 0.5 * r.squaredNorm() + 0.5 * z.squaredNorm() / (sigma_z_ * sigma_z_);
  }
  bool GaussNewtonHessian(const Eigen::VectorXd&, Eigen::MatrixXd* hessian) const override {
    *hessian = A_.transpose() * A_ / (sigma_ * sigma_) +
               Eigen::MatrixXd::Identity(dim(), dim()) / (sigma_z_ * sigma_z_);
    return true;
  }

 private:
  Eigen::MatrixXd A_;
  Eigen::VectorXd y_;
  double sigma_, sigma_z_;
};

TEST(LaplaceSampler, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(LaplaceSampler::Options().IsValid(&error)) << error;
}

TEST(LaplaceSampler, BadOptionsNameTheField) {
  std::string error;
  LaplaceSampler::Options options;
  options.num_samples = 0;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("num_samples"), std::string::npos) << error;
  options = LaplaceSampler::Options();
  options.min_relative_pivot = 0;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("min_relative_pivot"), std::string::npos) << error;
  EXPECT_THROW(LaplaceSampler{options}, std::invalid_argument);
}

TEST(LaplaceSampler, MatchesTheExactPosteriorOfALinearGaussianModel) {
  boost::random::mt19937_64 rng(3);
  boost::random::normal_distribution<double> normal;
  const int m = 30, d = 4;
  Eigen::MatrixXd A(m, d);
  for (Eigen::Index i = 0; i < A.size(); ++i) A(i) = normal(rng);
  Eigen::VectorXd y(m);
  for (int i = 0; i < m; ++i) y[i] = normal(rng);
  const double sigma = 0.5, sigma_z = 2.0;
  const LinearPotential potential(A, y, sigma, sigma_z);
  // Exact posterior: covariance (A^T A / s^2 + I / s_z^2)^-1 by the Woodbury identity
  // (an independent route), mean Sigma A^T y / s^2.
  const Eigen::MatrixXd K = sigma * sigma * Eigen::MatrixXd::Identity(m, m) +
                            sigma_z * sigma_z * A * A.transpose();
  const Eigen::MatrixXd cov = sigma_z * sigma_z * Eigen::MatrixXd::Identity(d, d) -
                              std::pow(sigma_z, 4) * A.transpose() * K.inverse() * A;
  const Eigen::VectorXd mean = cov * A.transpose() * y / (sigma * sigma);

  LaplaceSampler::Options options;
  options.num_samples = 20000;
  options.seed = 5;
  const LaplaceSampler laplace(options);
  Eigen::MatrixXd samples;
  const LaplaceSampler::Summary summary = laplace.Sample(potential, mean, &samples);
  ASSERT_TRUE(summary.IsSolutionUsable()) << summary.FullReport();
  EXPECT_TRUE(summary.covariance.isApprox(cov, 1e-10)) << summary.covariance << "\n\n" << cov;
  EXPECT_NEAR(summary.log_det_covariance, std::log(cov.determinant()), 1e-9);
  ASSERT_EQ(samples.rows(), 20000);
  // Sample moments of iid draws: SE(mean_k) = sqrt(S_kk / n), SE(S_ij) =
  // sqrt((S_ii S_jj + S_ij^2) / n) (Gaussian fourth moments).
  const double n = samples.rows();
  const Eigen::RowVectorXd sample_mean = samples.colwise().mean();
  const Eigen::MatrixXd centred = samples.rowwise() - mean.transpose();
  const Eigen::MatrixXd sample_cov = centred.transpose() * centred / n;
  for (int i = 0; i < d; ++i) {
    EXPECT_NEAR(sample_mean[i], mean[i], kSigmas * std::sqrt(cov(i, i) / n));
    for (int j = 0; j < d; ++j) {
      const double se = std::sqrt((cov(i, i) * cov(j, j) + cov(i, j) * cov(i, j)) / n);
      EXPECT_NEAR(sample_cov(i, j), cov(i, j), kSigmas * se) << i << ", " << j;
    }
  }
}

TEST(LaplaceSampler, NearSingularHessianIsReportedNotThrown) {
  Eigen::Matrix3d precision = Eigen::Matrix3d::Identity();
  precision(2, 2) = 1e-14;
  const GaussianPotential flat(Eigen::Vector3d::Zero(), precision);
  const LaplaceSampler laplace{LaplaceSampler::Options()};
  Eigen::MatrixXd samples;
  LaplaceSampler::Summary summary = laplace.Sample(flat, Eigen::Vector3d::Zero(), &samples);
  EXPECT_EQ(summary.termination_type, LaplaceTermination::kIllConditioned) << summary.message;
  EXPECT_NE(summary.message.find("singular"), std::string::npos);
  EXPECT_EQ(samples.rows(), 0);
  precision(2, 2) = -1;
  const GaussianPotential saddle(Eigen::Vector3d::Zero(), precision);
  summary = laplace.Sample(saddle, Eigen::Vector3d::Zero(), &samples);
  EXPECT_EQ(summary.termination_type, LaplaceTermination::kNotPositiveDefinite);
  EXPECT_EQ(samples.rows(), 0);
}

TEST(LaplaceSampler, CovarianceOnATinyTrunkIsSymmetricPositiveDefinite) {
  const SensorTrunk trunk = testing_util::MakeTinyTrunk(8, 9, 16, 2, 6, 4);
  Eigen::VectorXd z_true(6);
  z_true << 0.3, -0.2, 0.1, 0.4, -0.3, 0.2;
  const TrunkTargets targets = testing_util::MakeTargets(trunk, z_true, 0.05, 2);
  const LatentProblem problem(trunk, targets, {});
  const TrunkPotential potential(problem);
  LatentFitter::Options fit;
  fit.strategy = FitStrategy::FromString("ceres:50");
  const LatentFitter fitter(trunk, fit);
  const LaplaceSampler laplace{LaplaceSampler::Options()};
  Eigen::MatrixXd samples;
  const LaplaceSampler::Summary summary = laplace.Sample(problem, fitter, &samples);
  ASSERT_TRUE(summary.IsSolutionUsable()) << summary.FullReport();
  EXPECT_TRUE(summary.fit_ran);
  EXPECT_EQ(samples.rows(), 100);
  EXPECT_TRUE(samples.allFinite());
  const Eigen::MatrixXd& cov = summary.covariance;
  EXPECT_EQ(cov, cov.transpose());
  Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(cov);
  EXPECT_GT(eigen.eigenvalues().minCoeff(), 0.0);
  // At the mode the gradient of U vanishes (fit and sampler share the problem), down to
  // the noise of the problem's float evaluation: compared with the gradient where the fit
  // starts (z = 0), under 1% of it is left (measured: 0.0071 of it at -O3, 0.0078 in the -O1
  // sanitizer build; an absolute bound sat within 5% of both).
  Eigen::VectorXd g, g_start;
  potential.Evaluate(summary.mode, &g);
  potential.Evaluate(Eigen::VectorXd::Zero(z_true.size()), &g_start);
  EXPECT_LT(g.norm(), 1e-2 * g_start.norm());
}

TEST(LaplaceSampler, AGivenHessianGivesTheSamplesTheMatrixWouldGive) {
  const Eigen::MatrixXd A = Eigen::MatrixXd::Random(20, 3);
  const LinearPotential potential(A, Eigen::VectorXd::Random(20), 0.1, 2.0);
  const Eigen::VectorXd mode = Eigen::Vector3d(0.1, -0.2, 0.3);
  Eigen::MatrixXd hessian;
  ASSERT_TRUE(potential.GaussNewtonHessian(mode, &hessian));
  const LaplaceSampler laplace{LaplaceSampler::Options()};
  Eigen::MatrixXd a, b;
  const LaplaceSampler::Summary sa = laplace.Sample(potential, mode, &a);
  const LaplaceSampler::Summary sb =
      laplace.SampleWithHessian(mode, potential.Evaluate(mode, nullptr), hessian, &b);
  ASSERT_TRUE(sb.IsSolutionUsable()) << sb.FullReport();
  EXPECT_EQ(a, b);
  EXPECT_EQ(sa.covariance, sb.covariance);
  EXPECT_DOUBLE_EQ(sa.potential_at_mode, sb.potential_at_mode);
  EXPECT_THROW(laplace.SampleWithHessian(mode, 0.0, Eigen::MatrixXd(3, 2), &b),
               std::invalid_argument);
  EXPECT_THROW(laplace.SampleWithHessian(Eigen::Vector2d(0, 0), 0.0, hessian, &b),
               std::invalid_argument);
  EXPECT_THROW(laplace.SampleWithHessian(mode, 0.0, hessian, nullptr), std::invalid_argument);
}

TEST(LaplaceSampler, SameSeedSameSamples) {
  const GaussianPotential potential(Eigen::Vector2d(1, 2), Eigen::Matrix2d::Identity());
  LaplaceSampler::Options options;
  Eigen::MatrixXd a, b, c;
  LaplaceSampler(options).Sample(potential, Eigen::Vector2d(1, 2), &a);
  LaplaceSampler(options).Sample(potential, Eigen::Vector2d(1, 2), &b);
  options.seed = 1;
  LaplaceSampler(options).Sample(potential, Eigen::Vector2d(1, 2), &c);
  EXPECT_EQ(a, b);
  EXPECT_FALSE(a == c);
}

}  // namespace
}  // namespace tactfunc
