// Copyright 2026 The tactfunc Authors.
//
// PoseMlp: the downstream pose regressor of "Tactile Functasets" (Sec. III-D, IV-C):
// g_phi maps a frame's latent z in R^d to the in-hand pose of the tool. The paper uses
// three hidden layers of 512 ReLU units on 512-dimensional latents.
//
//   z_hat   = (z - mu) ./ sigma                 input standardisation (part of the model)
//   h_0     = z_hat
//   h_{l+1} = relu(W_l h_l + b_l),   l = 0 .. L-1
//   o       = W_L h_L + b_L,         o in R^4
//   o       = (x / s, y / s, cos(n yaw), sin(n yaw))       (what o is trained towards)
//
// with s = Options::position_scale (metres per output unit, 5 mm by default) so that
// every target is O(1), and n the tool's symmetry order (below). Predict() turns o
// into the pose sensor_T_object = (x, y, yaw): x = s o_0, y = s o_1,
// yaw = atan2(o_3, o_2) / n.
//
// Symmetric tools (decision). For a tool with C_n symmetry (models/simulator/tool.h) the tactile
// image at yaw and at yaw + 2 pi k / n is the same, so regressing the raw yaw (or its
// cos and sin) is ill-posed: the best squared-error fit is the average of the n
// equivalent answers, which is no answer. We therefore train on (cos(n yaw),
// sin(n yaw)), which is invariant under the symmetry, with n passed per sample with the
// targets (PoseTargets::symmetry_orders; n = 1 for asymmetric tools), and Predict()
// divides the angle by n: it returns the representative in (-pi/n, pi/n]; score it
// with YawErrorModuloSymmetry. For n = 0 (the hemisphere, continuous symmetry) yaw is
// unobservable: those samples contribute no yaw terms to the loss, and Predict()
// returns yaw = 0 with a zero Jacobian row. One network serves all tools; the caller
// (who knows which tool is in the hand) supplies n at prediction time.
//
// Loss (Loss(), the trainer): the mean over the M samples of
//   (o_0 - x/s)^2 + (o_1 - y/s)^2 + w_yaw [n != 0] ((o_2 - cos n yaw)^2 + (o_3 - sin n yaw)^2)
// -- the paper's squared-error regression loss (Eq. 8) in the scaled outputs; w_yaw is
// PoseMlpTrainingOptions::yaw_loss_weight (1).
//
// Parameters: ONE flat float vector (what Adam updates and the file stores). Layout, in
// this order, every matrix column-major (out x in): W_0, b_0, W_1, b_1, ..., W_L, b_L.
// Initialisation (deterministic from a seed, Boost.Random mt19937_64): He et al. 2015
// for the ReLU layers, W_l ~ N(0, 2 / fan_in); LeCun for the linear output layer,
// W_L ~ N(0, 1 / fan_in); biases 0. The standardisation starts at mu = 0, sigma = 1;
// TrainPoseMlp sets it from the training latents.
//
// Buffers (documented once): inputs N x d (one latent per row, raw: the model
// standardises), outputs and d_outputs N x 4, d_inputs N x d, targets M x 3 (x in m,
// y in m, yaw in rad per row). Forward/Backward exist in float (fast; Eigen GEMM) and
// double (for derivative checks: the float parameters are widened, or pass your own).
//
// Errors: bad Options throw std::invalid_argument from the constructor with the
// IsValid() message; buffers of the wrong shape, non-finite training inputs or targets
// and negative symmetry orders throw std::invalid_argument quoting expected and found;
// files throw TensorFileError naming the file and the field. Thread safety: const
// methods are safe to call concurrently.
//
// File (Save/Load): a TensorFile (models/core/tensor_file.h) of kind "pose_model". JSON meta
// {"format": "tactfunc-pose-model", "version": 1, "input_dim": d, "hidden_sizes": [...],
// "position_scale": s, "outputs": "x/s, y/s, cos(n yaw), sin(n yaw)", "info": {...}};
// tensors "parameters" (float32 [P]), "input_mean" and "input_stddev" (float32 [d]).
// Written atomically; the round trip is exact.
#ifndef TACTFUNC_MODELS_POSE_POSE_MLP_H_
#define TACTFUNC_MODELS_POSE_POSE_MLP_H_

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "models/pose/dense_layers.h"

