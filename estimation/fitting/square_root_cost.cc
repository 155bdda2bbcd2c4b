// Copyright 2026 The tactfunc Authors.
#include "estimation/fitting/square_root_cost.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>

namespace tactfunc {

SquareRootCost::SquareRootCost(const ceres::CostFunction* source, double prior_precision)
    : source_(source), prior_precision_(prior_precision) {
  if (source == nullptr || source->parameter_block_sizes().size() != 1) {
    throw std::invalid_argument(
        "SquareRootCost: the source cost must have exactly one parameter block");
  }
  if (!(prior_precision >= 0) || !std::isfinite(prior_precision)) {
    throw std::invalid_argument("SquareRootCost: prior_precision must be finite and >= 0, found " +
                                std::to_string(prior_precision));
  }
  const int d = source->parameter_block_sizes()[0];
  mutable_parameter_block_sizes()->push_back(d);
  set_num_residuals(d + 1);
  source_residuals_.resize(static_cast<std::size_t>(source->num_residuals()));
}

bool SquareRootCost::Evaluate(double const* const* parameters, double* residuals,
                              double** jacobians) const {
  const int d = parameter_block_sizes()[0];
  const int n = source_->num_residuals();
  const bool want_jacobian = jacobians != nullptr && jacobians[0] != nullptr;
  if (want_jacobian) {
    source_jacobian_.resize(static_cast<std::size_t>(n) * d);
  }
  double* source_jacobians[] = {want_jacobian ? source_jacobian_.data() : nullptr};
  if (!source_->Evaluate(parameters, source_residuals_.data(),
                         want_jacobian ? source_jacobians : nullptr)) {
    return false;
  }
  const Eigen::Map<const Eigen::VectorXd> x(parameters[0], d);
  const Eigen::Map<const Eigen::VectorXd> r(source_residuals_.data(), n);
  const double p2 = prior_precision_ * prior_precision_;
  // ||r_a||^2, the term's cost times two.
  const double total = r.squaredNorm() + p2 * x.squaredNorm();
  if (!std::isfinite(total)) return false;

  Eigen::Map<Eigen::VectorXd> q(residuals, d);
  if (!want_jacobian) {
    q.setZero();
    residuals[d] = std::sqrt(total);
    return true;
  }

  // Ceres' row-major n x d Jacobian is J^T (d x n) column-major in memory.
  const Eigen::Map<const Eigen::MatrixXd> jt(source_jacobian_.data(), d, n);
  // G's lower triangle (all that the Cholesky and eigen solvers read).
  Eigen::MatrixXd g = Eigen::MatrixXd::Zero(d, d);
  g.selfadjointView<Eigen::Lower>().rankUpdate(jt);
  g.diagonal().array() += p2;
  const Eigen::VectorXd b = jt * r + p2 * x;
  if (!g.allFinite() || !b.allFinite()) return false;

  Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> jacobian(
      jacobians[0], d + 1, d);
  jacobian.setZero();
  // Cholesky G = L L^T, R = L^T, q = L^-1 b; accepted unless G is (numerically) singular,
  // where q would carry more than the whole cost.
  const Eigen::LLT<Eigen::MatrixXd> llt(g);
  bool done = false;
  if (llt.info() == Eigen::Success) {
    q = llt.matrixL().solve(b);
    if (q.allFinite() && q.squaredNorm() <= total * (1 + 1e-9)) {
      jacobian.topRows(d) = llt.matrixU();
      done = true;
    }
  }
  if (!done) {
    // G = V Lambda V^T: R's row k is sqrt(lambda_k) v_k^T and q_k = v_k^T b / sqrt(lambda_k),
    // directions with lambda_k at rounding level left out (b has no part along them).
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(g);
    if (eigen.info() != Eigen::Success) return false;
    const Eigen::VectorXd& lambda = eigen.eigenvalues();
    const double floor = std::max(lambda.maxCoeff(), 0.0) * 1e-13 * d;
    for (int k = 0; k < d; ++k) {
      if (lambda[k] > floor) {
        const double root = std::sqrt(lambda[k]);
        jacobian.row(k) = root * eigen.eigenvectors().col(k).transpose();
        q[k] = eigen.eigenvectors().col(k).dot(b) / root;
      } else {
        q[k] = 0;
      }
    }
    // Rounding may still put a hair more than the cost into q: q takes the cost then.
    const double explained = q.squaredNorm();
    if (explained > total && explained > 0) q *= std::sqrt(total / explained);
  }
  residuals[d] = std::sqrt(std::max(0.0, total - q.squaredNorm()));
  last_x_.resize(0);
  if (!q.allFinite() || !jacobian.allFinite()) return false;
  last_g_ = g.selfadjointView<Eigen::Lower>();
  last_x_ = x;
  return true;
}

const Eigen::MatrixXd* SquareRootCost::GaussNewtonMatrixAt(const double* x) const {
  const int d = parameter_block_sizes()[0];
  if (last_x_.size() != d || last_x_ != Eigen::Map<const Eigen::VectorXd>(x, d)) return nullptr;
  return &last_g_;
}

}  // namespace tactfunc
