// Copyright 2026 The tactfunc Authors.
#include "models/pose/pose_mlp.h"

#include <algorithm>
#include <boost/random/mersenne_twister.hpp>
#include <boost/random/normal_distribution.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <utility>
#include <vector>

#include "models/core/atomic_file.h"
#include "models/core/internal/checks.h"
#include "models/core/tensor_file.h"
#include "nlohmann/json.hpp"

namespace tactfunc {
namespace {

constexpr const char* kFormat = "tactfunc-pose-model";
constexpr int kVersion = 1;
constexpr const char* kKind = "pose_model";

using internal::Check;
using internal::Num;

std::string Shape(long rows, long cols) {
  return std::to_string(rows) + " x " + std::to_string(cols);
}

std::vector<double> ToVector(const Eigen::VectorXf& v) {
  return std::vector<double>(v.data(), v.data() + v.size());
}

}  // namespace

// ---- Options ----------------------------------------------------------------------

bool PoseMlp::Options::IsValid(std::string* error) const {
  std::string message;
  if (input_dim < 1) {
    message = "PoseMlp::Options.input_dim must be >= 1, got " + std::to_string(input_dim);
  } else if (!(position_scale > 0) || !std::isfinite(position_scale)) {
    message = "PoseMlp::Options.position_scale must be finite and > 0 (metres), got " +
              Num(position_scale);
  } else {
    for (std::size_t l = 0; l < hidden_sizes.size(); ++l) {
      if (hidden_sizes[l] < 1) {
        message = "PoseMlp::Options.hidden_sizes[" + std::to_string(l) + "] must be >= 1, got " +
                  std::to_string(hidden_sizes[l]);
        break;
      }
    }
  }
  if (error != nullptr) *error = message;
  return message.empty();
}

bool PoseMlpTrainingOptions::IsValid(std::string* error) const {
  std::string message;
  if (epochs < 1) {
    message = "PoseMlpTrainingOptions.epochs must be >= 1, got " + std::to_string(epochs);
  } else if (batch_size < 1) {
    message = "PoseMlpTrainingOptions.batch_size must be >= 1, got " + std::to_string(batch_size);
  } else if (!(learning_rate > 0) || !std::isfinite(learning_rate)) {
    message =
        "PoseMlpTrainingOptions.learning_rate must be finite and > 0, got " + Num(learning_rate);
  } else if (!(beta1 >= 0 && beta1 < 1)) {
    message = "PoseMlpTrainingOptions.beta1 must be in [0, 1), got " + Num(beta1);
  } else if (!(beta2 >= 0 && beta2 < 1)) {
    message = "PoseMlpTrainingOptions.beta2 must be in [0, 1), got " + Num(beta2);
  } else if (!(epsilon > 0) || !std::isfinite(epsilon)) {
    message = "PoseMlpTrainingOptions.epsilon must be finite and > 0, got " + Num(epsilon);
  } else if (!(weight_decay >= 0) || !std::isfinite(weight_decay)) {
    message =
        "PoseMlpTrainingOptions.weight_decay must be finite and >= 0, got " + Num(weight_decay);
  } else if (!(yaw_loss_weight >= 0) || !std::isfinite(yaw_loss_weight)) {
    message = "PoseMlpTrainingOptions.yaw_loss_weight must be finite and >= 0, got " +
              Num(yaw_loss_weight);
  }
  if (error != nullptr) *error = message;
  return message.empty();
}

// ---- Construction -----------------------------------------------------------------

PoseMlp::PoseMlp(const Options& options, std::uint64_t seed) : options_(options) {
  std::string error;
  Check(options_.IsValid(&error), error);
  std::vector<int> outs = options_.hidden_sizes;
  outs.push_back(kOutputDim);
  int offset = 0;
  layers_ = DenseLayerLayout(options_.input_dim, outs, &offset);
  parameters_ = Eigen::VectorXf::Zero(offset);
  input_mean_ = Eigen::VectorXf::Zero(options_.input_dim);
  input_stddev_ = Eigen::VectorXf::Ones(options_.input_dim);
  Initialize(seed);
}

void PoseMlp::Initialize(std::uint64_t seed) {
  boost::random::mt19937_64 rng(seed);
  parameters_.setZero();
  for (std::size_t l = 0; l < layers_.size(); ++l) {
    const Layer& layer = layers_[l];
    const bool is_output = l + 1 == layers_.size();
    // He for ReLU layers (gain 2), LeCun for the linear output (gain 1).
    const double stddev = std::sqrt((is_output ? 1.0 : 2.0) / layer.in);
    boost::random::normal_distribution<double> normal(0.0, stddev);
    for (int k = 0; k < layer.in * layer.out; ++k) {
      parameters_[layer.weight_offset + k] = static_cast<float>(normal(rng));
    }
  }
}

void PoseMlp::SetParameters(const Eigen::VectorXf& parameters) {
  Check(parameters.size() == parameters_.size(),
        "PoseMlp::SetParameters: expected " + std::to_string(parameters_.size()) +
            " parameters, got " + std::to_string(parameters.size()));
  parameters_ = parameters;
}

void PoseMlp::SetInputStandardization(const Eigen::VectorXf& mean, const Eigen::VectorXf& stddev) {
  const int d = options_.input_dim;
  Check(mean.size() == d && stddev.size() == d,
        "PoseMlp::SetInputStandardization: expected mean and stddev of size " + std::to_string(d) +
            ", got " + std::to_string(mean.size()) + " and " + std::to_string(stddev.size()));
  Check(mean.allFinite(), "PoseMlp::SetInputStandardization: the mean must be finite");
  Check(stddev.allFinite() && (stddev.array() > 0).all(),
        "PoseMlp::SetInputStandardization: every stddev must be finite and > 0");
  input_mean_ = mean;
  input_stddev_ = stddev;
}

void PoseMlp::CheckInputs(int rows, int cols, const char* what) const {
  Check(cols == options_.input_dim, std::string("PoseMlp::") + what + ": expected inputs N x " +
                                        std::to_string(options_.input_dim) + ", got " +
                                        Shape(rows, cols));
}

// ---- Passes -----------------------------------------------------------------------

template <typename Scalar>
PoseMlp::MatrixX<Scalar> PoseMlp::Standardize(const MatrixX<Scalar>& inputs) const {
  const VectorX<Scalar> mean = input_mean_.cast<Scalar>();
  const VectorX<Scalar> inv_std = input_stddev_.cast<Scalar>().cwiseInverse();
  return ((inputs.rowwise() - mean.transpose()).array().rowwise() * inv_std.transpose().array())
      .matrix();
}

template <typename Scalar>
PoseMlp::MatrixX<Scalar> PoseMlp::ForwardKeep(const Scalar* p, const MatrixX<Scalar>& inputs,
                                              std::vector<MatrixX<Scalar>>* activations) const {
  MatrixX<Scalar> h = Standardize(inputs);
  if (activations != nullptr) activations->clear();
  for (std::size_t l = 0; l < layers_.size(); ++l) {
    const Layer& layer = layers_[l];
    const Eigen::Map<const MatrixX<Scalar>> w(p + layer.weight_offset, layer.out, layer.in);
    const Eigen::Map<const VectorX<Scalar>> b(p + layer.bias_offset, layer.out);
    MatrixX<Scalar> z = h * w.transpose();  // N x out
    z.rowwise() += b.transpose();
    if (activations != nullptr) activations->push_back(std::move(h));
    if (l + 1 == layers_.size()) return z;
    h = z.cwiseMax(Scalar(0));
  }
  return h;  // unreachable: there is always an output layer
}

template <typename Scalar>
void PoseMlp::BackwardFrom(const Scalar* p, const std::vector<MatrixX<Scalar>>& activations,
                           const MatrixX<Scalar>& d_outputs, VectorX<Scalar>* d_parameters,
                           MatrixX<Scalar>* d_inputs) const {
  if (d_parameters != nullptr) d_parameters->setZero(parameters_.size());
  MatrixX<Scalar> g = d_outputs;  // dL/dz_l, N x out
  for (int l = static_cast<int>(layers_.size()) - 1; l >= 0; --l) {
    const Layer& layer = layers_[l];
    const MatrixX<Scalar>& h = activations[l];  // N x in
    if (d_parameters != nullptr) {
      Eigen::Map<MatrixX<Scalar>>(d_parameters->data() + layer.weight_offset, layer.out, layer.in)
          .noalias() = g.transpose() * h;
      Eigen::Map<VectorX<Scalar>>(d_parameters->data() + layer.bias_offset, layer.out) =
          g.colwise().sum().transpose();
    }
    if (l == 0 && d_inputs == nullptr) break;
    const Eigen::Map<const MatrixX<Scalar>> w(p + layer.weight_offset, layer.out, layer.in);
    MatrixX<Scalar> dh = g * w;  // N x in
    if (l > 0) {
      // h = relu(z_{l-1}): pass the gradient where h > 0 (ReLU'(0) = 0).
      g = (h.array() > Scalar(0)).select(dh.array(), Scalar(0)).matrix();
    } else {
      const VectorX<Scalar> inv_std = input_stddev_.cast<Scalar>().cwiseInverse();
      *d_inputs = (dh.array().rowwise() * inv_std.transpose().array()).matrix();
    }
  }
}

template <typename Scalar>
PoseMlp::MatrixX<Scalar> PoseMlp::Forward(const MatrixX<Scalar>& inputs) const {
  CheckInputs(static_cast<int>(inputs.rows()), static_cast<int>(inputs.cols()), "Forward");
  if constexpr (std::is_same_v<Scalar, float>) {
    return ForwardKeep<Scalar>(parameters_.data(), inputs, nullptr);
  } else {
    const VectorX<Scalar> p = parameters_.cast<Scalar>();
    return ForwardKeep<Scalar>(p.data(), inputs, nullptr);
  }
}

template <typename Scalar>
PoseMlp::MatrixX<Scalar> PoseMlp::Forward(const VectorX<Scalar>& parameters,
                                          const MatrixX<Scalar>& inputs) const {
  CheckInputs(static_cast<int>(inputs.rows()), static_cast<int>(inputs.cols()), "Forward");
  Check(parameters.size() == parameters_.size(),
        "PoseMlp::Forward: expected " + std::to_string(parameters_.size()) + " parameters, got " +
            std::to_string(parameters.size()));
  return ForwardKeep<Scalar>(parameters.data(), inputs, nullptr);
}

template <typename Scalar>
void PoseMlp::Backward(const VectorX<Scalar>& parameters, const MatrixX<Scalar>& inputs,
                       const MatrixX<Scalar>& d_outputs, VectorX<Scalar>* d_parameters,
                       MatrixX<Scalar>* d_inputs) const {
  CheckInputs(static_cast<int>(inputs.rows()), static_cast<int>(inputs.cols()), "Backward");
  Check(parameters.size() == parameters_.size(),
        "PoseMlp::Backward: expected " + std::to_string(parameters_.size()) + " parameters, got " +
            std::to_string(parameters.size()));
  Check(d_outputs.rows() == inputs.rows() && d_outputs.cols() == kOutputDim,
        "PoseMlp::Backward: expected d_outputs " + Shape(inputs.rows(), kOutputDim) + ", got " +
            Shape(d_outputs.rows(), d_outputs.cols()));
  std::vector<MatrixX<Scalar>> activations;
  ForwardKeep<Scalar>(parameters.data(), inputs, &activations);
  BackwardFrom<Scalar>(parameters.data(), activations, d_outputs, d_parameters, d_inputs);
}

template <typename Scalar>
void PoseMlp::Backward(const MatrixX<Scalar>& inputs, const MatrixX<Scalar>& d_outputs,
                       VectorX<Scalar>* d_parameters, MatrixX<Scalar>* d_inputs) const {
  Backward<Scalar>(VectorX<Scalar>(parameters_.cast<Scalar>()), inputs, d_outputs, d_parameters,
                   d_inputs);
}

Eigen::MatrixXd PoseMlp::InputJacobian(const Eigen::VectorXd& z) const {
  Check(z.size() == options_.input_dim, "PoseMlp::InputJacobian: expected a latent of size " +
                                            std::to_string(options_.input_dim) + ", got " +
                                            std::to_string(z.size()));
  // Four copies of z with d_outputs = I: row k of d_inputs is d o_k / d z.
  const Eigen::MatrixXd inputs = z.transpose().replicate(kOutputDim, 1);
  Eigen::MatrixXd jacobian;
  Backward<double>(inputs, Eigen::MatrixXd::Identity(kOutputDim, kOutputDim), nullptr, &jacobian);
  return jacobian;
}

// ---- Poses ------------------------------------------------------------------------

SE2d PoseMlp::Predict(const Eigen::VectorXd& z, int symmetry_order,
                      Eigen::MatrixXd* J_xyyaw_z) const {
  Check(symmetry_order >= 0,
        "PoseMlp::Predict: symmetry order must be >= 0, got " + std::to_string(symmetry_order));
  Check(z.size() == options_.input_dim, "PoseMlp::Predict: expected a latent of size " +
                                            std::to_string(options_.input_dim) + ", got " +
                                            std::to_string(z.size()));
  const Eigen::MatrixXd o = Forward<double>(Eigen::MatrixXd(z.transpose()));
  const double s = options_.position_scale;
  const double c = o(0, 2), sn = o(0, 3);
  const double yaw = symmetry_order >= 1 ? std::atan2(sn, c) / symmetry_order : 0.0;
  if (J_xyyaw_z != nullptr) {
    const Eigen::MatrixXd j = InputJacobian(z);
    J_xyyaw_z->resize(3, options_.input_dim);
    J_xyyaw_z->row(0) = s * j.row(0);
    J_xyyaw_z->row(1) = s * j.row(1);
    const double r2 = c * c + sn * sn;
    if (symmetry_order >= 1 && r2 > 0) {
      J_xyyaw_z->row(2) = (c * j.row(3) - sn * j.row(2)) / (r2 * symmetry_order);
    } else {
      J_xyyaw_z->row(2).setZero();
    }
  }
  return SE2d::FromXYYaw(s * o(0, 0), s * o(0, 1), yaw);
}

std::vector<SE2d> PoseMlp::PredictBatch(const Eigen::MatrixXf& inputs,
                                        int symmetry_order) const {
  Check(symmetry_order >= 0, "PoseMlp::PredictBatch: symmetry order must be >= 0, got " +
                                 std::to_string(symmetry_order));
  const Eigen::MatrixXf o = Forward<float>(inputs);
  std::vector<SE2d> poses;
  poses.reserve(static_cast<std::size_t>(o.rows()));
  const double s = options_.position_scale;
  for (Eigen::Index i = 0; i < o.rows(); ++i) {
    const double yaw =
        symmetry_order >= 1 ? std::atan2(double(o(i, 3)), double(o(i, 2))) / symmetry_order : 0.0;
    poses.push_back(SE2d::FromXYYaw(s * o(i, 0), s * o(i, 1), yaw));
  }
  return poses;
}

// ---- Loss -------------------------------------------------------------------------

Eigen::MatrixXf PoseMlp::EncodeTargets(const PoseTargets& targets,
                                       Eigen::VectorXf* yaw_mask) const {
  const Eigen::Index m = targets.poses.rows();
  Check(targets.poses.cols() == 3,
        "PoseMlp: expected target poses M x 3 (x, y, yaw), got " + Shape(m, targets.poses.cols()));
  Check(targets.poses.allFinite(), "PoseMlp: the target poses must be finite");
  Check(targets.symmetry_orders.size() == 0 || targets.symmetry_orders.size() == m,
        "PoseMlp: expected " + std::to_string(m) + " symmetry orders (or none), got " +
            std::to_string(targets.symmetry_orders.size()));
  Eigen::MatrixXf encoded(m, kOutputDim);
  if (yaw_mask != nullptr) yaw_mask->resize(m);
  const double s = options_.position_scale;
  for (Eigen::Index i = 0; i < m; ++i) {
    const int n = targets.symmetry_orders.size() == 0 ? 1 : targets.symmetry_orders[i];
    Check(n >= 0, "PoseMlp: symmetry order of target " + std::to_string(i) + " must be >= 0, got " +
                      std::to_string(n));
    const double yaw = targets.poses(i, 2);
    encoded(i, 0) = static_cast<float>(targets.poses(i, 0) / s);
    encoded(i, 1) = static_cast<float>(targets.poses(i, 1) / s);
    encoded(i, 2) = n == 0 ? 0.0f : static_cast<float>(std::cos(n * yaw));
    encoded(i, 3) = n == 0 ? 0.0f : static_cast<float>(std::sin(n * yaw));
    if (yaw_mask != nullptr) (*yaw_mask)[i] = n == 0 ? 0.0f : 1.0f;
  }
  return encoded;
}

namespace {

// Loss and dL/do for outputs N x 4 against encoded targets and the yaw mask.
template <typename Scalar>
double EncodedLoss(const Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>& outputs,
                   const Eigen::MatrixXf& encoded, const Eigen::VectorXf& yaw_mask,
                   double yaw_loss_weight,
                   Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>* d_outputs) {
  const Eigen::Index n = outputs.rows();
  if (n == 0) {
    if (d_outputs != nullptr) d_outputs->resize(0, PoseMlp::kOutputDim);
    return 0.0;
  }
  Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic> r = outputs - encoded.cast<Scalar>();
  const Eigen::Matrix<Scalar, Eigen::Dynamic, 1> yaw_w =
      yaw_mask.cast<Scalar>() * static_cast<Scalar>(yaw_loss_weight);
  r.col(2).array() *= yaw_w.array().sqrt();
  r.col(3).array() *= yaw_w.array().sqrt();
  const double loss = static_cast<double>(r.squaredNorm()) / n;
  if (d_outputs != nullptr) {
    *d_outputs = r * static_cast<Scalar>(2.0 / n);
    d_outputs->col(2).array() *= yaw_w.array().sqrt();
    d_outputs->col(3).array() *= yaw_w.array().sqrt();
  }
  return loss;
}

}  // namespace

template <typename Scalar>
double PoseMlp::Loss(const MatrixX<Scalar>& outputs, const PoseTargets& targets,
                     double yaw_loss_weight, MatrixX<Scalar>* d_outputs) const {
  Eigen::VectorXf mask;
  const Eigen::MatrixXf encoded = EncodeTargets(targets, &mask);
  Check(outputs.rows() == encoded.rows() && outputs.cols() == kOutputDim,
        "PoseMlp::Loss: expected outputs " + Shape(encoded.rows(), kOutputDim) + ", got " +
            Shape(outputs.rows(), outputs.cols()));
  return EncodedLoss<Scalar>(outputs, encoded, mask, yaw_loss_weight, d_outputs);
}

// ---- Files ------------------------------------------------------------------------

void PoseMlp::set_info_json(const std::string& json) {
  nlohmann::json parsed;
  try {
    parsed = nlohmann::json::parse(json);
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(std::string("PoseMlp info is not JSON: ") + e.what());
  }
  Check(parsed.is_object(), "PoseMlp info must be a JSON object");
  info_json_ = parsed.dump();
}

void PoseMlp::SetCalibrationResiduals(const Eigen::MatrixXd& residuals) {
  Check(residuals.cols() == 3 && residuals.allFinite(),
        "PoseMlp::SetCalibrationResiduals: expected R x 3 finite residuals (x m, y m, yaw "
        "rad), got " + std::to_string(residuals.rows()) + " x " +
            std::to_string(residuals.cols()) + (residuals.allFinite() ? "" : " with non-finite values"));
  calibration_residuals_ = residuals;
}

std::string PoseMlp::Serialize() const {
  TensorFile file(kKind);
  nlohmann::json meta;
  meta["format"] = kFormat;
  meta["version"] = kVersion;
  meta["input_dim"] = options_.input_dim;
  meta["hidden_sizes"] = options_.hidden_sizes;
  meta["position_scale"] = options_.position_scale;
  meta["outputs"] = "x/s, y/s, cos(n yaw), sin(n yaw)";
  meta["info"] = nlohmann::json::parse(info_json_);
  file.set_meta_json(meta.dump());
  file.Add("parameters", TensorFile::DType::kFloat32, {parameters_.size()}, ToVector(parameters_));
  file.Add("input_mean", TensorFile::DType::kFloat32, {input_mean_.size()}, ToVector(input_mean_));
  file.Add("input_stddev", TensorFile::DType::kFloat32, {input_stddev_.size()},
           ToVector(input_stddev_));
  if (calibration_residuals_.rows() > 0) {
    const Eigen::Matrix<double, Eigen::Dynamic, 3, Eigen::RowMajor> rows = calibration_residuals_;
    file.Add("calibration_residuals", TensorFile::DType::kFloat64,
             {rows.rows(), 3}, std::vector<double>(rows.data(), rows.data() + rows.size()));
  }
  return file.Serialize();
}

void PoseMlp::Save(const std::string& path) const { WriteFileAtomically(path, Serialize()); }

namespace {

PoseMlp FromTensorFile(const TensorFile& file, const std::string& source) {
  file.CheckFormat(kFormat, kVersion);
  std::string field = "meta";
  try {
    const nlohmann::json meta = nlohmann::json::parse(file.meta_json());
    PoseMlp::Options options;
    field = "input_dim";
    options.input_dim = meta.at("input_dim").get<int>();
    field = "hidden_sizes";
    options.hidden_sizes = meta.at("hidden_sizes").get<std::vector<int>>();
    field = "position_scale";
    options.position_scale = meta.at("position_scale").get<double>();
    std::string error;
    if (!options.IsValid(&error)) throw TensorFileError(source + ": " + error);
    PoseMlp model(options);
    field = "info";
    const nlohmann::json& info = meta.at("info");
    if (!info.is_object()) throw TensorFileError(source + ": field 'info' must be an object");
    model.set_info_json(info.dump());

    auto read = [&](const std::string& name, Eigen::Index size) {
      const TensorFile::Tensor& t = file.Get(name, {static_cast<std::int64_t>(size)});
      Eigen::VectorXf v(size);
      for (Eigen::Index k = 0; k < size; ++k) v[k] = static_cast<float>(t.values[k]);
      if (!v.allFinite()) {
        throw TensorFileError(source + ": tensor '" + name + "' holds non-finite values");
      }
      return v;
    };
    model.SetParameters(read("parameters", model.NumParameters()));
    const Eigen::VectorXf mean = read("input_mean", options.input_dim);
    const Eigen::VectorXf stddev = read("input_stddev", options.input_dim);
    if (!(stddev.array() > 0).all()) {
      throw TensorFileError(source + ": tensor 'input_stddev' must be > 0 everywhere");
    }
    model.SetInputStandardization(mean, stddev);
    if (file.Has("calibration_residuals")) {
      const TensorFile::Tensor& t = file.Get("calibration_residuals");
      if (t.shape.size() != 2 || t.shape[1] != 3) {
        throw TensorFileError(source + ": tensor 'calibration_residuals': expected shape R x 3");
      }
      Eigen::MatrixXd residuals(t.shape[0], 3);
      for (Eigen::Index r = 0; r < residuals.rows(); ++r) {
        for (int c = 0; c < 3; ++c) residuals(r, c) = t.values[r * 3 + c];
      }
      if (!residuals.allFinite()) {
        throw TensorFileError(source + ": tensor 'calibration_residuals' holds non-finite values");
      }
      model.SetCalibrationResiduals(residuals);
    }
    return model;
  } catch (const nlohmann::json::exception& e) {
    throw TensorFileError(source + ": field '" + field + "' is missing or has the wrong type (" +
                          e.what() + ")");
  }
}

}  // namespace

PoseMlp PoseMlp::Parse(const std::string& bytes, const std::string& source) {
  return FromTensorFile(TensorFile::Parse(bytes, source, kKind), source);
}

PoseMlp PoseMlp::Load(const std::string& path) {
  return FromTensorFile(TensorFile::Read(path, kKind), path);
}

// ---- Training ---------------------------------------------------------------------

const char* ToString(PoseMlpTrainingTermination termination) {
  switch (termination) {
    case PoseMlpTrainingTermination::kCompleted:
      return "COMPLETED";
    case PoseMlpTrainingTermination::kUserRequested:
      return "USER_REQUESTED";
    case PoseMlpTrainingTermination::kNonFinite:
      return "NON_FINITE";
  }
  return "UNKNOWN";
}

std::string PoseMlpTrainingSummary::BriefReport() const {
  return std::string("TrainPoseMlp: ") + ToString(termination) + ", " +
         std::to_string(epochs_completed) + " epochs, loss " + Num(initial_loss) + " -> " +
         Num(final_loss) + " (" + Num(total_time_in_seconds) + " s)" +
         (message.empty() ? "" : ": " + message);
}

std::string PoseMlpTrainingSummary::FullReport() const {
  std::ostringstream out;
  out << BriefReport() << "\nepoch  mean minibatch loss\n";
  for (std::size_t e = 0; e < loss_history.size(); ++e) {
    out << e << "  " << Num(loss_history[e]) << "\n";
  }
  return out.str();
}

struct PoseMlpTrainerAccess {
  static double FullLoss(const PoseMlp& model, const Eigen::MatrixXf& inputs,
                         const Eigen::MatrixXf& encoded, const Eigen::VectorXf& mask,
                         double yaw_loss_weight) {
    constexpr Eigen::Index kChunk = 4096;
    const Eigen::Index m = inputs.rows();
    double total = 0;
    for (Eigen::Index start = 0; start < m; start += kChunk) {
      const Eigen::Index rows = std::min(kChunk, m - start);
      const Eigen::MatrixXf o = model.ForwardKeep<float>(
          model.parameters_.data(), Eigen::MatrixXf(inputs.middleRows(start, rows)), nullptr);
      total += EncodedLoss<float>(o, encoded.middleRows(start, rows), mask.segment(start, rows),
                                  yaw_loss_weight, nullptr) *
               rows;
    }
    return m == 0 ? 0.0 : total / m;
  }