#include "Eigen/Core"
#include "models/core/se2.h"

namespace tactfunc {

// Training targets: one pose per row and the symmetry order of the tool in each sample.
struct PoseTargets {
  Eigen::MatrixXd poses;            // M x 3: x (m), y (m), yaw (rad)
  Eigen::VectorXi symmetry_orders;  // M entries >= 0 (Tool::symmetry_order()); empty = all 1
};

class PoseMlp {
 public:
  template <typename Scalar>
  using MatrixX = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;
  template <typename Scalar>
  using VectorX = Eigen::Matrix<Scalar, Eigen::Dynamic, 1>;
  static constexpr int kOutputDim = 4;  // x/s, y/s, cos(n yaw), sin(n yaw)

  struct Options {
    // Latent dimension d. >= 1. The paper's functa are 512-dimensional (Sec. IV-A).
    int input_dim = 512;
    // Widths of the hidden ReLU layers, each >= 1 (may be empty: a linear model).
    // Three of 512: the paper's pose MLP (Sec. IV-C).
    std::vector<int> hidden_sizes = {512, 512, 512};
    // Metres per position output unit, finite and > 0. 5 mm: in-hand offsets of the
    // Touch2Touch tools are a few mm, so x/s and y/s are O(1).
    double position_scale = 0.005;
    bool IsValid(std::string* error) const;
  };

  // A He-initialised network drawn from `seed`. Throws std::invalid_argument if
  // !options.IsValid().
  explicit PoseMlp(const Options& options, std::uint64_t seed = 0);

  const Options& options() const { return options_; }
  int input_dim() const { return options_.input_dim; }
  int num_layers() const { return static_cast<int>(options_.hidden_sizes.size()) + 1; }

  // ---- Parameters ------------------------------------------------------------------
  int NumParameters() const { return static_cast<int>(parameters_.size()); }
  const Eigen::VectorXf& parameters() const { return parameters_; }
  // Throws std::invalid_argument if the size is not NumParameters().
  void SetParameters(const Eigen::VectorXf& parameters);
  // Re-draws the parameters from `seed` as the constructor does (standardisation kept).
  void Initialize(std::uint64_t seed);

  // Input standardisation mu and sigma (size d).
  const Eigen::VectorXf& input_mean() const { return input_mean_; }
  const Eigen::VectorXf& input_stddev() const { return input_stddev_; }
  // Throws std::invalid_argument unless both have d entries, all finite, sigma > 0.
  void SetInputStandardization(const Eigen::VectorXf& mean, const Eigen::VectorXf& stddev);

  // ---- Batched passes --------------------------------------------------------------
  // Outputs o, N x 4, for raw inputs N x d (with this model's parameters, or with
  // `parameters` of size NumParameters() in this model's layout).
  template <typename Scalar>
  MatrixX<Scalar> Forward(const MatrixX<Scalar>& inputs) const;
  template <typename Scalar>
  MatrixX<Scalar> Forward(const VectorX<Scalar>& parameters, const MatrixX<Scalar>& inputs) const;

  // Exact reverse pass: for a scalar function L of the outputs with dL/do = d_outputs
  // (N x 4), writes dL/dparameters (NumParameters(), summed over the batch) and dL/d
  // inputs (N x d, through the standardisation). Either output may be null. ReLU'(0)
  // is taken as 0.
  template <typename Scalar>
  void Backward(const MatrixX<Scalar>& inputs, const MatrixX<Scalar>& d_outputs,
                VectorX<Scalar>* d_parameters, MatrixX<Scalar>* d_inputs) const;
  template <typename Scalar>
  void Backward(const VectorX<Scalar>& parameters, const MatrixX<Scalar>& inputs,
                const MatrixX<Scalar>& d_outputs, VectorX<Scalar>* d_parameters,
                MatrixX<Scalar>* d_inputs) const;

