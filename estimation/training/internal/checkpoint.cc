// Copyright 2026 The tactfunc Authors.
#include "estimation/training/internal/checkpoint.h"

#include <cstdio>
#include <stdexcept>

namespace tactfunc::internal {

using Json = nlohmann::json;

std::uint64_t Fnv1a(const void* data, std::size_t size, std::uint64_t hash) {
  const auto* bytes = static_cast<const unsigned char*>(data);
  for (std::size_t i = 0; i < size; ++i) hash = (hash ^ bytes[i]) * 1099511628211ull;
  return hash;
}

std::string FingerprintHex(std::uint64_t fingerprint) {
  char buffer[17];
  std::snprintf(buffer, sizeof(buffer), "%016llx", static_cast<unsigned long long>(fingerprint));
  return buffer;
}

TensorFile NewCheckpoint(const CheckpointRun& run, int step, double train_seconds) {
  TensorFile file("checkpoint");
  Json meta;
  meta["format"] = run.format;
  meta["version"] = run.version;
  meta["sensor"] = run.sensor;
  meta["step"] = step;
  meta["train_seconds"] = train_seconds;
  meta["frames"] = {{"count", run.num_frames}, {"fingerprint", FingerprintHex(run.fingerprint)}};
  meta["options"] = Json::parse(run.options_json);
  file.set_meta_json(meta.dump());
  return file;
}

namespace {
std::string JsonValueText(const Json* value) {
  return value == nullptr ? std::string("(absent)") : value->dump();
}
}  // namespace

TensorFile ReadCheckpoint(const std::string& path, const CheckpointRun& run, Json* meta_out) {
  TensorFile file;
  try {
    file = TensorFile::Read(path, "checkpoint");
  } catch (const TensorFileError& e) {
    throw TensorFileError(std::string("cannot resume from checkpoint: ") + e.what() +
                          " (delete it, or train without resume, to start anew)");
  }
  const std::string where = "checkpoint " + path + ": ";
  Json meta;
  try {
    meta = Json::parse(file.meta_json());
    if (meta.at("format").get<std::string>() != run.format) {
      throw TensorFileError(where + "meta.format: expected '" + run.format + "', found '" +
                            meta.at("format").get<std::string>() + "'");
    }
    if (meta.at("version").get<int>() != run.version) {
      throw TensorFileError(where + "meta.version: expected " + std::to_string(run.version) +
                            ", found " + meta.at("version").dump());
    }
  } catch (const Json::exception& e) {
    throw TensorFileError(where + "malformed meta: " + e.what());
  }
  const std::string checkpoint_sensor = meta.value("sensor", std::string());
  if (checkpoint_sensor != run.sensor) {
    throw std::runtime_error(where + "was written for sensor '" + checkpoint_sensor + "', not '" +
                             run.sensor + "'");
  }
  const Json current = Json::parse(run.options_json);
  const Json& saved = meta.at("options");
  for (auto it = current.begin(); it != current.end(); ++it) {
    const Json* old = saved.contains(it.key()) ? &saved.at(it.key()) : nullptr;
    if (old == nullptr || *old != it.value()) {
      throw std::runtime_error(where + "option '" + it.key() + "' differs: " + JsonValueText(old) +
                               " in the checkpoint, " + it.value().dump() +
                               " now. Resume with the same options, or start anew without resume.");
    }
  }
  for (auto it = saved.begin(); it != saved.end(); ++it) {
    if (!current.contains(it.key())) {
      throw std::runtime_error(where + "option '" + it.key() +
                               "' is set in the checkpoint but not in this run (or unknown to this version of "
                               "tactfunc). Resume with the same options, or start anew without "
                               "resume.");
    }
  }
  const Json& frames = meta.at("frames");
  if (frames.at("count").get<int>() != run.num_frames ||
      frames.at("fingerprint").get<std::string>() != FingerprintHex(run.fingerprint)) {
    throw std::runtime_error(where + "training frames differ: the checkpoint was trained on " +
                             frames.at("count").dump() + " frames (fingerprint " +
                             frames.at("fingerprint").get<std::string>() + "), now " +
                             std::to_string(run.num_frames) + " frames (fingerprint " +
                             FingerprintHex(run.fingerprint) + ")");
  }
  if (meta_out != nullptr) *meta_out = std::move(meta);
  return file;
}

Eigen::VectorXd CheckpointVector(const TensorFile& file, const std::string& name,
                                 std::int64_t size) {
  const TensorFile::Tensor& t = file.Get(name, {size});
  return Eigen::VectorXd(Eigen::Map<const Eigen::VectorXd>(t.values.data(), size));
}

std::vector<double> ToStdVector(const Eigen::VectorXd& v) {
  return std::vector<double>(v.data(), v.data() + v.size());
}

}  // namespace tactfunc::internal
