// Copyright 2026 The tactfunc Authors.
//
// NumPy .npy files of float32 arrays, to hand tactfunc's data to NumPy and PyTorch
// (`np.load(path)`). Format version 1.0:
//
//   "\x93NUMPY" 0x01 0x00           magic, major and minor version
//   uint16 little-endian HLEN       length of the header text that follows
//   "{'descr': '<f4', 'fortran_order': False, 'shape': (2, 3), }"
//                                   padded with spaces and ended by '\n' so that
//                                   10 + HLEN is a multiple of 64 (the data aligned)
//   the values, little-endian float32, C order (the last index fastest)
//
// A one-dimensional shape is written "(n,)" and a zero-dimensional one "()", as NumPy
// writes them.
#ifndef TACTFUNC_ESTIMATION_DATA_NPY_WRITER_H_
#define TACTFUNC_ESTIMATION_DATA_NPY_WRITER_H_

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "models/core/atomic_file.h"

namespace tactfunc {

// The header (magic through the '\n') of a float32 C-order array of `shape`: a multiple
// of 64 bytes. Throws std::invalid_argument for a negative dimension or a header longer
// than version 1.0 allows (65535 bytes of text).
std::string NpyFloat32Header(const std::vector<std::int64_t>& shape);

// The whole file: the header and `count` values as little-endian float32. Throws
// std::invalid_argument if `count` is not the product of `shape`.
std::string NpyFloat32Bytes(const std::vector<std::int64_t>& shape, const float* values,
                            std::size_t count);

// Writes NpyFloat32Bytes to `path` atomically (WriteFileAtomically): a reader sees the
// old file or the whole new one. Throws like both.
void WriteNpyFloat32(const std::string& path, const std::vector<std::int64_t>& shape,
                     const float* values, std::size_t count,
                     Durability durability = Durability::kSynced);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_DATA_NPY_WRITER_H_