  // d o / d z at one raw latent z (size d): 4 x d, in double. What a Laplace
  // approximation or a sampler's proposal needs.
  Eigen::MatrixXd InputJacobian(const Eigen::VectorXd& z) const;

  // ---- Poses -------------------------------------------------------------------------
  // The pose sensor_T_object (x, y in m, yaw in rad) at latent z for a tool of symmetry
  // order n (header comment). J_xyyaw_z (optional): 3 x d, the derivative of the
  // coordinates (x, y, yaw) with respect to z (not a right Jacobian on SE(2)). Throws
  // for n < 0 or a z of the wrong size.
  SE2d Predict(const Eigen::VectorXd& z, int symmetry_order = 1,
               Eigen::MatrixXd* J_xyyaw_z = nullptr) const;
  // Batched, in float: one sensor_T_object per row of inputs (N x d), all of symmetry
  // order n. A non-finite output gives a pose with non-finite coordinates.
  std::vector<SE2d> PredictBatch(const Eigen::MatrixXf& inputs, int symmetry_order = 1) const;

  // ---- Loss ----------------------------------------------------------------------------
  // The training targets o* (M x 4) of `targets` and the per-sample yaw mask (1, or 0
  // for n = 0). Throws std::invalid_argument for a targets.poses that is not M x 3 or
  // not finite, or symmetry orders of the wrong size or negative.
  Eigen::MatrixXf EncodeTargets(const PoseTargets& targets, Eigen::VectorXf* yaw_mask) const;
  // The loss of the header comment for outputs N x 4 against N targets; d_outputs
  // (optional) receives dL/do, N x 4.
  template <typename Scalar>
  double Loss(const MatrixX<Scalar>& outputs, const PoseTargets& targets,
              double yaw_loss_weight = 1.0, MatrixX<Scalar>* d_outputs = nullptr) const;

  // ---- Calibration: the regressor's own error ------------------------------------------
  // Residuals of the trained model on calibration contacts held out of its training
  // (`tactfunc train-pose --calibration-fraction`): r_j = Log(T_pred(z_j)^-1 T_true_j),
  // (x m, y m, yaw rad), a right (body-frame) perturbation as models/core/se2.h uses, with
  // the true yaw taken modulo the tool's symmetry (the copy nearest the prediction; the
  // prediction's yaw for n = 0). Computed by CalibrationResiduals (samplers/
  // pose_posterior.h). The pose posteriors compose every pose sample with a residual
  // drawn from these (PosePosterior::Options::model_error), so that the distribution
  // covers the regressor's error and not only the latent's (docs/POSES.md,
  // "Calibration"). R x 3; empty (the default, and files written before it existed) =
  // none. Stored in the pose model file as the float64 tensor "calibration_residuals".
  const Eigen::MatrixXd& calibration_residuals() const { return calibration_residuals_; }
  // Throws std::invalid_argument unless residuals is R x 3 (R >= 0) and finite.
  void SetCalibrationResiduals(const Eigen::MatrixXd& residuals);

  // ---- Files -------------------------------------------------------------------------
  // Free-form JSON object stored with the model (training summary, data provenance).
  const std::string& info_json() const { return info_json_; }
  void set_info_json(const std::string& json);  // throws std::invalid_argument if not an object
  void Save(const std::string& path) const;     // atomic
  // Throws TensorFileError naming the file and the bad field.
  static PoseMlp Load(const std::string& path);
  std::string Serialize() const;
  static PoseMlp Parse(const std::string& bytes, const std::string& source);

