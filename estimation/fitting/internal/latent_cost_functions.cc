// Copyright 2026 The tactfunc Authors.
#include "estimation/fitting/internal/latent_cost_functions.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "ceres/dynamic_autodiff_cost_function.h"

namespace tactfunc {
namespace internal {
namespace {

std::string Shape(long rows, long cols) {
  return std::to_string(rows) + "x" + std::to_string(cols);
}

// The autodiff functor: one LatentModulatedSiren::Evaluate<T> per pixel.
class AutoDiffLatentFunctor {
 public:
  AutoDiffLatentFunctor(const LatentModulatedSiren* siren, const LatentResidualData* data)
      : siren_(siren), data_(data) {}

  template <typename T>
  bool operator()(T const* const* parameters, T* residuals) const {
    const int n = data_->num_pixels();
    const int channels = data_->channels;
    std::vector<T> out(channels);
    for (int j = 0; j < n; ++j) {
      const T coord[2] = {T(data_->coords(j, 0)), T(data_->coords(j, 1))};
      siren_->Evaluate<T>(coord, parameters[0], out.data());
      for (int c = 0; c < channels; ++c) {
        const int i = j * channels + c;
        residuals[i] = data_->residual_scale[i] * (out[c] - data_->targets(j, c));
      }
    }
    return true;
  }

