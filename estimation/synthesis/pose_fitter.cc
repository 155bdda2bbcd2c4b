// Copyright 2026 The tactfunc Authors.
#include "estimation/synthesis/pose_fitter.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "ceres/problem.h"
#include "ceres/solver.h"
#include "models/simulator/tool.h"

namespace tactfunc {

bool SE2Manifold::Plus(const double* x, const double* delta, double* out) const {
  const SE2d t = SE2d::FromXYYaw(x[0], x[1], x[2]);
  const SE2d u = t.Plus(SE2d::Tangent(delta[0], delta[1], delta[2]));
  out[0] = u.x();
  out[1] = u.y();
  out[2] = u.yaw();
  return true;
}

bool SE2Manifold::PlusJacobian(const double* x, double* jacobian) const {
  Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> j(jacobian);
  j = PoseCoordinatesFromTangent(SE2d::FromXYYaw(x[0], x[1], x[2]));
  return true;
}

bool SE2Manifold::Minus(const double* y, const double* x, double* out) const {
  const SE2d a = SE2d::FromXYYaw(y[0], y[1], y[2]);
  const SE2d b = SE2d::FromXYYaw(x[0], x[1], x[2]);
  const SE2d::Tangent d = a.Minus(b);
  out[0] = d[0];
  out[1] = d[1];
  out[2] = d[2];
  return true;
}

bool SE2Manifold::MinusJacobian(const double* x, double* jacobian) const {
  Eigen::Map<Eigen::Matrix<double, 3, 3, Eigen::RowMajor>> j(jacobian);
  j = PoseCoordinatesFromTangent(SE2d::FromXYYaw(x[0], x[1], x[2])).transpose();
  return true;
}

GeneratorPoseCost::GeneratorPoseCost(const LatentProblem& problem, const PoseGenerator& generator,
                                     int tool_index)
    : problem_(&problem), generator_(&generator), tool_(tool_index) {
  if (generator.latent_dim() != problem.dim()) {
    throw std::invalid_argument("GeneratorPoseCost: the generator's latent_dim " +
                                std::to_string(generator.latent_dim()) +
                                " is not the trunk's " + std::to_string(problem.dim()));
  }
  generator.SymmetryOrder(tool_index);  // throws for a bad index
  set_num_residuals(problem.num_residuals());
  mutable_parameter_block_sizes()->push_back(3);
  mutable_parameter_block_sizes()->push_back(1);
}

bool GeneratorPoseCost::Evaluate(double const* const* parameters, double* residuals,
                                 double** jacobians) const {
  const SE2d pose = SE2d::FromXYYaw(parameters[0][0], parameters[0][1], parameters[0][2]);
  const double depth = parameters[1][0];
  const bool want = jacobians != nullptr && (jacobians[0] != nullptr || jacobians[1] != nullptr);
  PoseGenerator::PoseJacobian J_z_pose;
  const Eigen::VectorXd z = generator_->Generate(tool_, pose, depth, want ? &J_z_pose : nullptr);
  const int n = problem_->num_residuals();
  if (!want) return problem_->ResidualsAndJacobian(z.data(), residuals, nullptr);
  // d r / d pose = (d r / d z)(d z / d pose), taken along the 4 pose directions through
  // the trunk's reverse passes (not the n x d latent Jacobian times them).
  Eigen::Matrix<double, Eigen::Dynamic, 4, Eigen::RowMajor> J_r_pose(n, 4);
  if (!problem_->ResidualsAndJacobianAlong(z.data(), J_z_pose, residuals, J_r_pose.data())) {
    return false;
  }
  if (jacobians[0] != nullptr) {
    Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>>(jacobians[0], n, 3) =
        J_r_pose.leftCols<3>();
  }
  if (jacobians[1] != nullptr) {
    Eigen::Map<Eigen::VectorXd>(jacobians[1], n) = J_r_pose.col(3);
  }
  return J_r_pose.allFinite();
}

bool PoseFitOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error != nullptr) *error = "PoseFitOptions: " + m;
    return false;
  };
  if (max_iterations < 1) return fail("max_iterations must be >= 1");
  if (max_refined_starts < 1) return fail("max_refined_starts must be >= 1");
  if (coarse_refined_starts < 1) return fail("coarse_refined_starts must be >= 1");
  if (coarse_iterations < 1) return fail("coarse_iterations must be >= 1");
  if (!(depth_min_m >= 0 && depth_max_m > depth_min_m)) {
    return fail("expected 0 <= depth_min_m < depth_max_m");
  }
  if (!(merge_position_m > 0) || !(merge_yaw_rad > 0)) {
    return fail("merge_position_m and merge_yaw_rad must be > 0");
  }
  return true;
}

