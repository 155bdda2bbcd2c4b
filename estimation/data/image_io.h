// Copyright 2026 The tactfunc Authors.
//
// File input and output for tactile datasets: atomic writes, and the two pixel
// encodings a tactfunc dataset stores its frames in (docs/DATASET_FORMAT.md).
//
// In memory every frame is a float `Image` in physical units:
//   - depth (Soft Bubble): metres, one channel, NaN where the pixel is invalid;
//   - rgb (GelSlim): intensities in [0, 1], three channels (or one for a grayscale
//     user folder), channel order R, G, B.
// On disk:
//   - PixelEncoding::kDepthU16Micrometres ("depth_u16_um"): a 16-bit one-channel PNG
//     holding round(depth_m * 1e6), i.e. micrometres; 0 marks an invalid pixel. The
//     representable depths are 1 um .. 65.534 mm.
//   - PixelEncoding::kRgb8 ("rgb8"): an 8-bit PNG (or, when reading user data, JPEG)
//     holding round(v * 255) clamped to [0, 255]; colour files are stored in the usual
//     file order and converted, so callers only ever see R, G, B.
// Round trips are bit-exact for values already on the quantisation grid: a frame read
// from a file, written and read again is identical, float for float.
//
// Errors: bad input (a corrupt or missing file, a value that cannot be encoded, a file
// of the wrong bit depth) raises DatasetError, whose message names the file and
// quotes what was expected and what was found. Failures of the file system while
// writing raise std::runtime_error naming the path.
#ifndef TACTFUNC_ESTIMATION_DATA_IMAGE_IO_H_
#define TACTFUNC_ESTIMATION_DATA_IMAGE_IO_H_

#include <cstdint>
#include <stdexcept>
#include <string>

#include "models/core/atomic_file.h"
#include "models/core/image.h"

namespace tactfunc {

// Raised for every bad input met while reading or writing a dataset: missing or
// corrupt files, malformed labels.csv lines, inconsistent metadata, values that cannot
// be encoded. The message names the file (and line or field where there is one), what
// was expected and what was found. Declared here (and available through
// estimation/data/dataset.h) because the image readers below raise it too.
class DatasetError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// WriteFileAtomically and Durability come from models/core/atomic_file.h.

// The whole file as bytes. Throws DatasetError (a std::runtime_error) naming `path`
// if it does not exist or cannot be read.
std::string ReadFile(const std::string& path);

enum class PixelEncoding {
  kDepthU16Micrometres,  // "depth_u16_um": 16-bit PNG, micrometres, 0 = invalid
  kRgb8,                 // "rgb8": 8-bit PNG/JPEG, intensity * 255
};
const char* ToString(PixelEncoding encoding);
// Parses "depth_u16_um" or "rgb8"; returns false and leaves *encoding untouched
// otherwise.
bool PixelEncodingFromString(const std::string& name, PixelEncoding* encoding);

// Encodes `image` as PNG bytes. compression_level: zlib level in [0, 9]; level 1
// (the default) uses Huffman-only coding, which is both faster and smaller than LZ77
// on noisy sensor frames; std::invalid_argument outside [0, 9]. Throws DatasetError if a value cannot be encoded:
//   depth: one channel; finite values must round to [1, 65534] um (a depth below
//          0.5 um would read back as invalid, one of 65.5345 mm or more does not fit);
//          NaN is written as 0 (invalid); +-inf is an error.
//   rgb8:  one or three channels; values are clamped to [0, 1]; NaN is an error (the
//          encoding has no invalid marker).
std::string EncodePng(const Image& image, PixelEncoding encoding, int compression_level = 1);

// EncodePng + WriteFileAtomically; encoding errors name `path`.
void WritePngAtomically(const std::string& path, const Image& image, PixelEncoding encoding,
                        int compression_level = 1,
                        Durability durability = Durability::kSynced);

// The most pixels (rows * cols) a frame may have: 4096 x 4096. Every image's header is
// read and checked against it before any pixel is decoded, so an oversized or hostile
// file is refused in a few kilobytes of memory.
inline constexpr std::int64_t kMaxFramePixels = std::int64_t{4096} * 4096;

// What an image file's header says, read without decoding any pixel.
struct ImageHeader {
  enum class Format { kPng, kJpeg };
  Format format = Format::kPng;
  int rows = 0;
  int cols = 0;
  // Samples per pixel as stored: PNG gray 1, gray+alpha 2, palette/RGB 3, RGBA 4;
  // JPEG its component count.
  int channels = 0;
  int bit_depth = 0;  // bits per sample as stored (PNG 1, 2, 4, 8 or 16; JPEG 8 or 12)
};

// Reads the header of a PNG or JPEG file: PNG's IHDR chunk, or the JPEG segments up to
// the first start-of-frame marker (skipped by their lengths, never loaded whole). Throws
// DatasetError naming `path` for another format, a damaged header, or a size beyond
// kMaxFramePixels ("... 20000x20000 pixels, more than the 16777216 a frame may have").
ImageHeader ReadImageHeader(const std::string& path);
// As ReadImageHeader, from the file's bytes in memory; `name` is used in messages.
ImageHeader ParseImageHeader(const std::string& bytes, const std::string& name);

// Decodes an image file (PNG, or JPEG for rgb8) into physical units (see above).
// Throws DatasetError naming `path` if the file is missing, not an image, or of the
// wrong kind: depth needs a 16-bit one-channel PNG; rgb8 needs 8 bits and 1, 3 or 4
// channels (an alpha channel is dropped). The header is read first (ReadImageHeader):
// a frame beyond kMaxFramePixels is refused before its file is read.
Image ReadImage(const std::string& path, PixelEncoding encoding);

// As ReadImage, from bytes already in memory; `name` is used in error messages.
Image DecodeImage(const std::string& bytes, PixelEncoding encoding, const std::string& name);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_DATA_IMAGE_IO_H_
