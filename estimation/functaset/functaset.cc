// Copyright 2026 The tactfunc Authors.
#include "estimation/functaset/functaset.h"

#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>
#include <utility>

#include "models/core/atomic_file.h"
#include "models/core/tensor_file.h"
#include "nlohmann/json.hpp"

namespace tactfunc {
namespace {

constexpr const char* kFormat = "tactfunc-functaset";
constexpr const char* kKind = "functaset";
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::string Hex(std::uint32_t value) {
  char buffer[16];
  std::snprintf(buffer, sizeof(buffer), "0x%08" PRIx32, value);
  return buffer;
}

}  // namespace

void Functaset::AddSensor(SensorKind sensor, int latent_dim) {
  if (latent_dim < 1) {
    throw std::invalid_argument(std::string("Functaset: latent_dim of sensor '") +
                                ToString(sensor) + "' must be >= 1, got " +
                                std::to_string(latent_dim));
  }
  auto it = blocks_.find(sensor);
  if (it != blocks_.end()) {
    if (it->second.latent_dim != latent_dim) {
      throw std::invalid_argument(std::string("Functaset: sensor '") + ToString(sensor) +
                                  "' has latent_dim " + std::to_string(it->second.latent_dim) +
                                  ", cannot redeclare it with " + std::to_string(latent_dim));
    }
    return;
  }
  blocks_[sensor].latent_dim = latent_dim;
}

bool Functaset::has_sensor(SensorKind sensor) const { return blocks_.count(sensor) > 0; }

std::vector<SensorKind> Functaset::sensors() const {
  std::vector<SensorKind> out;
  for (const auto& [sensor, block] : blocks_) out.push_back(sensor);
  return out;
}

const Functaset::SensorBlock& Functaset::Block(SensorKind sensor) const {
  auto it = blocks_.find(sensor);
  if (it == blocks_.end()) {
    throw std::invalid_argument(std::string("the functaset has no sensor '") + ToString(sensor) +
                                "'");
  }
  return it->second;
}

int Functaset::latent_dim(SensorKind sensor) const { return Block(sensor).latent_dim; }

const std::string& Functaset::fit_strategy(SensorKind sensor) const {
  return Block(sensor).fit_strategy;
}

void Functaset::set_fit_strategy(SensorKind sensor, const std::string& strategy) {
  Block(sensor);  // throws for an undeclared sensor
  blocks_[sensor].fit_strategy = strategy;
}

void Functaset::Add(SensorKind sensor, FunctasetEntry entry) {
  auto it = blocks_.find(sensor);
  if (it == blocks_.end()) {
    throw std::invalid_argument(std::string("Functaset::Add: sensor '") + ToString(sensor) +
                                "' was not declared with AddSensor");
  }
  SensorBlock& block = it->second;
  if (entry.id.empty()) throw std::invalid_argument("Functaset::Add: empty frame id");
  if (entry.latent.size() != block.latent_dim) {
    throw std::invalid_argument(
        "Functaset::Add: frame '" + entry.id + "' (" + ToString(sensor) + ") has a latent of " +
        std::to_string(entry.latent.size()) +
        " values, expected latent_dim = " + std::to_string(block.latent_dim));
  }
  if (!block.index.emplace(entry.id, block.entries.size()).second) {
    throw std::invalid_argument("Functaset::Add: frame '" + entry.id + "' (" + ToString(sensor) +
                                ") is already in the functaset");
  }
  block.entries.push_back(std::move(entry));
}

const std::vector<FunctasetEntry>& Functaset::entries(SensorKind sensor) const {
  return Block(sensor).entries;
}

std::optional<std::size_t> Functaset::Find(SensorKind sensor, const std::string& id) const {
  auto it = blocks_.find(sensor);
  if (it == blocks_.end()) return std::nullopt;
  auto found = it->second.index.find(id);
  if (found == it->second.index.end()) return std::nullopt;
  return found->second;
}

std::size_t Functaset::size() const {
  std::size_t total = 0;
  for (const auto& [sensor, block] : blocks_) total += block.entries.size();
  return total;
}

Functaset::LatentMatrix Functaset::Latents(SensorKind sensor, std::optional<Split> split) const {
  const SensorBlock& block = Block(sensor);
  std::size_t count = 0;
  for (const FunctasetEntry& e : block.entries) count += !split || e.split == *split;
  LatentMatrix out(count, block.latent_dim);
  Eigen::Index row = 0;
  for (const FunctasetEntry& e : block.entries) {
    if (!split || e.split == *split) out.row(row++) = e.latent.transpose();
  }
  return out;
}

void Functaset::CheckModel(const FunctaModel& model, const std::string& model_name,
                           const std::string& functaset_name) const {
  const std::string name =
      !functaset_name.empty() ? functaset_name : (!source_.empty() ? source_ : "(in memory)");
  if (model.checksum() != model_checksum_) {
    throw FunctasetModelMismatch("functaset " + name + " was encoded with model checksum " +
                                 Hex(model_checksum_) + ", but model " + model_name + " has " +
                                 Hex(model.checksum()) +
                                 ": its latents only mean something under the model they "
                                 "were encoded with (re-encode with `tactfunc encode`)");
  }
  for (const auto& [sensor, block] : blocks_) {
    if (!model.HasSensor(sensor)) {
      throw FunctasetModelMismatch("functaset " + name + " holds sensor '" + ToString(sensor) +
                                   "', but model " + model_name + " has no trunk for it");
    }
    const int d = model.Trunk(sensor).siren.latent_dim();
    if (d != block.latent_dim) {
      throw FunctasetModelMismatch("functaset " + name + ": sensor '" + ToString(sensor) +
                                   "' has latent_dim " + std::to_string(block.latent_dim) +
                                   ", but model " + model_name + "'s trunk has " +
                                   std::to_string(d));
    }
  }
}

std::string Functaset::Serialize() const {
  TensorFile file(kKind);
  nlohmann::json meta;
  meta["format"] = kFormat;
  meta["version"] = kFunctasetVersion;
  meta["complete"] = complete_;
  meta["model_checksum"] = model_checksum_;
  meta["dataset"] = dataset_;
  meta["sensors"] = nlohmann::json::array();
  for (const auto& [sensor, block] : blocks_) {
    const std::string name = ToString(sensor);
    const std::int64_t m = static_cast<std::int64_t>(block.entries.size());
    const std::int64_t d = block.latent_dim;
    nlohmann::json ids = nlohmann::json::array(), splits = nlohmann::json::array(),
                   tools = nlohmann::json::array();
    std::vector<double> latents, psnr, poses;
    latents.reserve(m * d);
    psnr.reserve(m);
    poses.reserve(m * 4);
    for (const FunctasetEntry& e : block.entries) {
      ids.push_back(e.id);
      splits.push_back(ToString(e.split));
      if (e.label) {
        tools.push_back(e.label->tool);
        const SE2d& pose = e.label->sensor_T_object;
        poses.insert(poses.end(), {pose.x(), pose.y(), pose.yaw(), e.label->depth_m});
      } else {
        tools.push_back(nullptr);
        poses.insert(poses.end(), {kNaN, kNaN, kNaN, kNaN});
      }
      for (Eigen::Index k = 0; k < d; ++k) latents.push_back(e.latent[k]);
      psnr.push_back(e.psnr);
    }
    meta["sensors"].push_back({{"sensor", name},
                               {"latent_dim", block.latent_dim},
                               {"fit_strategy", block.fit_strategy},
                               {"count", m},
                               {"ids", std::move(ids)},
                               {"splits", std::move(splits)},
                               {"tools", std::move(tools)}});
    file.Add(name + "/latents",
             latent_precision_ == LatentPrecision::kFloat16 ? TensorFile::DType::kFloat16
                                                            : TensorFile::DType::kFloat32,
             {m, d}, std::move(latents));
    file.Add(name + "/psnr", TensorFile::DType::kFloat32, {m}, std::move(psnr));
    file.Add(name + "/poses", TensorFile::DType::kFloat64, {m, 4}, std::move(poses));
  }
  file.set_meta_json(meta.dump());
  return file.Serialize();
}

void Functaset::Save(const std::string& path) const {
  // Readers (and a resuming encoder) see the old file or the whole new one.
  WriteFileAtomically(path, Serialize());
}

Functaset Functaset::Parse(const std::string& bytes, const std::string& source) {
  const TensorFile file = TensorFile::Parse(bytes, source, kKind);
  Functaset out;
  out.source_ = source;
  std::string field = "meta";
  auto fail = [&](const std::string& what) {
    return TensorFileError(source + ": field '" + field + "': " + what);
  };
  file.CheckFormat(kFormat, kFunctasetVersion);
  try {
    const nlohmann::json meta = nlohmann::json::parse(file.meta_json());
    field = "complete";
    out.complete_ = meta.at("complete").get<bool>();
    field = "model_checksum";
    const auto& checksum = meta.at("model_checksum");
    if (!checksum.is_number_unsigned() || checksum.get<std::uint64_t>() > 0xffffffffull) {
      throw fail("expected an unsigned 32-bit integer, got " + checksum.dump());
    }
    out.model_checksum_ = static_cast<std::uint32_t>(checksum.get<std::uint64_t>());
    field = "dataset";
    out.dataset_ = meta.at("dataset").get<std::string>();
    field = "sensors";
    const auto& sensors = meta.at("sensors");
    if (!sensors.is_array()) throw fail("expected an array, got " + sensors.dump());
    for (std::size_t s = 0; s < sensors.size(); ++s) {
      const auto& entry = sensors[s];
      const std::string where = "sensors[" + std::to_string(s) + "]";
      field = where + ".sensor";
      const std::string name = entry.at("sensor").get<std::string>();
      SensorKind sensor;
      if (!SensorKindFromString(name, &sensor) || name != ToString(sensor)) {
        throw fail("unknown sensor '" + name + "', expected bubble or gelslim");
      }
      if (out.has_sensor(sensor)) throw fail("sensor '" + name + "' appears twice");
      field = where + ".latent_dim";
      const int d = entry.at("latent_dim").get<int>();
      if (d < 1) throw fail("expected >= 1, got " + std::to_string(d));
      field = where + ".count";
      const std::int64_t m = entry.at("count").get<std::int64_t>();
      if (m < 0) throw fail("expected >= 0, got " + std::to_string(m));
      // Arrays of exactly `count` elements.
      auto array = [&](const char* key) -> const nlohmann::json& {
        field = where + "." + key;
        const auto& a = entry.at(key);
        if (!a.is_array() || static_cast<std::int64_t>(a.size()) != m) {
          throw fail("expected an array of count = " + std::to_string(m) + " elements, got " +
                     (a.is_array() ? std::to_string(a.size()) + " elements" : a.type_name()));
        }
        return a;
      };
      const auto& id_array = array("ids");
      const auto& split_array = array("splits");
      const auto& tool_array = array("tools");
      const auto& latents = file.Get(name + "/latents", {m, d});
      const auto& psnr = file.Get(name + "/psnr", {m});
      const auto& poses = file.Get(name + "/poses", {m, 4});
      if (latents.dtype == TensorFile::DType::kFloat64 ||
          psnr.dtype != TensorFile::DType::kFloat32 || poses.dtype != TensorFile::DType::kFloat64) {
        field = name + "/*";
        throw fail("expected latents float32 or float16, psnr float32, poses float64");
      }
      if (latents.dtype == TensorFile::DType::kFloat16) {
        out.latent_precision_ = LatentPrecision::kFloat16;
      }
      out.AddSensor(sensor, d);
      if (entry.contains("fit_strategy")) {
        field = where + ".fit_strategy";
        out.set_fit_strategy(sensor, entry.at("fit_strategy").get<std::string>());
      }
      for (std::int64_t i = 0; i < m; ++i) {
        const std::string item = "[" + std::to_string(i) + "]";
        FunctasetEntry e;
        field = where + ".ids" + item;
        e.id = id_array[i].get<std::string>();
        if (e.id.empty()) throw fail("empty frame id");
        if (out.Find(sensor, e.id)) throw fail("frame '" + e.id + "' appears twice");
        field = where + ".splits" + item;
        const std::string split = split_array[i].get<std::string>();
        if (!SplitFromString(split, &e.split)) {
          throw fail("expected \"train\" or \"test\", got \"" + split + "\"");
        }
        field = where + ".tools" + item;
        if (!tool_array[i].is_null()) {
          PoseLabel label;
          label.tool = tool_array[i].get<std::string>();
          if (label.tool.empty()) throw fail("empty tool name (use null for unlabelled)");
          const double* p = poses.values.data() + 4 * i;
          if (!(std::isfinite(p[0]) && std::isfinite(p[1]) && std::isfinite(p[2]) &&
                std::isfinite(p[3]))) {
            field = name + "/poses" + item;
            throw fail("labelled frame '" + e.id + "' has a non-finite pose");
          }
          label.sensor_T_object = SE2d::FromXYYaw(p[0], p[1], p[2]);
          label.depth_m = p[3];
          e.label = std::move(label);
        }
        e.latent.resize(d);
        for (int k = 0; k < d; ++k) {
          e.latent[k] = static_cast<float>(latents.values[static_cast<std::size_t>(i) * d + k]);
        }
        e.psnr = static_cast<float>(psnr.values[i]);
        out.Add(sensor, std::move(e));
      }
    }
  } catch (const nlohmann::json::exception& e) {
    throw TensorFileError(source + ": field '" + field + "' is missing or has the wrong type (" +
                          e.what() + ")");
  }
  return out;
}

Functaset Functaset::Load(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw TensorFileError(path + ": cannot open (does it exist?)");
  std::ostringstream bytes;
  bytes << in.rdbuf();
  return Parse(bytes.str(), path);
}

}  // namespace tactfunc
