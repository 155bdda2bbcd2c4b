// Copyright 2026 The tactfunc Authors.
//
// LatentProblem: the one definition of a frame's latent posterior U(z). Checked here:
// U against its formula, grad U and H_GN against central differences (with and without a
// robust loss), the Ceres view (1/2 ||r'||^2 + prior) against the samplers' view
// (Evaluate), minibatches against the full gradient, the meta-SGD steps against
// MetaSgd's own inner loop, the automatic sigma rule, pixel selection, and bad input.
#include "estimation/fitting/latent_problem.h"

#include <algorithm>
#include <cmath>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "models/trunk/meta_sgd.h"
#include "tests/support/sampler_test_util.h"

namespace tactfunc {
namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;
using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

constexpr int kProblemRows = 6, kProblemCols = 7;

SensorTrunk Trunk() { return testing_util::MakeTinyTrunk(kProblemRows, kProblemCols, 16, 2, 4, 3); }
const Eigen::Vector4d kTrue(0.3, -0.2, 0.1, 0.4);

LatentProblem::Options DoubleOptions() {
  LatentProblem::Options options;
  options.precision = LatentProblem::Precision::kDouble;
  return options;
}

// Central differences of U's gradient.
VectorXd NumericGradient(const LatentProblem& problem, const VectorXd& z, double h = 1e-6) {
  VectorXd g(z.size());
  for (int k = 0; k < z.size(); ++k) {
    VectorXd zp = z, zm = z;
    zp[k] += h;
    zm[k] -= h;
    g[k] = (problem.Evaluate(zp) - problem.Evaluate(zm)) / (2 * h);
  }
  return g;
}

TEST(LatentProblemOptions, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(LatentProblem::Options().IsValid(&error)) << error;
}

TEST(LatentProblemOptions, BadOptionsNameTheFieldAndTheConstructorThrows) {
  const SensorTrunk trunk = Trunk();
  const TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.0, 1);
  const struct {
    const char* field;
    void (*spoil)(LatentProblem::Options*);
  } cases[] = {
      {"sigma", [](LatentProblem::Options* o) { o->sigma = -1; }},
      {"sigma_z", [](LatentProblem::Options* o) { o->sigma_z = 0; }},
      {"robust_loss_scale", [](LatentProblem::Options* o) { o->robust_loss_scale = NAN; }},
      {"pixel_stride", [](LatentProblem::Options* o) { o->pixel_stride = 0; }},
      {"max_pixels", [](LatentProblem::Options* o) { o->max_pixels = -1; }},
      {"contact_share", [](LatentProblem::Options* o) { o->contact_share = 1.5; }},
  };
  for (const auto& c : cases) {
    LatentProblem::Options options;
    c.spoil(&options);
    std::string error;
    EXPECT_FALSE(options.IsValid(&error)) << c.field;
    EXPECT_NE(error.find(c.field), std::string::npos) << error;
    EXPECT_THROW(LatentProblem(trunk, targets, options), std::invalid_argument) << c.field;
  }
}

TEST(LatentProblem, AutomaticSigmaIsTheTrunksResidualSigmaElse001) {
  SensorTrunk trunk = Trunk();
  const TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.0, 1);
  EXPECT_EQ(LatentProblem(trunk, targets, {}).sigma(), 0.05);
  trunk.residual_sigma = 0;
  EXPECT_EQ(LatentProblem::AutomaticSigma(trunk), 0.01);
  EXPECT_EQ(LatentProblem(trunk, targets, {}).sigma(), 0.01);
  LatentProblem::Options options;
  options.sigma = 0.2;
  EXPECT_EQ(LatentProblem(trunk, targets, options).sigma(), 0.2);
}

