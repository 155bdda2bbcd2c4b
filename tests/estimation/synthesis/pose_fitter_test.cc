// Copyright 2026 The tactfunc Authors.
#include "estimation/synthesis/pose_fitter.h"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "ceres/autodiff_cost_function.h"
#include "ceres/dynamic_autodiff_cost_function.h"
#include "ceres/dynamic_numeric_diff_cost_function.h"
#include "ceres/jet.h"
#include "estimation/functaset/functaset.h"
#include "estimation/synthesis/generator_posterior.h"
#include "models/pose/pose_mlp.h"
#include "models/simulator/tool.h"
#include "tests/support/sampler_test_util.h"

namespace tactfunc {
namespace {

constexpr int kRows = 10, kCols = 12, kLatent = 6;

SensorTrunk Trunk() { return testing_util::MakeTinyTrunk(kRows, kCols, 16, 2, kLatent, 11); }

PoseGenerator Generator() {
  PoseGenerator g = testing_util::MakeTinyGenerator(kLatent, 12, 5);
  g.SetLatentStandardization(Eigen::VectorXd::Zero(kLatent),
                             Eigen::VectorXd::Constant(kLatent, 0.6));
  return g;
}

// The frame the generator renders at a pose (noise-free unless noise > 0).
TrunkTargets Render(const SensorTrunk& trunk, const PoseGenerator& g, int tool, const SE2d& pose,
                    double depth, double noise = 0) {
  return testing_util::MakeTargets(trunk, g.Generate(tool, pose, depth), noise, 17);
}

TEST(SE2Manifold, PlusMinusRoundTripAndJacobiansMatchDifferences) {
  const SE2Manifold m;
  const double x[3] = {0.01, -0.02, 2.9};
  const double delta[3] = {0.003, -0.001, 0.5};  // crosses yaw = pi
  double y[3], back[3];
  ASSERT_TRUE(m.Plus(x, delta, y));
  EXPECT_LE(y[2], M_PI);
  ASSERT_TRUE(m.Minus(y, x, back));
  for (int i = 0; i < 3; ++i) EXPECT_NEAR(back[i], delta[i], 1e-12);
  double J[9], Jm[9];
  ASSERT_TRUE(m.PlusJacobian(x, J));
  ASSERT_TRUE(m.MinusJacobian(x, Jm));
  for (int c = 0; c < 3; ++c) {
    double d[3] = {0, 0, 0};
    d[c] = 1e-7;
    double yp[3], ym[3];
    m.Plus(x, d, yp);
    d[c] = -1e-7;
    m.Plus(x, d, ym);
    for (int r = 0; r < 3; ++r) EXPECT_NEAR(J[3 * r + c], (yp[r] - ym[r]) / 2e-7, 1e-6);
  }
  const Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> P(J), M(Jm);
  EXPECT_TRUE((M * P).isApprox(Eigen::Matrix3d::Identity(), 1e-12));
}

// The autodiff reference: trunk and generator as Jet templates.
struct AutoDiffPoseResidual {
  const LatentProblem* problem;
  const PoseGenerator* g;
  int tool;
  template <typename T>
  bool operator()(T const* const* p, T* r) const {
    std::vector<T> z(kLatent);
    g->GenerateT<T>(tool, p[0], p[1][0], z.data());
    const double inv = 1.0 / problem->sigma();
    for (int j = 0; j < problem->num_pixels(); ++j) {
      const T coord[2] = {T(problem->coords()(j, 0)), T(problem->coords()(j, 1))};
      T out;
      problem->trunk().siren.Evaluate(coord, z.data(), &out);
      r[j] = (out - T(problem->pixel_targets()(j, 0))) *
             T(std::sqrt(problem->pixel_weights()[j]) * inv);
    }
    return true;
  }
};

TEST(GeneratorPoseCost, AnalyticJacobianMatchesAutodiffAndNumericDifferentiation) {
  const SensorTrunk trunk = Trunk();
  const PoseGenerator g = Generator();
  const TrunkTargets targets = Render(trunk, g, 0, SE2d::FromXYYaw(1e-3, 0, 0.7), 0.008, 0.01);
  LatentProblem::Options po;
  po.precision = LatentProblem::Precision::kDouble;  // central differences need double passes
  const LatentProblem problem(trunk, targets, po);
  const GeneratorPoseCost analytic(problem, g, 0);
  const double pose[3] = {-5e-4, 1.5e-3, -2.2};
  const double depth = 0.011;
  const double* params[2] = {pose, &depth};
  const int n = problem.num_residuals();
  std::vector<double> r(n), J0(3 * n), J1(n);
  double* jac[2] = {J0.data(), J1.data()};
  ASSERT_TRUE(analytic.Evaluate(params, r.data(), jac));

  auto* functor = new AutoDiffPoseResidual{&problem, &g, 0};
  ceres::DynamicAutoDiffCostFunction<AutoDiffPoseResidual, 4> autodiff(functor);
  autodiff.AddParameterBlock(3);
  autodiff.AddParameterBlock(1);
  autodiff.SetNumResiduals(n);
  std::vector<double> ra(n), A0(3 * n), A1(n);
  double* ajac[2] = {A0.data(), A1.data()};
  ASSERT_TRUE(autodiff.Evaluate(params, ra.data(), ajac));

  struct Numeric {
    const GeneratorPoseCost* cost;
    bool operator()(double const* const* p, double* r) const {
      return cost->Evaluate(p, r, nullptr);
    }
  };
  ceres::NumericDiffOptions nd;
  ceres::DynamicNumericDiffCostFunction<Numeric, ceres::CENTRAL> numeric(new Numeric{&analytic},
                                                                         ceres::TAKE_OWNERSHIP, nd);
  numeric.AddParameterBlock(3);
  numeric.AddParameterBlock(1);
  numeric.SetNumResiduals(n);
  std::vector<double> rn(n), N0(3 * n), N1(n);
  double* njac[2] = {N0.data(), N1.data()};
  ASSERT_TRUE(numeric.Evaluate(params, rn.data(), njac));

  double scale = 0;
  for (double v : A0) scale = std::max(scale, std::abs(v));
  for (int i = 0; i < n; ++i) {
    EXPECT_NEAR(r[i], ra[i], 1e-9 * (1 + std::abs(ra[i])));
    for (int c = 0; c < 3; ++c) {
      EXPECT_NEAR(J0[3 * i + c], A0[3 * i + c], 1e-9 * scale) << "residual " << i << " col " << c;
      EXPECT_NEAR(J0[3 * i + c], N0[3 * i + c], 1e-5 * scale) << "residual " << i << " col " << c;
    }
    EXPECT_NEAR(J1[i], A1[i], 1e-9 * scale);
    EXPECT_NEAR(J1[i], N1[i], 1e-5 * scale);
  }
}

TEST(PoseCosts, EqualHalfTheSquaredResidualsAtEachStartsLatent) {
  const SensorTrunk trunk = Trunk();
  const PoseGenerator g = Generator();
  const TrunkTargets targets = Render(trunk, g, 1, SE2d::FromXYYaw(-1e-3, 2e-3, 0.3), 0.01, 0.01);
  LatentProblem::Options po;
  po.precision = LatentProblem::Precision::kDouble;
  const LatentProblem problem(trunk, targets, po);
  const std::vector<PoseStart> starts = {{SE2d::FromXYYaw(-1e-3, 2e-3, 0.3), 0.01, "a"},
                                         {SE2d::FromXYYaw(2e-3, 0, -2.5), 0.004, "b"},
                                         {SE2d::FromXYYaw(0, -3e-3, 1.9), 0.015, "c"}};
  for (int tool = 0; tool < 2; ++tool) {
    const std::vector<double> costs = PoseCosts(problem, g, tool, starts);
    ASSERT_EQ(costs.size(), starts.size());
    for (std::size_t i = 0; i < starts.size(); ++i) {
      // The latent of one start from Generate, its residuals from the problem.
      const Eigen::VectorXd z = g.Generate(tool, starts[i].sensor_T_object, starts[i].depth_m);
      Eigen::VectorXd r(problem.num_residuals());
      ASSERT_TRUE(problem.ResidualsAndJacobian(z.data(), r.data(), nullptr));
      const double expected = 0.5 * r.squaredNorm();
      EXPECT_NEAR(costs[i], expected, 1e-10 * expected) << "tool " << tool << " start " << i;
      EXPECT_NEAR(PoseCost(problem, g, tool, starts[i].sensor_T_object, starts[i].depth_m),
                  costs[i], 1e-10 * expected);
    }
  }
  EXPECT_TRUE(PoseCosts(problem, g, 0, {}).empty());
}

TEST(FitPoseModes, RecoversTheRenderedPoseFromNearbyStartsAndKeepsDistinctModes) {
  const SensorTrunk trunk = Trunk();
  const PoseGenerator g = Generator();
  const SE2d truth = SE2d::FromXYYaw(1.2e-3, -0.8e-3, 0.6);
  const TrunkTargets targets = Render(trunk, g, 0, truth, 0.009);
  LatentProblem::Options po;
  po.sigma = 0.01;
  const LatentProblem problem(trunk, targets, po);
  PoseFitOptions options;
  options.max_iterations = 50;
  const std::vector<PoseStart> starts = {{SE2d::FromXYYaw(1.0e-3, -0.6e-3, 0.5), 0.0085, "near"},
                                         {SE2d::FromXYYaw(1.3e-3, -0.9e-3, 0.65), 0.0095, "near2"}};
  const std::vector<PoseFit> modes = FitPoseModes(problem, g, 0, starts, options);
  ASSERT_FALSE(modes.empty());
  EXPECT_TRUE(modes[0].usable);
  EXPECT_NEAR(modes[0].sensor_T_object.x(), truth.x(), 2e-5);
  EXPECT_NEAR(modes[0].sensor_T_object.y(), truth.y(), 2e-5);
  EXPECT_NEAR(modes[0].sensor_T_object.yaw(), truth.yaw(), 1e-3);
  EXPECT_NEAR(modes[0].depth_m, 0.009, 2e-5);
  EXPECT_LT(modes[0].cost, 1e-4);
  // The two nearby starts reach one mode.
  EXPECT_EQ(modes.size(), 1u);
  // The depth stays inside its bounds from a start outside them.
  const std::vector<PoseFit> bounded =
      FitPoseModes(problem, g, 0, {{SE2d::FromXYYaw(1.2e-3, -0.8e-3, 0.6), 0.5, "deep"}}, options);
  ASSERT_FALSE(bounded.empty());
  EXPECT_LE(bounded[0].depth_m, options.depth_max_m);
}

// The modes of tool 0 fitted to the noise-free frame it renders at (truth, depth), from one
// start.
std::vector<PoseFit> FitRendered(const SE2d& truth, double depth, const PoseStart& start,
                                 const PoseFitOptions& options) {
  const SensorTrunk trunk = Trunk();
  const PoseGenerator g = Generator();
  LatentProblem::Options po;
  po.sigma = 0.01;
  const LatentProblem problem(trunk, Render(trunk, g, 0, truth, depth), po);
  return FitPoseModes(problem, g, 0, {start}, options);
}

TEST(FitPoseModes, StepsPastADepthBoundEndOnTheBound) {
  // The frame is rendered deeper than the depth may go: the minimizer's steps are
  // projected onto the bounds (no line search), so the fit ends on the bound.
  const SE2d truth = SE2d::FromXYYaw(0.5e-3, 0.3e-3, -0.4);
  const PoseStart start{SE2d::FromXYYaw(0.6e-3, 0.2e-3, -0.3), 0.008, "shallow"};
  PoseFitOptions options;
  options.max_iterations = 50;
  options.depth_max_m = 0.010;
  const std::vector<PoseFit> bounded = FitRendered(truth, 0.012, start, options);
  ASSERT_FALSE(bounded.empty());
  EXPECT_LE(bounded[0].depth_m, options.depth_max_m);
  EXPECT_NEAR(bounded[0].depth_m, options.depth_max_m, 1e-6);
  // Inside the bounds the same frame is fitted exactly, from the same start.
  options.depth_max_m = 0.0175;
  const std::vector<PoseFit> free = FitRendered(truth, 0.012, start, options);
  ASSERT_FALSE(free.empty());
  EXPECT_NEAR(free[0].depth_m, 0.012, 2e-5);
  EXPECT_LT(free[0].cost, bounded[0].cost);
}

// A frame's problem (every pixel, sigma 0.01) and a coarse one on 40 of its pixels; it
// holds the frame, which the problems refer to.
struct TwoProblems {
  TwoProblems(const SensorTrunk& trunk, TrunkTargets frame)
      : targets(std::move(frame)),
        problem(trunk, targets, Options(0)),
        coarse(trunk, targets, Options(40)) {}
  static LatentProblem::Options Options(int max_pixels) {
    LatentProblem::Options po;
    po.sigma = 0.01;
    po.max_pixels = max_pixels;
    return po;
  }
  TrunkTargets targets;
  LatentProblem problem, coarse;
};

TEST(FitPoseModes, AModesCostAndJtJAreThoseOfAnEvaluationAtIt) {
  // The fit takes them from the minimizer's last Jacobian evaluation; they must be the
  // ones a new evaluation at the returned pose and depth gives, on both stages.
  const SensorTrunk trunk = Trunk();
  const PoseGenerator g = Generator();
  const TwoProblems two(trunk, Render(trunk, g, 0, SE2d::FromXYYaw(-0.4e-3, 0.9e-3, 1.1), 0.009,
                                      0.02));
  const LatentProblem& problem = two.problem;
  const LatentProblem& coarse = two.coarse;
  PoseFitOptions options;
  options.max_iterations = 3;  // stopped before convergence, too
  const std::vector<PoseStart> starts = {{SE2d::FromXYYaw(-0.2e-3, 0.7e-3, 0.9), 0.0080, "a"},
                                         {SE2d::FromXYYaw(0.5e-3, -0.5e-3, -2.0), 0.0110, "b"}};
  for (const LatentProblem* c : {static_cast<const LatentProblem*>(nullptr), &coarse}) {
    const std::vector<PoseFit> modes = FitPoseModes(problem, g, 0, starts, options, c);
    ASSERT_FALSE(modes.empty());
    const GeneratorPoseCost cost(problem, g, 0);
    for (const PoseFit& f : modes) {
      const int m = problem.num_residuals();
      const double pose[3] = {f.sensor_T_object.x(), f.sensor_T_object.y(),
                              f.sensor_T_object.yaw()};
      const double depth = f.depth_m;
      Eigen::VectorXd r(m), J1(m);
      Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> J0(m, 3);
      const double* params[2] = {pose, &depth};
      double* jac[2] = {J0.data(), J1.data()};
      ASSERT_TRUE(cost.Evaluate(params, r.data(), jac));
      Eigen::Matrix<double, Eigen::Dynamic, 4> J(m, 4);
      J.leftCols<3>() = J0 * PoseCoordinatesFromTangent(f.sensor_T_object);
      J.col(3) = J1;
      const Eigen::Matrix4d JtJ = J.transpose() * J;
      EXPECT_NEAR(f.cost, 0.5 * r.squaredNorm(), 1e-9 * (1 + f.cost));
      EXPECT_LE((f.JtJ - JtJ).norm(), 1e-9 * JtJ.norm()) << f.JtJ << "\n\n" << JtJ;
    }
  }
}

TEST(FitPoseModes, ItsTwoStagesRunApartGiveTheSameModes) {
  // GeneratorPosterior's tool pruning runs the coarse stage of every tool before the rest
  // of any; the modes must be those of the search run in one go.
  const SensorTrunk trunk = Trunk();
  const PoseGenerator g = Generator();
  const TwoProblems two(trunk, Render(trunk, g, 1, SE2d::FromXYYaw(0.6e-3, -0.3e-3, 0.4), 0.010,
                                      0.02));
  const LatentProblem& problem = two.problem;
  const LatentProblem& coarse = two.coarse;
  PoseFitOptions options;
  options.coarse_refined_starts = 3;
  options.max_refined_starts = 2;
  std::vector<PoseStart> starts;
  for (int k = 0; k < 6; ++k) {
    starts.push_back({SE2d::FromXYYaw(0.2e-3 * k, -0.1e-3 * k, -3.0 + k), 0.004 + 0.002 * k,
                      "s" + std::to_string(k)});
  }
  starts.push_back({SE2d::FromXYYaw(0, 0, 0), 0.03, "deep"});  // clamped to the bound
  const CoarseStarts first = CoarsePoseStarts(coarse, g, 1, starts, options);
  ASSERT_EQ(first.starts.size(), 3u);
  ASSERT_EQ(first.costs.size(), 3u);
  EXPECT_EQ(first.BestCost(), *std::min_element(first.costs.begin(), first.costs.end()));
  for (std::size_t i = 0; i < first.starts.size(); ++i) {
    EXPECT_EQ(first.costs[i], PoseCost(coarse, g, 1, first.starts[i].sensor_T_object,
                                       first.starts[i].depth_m));
  }
  const std::vector<PoseFit> apart = FitPoseModesFromCoarse(problem, g, 1, first, options);
  const std::vector<PoseFit> together = FitPoseModes(problem, g, 1, starts, options, &coarse);
  ASSERT_FALSE(together.empty());
  ASSERT_EQ(apart.size(), together.size());
  for (std::size_t i = 0; i < apart.size(); ++i) {
    EXPECT_EQ(apart[i].sensor_T_object.x(), together[i].sensor_T_object.x());
    EXPECT_EQ(apart[i].sensor_T_object.yaw(), together[i].sensor_T_object.yaw());
    EXPECT_EQ(apart[i].depth_m, together[i].depth_m);
    EXPECT_EQ(apart[i].cost, together[i].cost);
    EXPECT_EQ(apart[i].start, together[i].start);
  }
  EXPECT_THROW(CoarsePoseStarts(coarse, g, 1, {}, options), std::invalid_argument);
  CoarseStarts broken = first;
  broken.costs.pop_back();
  EXPECT_THROW(FitPoseModesFromCoarse(problem, g, 1, broken, options), std::invalid_argument);
  EXPECT_EQ(CoarseStarts().BestCost(), std::numeric_limits<double>::infinity());
}

LaplaceComponent Component(const std::string& tool, int n, double weight, const SE2d& mean) {
  LaplaceComponent c;
  c.tool = tool;
  c.symmetry_order = n;
  c.weight = weight;
  c.mean = mean;
  c.covariance = 1e-8 * Eigen::Matrix4d::Identity();
  return c;
}

TEST(PoseMixture, MeanWeighsTheModesOfOneToolAfterFoldingItsSymmetry) {
  // A C4 tool's two modes at yaw 0.1 and 0.1 + pi / 2 + 0.2 are 0.2 rad apart once
  // folded: their weighted mean lies 3/4 of the way towards the heavier one.
  const PoseMixture mixture(
      {Component("square", 4, 0.45, SE2d::FromXYYaw(1e-3, 0, 0.1)),
       Component("square", 4, 0.15, SE2d::FromXYYaw(3e-3, 0, 0.1 + M_PI / 2 + 0.2)),
       Component("rod", 2, 0.4, SE2d::FromXYYaw(-5e-3, 0, 1.0))});
  const SE2d square = mixture.Mean("square");
  EXPECT_NEAR(square.x(), 1.5e-3, 1e-5);
  EXPECT_NEAR(YawErrorModuloSymmetry(square.yaw(), 0.15, 4), 0, 1e-3);
  // The unconditional mean is that of the most probable tool (square: 0.6 of the mass).
  EXPECT_NEAR(mixture.Mean().x(), square.x(), 1e-12);
  // One component: its own mean.
  const SE2d rod = mixture.Mean("rod");
  EXPECT_NEAR(rod.x(), -5e-3, 1e-12);
  EXPECT_NEAR(YawErrorModuloSymmetry(rod.yaw(), 1.0, 2), 0, 1e-9);
  EXPECT_THROW(mixture.Mean("spoon"), std::invalid_argument);
  // The square's mean yaw is given in the representative of its heavier mode (0.1).
  EXPECT_NEAR(square.yaw(), 0.15, 1e-3);
}

TEST(PoseMixture, MeanGivesTheYawNearestTheHeaviestModeNotAnotherRepresentative) {
  // A rod (C2) mode at yaw -2.4 rad folds to -2.4 + pi for the mean; the mean is still
  // reported at -2.4, the component's own pose, as a consumer comparing it with the
  // mode expects. Likewise for a C3 tool whose two modes straddle the fold.
  const PoseMixture rod({Component("rod", 2, 1.0, SE2d::FromXYYaw(1e-3, 2e-3, -2.4))});
  EXPECT_NEAR(rod.Mean().yaw(), -2.4, 1e-12);
  EXPECT_NEAR(rod.Mean().x(), 1e-3, 1e-12);
  const double third = 2 * M_PI / 3;
  const PoseMixture c3({Component("triangle", 3, 0.75, SE2d::FromXYYaw(0, 0, 2.9)),
                        Component("triangle", 3, 0.25, SE2d::FromXYYaw(0, 0, 2.9 - third - 0.2))});
  // Folded, the modes are 0.2 apart; the mean sits a quarter of the way to the lighter.
  EXPECT_NEAR(c3.Mean().yaw(), 2.85, 1e-3);
  // Asymmetric tools are not folded: the mean is the barycentre itself.
  const PoseMixture l({Component("l_shape", 1, 0.5, SE2d::FromXYYaw(0, 0, 3.0)),
                       Component("l_shape", 1, 0.5, SE2d::FromXYYaw(0, 0, -3.0))});
  EXPECT_NEAR(std::abs(l.Mean().yaw()), M_PI, 1e-9);
}

// An l_shape frame (the generator's tool 0) with a little noise, the tool the two
// GeneratorPosterior tests below ask to be found among both.
const SE2d kLShapeTruth = SE2d::FromXYYaw(-0.7e-3, 0.4e-3, -1.0);
TrunkTargets LShapeFrame(const SensorTrunk& trunk, const PoseGenerator& g) {
  return Render(trunk, g, 0, kLShapeTruth, 0.010, 0.002);
}

TEST(GeneratorPosterior, LaplaceCoversTheTruthAndPrefersTheRenderingTool) {
  const SensorTrunk trunk = Trunk();
  const PoseGenerator g = Generator();
  const SE2d& truth = kLShapeTruth;
  const TrunkTargets targets = LShapeFrame(trunk, g);
  GeneratorPosterior::Options options;
  options.sigma_inflation = 1;
  options.fit.max_iterations = 50;
  const GeneratorPosterior posterior(trunk, g, options);  // no k-NN: grid starts
  PoseMixture mixture;
  const GeneratorPosterior::Summary s = posterior.Estimate(targets, "", &mixture);
  ASSERT_TRUE(s.usable) << s.message;
  EXPECT_EQ(s.tool, "l_shape");
  EXPECT_GT(s.tool_probabilities.at("l_shape"), 0.95);
  EXPECT_NEAR(s.mean.x(), truth.x(), 5e-4);
  EXPECT_NEAR(YawErrorModuloSymmetry(s.mean.yaw(), truth.yaw(), 1), 0, 0.05);
  EXPECT_TRUE(mixture.Contains(truth, 0.9, 400, 1, "l_shape"));
  // The posterior mean of the tool: near the truth as well.
  EXPECT_NEAR(mixture.Mean("l_shape").x(), truth.x(), 5e-4);
  // A scene that names the tool fits only that tool.
  const GeneratorPosterior::Summary named = posterior.Estimate(targets, "rod", &mixture);
  ASSERT_TRUE(named.usable);
  for (const LaplaceComponent& c : mixture.components()) EXPECT_EQ(c.tool, "rod");
  EXPECT_THROW(posterior.Estimate(targets, "spoon", &mixture), std::invalid_argument);
  // Deterministic.
  PoseMixture again;
  posterior.Estimate(targets, "", &again);
  EXPECT_EQ(again.Mode().x(), posterior.Estimate(targets, "", &mixture).mean.x());
}

// Each mode of `actual` is `expected`'s, in order: its tool, pose and likelihood to the bit.
void ExpectSameModes(const std::vector<LaplaceComponent>& expected,
                     const std::vector<LaplaceComponent>& actual) {
  ASSERT_EQ(actual.size(), expected.size());
  for (std::size_t i = 0; i < expected.size(); ++i) {
    EXPECT_EQ(actual[i].tool, expected[i].tool);
    EXPECT_EQ(actual[i].mean.x(), expected[i].mean.x());
    EXPECT_EQ(actual[i].mean.yaw(), expected[i].mean.yaw());
    EXPECT_EQ(actual[i].log_likelihood, expected[i].log_likelihood);
  }
}

TEST(GeneratorPosterior, ToolPruningRefinesOnlyTheToolsNearTheBestAndKeepsTheirModes) {
  const SensorTrunk trunk = Trunk();
  const PoseGenerator g = Generator();
  const TrunkTargets targets = LShapeFrame(trunk, g);
  GeneratorPosterior::Options options;
  options.sigma_inflation = 1;
  EXPECT_EQ(options.tool_prune_ratio, 2);  // the default: on
  options.tool_prune_ratio = 1;
  {
    // Without a coarse stage (the frame has no more pixels than it) nothing is screened
    // out or pruned.
    PoseMixture m;
    const GeneratorPosterior::Summary s =
        GeneratorPosterior(trunk, g, options).Estimate(targets, "", &m);
    EXPECT_EQ(s.tools_screened_in, 2);
    EXPECT_EQ(s.tools_refined, 2);
  }
  options.coarse_pixels = 40;  // tools are compared after it
  options.tool_prune_ratio = 0;
  PoseMixture every, pruned;
  const GeneratorPosterior::Summary all =
      GeneratorPosterior(trunk, g, options).Estimate(targets, "", &every);
  ASSERT_TRUE(all.usable) << all.message;
  EXPECT_EQ(all.tools_refined, 2);
  ASSERT_EQ(all.tool, "l_shape");
  // At ratio 1 only the tool of the lowest coarse cost goes on: the rendering one.
  options.tool_prune_ratio = 1;
  const GeneratorPosterior::Summary one =
      GeneratorPosterior(trunk, g, options).Estimate(targets, "", &pruned);
  ASSERT_TRUE(one.usable) << one.message;
  EXPECT_EQ(one.tools_refined, 1);
  EXPECT_EQ(one.tool, "l_shape");
  EXPECT_EQ(one.tool_probabilities.at("rod"), 0);  // listed, with no weight
  EXPECT_EQ(one.tool_probabilities.at("l_shape"), 1);
  // The kept tool's modes are the ones the unpruned search found, to the bit.
  std::vector<LaplaceComponent> kept;
  for (const LaplaceComponent& c : every.components()) {
    if (c.tool == "l_shape") kept.push_back(c);
  }
  ExpectSameModes(kept, pruned.components());
  // A named tool is the only candidate: nothing to prune.
  EXPECT_EQ(GeneratorPosterior(trunk, g, options).Estimate(targets, "rod", &pruned).tools_refined,
            1);
  options.tool_prune_ratio = 0.5;
  std::string error;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, ::testing::HasSubstr("tool_prune_ratio"));
}

// Screening runs each tool's coarse stage from its starts without the grids first; a tool
// it prunes never reaches the full coarse stage, and a tool it keeps gets the modes the
// search without screening finds, to the bit.
TEST(GeneratorPosterior, ToolScreeningKeepsTheBestToolAndItsModes) {
  const SensorTrunk trunk = Trunk();
  const PoseGenerator g = Generator();
  const TrunkTargets targets = LShapeFrame(trunk, g);
  GeneratorPosterior::Options options;
  options.sigma_inflation = 1;
  EXPECT_TRUE(options.tool_screen);  // the default: on
  options.coarse_pixels = 40;
  options.tool_prune_ratio = 1;
  options.tool_screen = false;
  PoseMixture unscreened, screened;
  const GeneratorPosterior::Summary without =
      GeneratorPosterior(trunk, g, options).Estimate(targets, "", &unscreened);
  ASSERT_TRUE(without.usable) << without.message;
  EXPECT_EQ(without.tools_screened_in, 2);  // no screening: every tool's coarse stage runs
  EXPECT_EQ(without.tools_refined, 1);
  options.tool_screen = true;
  const GeneratorPosterior::Summary with =
      GeneratorPosterior(trunk, g, options).Estimate(targets, "", &screened);
  ASSERT_TRUE(with.usable) << with.message;
  EXPECT_EQ(with.tools_screened_in, 1);
  EXPECT_EQ(with.tools_refined, 1);
  EXPECT_EQ(with.tool, "l_shape");
  EXPECT_EQ(with.tool_probabilities.at("rod"), 0);
  ExpectSameModes(unscreened.components(), screened.components());
  // A named tool is never screened.
  EXPECT_EQ(GeneratorPosterior(trunk, g, options).Estimate(targets, "rod", &screened)
                .tools_screened_in,
            1);
}

// The screening's starts: the k-NN and pose MLP starts (or the centre's few yaws) and
// their flips, without the position and yaw grids.
TEST(GeneratorPosterior, StartsWithoutGridsLeaveOutThePositionAndYawGrids) {
  const SensorTrunk trunk = Trunk();
  const PoseGenerator g = Generator();
  const TrunkTargets targets = LShapeFrame(trunk, g);
  GeneratorPosterior::Options options;
  const GeneratorPosterior posterior(trunk, g, options);
  const LatentProblem problem(trunk, targets, options.problem);
  const Eigen::VectorXf query = Eigen::VectorXf::Zero(trunk.siren.latent_dim());
  const int l_shape = g.ToolIndex("l_shape");
  const std::vector<PoseStart> full = posterior.Starts(problem, query, l_shape);
  const std::vector<PoseStart> bare =
      posterior.Starts(problem, query, l_shape, nullptr, /*grids=*/false);
  ASSERT_FALSE(bare.empty());
  EXPECT_LT(bare.size(), full.size());
  for (const PoseStart& s : bare) {
    EXPECT_EQ(s.source.find("+shift"), std::string::npos) << s.source;
    EXPECT_EQ(s.source.find("+grid"), std::string::npos) << s.source;
  }
  int shifted = 0;
  for (const PoseStart& s : full) shifted += s.source.find("+shift") != std::string::npos;
  EXPECT_GT(shifted, 0);
}

// The final stage refines each mode again on more pixels and takes the Laplace
// approximation there: the summary's pixels are the final problem's, and the best mode's
// objective on that problem is lower than where the search on few pixels left it.
TEST(GeneratorPosterior, TheFinalStageRefinesTheModesOnItsOwnPixels) {
  const SensorTrunk trunk = Trunk();
  const PoseGenerator g = Generator();
  const SE2d truth = SE2d::FromXYYaw(-0.7e-3, 0.4e-3, -1.0);
  const TrunkTargets targets = Render(trunk, g, 0, truth, 0.010, 0.01);
  GeneratorPosterior::Options options;
  options.sigma_inflation = 2;
  options.problem.max_pixels = 24;
  options.coarse_pixels = 12;
  PoseMixture searched, refined;
  const GeneratorPosterior::Summary s =
      GeneratorPosterior(trunk, g, options).Estimate(targets, "l_shape", &searched);
  ASSERT_TRUE(s.usable) << s.message;
  EXPECT_EQ(s.num_pixels, 24);
  EXPECT_EQ(options.RankingProblem().max_pixels, 24);
  options.final_pixels = kRows * kCols;  // every pixel
  EXPECT_EQ(options.RankingProblem().max_pixels, kRows * kCols);
  const GeneratorPosterior::Summary f =
      GeneratorPosterior(trunk, g, options).Estimate(targets, "l_shape", &refined);
  ASSERT_TRUE(f.usable) << f.message;
  EXPECT_EQ(f.num_pixels, kRows * kCols);
  LatentProblem::Options whole = options.problem;
  whole.max_pixels = 0;
  const LatentProblem all(trunk, targets, whole);
  const int tool = g.ToolIndex("l_shape");
  const auto best_cost = [&](const PoseMixture& m) {
    double best = std::numeric_limits<double>::infinity();
    for (const LaplaceComponent& c : m.components()) {
      best = std::min(best, PoseCost(all, g, tool, c.mean, c.depth_m));
    }
    return best;
  };
  EXPECT_LT(best_cost(refined), best_cost(searched));
  EXPECT_LT(PoseCost(all, g, tool, refined.Mode(), refined.components().front().depth_m),
            PoseCost(all, g, tool, SE2d::FromXYYaw(0, 0, 0), 0.010));
  // -1 (the default) takes the generator's recorded stage: none here, then 20 pixels.
  options.final_pixels = -1;
  EXPECT_EQ(GeneratorPosterior(trunk, g, options).options().final_pixels, 0);
  PoseGenerator staged = g;
  staged.set_final_pixels(20);
  const GeneratorPosterior by_generator(trunk, staged, options);
  EXPECT_EQ(by_generator.options().final_pixels, 20);
  EXPECT_EQ(by_generator.options().RankingProblem().max_pixels, 20);
  EXPECT_EQ(by_generator.Estimate(targets, "l_shape", nullptr).num_pixels, 20);
  std::string error;
  options.final_pixels = -2;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, ::testing::HasSubstr("final_pixels"));
}

