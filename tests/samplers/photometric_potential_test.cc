// Copyright 2026 The tactfunc Authors.
//
// PhotometricPotential against what it defines: U and its gradient against central
// differences, the minibatch estimate over every pixel against U, and the Gauss-Newton
// Hessian (from the trunk's batched Jacobian) against J^T W J / sigma^2 + I / sigma_z^2
// with J built row by row from the trunk's reverse pass, in double.
#include "samplers/photometric_potential.h"

#include <cmath>
#include <numeric>
#include <stdexcept>
#include <vector>

#include "gtest/gtest.h"

namespace tactfunc {
namespace {

double Uniform(unsigned* state) {
  *state = *state * 1664525u + 1013904223u;
  return 2.0 * (*state >> 8) / double(1u << 24) - 1.0;
}

struct Fixture {
  PhotometricTrunk trunk;
  TrunkTargets targets;
  Eigen::VectorXd z;
};

Fixture MakeFixture() {
  PhotometricTrunk::Options o;
  o.rows = 8;
  o.cols = 10;
  o.width = 12;
  o.num_hidden_layers = 2;
  o.latent_dim = 9;
  o.shading_width = 6;
  o.supersample = 2;
  unsigned state = 3;
  Image reference(16, 20, 1);
  for (float& v : reference.data) v = static_cast<float>(0.5 + 0.2 * Uniform(&state));
  Fixture f{PhotometricTrunk(o, reference, 9), {}, Eigen::VectorXd(o.latent_dim)};
  Eigen::VectorXd head = f.trunk.head_parameters();
  head[head.size() - 1] = 1.2;  // markers that move
  f.trunk.SetHeadParameters(head);
  for (int k = 0; k < o.latent_dim; ++k) f.z[k] = 0.3 * Uniform(&state);
  f.targets.rows = o.rows;
  f.targets.cols = o.cols;
  f.targets.values.resize(o.rows * o.cols, 1);
  f.targets.weights.resize(o.rows * o.cols);
  for (int j = 0; j < o.rows * o.cols; ++j) {
    f.targets.values(j, 0) = static_cast<float>(0.05 * Uniform(&state));
    f.targets.weights[j] = j % 7 == 3 ? 0.0f : static_cast<float>(1.0 + 0.5 * Uniform(&state));
  }
  return f;
}

TEST(PhotometricPotentialTest, GradientMatchesCentralDifferencesAndMinibatchesScaleToU) {
  const Fixture f = MakeFixture();
  const PhotometricPotential potential(f.trunk, f.targets, 0.05, 0.7);
  EXPECT_EQ(potential.dim(), 9);
  EXPECT_EQ(potential.NumDataTerms(), 80 - 11);  // pixels 3, 10, ..., 73 weigh 0
  Eigen::VectorXd gradient;
  const double u = potential.Evaluate(f.z, &gradient);
  EXPECT_GT(u, 0.0);
  EXPECT_EQ(potential.Evaluate(f.z, nullptr), u);
  // U is evaluated in float: a step small enough for the SIREN's curvature (1e-3 misses
  // the pose's slopes by a few percent at this 4-pixels-a-unit grid), large enough for
  // float's rounding of U.
  const double h = 1e-4;
  const double scale = 1 + gradient.cwiseAbs().maxCoeff();
  for (int k = 0; k < potential.dim(); ++k) {
    Eigen::VectorXd up = f.z, down = f.z;
    up[k] += h;
    down[k] -= h;
    const double numeric = (potential.Evaluate(up, nullptr) - potential.Evaluate(down, nullptr)) /
                           (2 * h);
    EXPECT_NEAR(gradient[k], numeric, 5e-3 * scale) << "dU/dz[" << k << "]";
  }
  // Every data term once: the minibatch estimate is U itself.
  std::vector<int> all(potential.NumDataTerms());
  std::iota(all.begin(), all.end(), 0);
  Eigen::VectorXd batch_gradient;
  EXPECT_NEAR(potential.EvaluateMinibatch(f.z, all, &batch_gradient), u, 1e-6 * u);
  EXPECT_LT((batch_gradient - gradient).cwiseAbs().maxCoeff(),
            1e-5 * (1 + gradient.cwiseAbs().maxCoeff()));
  // Half the terms, scaled by two: near U, not equal to it.
  std::vector<int> half;
  for (int i = 0; i < potential.NumDataTerms(); i += 2) half.push_back(i);
  const double estimate = potential.EvaluateMinibatch(f.z, half, nullptr);
  EXPECT_NE(estimate, u);
  EXPECT_NEAR(estimate, u, 0.5 * u);
  EXPECT_THROW(potential.EvaluateMinibatch(f.z, {potential.NumDataTerms()}, nullptr),
               std::invalid_argument);
}

TEST(PhotometricPotentialTest, GaussNewtonHessianMatchesTheExactJacobian) {
  const Fixture f = MakeFixture();
  const double sigma = 0.05, sigma_z = 0.7;
  const PhotometricPotential potential(f.trunk, f.targets, sigma, sigma_z);
  Eigen::MatrixXd hessian;
  ASSERT_TRUE(potential.GaussNewtonHessian(f.z, &hessian));
  // Row j of J from the reverse pass with dL/dY = e_j, in double.
  const int d = potential.dim();
  Eigen::MatrixXd expected = Eigen::MatrixXd::Identity(d, d) / (sigma_z * sigma_z);
  for (int j = 0; j < 80; ++j) {
    const double w = f.targets.weights[j];
    if (w == 0) continue;
    Eigen::VectorXd row;
    f.trunk.Backward<double>({j}, f.z, Eigen::MatrixXd::Ones(1, 1), &row, nullptr, nullptr);
    expected += w / (sigma * sigma) * row * row.transpose();
  }
  EXPECT_GT(expected.norm(), 10.0 * d / (sigma_z * sigma_z));  // the data dominate
  EXPECT_LT((hessian - expected).norm(), 1e-3 * expected.norm());
  EXPECT_LT((hessian - hessian.transpose()).norm(), 1e-12 * hessian.norm());
  // U from the Jacobian's own pass: Evaluate's U up to the float passes' last bits, and
  // the same Hessian.
  double u = 0;
  Eigen::MatrixXd with_u;
  ASSERT_TRUE(potential.PotentialAndGaussNewtonHessian(f.z, &u, &with_u));
  EXPECT_EQ(with_u, hessian);
  const double evaluated = potential.Evaluate(f.z, nullptr);
  EXPECT_GT(evaluated, 0.0);
  EXPECT_NEAR(u, evaluated, 1e-5 * evaluated);
}

TEST(PhotometricPotentialTest, RefusesTargetsOfAnotherShapeAndBadSigmas) {
  const Fixture f = MakeFixture();
  TrunkTargets small = f.targets;
  small.values.conservativeResize(40, 1);
  EXPECT_THROW(PhotometricPotential(f.trunk, small, 0.05, 1.0), std::invalid_argument);
  EXPECT_THROW(PhotometricPotential(f.trunk, f.targets, 0.0, 1.0), std::invalid_argument);
  EXPECT_THROW(PhotometricPotential(f.trunk, f.targets, 0.05, NAN), std::invalid_argument);
  TrunkTargets negative = f.targets;
  negative.weights[5] = -1.0f;
  EXPECT_THROW(PhotometricPotential(f.trunk, negative, 0.05, 1.0), std::invalid_argument);
  const PhotometricPotential potential(f.trunk, f.targets, 0.05, 1.0);
  EXPECT_THROW(potential.Evaluate(Eigen::VectorXd::Zero(4), nullptr), std::invalid_argument);
}

}  // namespace
}  // namespace tactfunc