TEST(LatentProblem, PotentialIsTheWeightedSumOfSquaresPlusPrior) {
  const SensorTrunk trunk = Trunk();
  TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.05, 1);
  targets.weights[5] = 0;
  targets.values(5, 0) = NAN;  // an invalid pixel may hold NaN
  targets.weights[6] = 0.5;
  LatentProblem::Options options = DoubleOptions();
  options.sigma = 0.1;
  options.sigma_z = 2.0;
  const LatentProblem problem(trunk, targets, options);
  const VectorXd z = Eigen::Vector4d(0.1, 0.1, -0.1, 0.0);
  const MatrixXd y =
      trunk.siren.Forward<double>(trunk.siren.Grid<double>(kProblemRows, kProblemCols), z);
  double expected = z.squaredNorm() / (2 * 4.0);
  for (int j = 0; j < kProblemRows * kProblemCols; ++j) {
    if (targets.weights[j] > 0) {
      expected += targets.weights[j] * std::pow(y(j, 0) - targets.values(j, 0), 2) / (2 * 0.01);
    }
  }
  EXPECT_NEAR(problem.Evaluate(z), expected, 1e-9 * expected);
  EXPECT_EQ(problem.num_valid_pixels(), kProblemRows * kProblemCols - 1);
  EXPECT_EQ(problem.num_pixels(), kProblemRows * kProblemCols - 1);
}

// What Ceres minimises (1/2 ||r'||^2 + 1/2 ||z / sigma_z||^2) is the U the samplers see,
// with and without a robust loss.
TEST(LatentProblem, CeresViewAndSamplerViewAreTheSameFunction) {
  const SensorTrunk trunk = Trunk();
  TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.05, 2);
  // outliers
  for (int j = 0; j < kProblemRows * kProblemCols; j += 5) targets.values(j, 0) += 1.0f;
  for (auto loss : {LatentProblem::RobustLoss::kNone, LatentProblem::RobustLoss::kHuber,
                    LatentProblem::RobustLoss::kCauchy}) {
    LatentProblem::Options options = DoubleOptions();
    options.robust_loss = loss;
    options.sigma_z = 0.7;
    const LatentProblem problem(trunk, targets, options);
    const VectorXd z = Eigen::Vector4d(0.2, -0.1, 0.0, 0.3);
    VectorXd r(problem.num_residuals());
    ASSERT_TRUE(problem.ResidualsAndJacobian(z.data(), r.data(), nullptr));
    const double ceres_view = 0.5 * r.squaredNorm() + 0.5 * (z / 0.7).squaredNorm();
    EXPECT_NEAR(problem.Evaluate(z), ceres_view, 1e-10 * ceres_view) << ToString(loss);
  }
}

// DataCost is the data part of the Ceres view. Over the whole frame it also gives the
// frame's PSNR from the same pass; over thinned pixels it gives no PSNR (that needs its
// own whole-frame pass), and its cost is over the selected pixels only.
TEST(LatentProblem, DataCostIsTheCeresDataCostAndGivesThePsnrOnlyOverTheWholeFrame) {
  const SensorTrunk trunk = Trunk();
  TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.05, 2);
  targets.weights[4] = 0;
  const VectorXd z = Eigen::Vector4d(0.2, -0.1, 0.0, 0.3);
  for (const int stride : {1, 3}) {
    LatentProblem::Options options = DoubleOptions();
    options.robust_loss = LatentProblem::RobustLoss::kHuber;
    options.pixel_stride = stride;
    const LatentProblem problem(trunk, targets, options);
    VectorXd r(problem.num_residuals());
    ASSERT_TRUE(problem.ResidualsAndJacobian(z.data(), r.data(), nullptr));
    std::optional<double> psnr = 123.0;
    const double cost = problem.DataCost(z, &psnr);
    EXPECT_NEAR(cost, 0.5 * r.squaredNorm(), 1e-12 * cost) << "stride " << stride;
    if (stride == 1) {
      ASSERT_TRUE(psnr.has_value());
      EXPECT_DOUBLE_EQ(*psnr, problem.Psnr(z));
    } else {
      EXPECT_LT(problem.num_pixels(), problem.num_valid_pixels());
      EXPECT_FALSE(psnr.has_value()) << "a thinned problem has no whole-frame pass";
    }
  }
}