// The mode weights follow the evidence of the likelihood tempered by 1/tau: the
// components, their log evidences and log likelihoods do not depend on tau; their
// weights' log ratios are TemperedLogEvidence's differences, in which only the
// likelihoods' difference is scaled by 1/tau (the Occam factors are not); at tau = 1 they
// are the log evidences' differences.
TEST(GeneratorPosterior, TheWeightTemperatureTempersTheLikelihoodOnly) {
  const SensorTrunk trunk = Trunk();
  const PoseGenerator g = Generator();
  const TrunkTargets targets =
      Render(trunk, g, 0, SE2d::FromXYYaw(-0.7e-3, 0.4e-3, -1.0), 0.010, 0.002);
  GeneratorPosterior::Options options;
  options.sigma_inflation = 3;
  options.fit.max_iterations = 20;
  PoseMixture plain, sharp;
  const GeneratorPosterior at_one(trunk, g, options);  // every tool: several components
  ASSERT_TRUE(at_one.Estimate(targets, "", &plain).usable);
  options.weight_temperature = 0.5;
  const GeneratorPosterior at_half(trunk, g, options);
  ASSERT_TRUE(at_half.Estimate(targets, "", &sharp).usable);
  ASSERT_GE(plain.components().size(), 2u);
  ASSERT_EQ(sharp.components().size(), plain.components().size());
  // The components in the same order at both temperatures (by their poses).
  auto same = [](const LaplaceComponent& x, const LaplaceComponent& y) {
    return x.tool == y.tool && x.mean.x() == y.mean.x() && x.mean.yaw() == y.mean.yaw();
  };
  const LaplaceComponent& a = sharp.components()[0];
  const LaplaceComponent& b = sharp.components()[1];
  const LaplaceComponent* a1 = nullptr;
  const LaplaceComponent* b1 = nullptr;
  for (const LaplaceComponent& c : plain.components()) {
    if (same(c, a)) a1 = &c;
    if (same(c, b)) b1 = &c;
  }
  ASSERT_NE(a1, nullptr);
  ASSERT_NE(b1, nullptr);
  EXPECT_EQ(a.log_evidence, a1->log_evidence);
  EXPECT_EQ(a.log_likelihood, a1->log_likelihood);
  EXPECT_LT(a.log_likelihood, 0);
  const double tempered = TemperedLogEvidence(a, 0.5) - TemperedLogEvidence(b, 0.5);
  EXPECT_NEAR(std::log(a.weight / b.weight), tempered, 1e-9 * (1 + std::abs(tempered)));
  // Only the likelihood is scaled: the Occam factors' difference enters once.
  const double occam = (a.log_evidence - a.log_likelihood) - (b.log_evidence - b.log_likelihood);
  const double expected = 2 * (a.log_likelihood - b.log_likelihood) + occam +
                          0.5 * (a.dimension - b.dimension) * std::log(0.5);
  EXPECT_NEAR(tempered, expected, 1e-9 * (1 + std::abs(expected)));
  const double untempered = a1->log_evidence - b1->log_evidence;
  EXPECT_NEAR(std::log(a1->weight / b1->weight), untempered, 1e-9 * (1 + std::abs(untempered)));
  EXPECT_EQ(TemperedLogEvidence(a, 1.0), a.log_evidence);
  // A generator calibrated when tau tempered the whole evidence keeps w ~ Z^(1/tau).
  PoseGenerator legacy = g;
  legacy.set_weight_temperature(0.5, false);
  options.weight_temperature = 0;
  PoseMixture old;
  ASSERT_TRUE(GeneratorPosterior(trunk, legacy, options).Estimate(targets, "", &old).usable);
  ASSERT_GE(old.components().size(), 2u);
  const LaplaceComponent& c = old.components()[0];
  const LaplaceComponent& e = old.components()[1];
  EXPECT_NEAR(std::log(c.weight / e.weight), 2 * (c.log_evidence - e.log_evidence),
              1e-9 * (1 + std::abs(c.log_evidence - e.log_evidence)));
  std::string error;
  options.weight_temperature = -1;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, ::testing::HasSubstr("weight_temperature"));
}

