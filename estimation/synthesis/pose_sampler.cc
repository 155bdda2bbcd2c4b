// Copyright 2026 The tactfunc Authors.
#include "estimation/synthesis/pose_sampler.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>

namespace tactfunc {

bool PoseSamplerOptions::IsValid(std::string* error) const {
  if (!(depth_min_m >= 0 && depth_max_m > depth_min_m) || !std::isfinite(depth_max_m)) {
    if (error != nullptr) *error = "PoseSamplerOptions: expected 0 <= depth_min_m < depth_max_m";
    return false;
  }
  if (!(jump_probability >= 0 && jump_probability < 1) ||
      !(jump_variance_scale > 0) || !std::isfinite(jump_variance_scale)) {
    if (error != nullptr) {
      *error = "PoseSamplerOptions: expected jump_probability in [0, 1) and jump_variance_scale > 0";
    }
    return false;
  }
  return chain.IsValid(4, error);
}

std::vector<SE2d> PoseSamples::Poses() const {
  const Eigen::MatrixXd all = chains.Stacked();
  std::vector<SE2d> poses;
  poses.reserve(all.rows());
  for (Eigen::Index i = 0; i < all.rows(); ++i) {
    poses.push_back(SE2d::FromXYYaw(all(i, 0), all(i, 1), all(i, 2)));
  }
  return poses;
}

Eigen::Matrix4d CoordinateCovariance(const LaplaceComponent& component) {
  Eigen::Matrix4d P = Eigen::Matrix4d::Identity();
  P.topLeftCorner<3, 3>() = PoseCoordinatesFromTangent(component.mean);
  Eigen::Matrix4d c = P * component.covariance * P.transpose();
  c = 0.5 * (c + c.transpose()).eval();
  if (component.symmetry_order == 0) {
    c.row(2).setZero();
    c.col(2).setZero();
    c(2, 2) = M_PI * M_PI / 4;
  }
  return c;
}

namespace {
Eigen::VectorXd CoordinateMean(const LaplaceComponent& c, const PoseSamplerOptions& options) {
  Eigen::VectorXd x(4);
  x << c.mean.x(), c.mean.y(), c.mean.yaw(),
      std::clamp(c.depth_m, options.depth_min_m, options.depth_max_m);
  return x;
}
}  // namespace

PoseSamples SamplePosePosterior(const LatentProblem& problem, const PoseGenerator& generator,
                                int tool_index, double sigma, const LaplaceComponent& start,
                                const PoseSamplerOptions& options) {
  return SamplePosePosterior(problem, generator, tool_index, sigma,
                             std::vector<LaplaceComponent>{start}, options);
}

PoseSamples SamplePosePosterior(const LatentProblem& problem, const PoseGenerator& generator,
                                int tool_index, double sigma,
                                const std::vector<LaplaceComponent>& modes,
                                const PoseSamplerOptions& options) {
  if (modes.empty()) throw std::invalid_argument("SamplePosePosterior: no starting component");
  const LaplaceComponent& start = modes.front();
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  if (!(sigma > 0) || !std::isfinite(sigma)) {
    throw std::invalid_argument("SamplePosePosterior: sigma must be finite and > 0, got " +
                                std::to_string(sigma));
  }
  // Validates the tool index and the latent sizes (throws); the chain itself needs only
  // the gradient of log p, so it takes the trunk's reverse pass J_r_z^T r (a vector-
  // Jacobian product) instead of the residuals' full latent Jacobian.
  const GeneratorPoseCost validated(problem, generator, tool_index);
  (void)validated;
  const int n = generator.SymmetryOrder(tool_index);
  const double scale2 = std::pow(problem.sigma() / sigma, 2);  // r_s = r * problem sigma / sigma
  const double prior_variance = problem.sigma_z() * problem.sigma_z();
  PoseSamples out;
  out.sigma = sigma;
  // log p = -1/2 ||r_s||^2 = -scale2 U_data(h(x)), U_data = U - the latent prior (the
  // problem's 1/2 ||r||^2 at its own sigma); grad log p = -scale2 J_z_x^T grad U_data.
  LogDensityFunction log_density = [&](const Eigen::VectorXd& x, Eigen::VectorXd* gradient) {
    if (!(x[3] >= options.depth_min_m && x[3] <= options.depth_max_m)) {
      return -std::numeric_limits<double>::infinity();
    }
    ++out.trunk_evaluations;
    PoseGenerator::PoseJacobian J_z_x;
    const Eigen::VectorXd z = generator.Generate(tool_index, SE2d::FromXYYaw(x[0], x[1], x[2]),
                                                 x[3], gradient != nullptr ? &J_z_x : nullptr);
    Eigen::VectorXd grad_u;
    const double u_data = problem.Evaluate(z, gradient != nullptr ? &grad_u : nullptr) -
                          0.5 * z.squaredNorm() / prior_variance;
    if (!std::isfinite(u_data)) return -std::numeric_limits<double>::infinity();
    if (gradient != nullptr) {
      grad_u -= z / prior_variance;
      *gradient = -scale2 * (J_z_x.transpose() * grad_u);
      if (!gradient->allFinite()) return -std::numeric_limits<double>::infinity();
    }
    return -scale2 * u_data;
  };
  MetropolisOptions chain = options.chain;
  chain.angles = {2};
  chain.angle_fold = n > 0 ? 2 * M_PI / n : 2 * M_PI;
  if (modes.size() > 1 && options.jump_probability > 0) {
    chain.jump_probability = options.jump_probability;
    // Half the Laplace weight, half uniform: a mode the Laplace evidence underrates is
    // still proposed often enough for the MH ratio to correct its mass.
    double total = 0;
    for (const LaplaceComponent& mode : modes) total += std::max(0.0, mode.weight);
    for (const LaplaceComponent& mode : modes) {
      JumpComponent j;
      j.weight = 0.5 / modes.size() + (total > 0 ? 0.5 * std::max(0.0, mode.weight) / total
                                                 : 0.5 / modes.size());
      j.mean = CoordinateMean(mode, options);
      j.covariance = options.jump_variance_scale * CoordinateCovariance(mode);
      chain.jumps.push_back(std::move(j));
    }
  }
  const Eigen::VectorXd x0 = CoordinateMean(start, options);
  out.chains = SampleMetropolis(log_density, x0, CoordinateCovariance(start), chain);
  return out;
}

}  // namespace tactfunc
