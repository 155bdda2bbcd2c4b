// Copyright 2026 The tactfunc Authors.
//
// Functaset: the set of latents of a tactile dataset (Sec. III-B of "Tactile
// Functasets"). Every frame i of the dataset is stored as ONE short latent z_i in R^d
// that modulates its sensor's shared SIREN trunk (models/trunk/functa_model.h); the frame is
// recovered as f_theta(x; z_i) at every pixel x (estimation/evaluation/reconstruction.h). The
// functaset is what downstream models (k-NN, the pose MLP, SGLD) read instead of the
// raw frames.
//
// Per entry: the frame id (the dataset's file stem), its split, its pose label if it
// has one, the latent (float32, latent_dim of its sensor's trunk) and the PSNR of the
// fit against the (noisy) frame it was encoded from (estimation/data/trunk_targets.h, Psnr).
// Entries are grouped by sensor (in SensorKind order); within a sensor they keep the
// order in which they were added (the encoder adds them in Dataset::frames() order).
//
// A functaset belongs to exactly one model: it records the model file's CRC-32
// (FunctaModel::checksum()) and CheckModel refuses any other model, because latents
// are meaningless under another trunk. It also records the dataset path it came from.
//
// On disk (docs/FUNCTASET.md): a TensorFile (models/core/tensor_file.h) of kind
// "functaset", written atomically, with the JSON meta
//   {"format": "tactfunc-functaset", "version": 1, "complete": true|false,
//    "model_checksum": <uint32>, "dataset": "<path>",
//    "sensors": [{"sensor": "bubble", "latent_dim": d, "count": M, "fit_strategy": "...",
//                 "ids": [M strings], "splits": [M of "train"|"test"],
//                 "tools": [M of tool name or null (unlabelled)]}, ...]}
// and per sensor the tensors
//   "<sensor>/latents"  float32 [M x d]   row i = latent of entry i
//   "<sensor>/psnr"     float32 [M]       dB; NaN if the frame had no valid pixel
//   "<sensor>/poses"    float64 [M x 4]   x_m, y_m, yaw_rad, depth_m; NaN if unlabelled
// "complete": false marks a partial file written by an interrupted or running encoder
// (estimation/functaset/latent_encoder.h), which `tactfunc encode --resume` continues.
//
// Errors: Load/Parse raise TensorFileError naming the file and the bad field or tensor
// (the container itself -- magic, version, kind, extents, CRC -- is checked by
// TensorFile); CheckModel raises FunctasetModelMismatch; Add raises
// std::invalid_argument for an entry that does not fit.
#ifndef TACTFUNC_ESTIMATION_FUNCTASET_FUNCTASET_H_
#define TACTFUNC_ESTIMATION_FUNCTASET_FUNCTASET_H_

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "estimation/data/dataset.h"
#include "models/trunk/functa_model.h"
#include "models/core/sensor.h"

namespace tactfunc {

inline constexpr int kFunctasetVersion = 1;

// A functaset used with a model it was not encoded with.
class FunctasetModelMismatch : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct FunctasetEntry {
  std::string id;  // frame id in the dataset (file stem)
  Split split = Split::kTrain;
  std::optional<PoseLabel> label;  // absent for unlabelled frames
  Eigen::VectorXf latent;          // latent_dim of the sensor's trunk
  // PSNR (dB) of f(x; latent) against the noisy frame, as Psnr() defines it. NaN when
  // the frame has no valid pixel, +inf for an exact fit.
  float psnr = 0;
};

class Functaset {
 public:
  // Row-major M x d latent matrix (one latent per row), as k-NN indexes take them.
  using LatentMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

  Functaset() = default;
  Functaset(std::uint32_t model_checksum, std::string dataset)
      : model_checksum_(model_checksum), dataset_(std::move(dataset)) {}

