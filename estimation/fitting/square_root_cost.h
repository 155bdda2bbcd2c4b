// Copyright 2026 The tactfunc Authors.
//
// SquareRootCost: a least-squares term of many residuals over ONE parameter block of d
// values, handed to Ceres in its square-root information form, d + 1 residuals.
//
// The term. A source ceres::CostFunction gives n residuals r(x) and their Jacobian J
// (n x d); optionally a Gaussian prior adds x / sigma_p (so r_a = [r; x / sigma_p] and
// J_a = [J; I / sigma_p], the prior's d residuals folded in). Its cost is 1/2 ||r_a||^2.
// Where Ceres asks for the Jacobian, at x:
//
//   G = J_a^T J_a = R^T R   (R upper triangular, d x d: Cholesky; where G is singular,
//                            R = Lambda^(1/2) V^T from G = V Lambda V^T)
//   b = J_a^T r_a,   q = R^(-T) b (on R's non-null rows)
//
//   residuals   [ q ; sqrt(||r_a||^2 - ||q||^2) ]        Jacobian   [ R ; 0 ]
//
// so that the cost (1/2 ||.||^2 = 1/2 ||r_a||^2), the gradient (J'^T r' = b) and the
// Gauss-Newton matrix (J'^T J' = G) are the term's own: every quantity a trust-region
// step reads -- the LM or dogleg step, the model's predicted decrease, Jacobi scaling
// (R's column norms are J_a's) and the tolerances -- is unchanged, and Ceres takes the
// same steps as on the n residuals, up to rounding. Where Ceres asks for the residuals
// alone (a candidate step's cost) they are [0, ..., 0, ||r_a||]: the same cost.
//
// Why: Ceres then forms and factors the normal equations of d + 1 rows, not n. On the
// Soft Bubble's 6,160 pixels at d = 64 that product ran in Debian's libceres (built for
// generic x86-64, no AVX) and took about 40 % of a ceres:10 fit's time; here it is one
// symmetric rank update in the project's own (vectorised) Eigen.
//
// What it is not: the residual vector is not a differentiable function of x (its first d
// entries are defined at Jacobian evaluations), so Ceres' gradient checker, numeric
// differentiation of it, or a ceres::LossFunction on the block do not apply (a robust
// loss belongs inside the source, as LatentProblem's is). Cost and gradient are exact, so
// Ceres' covariance of the block's parameters is the Gauss-Newton one, G^-1, as before.
//
// Errors: the constructor throws std::invalid_argument for a source without exactly one
// parameter block or a negative prior precision. Evaluate returns false (Ceres rejects
// the point) if the source fails or anything is not finite.
//
// Thread safety: one object keeps the source's n residuals and Jacobian, and the last G,
// between calls; use one per solve (Ceres evaluates a single residual block serially).
#ifndef TACTFUNC_ESTIMATION_FITTING_SQUARE_ROOT_COST_H_
#define TACTFUNC_ESTIMATION_FITTING_SQUARE_ROOT_COST_H_

#include <vector>

#include <Eigen/Core>

#include "ceres/cost_function.h"

namespace tactfunc {

class SquareRootCost : public ceres::CostFunction {
 public:
  // `source` (not owned; must outlive the object) has one parameter block of d values.
  // prior_precision = 1 / sigma_p (>= 0; 0 = no prior term).
  SquareRootCost(const ceres::CostFunction* source, double prior_precision);

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

  // G = J_a^T J_a (d x d, symmetric) of the last successful Jacobian evaluation if it was
  // at exactly x (d values), else null: the Gauss-Newton matrix at a solver's result,
  // with no pass of its own (a Laplace approximation's Hessian).
  const Eigen::MatrixXd* GaussNewtonMatrixAt(const double* x) const;

 private:
  const ceres::CostFunction* source_;
  double prior_precision_;
  // The source's residuals and row-major Jacobian (n x d: in memory J^T, d x n).
  mutable std::vector<double> source_residuals_;
  mutable std::vector<double> source_jacobian_;
  // The last successful Jacobian evaluation's point and G (both sides of the diagonal).
  mutable Eigen::VectorXd last_x_;
  mutable Eigen::MatrixXd last_g_;
};

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_FITTING_SQUARE_ROOT_COST_H_
