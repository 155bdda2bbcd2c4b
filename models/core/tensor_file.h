// Copyright 2026 The tactfunc Authors.
//
// TensorFile: the versioned, checksummed container behind tactfunc's model files
// (.tfm) and functaset files (.tfs).
//
// Layout (all integers little-endian):
//   offset  size  field
//   0       8     magic "TACTFUNC"
//   8       4     u32 container version (kTensorFileVersion)
//   12      4     u32 reserved (0)
//   16      8     u64 J, length of the JSON header
//   24      J     JSON header (UTF-8): {"kind": "model"|"functaset"|..., "meta": {...},
//                   "tensors": [{"name": s, "dtype": "float32"|"float64",
//                                "shape": [d0, d1, ...], "offset": o, "bytes": b}, ...]}
//                   (dtype also "float16" or "uint8")
//   24+J    P     payload: the tensors, row-major (C order), each starting at
//                 `offset` bytes into the payload (8-byte aligned)
//   24+J+P  4     u32 CRC-32 (zlib's polynomial) of every byte before it
//
// Reading it from Python with numpy:
//   import json, struct, zlib, numpy as np
//   b = open("model.tfm", "rb").read()
//   assert b[:8] == b"TACTFUNC" and zlib.crc32(b[:-4]) == struct.unpack("<I", b[-4:])[0]
//   (n,) = struct.unpack("<Q", b[16:24]); head = json.loads(b[24:24 + n]); p = 24 + n
//   t = {d["name"]: np.frombuffer(b, d["dtype"], int(np.prod(d["shape"])), p + d["offset"])
//        .reshape(d["shape"]) for d in head["tensors"]}
//
// Files are written atomically (temporary file, then rename). Reading checks the
// magic, the version, the kind, the JSON, every tensor's extent and the checksum, and
// raises TensorFileError naming the file and what is wrong: a truncated, corrupt or
// foreign file is never half-read.
#ifndef TACTFUNC_MODELS_CORE_TENSOR_FILE_H_
#define TACTFUNC_MODELS_CORE_TENSOR_FILE_H_

#include <cstddef>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <vector>

namespace tactfunc {

inline constexpr std::uint32_t kTensorFileVersion = 1;

class TensorFileError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class TensorFile {
 public:
  // float16: IEEE binary16 (numpy's float16), e.g. a functaset's latents at half the
  // bytes; values are rounded to nearest-even when added.
  // uint8: one unsigned byte per element (numpy's uint8), e.g. a functaset's packed
  // latent codes. In memory the values are doubles holding integers 0..255; Serialize
  // throws std::invalid_argument naming the tensor for any other value.
  enum class DType { kFloat32, kFloat64, kFloat16, kUint8 };
  struct Tensor {
    std::string name;
    DType dtype = DType::kFloat32;
    std::vector<std::int64_t> shape;
    std::vector<double> values;  // row-major; float32 tensors are stored rounded
    std::int64_t numel() const;
  };

  TensorFile() = default;
  explicit TensorFile(std::string kind) : kind_(std::move(kind)) {}

  const std::string& kind() const { return kind_; }
  // The "meta" object of the JSON header, as JSON text (default "{}").
  const std::string& meta_json() const { return meta_json_; }
  // Throws TensorFileError if `json` is not a JSON object.
  void set_meta_json(const std::string& json);

  // Adds a tensor; throws std::invalid_argument if the name exists or the shape does
  // not match values.size().
  void Add(const std::string& name, DType dtype, std::vector<std::int64_t> shape,
           std::vector<double> values);
  bool Has(const std::string& name) const;
  // Throws TensorFileError naming the file and the missing tensor.
  const Tensor& Get(const std::string& name) const;
  // Get() that also checks the shape; throws TensorFileError quoting both shapes.
  const Tensor& Get(const std::string& name,
                    const std::vector<std::int64_t>& expected_shape) const;
  const std::vector<Tensor>& tensors() const { return tensors_; }

  std::string Serialize() const;
  // Parses bytes read from `source` (a path, used in messages). If `expected_kind` is
  // not empty the file must be of that kind.
  static TensorFile Parse(const std::string& bytes, const std::string& source,
                          const std::string& expected_kind = "");

  void Write(const std::string& path) const;  // atomically
  static TensorFile Read(const std::string& path, const std::string& expected_kind = "");

  // Checks the "format" and "version" fields of the meta object, which every tactfunc
  // file kind carries (e.g. "tactfunc-model", 1). Throws TensorFileError naming the
  // source and the field: a missing field, another format, another version.
  void CheckFormat(const std::string& format, int version) const;

  // CRC-32 of the file as last written or read (0 before either): the identity by which
  // a functaset names the model it belongs to.
  std::uint32_t checksum() const { return checksum_; }
  const std::string& source() const { return source_; }

 private:
  std::string kind_;
  std::string meta_json_ = "{}";
  std::vector<Tensor> tensors_;
  mutable std::uint32_t checksum_ = 0;
  mutable std::string source_;
};

const char* ToString(TensorFile::DType dtype);
// Bytes one element of `dtype` takes in the file: 1, 2, 4 or 8.
std::size_t ElementBytes(TensorFile::DType dtype);

// CRC-32 (zlib's polynomial 0xEDB88320), as Python's zlib.crc32.
std::uint32_t Crc32(const void* data, std::size_t size);

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_CORE_TENSOR_FILE_H_