// Temperature scaling on hand-made cases: two distant modes whose log likelihoods differ
// by D, the truth in the heavier one in 9 cases of 10, is fitted best by tau = D /
// logit(0.9); two close modes that share the truth's density do not pull tau up.
TEST(FitWeightTemperature, MatchesHowOftenTheHeaviestModeHoldsTheTruth) {
  const double logit = std::log(0.9 / 0.1);
  const double d = 0.25 * logit;
  const WeightTemperatureCase in_heavier{{d, 0.0}, {0.0, -1e3}, {}, {}};
  const WeightTemperatureCase in_lighter{{d, 0.0}, {-1e3, 0.0}, {}, {}};
  std::vector<WeightTemperatureCase> cases(9, in_heavier);
  cases.push_back(in_lighter);
  const double tau = FitWeightTemperature(cases, 0.05);
  EXPECT_NEAR(std::log(tau), std::log(0.25), std::log(20.0) / 60) << tau;  // one grid step
  // The order of the components does not matter.
  std::vector<WeightTemperatureCase> swapped;
  for (const WeightTemperatureCase& c : cases) {
    swapped.push_back({{c.log_likelihood[1], c.log_likelihood[0]},
                       {c.log_density[1], c.log_density[0]},
                       {},
                       {}});
  }
  EXPECT_EQ(FitWeightTemperature(swapped, 0.05), tau);
  // A truth between two close modes (equal density under both) leaves tau at the floor
  // the separated cases give alone.
  std::vector<WeightTemperatureCase> close(9, in_heavier);
  close.push_back({{d, 0.0}, {-1.0, -1.0}, {}, {}});
  EXPECT_NEAR(FitWeightTemperature(close, 0.1), 0.1, 1e-12);
  // The truth always in the heaviest mode: the grid's floor. No cases: 1.
  EXPECT_NEAR(FitWeightTemperature({{{1.0, 0.0, -2.0}, {0.0, -1e3, -1e3}, {}, {}}}, 0.1), 0.1,
              1e-12);
  EXPECT_EQ(FitWeightTemperature({}, 0.05), 1);
  // The truth in the lighter mode of every case: as flat as the grid allows.
  EXPECT_EQ(FitWeightTemperature({in_lighter}, 0.05), 1);
  EXPECT_THROW(FitWeightTemperature({{{1.0, 0.0}, {0.0}, {}, {}}}, 0.05), std::invalid_argument);
  EXPECT_THROW(FitWeightTemperature({{{1.0, 0.0}, {0.0, 0.0}, {0.0}, {}}}, 0.05),
               std::invalid_argument);
  // An Occam factor is not tempered: the likelihoods tie and the first mode is twice as
  // wide (log 2 more evidence), so its weight is 2/3 at every tau, every tau scores the
  // same and the tie keeps tau = 1, though the truth is in the wide mode 9 times in 10.
  // (Were the factor tempered, w = 2^(1/tau) / (1 + 2^(1/tau)) = 0.9 would pick tau =
  // log 2 / log 9, about 0.32.)
  const WeightTemperatureCase wide_holds{{0.0, 0.0}, {0.0, -1e3}, {std::log(2.0), 0.0}, {}};
  const WeightTemperatureCase narrow_holds{{0.0, 0.0}, {-1e3, 0.0}, {std::log(2.0), 0.0}, {}};
  std::vector<WeightTemperatureCase> tied(9, wide_holds);
  tied.push_back(narrow_holds);
  EXPECT_EQ(FitWeightTemperature(tied, 0.05), 1);
  // The same cases with the first likelihood D higher: the weights sharpen with 1/tau
  // while the Occam factor's log 2 stays, so the score's best tau moves below 1.
  const WeightTemperatureCase better_wide{{d, 0.0}, {0.0, -1e3}, {std::log(2.0), 0.0}, {}};
  const WeightTemperatureCase better_narrow{{d, 0.0}, {-1e3, 0.0}, {std::log(2.0), 0.0}, {}};
  std::vector<WeightTemperatureCase> mixed(9, better_wide);
  mixed.push_back(better_narrow);
  // The truth in the heavier mode 9 times in 10: w = 0.9 at D / tau + log 2 = logit(0.9).
  const double tau_mixed = FitWeightTemperature(mixed, 0.05);
  EXPECT_NEAR(std::log(tau_mixed), std::log(d / (logit - std::log(2.0))), std::log(20.0) / 60)
      << tau_mixed;
  EXPECT_THROW(FitWeightTemperature(cases, 0), std::invalid_argument);
  EXPECT_THROW(FitWeightTemperature(cases, 1.5), std::invalid_argument);
}