double PoseCost(const LatentProblem& problem, const PoseGenerator& generator, int tool_index,
                const SE2d& pose, double depth_m) {
  return PoseCosts(problem, generator, tool_index, {{pose, depth_m, ""}}).front();
}

std::vector<double> PoseCosts(const LatentProblem& problem, const PoseGenerator& generator,
                              int tool_index, const std::vector<PoseStart>& starts) {
  std::vector<SE2d> poses;
  std::vector<double> depths;
  poses.reserve(starts.size());
  depths.reserve(starts.size());
  for (const PoseStart& s : starts) {
    poses.push_back(s.sensor_T_object);
    depths.push_back(s.depth_m);
  }
  const Eigen::MatrixXd Z = generator.GenerateMany(tool_index, poses, depths);
  std::vector<double> costs(starts.size(), std::numeric_limits<double>::infinity());
  Eigen::VectorXd z(problem.dim()), r(problem.num_residuals());
  for (std::size_t i = 0; i < starts.size(); ++i) {
    z = Z.row(static_cast<Eigen::Index>(i)).transpose();
    if (!problem.ResidualsAndJacobian(z.data(), r.data(), nullptr)) continue;
    const double cost = 0.5 * r.squaredNorm();
    if (std::isfinite(cost)) costs[i] = cost;
  }
  return costs;
}

namespace {

bool Same(const SE2d& a, const SE2d& b, int n, const PoseFitOptions& o) {
  const double dp = std::hypot(a.x() - b.x(), a.y() - b.y());
  return dp <= o.merge_position_m && YawErrorModuloSymmetry(a.yaw(), b.yaw(), n) <= o.merge_yaw_rad;
}

ceres::Solver::Options SolverOptions(int iterations) {
  ceres::Solver::Options solver;
  solver.minimizer_type = ceres::TRUST_REGION;
  solver.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  solver.linear_solver_type = ceres::DENSE_QR;
  solver.max_num_iterations = iterations;
  solver.num_threads = 1;
  solver.logging_type = ceres::SILENT;
  solver.minimizer_progress_to_stdout = false;
  solver.function_tolerance = 1e-7;
  solver.gradient_tolerance = 1e-10;
  solver.parameter_tolerance = 1e-8;
  // The depth's bounds make the problem bound-constrained, and Ceres' trust-region
  // minimizer then runs a line search along each projected step by default, evaluating
  // the Jacobian at every trial point on top of the candidate's cost and the Jacobian at
  // the accepted point: about twice the trunk passes per iteration. Without it a step is
  // projected onto the bounds (Plus clamps the depth) and accepted or rejected by its gain
  // ratio as any Levenberg-Marquardt step. The posteriors move by less than they differ
  // between sets of contacts, in 59-66 % of the time (docs/POSES.md, "Without the line
  // search").
  solver.max_num_line_search_step_size_iterations = 0;
  return solver;
}

// GeneratorPoseCost that keeps its last evaluation with a Jacobian. Ceres' minimizer
// evaluates the Jacobian at every point it accepts, the last of them the point it
// returns, so the residuals and Jacobian a mode's Laplace approximation needs are already
// computed when its fit ends. Not for concurrent use (one per Refine).
class RecordingPoseCost final : public GeneratorPoseCost {
 public:
  using GeneratorPoseCost::GeneratorPoseCost;

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const bool ok = GeneratorPoseCost::Evaluate(parameters, residuals, jacobians);
    if (jacobians == nullptr || jacobians[0] == nullptr || jacobians[1] == nullptr) return ok;
    recorded_ = ok;
    if (!ok) return ok;
    const int m = num_residuals();
    std::copy(parameters[0], parameters[0] + 3, pose_);
    depth_ = parameters[1][0];
    r_ = Eigen::Map<const Eigen::VectorXd>(residuals, m);
    J0_ = Eigen::Map<const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>>(
        jacobians[0], m, 3);
    J1_ = Eigen::Map<const Eigen::VectorXd>(jacobians[1], m);
    return ok;
  }