// The pass at z = 0 (StartPass) stands in for the trunk's pass there: residuals,
// Jacobian and DataCost (with its PSNR) equal those of a pass at z = 0 up to float
// rounding, with masked pixels, a fractional weight, thinning and a robust loss.
TEST(LatentProblem, TheStartPassGivesTheResidualsJacobianAndCostAtZero) {
  const SensorTrunk trunk = Trunk();
  TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.05, 3);
  targets.weights[4] = 0;
  targets.weights[9] = 0.3f;
  const StartPass pass(trunk, kProblemRows, kProblemCols);
  ASSERT_EQ(pass.jacobian.rows(), 4);
  ASSERT_EQ(pass.jacobian.cols(), kProblemRows * kProblemCols * trunk.siren.output_channels());
  const VectorXd zero = VectorXd::Zero(4);
  for (const auto loss : {LatentProblem::RobustLoss::kNone, LatentProblem::RobustLoss::kCauchy}) {
    for (const int stride : {1, 2}) {
      SCOPED_TRACE(std::string(ToString(loss)) + " stride " + std::to_string(stride));
      LatentProblem::Options options;
      options.robust_loss = loss;
      options.pixel_stride = stride;
      const LatentProblem problem(trunk, targets, options);
      ASSERT_TRUE(problem.CanUse(pass));
      const int n = problem.num_residuals();
      VectorXd r(n), r0(n);
      RowMajor J(n, 4), J0(n, 4);
      ASSERT_TRUE(problem.ResidualsAndJacobian(zero.data(), r.data(), J.data()));
      ASSERT_TRUE(problem.ResidualsAndJacobianAtStart(pass, r0.data(), J0.data()));
      EXPECT_LE((r0 - r).cwiseAbs().maxCoeff(), 1e-5 * r.cwiseAbs().maxCoeff());
      EXPECT_LE((J0 - J).cwiseAbs().maxCoeff(), 1e-5 * J.cwiseAbs().maxCoeff());
      std::optional<double> psnr, psnr0;
      const double cost = problem.DataCost(zero, &psnr);
      const double cost0 = problem.DataCostAtStart(pass, &psnr0);
      EXPECT_NEAR(cost0, cost, 1e-5 * cost);
      ASSERT_EQ(psnr0.has_value(), psnr.has_value());
      if (psnr) {
        EXPECT_NEAR(*psnr0, *psnr, 1e-4);
      }
    }
  }
}

TEST(LatentProblem, MetaSgdStepsThroughTheStartPassAreTheTrunksSteps) {
  SensorTrunk trunk = Trunk();
  trunk.meta_sgd.latent_l2_weight = 0.01;  // its gradient is 0 at z = 0, not later
  TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.05, 4);
  targets.weights[3] = 0;
  targets.weights[8] = 0.5f;
  const StartPass pass(trunk, kProblemRows, kProblemCols);
  for (const int stride : {1, 2}) {
    SCOPED_TRACE(stride);
    LatentProblem::Options options;
    options.pixel_stride = stride;
    const LatentProblem problem(trunk, targets, options);
    const VectorXd zero = VectorXd::Zero(4);
    for (const int steps : {1, 3}) {
      double cost = 0, cost_pass = 0;
      std::optional<double> psnr, psnr_pass;
      const VectorXd z = problem.MetaSgdSteps(zero, steps, &cost, &psnr);
      const VectorXd z_pass = problem.MetaSgdSteps(zero, steps, &cost_pass, &psnr_pass, &pass);
      EXPECT_LE((z_pass - z).norm(), 1e-5 * z.norm()) << steps;
      EXPECT_GT(z.norm(), 0.0);
      EXPECT_NEAR(cost_pass, cost, 1e-5 * cost);
      ASSERT_EQ(psnr_pass.has_value(), psnr.has_value());
      if (psnr) {
        EXPECT_NEAR(*psnr_pass, *psnr, 1e-4);
      }
    }
    // Away from z = 0 the pass is not used: the same steps exactly.
    const VectorXd start = 0.1 * VectorXd::Ones(4);
    EXPECT_EQ(problem.MetaSgdSteps(start, 2, nullptr, nullptr, &pass),
              problem.MetaSgdSteps(start, 2));
  }
}