 private:
  const LatentModulatedSiren* siren_;
  const LatentResidualData* data_;
};

template <int kStride>
std::unique_ptr<ceres::CostFunction> MakeDynamic(const LatentModulatedSiren* siren,
                                                 const LatentResidualData* data) {
  auto cost = std::make_unique<ceres::DynamicAutoDiffCostFunction<AutoDiffLatentFunctor, kStride>>(
      new AutoDiffLatentFunctor(siren, data));
  cost->AddParameterBlock(siren->latent_dim());
  cost->SetNumResiduals(data->num_residuals());
  return cost;
}

}  // namespace

LatentResidualData SelectPixels(const LatentModulatedSiren& siren, const TrunkTargets& targets,
                                double sigma, int stride, int max_pixels) {
  const long rows = targets.rows, cols = targets.cols;
  const int channels = siren.output_channels();
  if (rows < 1 || cols < 1) {
    throw std::invalid_argument("LatentFitter: targets must have rows and cols >= 1, found " +
                                Shape(rows, cols));
  }
  const long n = rows * cols;
  if (targets.values.rows() != n || targets.values.cols() != channels) {
    throw std::invalid_argument(
        "LatentFitter: targets.values must be " + Shape(n, channels) + " (rows*cols = " +
        Shape(rows, cols) + " pixels x the trunk's " + std::to_string(channels) +
        " channels), found " + Shape(targets.values.rows(), targets.values.cols()));
  }
  if (targets.weights.size() != n) {
    throw std::invalid_argument("LatentFitter: targets.weights must have " + std::to_string(n) +
                                " entries (rows*cols), found " +
                                std::to_string(targets.weights.size()));
  }
  std::vector<int> valid;
  valid.reserve(n);
  for (long j = 0; j < n; ++j) {
    const float w = targets.weights[j];
    if (!std::isfinite(w) || w < 0) {
      throw std::invalid_argument("LatentFitter: targets.weights[" + std::to_string(j) +
                                  "] must be finite and >= 0, found " + std::to_string(w));
    }
    if (w == 0) continue;
    for (int c = 0; c < channels; ++c) {
      if (!std::isfinite(targets.values(j, c))) {
        throw std::invalid_argument(
            "LatentFitter: targets.values(" + std::to_string(j) + ", " + std::to_string(c) +
            ") of a valid pixel (weight " + std::to_string(w) +
            ") is not finite; give invalid pixels weight 0");
      }
    }
    valid.push_back(static_cast<int>(j));
  }
  std::vector<int> chosen;
  for (size_t i = 0; i < valid.size(); i += stride) chosen.push_back(valid[i]);
  if (max_pixels > 0 && static_cast<long>(chosen.size()) > max_pixels) {
    std::vector<int> thinned(max_pixels);
    const double step = static_cast<double>(chosen.size()) / max_pixels;
    for (int i = 0; i < max_pixels; ++i) thinned[i] = chosen[static_cast<size_t>(i * step)];
    chosen.swap(thinned);
  }

  LatentResidualData data;
  data.channels = channels;
  data.num_valid_pixels = static_cast<int>(valid.size());
  const int m = static_cast<int>(chosen.size());
  const Eigen::MatrixXd grid = siren.Grid<double>(targets.rows, targets.cols);
  data.coords.resize(m, 2);
  data.targets.resize(m, channels);
  data.weights_float.resize(m);
  data.residual_scale.resize(static_cast<long>(m) * channels);
  for (int i = 0; i < m; ++i) {
    const int j = chosen[i];
    data.coords.row(i) = grid.row(j);
    const double w = targets.weights[j];
    data.weights_float[i] = static_cast<float>(w);
    for (int c = 0; c < channels; ++c) {
      data.targets(i, c) = targets.values(j, c);
      data.residual_scale[static_cast<long>(i) * channels + c] = std::sqrt(w) / sigma;
    }
  }
  data.coords_float = data.coords.cast<float>();
  data.targets_float = data.targets.cast<float>();
  return data;
}

// ---- Analytic -----------------------------------------------------------------------------

template <typename Scalar>
AnalyticLatentCost<Scalar>::AnalyticLatentCost(const LatentModulatedSiren* siren,
                                               const LatentResidualData* data)
    : siren_(siren), data_(data), coords_(data->coords.cast<Scalar>()) {
  mutable_parameter_block_sizes()->push_back(siren->latent_dim());
  set_num_residuals(data->num_residuals());
}

template <typename Scalar>
bool AnalyticLatentCost<Scalar>::Evaluate(double const* const* parameters, double* residuals,
                                          double** jacobians) const {
  const int d = siren_->latent_dim();
  const int channels = data_->channels;
  const long n = coords_.rows();
  const LatentModulatedSiren::VectorX<Scalar> z =
      Eigen::Map<const Eigen::VectorXd>(parameters[0], d).cast<Scalar>();
  const bool want_jacobian = jacobians != nullptr && jacobians[0] != nullptr;
  LatentModulatedSiren::MatrixX<Scalar> outputs, J;
  siren_->ForwardAndLatentJacobian<Scalar>(coords_, z, &outputs, want_jacobian ? &J : nullptr);
  bool finite = true;
  for (long j = 0; j < n; ++j) {
    for (int c = 0; c < channels; ++c) {
      const long i = j * channels + c;
      residuals[i] = data_->residual_scale[i] *
                     (static_cast<double>(outputs(j, c)) - data_->targets(j, c));
      finite = finite && std::isfinite(residuals[i]);
    }
  }
  if (want_jacobian) {
    // Ceres wants the (n*C) x d Jacobian row-major; ours is column-major.
    Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> out(
        jacobians[0], n * channels, d);
    out = data_->residual_scale.asDiagonal() * J.template cast<double>();
    finite = finite && out.allFinite();
  }
  return finite;
}

template class AnalyticLatentCost<float>;
template class AnalyticLatentCost<double>;

// ---- Autodiff ----------------------------------------------------------------------------

std::unique_ptr<ceres::CostFunction> MakeAutoDiffLatentCost(const LatentModulatedSiren* siren,
                                                            const LatentResidualData* data,
                                                            int stride) {
  if (stride == 0) {
    stride = 64;
    for (int s : {4, 8, 16, 32}) {
      if (s >= siren->latent_dim()) {
        stride = s;
        break;
      }
    }
  }
  switch (stride) {
    case 4:
      return MakeDynamic<4>(siren, data);
    case 8:
      return MakeDynamic<8>(siren, data);
    case 16:
      return MakeDynamic<16>(siren, data);
    case 32:
      return MakeDynamic<32>(siren, data);
    case 64:
      return MakeDynamic<64>(siren, data);
    default:
      throw std::invalid_argument("MakeAutoDiffLatentCost: stride must be 0 (automatic), 4, 8, 16, 32 or 64, found " +
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

// ---- Robust ------------------------------------------------------------------------------

RobustifiedCost::RobustifiedCost(const ceres::CostFunction* inner, const ceres::LossFunction* loss)
    : inner_(inner), loss_(loss) {
  *mutable_parameter_block_sizes() = inner->parameter_block_sizes();
  set_num_residuals(inner->num_residuals());
}

bool RobustifiedCost::Evaluate(double const* const* parameters, double* residuals,
                               double** jacobians) const {
  if (!inner_->Evaluate(parameters, residuals, jacobians)) return false;
  const int m = num_residuals();
  const bool want_jacobian = jacobians != nullptr && jacobians[0] != nullptr;
  const int d = want_jacobian ? inner_->parameter_block_sizes()[0] : 0;
  for (int i = 0; i < m; ++i) {
    const double r = residuals[i];
    const double s = r * r;
    double rho[3];
    loss_->Evaluate(s, rho);
    const double root = std::sqrt(rho[0]);
    double factor = 1.0;  // rho'(0) = 1 for every loss Ceres ships
    if (s > 0 && root > 0) {
      residuals[i] = std::copysign(root, r);
      factor = rho[1] * std::abs(r) / root;
    }
    if (want_jacobian) {
      double* row = jacobians[0] + static_cast<long>(i) * d;
      for (int k = 0; k < d; ++k) row[k] *= factor;
    }
  }
  return true;
}

template <>
float DataLossAndGradient<float>(const LatentModulatedSiren& siren,
                                 const LatentResidualData& data, const Eigen::VectorXf& z,
                                 Eigen::VectorXf* dL_dz) {
  return siren.LossAndGradient<float>(data.coords_float, z, data.targets_float,
                                      data.weights_float, dL_dz, nullptr);
}

template <>
double DataLossAndGradient<double>(const LatentModulatedSiren& siren,
                                   const LatentResidualData& data, const Eigen::VectorXd& z,
                                   Eigen::VectorXd* dL_dz) {
  return siren.LossAndGradient<double>(data.coords, z, data.targets,
                                       data.weights_float.cast<double>(), dL_dz, nullptr);
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

}  // namespace internal
}  // namespace tactfunc
