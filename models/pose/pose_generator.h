// Copyright 2026 The tactfunc Authors.
//
// PoseGenerator: the pose-conditioned generator h(tool, sensor_T_object, depth) -> z of the
// analysis-by-synthesis pose posterior (docs/POSES.md, "The generator path"). With the
// frozen trunk f_theta (models/trunk/latent_modulated_siren.h) it renders the frame a pose
// hypothesis should produce, f_theta(x; h(tool, T, depth)), so that a pose can be fitted to
// a frame directly (estimation/synthesis/pose_fitter.h) instead of being regressed from
// the frame's latent.
//
// Features (what respects SE(2) and the tool's symmetry). For tool t of symmetry order n
// (Tool::symmetry_order) and T = (x, y, yaw):
//   f = ( onehot(t),  x / s,  y / s,  (depth - depth_center) / depth_scale,
//         cos(k n yaw), sin(k n yaw) for k = 1 .. K )            (K = yaw_harmonics)
// Only multiples of the symmetry order enter, so h is invariant under the tool's symmetry
// by construction (a C_n tool renders the same at yaw and yaw + 2 pi / n); for n = 0 (the
// hemisphere) the yaw features are 0 and yaw is unobservable. F = #tools + 3 + 2 K.
//
// Network: h_0 = f, h_{l+1} = tanh(W_l h_l + b_l), u = W_L h_L + b_L, and the latent
// z = mu + sigma .* u (output standardisation, set from the training latents). tanh keeps
// h smooth, so Gauss-Newton sees a continuous Jacobian. Parameters: ONE flat double
// vector, per layer W_l (out x in, column-major) then b_l. Initialisation: Glorot-uniform
// (tanh) from a seed (Boost.Random mt19937_64), biases 0, mu = 0, sigma = 1.
//
// Pose parameters and Jacobians. J_z_pose (d x 4) is the derivative of z with respect to
// the COORDINATES (x, y, yaw, depth); with a right perturbation T Exp(delta) the
// tangent Jacobian is J_z_pose.leftCols(3) * [R(yaw) 0; 0 1] (PoseTangentFromCoordinates).
//
// Buffers: features N x F (one sample per row), latents N x d, dL/dZ N x d.
//
// File (Save / Load): a TensorFile (models/core/tensor_file.h) of kind "pose_generator".
// JSON meta {"format": "tactfunc-pose-generator", "version": 1, "tools": [names],
// "symmetry_orders": [n], "latent_dim", "hidden_sizes", "yaw_harmonics",
// "position_scale", "depth_center", "depth_scale", "sigma_inflation", "info": {...}},
// and "weight_temperature" when it was calibrated (files written before it have none and
// load with 0, read as 1 by the posterior); "final_pixels" when kappa and tau were
// calibrated with the posterior's final stage on (absent = off);
// float64 tensors "parameters" [P], "latent_mean" [d], "latent_stddev" [d]. Written
// atomically; loading checks the kind, the version, every field and shape and throws
// TensorFileError naming the file and the field; the round trip is exact.
//
// Errors: bad Options throw std::invalid_argument (IsValid's message) from the
// constructor; buffers of the wrong shape and unknown tool indices throw
// std::invalid_argument quoting expected and found. Const methods are thread-safe.
#ifndef TACTFUNC_MODELS_POSE_POSE_GENERATOR_H_
#define TACTFUNC_MODELS_POSE_POSE_GENERATOR_H_

#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

#include "models/pose/dense_layers.h"

#include "Eigen/Core"
#include "models/core/se2.h"

namespace tactfunc {

class PoseGenerator {
 public:
  using PoseJacobian = Eigen::Matrix<double, Eigen::Dynamic, 4>;