TEST(LatentProblem, AStartPassOfAnotherSizeTrunkOrPrecisionIsNotUsed) {
  const SensorTrunk trunk = Trunk(), other = Trunk();
  const TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.0, 1);
  const LatentProblem problem(trunk, targets, {});
  EXPECT_TRUE(problem.CanUse(StartPass(trunk, kProblemRows, kProblemCols)));
  EXPECT_FALSE(problem.CanUse(StartPass(trunk, kProblemRows + 1, kProblemCols)));
  EXPECT_FALSE(problem.CanUse(StartPass(other, kProblemRows, kProblemCols)));
  EXPECT_FALSE(
      LatentProblem(trunk, targets, DoubleOptions())
          .CanUse(StartPass(trunk, kProblemRows, kProblemCols)));
  EXPECT_THROW(StartPass(trunk, 0, kProblemCols), std::invalid_argument);
}

TEST(LatentProblem, GradientMatchesCentralDifferencesWithAndWithoutRobustLoss) {
  const SensorTrunk trunk = Trunk();
  TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.05, 1);
  // outliers
  for (int j = 0; j < kProblemRows * kProblemCols; j += 6) targets.values(j, 0) -= 0.8f;
  for (auto loss : {LatentProblem::RobustLoss::kNone, LatentProblem::RobustLoss::kHuber,
                    LatentProblem::RobustLoss::kCauchy}) {
    LatentProblem::Options options = DoubleOptions();
    options.robust_loss = loss;
    const LatentProblem problem(trunk, targets, options);
    for (const Eigen::Vector4d& z :
         {Eigen::Vector4d::Zero().eval(), kTrue, Eigen::Vector4d(1e-6, -1e-6, 0, 1e-6)}) {
      VectorXd g;
      problem.Evaluate(z, &g);
      const VectorXd numeric = NumericGradient(problem, z);
      for (int k = 0; k < 4; ++k) {
        EXPECT_NEAR(g[k], numeric[k], 1e-6 * (1 + std::abs(numeric[k])))
            << ToString(loss) << " k " << k;
      }
    }
  }
}

TEST(LatentProblem, RobustJacobianMatchesCentralDifferencesOfTheResiduals) {
  const SensorTrunk trunk = Trunk();
  TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.05, 4);
  for (int j = 0; j < kProblemRows * kProblemCols; j += 4) targets.values(j, 0) += 0.5f;
  LatentProblem::Options options = DoubleOptions();
  options.robust_loss = LatentProblem::RobustLoss::kCauchy;
  options.robust_loss_scale = 2.385;
  const LatentProblem problem(trunk, targets, options);
  const int n = problem.num_residuals();
  const VectorXd z = Eigen::Vector4d(0.1, 0.3, -0.2, 0.2);
  VectorXd r(n);
  RowMajor J(n, 4);
  ASSERT_TRUE(problem.ResidualsAndJacobian(z.data(), r.data(), J.data()));
  const double h = 1e-6;
  for (int k = 0; k < 4; ++k) {
    VectorXd zp = z, zm = z, rp(n), rm(n);
    zp[k] += h;
    zm[k] -= h;
    problem.ResidualsAndJacobian(zp.data(), rp.data(), nullptr);
    problem.ResidualsAndJacobian(zm.data(), rm.data(), nullptr);
    const VectorXd numeric = (rp - rm) / (2 * h);
    EXPECT_LE((J.col(k) - numeric).cwiseAbs().maxCoeff(), 1e-5 * (1 + numeric.cwiseAbs().maxCoeff()))
        << "k " << k;
  }
}