// A pose MLP that reads another trunk's latents (a generator trained through a larger
// trunk than the pose MLP's): its start is the MLP at the frame's meta-SGD latent under
// its own trunk, and a trunk of another frame format, or none for a mismatched MLP, is
// refused.
TEST(GeneratorPosterior, APoseMlpOnItsOwnTrunkStartsFromThatTrunksLatent) {
  const SensorTrunk trunk = Trunk();
  const PoseGenerator g = Generator();
  const SensorTrunk other = testing_util::MakeTinyTrunk(kRows, kCols, 16, 2, 4, 23);  // d = 4
  PoseMlp::Options mo;
  mo.input_dim = 4;
  mo.hidden_sizes = {8};
  const PoseMlp mlp(mo, 3);
  const TrunkTargets targets = Render(trunk, g, 1, SE2d::FromXYYaw(1e-3, -2e-3, 0.3), 0.010);
  const GeneratorPosterior::Options options;
  const GeneratorPosterior posterior(trunk, g, options, nullptr, &mlp, &other);
  const LatentProblem problem(trunk, targets, options.problem);
  const LatentProblem own(other, targets, options.problem);
  const Eigen::VectorXf query =
      own.MetaSgdSteps(Eigen::VectorXd::Zero(own.dim()), other.meta_sgd.inner_steps).cast<float>();
  const SE2d expected = mlp.Predict(query.cast<double>(), g.SymmetryOrder(1));
  int found = 0;
  for (const PoseStart& start : posterior.Starts(problem, Eigen::VectorXf(), 1, &query)) {
    if (start.source != "mlp") continue;
    ++found;
    EXPECT_EQ(start.sensor_T_object.x(), expected.x());
    EXPECT_EQ(start.sensor_T_object.y(), expected.y());
    EXPECT_EQ(start.sensor_T_object.yaw(), expected.yaw());
  }
  EXPECT_EQ(found, 1);
  EXPECT_TRUE(posterior.Estimate(targets, g.options().tools[1], nullptr).usable);
  EXPECT_THROW(GeneratorPosterior(trunk, g, options, nullptr, &mlp), std::invalid_argument);
  const SensorTrunk wider = testing_util::MakeTinyTrunk(kRows, kCols + 1, 16, 2, 4, 23);
  EXPECT_THROW(GeneratorPosterior(trunk, g, options, nullptr, &mlp, &wider), std::invalid_argument);
}

