// Copyright 2026 The tactfunc Authors.
//
// SquareRootCost: a many-residual term handed to Ceres as d + 1 residuals must keep the
// cost, the gradient J^T r and the Gauss-Newton matrix J^T J of the term exactly (up to
// rounding, checked to 1e-10 relative), on full-rank and on rank-deficient Jacobians, and
// Ceres must take the same steps on it as on the original residuals.
#include "estimation/fitting/square_root_cost.h"

#include <cmath>
#include <memory>
#include <stdexcept>
#include <vector>

#include "ceres/problem.h"
#include "ceres/sized_cost_function.h"
#include "ceres/solver.h"
#include "gtest/gtest.h"
#include "tests/support/uniform_numbers.h"

namespace tactfunc {
namespace {

using Eigen::MatrixXd;
using Eigen::VectorXd;
using RowMajor = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
using testing_util::Uniform;  // deterministic numbers in [-1, 1)

// r(x) = tanh(A x) - y: smooth, nonlinear, with the Jacobian's rank that of A.
class TanhResiduals : public ceres::CostFunction {
 public:
  TanhResiduals(MatrixXd a, VectorXd y) : a_(std::move(a)), y_(std::move(y)) {
    mutable_parameter_block_sizes()->push_back(static_cast<int>(a_.cols()));
    set_num_residuals(static_cast<int>(a_.rows()));
  }
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const Eigen::Map<const VectorXd> x(parameters[0], a_.cols());
    const VectorXd t = (a_ * x).array().tanh().matrix();
    Eigen::Map<VectorXd>(residuals, a_.rows()) = t - y_;
    if (jacobians != nullptr && jacobians[0] != nullptr) {
      Eigen::Map<RowMajor>(jacobians[0], a_.rows(), a_.cols()) =
          (1 - t.array().square()).matrix().asDiagonal() * a_;
    }
    return true;
  }

