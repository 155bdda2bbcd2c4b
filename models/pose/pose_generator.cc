// Copyright 2026 The tactfunc Authors.
#include "models/pose/pose_generator.h"

#include <boost/random/mersenne_twister.hpp>
#include <boost/random/uniform_real_distribution.hpp>
#include <cmath>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "models/core/atomic_file.h"
#include "models/core/internal/checks.h"
#include "models/core/tensor_file.h"
#include "nlohmann/json.hpp"

namespace tactfunc {
namespace {

// tanh of every value through Eigen's vectorised exp: tanh(x) = 1 - 2 / (exp(2x) + 1).
// Eigen 3.4 evaluates double tanh one value at a time through libm, which took 11 % of
// a pose search's samples (`perf record` of `tactfunc eval-generator`); this form runs
// at about a tenth of the time per value and stays within 4e-16 of std::tanh in
// absolute terms over [-30, 30] (exp's overflow to inf gives 1, its underflow to 0
// gives -1, a NaN stays NaN).
template <typename Derived>
Eigen::Array<double, Eigen::Dynamic, Eigen::Dynamic> Tanh(const Eigen::ArrayBase<Derived>& x) {
  return 1.0 - 2.0 / ((2.0 * x).exp() + 1.0);
}

constexpr char kKind[] = "pose_generator";
constexpr char kFormat[] = "tactfunc-pose-generator";
constexpr int kVersion = 1;

using internal::Check;

std::vector<double> ToVector(const Eigen::VectorXd& v) {
  return std::vector<double>(v.data(), v.data() + v.size());
}

}  // namespace

bool PoseGenerator::Options::IsValid(std::string* error) const {
  auto fail = [&](const std::string& message) {
    if (error != nullptr) *error = "PoseGenerator::Options: " + message;
    return false;
  };
  if (tools.empty()) return fail("tools must name at least one tool");
  if (symmetry_orders.size() != tools.size()) {
    return fail("symmetry_orders must have one entry per tool (" +
                std::to_string(tools.size()) + "), got " +
                std::to_string(symmetry_orders.size()));
  }
  std::set<std::string> seen;
  for (std::size_t i = 0; i < tools.size(); ++i) {
    if (tools[i].empty()) return fail("tools[" + std::to_string(i) + "] is empty");
    if (!seen.insert(tools[i]).second) return fail("tool '" + tools[i] + "' is listed twice");
    if (symmetry_orders[i] < 0) {
      return fail("symmetry_orders[" + std::to_string(i) + "] must be >= 0, got " +
                  std::to_string(symmetry_orders[i]));
    }
  }
  if (latent_dim < 1) return fail("latent_dim must be >= 1, got " + std::to_string(latent_dim));
  for (int h : hidden_sizes) {
    if (h < 1) return fail("hidden_sizes must be >= 1, got " + std::to_string(h));
  }
  if (yaw_harmonics < 1) {
    return fail("yaw_harmonics must be >= 1, got " + std::to_string(yaw_harmonics));
  }
  if (!(position_scale > 0) || !std::isfinite(position_scale)) {
    return fail("position_scale must be finite and > 0");
  }
  if (!std::isfinite(depth_center)) return fail("depth_center must be finite");
  if (!(depth_scale > 0) || !std::isfinite(depth_scale)) {
    return fail("depth_scale must be finite and > 0");
  }
  return true;
}

PoseGenerator::PoseGenerator(const Options& options, std::uint64_t seed) : options_(options) {
  std::string error;
  if (!options_.IsValid(&error)) throw std::invalid_argument(error);
  std::vector<int> outs = options_.hidden_sizes;
  outs.push_back(options_.latent_dim);
  int offset = 0;
  layers_ = DenseLayerLayout(feature_dim(), outs, &offset);
  parameters_ = Eigen::VectorXd::Zero(offset);
  latent_mean_ = Eigen::VectorXd::Zero(options_.latent_dim);
  latent_stddev_ = Eigen::VectorXd::Ones(options_.latent_dim);
  Initialize(seed);
}

void PoseGenerator::Initialize(std::uint64_t seed) {
  boost::random::mt19937_64 rng(seed);
  parameters_.setZero();
  for (const Layer& layer : layers_) {
    const double limit = std::sqrt(6.0 / (layer.in + layer.out));
    boost::random::uniform_real_distribution<double> u(-limit, limit);
    for (int k = 0; k < layer.in * layer.out; ++k) parameters_[layer.weight_offset + k] = u(rng);
  }
}

int PoseGenerator::ToolIndex(const std::string& tool) const {
  for (int i = 0; i < num_tools(); ++i) {
    if (options_.tools[i] == tool) return i;
  }
  return -1;
}

void PoseGenerator::CheckToolIndex(int tool_index) const {
  Check(tool_index >= 0 && tool_index < num_tools(),
        "PoseGenerator: tool index " + std::to_string(tool_index) + " outside [0, " +
            std::to_string(num_tools()) + ")");
}

int PoseGenerator::SymmetryOrder(int tool_index) const {
  CheckToolIndex(tool_index);
  return options_.symmetry_orders[tool_index];
}

void PoseGenerator::SetParameters(const Eigen::VectorXd& parameters) {
  Check(parameters.size() == parameters_.size(),
        "PoseGenerator::SetParameters: expected " + std::to_string(parameters_.size()) +
            " values, got " + std::to_string(parameters.size()));
  parameters_ = parameters;
}

void PoseGenerator::SetLatentStandardization(const Eigen::VectorXd& mean,
                                             const Eigen::VectorXd& stddev) {
  Check(mean.size() == options_.latent_dim && stddev.size() == options_.latent_dim,
        "PoseGenerator::SetLatentStandardization: expected " +
            std::to_string(options_.latent_dim) + " entries, got " +
            std::to_string(mean.size()) + " and " + std::to_string(stddev.size()));
  Check(mean.allFinite() && stddev.allFinite() && (stddev.array() > 0).all(),
        "PoseGenerator::SetLatentStandardization: expected finite values and stddev > 0");
  latent_mean_ = mean;
  latent_stddev_ = stddev;
}

void PoseGenerator::set_sigma_inflation(double kappa) {
  Check(kappa >= 0 && std::isfinite(kappa),
        "PoseGenerator::set_sigma_inflation: expected a finite value >= 0, got " +
            std::to_string(kappa));
  sigma_inflation_ = kappa;
}

void PoseGenerator::set_weight_temperature(double tau, bool on_likelihood) {
  Check(tau >= 0 && std::isfinite(tau),
        "PoseGenerator::set_weight_temperature: expected a finite value >= 0, got " +
            std::to_string(tau));
  weight_temperature_ = tau;
  weight_temperature_on_likelihood_ = on_likelihood;
}

void PoseGenerator::set_final_pixels(int n) {
  Check(n >= 0, "PoseGenerator::set_final_pixels: expected a value >= 0, got " +
                    std::to_string(n));
  final_pixels_ = n;
}

Eigen::VectorXd PoseGenerator::Features(int tool_index, const SE2d& pose, double depth_m,
                                        PoseJacobian* J_f_pose) const {
  CheckToolIndex(tool_index);
  const int n = options_.symmetry_orders[tool_index];
  const int b = num_tools();
  Eigen::VectorXd f = Eigen::VectorXd::Zero(feature_dim());
  if (J_f_pose != nullptr) *J_f_pose = PoseJacobian::Zero(feature_dim(), 4);
  f[tool_index] = 1;
  f[b] = pose.x() / options_.position_scale;
  f[b + 1] = pose.y() / options_.position_scale;
  f[b + 2] = (depth_m - options_.depth_center) / options_.depth_scale;
  if (J_f_pose != nullptr) {
    (*J_f_pose)(b, 0) = 1 / options_.position_scale;
    (*J_f_pose)(b + 1, 1) = 1 / options_.position_scale;
    (*J_f_pose)(b + 2, 3) = 1 / options_.depth_scale;
  }
  if (n != 0) {
    for (int k = 1; k <= options_.yaw_harmonics; ++k) {
      const double m = static_cast<double>(k * n);
      const double c = std::cos(m * pose.yaw()), s = std::sin(m * pose.yaw());
      f[b + 1 + 2 * k] = c;
      f[b + 2 + 2 * k] = s;
      if (J_f_pose != nullptr) {
        (*J_f_pose)(b + 1 + 2 * k, 2) = -m * s;
        (*J_f_pose)(b + 2 + 2 * k, 2) = m * c;
      }
    }
  }
  return f;
}

Eigen::MatrixXd PoseGenerator::Forward(const Eigen::MatrixXd& features) const {
  return Forward(parameters_, features);
}

Eigen::MatrixXd PoseGenerator::Forward(const Eigen::VectorXd& parameters,
                                       const Eigen::MatrixXd& features) const {
  Check(parameters.size() == parameters_.size() && features.cols() == feature_dim(),
        "PoseGenerator::Forward: expected " + std::to_string(parameters_.size()) +
            " parameters and N x " + std::to_string(feature_dim()) + " features, got " +
            std::to_string(parameters.size()) + " and " + std::to_string(features.rows()) +
            " x " + std::to_string(features.cols()));
  Eigen::MatrixXd h = features.transpose();  // F x N
  for (std::size_t l = 0; l < layers_.size(); ++l) {
    const Layer& L = layers_[l];
    Eigen::Map<const Eigen::MatrixXd> W(parameters.data() + L.weight_offset, L.out, L.in);
    Eigen::Map<const Eigen::VectorXd> bias(parameters.data() + L.bias_offset, L.out);
    Eigen::MatrixXd a = W * h;
    a.colwise() += bias;
    h = l + 1 < layers_.size() ? Eigen::MatrixXd(Tanh(a.array()).matrix()) : a;
  }
  Eigen::MatrixXd z = h.transpose();  // N x d
  z.array().rowwise() *= latent_stddev_.transpose().array();
  z.rowwise() += latent_mean_.transpose();
  return z;
}

void PoseGenerator::Backward(const Eigen::VectorXd& parameters, const Eigen::MatrixXd& features,
                             const Eigen::MatrixXd& dL_dZ, Eigen::VectorXd* dL_dparameters,
                             Eigen::MatrixXd* dL_dfeatures) const {
  Check(parameters.size() == parameters_.size() && features.cols() == feature_dim() &&
            dL_dZ.rows() == features.rows() && dL_dZ.cols() == options_.latent_dim,
        "PoseGenerator::Backward: expected " + std::to_string(parameters_.size()) +
            " parameters, N x " + std::to_string(feature_dim()) + " features and N x " +
            std::to_string(options_.latent_dim) + " dL/dZ, got " +
            std::to_string(parameters.size()) + ", " + std::to_string(features.rows()) +
            " x " + std::to_string(features.cols()) + ", " + std::to_string(dL_dZ.rows()) +
            " x " + std::to_string(dL_dZ.cols()));
  std::vector<Eigen::MatrixXd> acts;  // inputs of each layer, in x N
  acts.push_back(features.transpose());
  for (std::size_t l = 0; l + 1 < layers_.size(); ++l) {
    const Layer& L = layers_[l];
    Eigen::Map<const Eigen::MatrixXd> W(parameters.data() + L.weight_offset, L.out, L.in);
    Eigen::Map<const Eigen::VectorXd> bias(parameters.data() + L.bias_offset, L.out);
    Eigen::MatrixXd a = W * acts.back();
    a.colwise() += bias;
    acts.push_back(Tanh(a.array()).matrix());
  }
  if (dL_dparameters != nullptr) *dL_dparameters = Eigen::VectorXd::Zero(parameters_.size());
  Eigen::MatrixXd delta = dL_dZ.transpose();  // d x N, w.r.t. the output u
  delta.array().colwise() *= latent_stddev_.array();
  for (int l = static_cast<int>(layers_.size()) - 1; l >= 0; --l) {
    const Layer& L = layers_[l];
    Eigen::Map<const Eigen::MatrixXd> W(parameters.data() + L.weight_offset, L.out, L.in);
    if (dL_dparameters != nullptr) {
      Eigen::Map<Eigen::MatrixXd>(dL_dparameters->data() + L.weight_offset, L.out, L.in) =
          delta * acts[l].transpose();
      Eigen::Map<Eigen::VectorXd>(dL_dparameters->data() + L.bias_offset, L.out) =
          delta.rowwise().sum();
    }
    if (l == 0 && dL_dfeatures == nullptr) break;
    Eigen::MatrixXd back = W.transpose() * delta;  // in x N
    if (l > 0) {
      back.array() *= 1 - acts[l].array().square();
      delta.swap(back);
    } else {
      *dL_dfeatures = back.transpose();
    }
  }
}

Eigen::VectorXd PoseGenerator::Generate(int tool_index, const SE2d& pose, double depth_m,
                                        PoseJacobian* J_z_pose) const {
  PoseJacobian J_f;
  const Eigen::VectorXd f = Features(tool_index, pose, depth_m, J_z_pose ? &J_f : nullptr);
  if (J_z_pose == nullptr) return Forward(f.transpose()).row(0).transpose();
  // Forward mode through the 4 coordinate directions beside the value: column 0 of hx is
  // h, columns 1..4 dh/d(x, y, yaw, depth). W * hx is accumulated in blocks of 32 rows
  // of W held in registers, column of W by column (one read of W): as a general matrix
  // product Eigen would first copy all of W into its packed panels, which for this
  // shape costs more than the product itself (`perf`: the packing was the search's
  // second-largest cost with a 512-wide generator).
  Eigen::Matrix<double, Eigen::Dynamic, 5> hx(f.size(), 5);
  hx.col(0) = f;
  hx.rightCols<4>() = J_f;
  Eigen::Matrix<double, Eigen::Dynamic, 5> a;
  for (std::size_t l = 0; l < layers_.size(); ++l) {
    const Layer& L = layers_[l];
    Eigen::Map<const Eigen::MatrixXd> W(parameters_.data() + L.weight_offset, L.out, L.in);
    Eigen::Map<const Eigen::VectorXd> bias(parameters_.data() + L.bias_offset, L.out);
    a.resize(L.out, 5);
    constexpr int kRows = 32;
    int i0 = 0;
    for (; i0 + kRows <= L.out; i0 += kRows) {
      Eigen::Matrix<double, kRows, 5> block = Eigen::Matrix<double, kRows, 5>::Zero();
      for (int k = 0; k < L.in; ++k) {
        block.noalias() += W.col(k).segment<kRows>(i0) * hx.row(k);
      }
      a.middleRows<kRows>(i0) = block;
    }
    if (i0 < L.out) {
      const int rest = L.out - i0;
      a.bottomRows(rest).setZero();
      for (int k = 0; k < L.in; ++k) {
        a.bottomRows(rest).noalias() += W.col(k).tail(rest) * hx.row(k);
      }
    }
    a.col(0) += bias;
    if (l + 1 < layers_.size()) {
      hx.resize(L.out, 5);
      hx.col(0) = Tanh(a.col(0).array()).matrix();
      const Eigen::ArrayXd slope = 1 - hx.col(0).array().square();
      hx.rightCols<4>() = a.rightCols<4>().array().colwise() * slope;
    } else {
      hx = a;
    }
  }
  *J_z_pose = hx.rightCols<4>();
  J_z_pose->array().colwise() *= latent_stddev_.array();
  return latent_mean_ + latent_stddev_.cwiseProduct(hx.col(0));
}

Eigen::MatrixXd PoseGenerator::GenerateMany(int tool_index,
                                            const std::vector<SE2d>& sensor_T_objects,
                                            const std::vector<double>& depths_m) const {
  Check(sensor_T_objects.size() == depths_m.size(),
        "PoseGenerator::GenerateMany: " + std::to_string(sensor_T_objects.size()) +
            " poses but " + std::to_string(depths_m.size()) + " depths");
  CheckToolIndex(tool_index);
  Eigen::MatrixXd features(static_cast<Eigen::Index>(sensor_T_objects.size()), feature_dim());
  for (std::size_t i = 0; i < sensor_T_objects.size(); ++i) {
    features.row(static_cast<Eigen::Index>(i)) =
        Features(tool_index, sensor_T_objects[i], depths_m[i]).transpose();
  }
  return Forward(features);
}

Eigen::Matrix3d PoseCoordinatesFromTangent(const SE2d& pose) {
  Eigen::Matrix3d j = Eigen::Matrix3d::Identity();
  j.topLeftCorner<2, 2>() = pose.Rotation();
  return j;
}

void PoseGenerator::set_info_json(const std::string& json) {
  nlohmann::json parsed;
  try {
    parsed = nlohmann::json::parse(json);
  } catch (const nlohmann::json::exception& e) {
    throw std::invalid_argument(std::string("PoseGenerator::set_info_json: not JSON: ") + e.what());
  }
  Check(parsed.is_object(), "PoseGenerator::set_info_json: expected a JSON object");
  info_json_ = parsed.dump();
}

std::string PoseGenerator::Serialize() const {
  TensorFile file(kKind);
  nlohmann::json meta;
  meta["format"] = kFormat;
  meta["version"] = kVersion;
  meta["tools"] = options_.tools;
  meta["symmetry_orders"] = options_.symmetry_orders;
  meta["latent_dim"] = options_.latent_dim;
  meta["hidden_sizes"] = options_.hidden_sizes;
  meta["yaw_harmonics"] = options_.yaw_harmonics;
  meta["position_scale"] = options_.position_scale;
  meta["depth_center"] = options_.depth_center;
  meta["depth_scale"] = options_.depth_scale;
  meta["sigma_inflation"] = sigma_inflation_;
  if (weight_temperature_ > 0) {
    meta["weight_temperature"] = weight_temperature_;
    meta["weight_temperature_on"] = weight_temperature_on_likelihood_ ? "likelihood" : "evidence";
  }
  if (final_pixels_ > 0) meta["final_pixels"] = final_pixels_;
  meta["info"] = nlohmann::json::parse(info_json_);
  file.set_meta_json(meta.dump());
  file.Add("parameters", TensorFile::DType::kFloat64, {parameters_.size()}, ToVector(parameters_));
  file.Add("latent_mean", TensorFile::DType::kFloat64, {latent_mean_.size()},
           ToVector(latent_mean_));
  file.Add("latent_stddev", TensorFile::DType::kFloat64, {latent_stddev_.size()},
           ToVector(latent_stddev_));
  return file.Serialize();
}

void PoseGenerator::Save(const std::string& path) const {
  WriteFileAtomically(path, Serialize());
}

namespace {

PoseGenerator FromTensorFile(const TensorFile& file, const std::string& source) {
  file.CheckFormat(kFormat, kVersion);
  std::string field = "meta";
  try {
    const nlohmann::json meta = nlohmann::json::parse(file.meta_json());
    PoseGenerator::Options options;
    field = "tools";
    options.tools = meta.at("tools").get<std::vector<std::string>>();
    field = "symmetry_orders";
    options.symmetry_orders = meta.at("symmetry_orders").get<std::vector<int>>();
    field = "latent_dim";
    options.latent_dim = meta.at("latent_dim").get<int>();
    field = "hidden_sizes";
    options.hidden_sizes = meta.at("hidden_sizes").get<std::vector<int>>();
    field = "yaw_harmonics";
    options.yaw_harmonics = meta.at("yaw_harmonics").get<int>();
    field = "position_scale";
    options.position_scale = meta.at("position_scale").get<double>();
    field = "depth_center";
    options.depth_center = meta.at("depth_center").get<double>();
    field = "depth_scale";
    options.depth_scale = meta.at("depth_scale").get<double>();
    std::string error;
    if (!options.IsValid(&error)) throw TensorFileError(source + ": " + error);
    PoseGenerator model(options);
    field = "sigma_inflation";
    const double kappa = meta.at("sigma_inflation").get<double>();
    if (!(kappa >= 0) || !std::isfinite(kappa)) {
      throw TensorFileError(source + ": field 'sigma_inflation' must be finite and >= 0");
    }
    model.set_sigma_inflation(kappa);
    if (meta.contains("weight_temperature")) {
      field = "weight_temperature";
      const double tau = meta.at("weight_temperature").get<double>();
      if (!(tau > 0) || !std::isfinite(tau)) {
        throw TensorFileError(source + ": field 'weight_temperature' must be finite and > 0");
      }
      // A file without the field was calibrated when tau tempered the whole evidence.
      std::string on = "evidence";
      if (meta.contains("weight_temperature_on")) {
        field = "weight_temperature_on";
        on = meta.at("weight_temperature_on").get<std::string>();
        if (on != "likelihood" && on != "evidence") {
          throw TensorFileError(source + ": field 'weight_temperature_on' must be \"likelihood\" "
                                "or \"evidence\", got \"" + on + "\"");
        }
      }
      model.set_weight_temperature(tau, on == "likelihood");
    }
    if (meta.contains("final_pixels")) {
      field = "final_pixels";
      const nlohmann::json& n = meta.at("final_pixels");
      const bool in_range = n.is_number_integer() && n.get<std::int64_t>() >= 0 &&
                            n.get<std::int64_t>() <= (1 << 20);
      if (!in_range) {
        throw TensorFileError(source + ": field 'final_pixels' must be an integer in [0, 1048576]");
      }
      model.set_final_pixels(n.get<int>());
    }
    field = "info";
    const nlohmann::json& info = meta.at("info");
    if (!info.is_object()) throw TensorFileError(source + ": field 'info' must be an object");
    model.set_info_json(info.dump());
    auto read = [&](const std::string& name, Eigen::Index size) {
      const TensorFile::Tensor& t = file.Get(name, {static_cast<std::int64_t>(size)});
      Eigen::VectorXd v = Eigen::Map<const Eigen::VectorXd>(t.values.data(), size);
      if (!v.allFinite()) {
        throw TensorFileError(source + ": tensor '" + name + "' holds non-finite values");
      }
      return v;
    };
    model.SetParameters(read("parameters", model.NumParameters()));
    const Eigen::VectorXd mean = read("latent_mean", options.latent_dim);
    const Eigen::VectorXd stddev = read("latent_stddev", options.latent_dim);
    if (!(stddev.array() > 0).all()) {
      throw TensorFileError(source + ": tensor 'latent_stddev' must be > 0 everywhere");
    }
    model.SetLatentStandardization(mean, stddev);
    return model;
  } catch (const nlohmann::json::exception& e) {
    throw TensorFileError(source + ": field '" + field + "' is missing or has the wrong type (" +
                          e.what() + ")");
  }
}

}  // namespace

PoseGenerator PoseGenerator::Parse(const std::string& bytes, const std::string& source) {
  return FromTensorFile(TensorFile::Parse(bytes, source, kKind), source);
}

PoseGenerator PoseGenerator::Load(const std::string& path) {
  return FromTensorFile(TensorFile::Read(path, kKind), path);
}

}  // namespace tactfunc
