// Copyright 2026 The tactfunc Authors.
//
// The exact meta-gradient through K inner steps is checked against 4th-order central
// differences of the outer loss (relative error 1e-6 per parameter block), against the
// same reverse loop with Hessian-vector products that repeat the inner passes (bit for
// bit), and the first-order variant is shown to differ from it measurably.
#include "models/trunk/meta_sgd.h"

#include <cmath>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "models/trunk/latent_modulated_siren.h"
#include "tests/support/derivative_checks.h"
#include "tests/support/uniform_numbers.h"

namespace tactfunc {
namespace {

using Siren = LatentModulatedSiren;
using Eigen::MatrixXd;
using Eigen::MatrixXf;
using Eigen::VectorXd;
using Eigen::VectorXf;

using testing_util::Uniform;  // deterministic numbers in [-1, 1)

Siren SmallSiren(int layers, unsigned seed) {
  Siren::Options options;
  options.width = 10;
  options.num_hidden_layers = layers;
  options.latent_dim = 5;
  options.output_channels = 2;
  Siren siren(options, seed);
  siren.SetParameters(siren.parameters() +
                      0.05 * Uniform(siren.NumParameters(), 1, seed + 3));
  return siren;
}

struct Problem {
  MatrixXd coords, targets;
  VectorXd weights, alpha;
};

Problem MakeProblem(const Siren& siren) {
  Problem p;
  p.coords = Uniform(9, 2, 1);
  p.targets = 0.5 * Uniform(9, 2, 2);
  p.weights = 0.5 * (Uniform(9, 1, 3).array() + 1.0);
  p.weights[4] = 0.0;
  // Rates large enough that the inner steps move z by O(0.1) (the gradient w.r.t. z
  // is O(0.1) here), so the second-order terms matter, and small enough that the
  // outer loss stays smooth at the finite-difference step (alpha ~ 3 needs h < 1e-5).
  p.alpha = 1.0 + 0.5 * Uniform(siren.latent_dim(), 1, 4).array();
  return p;
}

// Finite-difference step: the first layer's phases move by omega_0 * h per unit of
// theta and are composed through 2-3 sine layers and K inner steps, so the 4th-order
// rule's truncation error (~ h^4 f^(5)) needs h = 1e-5 to stay below 1e-6; rounding
// then costs ~ 1e-16 |L| / h ~ 1e-12.
constexpr double kStep = 1e-5;

using testing_util::Derivative;
using testing_util::ExpectClose;

TEST(MetaSgdOptions, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(MetaSgd::Options().IsValid(&error)) << error;
}

TEST(MetaSgdOptions, BadOptionsNameTheField) {
  MetaSgd::Options options;
  options.inner_steps = -1;
  std::string error;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("inner_steps"), std::string::npos) << error;
  EXPECT_THROW(MetaSgd{options}, std::invalid_argument);
  options = MetaSgd::Options();
  options.latent_l2_weight = -0.1;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("latent_l2_weight"), std::string::npos) << error;
}

// The meta-gradient of `result` against 4th-order central differences of
// outer_loss(trunk, alpha), per parameter block and for alpha.
void ExpectFiniteDifferenceGradients(
    const MetaSgd::Result<double>& result, const Siren& siren, const VectorXd& alpha,
    const std::function<double(const Siren&, const VectorXd&)>& outer_loss,
    const std::string& what) {
  Siren probe = siren;
  VectorXd numeric_theta(siren.NumParameters());
  for (int i = 0; i < siren.NumParameters(); ++i) {
    numeric_theta[i] = Derivative(
        [&](double delta) {
          VectorXd theta = siren.parameters();
          theta[i] += delta;
          probe.SetParameters(theta);
          return outer_loss(probe, alpha);
        },
        kStep);
  }
  VectorXd numeric_alpha(siren.latent_dim());
  for (int k = 0; k < siren.latent_dim(); ++k) {
    numeric_alpha[k] = Derivative(
        [&](double delta) {
          VectorXd moved = alpha;
          moved[k] += delta;
          return outer_loss(siren, moved);
        },
        kStep);
  }
  for (const ParameterBlock& block : siren.parameter_blocks()) {
    ExpectClose(result.dL_dtheta.segment(block.offset, block.size()),
                numeric_theta.segment(block.offset, block.size()), 1e-6, 1e-10,
                what + " " + block.Name());
  }
  ExpectClose(result.dL_dalpha, numeric_alpha, 1e-6, 1e-10, what + " alpha");
}

