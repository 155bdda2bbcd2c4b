// Copyright 2026 The tactfunc Authors.
//
// Fitting the pose itself to a frame by analysis-by-synthesis: for a tool t, the whitened
// residuals of the frame's LatentProblem (estimation/fitting/latent_problem.h; the
// selected valid pixels, the pixel sigma) at the latent the generator renders,
//
//   r(T, depth) = sqrt(w_j) (f_theta(x_j; h(t, T, depth)) - y_j) / sigma,
//
// minimised by Ceres' Levenberg-Marquardt over T = sensor_T_object on SE2Manifold (the
// project's SE2 with RIGHT perturbations T Exp(delta), models/core/se2.h) and the depth in
// bounds (each step projected onto them, without Ceres' line search for bounded problems;
// a mode's J^T J is the minimizer's last Jacobian, at the point it returns). Jacobian:
// analytic, J_r_z (LatentProblem::ResidualsAndJacobian, the trunk's latent Jacobian) times
// J_z_pose (PoseGenerator::Generate), d r / d(x, y, yaw, depth) in coordinates; Ceres
// composes it with the manifold's PlusJacobian.
//
// Multi-start: every start is scored by one forward pass, the best distinct
// max_refined_starts are refined, and every distinct converged mode is kept (two modes are
// the same when their positions are within merge_position_m and their yaws, modulo the
// tool's symmetry, within merge_yaw_rad). With a coarse problem (the same frame, fewer
// pixels) the search runs in two stages: the starts are scored on it, the best start of
// each of the coarse_refined_starts best distinct yaws (any position) is refined on it
// for coarse_iterations, and the best distinct
// max_refined_starts of those (by their coarse cost) are refined on the full problem.
// Starts are many and cheap there (a yaw grid per start position), the full-resolution
// Jacobians few.
//
// Errors: bad options throw std::invalid_argument; fits that fail come back with
// usable = false. Thread-safe (const).
#ifndef TACTFUNC_ESTIMATION_SYNTHESIS_POSE_FITTER_H_
#define TACTFUNC_ESTIMATION_SYNTHESIS_POSE_FITTER_H_

#include <string>
#include <vector>

#include <Eigen/Core>

#include "ceres/cost_function.h"
#include "ceres/manifold.h"
#include "estimation/fitting/latent_problem.h"
#include "models/pose/pose_generator.h"

namespace tactfunc {

// SE(2) as a Ceres manifold. Ambient (x, y, yaw) with yaw in (-pi, pi]; tangent (x, y,
// theta) of the right perturbation: Plus(T, delta) = T Exp(delta), Minus(U, T) =
// Log(T^-1 U). PlusJacobian at delta = 0 is [R(yaw) 0; 0 1] (PoseCoordinatesFromTangent),
// MinusJacobian its inverse.
class SE2Manifold : public ceres::Manifold {
 public:
  int AmbientSize() const override { return 3; }
  int TangentSize() const override { return 3; }
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override;
  bool PlusJacobian(const double* x, double* jacobian) const override;
  bool Minus(const double* y, const double* x, double* y_minus_x) const override;
  bool MinusJacobian(const double* x, double* jacobian) const override;
};

// The residuals of the header comment for tool `tool_index`: parameter blocks (x, y, yaw)
// and (depth); num_residuals = problem.num_residuals(). problem and generator must
// outlive the cost.
class GeneratorPoseCost : public ceres::CostFunction {
 public:
  GeneratorPoseCost(const LatentProblem& problem, const PoseGenerator& generator, int tool_index);
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override;

 private:
  const LatentProblem* problem_;
  const PoseGenerator* generator_;
  int tool_;
};

struct PoseStart {
  SE2d sensor_T_object;
  double depth_m = 0.009;
  std::string source;  // "mlp", "knn", "symmetry", ...
};

struct PoseFit {
  bool usable = false;
  SE2d sensor_T_object;
  double depth_m = 0;
  // 1/2 ||r||^2 at the problem's sigma, and sum of squared unwhitened residuals / N C.
  double cost = 0;
  double mean_squared_residual = 0;
  // J^T J of the whitened residuals at the mode (problem sigma), over the tangent
  // (x, y, theta) of the right perturbation and the depth: 4 x 4.
  Eigen::Matrix4d JtJ = Eigen::Matrix4d::Zero();
  int iterations = 0;
  std::string start;  // the source of the start it came from
};

struct PoseFitOptions {
  // Defaults chosen on 1,200 fresh contacts (docs/POSES.md, "The search's defaults" and
  // "More contacts for the generator").
  int max_iterations = 4;          // Levenberg-Marquardt iterations per start, >= 1
  int max_refined_starts = 4;      // best distinct starts refined, >= 1
  int coarse_refined_starts = 8;   // with a coarse problem: starts refined on it, >= 1
  int coarse_iterations = 3;       // their iterations there, >= 1
  double depth_min_m = 0.0015;     // depth bounds, 0 <= min < max
  double depth_max_m = 0.0175;
  double merge_position_m = 0.3e-3;  // > 0
  double merge_yaw_rad = 0.05;       // > 0
  bool IsValid(std::string* error) const;
};

// Fits the pose of tool `tool_index` from `starts` (non-empty); returns the distinct
// usable modes, lowest cost first. coarse (optional): the same frame with fewer pixels
// for the first stage (header comment); it must outlive the call.
std::vector<PoseFit> FitPoseModes(const LatentProblem& problem, const PoseGenerator& generator,
                                  int tool_index, const std::vector<PoseStart>& starts,
                                  const PoseFitOptions& options,
                                  const LatentProblem* coarse = nullptr);

// FitPoseModes with a coarse problem, in its two stages, for a caller that compares tools
// between them (GeneratorPosterior's tool pruning). CoarsePoseStarts is the first: the
// starts scored on `coarse`, the best of its distinct yaws refined there; the refined
// starts come back with their costs on `coarse`. FitPoseModesFromCoarse is the rest:
// FitPoseModes(problem, ..., starts, options, &coarse) returns exactly
// FitPoseModesFromCoarse(problem, ..., CoarsePoseStarts(coarse, ..., starts, options),
// options).
struct CoarseStarts {
  std::vector<PoseStart> starts;
  std::vector<double> costs;  // 1/2 ||r||^2 on the coarse problem, one per start
  double BestCost() const;    // +inf if there is none
};
CoarseStarts CoarsePoseStarts(const LatentProblem& coarse, const PoseGenerator& generator,
                              int tool_index, const std::vector<PoseStart>& starts,
                              const PoseFitOptions& options);
std::vector<PoseFit> FitPoseModesFromCoarse(const LatentProblem& problem,
                                            const PoseGenerator& generator, int tool_index,
                                            const CoarseStarts& coarse_starts,
                                            const PoseFitOptions& options);

// 1/2 ||r||^2 (problem sigma) at one pose, one forward pass; +inf if not finite.
double PoseCost(const LatentProblem& problem, const PoseGenerator& generator, int tool_index,
                const SE2d& sensor_T_object, double depth_m);
// PoseCost at every start (its pose and depth as given), the latents of all of them
// rendered by one batched generator pass (PoseGenerator::GenerateMany).
std::vector<double> PoseCosts(const LatentProblem& problem, const PoseGenerator& generator,
                              int tool_index, const std::vector<PoseStart>& starts);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_SYNTHESIS_POSE_FITTER_H_
