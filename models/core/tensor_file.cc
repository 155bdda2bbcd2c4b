// Copyright 2026 The tactfunc Authors.
#include "models/core/tensor_file.h"

#include "models/core/atomic_file.h"
#include "models/core/text_limits.h"

#include <atomic>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <Eigen/Core>
#include <boost/crc.hpp>

#include "nlohmann/json.hpp"

namespace tactfunc {
namespace {

constexpr char kMagic[8] = {'T', 'A', 'C', 'T', 'F', 'U', 'N', 'C'};
constexpr std::size_t kFixedHeader = 24;

template <typename T>
void PutLittle(std::string* out, T value) {
  static_assert(std::is_integral_v<T>);
  for (std::size_t i = 0; i < sizeof(T); ++i) {
    out->push_back(static_cast<char>((static_cast<std::uint64_t>(value) >> (8 * i)) & 0xff));
  }
}

template <typename T>
T GetLittle(const std::string& bytes, std::size_t offset) {
  std::uint64_t value = 0;
  for (std::size_t i = 0; i < sizeof(T); ++i) {
    value |= static_cast<std::uint64_t>(static_cast<unsigned char>(bytes[offset + i]))
             << (8 * i);
  }
  return static_cast<T>(value);
}

std::uint16_t HalfBits(double v) {
  return Eigen::numext::bit_cast<std::uint16_t>(Eigen::half(static_cast<float>(v)));
}

double FromHalfBits(std::uint16_t bits) {
  return static_cast<float>(Eigen::numext::bit_cast<Eigen::half>(bits));
}

// The largest dimension or element count a tensor may declare: 2^48, far above any
// real tensor and low enough that products of counts and element sizes cannot overflow.
constexpr std::uint64_t kMaxCount = std::uint64_t{1} << 48;

// A header field that must be a non-negative integer of at most `max` (JSON integers
// only: 1.0, -1 or 1e21 are refused rather than cast). Returns false otherwise.
bool ReadCount(const nlohmann::json& value, std::uint64_t max, std::uint64_t* out) {
  if (value.is_number_unsigned()) {
    *out = value.get<std::uint64_t>();
  } else if (value.is_number_integer()) {
    const std::int64_t v = value.get<std::int64_t>();
    if (v < 0) return false;
    *out = static_cast<std::uint64_t>(v);
  } else {
    return false;
  }
  return *out <= max;
}

// A JSON value quoted in an error message: at most kMaxQuotedBytes of its text.
std::string Quote(const nlohmann::json& value) {
  return Excerpt(value.is_string() ? "\"" + value.get<std::string>() + "\"" : value.dump());
}

std::string ShapeString(const std::vector<std::int64_t>& shape) {
  std::string s = "[";
  for (std::size_t i = 0; i < shape.size(); ++i) {
    s += (i ? ", " : "") + std::to_string(shape[i]);
  }
  return s + "]";
}

}  // namespace

std::uint32_t Crc32(const void* data, std::size_t size) {
  boost::crc_32_type crc;
  crc.process_bytes(data, size);
  return crc.checksum();
}

std::int64_t TensorFile::Tensor::numel() const {
  std::int64_t n = 1;
  for (std::int64_t d : shape) n *= d;
  return n;
}

std::size_t ElementBytes(TensorFile::DType dtype) {
  switch (dtype) {
    case TensorFile::DType::kUint8:
      return 1;
    case TensorFile::DType::kFloat16:
      return 2;
    case TensorFile::DType::kFloat32:
      return 4;
    case TensorFile::DType::kFloat64:
      return 8;
  }
  return 8;
}

const char* ToString(TensorFile::DType dtype) {
  switch (dtype) {
    case TensorFile::DType::kUint8:
      return "uint8";
    case TensorFile::DType::kFloat16:
      return "float16";
    case TensorFile::DType::kFloat32:
      return "float32";
    case TensorFile::DType::kFloat64:
      return "float64";
  }
  return "unknown";
}

void TensorFile::set_meta_json(const std::string& json) {
  nlohmann::json parsed;
  try {
    parsed = nlohmann::json::parse(json);
  } catch (const std::exception& e) {
    throw TensorFileError("TensorFile meta is not valid JSON: " + std::string(e.what()));
  }
  if (!parsed.is_object()) throw TensorFileError("TensorFile meta must be a JSON object");
  meta_json_ = parsed.dump();
}

void TensorFile::Add(const std::string& name, DType dtype,
                     std::vector<std::int64_t> shape, std::vector<double> values) {
  if (Has(name)) throw std::invalid_argument("TensorFile: duplicate tensor '" + name + "'");
  Tensor tensor;
  tensor.name = name;
  tensor.dtype = dtype;
  tensor.shape = std::move(shape);
  for (std::int64_t d : tensor.shape) {
    if (d < 0) throw std::invalid_argument("TensorFile: negative dimension in '" + name + "'");
  }
  if (tensor.numel() != static_cast<std::int64_t>(values.size())) {
    throw std::invalid_argument("TensorFile: tensor '" + name + "' has shape " +
                                ShapeString(tensor.shape) + " but " +
                                std::to_string(values.size()) + " values");
  }
  if (dtype == DType::kFloat32) {
    for (double& v : values) v = static_cast<float>(v);
  } else if (dtype == DType::kFloat16) {
    for (double& v : values) v = FromHalfBits(HalfBits(v));
  }
  tensor.values = std::move(values);
  tensors_.push_back(std::move(tensor));
}

bool TensorFile::Has(const std::string& name) const {
  for (const Tensor& t : tensors_) {
    if (t.name == name) return true;
  }
  return false;
}

const TensorFile::Tensor& TensorFile::Get(const std::string& name) const {
  for (const Tensor& t : tensors_) {
    if (t.name == name) return t;
  }
  throw TensorFileError((source_.empty() ? std::string("tensor file") : source_) +
                        ": missing tensor '" + name + "'");
}

const TensorFile::Tensor& TensorFile::Get(
    const std::string& name, const std::vector<std::int64_t>& expected_shape) const {
  const Tensor& t = Get(name);
  if (t.shape != expected_shape) {
    throw TensorFileError((source_.empty() ? std::string("tensor file") : source_) +
                          ": tensor '" + name + "' has shape " + ShapeString(t.shape) +
                          ", expected " + ShapeString(expected_shape));
  }
  return t;
}

std::string TensorFile::Serialize() const {
  nlohmann::json header;
  header["kind"] = kind_;
  header["meta"] = nlohmann::json::parse(meta_json_);
  header["tensors"] = nlohmann::json::array();
  std::uint64_t offset = 0;
  for (const Tensor& t : tensors_) {
    const std::uint64_t bytes = t.numel() * ElementBytes(t.dtype);
    header["tensors"].push_back({{"name", t.name},
                                 {"dtype", ToString(t.dtype)},
                                 {"shape", t.shape},
                                 {"offset", offset},
                                 {"bytes", bytes}});
    offset += (bytes + 7) / 8 * 8;
  }
  const std::string json = header.dump();
  std::string out(kMagic, kMagic + 8);
  PutLittle<std::uint32_t>(&out, kTensorFileVersion);
  PutLittle<std::uint32_t>(&out, 0);
  PutLittle<std::uint64_t>(&out, json.size());
  out += json;
  const std::size_t payload = out.size();
  out.resize(payload + offset, '\0');
  std::uint64_t at = 0;
  for (const Tensor& t : tensors_) {
    char* dst = out.data() + payload + at;
    if (t.dtype == DType::kUint8) {
      for (std::size_t i = 0; i < t.values.size(); ++i) {
        const double v = t.values[i];
        if (!(v >= 0 && v <= 255 && v == std::floor(v))) {
          throw std::invalid_argument("TensorFile: uint8 tensor '" + t.name + "' element " +
                                      std::to_string(i) + " is " + std::to_string(v) +
                                      ", expected an integer in [0, 255]");
        }
        *dst++ = static_cast<char>(static_cast<unsigned char>(v));
      }
    } else if (t.dtype == DType::kFloat16) {
      for (double v : t.values) {
        const std::uint16_t bits = HalfBits(v);
        *dst++ = static_cast<char>(bits & 0xff);
        *dst++ = static_cast<char>(bits >> 8);
      }
    } else if (t.dtype == DType::kFloat32) {
      for (double v : t.values) {
        const float f = static_cast<float>(v);
        std::uint32_t bits;
        std::memcpy(&bits, &f, 4);
        for (int i = 0; i < 4; ++i) *dst++ = static_cast<char>((bits >> (8 * i)) & 0xff);
      }
    } else {
      for (double v : t.values) {
        std::uint64_t bits;
        std::memcpy(&bits, &v, 8);
        for (int i = 0; i < 8; ++i) *dst++ = static_cast<char>((bits >> (8 * i)) & 0xff);
      }
    }
    at += (t.numel() * ElementBytes(t.dtype) + 7) / 8 * 8;
  }
  checksum_ = Crc32(out.data(), out.size());
  PutLittle<std::uint32_t>(&out, checksum_);
  return out;
}

TensorFile TensorFile::Parse(const std::string& bytes, const std::string& source,
                             const std::string& expected_kind) {
  auto fail = [&](const std::string& what) -> TensorFileError {
    return TensorFileError(source + ": " + what);
  };
  if (bytes.size() < kFixedHeader + 4) {
    throw fail("truncated: " + std::to_string(bytes.size()) +
               " bytes is shorter than any tactfunc file");
  }
  if (std::memcmp(bytes.data(), kMagic, 8) != 0) {
    throw fail("not a tactfunc file (expected the magic bytes \"TACTFUNC\")");
  }
  const auto version = GetLittle<std::uint32_t>(bytes, 8);
  if (version != kTensorFileVersion) {
    throw fail("container version " + std::to_string(version) + ", this build reads version " +
               std::to_string(kTensorFileVersion));
  }
  const auto stored = GetLittle<std::uint32_t>(bytes, bytes.size() - 4);
  const std::uint32_t actual = Crc32(bytes.data(), bytes.size() - 4);
  const auto json_length = GetLittle<std::uint64_t>(bytes, 16);
  if (json_length > bytes.size() - kFixedHeader - 4) {
    throw fail("truncated or corrupt: the header claims " + std::to_string(json_length) +
               " bytes of JSON but the file has " + std::to_string(bytes.size()));
  }
  if (stored != actual) {
    char text[96];
    std::snprintf(text, sizeof(text), "checksum mismatch (stored %08x, computed %08x)",
                  stored, actual);
    throw fail(std::string(text) + ": the file is corrupt or truncated");
  }
  const std::string_view json_text(bytes.data() + kFixedHeader, json_length);
  if (JsonNestingDepth(json_text) > kMaxJsonDepth) {
    throw fail("header: expected JSON nested at most " + std::to_string(kMaxJsonDepth) +
               " levels deep, got deeper nesting");
  }
  nlohmann::json header;
  try {
    header = nlohmann::json::parse(json_text.begin(), json_text.end());
  } catch (const std::exception& e) {
    throw fail("header is not valid JSON: " + Excerpt(e.what()));
  }
  TensorFile file;
  file.source_ = source;
  try {
    if (!header.is_object()) throw fail("header: expected a JSON object, got " + Quote(header));
    if (!header.at("kind").is_string()) {
      throw fail("header field 'kind': expected a string, got " + Quote(header.at("kind")));
    }
    file.kind_ = header.at("kind").get<std::string>();
    if (!header.at("meta").is_object()) {
      throw fail("header field 'meta': expected a JSON object, got " + Quote(header.at("meta")));
    }
    file.meta_json_ = header.at("meta").dump();
    if (!expected_kind.empty() && file.kind_ != expected_kind) {
      throw fail("is a '" + Excerpt(file.kind_) + "' file, expected a '" + expected_kind +
                 "' file");
    }
    const std::size_t payload = kFixedHeader + json_length;
    const std::size_t payload_bytes = bytes.size() - 4 - payload;
    if (!header.at("tensors").is_array()) {
      throw fail("header field 'tensors': expected an array, got " + Quote(header.at("tensors")));
    }
    for (const auto& entry : header.at("tensors")) {
      Tensor t;
      if (!entry.is_object() || !entry.at("name").is_string()) {
        throw fail("header field 'tensors': expected objects with a string 'name', got " +
                   Quote(entry));
      }
      t.name = entry.at("name").get<std::string>();
      const std::string where = "tensor '" + Excerpt(t.name) + "'";
      if (!entry.at("dtype").is_string()) {
        throw fail(where + ": field 'dtype': expected a string, got " + Quote(entry.at("dtype")));
      }
      const std::string dtype = entry.at("dtype").get<std::string>();
      if (dtype == "float32") {
        t.dtype = DType::kFloat32;
      } else if (dtype == "float64") {
        t.dtype = DType::kFloat64;
      } else if (dtype == "float16") {
        t.dtype = DType::kFloat16;
      } else if (dtype == "uint8") {
        t.dtype = DType::kUint8;
      } else {
        throw fail(where + ": dtype '" + Excerpt(dtype) +
                   "', expected uint8, float16, float32 or float64");
      }
      const nlohmann::json& shape = entry.at("shape");
      if (!shape.is_array() || shape.size() > 32) {
        throw fail(where + ": field 'shape': expected an array of at most 32 dimensions, got " +
                   Quote(shape));
      }
      // Every count is checked before it is converted or multiplied: no float-to-integer
      // cast of an out-of-range value, no overflow.
      std::uint64_t numel = 1;
      for (const nlohmann::json& dim : shape) {
        std::uint64_t d = 0;
        if (!ReadCount(dim, kMaxCount, &d)) {
          throw fail(where + ": field 'shape': expected integers in [0, 2^48], got " +
                     Quote(dim));
        }
        if (d != 0 && numel > kMaxCount / d) {
          throw fail(where + ": field 'shape': " + Quote(shape) + " holds more than 2^48 elements");
        }
        numel *= d;
        t.shape.push_back(static_cast<std::int64_t>(d));
      }
      std::uint64_t offset = 0;
      if (!ReadCount(entry.at("offset"), kMaxCount, &offset)) {
        throw fail(where + ": field 'offset': expected an integer in [0, 2^48], got " +
                   Quote(entry.at("offset")));
      }
      const std::uint64_t size = numel * ElementBytes(t.dtype);
      if (offset > payload_bytes || size > payload_bytes - offset) {
        throw fail(where + " (" + std::to_string(size) + " bytes at " + std::to_string(offset) +
                   ") lies outside the " + std::to_string(payload_bytes) + "-byte payload");
      }
      t.values.resize(numel);
      const char* src = bytes.data() + payload + offset;
      for (auto& v : t.values) {
        if (t.dtype == DType::kUint8) {
          v = static_cast<unsigned char>(*src++);
        } else if (t.dtype == DType::kFloat16) {
          std::uint16_t bits = static_cast<unsigned char>(*src++);
          bits |= static_cast<std::uint16_t>(static_cast<unsigned char>(*src++)) << 8;
          v = FromHalfBits(bits);
        } else if (t.dtype == DType::kFloat32) {
          std::uint32_t bits = 0;
          for (int i = 0; i < 4; ++i) bits |= static_cast<std::uint32_t>(static_cast<unsigned char>(*src++)) << (8 * i);
          float f;
          std::memcpy(&f, &bits, 4);
          v = f;
        } else {
          std::uint64_t bits = 0;
          for (int i = 0; i < 8; ++i) bits |= static_cast<std::uint64_t>(static_cast<unsigned char>(*src++)) << (8 * i);
          std::memcpy(&v, &bits, 8);
        }
      }
      if (file.Has(t.name)) throw fail("duplicate " + where);
      file.tensors_.push_back(std::move(t));
    }
  } catch (const nlohmann::json::exception& e) {
    throw fail(std::string("header misses a field or has the wrong type: ") + Excerpt(e.what()));
  }
  file.checksum_ = actual;
  return file;
}

void TensorFile::CheckFormat(const std::string& format, int version) const {
  const std::string where = source_.empty() ? std::string("tensor file") : source_;
  const nlohmann::json meta = nlohmann::json::parse(meta_json_);
  if (!meta.contains("format") || !meta["format"].is_string()) {
    throw TensorFileError(where + ": field 'format' is missing; expected \"" + format + "\"");
  }
  if (meta["format"].get<std::string>() != format) {
    throw TensorFileError(where + ": field 'format': expected \"" + format + "\", got " +
                          Quote(meta["format"]));
  }
  if (!meta.contains("version") || !meta["version"].is_number_integer()) {
    throw TensorFileError(where + ": field 'version' is missing; expected " +
                          std::to_string(version));
  }
  const int found = meta["version"].get<int>();
  if (found != version) {
    throw TensorFileError(where + ": field 'version': " + format + " version " +
                          std::to_string(found) + ", this build reads version " +
                          std::to_string(version));
  }
}

void TensorFile::Write(const std::string& path) const {
  WriteFileAtomically(path, Serialize());
  source_ = path;
}

TensorFile TensorFile::Read(const std::string& path, const std::string& expected_kind) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw TensorFileError(path + ": cannot open (does it exist?)");
  std::ostringstream buffer;
  buffer << in.rdbuf();
  return Parse(buffer.str(), path, expected_kind);
}

}  // namespace tactfunc
