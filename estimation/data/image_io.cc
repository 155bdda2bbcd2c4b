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
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>
#include <vector>

#include "estimation/data/internal/path_util.h"
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

}  // namespace

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
  cv::Mat mat;
  try {
    if (!bytes.empty()) {
      mat = cv::imdecode(
          cv::Mat(1, static_cast<int>(bytes.size()), CV_8U, const_cast<char*>(bytes.data())),
          cv::IMREAD_UNCHANGED);
    }
  } catch (const cv::Exception& e) {
    throw DatasetError(name +
                       ": expected a PNG or JPEG image, got a file OpenCV "
                       "cannot decode (" +
                       std::string(e.what()) + ")");
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
  return DecodeImage(ReadFile(path), encoding, path);
}

namespace internal {

Image ImageFromRgb8Mat(const cv::Mat& input, const std::string& name) {
  if (input.depth() != CV_8U) {
    throw DatasetError(name + ": rgb8 expects an 8-bit image, got " + DepthName(input.depth()) +
                       " with " + std::to_string(input.channels()) + " channel(s)");
  }
  cv::Mat mat;
  switch (input.channels()) {
    case 1:
      mat = input;
      break;
    case 3:
      cv::cvtColor(input, mat, cv::COLOR_BGR2RGB);
      break;
    case 4:
      cv::cvtColor(input, mat, cv::COLOR_BGRA2RGB);
      break;
    default:
      throw DatasetError(name + ": rgb8 expects 1, 3 or 4 channels, got " +
                         std::to_string(input.channels()));
  }
  const int channels = mat.channels();
  Image image(mat.rows, mat.cols, channels);
  const std::size_t row_values = static_cast<std::size_t>(mat.cols) * channels;
  for (int r = 0; r < mat.rows; ++r) {
    const auto* row = mat.ptr<std::uint8_t>(r);
    float* out = image.data.data() + r * row_values;
    for (std::size_t i = 0; i < row_values; ++i) out[i] = row[i] / 255.0f;
  }
  return image;
}

}  // namespace internal
}  // namespace tactfunc