  // The residuals and the Jacobian blocks (x, y, yaw) and (depth) at exactly (pose, depth):
  // the recorded evaluation if it was there, else a new one. False if it failed.
  bool EvaluateAt(const double pose[3], double depth, Eigen::VectorXd* r,
                  Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor>* J0,
                  Eigen::VectorXd* J1) const {
    if (recorded_ && std::equal(pose, pose + 3, pose_) && depth == depth_) {
      *r = r_;
      *J0 = J0_;
      *J1 = J1_;
      return true;
    }
    const int m = num_residuals();
    r->resize(m);
    J0->resize(m, 3);
    J1->resize(m);
    const double* params[2] = {pose, &depth};
    double* jac[2] = {J0->data(), J1->data()};
    return GeneratorPoseCost::Evaluate(params, r->data(), jac);
  }

 private:
  mutable bool recorded_ = false;
  mutable double pose_[3] = {0, 0, 0};
  mutable double depth_ = 0;
  mutable Eigen::VectorXd r_, J1_;
  mutable Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> J0_;
};

// Levenberg-Marquardt on `cost` (not owned) from (pose, depth) in place; returns the
// iterations run.
int Refine(GeneratorPoseCost* cost, const PoseFitOptions& options, int iterations,
           double pose[3], double* depth) {
  ceres::Problem::Options po;
  po.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  po.manifold_ownership = ceres::TAKE_OWNERSHIP;
  ceres::Problem cp(po);
  cp.AddResidualBlock(cost, nullptr, pose, depth);
  cp.SetManifold(pose, new SE2Manifold);
  cp.SetParameterLowerBound(depth, 0, options.depth_min_m);
  cp.SetParameterUpperBound(depth, 0, options.depth_max_m);
  ceres::Solver::Summary summary;
  ceres::Solve(SolverOptions(iterations), &cp, &summary);
  return static_cast<int>(summary.iterations.size());
}

// The best distinct (coarse tolerance) finite-cost entries of `scored` (sorted by cost),
// at most `count`.
// yaw_only: distinct in yaw alone (any position), so that every yaw hypothesis is
// represented by its best position.
std::vector<int> BestDistinct(const std::vector<std::pair<double, int>>& scored,
                              const std::vector<PoseStart>& starts, int n, int count,
                              const PoseFitOptions& options, bool yaw_only = false) {
  PoseFitOptions coarse = options;
  coarse.merge_position_m = yaw_only ? 1.0 : std::max(options.merge_position_m, 0.5e-3);
  coarse.merge_yaw_rad = std::max(options.merge_yaw_rad, 0.15);
  std::vector<int> chosen;
  for (const auto& [cost, i] : scored) {
    if (!std::isfinite(cost)) continue;
    bool dup = false;
    for (int c : chosen) dup |= Same(starts[c].sensor_T_object, starts[i].sensor_T_object, n, coarse);
    if (dup) continue;
    chosen.push_back(i);
    if (static_cast<int>(chosen.size()) >= count) break;
  }
  return chosen;
}

// (cost, index) of every start, lowest cost first (ties in index order).
std::vector<std::pair<double, int>> Sorted(const std::vector<double>& costs) {
  std::vector<std::pair<double, int>> scored;
  for (std::size_t i = 0; i < costs.size(); ++i) scored.emplace_back(costs[i], static_cast<int>(i));
  std::stable_sort(scored.begin(), scored.end(),
                   [](const auto& a, const auto& b) { return a.first < b.first; });
  return scored;
}

std::vector<PoseStart> Clamped(std::vector<PoseStart> starts, const PoseFitOptions& options) {
  for (PoseStart& s : starts) {
    s.depth_m = std::clamp(s.depth_m, options.depth_min_m, options.depth_max_m);
  }
  return starts;
}

void CheckSearch(const PoseFitOptions& options, bool have_starts, const char* who) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  if (!have_starts) throw std::invalid_argument(std::string(who) + ": no starts");
}