  static PoseMlpTrainingSummary Train(PoseMlp* model, const Eigen::MatrixXf& inputs,
                                      const PoseTargets& targets,
                                      const PoseMlpTrainingOptions& options,
                                      const PoseMlpProgressCallback& progress) {
    const auto start_time = std::chrono::steady_clock::now();
    Check(model != nullptr, "TrainPoseMlp: model is null");
    std::string error;
    Check(options.IsValid(&error), error);
    model->CheckInputs(static_cast<int>(inputs.rows()), static_cast<int>(inputs.cols()),
                       "TrainPoseMlp");
    Check(targets.poses.rows() == inputs.rows(),
          "TrainPoseMlp: expected " + std::to_string(inputs.rows()) +
              " target rows (one per input), got " + std::to_string(targets.poses.rows()));
    Check(inputs.rows() > 0, "TrainPoseMlp: expected at least one training sample, got none");
    Check(inputs.allFinite(), "TrainPoseMlp: the inputs must be finite");
    Eigen::VectorXf mask;
    const Eigen::MatrixXf encoded = model->EncodeTargets(targets, &mask);
    const Eigen::Index m = inputs.rows();

    if (options.standardize_inputs) {
      const Eigen::VectorXd mean = inputs.cast<double>().colwise().mean().transpose();
      Eigen::VectorXd stddev =
          ((inputs.cast<double>().rowwise() - mean.transpose()).colwise().squaredNorm() /
           static_cast<double>(m))
              .cwiseSqrt()
              .transpose();
      for (Eigen::Index k = 0; k < stddev.size(); ++k) {
        if (!(stddev[k] >= 1e-6)) stddev[k] = 1.0;
      }
      model->SetInputStandardization(mean.cast<float>(), stddev.cast<float>());
    }

    PoseMlpTrainingSummary summary;
    summary.initial_loss = FullLoss(*model, inputs, encoded, mask, options.yaw_loss_weight);

    const Eigen::Index p = model->parameters_.size();
    Eigen::VectorXf m1 = Eigen::VectorXf::Zero(p), m2 = Eigen::VectorXf::Zero(p);
    // Decay mask: 1 on weight matrices, 0 on biases.
    Eigen::VectorXf decay = Eigen::VectorXf::Zero(p);
    for (const PoseMlp::Layer& layer : model->layers_) {
      decay.segment(layer.weight_offset, layer.in * layer.out).setOnes();
    }
    std::vector<int> order(static_cast<std::size_t>(m));
    std::iota(order.begin(), order.end(), 0);
    boost::random::mt19937_64 rng(options.seed);
    std::vector<Eigen::MatrixXf> activations;
    Eigen::VectorXf gradient;
    Eigen::VectorXf last_good = model->parameters_;
    long long step = 0;
    const int b = options.batch_size;
    Eigen::MatrixXf batch_inputs, batch_targets, d_outputs;
    Eigen::VectorXf batch_mask;
    summary.termination = PoseMlpTrainingTermination::kCompleted;
    for (int epoch = 0; epoch < options.epochs; ++epoch) {
      // Fisher-Yates with our own generator (std::shuffle's use of it is unspecified).
      for (std::size_t i = order.size(); i > 1; --i) {
        const std::size_t j = static_cast<std::size_t>(rng() % i);
        std::swap(order[i - 1], order[j]);
      }
      double epoch_loss = 0;
      for (Eigen::Index start = 0; start < m; start += b) {
        const Eigen::Index rows = std::min<Eigen::Index>(b, m - start);
        batch_inputs.resize(rows, inputs.cols());
        batch_targets.resize(rows, PoseMlp::kOutputDim);
        batch_mask.resize(rows);
        for (Eigen::Index r = 0; r < rows; ++r) {
          const int i = order[static_cast<std::size_t>(start + r)];
          batch_inputs.row(r) = inputs.row(i);
          batch_targets.row(r) = encoded.row(i);
          batch_mask[r] = mask[i];
        }
        const Eigen::MatrixXf o =
            model->ForwardKeep<float>(model->parameters_.data(), batch_inputs, &activations);
        const double loss =
            EncodedLoss<float>(o, batch_targets, batch_mask, options.yaw_loss_weight, &d_outputs);
        epoch_loss += loss * rows;
        model->BackwardFrom<float>(model->parameters_.data(), activations, d_outputs, &gradient,
                                   nullptr);
        ++step;
        const float b1 = static_cast<float>(options.beta1), b2 = static_cast<float>(options.beta2);
        m1 = b1 * m1 + (1 - b1) * gradient;
        m2 = b2 * m2 + (1 - b2) * gradient.cwiseAbs2();
        const double c1 = 1 - std::pow(options.beta1, static_cast<double>(step));
        const double c2 = 1 - std::pow(options.beta2, static_cast<double>(step));
        const float lr = static_cast<float>(options.learning_rate);
        const float eps = static_cast<float>(options.epsilon);
        model->parameters_.array() -=
            lr *
            ((m1.array() / static_cast<float>(c1)) /
                 ((m2.array() / static_cast<float>(c2)).sqrt() + eps) +
             static_cast<float>(options.weight_decay) * decay.array() * model->parameters_.array());
      }
      epoch_loss /= static_cast<double>(m);
      if (!std::isfinite(epoch_loss) || !model->parameters_.allFinite()) {
        model->parameters_ = last_good;
        summary.termination = PoseMlpTrainingTermination::kNonFinite;
        summary.message = "the loss became non-finite in epoch " + std::to_string(epoch) +
                          "; parameters restored to the end of the previous epoch (lower the "
                          "learning rate)";
        break;
      }
      last_good = model->parameters_;
      summary.loss_history.push_back(epoch_loss);
      summary.epochs_completed = epoch + 1;
      if (progress && !progress(epoch, epoch_loss)) {
        summary.termination = PoseMlpTrainingTermination::kUserRequested;
        summary.message = "stopped by the progress callback after epoch " + std::to_string(epoch);
        break;
      }
    }
    summary.final_loss = FullLoss(*model, inputs, encoded, mask, options.yaw_loss_weight);
    summary.total_time_in_seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start_time).count();
    return summary;
  }
};

