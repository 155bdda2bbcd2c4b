// Copyright 2026 The tactfunc Authors.
#include "estimation/data/npy_writer.h"

#include <cstring>
#include <stdexcept>

namespace tactfunc {
namespace {

constexpr char kMagic[] = "\x93NUMPY";
constexpr std::size_t kMagicBytes = 6;
constexpr std::size_t kPreamble = kMagicBytes + 2 + 2;  // magic, version, HLEN
constexpr std::size_t kAlignment = 64;

std::string ShapeText(const std::vector<std::int64_t>& shape) {
  std::string text = "(";
  for (std::size_t i = 0; i < shape.size(); ++i) {
    if (i > 0) text += ", ";
    text += std::to_string(shape[i]);
  }
  if (shape.size() == 1) text += ",";
  return text + ")";
}

bool HostIsLittleEndian() {
  const std::uint32_t one = 1;
  unsigned char first;
  std::memcpy(&first, &one, 1);
  return first == 1;
}

}  // namespace

std::string NpyFloat32Header(const std::vector<std::int64_t>& shape) {
  for (std::size_t i = 0; i < shape.size(); ++i) {
    if (shape[i] < 0) {
      throw std::invalid_argument("NpyFloat32Header: shape[" + std::to_string(i) +
                                  "]: expected a size >= 0, got " + std::to_string(shape[i]));
    }
  }
  std::string dict = "{'descr': '<f4', 'fortran_order': False, 'shape': " + ShapeText(shape) +
                     ", }";
  // Spaces, then '\n', up to the next multiple of 64 bytes of the whole header.
  const std::size_t unpadded = kPreamble + dict.size() + 1;
  dict.append((kAlignment - unpadded % kAlignment) % kAlignment, ' ');
  dict += '\n';
  if (dict.size() > 0xffff) {
    throw std::invalid_argument("NpyFloat32Header: expected a header of at most 65535 bytes "
                                "(.npy version 1.0), got " + std::to_string(dict.size()) +
                                " for shape " + ShapeText(shape));
  }
  std::string header(kMagic, kMagicBytes);
  header += static_cast<char>(1);  // major version
  header += static_cast<char>(0);  // minor version
  header += static_cast<char>(dict.size() & 0xff);
  header += static_cast<char>((dict.size() >> 8) & 0xff);
  return header + dict;
}

std::string NpyFloat32Bytes(const std::vector<std::int64_t>& shape, const float* values,
                            std::size_t count) {
  std::string bytes = NpyFloat32Header(shape);
  std::size_t expected = 1;
  for (std::int64_t n : shape) expected *= static_cast<std::size_t>(n);
  if (count != expected) {
    throw std::invalid_argument("NpyFloat32Bytes: expected " + std::to_string(expected) +
                                " values for shape " + ShapeText(shape) + ", got " +
                                std::to_string(count));
  }
  const std::size_t start = bytes.size();
  bytes.resize(start + count * 4);
  char* out = bytes.data() + start;
  if (HostIsLittleEndian()) {
    if (count > 0) std::memcpy(out, values, count * 4);
  } else {
    for (std::size_t i = 0; i < count; ++i) {
      std::uint32_t bits;
      std::memcpy(&bits, &values[i], 4);
      for (int b = 0; b < 4; ++b) *out++ = static_cast<char>((bits >> (8 * b)) & 0xff);
    }
  }
  return bytes;
}

void WriteNpyFloat32(const std::string& path, const std::vector<std::int64_t>& shape,
                     const float* values, std::size_t count, Durability durability) {
  WriteFileAtomically(path, NpyFloat32Bytes(shape, values, count), durability);
}

}  // namespace tactfunc
