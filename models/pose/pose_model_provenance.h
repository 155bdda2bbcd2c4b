// Copyright 2026 The tactfunc Authors.
//
// Where a pose model (PoseMlp, .tpm) came from, as `tactfunc train-pose` records it in
// the model's info (PoseMlp::info_json): the sensor and latent space it was trained on,
// the latent map the posteriors must centre on, the calibrated pixel sigma, the
// training run and its figures. One typed, versioned struct for the writer (train-pose)
// and every reader (the posteriors, the model-using commands):
//
//   PoseModelProvenance p;
//   p.sensor = "bubble"; ...
//   mlp.set_info_json(p.ToJson());
//   const PoseModelProvenance q = PoseModelProvenance::FromJson(mlp.info_json(), path);
//
// Versions (field "provenance_version"):
//   0  written before the field existed: every other field optional; "latent_map"
//      absent is taken from "latents" ("refit S" -> S, else "functaset").
//   1  this version; ToJson writes every field.
// FromJson reads both: an absent field gets its default below; a present field of the
// wrong type throws std::invalid_argument naming the source, the field and the type
// expected. Unknown fields are ignored (a newer writer may add some).
#ifndef TACTFUNC_MODELS_POSE_POSE_MODEL_PROVENANCE_H_
#define TACTFUNC_MODELS_POSE_POSE_MODEL_PROVENANCE_H_

#include <cstdint>
#include <limits>
#include <optional>
#include <string>

namespace tactfunc {

struct PoseModelProvenance {
  static constexpr int kVersion = 1;

  // 0 for an info written before versioning (see the header comment).
  int version = kVersion;
  // The sensor whose latents the model takes ("bubble", "gelslim"); "" = not recorded.
  std::string sensor;
  // The functaset it was trained on (as given on train-pose's command line).
  std::string functaset;
  // Checksum of the trunk model of that functaset (FunctaModel::checksum), if recorded.
  std::optional<std::uint32_t> model_checksum;
  // How the training latents were obtained: "functaset" or "refit <strategy>".
  std::string latents = "functaset";
  // The latent map the MLP was trained on, as a LatentFitter strategy, or "functaset"
  // (encode's meta-SGD steps of the trunk).
  std::string latent_map = "functaset";
  // The pixel sigma the residual calibration used; 0 = none recorded (automatic).
  double posterior_sigma = 0;
  // The refit's pixel sigma; 0 = not given (the trunk's residual sigma).
  double refit_sigma = 0;
  std::int64_t train_samples = 0;
  std::int64_t calibration_samples = 0;
  std::string calibration_tools;  // comma-separated; "" = a random fraction
  std::string excluded_tools;     // comma-separated; "" = none
  // The training run; absent in an info that does not record it.
  std::optional<int> epochs;
  std::optional<int> batch;
  std::optional<double> learning_rate;
  std::optional<std::uint64_t> seed;
  double final_loss = std::numeric_limits<double>::quiet_NaN();  // NaN: not recorded
  std::string termination;
  // Pose errors of the trained model (NaN: not recorded or no frame).
  struct TrainTest {
    double train = std::numeric_limits<double>::quiet_NaN();
    double test = std::numeric_limits<double>::quiet_NaN();
  };
  TrainTest rmse_mm, rmse_deg;

  // The info as a JSON object text (keys sorted; NaN written as null; absent optionals
  // left out).
  std::string ToJson() const;
  // Parses an info written by ToJson or by an older train-pose. `source` names the
  // file in error messages. Throws std::invalid_argument if `json` is not a JSON object
  // or a field has the wrong type (naming the field and the type expected), or if the
  // version is newer than kVersion.
  static PoseModelProvenance FromJson(const std::string& json, const std::string& source);
};

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_POSE_POSE_MODEL_PROVENANCE_H_