TEST(LatentProblem, TheJacobianAlongDirectionsIsTheRobustJacobianTimesThem) {
  const SensorTrunk trunk = Trunk();
  TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.05, 4);
  for (int j = 0; j < kProblemRows * kProblemCols; j += 4) targets.values(j, 0) += 0.5f;
  for (const auto precision : {LatentProblem::Precision::kDouble, LatentProblem::Precision::kFloat}) {
    LatentProblem::Options options;
    options.precision = precision;
    options.robust_loss = LatentProblem::RobustLoss::kCauchy;
    options.robust_loss_scale = 2.385;
    const LatentProblem problem(trunk, targets, options);
    const int n = problem.num_residuals();
    const VectorXd z = Eigen::Vector4d(0.1, 0.3, -0.2, 0.2);
    MatrixXd D(4, 3);
    D << 1, 0.5, -2, 0, 1, 0.25, 3, -1, 0, 0.5, 0.5, 1;
    VectorXd r(n), r_along(n);
    RowMajor J(n, 4), J_along(n, 3);
    ASSERT_TRUE(problem.ResidualsAndJacobian(z.data(), r.data(), J.data()));
    ASSERT_TRUE(problem.ResidualsAndJacobianAlong(z.data(), D, r_along.data(), J_along.data()));
    EXPECT_EQ(r_along, r);
    const MatrixXd expected = J * D;
    const double tolerance =
        (precision == LatentProblem::Precision::kDouble ? 1e-12 : 1e-5) *
        (1 + expected.cwiseAbs().maxCoeff());
    EXPECT_LE((J_along - expected).cwiseAbs().maxCoeff(), tolerance);
  }
  const LatentProblem problem(trunk, targets, DoubleOptions());
  VectorXd r(problem.num_residuals());
  RowMajor J(problem.num_residuals(), 2);
  const VectorXd z = VectorXd::Zero(4);
  EXPECT_THROW(problem.ResidualsAndJacobianAlong(z.data(), MatrixXd::Zero(5, 2), r.data(), J.data()),
               std::invalid_argument);
}

TEST(LatentProblem, MinibatchesOfAPartitionAverageToTheFullGradient) {
  const SensorTrunk trunk = Trunk();
  const TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.05, 1);
  for (auto loss : {LatentProblem::RobustLoss::kNone, LatentProblem::RobustLoss::kHuber}) {
    LatentProblem::Options options = DoubleOptions();
    options.robust_loss = loss;
    options.robust_loss_scale = 0.5;  // some residuals in Huber's linear part
    const LatentProblem problem(trunk, targets, options);
    const VectorXd z = Eigen::Vector4d(0.1, 0.2, 0.3, 0.4);
    VectorXd full, g, sum = VectorXd::Zero(4);
    const double u = problem.Evaluate(z, &full);
    double u_sum = 0;
    for (int part = 0; part < 6; ++part) {  // 6 batches of 7 of the 42 pixels
      std::vector<int> batch;
      for (int i = part; i < kProblemRows * kProblemCols; i += 6) batch.push_back(i);
      u_sum += problem.EvaluateMinibatch(z, batch, &g) / 6;
      sum += g / 6;
    }
    EXPECT_NEAR(u_sum, u, 1e-9 * u) << ToString(loss);
    EXPECT_TRUE(sum.isApprox(full, 1e-9)) << ToString(loss);
  }
  const LatentProblem problem(trunk, targets, {});
  VectorXd g;
  EXPECT_THROW(problem.EvaluateMinibatch(VectorXd::Zero(4), {42}, &g), std::invalid_argument);
}

TEST(LatentProblem, DataTermsSumToUAndItsGradientAndGiveTheGaussNewtonHessian) {
  const SensorTrunk trunk = Trunk();
  const TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.05, 1);
  for (auto loss : {LatentProblem::RobustLoss::kNone, LatentProblem::RobustLoss::kHuber}) {
    LatentProblem::Options options = DoubleOptions();
    options.robust_loss = loss;
    options.robust_loss_scale = 0.5;
    const LatentProblem problem(trunk, targets, options);
    const VectorXd z = Eigen::Vector4d(0.1, 0.2, 0.3, 0.4);
    VectorXd full, values;
    Eigen::MatrixXd gradients, hessian, expected_hessian;
    const double u = problem.Evaluate(z, &full);
    problem.DataTerms(z, &values, &gradients, &hessian);
    problem.GaussNewtonHessian(z, &expected_hessian);
    ASSERT_EQ(values.size(), problem.num_pixels());
    ASSERT_EQ(gradients.rows(), problem.num_pixels());
    const double prior = 0.5 * z.squaredNorm() / (options.sigma_z * options.sigma_z);
    EXPECT_NEAR(values.sum() + prior, u, 1e-9 * u) << ToString(loss);
    const VectorXd sum = gradients.colwise().sum().transpose() +
                         z / (options.sigma_z * options.sigma_z);
    EXPECT_TRUE(sum.isApprox(full, 1e-9)) << ToString(loss);
    EXPECT_TRUE(hessian.isApprox(expected_hessian, 1e-9)) << ToString(loss);
    // A minibatch's data terms are its rows of them.
    VectorXd g;
    const std::vector<int> batch = {2, 9, 30};
    const double scale = problem.num_pixels() / 3.0;
    double batch_values = 0;
    VectorXd batch_gradient = z / (options.sigma_z * options.sigma_z);
    for (int j : batch) {
      batch_values += scale * values[j];
      batch_gradient += scale * gradients.row(j).transpose();
    }
    EXPECT_NEAR(problem.EvaluateMinibatch(z, batch, &g), batch_values + prior, 1e-9 * u);
    EXPECT_TRUE(g.isApprox(batch_gradient, 1e-9)) << ToString(loss);
  }
}