// A k-NN functaset of another trunk's latents (a generator with a trunk of its own): the
// frame's query is its latent under the functaset's trunk (KnnPoseStarts::query_trunk).
// The functaset holds the frame under that trunk (labelled with one pose) and under the
// renderer's (labelled with another); with one neighbour and no other starts the search
// starts from the first pose with the query trunk given and from the second without,
// each exactly as a functaset holding that entry alone.
TEST(GeneratorPosterior, KnnStartsReadTheFrameUnderTheFunctasetsOwnTrunk) {
  const SensorTrunk trunk = Trunk();
  const PoseGenerator g = Generator();
  const SensorTrunk own = testing_util::MakeTinyTrunk(kRows, kCols, 16, 2, kLatent, 29);
  const std::string tool = g.options().tools[1];
  const TrunkTargets targets = Render(trunk, g, 1, SE2d::FromXYYaw(1e-3, -2e-3, 0.3), 0.010);
  GeneratorPosterior::Options options;
  options.knn_k = 1;
  options.flip_starts = false;
  options.yaw_grid = 1;  // no other yaws
  options.position_grid_m = 0;
  auto latent = [&](const SensorTrunk& t) {
    const LatentProblem p(t, targets, options.problem);
    return Eigen::VectorXf(
        p.MetaSgdSteps(Eigen::VectorXd::Zero(p.dim()), t.meta_sgd.inner_steps).cast<float>());
  };
  const Eigen::VectorXf z_own = latent(own), z_renderer = latent(trunk);
  ASSERT_GT((z_own - z_renderer).norm(), 1e-5);
  const FunctasetEntry under_own{"own", Split::kTrain,
                                 PoseLabel{tool, SE2d::FromXYYaw(1.5e-3, -1.5e-3, 0.35), 0.011},
                                 z_own};
  const FunctasetEntry under_renderer{
      "renderer", Split::kTrain, PoseLabel{tool, SE2d::FromXYYaw(-3e-3, 2e-3, -1.0), 0.008},
      z_renderer};
  auto functaset = [](const std::vector<FunctasetEntry>& entries) {
    Functaset f(0, "test");
    f.AddSensor(SensorKind::kSoftBubble, kLatent);
    for (const FunctasetEntry& e : entries) f.Add(SensorKind::kSoftBubble, e);
    return f;
  };
  const Functaset both = functaset({under_own, under_renderer});
  const Functaset only_own = functaset({under_own}), only_renderer = functaset({under_renderer});
  auto mode = [&](const KnnPoseStarts& knn) {
    PoseMixture mixture;
    const GeneratorPosterior posterior(trunk, g, options, &knn);
    EXPECT_TRUE(posterior.Estimate(targets, tool, &mixture).usable);
    return mixture.components().front().mean;
  };
  const SE2d with_own = mode(KnnPoseStarts(both, SensorKind::kSoftBubble, &own));
  const SE2d expected_own = mode(KnnPoseStarts(only_own, SensorKind::kSoftBubble));
  EXPECT_EQ(with_own.x(), expected_own.x());
  EXPECT_EQ(with_own.y(), expected_own.y());
  EXPECT_EQ(with_own.yaw(), expected_own.yaw());
  const SE2d without = mode(KnnPoseStarts(both, SensorKind::kSoftBubble));
  const SE2d expected_renderer = mode(KnnPoseStarts(only_renderer, SensorKind::kSoftBubble));
  // The two starts end in different modes, so the equalities tell the queries apart.
  EXPECT_TRUE(expected_own.x() != expected_renderer.x() ||
              expected_own.yaw() != expected_renderer.yaw());
  EXPECT_EQ(without.x(), expected_renderer.x());
  EXPECT_EQ(without.yaw(), expected_renderer.yaw());
  // The query trunk given as the renderer itself changes nothing.
  const SE2d same = mode(KnnPoseStarts(both, SensorKind::kSoftBubble, &trunk));
  EXPECT_EQ(same.x(), without.x());
  EXPECT_EQ(same.yaw(), without.yaw());
  // A query trunk of another latent size, or another frame format, is refused.
  const SensorTrunk smaller = testing_util::MakeTinyTrunk(kRows, kCols, 16, 2, 4, 29);
  EXPECT_THROW(KnnPoseStarts(both, SensorKind::kSoftBubble, &smaller), std::invalid_argument);
  const SensorTrunk wider = testing_util::MakeTinyTrunk(kRows, kCols + 1, 16, 2, kLatent, 29);
  const KnnPoseStarts knn_wider(both, SensorKind::kSoftBubble, &wider);
  EXPECT_THROW(GeneratorPosterior(trunk, g, options, &knn_wider), std::invalid_argument);
}