  struct Options {
    // Tool names, in one-hot order (each once, none empty), and their symmetry orders
    // (>= 0, one per tool; Tool::symmetry_order). At least one tool.
    std::vector<std::string> tools;
    std::vector<int> symmetry_orders;
    // Latent size d of the trunk the generator feeds. >= 1.
    int latent_dim = 64;
    // tanh hidden layers, each >= 1 (may be empty: a linear map of the features).
    std::vector<int> hidden_sizes = {256, 256};
    // K, the yaw harmonics (multiples of the symmetry order). >= 1.
    int yaw_harmonics = 4;
    // Metres per position feature unit, > 0; depth feature = (depth - center) / scale,
    // scale > 0. 5 mm / 9 mm / 4 mm: synthetic contacts lie within +-4 mm and 3..15 mm.
    double position_scale = 0.005;
    double depth_center = 0.009;
    double depth_scale = 0.004;
    bool IsValid(std::string* error) const;
  };

  // Throws std::invalid_argument if !options.IsValid().
  explicit PoseGenerator(const Options& options, std::uint64_t seed = 0);

  const Options& options() const { return options_; }
  int latent_dim() const { return options_.latent_dim; }
  int num_tools() const { return static_cast<int>(options_.tools.size()); }
  int feature_dim() const { return num_tools() + 3 + 2 * options_.yaw_harmonics; }
  // Index of `tool` in options().tools, or -1.
  int ToolIndex(const std::string& tool) const;
  int SymmetryOrder(int tool_index) const;

  // ---- Parameters ---------------------------------------------------------------
  int NumParameters() const { return static_cast<int>(parameters_.size()); }
  const Eigen::VectorXd& parameters() const { return parameters_; }
  void SetParameters(const Eigen::VectorXd& parameters);  // throws on a wrong size
  void Initialize(std::uint64_t seed);
  const Eigen::VectorXd& latent_mean() const { return latent_mean_; }
  const Eigen::VectorXd& latent_stddev() const { return latent_stddev_; }
  // Throws unless both have d finite entries and stddev > 0.
  void SetLatentStandardization(const Eigen::VectorXd& mean, const Eigen::VectorXd& stddev);

  // The multiplier kappa of the pose posterior's pixel sigma (sigma = kappa * the RMS
  // residual of the best fit; estimation/synthesis/generator_posterior.h), calibrated on
  // held-out contacts; 0 = not calibrated.
  double sigma_inflation() const { return sigma_inflation_; }
  void set_sigma_inflation(double kappa);  // >= 0, finite

  // The temperature tau of the posterior's mode weights (estimation/synthesis/
  // generator_posterior.h), calibrated on held-out contacts; 0 = not calibrated (the
  // posterior then uses 1). on_likelihood: what tau was calibrated to temper, the
  // likelihood alone (every calibration since 2026-11-29) or each mode's whole evidence,
  // w ~ Z^(1/tau) (false: a file calibrated before, whose tau the posterior applies as it
  // was calibrated). Stored as "weight_temperature_on" ("likelihood" | "evidence"); a file
  // without it was calibrated before and reads as "evidence".
  double weight_temperature() const { return weight_temperature_; }
  bool weight_temperature_on_likelihood() const { return weight_temperature_on_likelihood_; }
  void set_weight_temperature(double tau, bool on_likelihood = true);  // tau >= 0, finite

  // The pixels of the posterior's final stage (GeneratorPosterior::Options::final_pixels)
  // that kappa and tau were calibrated with; 0 = none. The posterior runs that stage
  // unless told otherwise, so that the calibration holds.
  int final_pixels() const { return final_pixels_; }
  void set_final_pixels(int n);  // >= 0

  // ---- Features and passes -------------------------------------------------------
  // The feature vector of the header comment (size F); J_f_pose (optional, F x 4): its
  // derivative w.r.t. the coordinates (x, y, yaw, depth).
  Eigen::VectorXd Features(int tool_index, const SE2d& sensor_T_object, double depth_m,
                           PoseJacobian* J_f_pose = nullptr) const;
  // Latents N x d of features N x F (with this model's parameters or `parameters`).
  Eigen::MatrixXd Forward(const Eigen::MatrixXd& features) const;
  Eigen::MatrixXd Forward(const Eigen::VectorXd& parameters,
                          const Eigen::MatrixXd& features) const;
  // Exact reverse pass for a scalar loss with dL/dZ (N x d): dL/dparameters (summed over
  // the batch) and dL/dfeatures (N x F). Either may be null.
  void Backward(const Eigen::VectorXd& parameters, const Eigen::MatrixXd& features,
                const Eigen::MatrixXd& dL_dZ, Eigen::VectorXd* dL_dparameters,
                Eigen::MatrixXd* dL_dfeatures) const;
  // z = h(tool, T, depth) (size d) and optionally J_z_pose (d x 4, coordinates).
  Eigen::VectorXd Generate(int tool_index, const SE2d& sensor_T_object, double depth_m,
                           PoseJacobian* J_z_pose = nullptr) const;
  // The latents of many hypotheses of one tool at once, N x d (row i: poses[i],
  // depths[i]): one matrix product per layer instead of N matrix-vector products, the
  // same values as Generate up to rounding. Throws std::invalid_argument if the two
  // lists differ in length.
  Eigen::MatrixXd GenerateMany(int tool_index, const std::vector<SE2d>& sensor_T_objects,
                               const std::vector<double>& depths_m) const;