TEST(LatentProblem, GaussNewtonHessianIsTheHessianAtAnExactFit) {
  // With noise-free targets the residuals vanish at the true latent, where J^T J / sigma^2
  // + I / sigma_z^2 is the exact Hessian of U: compare with differences of the gradient.
  const SensorTrunk trunk = Trunk();
  const TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.0, 1);
  for (auto loss : {LatentProblem::RobustLoss::kNone, LatentProblem::RobustLoss::kHuber}) {
    for (auto precision : {LatentProblem::Precision::kDouble, LatentProblem::Precision::kFloat}) {
      LatentProblem::Options options;
      options.precision = precision;
      options.robust_loss = loss;
      const LatentProblem problem(trunk, targets, options);
      MatrixXd H;
      problem.GaussNewtonHessian(kTrue, &H);
      EXPECT_TRUE(H.isApprox(H.transpose(), 1e-12));
      if (precision == LatentProblem::Precision::kFloat) continue;
      MatrixXd numeric(4, 4);
      for (int k = 0; k < 4; ++k) {
        const double h = 1e-5;
        VectorXd zp = kTrue, zm = kTrue, gp, gm;
        zp[k] += h;
        zm[k] -= h;
        problem.Evaluate(zp, &gp);
        problem.Evaluate(zm, &gm);
        numeric.col(k) = (gp - gm) / (2 * h);
      }
      EXPECT_TRUE(H.isApprox(numeric, 1e-5)) << ToString(loss) << "\n" << H << "\n\n" << numeric;
    }
  }
}

TEST(LatentProblem, MetaSgdStepsAreTheTrunksInnerLoopFromAnyStart) {
  const SensorTrunk trunk = Trunk();
  const TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.02, 5);
  const LatentProblem problem(trunk, targets, DoubleOptions());
  const MatrixXd grid = trunk.siren.Grid<double>(kProblemRows, kProblemCols);
  const VectorXd expected = MetaSgd(trunk.meta_sgd).FitLatent<double>(
      trunk.siren, grid, targets.values.cast<double>(), targets.weights.cast<double>(),
      trunk.alpha);
  EXPECT_LE((problem.MetaSgdSteps(VectorXd::Zero(4), 3) - expected).cwiseAbs().maxCoeff(), 1e-12);
  // Three steps are one step, then two more from where it ended.
  const VectorXd one = problem.MetaSgdSteps(VectorXd::Zero(4), 1);
  EXPECT_LE((problem.MetaSgdSteps(one, 2) - expected).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_EQ(problem.MetaSgdSteps(one, 0), one);
}

TEST(LatentProblem, SelectsEveryStrideThPixelThenAtMostMaxPixels) {
  const SensorTrunk trunk = Trunk();
  TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.0, 1);
  targets.weights[0] = 0;  // 41 valid pixels
  LatentProblem::Options options;
  options.pixel_stride = 2;
  EXPECT_EQ(LatentProblem(trunk, targets, options).num_pixels(), 21);
  options.max_pixels = 10;
  const LatentProblem problem(trunk, targets, options);
  EXPECT_EQ(problem.num_pixels(), 10);
  EXPECT_EQ(problem.num_valid_pixels(), 41);
  EXPECT_EQ(problem.num_residuals(), 10);
  // Psnr is over all valid pixels: the true latent reproduces every one.
  EXPECT_GT(problem.Psnr(kTrue), 100.0);
}

