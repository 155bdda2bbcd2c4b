// Copyright 2026 The tactfunc Authors.
#include "estimation/data/image_io.h"

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <limits>
#include <opencv2/core.hpp>
#include <sstream>
#include <vector>

#include "estimation/data/codecs.h"
#include "estimation/data/internal/path_util.h"
#include "estimation/data/internal/png_reader.h"
#include "estimation/data/internal/png_writer.h"
#include "estimation/data/internal/opencv_image.h"

namespace tactfunc {
namespace {

// Micrometres per metre of the depth encoding.
constexpr double kMicrometresPerMetre = 1e6;
// 0 marks invalid pixels and 65535 is kept out of use (the format's bound: a depth of
// 65.535 mm or more is an error), so valid codes are [1, 65534].
constexpr double kMaxDepthCode = 65534.0;

std::string ErrnoText() { return std::strerror(errno); }

std::string ValueText(float v) { return internal::FormatDoubleShort(v); }

std::string PixelText(const Image& image, std::size_t i) {
  const std::size_t pixel = i / image.channels;
  return "pixel (row " + std::to_string(pixel / image.cols) + ", col " +
         std::to_string(pixel % image.cols) + ")";
}

// Encodes, naming `name` in errors (the path, or "image" for EncodePng).
std::string EncodePngNamed(const Image& image, PixelEncoding encoding, int compression_level,
                           const std::string& name) {
  if (compression_level < 0 || compression_level > 9) {
    throw std::invalid_argument("EncodePng: compression_level must be in [0, 9], got " +
                                std::to_string(compression_level));
  }
  if (image.rows <= 0 || image.cols <= 0 || image.size() != image.pixels() * image.channels) {
    throw DatasetError(name +
                       ": expected a non-empty image with rows*cols*channels "
                       "values, got shape " +
                       image.ShapeString() + " holding " + std::to_string(image.size()) +
                       " values");
  }
  cv::Mat mat;
  if (encoding == PixelEncoding::kDepthU16Micrometres) {
    if (image.channels != 1) {
      throw DatasetError(name + ": depth_u16_um expects 1 channel, got " +
                         std::to_string(image.channels));
    }
    mat.create(image.rows, image.cols, CV_16UC1);
    auto* out = mat.ptr<std::uint16_t>(0);  // continuous: freshly allocated
    for (std::size_t i = 0; i < image.size(); ++i) {
      const float v = image.data[i];
      if (std::isnan(v)) {
        out[i] = 0;
        continue;
      }
      const double code = std::round(static_cast<double>(v) * kMicrometresPerMetre);
      if (!(code >= 1.0 && code <= kMaxDepthCode)) {
        throw DatasetError(name + ": depth_u16_um: " + PixelText(image, i) +
                           ": expected a depth in [0.5e-6, 0.0655345) m (or NaN for "
                           "invalid), got " +
                           ValueText(v) + " m");
      }
      out[i] = static_cast<std::uint16_t>(code);
    }
  } else {
    if (image.channels != 1 && image.channels != 3) {
      throw DatasetError(name + ": rgb8 expects 1 or 3 channels, got " +
                         std::to_string(image.channels));
    }
    mat.create(image.rows, image.cols, CV_8UC(image.channels));
    auto* out = mat.ptr<std::uint8_t>(0);
    // One branch-free pass (it vectorises), then the NaN check on the rare failure:
    // rounding half up equals std::round for the non-negative codes, and NaN compares
    // false both ways so it is caught below.
    bool any_nan = false;
    for (std::size_t i = 0; i < image.size(); ++i) {
      const float v = image.data[i];
      any_nan |= (v != v);
      const float code = std::min(std::max(v * 255.0f, 0.0f), 255.0f) + 0.5f;
      out[i] = static_cast<std::uint8_t>(static_cast<int>(code));
    }
    if (any_nan) {
      for (std::size_t i = 0; i < image.size(); ++i) {
        if (std::isnan(image.data[i])) {
          throw DatasetError(name + ": rgb8: " + PixelText(image, i) +
                             ": expected an intensity in [0, 1], got NaN (rgb8 has no "
                             "invalid marker)");
        }
      }
    }
  }
  // mat holds the samples in R, G, B order (libpng's order), continuous.
  try {
    return internal::EncodePngSamples(mat.data, image.rows, image.cols, image.channels,
                                      mat.depth() == CV_16U ? 16 : 8, compression_level);
  } catch (const std::runtime_error& e) {
    throw DatasetError(name + ": " + e.what());
  }
}

const char* DepthName(int depth) {
  switch (depth) {
    case CV_8U:
      return "8-bit unsigned";
    case CV_8S:
      return "8-bit signed";
    case CV_16U:
      return "16-bit unsigned";
    case CV_16S:
      return "16-bit signed";
    case CV_32S:
      return "32-bit integer";
    case CV_32F:
      return "32-bit float";
    case CV_64F:
      return "64-bit float";
    default:
      return "unusual bit depth";
  }
}

// Reads `n` bytes at `offset` of an image file; false if the file is shorter.
using ByteSource = std::function<bool(std::uint64_t offset, std::size_t n, std::uint8_t* out)>;

std::uint32_t BigEndian(const std::uint8_t* p, int n) {
  std::uint32_t v = 0;
  for (int i = 0; i < n; ++i) v = (v << 8) | p[i];
  return v;
}

ImageHeader CheckedHeader(ImageHeader header, const std::string& name) {
  if (header.rows <= 0 || header.cols <= 0) {
    throw DatasetError(name + ": expected an image of at least 1x1 pixels, got a header "
                              "claiming " + std::to_string(header.cols) + "x" +
                       std::to_string(header.rows));
  }
  const std::int64_t pixels = static_cast<std::int64_t>(header.rows) * header.cols;
  if (pixels > kMaxFramePixels) {
    throw DatasetError(name + ": expected a frame of at most " +
                       std::to_string(kMaxFramePixels) + " pixels (4096x4096), got a header "
                       "claiming " + std::to_string(header.cols) + "x" +
                       std::to_string(header.rows) + " (width x height) = " +
                       std::to_string(pixels) + " pixels; refused before decoding");
  }
  return header;
}

ImageHeader ParseHeader(const ByteSource& read, const std::string& name) {
  std::uint8_t head[33];
  static constexpr std::uint8_t kPngSignature[8] = {0x89, 'P', 'N', 'G', '\r', '\n', 0x1a, '\n'};
  if (read(0, 8, head) && std::memcmp(head, kPngSignature, 8) == 0) {
    if (!read(0, 33, head) || BigEndian(head + 8, 4) != 13 || std::memcmp(head + 12, "IHDR", 4) != 0) {
      throw DatasetError(name + ": expected a PNG whose first chunk is a 13-byte IHDR, got a "
                                "damaged or truncated header");
    }
    const std::uint32_t width = BigEndian(head + 16, 4), height = BigEndian(head + 20, 4);
    if (width > 0x7fffffffu || height > 0x7fffffffu) {
      throw DatasetError(name + ": PNG header claims " + std::to_string(width) + "x" +
                         std::to_string(height) + " pixels, beyond the PNG limit of 2^31 - 1");
    }
    ImageHeader header;
    header.format = ImageHeader::Format::kPng;
    header.cols = static_cast<int>(width);
    header.rows = static_cast<int>(height);
    header.bit_depth = head[24];
    switch (head[25]) {
      case 0: header.channels = 1; break;
      case 2: header.channels = 3; break;
      case 3: header.channels = 3; break;
      case 4: header.channels = 2; break;
      case 6: header.channels = 4; break;
      default:
        throw DatasetError(name + ": PNG header: expected colour type 0, 2, 3, 4 or 6, got " +
                           std::to_string(head[25]));
    }
    return CheckedHeader(header, name);
  }
  if (read(0, 2, head) && head[0] == 0xFF && head[1] == 0xD8) {
    // JPEG: walk the segments (marker, 2-byte length) to the first start of frame.
    std::uint64_t at = 2;
    for (int segment = 0; segment < 100000; ++segment) {
      std::uint8_t marker[2];
      if (!read(at, 2, marker)) break;
      if (marker[0] != 0xFF) break;
      if (marker[1] == 0xFF) {  // fill byte
        ++at;
        continue;
      }
      at += 2;
      const std::uint8_t m = marker[1];
      if ((m >= 0xD0 && m <= 0xD7) || m == 0x01) continue;  // no length
      if (m == 0xD9 || m == 0xDA) break;  // end of image or scan before any frame header
      std::uint8_t length_bytes[2];
      if (!read(at, 2, length_bytes)) break;
      const std::uint32_t length = BigEndian(length_bytes, 2);
      if (length < 2) break;
      const bool start_of_frame = m >= 0xC0 && m <= 0xCF && m != 0xC4 && m != 0xC8 && m != 0xCC;
      if (start_of_frame) {
        std::uint8_t sof[6];
        if (length < 8 || !read(at + 2, 6, sof)) break;
        ImageHeader header;
        header.format = ImageHeader::Format::kJpeg;
        header.bit_depth = sof[0];
        header.rows = static_cast<int>(BigEndian(sof + 1, 2));
        header.cols = static_cast<int>(BigEndian(sof + 3, 2));
        header.channels = sof[5];
        if (header.rows == 0) {
          throw DatasetError(name + ": JPEG header gives the height as 0 (defined later by a "
                                    "DNL marker), which is not supported");
        }
        return CheckedHeader(header, name);
      }
      at += length;
    }
    throw DatasetError(name + ": expected a JPEG with a frame header (SOF marker), got a "
                              "damaged or truncated file");
  }
  throw DatasetError(name + ": expected a PNG or JPEG image, got a file that is neither "
                            "(no PNG signature or JPEG start marker)");
}

// Image files are read whole before decoding; beyond this the file cannot be a frame
// of kMaxFramePixels (16-bit RGBA, uncompressed, is 8 bytes per pixel) plus metadata.
constexpr std::uint64_t kMaxImageFileBytes =
    static_cast<std::uint64_t>(kMaxFramePixels) * 8 + (std::uint64_t{64} << 20);

}  // namespace

ImageHeader ParseImageHeader(const std::string& bytes, const std::string& name) {
  return ParseHeader(
      [&](std::uint64_t offset, std::size_t n, std::uint8_t* out) {
        if (offset > bytes.size() || n > bytes.size() - offset) return false;
        std::memcpy(out, bytes.data() + offset, n);
        return true;
      },
      name);
}

ImageHeader ReadImageHeader(const std::string& path) {
  if (internal::IsDirectory(path)) {
    throw DatasetError(path + ": expected a file, got a directory");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    throw DatasetError(path + ": expected a readable file, got error '" + ErrnoText() + "'");
  }
  return ParseHeader(
      [&](std::uint64_t offset, std::size_t n, std::uint8_t* out) {
        in.clear();
        in.seekg(static_cast<std::streamoff>(offset));
        in.read(reinterpret_cast<char*>(out), static_cast<std::streamsize>(n));
        return in.good() || (in.eof() && static_cast<std::size_t>(in.gcount()) == n);
      },
      path);
}

std::string ReadFile(const std::string& path) {
  if (internal::IsDirectory(path)) {
    throw DatasetError(path + ": expected a file, got a directory");
  }
  std::ifstream in(path, std::ios::binary);
  if (!in) {
    throw DatasetError(path + ": expected a readable file, got error '" + ErrnoText() + "'");
  }
  std::ostringstream contents;
  contents << in.rdbuf();
  if (in.bad()) throw DatasetError(path + ": read failed");
  return contents.str();
}

const char* ToString(PixelEncoding encoding) {
  switch (encoding) {
    case PixelEncoding::kDepthU16Micrometres:
      return "depth_u16_um";
    case PixelEncoding::kRgb8:
      return "rgb8";
  }
  return "unknown";
}

bool PixelEncodingFromString(const std::string& name, PixelEncoding* encoding) {
  if (name == "depth_u16_um") {
    *encoding = PixelEncoding::kDepthU16Micrometres;
    return true;
  }
  if (name == "rgb8") {
    *encoding = PixelEncoding::kRgb8;
    return true;
  }
  return false;
}

std::string EncodePng(const Image& image, PixelEncoding encoding, int compression_level) {
  return EncodePngNamed(image, encoding, compression_level, "image");
}

void WritePngAtomically(const std::string& path, const Image& image, PixelEncoding encoding,
                        int compression_level, Durability durability) {
  WriteFileAtomically(path, EncodePngNamed(image, encoding, compression_level, path),
                      durability);
}

Image DecodeImage(const std::string& bytes, PixelEncoding encoding, const std::string& name) {
  // The format and the size, before any pixel is decoded.
  const ImageHeader header = ParseImageHeader(bytes, name);
  if (bytes.size() > static_cast<std::uint64_t>(std::numeric_limits<int>::max())) {
    throw DatasetError(name + ": expected an image file under 2 GB, got " +
                       std::to_string(bytes.size()) + " bytes");
  }
  // PNG (every dataset tactfunc writes) by libpng here; anything else by OpenCV's
  // codec module, loaded on first use.
  std::string reason;
  const auto* data = reinterpret_cast<const std::uint8_t*>(bytes.data());
  const cv::Mat mat =
      header.format == ImageHeader::Format::kPng
          ? internal::DecodePngSamples(data, bytes.size(), &reason)
          : codecs::Decode(data, bytes.size(), codecs::DecodeMode::kUnchanged, &reason);
  if (mat.empty() && !reason.empty()) {
    throw DatasetError(name + ": expected a PNG or JPEG image, got " +
                       std::to_string(bytes.size()) + " bytes that do not decode as one (" +
                       reason + ")");
  }
  if (mat.empty()) {
    throw DatasetError(name + ": expected a PNG or JPEG image, got " +
                       std::to_string(bytes.size()) +
                       " bytes that do not decode as one (corrupt or truncated?)");
  }
  Image image;
  if (encoding == PixelEncoding::kDepthU16Micrometres) {
    if (mat.depth() != CV_16U || mat.channels() != 1) {
      throw DatasetError(name +
                         ": depth_u16_um expects a 16-bit unsigned 1-channel "
                         "PNG, got " +
                         DepthName(mat.depth()) + " with " + std::to_string(mat.channels()) +
                         " channel(s)");
    }
    image = Image(mat.rows, mat.cols, 1);
    for (int r = 0; r < mat.rows; ++r) {
      const auto* row = mat.ptr<std::uint16_t>(r);
      float* out = image.data.data() + static_cast<std::size_t>(r) * mat.cols;
      for (int c = 0; c < mat.cols; ++c) {
        out[c] = row[c] == 0 ? std::numeric_limits<float>::quiet_NaN()
                             : static_cast<float>(row[c] / kMicrometresPerMetre);
      }
    }
    return image;
  }
  return internal::ImageFromRgb8Mat(mat, name);
}

Image ReadImage(const std::string& path, PixelEncoding encoding) {
  ReadImageHeader(path);  // refuses an oversized frame before the file is read
  std::error_code ec;
  const std::uintmax_t size = std::filesystem::file_size(path, ec);
  if (!ec && size > kMaxImageFileBytes) {
    throw DatasetError(path + ": expected an image file of at most " +
                       std::to_string(kMaxImageFileBytes) + " bytes, got " +
                       std::to_string(size) + " bytes");
  }
  return DecodeImage(ReadFile(path), encoding, path);
}

namespace internal {

Image ImageFromRgb8Mat(const cv::Mat& input, const std::string& name) {
  if (input.depth() != CV_8U) {
    throw DatasetError(name + ": rgb8 expects an 8-bit image, got " + DepthName(input.depth()) +
                       " with " + std::to_string(input.channels()) + " channel(s)");
  }
  const int in_channels = input.channels();
  if (in_channels != 1 && in_channels != 3 && in_channels != 4) {
    throw DatasetError(name + ": rgb8 expects 1, 3 or 4 channels, got " +
                       std::to_string(in_channels));
  }
  // B, G, R (and A) samples to R, G, B values in [0, 1], alpha dropped, in one pass.
  const int channels = in_channels == 1 ? 1 : 3;
  Image image(input.rows, input.cols, channels);
  const std::size_t row_values = static_cast<std::size_t>(input.cols) * channels;
  for (int r = 0; r < input.rows; ++r) {
    const auto* row = input.ptr<std::uint8_t>(r);
    float* out = image.data.data() + r * row_values;
    if (channels == 1) {
      for (std::size_t i = 0; i < row_values; ++i) out[i] = row[i] / 255.0f;
      continue;
    }
    for (int c = 0; c < input.cols; ++c, row += in_channels, out += 3) {
      out[0] = row[2] / 255.0f;
      out[1] = row[1] / 255.0f;
      out[2] = row[0] / 255.0f;
    }
  }
  return image;
}

}  // namespace internal
}  // namespace tactfunc