PoseMlpTrainingSummary TrainPoseMlp(PoseMlp* model, const Eigen::MatrixXf& inputs,
                                    const PoseTargets& targets,
                                    const PoseMlpTrainingOptions& options,
                                    const PoseMlpProgressCallback& progress) {
  return PoseMlpTrainerAccess::Train(model, inputs, targets, options, progress);
}

// ---- Instantiations ---------------------------------------------------------------

#define TACTFUNC_POSE_MLP_INSTANTIATE(Scalar)                                               \
  template PoseMlp::MatrixX<Scalar> PoseMlp::Forward<Scalar>(const MatrixX<Scalar>&) const; \
  template PoseMlp::MatrixX<Scalar> PoseMlp::Forward<Scalar>(const VectorX<Scalar>&,        \
                                                             const MatrixX<Scalar>&) const; \
  template void PoseMlp::Backward<Scalar>(const MatrixX<Scalar>&, const MatrixX<Scalar>&,   \
                                          VectorX<Scalar>*, MatrixX<Scalar>*) const;        \
  template void PoseMlp::Backward<Scalar>(const VectorX<Scalar>&, const MatrixX<Scalar>&,   \
                                          const MatrixX<Scalar>&, VectorX<Scalar>*,         \
                                          MatrixX<Scalar>*) const;                          \
  template double PoseMlp::Loss<Scalar>(const MatrixX<Scalar>&, const PoseTargets&, double, \
                                        MatrixX<Scalar>*) const;
TACTFUNC_POSE_MLP_INSTANTIATE(float)
TACTFUNC_POSE_MLP_INSTANTIATE(double)
#undef TACTFUNC_POSE_MLP_INSTANTIATE

}  // namespace tactfunc