 private:
  MatrixXd a_;
  VectorXd y_;
};

struct Evaluation {
  VectorXd residuals;
  RowMajor jacobian;
};

Evaluation Evaluate(const ceres::CostFunction& cost, const VectorXd& x, bool jacobian) {
  Evaluation e;
  e.residuals.resize(cost.num_residuals());
  e.jacobian.resize(cost.num_residuals(), x.size());
  const double* parameters[] = {x.data()};
  double* jacobians[] = {e.jacobian.data()};
  EXPECT_TRUE(cost.Evaluate(parameters, e.residuals.data(), jacobian ? jacobians : nullptr));
  return e;
}

double Relative(const MatrixXd& a, const MatrixXd& reference) {
  return (a - reference).cwiseAbs().maxCoeff() / std::max(reference.cwiseAbs().maxCoeff(), 1e-300);
}

// Cost, gradient and Gauss-Newton matrix of the square-root form against the term's own
// (source residuals plus the prior x * precision).
void ExpectSameTerm(const ceres::CostFunction& source, double precision, const VectorXd& x) {
  const SquareRootCost square_root(&source, precision);
  ASSERT_EQ(square_root.num_residuals(), x.size() + 1);
  const Evaluation s = Evaluate(source, x, true);
  const Evaluation q = Evaluate(square_root, x, true);
  const Evaluation cost_only = Evaluate(square_root, x, false);
  const double p2 = precision * precision;
  const double cost = 0.5 * (s.residuals.squaredNorm() + p2 * x.squaredNorm());
  const VectorXd gradient = s.jacobian.transpose() * s.residuals + p2 * x;
  const MatrixXd gauss_newton =
      s.jacobian.transpose() * s.jacobian + p2 * MatrixXd::Identity(x.size(), x.size());
  EXPECT_NEAR(0.5 * q.residuals.squaredNorm(), cost, 1e-10 * cost);
  EXPECT_NEAR(0.5 * cost_only.residuals.squaredNorm(), cost, 1e-12 * cost);
  EXPECT_LE(Relative(q.jacobian.transpose() * q.residuals, gradient), 1e-10);
  EXPECT_LE(Relative(q.jacobian.transpose() * q.jacobian, gauss_newton), 1e-10);
  EXPECT_EQ(q.jacobian.row(x.size()).cwiseAbs().maxCoeff(), 0.0);  // the remainder's row
}

TEST(SquareRootCost, KeepsCostGradientAndGaussNewtonMatrixOfAFullRankTerm) {
  const TanhResiduals source(0.7 * Uniform(300, 6, 1), 0.5 * Uniform(300, 1, 2));
  for (double precision : {0.0, 0.3, 10.0}) {
    for (unsigned seed : {3u, 4u}) {
      SCOPED_TRACE(precision);
      ExpectSameTerm(source, precision, Uniform(6, 1, seed));
    }
  }
}

TEST(SquareRootCost, KeepsThemWhenTheJacobianIsRankDeficient) {
  // A of rank 3 in 6 columns and no prior: J^T J is singular, Cholesky fails, and the
  // eigen square root must still reproduce cost, gradient and J^T J.
  const MatrixXd a = Uniform(200, 3, 5) * Uniform(3, 6, 6);
  const TanhResiduals source(0.3 * a, 0.5 * Uniform(200, 1, 7));
  ExpectSameTerm(source, 0.0, Uniform(6, 1, 8));
  // Exactly zero Jacobian (x in the flat part): all the cost in the remainder.
  const TanhResiduals flat(MatrixXd::Zero(50, 4), Uniform(50, 1, 9));
  ExpectSameTerm(flat, 0.0, Uniform(4, 1, 10));
}

TEST(SquareRootCost, CeresTakesTheSameStepsAsOnTheSourceResiduals) {
  // Targets from a true x plus noise, so that the minimum is far below the start.
  const MatrixXd a = 0.8 * Uniform(400, 5, 11);
  const VectorXd y = (a * Uniform(5, 1, 13)).array().tanh().matrix() + 0.05 * Uniform(400, 1, 12);
  TanhResiduals source(a, y);
  const double precision = 0.5;
  auto solve = [&](bool square_root, VectorXd* x) {
    *x = VectorXd::Zero(5);
    ceres::Problem::Options options;
    options.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    ceres::Problem problem(options);
    SquareRootCost compressed(&source, precision);
    // The prior as a linear block of its own for the source form: x * precision.
    class Prior : public ceres::SizedCostFunction<5, 5> {
     public:
      explicit Prior(double p) : p_(p) {}
      bool Evaluate(double const* const* parameters, double* residuals,
                    double** jacobians) const override {
        for (int k = 0; k < 5; ++k) residuals[k] = p_ * parameters[0][k];
        if (jacobians != nullptr && jacobians[0] != nullptr) {
          Eigen::Map<RowMajor>(jacobians[0], 5, 5) = p_ * MatrixXd::Identity(5, 5);
        }
        return true;
      }

     private:
      double p_;
    } prior(precision);
    if (square_root) {
      problem.AddResidualBlock(&compressed, nullptr, x->data());
    } else {
      problem.AddResidualBlock(&source, nullptr, x->data());
      problem.AddResidualBlock(&prior, nullptr, x->data());
    }
    ceres::Solver::Options solver;
    solver.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;
    solver.max_num_iterations = 30;
    ceres::Solver::Summary summary;
    ceres::Solve(solver, &problem, &summary);
    return summary;
  };
  VectorXd xs, xq;
  const ceres::Solver::Summary s = solve(false, &xs), q = solve(true, &xq);
  EXPECT_EQ(s.num_successful_steps, q.num_successful_steps);
  EXPECT_EQ(s.num_unsuccessful_steps, q.num_unsuccessful_steps);
  EXPECT_NEAR(q.final_cost, s.final_cost, 1e-10 * s.final_cost);
  EXPECT_LE((xq - xs).norm(), 1e-8 * xs.norm()) << xs.transpose() << "\n" << xq.transpose();
  EXPECT_LT(s.final_cost, 0.1 * s.initial_cost);  // the solve did move
}

TEST(SquareRootCost, RefusesSeveralParameterBlocksAndABadPriorPrecision) {
  class TwoBlocks : public ceres::SizedCostFunction<1, 1, 1> {
    bool Evaluate(double const* const*, double*, double**) const override { return true; }
  } two;
  EXPECT_THROW(SquareRootCost(&two, 0.0), std::invalid_argument);
  const TanhResiduals source(Uniform(4, 2, 1), Uniform(4, 1, 2));
  EXPECT_THROW(SquareRootCost(&source, -1.0), std::invalid_argument);
  EXPECT_THROW(SquareRootCost(&source, std::nan("")), std::invalid_argument);
  EXPECT_THROW(SquareRootCost(nullptr, 1.0), std::invalid_argument);
}

TEST(SquareRootCost, ANonFiniteSourceIsRejected) {
  const TanhResiduals source(Uniform(10, 2, 1), Uniform(10, 1, 2));
  const SquareRootCost cost(&source, 1.0);
  const VectorXd x = VectorXd::Constant(2, std::nan(""));
  VectorXd residuals(3);
  RowMajor jacobian(3, 2);
  const double* parameters[] = {x.data()};
  double* jacobians[] = {jacobian.data()};
  EXPECT_FALSE(cost.Evaluate(parameters, residuals.data(), jacobians));
  EXPECT_FALSE(cost.Evaluate(parameters, residuals.data(), nullptr));
}

}  // namespace
}  // namespace tactfunc
