// Copyright 2026 The tactfunc Authors.
#include "estimation/fitting/latent_problem.h"

#include <cmath>
#include <limits>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <type_traits>
#include <utility>

#include "ceres/loss_function.h"
#include "models/trunk/meta_sgd.h"

namespace tactfunc {
namespace {

std::string Shape(long rows, long cols) {
  return std::to_string(rows) + "x" + std::to_string(cols);
}

using RowMajorMatrixXd = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

std::unique_ptr<ceres::LossFunction> MakeLoss(const LatentProblem::Options& options) {
  switch (options.robust_loss) {
    case LatentProblem::RobustLoss::kHuber:
      return std::make_unique<ceres::HuberLoss>(options.robust_loss_scale);
    case LatentProblem::RobustLoss::kCauchy:
      return std::make_unique<ceres::CauchyLoss>(options.robust_loss_scale);
    case LatentProblem::RobustLoss::kNone:
      break;
  }
  return nullptr;
}

// J^T J (d x d, as double) of a Jacobian J with one row per residual: SYRK in J's own
// scalar type (float or double) on the lower triangle, then filled in.
template <typename Jacobian>
Eigen::MatrixXd GramOfJacobian(const Jacobian& J) {
  using Scalar = typename Jacobian::Scalar;
  Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic> jtj =
      Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>::Zero(J.cols(), J.cols());
  jtj.template selfadjointView<Eigen::Lower>().rankUpdate(J.transpose());
  return jtj.template selfadjointView<Eigen::Lower>().toDenseMatrix().template cast<double>();
}

}  // namespace

const char* ToString(LatentProblem::RobustLoss loss) {
  switch (loss) {
    case LatentProblem::RobustLoss::kNone:
      return "none";
    case LatentProblem::RobustLoss::kHuber:
      return "huber";
    case LatentProblem::RobustLoss::kCauchy:
      return "cauchy";
  }
  return "unknown";
}

const char* ToString(LatentProblem::Precision precision) {
  return precision == LatentProblem::Precision::kFloat ? "float" : "double";
}

bool LatentProblem::Options::IsValid(std::string* error) const {
  std::ostringstream message;
  if (!(sigma >= 0.0) || !std::isfinite(sigma)) {
    message << "sigma must be finite and > 0 (or 0 = automatic), found " << sigma;
  } else if (!(sigma_z > 0.0) || !std::isfinite(sigma_z)) {
    message << "sigma_z must be finite and > 0, found " << sigma_z;
  } else if (robust_loss != RobustLoss::kNone && robust_loss != RobustLoss::kHuber &&
             robust_loss != RobustLoss::kCauchy) {
    message << "robust_loss is not a RobustLoss, found " << static_cast<int>(robust_loss);
  } else if (!(robust_loss_scale > 0.0) || !std::isfinite(robust_loss_scale)) {
    message << "robust_loss_scale must be finite and > 0, found " << robust_loss_scale;
  } else if (pixel_stride < 1) {
    message << "pixel_stride must be >= 1, found " << pixel_stride;
  } else if (max_pixels < 0) {
    message << "max_pixels must be >= 0 (0 = all), found " << max_pixels;
  } else if (!(contact_share >= 0.0 && contact_share <= 1.0)) {
    message << "contact_share must be in [0, 1], found " << contact_share;
  } else if (precision != Precision::kFloat && precision != Precision::kDouble) {
    message << "precision is not a Precision, found " << static_cast<int>(precision);
  } else {
    return true;
  }
  if (error != nullptr) *error = "LatentProblem::Options::" + message.str();
  return false;
}

double LatentProblem::AutomaticSigma(const SensorTrunk& trunk) {
  return trunk.residual_sigma > 0 ? trunk.residual_sigma : 0.01;
}

LatentProblem::LatentProblem(const SensorTrunk& trunk, const TrunkTargets& targets,
                             const Options& options)
    : trunk_(&trunk), frame_(&targets), options_(options) {
  std::string error;
  if (!options_.IsValid(&error)) throw std::invalid_argument(error);
  if (trunk.photometric != nullptr) {
    throw std::invalid_argument(
        "LatentProblem: the direct trunk's problem; a photometric trunk's latents are fitted "
        "by FitPhotometricLatent (adam:N)");
  }
  const LatentModulatedSiren& siren = trunk.siren;
  const int d = siren.latent_dim();
  if (trunk.alpha.size() != d) {
    throw std::invalid_argument("LatentProblem: trunk.alpha must have latent_dim = " +
                                std::to_string(d) + " entries, found " +
                                std::to_string(trunk.alpha.size()));
  }
  sigma_ = options_.sigma > 0 ? options_.sigma : AutomaticSigma(trunk);
  loss_ = MakeLoss(options_);

  const long rows = targets.rows, cols = targets.cols;
  const int channels = siren.output_channels();
  if (rows < 1 || cols < 1) {
    throw std::invalid_argument("LatentProblem: targets must have rows and cols >= 1, found " +
                                Shape(rows, cols));
  }
  const long n = rows * cols;
  if (targets.values.rows() != n || targets.values.cols() != channels) {
    throw std::invalid_argument(
        "LatentProblem: targets.values must be " + Shape(n, channels) + " (rows*cols = " +
        Shape(rows, cols) + " pixels x the trunk's " + std::to_string(channels) +
        " channels), found " + Shape(targets.values.rows(), targets.values.cols()));
  }
  if (targets.weights.size() != n) {
    throw std::invalid_argument("LatentProblem: targets.weights must have " + std::to_string(n) +
                                " entries (rows*cols), found " +
                                std::to_string(targets.weights.size()));
  }
  std::vector<int> valid;
  valid.reserve(n);
  for (long j = 0; j < n; ++j) {
    const float w = targets.weights[j];
    if (!std::isfinite(w) || w < 0) {
      throw std::invalid_argument("LatentProblem: targets.weights[" + std::to_string(j) +
                                  "] must be finite and >= 0, found " + std::to_string(w));
    }
    if (w == 0) continue;
    for (int c = 0; c < channels; ++c) {
      if (!std::isfinite(targets.values(j, c))) {
        throw std::invalid_argument(
            "LatentProblem: targets.values(" + std::to_string(j) + ", " + std::to_string(c) +
            ") of a valid pixel (weight " + std::to_string(w) +
            ") is not finite; give invalid pixels weight 0");
      }
    }
    valid.push_back(static_cast<int>(j));
  }
  num_valid_pixels_ = static_cast<int>(valid.size());
  std::vector<int> chosen;
  for (size_t i = 0; i < valid.size(); i += options_.pixel_stride) chosen.push_back(valid[i]);
  const int max_pixels = options_.max_pixels;
  std::vector<double> weight_factor;  // empty: 1 for every chosen pixel
  if (max_pixels > 0 && static_cast<long>(chosen.size()) > max_pixels) {
    if (options_.contact_share > 0) {
      ContactSample(targets, max_pixels, options_.contact_share, &chosen, &weight_factor);
    } else {
      std::vector<int> thinned(max_pixels);
      const double step = static_cast<double>(chosen.size()) / max_pixels;
      for (int i = 0; i < max_pixels; ++i) thinned[i] = chosen[static_cast<size_t>(i * step)];
      chosen.swap(thinned);
    }
  }

  const int m = static_cast<int>(chosen.size());
  const Eigen::MatrixXd grid = siren.Grid<double>(targets.rows, targets.cols);
  coords_.resize(m, 2);
  pixel_targets_.resize(m, channels);
  weights_.resize(m);
  weights_float_.resize(m);
  residual_scale_.resize(static_cast<long>(m) * channels);
  for (int i = 0; i < m; ++i) {
    const int j = chosen[i];
    coords_.row(i) = grid.row(j);
    const float w = weight_factor.empty()
                        ? targets.weights[j]
                        : static_cast<float>(targets.weights[j] * weight_factor[i]);
    weights_float_[i] = w;
    weights_[i] = w;
    for (int c = 0; c < channels; ++c) {
      pixel_targets_(i, c) = targets.values(j, c);
      residual_scale_[static_cast<long>(i) * channels + c] = std::sqrt(static_cast<double>(w)) / sigma_;
    }
  }
  coords_float_ = coords_.cast<float>();
  targets_float_ = pixel_targets_.cast<float>();
  pixel_index_ = std::move(chosen);
}

int LatentProblem::dim() const { return trunk_->siren.latent_dim(); }
int LatentProblem::channels() const { return trunk_->siren.output_channels(); }

void LatentProblem::CheckLatent(const Eigen::VectorXd& z, const char* where) const {
  if (z.size() != dim()) {
    throw std::invalid_argument(std::string("LatentProblem::") + where +
                                ": expected a latent of size " + std::to_string(dim()) +
                                ", found " + std::to_string(z.size()));
  }
}

// ---- Residuals (Ceres' view) ---------------------------------------------------------------

bool LatentProblem::ResidualsAndJacobian(const double* z_data, double* residuals,
                                         double* jacobian) const {
  return ResidualsAndJacobian(z_data, residuals, jacobian, nullptr);
}

bool LatentProblem::ResidualsAndJacobianAlong(const double* z, const Eigen::MatrixXd& directions,
                                              double* residuals, double* jacobian) const {
  if (directions.rows() != dim()) {
    throw std::invalid_argument("LatentProblem::ResidualsAndJacobianAlong: directions: expected " +
                                std::to_string(dim()) + " rows, got " +
                                std::to_string(directions.rows()));
  }
  return ResidualPass(z, residuals, jacobian, nullptr, &directions);
}

bool LatentProblem::ResidualsAndJacobian(const double* z_data, double* residuals,
                                         double* jacobian, Eigen::MatrixXd* outputs_out) const {
  return ResidualPass(z_data, residuals, jacobian, outputs_out, nullptr);
}

bool LatentProblem::ResidualPass(const double* z_data, double* residuals, double* jacobian,
                                 Eigen::MatrixXd* outputs_out,
                                 const Eigen::MatrixXd* directions) const {
  const int d = dim();
  // Jacobian columns: d, or the directions' k.
  const int cols = directions != nullptr ? static_cast<int>(directions->cols()) : d;
  const int c_count = channels();
  const long n = num_pixels();
  bool finite = true;
  auto run = [&](auto tag) {
    using Scalar = decltype(tag);
    using Matrix = LatentModulatedSiren::MatrixX<Scalar>;
    const Matrix* coords;
    if constexpr (std::is_same<Scalar, float>::value) {
      coords = &coords_float_;
    } else {
      coords = &coords_;
    }
    const LatentModulatedSiren::VectorX<Scalar> z =
        Eigen::Map<const Eigen::VectorXd>(z_data, d).cast<Scalar>();
    // Ceres wants the (N C) x cols Jacobian row-major, which in memory is the trunk's
    // output-column layout (cols x N C, column-major): taken where the trunk has it (no
    // readout branch, no spatial latents), so the copy below runs down columns.
    const bool columns = !trunk_->siren.has_readout() && !trunk_->siren.has_spatial();
    Matrix outputs, J, D;
    if (directions != nullptr) D = directions->cast<Scalar>();
    trunk_->siren.ForwardAndLatentJacobian<Scalar>(
        *coords, z, &outputs, jacobian != nullptr ? &J : nullptr, nullptr,
        columns ? JacobianLayout::kOutputColumns : JacobianLayout::kOutputRows,
        directions != nullptr ? &D : nullptr);
    for (long j = 0; j < n; ++j) {
      for (int c = 0; c < c_count; ++c) {
        const long i = j * c_count + c;
        residuals[i] =
            residual_scale_[i] * (static_cast<double>(outputs(j, c)) - pixel_targets_(j, c));
        finite = finite && std::isfinite(residuals[i]);
      }
    }
    if (outputs_out != nullptr) *outputs_out = outputs.template cast<double>();
    if (jacobian != nullptr && columns) {
      Eigen::Map<Eigen::MatrixXd> out(jacobian, cols, n * c_count);
      out = J.template cast<double>() * residual_scale_.asDiagonal();
      finite = finite && out.allFinite();
    } else if (jacobian != nullptr) {
      Eigen::Map<RowMajorMatrixXd> out(jacobian, n * c_count, cols);
      out = residual_scale_.asDiagonal() * J.template cast<double>();
      finite = finite && out.allFinite();
    }
  };
  if (options_.precision == Precision::kFloat) {
    run(float());
  } else {
    run(double());
  }
  Robustify(static_cast<int>(n * c_count), residuals, jacobian, cols);
  return finite;
}

// ---- The pass at z = 0 ------------------------------------------------------------------------

bool StartPass::Applies(const SensorTrunk& trunk) {
  return !trunk.siren.has_readout() && !trunk.siren.has_spatial();
}

StartPass::StartPass(const SensorTrunk& trunk_in, int rows_in, int cols_in)
    : trunk(&trunk_in), rows(rows_in), cols(cols_in) {
  if (!Applies(trunk_in)) {
    throw std::invalid_argument(
        "StartPass: the trunk has a readout branch or spatial latents, whose fits do not "
        "start at z = 0");
  }
  if (rows < 1 || cols < 1) {
    throw std::invalid_argument("StartPass: expected a frame of at least 1 x 1 pixels, found " +
                                std::to_string(rows) + " x " + std::to_string(cols));
  }
  const LatentModulatedSiren& siren = trunk_in.siren;
  // The coordinates exactly as LatentProblem makes them: the double grid, cast to float.
  const Eigen::MatrixXf coords = siren.Grid<double>(rows, cols).cast<float>();
  siren.ForwardAndLatentJacobian<float>(coords, Eigen::VectorXf::Zero(siren.latent_dim()),
                                        &outputs, &jacobian, nullptr,
                                        JacobianLayout::kOutputColumns);
}

bool LatentProblem::CanUse(const StartPass& pass) const {
  return pass.trunk == trunk_ && pass.rows == frame_->rows && pass.cols == frame_->cols &&
         options_.precision == Precision::kFloat;
}

bool LatentProblem::ResidualsAndJacobianAtStart(const StartPass& pass, double* residuals,
                                                double* jacobian) const {
  const int d = dim();
  const int c_count = channels();
  const long n = num_pixels();
  bool finite = true;
  for (long j = 0; j < n; ++j) {
    for (int c = 0; c < c_count; ++c) {
      const long i = j * c_count + c;
      residuals[i] = residual_scale_[i] * (static_cast<double>(pass.outputs(pixel_index_[j], c)) -
                                           pixel_targets_(j, c));
      finite = finite && std::isfinite(residuals[i]);
    }
  }
  if (jacobian != nullptr) {
    // Ceres' row-major (N C) x d block is d x (N C) column-major in memory.
    Eigen::Map<Eigen::MatrixXd> out(jacobian, d, n * c_count);
    for (long j = 0; j < n; ++j) {
      for (int c = 0; c < c_count; ++c) {
        const long i = j * c_count + c;
        out.col(i) = pass.jacobian.col(static_cast<long>(pixel_index_[j]) * c_count + c)
                         .cast<double>() *
                     residual_scale_[i];
      }
    }
    finite = finite && out.allFinite();
  }
  Robustify(static_cast<int>(n * c_count), residuals, jacobian, d);
  return finite;
}

double LatentProblem::DataCostAtStart(const StartPass& pass, std::optional<double>* psnr) const {
  Eigen::MatrixXd outputs(num_pixels(), channels());
  for (long j = 0; j < num_pixels(); ++j) {
    outputs.row(j) = pass.outputs.row(pixel_index_[j]).cast<double>();
  }
  return DataCostOfOutputs(outputs, psnr);
}

void LatentProblem::Robustify(int num_residuals, double* residuals, double* jacobian,
                              int cols) const {
  if (!loss_) return;
  for (int i = 0; i < num_residuals; ++i) {
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
    if (jacobian != nullptr) {
      double* row = jacobian + static_cast<long>(i) * cols;
      for (int k = 0; k < cols; ++k) row[k] *= factor;
    }
  }
}

// ---- U, its gradient and H_GN (the samplers' view) ------------------------------------------

template <typename Scalar>
double LatentProblem::DataTermAndGradient(const Eigen::VectorXd& z, const std::vector<int>* rows,
                                          double scale, Eigen::VectorXd* gradient) const {
  using Matrix = LatentModulatedSiren::MatrixX<Scalar>;
  using Vector = LatentModulatedSiren::VectorX<Scalar>;
  const Matrix* all_coords;
  const Matrix* all_targets;
  const Vector* all_weights;
  if constexpr (std::is_same<Scalar, float>::value) {
    all_coords = &coords_float_;
    all_targets = &targets_float_;
    all_weights = &weights_float_;
  } else {
    all_coords = &coords_;
    all_targets = &pixel_targets_;
    all_weights = &weights_;
  }
  // Without a robust loss: one forward and one reverse pass (the trunk's weighted MSE,
  // LossAndGradient: sum_j w_j ||f - y_j||^2 / (C sum_j w_j)), rescaled to U's data term.
  const Vector zs = z.cast<Scalar>();
  const double unit = scale * channels() / (2.0 * sigma_ * sigma_);
  Vector dL_dz;
  double sum_w = 0, loss = 0;
  auto evaluate = [&](const Matrix& coords, const Matrix& targets, const Vector& weights) {
    sum_w = weights.template cast<double>().sum();
    if (!(sum_w > 0)) return;
    loss = static_cast<double>(trunk_->siren.template LossAndGradient<Scalar>(
        coords, zs, targets, weights, gradient != nullptr ? &dL_dz : nullptr, nullptr));
  };
  if (rows == nullptr) {
    evaluate(*all_coords, *all_targets, *all_weights);
  } else {
    evaluate((*all_coords)(*rows, Eigen::all), (*all_targets)(*rows, Eigen::all),
             (*all_weights)(*rows));
  }
  if (!(sum_w > 0)) return 0;
  if (gradient != nullptr) *gradient += (unit * sum_w) * dL_dz.template cast<double>();
  return unit * sum_w * loss;
}

double LatentProblem::Evaluate(const Eigen::VectorXd& z, Eigen::VectorXd* gradient) const {
  CheckLatent(z, "Evaluate");
  return EvaluateRows(z, nullptr, gradient);
}

double LatentProblem::EvaluateMinibatch(const Eigen::VectorXd& z, const std::vector<int>& rows,
                                        Eigen::VectorXd* gradient) const {
  CheckLatent(z, "EvaluateMinibatch");
  for (int i : rows) {
    if (i < 0 || i >= num_pixels()) {
      throw std::invalid_argument("LatentProblem::EvaluateMinibatch: row " + std::to_string(i) +
                                  " outside [0, " + std::to_string(num_pixels()) + ")");
    }
  }
  return EvaluateRows(z, rows.empty() ? nullptr : &rows, gradient);
}

double LatentProblem::EvaluateRows(const Eigen::VectorXd& z, const std::vector<int>* rows,
                                   Eigen::VectorXd* gradient) const {
  const double scale =
      rows == nullptr ? 1.0 : static_cast<double>(num_pixels()) / rows->size();
  const double variance = options_.sigma_z * options_.sigma_z;
  const double prior = 0.5 * z.squaredNorm() / variance;
  if (gradient != nullptr) *gradient = z / variance;
  if (num_pixels() == 0) return prior;
  if (options_.robust_loss == RobustLoss::kNone) {
    return prior + (options_.precision == Precision::kFloat
                        ? DataTermAndGradient<float>(z, rows, scale, gradient)
                        : DataTermAndGradient<double>(z, rows, scale, gradient));
  }
  // U = 1/2 ||r'||^2 + prior, grad U = J'^T r' + z / sigma_z^2 (header comment), over
  // the rows' residuals scaled by N / n. The residuals of every selected pixel are
  // computed (one batched pass) and the rows picked from them.
  const int d = dim();
  const int c_count = channels();
  Eigen::VectorXd residuals(num_residuals());
  RowMajorMatrixXd jacobian;
  if (gradient != nullptr) jacobian.resize(num_residuals(), d);
  ResidualsAndJacobian(z.data(), residuals.data(), gradient != nullptr ? jacobian.data() : nullptr);
  if (rows == nullptr) {
    if (gradient != nullptr) *gradient += jacobian.transpose() * residuals;
    return prior + 0.5 * residuals.squaredNorm();
  }
  double data = 0;
  for (int j : *rows) {
    for (int c = 0; c < c_count; ++c) {
      const long i = static_cast<long>(j) * c_count + c;
      data += residuals[i] * residuals[i];
      if (gradient != nullptr) *gradient += scale * residuals[i] * jacobian.row(i).transpose();
    }
  }
  return prior + 0.5 * scale * data;
}

void LatentProblem::DataTerms(const Eigen::VectorXd& z, Eigen::VectorXd* values,
                              Eigen::MatrixXd* gradients, Eigen::MatrixXd* hessian) const {
  CheckLatent(z, "DataTerms");
  const int d = dim();
  const int c_count = channels();
  const long n = num_pixels();
  values->setZero(n);
  gradients->setZero(n, d);
  if (hessian != nullptr) hessian->setIdentity(d, d) /= options_.sigma_z * options_.sigma_z;
  if (n == 0) return;
  Eigen::VectorXd residuals(num_residuals());
  RowMajorMatrixXd jacobian(num_residuals(), d);
  ResidualsAndJacobian(z.data(), residuals.data(), jacobian.data());
  for (long j = 0; j < n; ++j) {
    for (int c = 0; c < c_count; ++c) {
      const long i = j * c_count + c;
      (*values)[j] += 0.5 * residuals[i] * residuals[i];
      gradients->row(j) += residuals[i] * jacobian.row(i);
    }
  }
  if (hessian == nullptr) return;
  // J^T J at the problem's precision, as GaussNewtonHessian.
  if (options_.precision == Precision::kFloat) {
    *hessian += GramOfJacobian(Eigen::MatrixXf(jacobian.cast<float>()));
  } else {
    *hessian += GramOfJacobian(jacobian);
  }
}

void LatentProblem::GaussNewtonHessian(const Eigen::VectorXd& z, Eigen::MatrixXd* hessian) const {
  CheckLatent(z, "GaussNewtonHessian");
  const int d = dim();
  const int c_count = channels();
  hessian->setIdentity(d, d);
  *hessian /= options_.sigma_z * options_.sigma_z;
  if (num_pixels() == 0) return;
  if (options_.robust_loss != RobustLoss::kNone) {
    Eigen::VectorXd residuals(num_residuals());
    RowMajorMatrixXd jacobian(num_residuals(), d);
    ResidualsAndJacobian(z.data(), residuals.data(), jacobian.data());
    *hessian += GramOfJacobian(jacobian);
    return;
  }
  // Rows j*C + c of J scaled by sqrt(w_j) / sigma, then J^T J by SYRK, in Scalar.
  auto accumulate = [&](auto tag) {
    using Scalar = decltype(tag);
    using Matrix = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;
    const Matrix* coords;
    if constexpr (std::is_same<Scalar, float>::value) {
      coords = &coords_float_;
    } else {
      coords = &coords_;
    }
    const Eigen::Matrix<Scalar, Eigen::Dynamic, 1> zs = z.cast<Scalar>();
    Matrix J;
    trunk_->siren.template ForwardAndLatentJacobian<Scalar>(*coords, zs, nullptr, &J);
    for (long j = 0; j < num_pixels(); ++j) {
      J.middleRows(j * c_count, c_count) *= static_cast<Scalar>(std::sqrt(weights_[j]) / sigma_);
    }
    *hessian += GramOfJacobian(J);
  };
  if (options_.precision == Precision::kFloat) {
    accumulate(float());
  } else {
    accumulate(double());
  }
}

// ---- Meta-SGD and PSNR ----------------------------------------------------------------------

Eigen::VectorXd LatentProblem::MetaSgdSteps(const Eigen::VectorXd& z0, int steps,
                                            double* start_cost,
                                            std::optional<double>* start_psnr,
                                            const StartPass* start) const {
  CheckLatent(z0, "MetaSgdSteps");
  if (start_cost != nullptr && start_psnr == nullptr) {
    throw std::invalid_argument("LatentProblem::MetaSgdSteps: start_psnr must not be null "
                                "when start_cost is asked for");
  }
  const MetaSgd meta_sgd(trunk_->meta_sgd);
  Eigen::VectorXd z;
  Eigen::MatrixXd outputs;
  if (start != nullptr && CanUse(*start) && steps >= 1 && z0.isZero(0.0)) {
    // The first step at z = 0: dL/dz = J_0 v with v_{j,c} = s w_j (y_{j,c} - t_{j,c}) on
    // the selected pixels, s = 2 / (C sum w) -- the trunk's weighted MSE, normalised as
    // its own passes normalise it -- and the latent penalty's gradient 2 lambda z = 0.
    const int c_count = channels();
    float scale = 0;
    LatentModulatedSiren::MseNormaliser<float>(weights_float_, num_pixels(), c_count, &scale);
    Eigen::VectorXf v = Eigen::VectorXf::Zero(start->jacobian.cols());
    if (scale != 0.0f) {
      for (long j = 0; j < num_pixels(); ++j) {
        const float w = weights_float_[j];
        if (w == 0.0f) continue;
        for (int c = 0; c < c_count; ++c) {
          const float r = start->outputs(pixel_index_[j], c) - targets_float_(j, c);
          v[static_cast<long>(pixel_index_[j]) * c_count + c] = scale * (w * r);
        }
      }
    }
    const Eigen::VectorXf gradient = start->jacobian * v;
    const Eigen::VectorXf z1 = -trunk_->alpha.cast<float>().cwiseProduct(gradient);
    z = meta_sgd
            .InnerLoop<float>(trunk_->siren, coords_float_, targets_float_, weights_float_,
                              trunk_->alpha.cast<float>(), z1, steps - 1)
            .cast<double>();
    if (start_cost != nullptr) *start_cost = DataCostAtStart(*start, start_psnr);
    return z;
  }
  if (options_.precision == Precision::kFloat) {
    Eigen::MatrixXf start_outputs;
    z = meta_sgd
            .InnerLoop<float>(trunk_->siren, coords_float_, targets_float_, weights_float_,
                              trunk_->alpha.cast<float>(), z0.cast<float>(), steps,
                              start_cost != nullptr ? &start_outputs : nullptr)
            .cast<double>();
    if (start_cost != nullptr) outputs = start_outputs.cast<double>();
  } else {
    z = meta_sgd.InnerLoop<double>(trunk_->siren, coords_, pixel_targets_,
                                   weights_float_.cast<double>(), trunk_->alpha, z0, steps,
                                   start_cost != nullptr ? &outputs : nullptr);
  }
  if (start_cost != nullptr) {
    *start_cost = DataCostOfOutputs(outputs, start_psnr);
  }
  return z;
}

Eigen::VectorXd LatentProblem::StartLatent() const {
  return trunk_->siren.StartLatent<double>(coords_, pixel_targets_,
                                           weights_float_.cast<double>());
}

// The trunk's output over the whole frame at the problem's precision, as floats (the
// PSNR's convention).
Eigen::MatrixXf LatentProblem::FramePrediction(const Eigen::VectorXd& z) const {
  const LatentModulatedSiren& siren = trunk_->siren;
  if (options_.precision == Precision::kFloat) {
    return siren.Forward<float>(siren.Grid<float>(frame_->rows, frame_->cols), z.cast<float>());
  }
  return siren.Forward<double>(siren.Grid<double>(frame_->rows, frame_->cols), z).cast<float>();
}

double LatentProblem::Psnr(const Eigen::VectorXd& z) const {
  CheckLatent(z, "Psnr");
  const double psnr = tactfunc::Psnr(FramePrediction(z), *frame_);  // +inf if exact
  return std::isnan(psnr) ? 0.0 : psnr;
}

double LatentProblem::DataCost(const Eigen::VectorXd& z, std::optional<double>* psnr) const {
  CheckLatent(z, "DataCost");
  const LatentModulatedSiren& siren = trunk_->siren;
  if (options_.precision == Precision::kFloat) {
    return DataCostOfOutputs(siren.Forward<float>(coords_float_, z.cast<float>()).cast<double>(),
                             psnr);
  }
  return DataCostOfOutputs(siren.Forward<double>(coords_, z), psnr);
}

double LatentProblem::DataCostOfOutputs(const Eigen::MatrixXd& outputs,
                                        std::optional<double>* psnr) const {
  const int c_count = channels();
  const long n = num_pixels();
  Eigen::VectorXd residuals(n * c_count);
  for (long i = 0; i < n; ++i) {
    for (int c = 0; c < c_count; ++c) {
      const long k = i * c_count + c;
      residuals[k] = residual_scale_[k] * (outputs(i, c) - pixel_targets_(i, c));
    }
  }
  Robustify(static_cast<int>(residuals.size()), residuals.data(), nullptr, 0);
  psnr->reset();
  if (n == num_valid_pixels_) {
    // The PSNR reads valid pixels only (estimation/data/trunk_targets.h), which are the
    // selected ones here; the others' predictions are never read.
    Eigen::MatrixXf prediction = Eigen::MatrixXf::Zero(frame_->values.rows(), c_count);
    for (long i = 0; i < n; ++i) {
      prediction.row(pixel_index_[i]) = outputs.row(i).cast<float>();
    }
    const double frame_psnr = tactfunc::Psnr(prediction, *frame_);
    *psnr = std::isnan(frame_psnr) ? 0.0 : frame_psnr;
  }
  return 0.5 * residuals.squaredNorm();
}

}  // namespace tactfunc