  // CRC-32 of the model file the latents belong to (FunctaModel::checksum()).
  std::uint32_t model_checksum() const { return model_checksum_; }
  void set_model_checksum(std::uint32_t checksum) { model_checksum_ = checksum; }
  // The dataset the frames came from (as given to the encoder; informational).
  const std::string& dataset() const { return dataset_; }
  void set_dataset(const std::string& dataset) { dataset_ = dataset; }
  // Storage precision of the latents in the file: float32 (default) or float16 (half the
  // bytes; IEEE binary16, relative rounding error <= 2^-11 -- its PSNR cost is measured
  // in docs/RESULTS_RECONSTRUCTION.md). In memory latents stay float; Save rounds,
  // Load reads either and reports which. Bytes per latent float: 4 or 2.
  enum class LatentPrecision { kFloat32, kFloat16 };
  LatentPrecision latent_precision() const { return latent_precision_; }
  void set_latent_precision(LatentPrecision precision) { latent_precision_ = precision; }
  int BytesPerLatentFloat() const {
    return latent_precision_ == LatentPrecision::kFloat16 ? 2 : 4;
  }

  // False for a partial functaset (an interrupted or running encoder's checkpoint).
  bool complete() const { return complete_; }
  void set_complete(bool complete) { complete_ = complete; }

  // Declares a sensor with its latent dimension (>= 1). Declaring it again with the
  // same dimension does nothing; another dimension throws std::invalid_argument.
  void AddSensor(SensorKind sensor, int latent_dim);
  bool has_sensor(SensorKind sensor) const;
  // The sensors declared, in SensorKind order.
  std::vector<SensorKind> sensors() const;
  // Throws std::invalid_argument naming the sensor if it was not declared.
  int latent_dim(SensorKind sensor) const;
  // How the sensor's latents were fitted: a fit strategy as LatentFitter names it
  // ("meta_sgd:3", "ceres:20"; estimation/fitting/latent_fitter.h). "" for files written
  // before the field existed (their encoder ran the trunk's meta-SGD inner loop).
  // Throws like latent_dim().
  const std::string& fit_strategy(SensorKind sensor) const;
  void set_fit_strategy(SensorKind sensor, const std::string& strategy);

  // Appends an entry to a declared sensor. Throws std::invalid_argument if the sensor
  // is not declared, the latent does not have latent_dim(sensor) entries, the id is
  // empty or (sensor, id) is already present.
  void Add(SensorKind sensor, FunctasetEntry entry);
  // The entries of one sensor, in the order added. Throws like latent_dim().
  const std::vector<FunctasetEntry>& entries(SensorKind sensor) const;
  // Index into entries(sensor) of frame `id`, or nullopt.
  std::optional<std::size_t> Find(SensorKind sensor, const std::string& id) const;
  // Entries over all sensors.
  std::size_t size() const;

  // The latents of one sensor (optionally of one split), M x d, in entry order.
  LatentMatrix Latents(SensorKind sensor, std::optional<Split> split = std::nullopt) const;

  // Throws FunctasetModelMismatch if `model` is not the model the latents were encoded
  // with: "functaset F was encoded with model checksum 0x..., but model M has 0x...".
  // Also if the model lacks a trunk for one of the functaset's sensors or its latent
  // dimension differs. `functaset_name` and `model_name` (paths) are for the message.
  void CheckModel(const FunctaModel& model, const std::string& model_name = "the model",
                  const std::string& functaset_name = "") const;

  // Writes atomically (models/core/atomic_file.h). Throws std::runtime_error naming the path.
  void Save(const std::string& path) const;
  // Throws TensorFileError naming the file and what is wrong.
  static Functaset Load(const std::string& path);
  std::string Serialize() const;
  // `source` names the bytes in messages (a path).
  static Functaset Parse(const std::string& bytes, const std::string& source);

  // The file this functaset was loaded from ("" if not loaded).
  const std::string& source() const { return source_; }

 private:
  struct SensorBlock {
    int latent_dim = 0;
    std::string fit_strategy;
    std::vector<FunctasetEntry> entries;
    std::unordered_map<std::string, std::size_t> index;  // id -> entries position
  };
  const SensorBlock& Block(SensorKind sensor) const;

  std::uint32_t model_checksum_ = 0;
  std::string dataset_;
  bool complete_ = true;
  LatentPrecision latent_precision_ = LatentPrecision::kFloat32;
  std::map<SensorKind, SensorBlock> blocks_;
  std::string source_;
};

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_FUNCTASET_FUNCTASET_H_
