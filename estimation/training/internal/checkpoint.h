// Copyright 2026 The tactfunc Authors.
//
// What the trainers' checkpoints share (TrunkTrainer, PhotometricTrainer): a TensorFile
// of kind "checkpoint" whose meta names its format and version, the sensor, the step,
// the training seconds so far, the training frames (count and a 64-bit fingerprint) and
// every option that shapes the trajectory. Reading one checks all of these against the
// run that resumes, naming the field that differs; the tensors are the trainer's own.
#ifndef TACTFUNC_ESTIMATION_TRAINING_INTERNAL_CHECKPOINT_H_
#define TACTFUNC_ESTIMATION_TRAINING_INTERNAL_CHECKPOINT_H_

#include <cstdint>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "models/core/tensor_file.h"
#include "nlohmann/json.hpp"

namespace tactfunc::internal {

// Identifies the checkpoint's owner and the run it belongs to.
struct CheckpointRun {
  std::string format;        // e.g. "tactfunc-checkpoint"
  int version = 1;
  std::string sensor;        // ToString(SensorKind)
  std::string options_json;  // the trajectory options, a JSON object
  std::uint64_t fingerprint = 0;  // of the training frames
  int num_frames = 0;
};

// FNV-1a, 64 bits, continued from `hash` over `size` bytes.
std::uint64_t Fnv1a(const void* data, std::size_t size,
                    std::uint64_t hash = 1469598103934665603ull);

// The 16 hex digits of a fingerprint.
std::string FingerprintHex(std::uint64_t fingerprint);

// A checkpoint file of `run` at `step` after `train_seconds`, its tensors still to add.
TensorFile NewCheckpoint(const CheckpointRun& run, int step, double train_seconds);

// Reads the checkpoint at `path` and checks it belongs to `run`; returns its meta (for
// "step" and "train_seconds"). Throws TensorFileError for an unreadable file or a foreign
// format or version, std::runtime_error naming the field for another sensor, an option
// that differs, or other training frames.
TensorFile ReadCheckpoint(const std::string& path, const CheckpointRun& run,
                          nlohmann::json* meta);

// Tensor `name` of shape {size} as a vector (TensorFileError if absent or of another
// shape).
Eigen::VectorXd CheckpointVector(const TensorFile& file, const std::string& name,
                                 std::int64_t size);
std::vector<double> ToStdVector(const Eigen::VectorXd& v);

}  // namespace tactfunc::internal

#endif  // TACTFUNC_ESTIMATION_TRAINING_INTERNAL_CHECKPOINT_H_
