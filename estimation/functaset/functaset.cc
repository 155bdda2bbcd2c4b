// Copyright 2026 The tactfunc Authors.
#include "estimation/functaset/functaset.h"
#include "models/core/text_limits.h"

#include <algorithm>
#include <cinttypes>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <limits>
#include <sstream>
#include <utility>

#include "models/core/atomic_file.h"
#include "models/core/tensor_file.h"
#include "models/simulator/tool.h"
#include "nlohmann/json.hpp"

namespace tactfunc {
namespace {

constexpr const char* kFormat = "tactfunc-functaset";
constexpr const char* kKind = "functaset";
constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();

std::vector<int> BitsOf(const std::vector<LatentGrid>& grids) {
  std::vector<int> bits;
  for (const LatentGrid& g : grids) bits.push_back(g.bits);
  return bits;
}

std::string Hex(std::uint32_t value) {
  char buffer[16];
  std::snprintf(buffer, sizeof(buffer), "0x%08" PRIx32, value);
  return buffer;
}

struct PrecisionInfo {
  Functaset::LatentPrecision precision;
  const char* name;
  int bits;
};
constexpr PrecisionInfo kPrecisions[] = {{Functaset::LatentPrecision::kFloat32, "float32", 32},
                                         {Functaset::LatentPrecision::kFloat16, "float16", 16},
                                         {Functaset::LatentPrecision::kUint8, "uint8", 8},
                                         {Functaset::LatentPrecision::kUint6, "uint6", 6},
                                         {Functaset::LatentPrecision::kUint4, "uint4", 4},
                                         {Functaset::LatentPrecision::kAllocated, "allocated", 0}};

const PrecisionInfo& Info(Functaset::LatentPrecision precision) {
  for (const PrecisionInfo& info : kPrecisions) {
    if (info.precision == precision) return info;
  }
  return kPrecisions[0];
}

}  // namespace

const char* ToString(Functaset::LatentPrecision precision) { return Info(precision).name; }

bool LatentPrecisionFromString(const std::string& name, Functaset::LatentPrecision* precision) {
  for (const PrecisionInfo& info : kPrecisions) {
    if (name == info.name) {
      *precision = info.precision;
      return true;
    }
  }
  return false;
}

int LatentBits(Functaset::LatentPrecision precision) { return Info(precision).bits; }

bool IsQuantised(Functaset::LatentPrecision precision) {
  return precision == Functaset::LatentPrecision::kAllocated || LatentBits(precision) <= 8;
}

double Functaset::BytesPerFrame(SensorKind sensor) const {
  const int d = latent_dim(sensor);
  const int bits = LatentBits(latent_precision_);
  if (latent_precision_ == LatentPrecision::kAllocated) return latent_bytes_;
  return IsQuantised(latent_precision_)
             ? static_cast<double>(PackedBytes(std::vector<int>(d, bits)))
             : static_cast<double>(d) * bits / 8;
}

std::uint64_t Functaset::SharedLatentBytes(SensorKind sensor) const {
  const std::uint64_t d = static_cast<std::uint64_t>(latent_dim(sensor));
  const std::uint64_t tables = !IsQuantised(latent_precision_) ? 0
                               : latent_precision_ == LatentPrecision::kAllocated ? 9 * d
                                                                                  : 8 * d;
  return tables + (rest_latent(sensor) ? 4 * d : 0);
}

int Functaset::ToolSymmetryOrder(const std::string& tool, bool* known) const {
  return SymmetryOrderOfTool(tool, tool_symmetries_, known);
}

std::vector<int> Functaset::code_bits(SensorKind sensor) const {
  const SensorBlock& block = Block(sensor);
  return block.codes ? BitsOf(block.codes->grids) : std::vector<int>();
}

std::int64_t Functaset::NumStoredLatents(SensorKind sensor) const {
  std::int64_t n = 0;
  for (const FunctasetEntry& e : Block(sensor).entries) n += e.at_rest ? 0 : 1;
  return n;
}

const Eigen::VectorXf* Functaset::rest_latent(SensorKind sensor) const {
  const SensorBlock& block = Block(sensor);
  return block.rest_latent ? &*block.rest_latent : nullptr;
}

void Functaset::set_rest_latent(SensorKind sensor, const Eigen::VectorXf& latent) {
  Block(sensor);  // throws for an undeclared sensor
  SensorBlock& block = blocks_[sensor];
  if (latent.size() != block.latent_dim) {
    throw std::invalid_argument(std::string("Functaset::set_rest_latent: ") + ToString(sensor) +
                                ": expected latent_dim = " + std::to_string(block.latent_dim) +
                                " values, got " + std::to_string(latent.size()));
  }
  block.rest_latent = latent;
  for (FunctasetEntry& e : block.entries) {
    if (e.at_rest) e.latent = latent;
  }
}

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

const std::string& Functaset::products(SensorKind sensor) const { return Block(sensor).products; }

void Functaset::set_products(SensorKind sensor, const std::string& products) {
  Block(sensor);  // throws for an undeclared sensor
  if (products != "float" && products != "bf16") {
    throw std::invalid_argument("Functaset: products must be float or bf16, got '" + products +
                                "'");
  }
  blocks_[sensor].products = products;
}

void Functaset::Add(SensorKind sensor, FunctasetEntry entry) {
  auto it = blocks_.find(sensor);
  if (it == blocks_.end()) {
    throw std::invalid_argument(std::string("Functaset::Add: sensor '") + ToString(sensor) +
                                "' was not declared with AddSensor");
  }
  SensorBlock& block = it->second;
  if (entry.id.empty()) throw std::invalid_argument("Functaset::Add: empty frame id");
  if (entry.at_rest) {
    if (!block.rest_latent) {
      throw std::invalid_argument("Functaset::Add: frame '" + entry.id + "' (" +
                                  ToString(sensor) +
                                  ") is at rest but the sensor has no rest latent");
    }
    entry.latent = *block.rest_latent;
  } else if (entry.latent.size() != block.latent_dim) {
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
    const int d = TrunkLatentDim(model.Trunk(sensor));
    if (d != block.latent_dim) {
      throw FunctasetModelMismatch("functaset " + name + ": sensor '" + ToString(sensor) +
                                   "' has latent_dim " + std::to_string(block.latent_dim) +
                                   ", but model " + model_name + "'s trunk has " +
                                   std::to_string(d));
    }
  }
}

Functaset::CodeTable Functaset::Codes(const SensorBlock& block) const {
  const int d = block.latent_dim;
  // The grids the entries were read with, if every latent still lies on them.
  if (block.codes && block.codes->precision == latent_precision_ &&
      (latent_precision_ != LatentPrecision::kAllocated ||
       block.codes->bytes == latent_bytes_)) {
    bool on_grid = true;
    for (const FunctasetEntry& e : block.entries) {
      if (e.at_rest) continue;  // the rest latent is stored apart, as float32
      for (int k = 0; k < d && on_grid; ++k) {
        const LatentGrid& grid = block.codes->grids[k];
        on_grid = Dequantise(Quantise(e.latent[k], grid), grid) == e.latent[k];
      }
      if (!on_grid) break;
    }
    if (on_grid) return *block.codes;
  }
  std::vector<std::vector<float>> values(d);
  for (const FunctasetEntry& e : block.entries) {
    if (e.at_rest) continue;
    for (int k = 0; k < d; ++k) values[k].push_back(e.latent[k]);
  }
  CodeTable table;
  table.precision = latent_precision_;
  table.bytes = latent_bytes_;
  table.grids.resize(d);
  if (latent_precision_ == LatentPrecision::kAllocated) {
    const std::vector<int> bits = AllocateBits(values, 8 * latent_bytes_);
    for (int k = 0; k < d; ++k) table.grids[k] = LeastSquaresGrid(values[k], bits[k]);
  } else {
    for (int k = 0; k < d; ++k) {
      table.grids[k] = RangeGrid(values[k], LatentBits(latent_precision_));
    }
  }
  return table;
}

std::string Functaset::Serialize() const {
  TensorFile file(kKind);
  nlohmann::json meta;
  meta["format"] = kFormat;
  meta["version"] = kFunctasetVersion;
  meta["complete"] = complete_;
  meta["model_checksum"] = model_checksum_;
  meta["dataset"] = dataset_;
  if (!tool_symmetries_.empty()) {  // absent = no declared tools (and older files)
    meta["tool_symmetry"] = tool_symmetries_;
  }
  meta["sensors"] = nlohmann::json::array();
  for (const auto& [sensor, block] : blocks_) {
    const std::string name = ToString(sensor);
    const std::int64_t m = static_cast<std::int64_t>(block.entries.size());
    const std::int64_t d = block.latent_dim;
    const std::int64_t stored = NumStoredLatents(sensor);  // latent rows in the file
    nlohmann::json ids = nlohmann::json::array(), splits = nlohmann::json::array(),
                   tools = nlohmann::json::array(), at_rest = nlohmann::json::array();
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
      if (!IsQuantised(latent_precision_) && !e.at_rest) {
        for (Eigen::Index k = 0; k < d; ++k) latents.push_back(e.latent[k]);
      }
      if (e.at_rest) at_rest.push_back(ids.size() - 1);
      psnr.push_back(e.psnr);
    }
    meta["sensors"].push_back({{"sensor", name},
                               {"latent_dim", block.latent_dim},
                               {"fit_strategy", block.fit_strategy},
                               {"count", m},
                               {"ids", std::move(ids)},
                               {"splits", std::move(splits)},
                               {"tools", std::move(tools)}});
    if (block.products != "float") meta["sensors"].back()["products"] = block.products;
    if (block.rest_latent) {
      // The entries at rest, by index, ascending. Absent in files without a rest latent
      // (and in files older than the field).
      meta["sensors"].back()["at_rest"] = std::move(at_rest);
      file.Add(name + "/rest_latent", TensorFile::DType::kFloat32, {d},
               std::vector<double>(block.rest_latent->data(), block.rest_latent->data() + d));
    }
    if (IsQuantised(latent_precision_)) {
      const bool allocated = latent_precision_ == LatentPrecision::kAllocated;
      if (allocated && (latent_bytes_ < 1 || latent_bytes_ > MaxCodeBytes(d))) {
        throw std::invalid_argument("Functaset: " + std::to_string(latent_bytes_) +
                                    " bytes per frame for " + name + " latents of " +
                                    std::to_string(d) + " values, expected 1.." +
                                    std::to_string(MaxCodeBytes(d)) + " (" +
                                    std::to_string(kMaxCodeBits) + " bits per value at most)");
      }
      if (allocated) {
        meta["sensors"].back()["latent_bytes"] = latent_bytes_;
      } else {
        meta["sensors"].back()["latent_bits"] = LatentBits(latent_precision_);
      }
      const CodeTable table = Codes(block);
      const std::vector<int> bits = BitsOf(table.grids);
      const std::int64_t row_bytes = allocated ? latent_bytes_ : PackedBytes(bits);
      std::vector<double> codes(stored * row_bytes, 0.0);
      std::vector<std::uint32_t> q(d);
      std::int64_t row = 0;
      for (std::int64_t i = 0; i < m; ++i) {
        if (block.entries[i].at_rest) continue;
        for (std::int64_t k = 0; k < d; ++k) {
          q[k] = Quantise(block.entries[i].latent[k], table.grids[k]);
        }
        PackCodes(q, bits, codes.data() + row * row_bytes);
        ++row;
      }
      std::vector<double> offset, step;
      for (const LatentGrid& g : table.grids) offset.push_back(g.offset), step.push_back(g.step);
      if (allocated) {
        file.Add(name + "/latent_bits", TensorFile::DType::kUint8, {d},
                 std::vector<double>(bits.begin(), bits.end()));
      }
      file.Add(name + "/latent_codes", TensorFile::DType::kUint8, {stored, row_bytes},
               std::move(codes));
      file.Add(name + "/latent_offset", TensorFile::DType::kFloat32, {d}, std::move(offset));
      file.Add(name + "/latent_step", TensorFile::DType::kFloat32, {d}, std::move(step));
    } else {
      file.Add(name + "/latents",
               latent_precision_ == LatentPrecision::kFloat16 ? TensorFile::DType::kFloat16
                                                              : TensorFile::DType::kFloat32,
               {stored, d}, std::move(latents));
    }
    file.Add(name + "/psnr", TensorFile::DType::kFloat32, {m}, std::move(psnr));
    file.Add(name + "/poses", TensorFile::DType::kFloat64, {m, 4}, std::move(poses));
  }
  // A dataset path that is not UTF-8 is written with U+FFFD for its bad bytes rather
  // than failing the write after every frame was encoded.
  file.set_meta_json(meta.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace));
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
      throw fail("expected an unsigned 32-bit integer, got " + Excerpt(checksum.dump()));
    }
    out.model_checksum_ = static_cast<std::uint32_t>(checksum.get<std::uint64_t>());
    field = "dataset";
    out.dataset_ = meta.at("dataset").get<std::string>();
    if (meta.contains("tool_symmetry")) {
      field = "tool_symmetry";
      const auto& orders = meta.at("tool_symmetry");
      if (!orders.is_object()) throw fail("expected an object, got " + Excerpt(orders.dump()));
      for (const auto& [tool, order] : orders.items()) {
        field = "tool_symmetry." + tool;
        if (!order.is_number_integer() || order.get<int>() < 0 || order.get<int>() > 360) {
          throw fail("expected an integer in [0, 360], got " + Excerpt(order.dump()));
        }
        out.tool_symmetries_[tool] = order.get<int>();
      }
    }
    field = "sensors";
    const auto& sensors = meta.at("sensors");
    if (!sensors.is_array()) throw fail("expected an array, got " + Excerpt(sensors.dump()));
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
      // Frames at rest share the rest latent and have no row of their own.
      std::vector<bool> at_rest(static_cast<std::size_t>(m), false);
      std::optional<Eigen::VectorXf> rest;
      if (file.Has(name + "/rest_latent")) {
        const auto& rest_tensor = file.Get(name + "/rest_latent", {d});
        if (rest_tensor.dtype != TensorFile::DType::kFloat32) {
          field = name + "/rest_latent";
          throw fail(std::string("expected float32, got ") + ToString(rest_tensor.dtype));
        }
        rest = Eigen::VectorXf(d);
        for (int k = 0; k < d; ++k) (*rest)[k] = static_cast<float>(rest_tensor.values[k]);
        field = where + ".at_rest";
        const auto& indices = entry.at("at_rest");
        if (!indices.is_array()) throw fail("expected an array, got " + Excerpt(indices.dump()));
        std::int64_t previous = -1;
        for (std::size_t j = 0; j < indices.size(); ++j) {
          field = where + ".at_rest[" + std::to_string(j) + "]";
          const auto& index = indices[j];
          if (!index.is_number_integer() || index.get<std::int64_t>() <= previous ||
              index.get<std::int64_t>() >= m) {
            throw fail("expected an entry index in (" + std::to_string(previous) + ", " +
                       std::to_string(m) + "), ascending, got " + Excerpt(index.dump()));
          }
          previous = index.get<std::int64_t>();
          at_rest[static_cast<std::size_t>(previous)] = true;
        }
      }
      const std::int64_t stored =
          m - static_cast<std::int64_t>(std::count(at_rest.begin(), at_rest.end(), true));
      const auto& psnr = file.Get(name + "/psnr", {m});
      const auto& poses = file.Get(name + "/poses", {m, 4});
      if (psnr.dtype != TensorFile::DType::kFloat32 || poses.dtype != TensorFile::DType::kFloat64) {
        field = name + "/*";
        throw fail("expected psnr float32, poses float64");
      }
      // Float latents, or b-bit codes with their grid (told apart by the tensors present).
      LatentPrecision precision = LatentPrecision::kFloat32;
      const TensorFile::Tensor* latents = nullptr;
      const TensorFile::Tensor* codes = nullptr;
      CodeTable table;
      if (file.Has(name + "/latents")) {
        latents = &file.Get(name + "/latents", {stored, d});
        if (latents->dtype != TensorFile::DType::kFloat32 &&
            latents->dtype != TensorFile::DType::kFloat16) {
          field = name + "/latents";
          throw fail(std::string("expected float32 or float16, got ") + ToString(latents->dtype));
        }
        if (latents->dtype == TensorFile::DType::kFloat16) precision = LatentPrecision::kFloat16;
      } else {
        if (!file.Has(name + "/latent_codes")) {
          field = where + ".latent_bits";
          throw fail("tensor '" + name + "/latents' (float latents) or '" + name +
                     "/latent_codes' (b-bit codes) is missing");
        }
        std::vector<int> bits;
        std::int64_t row_bytes = 0;
        if (entry.contains("latent_bytes")) {
          precision = LatentPrecision::kAllocated;
          field = where + ".latent_bytes";
          row_bytes = entry.at("latent_bytes").get<std::int64_t>();
          if (row_bytes < 1 || row_bytes > MaxCodeBytes(d)) {
            throw fail("expected 1.." + std::to_string(MaxCodeBytes(d)) + " (" +
                       std::to_string(kMaxCodeBits) + " bits per value at most), got " +
                       std::to_string(row_bytes));
          }
          if (s > 0 && out.latent_precision_ == LatentPrecision::kAllocated &&
              row_bytes != out.latent_bytes_) {
            throw fail("expected the earlier sensor's " + std::to_string(out.latent_bytes_) +
                       ", got " + std::to_string(row_bytes));
          }
          out.latent_bytes_ = static_cast<int>(row_bytes);
          field = name + "/latent_bits";
          const auto& bits_tensor = file.Get(name + "/latent_bits", {d});
          if (bits_tensor.dtype != TensorFile::DType::kUint8) {
            throw fail(std::string("expected uint8, got ") + ToString(bits_tensor.dtype));
          }
          for (double b : bits_tensor.values) {
            if (b > kMaxCodeBits) {
              throw fail("expected bits in [0, " + std::to_string(kMaxCodeBits) + "], got " +
                         std::to_string(static_cast<int>(b)));
            }
            bits.push_back(static_cast<int>(b));
          }
          if (PackedBytes(bits) > row_bytes) {
            throw fail("the bits add up to " + std::to_string(PackedBytes(bits)) +
                       " bytes, more than latent_bytes = " + std::to_string(row_bytes));
          }
        } else {
          field = where + ".latent_bits";
          const int b = entry.at("latent_bits").get<int>();
          if (b != 8 && b != 6 && b != 4) {
            throw fail("expected 8, 6 or 4, got " + std::to_string(b));
          }
          precision = b == 8   ? LatentPrecision::kUint8
                      : b == 6 ? LatentPrecision::kUint6
                               : LatentPrecision::kUint4;
          bits.assign(d, b);
          row_bytes = PackedBytes(bits);
        }
        table.precision = precision;
        table.bytes = precision == LatentPrecision::kAllocated ? static_cast<int>(row_bytes) : 0;
        codes = &file.Get(name + "/latent_codes", {stored, row_bytes});
        const auto& offset = file.Get(name + "/latent_offset", {d});
        const auto& step = file.Get(name + "/latent_step", {d});
        field = name + "/latent_*";
        if (codes->dtype != TensorFile::DType::kUint8 ||
            offset.dtype != TensorFile::DType::kFloat32 ||
            step.dtype != TensorFile::DType::kFloat32) {
          throw fail("expected latent_codes uint8, latent_offset and latent_step float32");
        }
        table.grids.resize(d);
        for (int k = 0; k < d; ++k) {
          LatentGrid& g = table.grids[k];
          g = {static_cast<float>(offset.values[k]), static_cast<float>(step.values[k]), bits[k]};
          if (!std::isfinite(g.offset) || !(g.step >= 0) || !std::isfinite(g.step)) {
            field = name + "/latent_step[" + std::to_string(k) + "]";
            throw fail("expected a finite offset and a finite step >= 0");
          }
        }
      }
      if (s > 0 && precision != out.latent_precision_ &&
          (IsQuantised(precision) || IsQuantised(out.latent_precision_))) {
        field = where;
        throw fail(std::string("latents stored as ") + ToString(precision) +
                   ", but an earlier sensor's as " + ToString(out.latent_precision_));
      }
      if (precision != LatentPrecision::kFloat32) out.latent_precision_ = precision;
      out.AddSensor(sensor, d);
      if (entry.contains("fit_strategy")) {
        field = where + ".fit_strategy";
        out.set_fit_strategy(sensor, entry.at("fit_strategy").get<std::string>());
      }
      if (entry.contains("products")) {
        field = where + ".products";
        const std::string products = entry.at("products").get<std::string>();
        if (products != "float" && products != "bf16") {
          throw fail("expected float or bf16, got '" + products + "'");
        }
        out.set_products(sensor, products);
      }
      if (rest) out.set_rest_latent(sensor, *rest);
      std::int64_t row = 0;  // latent row of the next entry not at rest
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
        e.at_rest = at_rest[i];
        if (!e.at_rest) {
          e.latent.resize(d);
          if (latents != nullptr) {
            for (int k = 0; k < d; ++k) {
              e.latent[k] =
                  static_cast<float>(latents->values[static_cast<std::size_t>(row) * d + k]);
            }
          } else {
            const double* codes_row = codes->values.data() + row * codes->shape[1];
            std::int64_t position = 0;
            for (int k = 0; k < d; ++k) {
              const LatentGrid& g = table.grids[k];
              e.latent[k] = Dequantise(UnpackCode(codes_row, position, g.bits), g);
              position += g.bits;
            }
          }
          ++row;
        }
        e.psnr = static_cast<float>(psnr.values[i]);
        out.Add(sensor, std::move(e));
      }
      if (codes != nullptr) out.blocks_[sensor].codes = std::move(table);
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