// The yaw grid copies every start position to the grid's yaws: each added start sits
// exactly where its base start sits, with the base's depth. The list grows while it is
// copied, so a reference into it would read freed memory once it reallocates; with a
// position grid of 24 rings the list is large enough for glibc to give it its own
// mapping, which a reallocation unmaps, so such a read would crash here.
TEST(GeneratorPosterior, YawGridStartsKeepTheirBaseStartsPositionAndDepth) {
  const SensorTrunk trunk = Trunk();
  const PoseGenerator g = Generator();
  const TrunkTargets targets = Render(trunk, g, 0, SE2d::FromXYYaw(1e-3, -2e-3, 0.3), 0.010);
  const LatentProblem problem(trunk, targets, LatentProblem::Options());
  GeneratorPosterior::Options options;
  options.position_grid_m = 0.1e-3;
  options.position_grid_rings = 24;
  const int shifts = 49 * 49 - 1;
  const GeneratorPosterior posterior(trunk, g, options);  // no k-NN: centre, position grid
  for (int tool : {0, 1}) {
    const int n = g.SymmetryOrder(tool);
    const std::vector<PoseStart> starts = posterior.Starts(problem, Eigen::VectorXf(), tool);
    // Base starts: the centre's yaw grid (8 / n yaws) and the positions around it.
    const int centre = std::max(1, 8 / n);
    const int base = centre + shifts;
    const int per_base = options.yaw_grid / n - 1;  // the grid's other yaws in one period
    ASSERT_EQ(static_cast<int>(starts.size()), base * (1 + per_base)) << "tool " << tool;
    int nonzero = 0;
    for (int i = 0; i < base; ++i) {
      for (int k = 0; k < per_base; ++k) {
        const PoseStart& copy = starts[base + i * per_base + k];
        EXPECT_EQ(copy.sensor_T_object.x(), starts[i].sensor_T_object.x()) << i << " " << k;
        EXPECT_EQ(copy.sensor_T_object.y(), starts[i].sensor_T_object.y()) << i << " " << k;
        EXPECT_EQ(copy.depth_m, starts[i].depth_m);
        EXPECT_EQ(copy.source, starts[i].source + "+grid");
        EXPECT_NEAR(std::remainder(copy.sensor_T_object.yaw() - starts[i].sensor_T_object.yaw() -
                                       2 * M_PI * (k + 1) / options.yaw_grid,
                                   2 * M_PI),
                    0, 1e-9);
      }
      nonzero += starts[i].sensor_T_object.x() != 0 || starts[i].sensor_T_object.y() != 0;
    }
    EXPECT_EQ(nonzero, shifts);  // the position grid's starts
  }
}

}  // namespace
}  // namespace tactfunc
