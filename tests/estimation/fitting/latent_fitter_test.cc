// Copyright 2026 The tactfunc Authors.
//
// LatentFitter and its cost functions.
//
// Derivatives: the analytic batched Jacobian (double) against the ceres::Jet autodiff
// reference (relative max-norm difference <= 1e-8; both are exact up to rounding, so
// they agree to about 1e-14) and against 4th-order central differences (<= 1e-6), at
// z = 0, at a tiny z (1e-7) and at a random z, for a 2-channel trunk with masked pixels.
// The robust transform's Jacobian is checked against central differences the same way.
//
// Fits use small trunks (width 24-32, 3 layers, d = 6-8) on 16x20 frames that the trunk
// itself generated from a known latent, so that a perfect fit exists (PSNR +inf).
#include "estimation/fitting/latent_fitter.h"

#include <cmath>
#include <cstdint>
#include <limits>
#include <memory>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "ceres/loss_function.h"
#include "estimation/fitting/latent_costs.h"
#include "estimation/knn/knn_index.h"
#include "gtest/gtest.h"
#include "models/trunk/meta_sgd.h"
#include "tests/support/uniform_numbers.h"

namespace tactfunc {
namespace {

using Eigen::MatrixXd;
using Eigen::MatrixXf;
using Eigen::VectorXd;
using Eigen::VectorXf;
using Fitter = LatentFitter;

constexpr int kRows = 16, kCols = 20;

using testing_util::Uniform;  // deterministic numbers in [-1, 1)

SensorTrunk MakeTrunk(int channels = 1, int width = 32, int latent_dim = 8, unsigned seed = 1) {
  LatentModulatedSiren::Options options;
  options.width = width;
  options.num_hidden_layers = 3;
  options.latent_dim = latent_dim;
  options.output_channels = channels;
  SensorTrunk trunk;
  trunk.siren = LatentModulatedSiren(options, seed);
  trunk.format.rows = kRows;
  trunk.format.cols = kCols;
  trunk.format.scale = 1.0;
  trunk.alpha = VectorXd::Constant(latent_dim, 0.5);
  trunk.meta_sgd.inner_steps = 3;
  return trunk;
}

// The frame the trunk generates from z (every pixel valid).
TrunkTargets Generate(const SensorTrunk& trunk, const VectorXd& z, int rows = kRows,
                      int cols = kCols) {
  TrunkTargets t;
  t.rows = rows;
  t.cols = cols;
  t.values = trunk.siren.Forward<double>(trunk.siren.Grid<double>(rows, cols), z).cast<float>();
  t.weights = VectorXf::Ones(rows * cols);
  return t;
}

VectorXd TrueLatent(int d, unsigned seed = 3) { return 0.4 * Uniform(d, 1, seed); }

Fitter::Options CeresOptions(int iterations) {
  Fitter::Options options;
  options.strategy = FitStrategy::FromString("ceres:" + std::to_string(iterations));
  return options;
}

LatentProblem::Options DoubleProblem() {
  LatentProblem::Options options;
  options.precision = LatentProblem::Precision::kDouble;
  return options;
}

// The fit of one frame: a fitter of `options` on the frame's latent problem.
Fitter::Summary FitFrame(const SensorTrunk& trunk, const Fitter::Options& options,
                         const TrunkTargets& targets, VectorXd* z,
                         const LatentProblem::Options& problem = {}) {
  return Fitter(trunk, options).Fit(LatentProblem(trunk, targets, problem), z);
}

// Jacobian (rows x d, row-major in Ceres' layout) and residuals of a cost at z.
void EvaluateCost(const ceres::CostFunction& cost, const VectorXd& z, VectorXd* residuals,
                  MatrixXd* jacobian) {
  const int d = static_cast<int>(z.size());
  residuals->resize(cost.num_residuals());
  Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> J(cost.num_residuals(), d);
  const double* parameters[] = {z.data()};
  double* jacobians[] = {J.data()};
  ASSERT_TRUE(cost.Evaluate(parameters, residuals->data(), jacobian ? jacobians : nullptr));
  if (jacobian) *jacobian = J;
}

// 4th-order central differences of the residuals.
MatrixXd NumericJacobian(const ceres::CostFunction& cost, const VectorXd& z, double h = 1e-4) {
  MatrixXd J(cost.num_residuals(), z.size());
  for (int k = 0; k < z.size(); ++k) {
    VectorXd r[4];
    const double steps[4] = {-2 * h, -h, h, 2 * h};
    for (int s = 0; s < 4; ++s) {
      VectorXd zs = z;
      zs[k] += steps[s];
      EvaluateCost(cost, zs, &r[s], nullptr);
    }
    J.col(k) = (r[0] - 8 * r[1] + 8 * r[2] - r[3]) / (12 * h);
  }
  return J;
}

double RelativeDifference(const MatrixXd& a, const MatrixXd& reference) {
  return (a - reference).cwiseAbs().maxCoeff() / std::max(reference.cwiseAbs().maxCoeff(), 1e-300);
}

// ---- Options and strategies -----------------------------------------------------------------

TEST(LatentFitterOptions, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(Fitter::Options().IsValid(&error)) << error;
  EXPECT_EQ(Fitter::Options().strategy.ToString(), "ceres:10");
}

TEST(LatentFitterOptions, BadOptionsNameTheFieldAndTheConstructorThrows) {
  const SensorTrunk trunk = MakeTrunk();
  struct Case {
    const char* field;
    void (*mutate)(Fitter::Options*);
  };
  const Case cases[] = {
      {"jacobian", [](Fitter::Options* o) { o->jacobian = Fitter::JacobianMode(7); }},
      {"knn_k", [](Fitter::Options* o) { o->knn_k = 0; }},
      {"solver_options", [](Fitter::Options* o) { o->solver_options.function_tolerance = -1; }},
      {"strategy", [](Fitter::Options* o) { o->strategy.steps = 0; }},
  };
  for (const Case& c : cases) {
    Fitter::Options options;
    c.mutate(&options);
    std::string error;
    EXPECT_FALSE(options.IsValid(&error)) << c.field;
    EXPECT_NE(error.find(c.field), std::string::npos) << error;
    EXPECT_THROW(Fitter(trunk, options), std::invalid_argument) << c.field;
  }
}

TEST(LatentFitterStrategy, ParsesEveryFormAndPrintsItBack) {
  for (const char* text : {"knn", "meta_sgd:3", "meta_sgd:0", "ceres:10", "knn+meta_sgd:2",
                           "knn+ceres:15", "adam:400", "knn+adam:5"}) {
    FitStrategy strategy;
    std::string error;
    ASSERT_TRUE(FitStrategy::Parse(text, &strategy, &error)) << text << ": " << error;
    EXPECT_EQ(strategy.ToString(), text);
  }
  const FitStrategy s = FitStrategy::FromString("knn+ceres:7");
  EXPECT_TRUE(s.knn);
  EXPECT_EQ(s.refinement, FitStrategy::Refinement::kCeres);
  EXPECT_EQ(s.steps, 7);
}

TEST(LatentFitterStrategy, BadStringsGiveClearErrors) {
  const std::pair<const char*, const char*> cases[] = {
      {"ceres", "needs a step count"},          {"ceres:0", "N >= 1"},
      {"ceres:-2", "not a non-negative integer"}, {"lbfgs:3", "unknown method 'lbfgs'"},
      {"knn+", "no method"},                    {"", "no method"},
      {"ceres:1x", "not a non-negative integer"}, {"knn+knn", "unknown method 'knn'"},
      {"adam:0", "N >= 1"},                     {"knn+adam:0", "N >= 1"},
  };
  for (const auto& [text, expected] : cases) {
    FitStrategy strategy;
    std::string error;
    EXPECT_FALSE(FitStrategy::Parse(text, &strategy, &error)) << text;
    EXPECT_NE(error.find(expected), std::string::npos) << text << ": " << error;
    EXPECT_NE(error.find(std::string("'") + text + "'"), std::string::npos) << error;
    EXPECT_THROW(FitStrategy::FromString(text), std::invalid_argument);
  }
}

TEST(LatentFitter, RefusesTheAdamStrategyOfPhotometricTrunks) {
  const SensorTrunk trunk = MakeTrunk();
  Fitter::Options options;
  options.strategy = FitStrategy::FromString("adam:10");
  try {
    Fitter fitter(trunk, options);
    FAIL() << "adam:10 accepted for a direct trunk";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("photometric"), std::string::npos) << e.what();
  }
}

TEST(LatentFitter, KnnStrategiesWithoutAnIndexThrow) {
  const SensorTrunk trunk = MakeTrunk();
  Fitter::Options options;
  options.strategy = FitStrategy::FromString("knn+ceres:5");
  EXPECT_THROW(Fitter(trunk, options), std::invalid_argument);
  BruteForceKnnIndex index(trunk.siren.latent_dim() + 1);
  const MatrixXf latents(0, trunk.siren.latent_dim() + 1);
  try {
    Fitter(trunk, options, &index, &latents);
    FAIL() << "expected a throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("0 x 9"), std::string::npos) << e.what();
  }
}

// ---- Cost functions ----------------------------------------------------------------------

class LatentFitterCostTest : public ::testing::Test {
 protected:
  LatentFitterCostTest() : trunk_(MakeTrunk(/*channels=*/2, /*width=*/12, /*latent_dim=*/5)) {
    // Perturb c (0 at initialisation) so no block of the trunk is special.
    LatentModulatedSiren& siren = trunk_.siren;
    siren.SetParameters(siren.parameters() + 0.05 * Uniform(siren.NumParameters(), 1, 11));
    targets_ = Generate(trunk_, TrueLatent(5));
    targets_.values += 0.1 * Uniform(kRows * kCols, 2, 12).cast<float>();
    for (int j = 0; j < kRows * kCols; j += 7) {
      targets_.weights[j] = 0;
      targets_.values(j, 0) = std::numeric_limits<float>::quiet_NaN();
    }
    targets_.weights[5] = 0.25f;  // a fractional weight
  }
  LatentProblem Problem(LatentProblem::Precision precision = LatentProblem::Precision::kDouble,
                        LatentProblem::RobustLoss loss = LatentProblem::RobustLoss::kNone) const {
    LatentProblem::Options options;
    options.sigma = 0.05;
    options.precision = precision;
    options.robust_loss = loss;
    options.robust_loss_scale = loss == LatentProblem::RobustLoss::kCauchy ? 2.385 : 1.345;
    return LatentProblem(trunk_, targets_, options);
  }
  SensorTrunk trunk_;
  TrunkTargets targets_;
};

TEST_F(LatentFitterCostTest, AnalyticJacobianMatchesAutodiffAndFiniteDifferences) {
  const LatentProblem problem = Problem();
  const AnalyticLatentCost analytic(&problem);
  const std::unique_ptr<ceres::CostFunction> autodiff = MakeAutoDiffLatentCost(&problem);
  const struct {
    const char* name;
    VectorXd z;
  } points[] = {{"zero", VectorXd::Zero(5)},
                {"tiny", 1e-7 * Uniform(5, 1, 21)},
                {"random", 0.8 * Uniform(5, 1, 22)}};
  for (const auto& p : points) {
    VectorXd ra, rd;
    MatrixXd Ja, Jd;
    EvaluateCost(analytic, p.z, &ra, &Ja);
    EvaluateCost(*autodiff, p.z, &rd, &Jd);
    ASSERT_EQ(ra.size(), problem.num_residuals());
    EXPECT_LE(RelativeDifference(ra, rd), 1e-12) << p.name;
    EXPECT_LE(RelativeDifference(Ja, Jd), 1e-8) << p.name;
    EXPECT_LE(RelativeDifference(Ja, NumericJacobian(analytic, p.z)), 1e-6) << p.name;
  }
}

TEST_F(LatentFitterCostTest, ResidualsAreWhitenedWeightedErrorsOfTheValidPixelsOnly) {
  const int n_valid = kRows * kCols - (kRows * kCols + 6) / 7;
  const LatentProblem problem = Problem();
  EXPECT_EQ(problem.num_valid_pixels(), n_valid);
  ASSERT_EQ(problem.num_pixels(), n_valid);
  const AnalyticLatentCost cost(&problem);
  const VectorXd z = 0.3 * Uniform(5, 1, 23);
  VectorXd r;
  EvaluateCost(cost, z, &r, nullptr);
  EXPECT_TRUE(r.allFinite());  // the NaN targets sit on masked pixels
  const MatrixXd y = trunk_.siren.Forward<double>(trunk_.siren.Grid<double>(kRows, kCols), z);
  int i = 0;
  for (int j = 0; j < kRows * kCols; ++j) {
    if (targets_.weights[j] == 0) continue;
    for (int c = 0; c < 2; ++c, ++i) {
      const double expected =
          std::sqrt(targets_.weights[j]) * (y(j, c) - targets_.values(j, c)) / 0.05;
      EXPECT_NEAR(r[i], expected, 1e-9 * std::max(1.0, std::abs(expected))) << j;
    }
  }
}

TEST_F(LatentFitterCostTest, FloatEvaluationAgreesWithDoubleToFloatPrecision) {
  const LatentProblem problem64 = Problem(), problem32 = Problem(LatentProblem::Precision::kFloat);
  const AnalyticLatentCost exact(&problem64);
  const AnalyticLatentCost fast(&problem32);
  const VectorXd z = 0.5 * Uniform(5, 1, 24);
  VectorXd r64, r32;
  MatrixXd J64, J32;
  EvaluateCost(exact, z, &r64, &J64);
  EvaluateCost(fast, z, &r32, &J32);
  // Float rounding (6e-8) of the pre-activations is multiplied by omega_0 = 30 in every
  // sine layer and summed over the width, so outputs carry about 1e-6 absolute error
  // (measured 8e-7); the bound, 1e-5 in output units (residual * sigma), is ten times that.
  EXPECT_LE(0.05 * (r32 - r64).cwiseAbs().maxCoeff(), 1e-5);
  EXPECT_LE(RelativeDifference(J32, J64), 1e-5);
}

TEST(LatentFitterPriorCost, IsZOverSigmaZWithIdentityOverSigmaZJacobian) {
  const LatentPriorCost prior(4, 0.5);
  const VectorXd z = Uniform(4, 1, 31);
  VectorXd r;
  MatrixXd J;
  EvaluateCost(prior, z, &r, &J);
  EXPECT_LE((r - z / 0.5).cwiseAbs().maxCoeff(), 1e-15);
  EXPECT_LE((J - 2.0 * MatrixXd::Identity(4, 4)).cwiseAbs().maxCoeff(), 1e-15);
}

TEST_F(LatentFitterCostTest, RobustTransformGivesTheRobustCostAndItsJacobian) {
  const LatentProblem plain_problem = Problem();
  const AnalyticLatentCost plain(&plain_problem);
  const VectorXd z = 0.3 * Uniform(5, 1, 25);
  for (int which = 0; which < 2; ++which) {
    std::unique_ptr<ceres::LossFunction> loss;
    if (which == 0) loss = std::make_unique<ceres::HuberLoss>(1.345);
    else loss = std::make_unique<ceres::CauchyLoss>(2.385);
    const LatentProblem robust_problem =
        Problem(LatentProblem::Precision::kDouble,
                which == 0 ? LatentProblem::RobustLoss::kHuber : LatentProblem::RobustLoss::kCauchy);
    const AnalyticLatentCost robust(&robust_problem);
    // The autodiff reference robustifies the same way.
    const std::unique_ptr<ceres::CostFunction> robust_autodiff =
        MakeAutoDiffLatentCost(&robust_problem);
    VectorXd r, rr, rd;
    MatrixXd J, Jd;
    EvaluateCost(plain, z, &r, nullptr);
    EvaluateCost(robust, z, &rr, &J);
    double expected = 0;
    for (int i = 0; i < r.size(); ++i) {
      double rho[3];
      loss->Evaluate(r[i] * r[i], rho);
      expected += 0.5 * rho[0];
    }
    EXPECT_NEAR(0.5 * rr.squaredNorm(), expected, 1e-10 * expected) << which;
    EXPECT_LE(RelativeDifference(J, NumericJacobian(robust, z)), 1e-6) << which;
    EvaluateCost(*robust_autodiff, z, &rd, &Jd);
    EXPECT_LE(RelativeDifference(rr, rd), 1e-12) << which;
    EXPECT_LE(RelativeDifference(J, Jd), 1e-8) << which;
  }
}

// ---- Fits ----------------------------------------------------------------------------------

TEST(LatentFitter, CeresFromZeroRecoversTheLatentOfAFrameTheTrunkGenerated) {
  const SensorTrunk trunk = MakeTrunk();
  const VectorXd z_true = TrueLatent(8);
  const TrunkTargets targets = Generate(trunk, z_true);
  LatentProblem::Options problem = DoubleProblem();
  problem.sigma_z = 1e4;  // no pull towards 0: the exact latent is the optimum
  VectorXd z;
  const Fitter::Summary summary = FitFrame(trunk, CeresOptions(50), targets, &z, problem);
  EXPECT_EQ(summary.termination_type, FitTermination::kConvergence) << summary.FullReport();
  EXPECT_TRUE(summary.ceres_ran);
  EXPECT_GT(summary.psnr, 80.0) << summary.FullReport();
  EXPECT_LE((z - z_true).norm(), 1e-3 * z_true.norm()) << summary.FullReport();
  EXPECT_LT(summary.final_cost, 1e-6 * summary.initial_cost);
  EXPECT_EQ(summary.num_pixels_used, kRows * kCols);
  EXPECT_EQ(summary.num_residuals, kRows * kCols + 8);
  EXPECT_FALSE(summary.BriefReport().empty());
}

TEST(LatentFitter, AutodiffAndAnalyticFitsAgree) {
  const SensorTrunk trunk = MakeTrunk(1, 16, 6);
  const TrunkTargets targets = Generate(trunk, TrueLatent(6, 5));
  Fitter::Options options = CeresOptions(20);
  VectorXd za, zd;
  const Fitter::Summary sa = FitFrame(trunk, options, targets, &za, DoubleProblem());
  options.jacobian = Fitter::JacobianMode::kAutoDiff;
  const Fitter::Summary sd = FitFrame(trunk, options, targets, &zd, DoubleProblem());
  EXPECT_EQ(sa.iterations, sd.iterations);
  EXPECT_LE((za - zd).norm(), 1e-8 * za.norm()) << sa.FullReport() << sd.FullReport();
}

TEST_F(LatentFitterCostTest, SquareRootAndPerPixelResidualsGiveTheSameFit) {
  // Masked pixels, a fractional weight, noise, two channels; plain and robust; double and
  // float: Ceres must take the same steps on U's d + 1 square-root residuals as on its
  // N C + d residuals.
  for (const auto loss : {LatentProblem::RobustLoss::kNone, LatentProblem::RobustLoss::kHuber}) {
    for (const auto precision :
         {LatentProblem::Precision::kDouble, LatentProblem::Precision::kFloat}) {
      SCOPED_TRACE(std::string(ToString(loss)) + " " + ToString(precision));
      const LatentProblem problem = Problem(precision, loss);
      Fitter::Options options = CeresOptions(20);
      VectorXd zq, zp;
      const Fitter::Summary q = Fitter(trunk_, options).Fit(problem, &zq);
      options.residual_form = Fitter::ResidualForm::kPerPixel;
      const Fitter::Summary p = Fitter(trunk_, options).Fit(problem, &zp);
      EXPECT_EQ(q.ceres_residual_form, Fitter::ResidualForm::kSquareRoot);
      EXPECT_EQ(q.solver_summary.num_residuals, 6);
      EXPECT_EQ(p.ceres_residual_form, Fitter::ResidualForm::kPerPixel);
      EXPECT_EQ(q.iterations, p.iterations) << q.FullReport() << p.FullReport();
      EXPECT_NEAR(q.final_cost, p.final_cost, 1e-9 * p.final_cost);
      EXPECT_LE((zq - zp).norm(), 1e-7 * zp.norm()) << q.FullReport() << p.FullReport();
      EXPECT_LT(q.final_cost, 0.99 * q.initial_cost);  // the fit did move
    }
  }
}

TEST_F(LatentFitterCostTest, GradientCheckingUsesThePerPixelResiduals) {
  // Ceres' gradient checker differentiates the residual vector, which the square-root
  // form defines at Jacobian evaluations only.
  const LatentProblem problem = Problem();
  Fitter::Options options = CeresOptions(3);
  options.solver_options.check_gradients = true;
  VectorXd z;
  const Fitter::Summary summary = Fitter(trunk_, options).Fit(problem, &z);
  EXPECT_EQ(summary.ceres_residual_form, Fitter::ResidualForm::kPerPixel);
  EXPECT_NE(summary.termination_type, FitTermination::kFailure) << summary.FullReport();
}

TEST_F(LatentFitterCostTest, AFitFromZeroThroughTheStartPassIsTheFitFromAZeroWarmStart) {
  // Without a warm start a ceres fit takes its start from the fitter's StartPass; a warm
  // start of zeros evaluates the trunk there. Same steps, same latent, same costs.
  const LatentProblem problem = Problem(LatentProblem::Precision::kFloat);
  const Fitter fitter(trunk_, CeresOptions(20));
  VectorXd za, zb;
  const Fitter::Summary a = fitter.Fit(problem, &za);
  const Fitter::Summary b = fitter.Fit(problem, VectorXd::Zero(5), &zb);
  EXPECT_EQ(a.iterations, b.iterations) << a.FullReport() << b.FullReport();
  EXPECT_NEAR(a.initial_cost, b.initial_cost, 1e-5 * b.initial_cost);
  EXPECT_NEAR(a.final_cost, b.final_cost, 1e-6 * b.final_cost);
  EXPECT_LE((za - zb).norm(), 1e-4 * zb.norm());
  EXPECT_NEAR(a.psnr, b.psnr, 1e-3);
  EXPECT_LT(a.final_cost, 0.99 * a.initial_cost);  // the fit did move
}

TEST_F(LatentFitterCostTest, TheFitHandsOutTheGaussNewtonHessianAtItsResult) {
  for (const auto precision :
       {LatentProblem::Precision::kDouble, LatentProblem::Precision::kFloat}) {
    SCOPED_TRACE(ToString(precision));
    const LatentProblem problem = Problem(precision);
    VectorXd z;
    const Fitter::Summary summary = Fitter(trunk_, CeresOptions(20)).Fit(problem, &z);
    ASSERT_EQ(summary.gauss_newton_hessian.rows(), 5) << summary.FullReport();
    MatrixXd expected;
    problem.GaussNewtonHessian(z, &expected);
    const double tolerance = precision == LatentProblem::Precision::kDouble ? 1e-10 : 1e-5;
    EXPECT_LE(RelativeDifference(summary.gauss_newton_hessian, expected), tolerance);
    // The result's cost and PSNR came from Ceres' last pass there: the same as a new pass.
    std::optional<double> psnr;
    const double data_cost = problem.DataCost(z, &psnr);
    EXPECT_NEAR(summary.final_cost, data_cost + 0.5 * z.squaredNorm(), 1e-6 * summary.final_cost);
    ASSERT_TRUE(psnr.has_value());
    EXPECT_NEAR(summary.psnr, *psnr, 1e-4);
  }
  // Per-pixel residuals and meta-SGD fits form no Hessian.
  Fitter::Options per_pixel = CeresOptions(20);
  per_pixel.residual_form = Fitter::ResidualForm::kPerPixel;
  VectorXd z;
  EXPECT_EQ(Fitter(trunk_, per_pixel).Fit(Problem(), &z).gauss_newton_hessian.size(), 0);
  Fitter::Options meta = CeresOptions(1);
  meta.strategy = FitStrategy::FromString("meta_sgd:3");
  EXPECT_EQ(Fitter(trunk_, meta).Fit(Problem(), &z).gauss_newton_hessian.size(), 0);
}

TEST(LatentFitter, MetaSgdFromZeroIsTheTrunksInnerLoop) {
  const SensorTrunk trunk = MakeTrunk();
  const TrunkTargets targets = Generate(trunk, TrueLatent(8));
  Fitter::Options options;
  options.strategy = FitStrategy::FromString("meta_sgd:3");
  VectorXd z;
  const Fitter::Summary summary = FitFrame(trunk, options, targets, &z, DoubleProblem());
  EXPECT_EQ(summary.termination_type, FitTermination::kCompleted);
  EXPECT_EQ(summary.iterations, 3);
  MetaSgd::Options meta;
  meta.inner_steps = 3;
  const VectorXd expected = MetaSgd(meta).FitLatent<double>(
      trunk.siren, trunk.siren.Grid<double>(kRows, kCols), targets.values.cast<double>(),
      targets.weights.cast<double>(), trunk.alpha);
  EXPECT_LE((z - expected).cwiseAbs().maxCoeff(), 1e-12);
}

TEST(LatentFitter, AMetaSgdFitReportsTheCostsAndPsnrOfSeparatePasses) {
  // The start's cost comes from the first step's forward pass and the final PSNR from
  // the pass over the problem's pixels: both must be what separate passes give, for a
  // whole-frame problem (PSNR from the same pass) and a thinned one (its own pass).
  const SensorTrunk trunk = MakeTrunk();
  TrunkTargets targets = Generate(trunk, TrueLatent(8));
  targets.values += 0.02 * Uniform(kRows * kCols, 1, 43).cast<float>();
  for (int j = 0; j < kRows * kCols; j += 7) targets.weights[j] = 0;
  Fitter::Options options;
  options.strategy = FitStrategy::FromString("meta_sgd:3");
  for (const int max_pixels : {0, 100}) {
    for (const auto precision :
         {LatentProblem::Precision::kFloat, LatentProblem::Precision::kDouble}) {
      LatentProblem::Options problem_options;
      problem_options.precision = precision;
      problem_options.max_pixels = max_pixels;
      const LatentProblem problem(trunk, targets, problem_options);
      VectorXd z;
      const Fitter::Summary summary = Fitter(trunk, options).Fit(problem, &z);
      SCOPED_TRACE(std::to_string(max_pixels) + " pixels, " + ToString(precision));
      const VectorXd start = problem.StartLatent();
      const double prior = 0.5 * start.squaredNorm() / (summary.sigma_z * summary.sigma_z);
      std::optional<double> ignored;
      const double start_cost = problem.DataCost(start, &ignored) + prior;
      EXPECT_NEAR(summary.initial_cost, start_cost, 1e-5 * start_cost);
      const double final_prior = 0.5 * z.squaredNorm() / (summary.sigma_z * summary.sigma_z);
      EXPECT_NEAR(summary.final_cost, problem.DataCost(z, &ignored) + final_prior,
                  1e-9 * summary.final_cost);
      EXPECT_NEAR(summary.psnr, problem.Psnr(z), 1e-4);
      EXPECT_LT(summary.final_cost, summary.initial_cost);
    }
  }
}

TEST(LatentFitter, MaskedPixelsDoNotChangeTheFit) {
  const SensorTrunk trunk = MakeTrunk();
  TrunkTargets a = Generate(trunk, TrueLatent(8));
  a.values += 0.02 * Uniform(kRows * kCols, 1, 41).cast<float>();
  TrunkTargets b = a;
  for (int j = 0; j < kRows * kCols; j += 3) {
    a.weights[j] = b.weights[j] = 0;
    a.values(j, 0) = std::numeric_limits<float>::quiet_NaN();
    b.values(j, 0) = 1e6f;
  }
  const Fitter fitter(trunk, CeresOptions(10));
  VectorXd za, zb;
  const Fitter::Summary sa = fitter.Fit(LatentProblem(trunk, a, {}), &za);
  const Fitter::Summary sb = fitter.Fit(LatentProblem(trunk, b, {}), &zb);
  EXPECT_EQ(za, zb);
  EXPECT_EQ(sa.psnr, sb.psnr);
  EXPECT_EQ(sa.num_valid_pixels, kRows * kCols - (kRows * kCols + 2) / 3);
}

TEST(LatentFitter, SubsamplingUsesTheRequestedPixels) {
  const SensorTrunk trunk = MakeTrunk();
  const TrunkTargets targets = Generate(trunk, TrueLatent(8));
  LatentProblem::Options problem;
  problem.pixel_stride = 2;
  problem.max_pixels = 100;
  problem.sigma_z = 1e4;
  VectorXd z;
  const Fitter::Summary summary = FitFrame(trunk, CeresOptions(30), targets, &z, problem);
  EXPECT_EQ(summary.num_pixels_used, 100);
  EXPECT_EQ(summary.num_valid_pixels, kRows * kCols);
  EXPECT_GT(summary.psnr, 60.0) << summary.FullReport();  // PSNR over all pixels
  // The fit's costs are over its 100 pixels; its PSNR over the whole frame. The closing
  // cost may come from Ceres' last Jacobian pass, whose sines round differently from a
  // forward pass's in the last float bit: at this exact fit the cost is itself rounding,
  // so the bound is relative to the starting cost.
  const LatentProblem thinned(trunk, targets, problem);
  std::optional<double> no_psnr;
  const double data_cost = thinned.DataCost(z, &no_psnr);
  EXPECT_NEAR(summary.final_cost, data_cost + 0.5 * (z / 1e4).squaredNorm(),
              1e-12 * summary.initial_cost);
  EXPECT_EQ(summary.psnr, thinned.Psnr(z));
}

class KnnFitTest : public ::testing::Test {
 protected:
  KnnFitTest() : trunk_(MakeTrunk()), index_(8) {
    latents_ = (0.5 * Uniform(300, 8, 51)).cast<float>();
    Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows = latents_;
    index_.Add(rows.data(), 300);
  }
  SensorTrunk trunk_;
  BruteForceKnnIndex index_;
  MatrixXf latents_;
};

TEST_F(KnnFitTest, AnExactQueryReturnsThatFunctasetLatent) {
  Fitter::Options options;
  options.strategy = FitStrategy::FromString("knn");
  const Fitter fitter(trunk_, options, &index_, &latents_);
  const VectorXd z17 = latents_.row(17).transpose().cast<double>();
  VectorXd z;
  const TrunkTargets targets = Generate(trunk_, z17);
  const Fitter::Summary summary = fitter.Fit(LatentProblem(trunk_, targets, {}), z17, &z);
  EXPECT_EQ(summary.termination_type, FitTermination::kCompleted);
  ASSERT_EQ(summary.neighbor_labels.size(), 8u);
  EXPECT_EQ(summary.neighbor_labels[0], 17);
  EXPECT_DOUBLE_EQ(summary.neighbor_weights[0], 1.0);
  EXPECT_EQ(z, z17);
}

TEST_F(KnnFitTest, InverseDistanceWeightsSumToOneAndDecrease) {
  Fitter::Options options;
  options.strategy = FitStrategy::FromString("knn");
  options.knn_k = 5;
  const Fitter fitter(trunk_, options, &index_, &latents_);
  const VectorXd z_true = TrueLatent(8, 9);
  VectorXd z;
  const TrunkTargets targets = Generate(trunk_, z_true);
  const Fitter::Summary summary = fitter.Fit(LatentProblem(trunk_, targets, {}), &z);
  ASSERT_EQ(summary.neighbor_weights.size(), 5u);
  double sum = 0;
  VectorXd expected = VectorXd::Zero(8);
  for (int i = 0; i < 5; ++i) {
    sum += summary.neighbor_weights[i];
    if (i > 0) {
      EXPECT_LE(summary.neighbor_weights[i], summary.neighbor_weights[i - 1]);
    }
    expected += summary.neighbor_weights[i] *
                latents_.row(summary.neighbor_labels[i]).transpose().cast<double>();
  }
  EXPECT_NEAR(sum, 1.0, 1e-12);
  EXPECT_LE((z - expected).norm(), 1e-6);
}

TEST_F(KnnFitTest, KnnPlusCeresIsAtLeastAsGoodAsKnn) {
  // A frame near (not at) functaset entry 40.
  const VectorXd z_true = latents_.row(40).transpose().cast<double>() + 0.05 * Uniform(8, 1, 61);
  const TrunkTargets targets = Generate(trunk_, z_true);
  Fitter::Options options;
  options.strategy = FitStrategy::FromString("knn");
  VectorXd z_knn, z_refined;
  const LatentProblem problem(trunk_, targets, {});
  const Fitter::Summary knn = Fitter(trunk_, options, &index_, &latents_).Fit(problem, &z_knn);
  options.strategy = FitStrategy::FromString("knn+ceres:20");
  const Fitter::Summary refined =
      Fitter(trunk_, options, &index_, &latents_).Fit(problem, &z_refined);
  ASSERT_EQ(refined.stages.size(), 3u);  // start, knn, ceres
  EXPECT_DOUBLE_EQ(refined.stages[1].cost, knn.final_cost);
  EXPECT_LE(refined.final_cost, knn.final_cost);
  EXPECT_GE(refined.psnr, knn.psnr) << knn.BriefReport() << "\n" << refined.BriefReport();
  EXPECT_TRUE(refined.IsSolutionUsable());
}

// ---- Extremes ------------------------------------------------------------------------------

// Ceres never raises the objective; meta-SGD descends the trunk's own MSE with fixed
// rates and need not lower it, so only Ceres fits are checked for descent.
void ExpectFiniteAndUsable(const Fitter::Summary& summary, const VectorXd& z) {
  EXPECT_TRUE(z.allFinite()) << summary.FullReport();
  EXPECT_TRUE(std::isfinite(summary.final_cost)) << summary.FullReport();
  EXPECT_FALSE(std::isnan(summary.psnr)) << summary.FullReport();
  EXPECT_TRUE(summary.IsSolutionUsable()) << summary.FullReport();
  if (summary.ceres_ran) {
    EXPECT_LE(summary.final_cost, summary.initial_cost) << summary.FullReport();
  }
}

TEST(LatentFitterExtremes, BlankAndSaturatedFramesGiveFiniteLatents) {
  const SensorTrunk trunk = MakeTrunk();
  for (float value : {0.0f, 1.0f, 1e4f}) {
    TrunkTargets targets = Generate(trunk, VectorXd::Zero(8));
    targets.values.setConstant(value);
    for (const char* strategy : {"ceres:20", "meta_sgd:3"}) {
      Fitter::Options options;
      options.strategy = FitStrategy::FromString(strategy);
      VectorXd z;
      const Fitter::Summary summary = FitFrame(trunk, options, targets, &z);
      ExpectFiniteAndUsable(summary, z);
    }
  }
}

TEST(LatentFitterExtremes, AFrameWithNoValidPixelReturnsThePriorMeanAndSaysSo) {
  const SensorTrunk trunk = MakeTrunk();
  TrunkTargets targets = Generate(trunk, TrueLatent(8));
  targets.values.setConstant(std::numeric_limits<float>::quiet_NaN());
  targets.weights.setZero();
  for (const char* strategy : {"ceres:10", "meta_sgd:3"}) {
    Fitter::Options options;
    options.strategy = FitStrategy::FromString(strategy);
    VectorXd z = VectorXd::Constant(8, 5.0);
    const Fitter::Summary summary = FitFrame(trunk, options, targets, &z);
    EXPECT_EQ(summary.termination_type, FitTermination::kNoValidPixels);
    EXPECT_FALSE(summary.IsSolutionUsable());
    EXPECT_NE(summary.message.find("no valid pixel"), std::string::npos);
    EXPECT_EQ(z, VectorXd::Zero(8));
    EXPECT_EQ(summary.psnr, 0.0);
    EXPECT_NE(summary.BriefReport().find("NO_VALID_PIXELS"), std::string::npos);
  }
}

TEST(LatentFitterExtremes, AMostlyNanFrameFitsItsFewValidPixels) {
  const SensorTrunk trunk = MakeTrunk();
  TrunkTargets targets = Generate(trunk, TrueLatent(8));
  for (int j = 0; j < kRows * kCols; ++j) {
    if (j % 20 == 0) continue;  // 5% valid
    targets.values(j, 0) = std::numeric_limits<float>::quiet_NaN();
    targets.weights[j] = 0;
  }
  VectorXd z;
  const Fitter::Summary summary = FitFrame(trunk, CeresOptions(20), targets, &z);
  ExpectFiniteAndUsable(summary, z);
  EXPECT_EQ(summary.num_pixels_used, kRows * kCols / 20);
  EXPECT_GT(summary.psnr, 30.0) << summary.FullReport();
}

TEST(LatentFitterExtremes, AFarWarmStartComesBackFinite) {
  const SensorTrunk trunk = MakeTrunk();
  const VectorXd z_true = TrueLatent(8);
  const TrunkTargets targets = Generate(trunk, z_true);
  for (const char* strategy : {"ceres:20", "meta_sgd:3"}) {
    Fitter::Options options;
    options.strategy = FitStrategy::FromString(strategy);
    VectorXd z;
    const Fitter::Summary summary = Fitter(trunk, options).Fit(
        LatentProblem(trunk, targets, {}), VectorXd(100.0 * z_true), &z);
    ExpectFiniteAndUsable(summary, z);
  }
}

TEST(LatentFitterExtremes, TinyAndHugePriorWidthsStayFinite) {
  const SensorTrunk trunk = MakeTrunk();
  const VectorXd z_true = TrueLatent(8);
  const TrunkTargets targets = Generate(trunk, z_true);
  const Fitter fitter(trunk, CeresOptions(30));
  LatentProblem::Options problem;
  problem.sigma_z = 1e-8;
  VectorXd z;
  Fitter::Summary summary =
      fitter.Fit(LatentProblem(trunk, targets, problem), VectorXd(z_true), &z);
  ExpectFiniteAndUsable(summary, z);
  EXPECT_LE(z.cwiseAbs().maxCoeff(), 1e-6) << summary.FullReport();  // pinned to the prior mean
  problem.sigma_z = 1e8;
  summary = fitter.Fit(LatentProblem(trunk, targets, problem), &z);
  ExpectFiniteAndUsable(summary, z);
  EXPECT_GT(summary.psnr, 60.0) << summary.FullReport();
}

TEST(LatentFitterExtremes, FloatAndDoubleEvaluationAgree) {
  // Stated tolerance: latents within 1e-4 relative. Float residuals carry about 1e-7
  // relative error, which moves the optimum of a well-conditioned fit by about that much
  // times the condition number of J (about 1e3 here).
  const SensorTrunk trunk = MakeTrunk();
  TrunkTargets targets = Generate(trunk, TrueLatent(8));
  targets.values += 0.01 * Uniform(kRows * kCols, 1, 71).cast<float>();
  VectorXd z32, z64;
  const Fitter::Summary s32 = FitFrame(trunk, CeresOptions(30), targets, &z32);
  const Fitter::Summary s64 = FitFrame(trunk, CeresOptions(30), targets, &z64, DoubleProblem());
  EXPECT_LE((z32 - z64).norm(), 1e-4 * z64.norm()) << s32.FullReport() << s64.FullReport();
  EXPECT_NEAR(s32.psnr, s64.psnr, 0.01);
}

TEST(LatentFitterExtremes, RobustLossesFitAndKeepTheCostFinite) {
  const SensorTrunk trunk = MakeTrunk();
  TrunkTargets targets = Generate(trunk, TrueLatent(8));
  for (int j = 0; j < kRows * kCols; j += 10) targets.values(j, 0) += 5.0f;  // outliers
  for (auto loss : {LatentProblem::RobustLoss::kHuber, LatentProblem::RobustLoss::kCauchy}) {
    LatentProblem::Options problem;
    problem.robust_loss = loss;
    VectorXd z;
    const Fitter::Summary summary = FitFrame(trunk, CeresOptions(30), targets, &z, problem);
    ExpectFiniteAndUsable(summary, z);
  }
}

TEST(LatentFitterExtremes, BadWarmStartsAndProblemsOfAnotherTrunkThrow) {
  const SensorTrunk trunk = MakeTrunk();
  const Fitter fitter(trunk, Fitter::Options());
  VectorXd z;
  const TrunkTargets targets = Generate(trunk, TrueLatent(8));
  const LatentProblem problem(trunk, targets, {});
  EXPECT_THROW(fitter.Fit(problem, VectorXd::Zero(3), &z), std::invalid_argument);
  EXPECT_THROW(fitter.Fit(problem, VectorXd::Constant(8, NAN), &z), std::invalid_argument);
  EXPECT_THROW(fitter.Fit(problem, nullptr), std::invalid_argument);
  const SensorTrunk other = MakeTrunk(1, 32, /*latent_dim=*/6);
  const TrunkTargets other_targets = Generate(other, TrueLatent(6));
  try {
    fitter.Fit(LatentProblem(other, other_targets, {}), &z);
    FAIL() << "expected a throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("6 entries"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace tactfunc
