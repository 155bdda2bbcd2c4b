// Copyright 2026 The tactfunc Authors.
#include "estimation/fitting/latent_costs.h"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "ceres/dynamic_autodiff_cost_function.h"

namespace tactfunc {
namespace {

// The autodiff functor: one LatentModulatedSiren::Evaluate<T> per selected pixel, whitened
// as LatentProblem whitens (sqrt(w_j) / sigma), not yet robustified.
class AutoDiffLatentFunctor {
 public:
  explicit AutoDiffLatentFunctor(const LatentProblem* problem) : problem_(problem) {}

  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    const LatentModulatedSiren& siren = problem_->trunk().siren;
    const int n = problem_->num_pixels();
    const int channels = problem_->channels();
    std::vector<T> out(channels);
    for (int j = 0; j < n; ++j) {
      const T coord[2] = {T(problem_->coords()(j, 0)), T(problem_->coords()(j, 1))};
      siren.Evaluate<T>(coord, parameters[0], out.data());
      const double scale = std::sqrt(problem_->pixel_weights()[j]) / problem_->sigma();
      for (int c = 0; c < channels; ++c) {
        residuals[j * channels + c] = scale * (out[c] - problem_->pixel_targets()(j, c));
      }
    }
    return true;
  }

 private:
  const LatentProblem* problem_;
};

// The dynamic autodiff cost, then the problem's robust transform.
class AutoDiffLatentCost : public ceres::CostFunction {
 public:
  AutoDiffLatentCost(const LatentProblem* problem, std::unique_ptr<ceres::CostFunction> raw)
      : problem_(problem), raw_(std::move(raw)) {
    mutable_parameter_block_sizes()->push_back(problem->dim());
    set_num_residuals(problem->num_residuals());
  }
  bool Evaluate(double const* const* parameters, double* residuals,
                double** jacobians) const override {
    if (!raw_->Evaluate(parameters, residuals, jacobians)) return false;
    const bool want_jacobian = jacobians != nullptr && jacobians[0] != nullptr;
    problem_->Robustify(num_residuals(), residuals, want_jacobian ? jacobians[0] : nullptr,
                        problem_->dim());
    return true;
  }

 private:
  const LatentProblem* problem_;
  std::unique_ptr<ceres::CostFunction> raw_;
};

template <int kStride>
std::unique_ptr<ceres::CostFunction> MakeDynamic(const LatentProblem* problem) {
  auto raw = std::make_unique<ceres::DynamicAutoDiffCostFunction<AutoDiffLatentFunctor, kStride>>(
      new AutoDiffLatentFunctor(problem));
  raw->AddParameterBlock(problem->dim());
  raw->SetNumResiduals(problem->num_residuals());
  return std::make_unique<AutoDiffLatentCost>(problem, std::move(raw));
}

}  // namespace

// ---- Analytic -----------------------------------------------------------------------------

AnalyticLatentCost::AnalyticLatentCost(const LatentProblem* problem, const StartPass* start)
    : problem_(problem), start_(start) {
  if (start != nullptr && !problem->CanUse(*start)) {
    throw std::invalid_argument(
        "AnalyticLatentCost: the start pass is not of this problem's trunk, frame size and "
        "precision");
  }
  mutable_parameter_block_sizes()->push_back(problem->dim());
  set_num_residuals(problem->num_residuals());
}

bool AnalyticLatentCost::Evaluate(double const* const* parameters, double* residuals,
                                  double** jacobians) const {
  const bool want_jacobian = jacobians != nullptr && jacobians[0] != nullptr;
  if (start_ != nullptr &&
      Eigen::Map<const Eigen::VectorXd>(parameters[0], problem_->dim()).isZero(0.0)) {
    return problem_->ResidualsAndJacobianAtStart(*start_, residuals,
                                                 want_jacobian ? jacobians[0] : nullptr);
  }
  if (!want_jacobian) return problem_->ResidualsAndJacobian(parameters[0], residuals, nullptr);
  last_z_.resize(0);
  if (!problem_->ResidualsAndJacobian(parameters[0], residuals, jacobians[0], &last_outputs_)) {
    return false;
  }
  last_z_ = Eigen::Map<const Eigen::VectorXd>(parameters[0], problem_->dim());
  return true;
}

const Eigen::MatrixXd* AnalyticLatentCost::OutputsAt(const double* z) const {
  const int d = problem_->dim();
  if (last_z_.size() != d || last_z_ != Eigen::Map<const Eigen::VectorXd>(z, d)) return nullptr;
  return &last_outputs_;
}

// ---- Autodiff ----------------------------------------------------------------------------

std::unique_ptr<ceres::CostFunction> MakeAutoDiffLatentCost(const LatentProblem* problem,
                                                            int stride) {
  if (stride == 0) {
    stride = 64;
    for (int s : {4, 8, 16, 32}) {
      if (s >= problem->dim()) {
        stride = s;
        break;
      }
    }
  }
  switch (stride) {
    case 4:
      return MakeDynamic<4>(problem);
    case 8:
      return MakeDynamic<8>(problem);
    case 16:
      return MakeDynamic<16>(problem);
    case 32:
      return MakeDynamic<32>(problem);
    case 64:
      return MakeDynamic<64>(problem);
    default:
      throw std::invalid_argument(
          "MakeAutoDiffLatentCost: stride must be 0 (automatic), 4, 8, 16, 32 or 64, found " +
          std::to_string(stride));
  }
}

// ---- Prior --------------------------------------------------------------------------------

LatentPriorCost::LatentPriorCost(int latent_dim, double sigma_z)
    : inverse_sigma_z_(1.0 / sigma_z) {
  mutable_parameter_block_sizes()->push_back(latent_dim);
  set_num_residuals(latent_dim);
}

bool LatentPriorCost::Evaluate(double const* const* parameters, double* residuals,
                               double** jacobians) const {
  const int d = num_residuals();
  for (int k = 0; k < d; ++k) residuals[k] = parameters[0][k] * inverse_sigma_z_;
  if (jacobians != nullptr && jacobians[0] != nullptr) {
    Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
        jacobians[0], d, d) = Eigen::MatrixXd::Identity(d, d) * inverse_sigma_z_;
  }
  for (int k = 0; k < d; ++k) {
    if (!std::isfinite(residuals[k])) return false;
  }
  return true;
}

double HalfSquaredNorm(const ceres::CostFunction& cost, const double* z) {
  std::vector<double> residuals(cost.num_residuals());
  const double* parameters[] = {z};
  if (!cost.Evaluate(parameters, residuals.data(), nullptr)) {
    return std::numeric_limits<double>::quiet_NaN();
  }
  double sum = 0;
  for (double r : residuals) sum += r * r;
  return 0.5 * sum;
}

}  // namespace tactfunc
