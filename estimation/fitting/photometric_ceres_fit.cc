// Copyright 2026 The tactfunc Authors.
#include "estimation/fitting/photometric_ceres_fit.h"

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <vector>

#include "ceres/ceres.h"
#include "estimation/fitting/square_root_cost.h"

namespace tactfunc {
namespace {

// The residuals of the header comment over `pixels`, one parameter block of d values.
class PhotometricResiduals : public ceres::CostFunction {
 public:
  PhotometricResiduals(const PhotometricTrunk& trunk, const PhotometricTrunk::Markers* markers,
                       std::vector<int> pixels, Eigen::MatrixXf targets,
                       Eigen::VectorXf sqrt_weights)
      : trunk_(trunk),
        markers_(markers),
        pixels_(std::move(pixels)),
        targets_(std::move(targets)),
        sqrt_weights_(std::move(sqrt_weights)) {
    set_num_residuals(static_cast<int>(pixels_.size()) * trunk.channels());
    mutable_parameter_block_sizes()->push_back(trunk.latent_dim());
  }

  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    const int d = trunk_.latent_dim(), c = trunk_.channels();
    const Eigen::VectorXf z = Eigen::Map<const Eigen::VectorXd>(parameters[0], d).cast<float>();
    Eigen::MatrixXf y, J;
    const bool want_jacobian = jacobians != nullptr && jacobians[0] != nullptr;
    if (want_jacobian) {
      trunk_.ForwardAndLatentJacobian<float>(pixels_, z, &y, &J, markers_,
                                             JacobianLayout::kOutputColumns);
    } else {
      y = trunk_.Forward<float>(pixels_, z, markers_);
    }
    const int n = static_cast<int>(pixels_.size());
    for (int i = 0; i < n; ++i) {
      for (int ch = 0; ch < c; ++ch) {
        residuals[i * c + ch] = static_cast<double>(sqrt_weights_[i]) *
                                (static_cast<double>(y(i, ch)) -
                                 static_cast<double>(targets_(i, ch)));
      }
    }
    if (want_jacobian) {
      // Ceres' Jacobian is row-major, rows i C + ch as the trunk's: in memory, the
      // trunk's output-column layout (J is d x n C), so the copy is contiguous.
      Eigen::Map<Eigen::MatrixXd> out(jacobians[0], d, static_cast<Eigen::Index>(n) * c);
      out = J.cast<double>();
      for (int i = 0; i < n; ++i) {
        out.middleCols(static_cast<Eigen::Index>(i) * c, c) *=
            static_cast<double>(sqrt_weights_[i]);
      }
      if (!out.allFinite()) return false;
    }
    for (int r = 0; r < n * c; ++r) {
      if (!std::isfinite(residuals[r])) return false;
    }
    return true;
  }

 private:
  const PhotometricTrunk& trunk_;
  const PhotometricTrunk::Markers* markers_;
  const std::vector<int> pixels_;
  const Eigen::MatrixXf targets_;
  const Eigen::VectorXf sqrt_weights_;
};

}  // namespace

bool PhotometricCeresOptions::IsValid(std::string* error) const {
  std::ostringstream message;
  if (iterations < 1) {
    message << "iterations must be >= 1, found " << iterations;
  } else if (pixels < 0) {
    message << "pixels must be >= 0 (0: every valid pixel), found " << pixels;
  }
  const std::string text = message.str();
  if (error != nullptr) *error = text;
  return text.empty();
}

PhotometricCeresFit FitPhotometricLatentCeres(const PhotometricTrunk& trunk,
                                              const TrunkTargets& frame,
                                              const Eigen::VectorXd& start,
                                              const PhotometricCeresOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) {
    throw std::invalid_argument("PhotometricCeresOptions: " + error);
  }
  const int c = trunk.channels();
  CheckTargetsShape(frame, trunk.options().rows, trunk.options().cols, c,
                    "FitPhotometricLatentCeres");
  if (start.size() != trunk.latent_dim() || !start.allFinite()) {
    throw std::invalid_argument("FitPhotometricLatentCeres: expected a finite start of " +
                                std::to_string(trunk.latent_dim()) + " values, found " +
                                std::to_string(start.size()) +
                                (start.allFinite() ? "" : " with non-finite entries"));
  }
  const std::vector<int> valid = ValidPixels(frame);
  PhotometricCeresFit fit;
  fit.latent = start;
  if (valid.empty()) {
    fit.message = "no valid pixel";
    return fit;
  }
  std::vector<int> pixels;
  const long count = options.pixels == 0
                         ? static_cast<long>(valid.size())
                         : std::min<long>(options.pixels, static_cast<long>(valid.size()));
  for (long k = 0; k < count; ++k) {
    pixels.push_back(valid[static_cast<std::size_t>(k * static_cast<long>(valid.size()) / count)]);
  }
  Eigen::MatrixXf targets(static_cast<Eigen::Index>(pixels.size()), c);
  Eigen::VectorXf sqrt_weights(static_cast<Eigen::Index>(pixels.size()));
  for (std::size_t i = 0; i < pixels.size(); ++i) {
    targets.row(static_cast<Eigen::Index>(i)) = frame.values.row(pixels[i]);
    sqrt_weights[static_cast<Eigen::Index>(i)] =
        frame.weights.size() == 0 ? 1.0f : std::sqrt(frame.weights[pixels[i]]);
  }
  ceres::Problem::Options problem_options;
  problem_options.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
  ceres::Problem problem(problem_options);
  const PhotometricResiduals residuals(trunk, options.markers, std::move(pixels),
                                       std::move(targets), std::move(sqrt_weights));
  // Ceres sees the residuals' square-root information form, d + 1 of them: the same steps
  // without Ceres forming normal equations of N C rows (estimation/fitting/square_root_cost.h).
  SquareRootCost square_root(&residuals, /*prior_precision=*/0.0);
  problem.AddResidualBlock(&square_root, nullptr, fit.latent.data());
  ceres::Solver::Options solver;
  solver.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;  // one dense block of d values
  solver.max_num_iterations = options.iterations;
  solver.num_threads = 1;
  solver.logging_type = ceres::SILENT;
  solver.minimizer_progress_to_stdout = false;
  ceres::Solver::Summary summary;
  ceres::Solve(solver, &problem, &summary);
  fit.initial_cost = summary.initial_cost;
  fit.final_cost = summary.final_cost;
  fit.iterations = static_cast<int>(summary.iterations.size());
  fit.message = summary.message;
  return fit;
}

}  // namespace tactfunc