// The weighted energy sum_i w_i |t_i|^2 over the selected pixels.
double SelectedEnergy(const LatentProblem& problem) {
  double sum = 0;
  for (int i = 0; i < problem.num_pixels(); ++i) {
    sum += problem.pixel_weights()[i] * problem.pixel_targets().row(i).squaredNorm();
  }
  return sum;
}

TEST(LatentProblem, ContactShareDrawsTowardsTheContactAndKeepsTheWeightedSumsScale) {
  const SensorTrunk trunk = Trunk();
  TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.0, 1);
  targets.weights[0] = 0;  // 41 valid pixels
  targets.weights[5] = 0.5f;
  std::vector<int> blob;
  for (int r = 2; r < 4; ++r) {
    for (int c = 3; c < 5; ++c) blob.push_back(r * kProblemCols + c);
  }
  for (int j : blob) targets.values.row(j) *= 20.0f;
  LatentProblem::Options options;
  const LatentProblem all(trunk, targets, options);
  options.max_pixels = 12;
  auto in_blob = [&](const LatentProblem& p) {
    int count = 0;
    for (int j : p.pixel_index()) count += std::count(blob.begin(), blob.end(), j);
    return count;
  };
  const LatentProblem even(trunk, targets, options);
  options.contact_share = 0.5;
  const LatentProblem half(trunk, targets, options);
  EXPECT_GT(in_blob(half), in_blob(even));
  EXPECT_LE(half.num_pixels(), 12);
  EXPECT_TRUE(std::is_sorted(half.pixel_index().begin(), half.pixel_index().end()));
  EXPECT_EQ(std::adjacent_find(half.pixel_index().begin(), half.pixel_index().end()),
            half.pixel_index().end());
  // Deterministic.
  EXPECT_EQ(LatentProblem(trunk, targets, options).pixel_index(), half.pixel_index());
  // A share of 1 draws in proportion to the energy: the weighted energy of the drawn pixels
  // is exactly m / N times the frame's.
  options.contact_share = 1;
  const LatentProblem full_share(trunk, targets, options);
  EXPECT_EQ(in_blob(full_share), 4);
  EXPECT_NEAR(SelectedEnergy(full_share), SelectedEnergy(all) * 12 / 41,
              1e-5 * SelectedEnergy(all));
  // A frame without difference energy is thinned evenly with its own weights.
  targets.values.setZero();
  const LatentProblem blank(trunk, targets, options);
  EXPECT_EQ(blank.num_pixels(), 12);
  for (int i = 0; i < blank.num_pixels(); ++i) {
    EXPECT_EQ(blank.pixel_weights()[i], targets.weights[blank.pixel_index()[i]]);
  }
}

TEST(LatentProblem, BadInputThrowsQuotingTheShapes) {
  const SensorTrunk trunk = Trunk();
  TrunkTargets targets = testing_util::MakeTargets(trunk, kTrue, 0.0, 1);
  targets.rows = 5;
  try {
    LatentProblem(trunk, targets, {});
    FAIL() << "expected a throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("35x1"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("42x1"), std::string::npos) << e.what();
  }
  targets = testing_util::MakeTargets(trunk, kTrue, 0.0, 1);
  targets.values(3, 0) = NAN;  // on a valid pixel
  EXPECT_THROW(LatentProblem(trunk, targets, {}), std::invalid_argument);
  targets = testing_util::MakeTargets(trunk, kTrue, 0.0, 1);
  targets.weights[2] = -1;
  EXPECT_THROW(LatentProblem(trunk, targets, {}), std::invalid_argument);
  targets.weights.resize(10);
  EXPECT_THROW(LatentProblem(trunk, targets, {}), std::invalid_argument);
  targets = testing_util::MakeTargets(trunk, kTrue, 0.0, 1);
  const LatentProblem problem(trunk, targets, {});
  EXPECT_THROW(problem.Evaluate(VectorXd::Zero(3)), std::invalid_argument);
  EXPECT_THROW(problem.MetaSgdSteps(VectorXd::Zero(5), 1), std::invalid_argument);
}

}  // namespace
}  // namespace tactfunc
