// Copyright 2026 The tactfunc Authors.
//
// MCMC over the pose of the generator path (docs/POSES.md, "MCMC over the pose"): draws
// (x, y, yaw, depth) of tool t from the frame's analysis-by-synthesis posterior
//
//   p(T, depth | y) ~ exp(-1/2 ||r(T, depth)||^2),   depth in [depth_min_m, depth_max_m],
//
// r the residuals of GeneratorPoseCost (estimation/synthesis/pose_fitter.h) whitened at
// the posterior's pixel sigma s (GeneratorPosterior::Summary::sigma, the s of its Laplace
// components: r_s = r * problem.sigma() / s), with a uniform prior over the pose and the
// depth; proposals outside the depth bounds are rejected without a trunk pass.
//
// Coordinates. The chain moves in the coordinates (x, y, yaw, depth), yaw wrapped to
// (-pi, pi]. The Haar measure of SE(2) is dx dy dyaw in these coordinates, so a uniform
// prior on the group is uniform in them, the density needs no Jacobian factor, and
// coordinate-space Metropolis steps are valid. The gradient is d log p / d(x, y, yaw,
// depth) = -J^T r_s with the analytic coordinate Jacobian J of GeneratorPoseCost.
//
// Kernels (samplers/metropolis.h): MALA or random-walk Metropolis, preconditioned by the
// starting Laplace component's covariance, carried from its tangent (right perturbation)
// to the coordinates, Sigma_c = P Sigma P^T with P = diag(R(yaw), 1, 1)
// (PoseCoordinatesFromTangent); for a tool without observable yaw (symmetry order 0) the
// yaw variance, absent from the component, is set to (pi / 2)^2 and the yaw wanders
// over the circle. The chains start at the component's mean perturbed by draws from its
// Gaussian; the step size adapts during the burn-in, then is frozen. Diagnostics fold the
// yaw modulo 2 pi / n for a C_n tool (the density has that symmetry exactly).
//
// Several modes. Given every Laplace component the search found for the tool (the
// overload taking a list), the chains also propose mode jumps (samplers/metropolis.h):
// independent draws from those components' Gaussians in the coordinates, their
// covariances widened by jump_variance_scale so the proposal's tails are heavier than
// the target's, each proposed with half its Laplace weight plus an equal share, and
// chain c starts at component c mod K. A chain started in one yaw
// mode then visits the others in proportion to their posterior mass instead of staying
// where it started.
//
// Errors: bad options or a tool index outside the generator throw std::invalid_argument.
#ifndef TACTFUNC_ESTIMATION_SYNTHESIS_POSE_SAMPLER_H_
#define TACTFUNC_ESTIMATION_SYNTHESIS_POSE_SAMPLER_H_

#include <vector>

#include <Eigen/Core>

#include "estimation/fitting/latent_problem.h"
#include "estimation/synthesis/generator_posterior.h"
#include "estimation/synthesis/pose_fitter.h"
#include "models/pose/pose_generator.h"
#include "samplers/metropolis.h"

namespace tactfunc {

struct PoseSamplerOptions {
  // Kernel, chains, burn-in, step size, seed. angles and angle_fold are set by the sampler.
  MetropolisOptions chain;
  double depth_min_m = PoseFitOptions().depth_min_m;  // the fitter's bounds by default
  double depth_max_m = PoseFitOptions().depth_max_m;
  // Mode jumps between the components (header comment): the probability of a jump
  // proposal per iteration (0 = none) and the factor on the components' covariances.
  double jump_probability = 0.1;
  double jump_variance_scale = 2.0;
  bool IsValid(std::string* error) const;
};

struct PoseSamples {
  // Samples over (x, y, yaw, depth) per chain, acceptance, ESS and split R-hat per
  // coordinate, wall time (samplers/metropolis.h).
  MetropolisResult chains;
  long trunk_evaluations = 0;  // forward passes (with the latent Jacobian for MALA)
  double sigma = 0;            // the pixel sigma the density used
  // Every kept sample as a pose.
  std::vector<SE2d> Poses() const;
};

// The starting component's covariance in the coordinates (x, y, yaw, depth) (header
// comment), symmetric positive definite.
Eigen::Matrix4d CoordinateCovariance(const LaplaceComponent& component);

// Samples the posterior of the header comment for tool `tool_index` of `generator` on
// `problem` at pixel sigma `sigma` (> 0), starting from `start`.
PoseSamples SamplePosePosterior(const LatentProblem& problem, const PoseGenerator& generator,
                                int tool_index, double sigma, const LaplaceComponent& start,
                                const PoseSamplerOptions& options);
// The same from every component in `modes` (non-empty, all of this tool; modes[0] is the
// start), with mode jumps between them when there are two or more (header comment).
PoseSamples SamplePosePosterior(const LatentProblem& problem, const PoseGenerator& generator,
                                int tool_index, double sigma,
                                const std::vector<LaplaceComponent>& modes,
                                const PoseSamplerOptions& options);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_SYNTHESIS_POSE_SAMPLER_H_