void CheckExactMetaGradient(int layers, int steps, double l2) {
  const Siren siren = SmallSiren(layers, 10 + layers);
  const Problem p = MakeProblem(siren);
  MetaSgd::Options options;
  options.inner_steps = steps;
  options.latent_l2_weight = l2;
  const MetaSgd meta(options);
  const MetaSgd::Result<double> result =
      meta.OuterLossAndGradient<double>(siren, p.coords, p.targets, p.weights, p.alpha);
  const std::string what = "L=" + std::to_string(layers) + " K=" + std::to_string(steps);
  EXPECT_GT(result.loss_at_zero - result.loss, 0.0) << what << ": inner loop must help";

  ExpectFiniteDifferenceGradients(
      result, siren, p.alpha,
      [&](const Siren& trunk, const VectorXd& alpha) {
        double loss;
        meta.FitLatent<double>(trunk, p.coords, p.targets, p.weights, alpha, &loss);
        return loss;
      },
      what);
}

TEST(MetaSgd, ExactMetaGradientMatchesFiniteDifferencesOfTheOuterLoss) {
  CheckExactMetaGradient(2, 3, 0.0);
  CheckExactMetaGradient(3, 2, 0.0);
}

TEST(MetaSgd, ExactMetaGradientWithLatentL2MatchesFiniteDifferences) {
  CheckExactMetaGradient(2, 3, 0.05);
}

// The outer loss with other outer targets (a frame's noise-free copy), written out: the
// inner loop fits p.targets from z_0 = 0, the outer loss is L(z_K; outer).
double OuterLossWrittenOut(const MetaSgd& meta, const Siren& siren, const Problem& p,
                           const VectorXd& alpha, const MatrixXd& outer) {
  const VectorXd z = meta.InnerLoop<double>(siren, p.coords, p.targets, p.weights, alpha,
                                            VectorXd::Zero(siren.latent_dim()),
                                            meta.options().inner_steps);
  return siren.Loss<double>(p.coords, z, outer, p.weights);
}

void CheckMetaGradientWithOuterTargets(bool first_order) {
  const Siren siren = SmallSiren(2, 21);
  const Problem p = MakeProblem(siren);
  const MatrixXd outer = p.targets + 0.2 * Uniform(9, 2, 8);
  MetaSgd::Options options;
  options.inner_steps = 3;
  options.first_order = first_order;
  const MetaSgd meta(options);
  const MetaSgd::Result<double> result =
      meta.OuterLossAndGradient<double>(siren, p.coords, p.targets, p.weights, p.alpha, &outer);
  const std::string what = "first_order " + std::to_string(first_order);
  EXPECT_NEAR(result.loss, OuterLossWrittenOut(meta, siren, p, p.alpha, outer),
              1e-12 * std::abs(result.loss))
      << what;
  // The noisy frame's own outer loss differs: the outer targets are used.
  const MetaSgd::Result<double> plain =
      meta.OuterLossAndGradient<double>(siren, p.coords, p.targets, p.weights, p.alpha);
  EXPECT_GT(std::abs(result.loss - plain.loss), 1e-3 * result.loss) << what;
  if (first_order) return;  // biased by design; only the exact gradient is checked
  ExpectFiniteDifferenceGradients(
      result, siren, p.alpha,
      [&](const Siren& trunk, const VectorXd& alpha) {
        return OuterLossWrittenOut(meta, trunk, p, alpha, outer);
      },
      what);
}

TEST(MetaSgd, OuterTargetsHaveTheExactMetaGradient) {
  CheckMetaGradientWithOuterTargets(false);
  CheckMetaGradientWithOuterTargets(true);
}