 private:
  using Layer = DenseLayer;
  template <typename Scalar>
  MatrixX<Scalar> Standardize(const MatrixX<Scalar>& inputs) const;
  // Forward keeping every layer's input h_l (activations[0] = standardised inputs).
  template <typename Scalar>
  MatrixX<Scalar> ForwardKeep(const Scalar* parameters, const MatrixX<Scalar>& inputs,
                              std::vector<MatrixX<Scalar>>* activations) const;
  template <typename Scalar>
  void BackwardFrom(const Scalar* parameters, const std::vector<MatrixX<Scalar>>& activations,
                    const MatrixX<Scalar>& d_outputs, VectorX<Scalar>* d_parameters,
                    MatrixX<Scalar>* d_inputs) const;
  void CheckInputs(int rows, int cols, const char* what) const;

  Options options_;
  std::vector<Layer> layers_;
  Eigen::VectorXf parameters_;
  Eigen::VectorXf input_mean_;
  Eigen::VectorXf input_stddev_;
  std::string info_json_ = "{}";
  Eigen::MatrixXd calibration_residuals_ = Eigen::MatrixXd::Zero(0, 3);

  friend struct PoseMlpTrainerAccess;
};

// ---- Training --------------------------------------------------------------------------

struct PoseMlpTrainingOptions {
  // Passes over the training set. >= 1.
  int epochs = 100;
  // Samples per Adam step. >= 1 (the last batch of an epoch may be smaller).
  int batch_size = 256;
  // Adam (Kingma & Ba 2015): step size, > 0; moment decays in [0, 1); epsilon > 0.
  // 1e-3, 0.9, 0.999, 1e-8 are the paper's defaults.
  double learning_rate = 1e-3;
  double beta1 = 0.9;
  double beta2 = 0.999;
  double epsilon = 1e-8;
  // Decoupled weight decay (AdamW, Loshchilov & Hutter 2019) on the weight matrices
  // (not the biases), per step: W <- W - learning_rate * weight_decay * W. >= 0.
  double weight_decay = 0.0;
  // w_yaw in the loss (header comment). >= 0.
  double yaw_loss_weight = 1.0;
  // Set the model's input standardisation to the per-dimension mean and standard
  // deviation of the training inputs (a standard deviation below 1e-6 becomes 1, so
  // constant dimensions pass through unscaled). If false, the model's own is kept.
  bool standardize_inputs = true;
  // Seed of the per-epoch shuffles.
  std::uint64_t seed = 0;
  bool IsValid(std::string* error) const;
};

enum class PoseMlpTrainingTermination {
  kCompleted,      // all epochs ran
  kUserRequested,  // the progress callback returned false
  kNonFinite,      // the loss became NaN or infinite: parameters of the last finite epoch
};
const char* ToString(PoseMlpTrainingTermination termination);

struct PoseMlpTrainingSummary {
  PoseMlpTrainingTermination termination = PoseMlpTrainingTermination::kCompleted;
  std::string message;
  int epochs_completed = 0;
  double initial_loss = 0;  // on the whole training set, before the first step
  double final_loss = 0;    // on the whole training set, after the last step
  // Mean minibatch loss of each completed epoch (as the parameters moved during it).
  std::vector<double> loss_history;
  double total_time_in_seconds = 0;
  std::string BriefReport() const;  // one line
  std::string FullReport() const;   // the above plus the loss history
};

// Called after each epoch with (epoch index from 0, that epoch's mean loss); return
// false to stop.
using PoseMlpProgressCallback = std::function<bool(int epoch, double loss)>;

// Trains `model` in place from its current parameters with Adam on minibatches of
// (inputs M x d, targets with M rows). Throws std::invalid_argument for bad options,
// a null model, shapes that do not match, or non-finite inputs / targets.
PoseMlpTrainingSummary TrainPoseMlp(PoseMlp* model, const Eigen::MatrixXf& inputs,
                                    const PoseTargets& targets,
                                    const PoseMlpTrainingOptions& options,
                                    const PoseMlpProgressCallback& progress = {});

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_POSE_POSE_MLP_H_