  // Any scalar type (ceres::Jet for autodiff checks): z[0 .. d) from pose[0..3] =
  // (x, y, yaw) and depth. O(P) per call.
  template <typename T>
  void GenerateT(int tool_index, const T* xyyaw, const T& depth, T* z) const;

  // ---- Files -------------------------------------------------------------------------
  const std::string& info_json() const { return info_json_; }
  void set_info_json(const std::string& json);  // throws if not a JSON object
  void Save(const std::string& path) const;     // atomic
  static PoseGenerator Load(const std::string& path);  // throws TensorFileError
  std::string Serialize() const;
  static PoseGenerator Parse(const std::string& bytes, const std::string& source);

 private:
  using Layer = DenseLayer;
  void CheckToolIndex(int tool_index) const;

  Options options_;
  std::vector<Layer> layers_;
  Eigen::VectorXd parameters_;
  Eigen::VectorXd latent_mean_;
  Eigen::VectorXd latent_stddev_;
  double sigma_inflation_ = 0;
  double weight_temperature_ = 0;
  bool weight_temperature_on_likelihood_ = true;
  int final_pixels_ = 0;
  std::string info_json_ = "{}";
};

// The tangent Jacobian of a right perturbation from coordinate Jacobian columns
// (x, y, yaw): J_tangent = J_coords [R(yaw) 0; 0 1] (for T Exp(delta), first order the
// position moves by R(yaw) delta_xy and the yaw by delta_yaw).
Eigen::Matrix3d PoseCoordinatesFromTangent(const SE2d& pose);

// ---- Template implementation ---------------------------------------------------------
template <typename T>
void PoseGenerator::GenerateT(int tool_index, const T* xyyaw, const T& depth, T* z) const {
  using std::cos;
  using std::sin;
  using std::tanh;
  CheckToolIndex(tool_index);
  const int n = options_.symmetry_orders[tool_index];
  std::vector<T> h(feature_dim(), T(0));
  h[tool_index] = T(1);
  const int b = num_tools();
  h[b] = xyyaw[0] / T(options_.position_scale);
  h[b + 1] = xyyaw[1] / T(options_.position_scale);
  h[b + 2] = (depth - T(options_.depth_center)) / T(options_.depth_scale);
  if (n != 0) {
    for (int k = 1; k <= options_.yaw_harmonics; ++k) {
      h[b + 1 + 2 * k] = cos(T(double(k * n)) * xyyaw[2]);
      h[b + 2 + 2 * k] = sin(T(double(k * n)) * xyyaw[2]);
    }
  }
  for (std::size_t l = 0; l < layers_.size(); ++l) {
    const Layer& layer = layers_[l];
    std::vector<T> out(layer.out);
    for (int o = 0; o < layer.out; ++o) {
      T s = T(parameters_[layer.bias_offset + o]);
      for (int i = 0; i < layer.in; ++i) {
        s += T(parameters_[layer.weight_offset + i * layer.out + o]) * h[i];
      }
      out[o] = l + 1 < layers_.size() ? tanh(s) : s;
    }
    h.swap(out);
  }
  for (int k = 0; k < options_.latent_dim; ++k) {
    z[k] = T(latent_mean_[k]) + T(latent_stddev_[k]) * h[k];
  }
}

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_POSE_POSE_GENERATOR_H_