TEST(MetaSgd, OuterTargetsOfAnotherShapeThrow) {
  const Siren siren = SmallSiren(2, 22);
  const Problem p = MakeProblem(siren);
  const MatrixXd outer = Uniform(8, 2, 9);
  const MetaSgd meta{MetaSgd::Options()};
  EXPECT_THROW(
      meta.OuterLossAndGradient<double>(siren, p.coords, p.targets, p.weights, p.alpha, &outer),
      std::invalid_argument);
}

TEST(MetaSgd, ZeroInnerStepsIsThePlainLossAtZeroLatent) {
  const Siren siren = SmallSiren(2, 7);
  const Problem p = MakeProblem(siren);
  MetaSgd::Options options;
  options.inner_steps = 0;
  const MetaSgd::Result<double> result = MetaSgd(options).OuterLossAndGradient<double>(
      siren, p.coords, p.targets, p.weights, p.alpha);
  VectorXd dz, dtheta;
  const double loss = siren.LossAndGradient<double>(p.coords, VectorXd::Zero(5),
                                                    p.targets, p.weights, &dz, &dtheta);
  EXPECT_EQ(result.loss, loss);
  EXPECT_EQ(result.loss_at_zero, loss);
  EXPECT_EQ(result.dL_dtheta, dtheta);
  EXPECT_EQ(result.dL_dalpha, VectorXd::Zero(5));
}

TEST(MetaSgd, FirstOrderDiffersMeasurablyFromExact) {
  const Siren siren = SmallSiren(2, 8);
  const Problem p = MakeProblem(siren);
  MetaSgd::Options options;
  const MetaSgd::Result<double> exact = MetaSgd(options).OuterLossAndGradient<double>(
      siren, p.coords, p.targets, p.weights, p.alpha);
  options.first_order = true;
  const MetaSgd::Result<double> first = MetaSgd(options).OuterLossAndGradient<double>(
      siren, p.coords, p.targets, p.weights, p.alpha);
  EXPECT_EQ(exact.loss, first.loss);  // same inner loop
  const double theta_gap =
      (exact.dL_dtheta - first.dL_dtheta).norm() / exact.dL_dtheta.norm();
  const double alpha_gap =
      (exact.dL_dalpha - first.dL_dalpha).norm() / exact.dL_dalpha.norm();
  EXPECT_GT(theta_gap, 1e-2);
  EXPECT_GT(alpha_gap, 1e-2);
  RecordProperty("theta_relative_gap", std::to_string(theta_gap));
  RecordProperty("alpha_relative_gap", std::to_string(alpha_gap));
}

TEST(MetaSgd, FloatMetaGradientAgreesWithDouble) {
  const Siren siren = SmallSiren(2, 9);
  const Problem p = MakeProblem(siren);
  const MetaSgd meta{MetaSgd::Options()};
  const auto d =
      meta.OuterLossAndGradient<double>(siren, p.coords, p.targets, p.weights, p.alpha);
  const auto f = meta.OuterLossAndGradient<float>(
      siren, p.coords.cast<float>(), p.targets.cast<float>(), p.weights.cast<float>(),
      p.alpha.cast<float>());
  EXPECT_NEAR(f.loss, d.loss, 1e-5 * d.loss);
  ExpectClose(f.dL_dtheta.cast<double>(), d.dL_dtheta, 1e-3, 0.0, "float theta");
  ExpectClose(f.dL_dalpha.cast<double>(), d.dL_dalpha, 1e-3, 0.0, "float alpha");
}