// The search's last stage: starts[chosen] refined on the full problem, the distinct usable
// modes kept, lowest cost first.
std::vector<PoseFit> RefineModes(const LatentProblem& problem, const PoseGenerator& generator,
                                 int tool_index, const std::vector<PoseStart>& starts,
                                 const std::vector<int>& chosen, const PoseFitOptions& options) {
  const int n = generator.SymmetryOrder(tool_index);
  std::vector<PoseFit> modes;
  for (int i : chosen) {
    double pose[3] = {starts[i].sensor_T_object.x(), starts[i].sensor_T_object.y(),
                      starts[i].sensor_T_object.yaw()};
    double depth = starts[i].depth_m;
    PoseFit fit;
    RecordingPoseCost cost(problem, generator, tool_index);
    fit.iterations = Refine(&cost, options, options.max_iterations, pose, &depth);
    fit.sensor_T_object = SE2d::FromXYYaw(pose[0], pose[1], pose[2]);
    fit.depth_m = depth;
    fit.start = starts[i].source;
    // Residuals and the tangent J^T J at the mode.
    const int m = problem.num_residuals();
    Eigen::VectorXd r, J1;
    Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> J0;
    if (!cost.EvaluateAt(pose, depth, &r, &J0, &J1)) continue;
    Eigen::Matrix<double, Eigen::Dynamic, 4> J(m, 4);
    J.leftCols<3>() = J0 * PoseCoordinatesFromTangent(fit.sensor_T_object);
    J.col(3) = J1;
    fit.JtJ = J.transpose() * J;
    fit.cost = 0.5 * r.squaredNorm();
    fit.mean_squared_residual = r.squaredNorm() * problem.sigma() * problem.sigma() / m;
    fit.usable = std::isfinite(fit.cost) && fit.JtJ.allFinite();
    if (!fit.usable) continue;
    bool dup = false;
    for (PoseFit& other : modes) {
      if (Same(other.sensor_T_object, fit.sensor_T_object, n, options)) {
        dup = true;
        if (fit.cost < other.cost) other = fit;
      }
    }
    if (!dup) modes.push_back(fit);
  }
  std::sort(modes.begin(), modes.end(),
            [](const PoseFit& a, const PoseFit& b) { return a.cost < b.cost; });
  return modes;
}

}  // namespace

double CoarseStarts::BestCost() const {
  double best = std::numeric_limits<double>::infinity();
  for (double c : costs) best = std::min(best, c);
  return best;
}

CoarseStarts CoarsePoseStarts(const LatentProblem& coarse, const PoseGenerator& generator,
                              int tool_index, const std::vector<PoseStart>& starts_in,
                              const PoseFitOptions& options) {
  CheckSearch(options, !starts_in.empty(), "CoarsePoseStarts");
  const int n = generator.SymmetryOrder(tool_index);
  const std::vector<PoseStart> starts = Clamped(starts_in, options);
  // Stage 1: refine the best distinct starts on the coarse problem, re-score.
  const std::vector<int> first =
      BestDistinct(Sorted(PoseCosts(coarse, generator, tool_index, starts)), starts, n,
                   options.coarse_refined_starts, options, /*yaw_only=*/true);
  CoarseStarts out;
  for (int i : first) {
    double pose[3] = {starts[i].sensor_T_object.x(), starts[i].sensor_T_object.y(),
                      starts[i].sensor_T_object.yaw()};
    double depth = starts[i].depth_m;
    GeneratorPoseCost cost(coarse, generator, tool_index);
    Refine(&cost, options, options.coarse_iterations, pose, &depth);
    out.starts.push_back({SE2d::FromXYYaw(pose[0], pose[1], pose[2]), depth, starts[i].source});
  }
  out.costs = PoseCosts(coarse, generator, tool_index, out.starts);
  return out;
}

std::vector<PoseFit> FitPoseModesFromCoarse(const LatentProblem& problem,
                                            const PoseGenerator& generator, int tool_index,
                                            const CoarseStarts& coarse_starts,
                                            const PoseFitOptions& options) {
  CheckSearch(options, true, "FitPoseModesFromCoarse");
  if (coarse_starts.costs.size() != coarse_starts.starts.size()) {
    throw std::invalid_argument("FitPoseModesFromCoarse: " +
                                std::to_string(coarse_starts.costs.size()) + " costs for " +
                                std::to_string(coarse_starts.starts.size()) + " starts");
  }
  const std::vector<int> chosen =
      BestDistinct(Sorted(coarse_starts.costs), coarse_starts.starts,
                   generator.SymmetryOrder(tool_index), options.max_refined_starts, options);
  return RefineModes(problem, generator, tool_index, coarse_starts.starts, chosen, options);
}

std::vector<PoseFit> FitPoseModes(const LatentProblem& problem, const PoseGenerator& generator,
                                  int tool_index, const std::vector<PoseStart>& starts_in,
                                  const PoseFitOptions& options, const LatentProblem* coarse) {
  CheckSearch(options, !starts_in.empty(), "FitPoseModes");
  if (coarse != nullptr) {
    return FitPoseModesFromCoarse(
        problem, generator, tool_index,
        CoarsePoseStarts(*coarse, generator, tool_index, starts_in, options), options);
  }
  // One stage: the starts as they are, scored on the full problem.
  CoarseStarts scored{Clamped(starts_in, options), {}};
  scored.costs = PoseCosts(problem, generator, tool_index, scored.starts);
  return FitPoseModesFromCoarse(problem, generator, tool_index, scored, options);
}

}  // namespace tactfunc