// The reverse loop of meta_sgd.h with every Hessian-vector product from
// LossGradientAndHessianProduct at z_k, which repeats the inner step's passes (as
// MetaSgd did before it kept them on tapes).
template <typename S>
void UntapedMetaGradient(const Siren& siren, const MetaSgd::Options& options,
                         const Siren::MatrixX<S>& coords, const Siren::MatrixX<S>& targets,
                         const Siren::VectorX<S>& weights, const Siren::VectorX<S>& alpha,
                         Siren::VectorX<S>* dL_dtheta, Siren::VectorX<S>* dL_dalpha) {
  using VectorS = Siren::VectorX<S>;
  const int steps = options.inner_steps;
  const S two_lambda = static_cast<S>(2.0 * options.latent_l2_weight);
  std::vector<VectorS> z(steps + 1), g(steps);
  z[0] = siren.StartLatent<S>(coords, targets, weights);
  for (int k = 0; k < steps; ++k) {
    siren.LossAndGradient<S>(coords, z[k], targets, weights, &g[k], nullptr);
    g[k] += two_lambda * z[k];
    z[k + 1] = z[k] - alpha.cwiseProduct(g[k]);
  }
  VectorS v, Hv_z, Hv_theta;
  siren.LossAndGradient<S>(coords, z[steps], targets, weights, &v, dL_dtheta);
  *dL_dalpha = VectorS::Zero(siren.latent_dim());
  for (int k = steps - 1; k >= 0; --k) {
    *dL_dalpha -= v.cwiseProduct(g[k]);
    const VectorS u = alpha.cwiseProduct(v);
    siren.LossGradientAndHessianProduct<S>(coords, z[k], targets, weights, nullptr, u,
                                           nullptr, nullptr, &Hv_z, &Hv_theta);
    *dL_dtheta -= Hv_theta;
    if (k > 0) v -= Hv_z + two_lambda * u;
  }
}

template <typename S>
void ExpectMetaGradientEqualsUntaped(const Siren& siren, const Problem& p,
                                     const MetaSgd::Options& options) {
  const Siren::MatrixX<S> coords = p.coords.cast<S>(), targets = p.targets.cast<S>();
  const Siren::VectorX<S> weights = p.weights.cast<S>(), alpha = p.alpha.cast<S>();
  const MetaSgd::Result<S> result =
      MetaSgd(options).OuterLossAndGradient<S>(siren, coords, targets, weights, alpha);
  Siren::VectorX<S> dL_dtheta, dL_dalpha;
  UntapedMetaGradient<S>(siren, options, coords, targets, weights, alpha, &dL_dtheta,
                         &dL_dalpha);
  EXPECT_EQ(result.dL_dtheta, dL_dtheta)
      << "max difference " << (result.dL_dtheta - dL_dtheta).cwiseAbs().maxCoeff();
  EXPECT_EQ(result.dL_dalpha, dL_dalpha);
}

// Global, spatial (with a global part) and readout trunks, K = 1 and 3, with the latent
// L2 term, float and double.
TEST(MetaSgd, ExactMetaGradientEqualsTheReverseLoopOfUntapedHessianProducts) {
  std::vector<Siren::Options> variants(3, SmallSiren(2, 0).options());
  variants[1].spatial_rows = variants[1].spatial_cols = 2;
  variants[1].spatial_channels = 1;  // 4 of the 5 latent values
  variants[2].readout_rows = 3;
  variants[2].readout_cols = 4;
  for (const Siren::Options& trunk_options : variants) {
    Siren siren(trunk_options, 21);
    siren.SetParameters(siren.parameters() + 0.05 * Uniform(siren.NumParameters(), 1, 22));
    SCOPED_TRACE("spatial " + std::to_string(siren.has_spatial()) + " readout " +
                 std::to_string(siren.has_readout()));
    const Problem p = MakeProblem(siren);
    for (int steps : {1, 3}) {
      MetaSgd::Options options;
      options.inner_steps = steps;
      options.latent_l2_weight = 0.05;
      ExpectMetaGradientEqualsUntaped<double>(siren, p, options);
      ExpectMetaGradientEqualsUntaped<float>(siren, p, options);
    }
  }
}

TEST(MetaSgd, WrongAlphaSizeThrows) {
  const Siren siren = SmallSiren(2, 1);
  const Problem p = MakeProblem(siren);
  EXPECT_THROW(MetaSgd(MetaSgd::Options())
                   .OuterLossAndGradient<double>(siren, p.coords, p.targets, p.weights,
                                                 VectorXd::Ones(2)),
               std::invalid_argument);
}

}  // namespace
}  // namespace tactfunc
