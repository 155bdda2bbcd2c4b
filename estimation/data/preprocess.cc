// Copyright 2026 The tactfunc Authors.
#include "estimation/data/preprocess.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>

#include "estimation/data/dataset.h"
#include "estimation/data/internal/path_util.h"
#include "estimation/data/internal/opencv_image.h"

namespace tactfunc {
namespace {

// A resized pixel is valid where at least half its source area was valid; the slack
// absorbs float rounding of area weights that are exactly one half.
constexpr float kMinValidFraction = 0.5f - 1e-6f;

// ITU-R BT.601 luma weights.
constexpr float kLumaR = 0.299f;
constexpr float kLumaG = 0.587f;
constexpr float kLumaB = 0.114f;

// Smallest and largest value over every channel of the pixels p with valid(p); with no
// such pixel, lo = +inf > hi = -inf.
struct ValueRange {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -std::numeric_limits<double>::infinity();
  bool empty() const { return !(lo <= hi); }
};

template <typename Valid>
ValueRange RangeOfValidPixels(const Image& image, const Valid& valid) {
  ValueRange range;
  const std::size_t pixels = image.pixels();
  for (std::size_t p = 0; p < pixels; ++p) {
    if (!valid(p)) continue;
    for (int k = 0; k < image.channels; ++k) {
      const double v = image.data[p * image.channels + k];
      range.lo = std::min(range.lo, v);
      range.hi = std::max(range.hi, v);
    }
  }
  return range;
}

// Checks `options` and `image` (non-empty) and returns the kFixedScale scale:
// options.fixed_scale, else sensor_scale. Throws std::invalid_argument naming `caller`
// and `what` (the image's role).
double CheckedFixedScale(const char* caller, const char* what, const Image& image,
                         const PreprocessOptions& options, double sensor_scale) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  if (image.empty() || image.size() != image.pixels() * image.channels) {
    throw std::invalid_argument(std::string(caller) + ": " + what +
                                ": expected a non-empty image, got " + image.ShapeString() +
                                " holding " + std::to_string(image.size()) + " values");
  }
  const double fixed_scale = options.fixed_scale > 0 ? options.fixed_scale : sensor_scale;
  if (options.normalization == PreprocessOptions::Normalization::kFixedScale &&
      !(std::isfinite(fixed_scale) && fixed_scale > 0)) {
    throw std::invalid_argument(
        std::string(caller) +
        ": kFixedScale needs a scale: expected PreprocessOptions::fixed_scale "
        "> 0 or sensor_scale > 0, got " +
        internal::FormatDoubleShort(options.fixed_scale) + " and " +
        internal::FormatDoubleShort(sensor_scale));
  }
  return fixed_scale;
}

// Steps 2-4 of Preprocess on `difference` (invalid pixels hold 0) with its validity
// `mask` (1 valid, 0 invalid, one per pixel); fixed_scale > 0 for kFixedScale.
PreprocessedFrame GrayResizeNormalize(Image difference, std::vector<float> mask,
                                      const PreprocessOptions& options, double fixed_scale) {
  const std::size_t pixels = difference.pixels();
  // 2. Grayscale (linear, so invalid pixels stay exactly 0).
  if (options.grayscale && difference.channels == 3) {
    Image gray(difference.rows, difference.cols, 1);
    for (std::size_t p = 0; p < pixels; ++p) {
      const float* rgb = &difference.data[p * 3];
      gray.data[p] = kLumaR * rgb[0] + kLumaG * rgb[1] + kLumaB * rgb[2];
    }
    difference = std::move(gray);
  }

  // 3. Mask-aware area resize, after noting the source-resolution range.
  PreprocessedFrame out;
  const ValueRange source =
      RangeOfValidPixels(difference, [&](std::size_t p) { return mask[p] > 0; });
  out.source_range = source.empty() ? 0.0 : source.hi - source.lo;
  const int rows = options.rows > 0 ? options.rows : difference.rows;
  const int cols = options.cols > 0 ? options.cols : difference.cols;
  const int out_channels = difference.channels;
  out.values = Image(rows, cols, out_channels, 0.0f);
  out.valid.assign(static_cast<std::size_t>(rows) * cols, 0);
  if (rows == difference.rows && cols == difference.cols) {
    out.values = std::move(difference);
    for (std::size_t p = 0; p < pixels; ++p) out.valid[p] = mask[p] > 0 ? 1 : 0;
  } else {
    cv::Mat resized_values;
    cv::Mat resized_mask;
    cv::resize(internal::MatView(difference), resized_values, cv::Size(cols, rows), 0, 0,
               cv::INTER_AREA);
    cv::resize(cv::Mat(difference.rows, difference.cols, CV_32F, mask.data()), resized_mask,
               cv::Size(cols, rows), 0, 0, cv::INTER_AREA);
    for (int r = 0; r < rows; ++r) {
      const float* values_row = resized_values.ptr<float>(r);
      const float* mask_row = resized_mask.ptr<float>(r);
      for (int c = 0; c < cols; ++c) {
        const float weight = mask_row[c];
        if (!(weight >= kMinValidFraction)) continue;
        out.valid[static_cast<std::size_t>(r) * cols + c] = 1;
        for (int k = 0; k < out_channels; ++k) {
          out.values.at(r, c, k) = values_row[c * out_channels + k] / weight;
        }
      }
    }
  }

  // 4. Normalisation.
  if (options.normalization == PreprocessOptions::Normalization::kFixedScale) {
    out.scale = fixed_scale;
    out.offset = 0;
  } else {
    const ValueRange range =
        RangeOfValidPixels(out.values, [&](std::size_t p) { return out.valid[p] != 0; });
    const double lo = range.lo, hi = range.hi;
    const bool any_valid = !range.empty();
    if (!any_valid || !(hi - lo >= options.min_range_epsilon)) {
      out.flat = true;
      out.scale = 1;
      out.offset = any_valid ? lo : 0;
      std::fill(out.values.data.begin(), out.values.data.end(), 0.0f);
      return out;
    }
    out.scale = hi - lo;
    out.offset = lo;
  }
  for (std::size_t p = 0; p < out.valid.size(); ++p) {
    for (int k = 0; k < out_channels; ++k) {
      float& v = out.values.data[p * out_channels + k];
      if (!out.valid[p]) {
        v = 0.0f;
        continue;
      }
      v = static_cast<float>((v - out.offset) / out.scale);
      // Guards overflow of huge differences over a tiny scale: never let inf out.
      if (!std::isfinite(v)) {
        out.valid[p] = 0;
        for (int j = 0; j < out_channels; ++j) out.values.data[p * out_channels + j] = 0.0f;
        break;
      }
    }
  }
  return out;
}

}  // namespace

bool PreprocessOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& message) {
    if (error != nullptr) *error = message;
    return false;
  };
  if (rows < 0 || cols < 0 || (rows == 0) != (cols == 0)) {
    return fail(
        "PreprocessOptions::rows/cols: expected both 0 (keep the size) or both "
        "> 0, got rows " +
        std::to_string(rows) + ", cols " + std::to_string(cols));
  }
  if (!(std::isfinite(fixed_scale) && fixed_scale >= 0)) {
    return fail(
        "PreprocessOptions::fixed_scale: expected a finite number > 0, or 0 for "
        "the sensor's scale, got " +
        internal::FormatDoubleShort(fixed_scale));
  }
  if (!(std::isfinite(min_range_epsilon) && min_range_epsilon > 0)) {
    return fail("PreprocessOptions::min_range_epsilon: expected a finite number > 0, got " +
                internal::FormatDoubleShort(min_range_epsilon));
  }
  return true;
}

const char* ToString(PreprocessOptions::Normalization normalization) {
  switch (normalization) {
    case PreprocessOptions::Normalization::kFixedScale:
      return "fixed_scale";
    case PreprocessOptions::Normalization::kPerImageMinMax:
      return "per_image_min_max";
  }
  return "unknown";
}

bool NormalizationFromString(const std::string& name,
                             PreprocessOptions::Normalization* normalization) {
  if (name == "fixed_scale") {
    *normalization = PreprocessOptions::Normalization::kFixedScale;
    return true;
  }
  if (name == "per_image_min_max") {
    *normalization = PreprocessOptions::Normalization::kPerImageMinMax;
    return true;
  }
  return false;
}

std::size_t PreprocessedFrame::num_valid() const {
  return static_cast<std::size_t>(std::count(valid.begin(), valid.end(), 1));
}

Image Difference(const Image& frame, const Image& reference, SensorKind sensor) {
  if (!frame.SameShape(reference) || reference.size() != frame.size()) {
    throw std::invalid_argument("Difference: reference: expected the frame's shape " +
                                frame.ShapeString() + ", got " + reference.ShapeString());
  }
  Image difference(frame.rows, frame.cols, frame.channels);
  for (std::size_t i = 0; i < frame.size(); ++i) {
    difference.data[i] = sensor == SensorKind::kSoftBubble ? reference.data[i] - frame.data[i]
                                                           : frame.data[i] - reference.data[i];
  }
  return difference;
}

PreprocessedFrame Preprocess(const Image& frame, const Image& reference, SensorKind sensor,
                             const PreprocessOptions& options, double sensor_scale) {
  const double fixed_scale =
      CheckedFixedScale("Preprocess", "frame", frame, options, sensor_scale);
  if (!frame.SameShape(reference) || reference.size() != frame.size()) {
    throw std::invalid_argument("Preprocess: reference: expected the frame's shape " +
                                frame.ShapeString() + ", got " + reference.ShapeString());
  }

  // 1. Difference and validity mask. Pressing the bubble moves the membrane towards
  // the camera (smaller depth), so reference - frame is positive under contact.
  // The difference in float, one vectorisable pass: a float subtraction rounds the exact
  // difference once, as the same difference taken in double and then rounded to float
  // does whenever that double is exact (two floats within 2^29 of each other's
  // magnitude: every pair of 8-bit or 16-bit frame values); then the pixels with a
  // non-finite value are zeroed and masked.
  const int channels = frame.channels;
  const std::size_t pixels = frame.pixels();
  const float sign = sensor == SensorKind::kSoftBubble ? -1.0f : 1.0f;
  Image difference(frame.rows, frame.cols, channels);
  const float* f = frame.data.data();
  const float* r = reference.data.data();
  float* d = difference.data.data();
  const std::size_t values = pixels * channels;
  bool all_finite = true;
  for (std::size_t i = 0; i < values; ++i) {
    d[i] = sign * (f[i] - r[i]);
    all_finite &= std::isfinite(d[i]);
  }
  std::vector<float> mask(pixels, 1.0f);
  if (!all_finite) {
    for (std::size_t p = 0; p < pixels; ++p) {
      bool valid = true;
      for (int c = 0; c < channels; ++c) valid = valid && std::isfinite(d[p * channels + c]);
      if (valid) continue;
      mask[p] = 0.0f;
      for (int c = 0; c < channels; ++c) d[p * channels + c] = 0.0f;
    }
  }

  return GrayResizeNormalize(std::move(difference), std::move(mask), options, fixed_scale);
}

PreprocessedFrame PreprocessImage(const Image& image, const PreprocessOptions& options,
                                  double sensor_scale) {
  const double fixed_scale =
      CheckedFixedScale("PreprocessImage", "image", image, options, sensor_scale);
  const int channels = image.channels;
  const std::size_t pixels = image.pixels();
  Image values(image.rows, image.cols, channels, 0.0f);
  std::vector<float> mask(pixels, 0.0f);
  for (std::size_t p = 0; p < pixels; ++p) {
    bool valid = true;
    for (int c = 0; c < channels; ++c) valid = valid && std::isfinite(image.data[p * channels + c]);
    if (!valid) continue;
    mask[p] = 1.0f;
    for (int c = 0; c < channels; ++c) values.data[p * channels + c] = image.data[p * channels + c];
  }
  return GrayResizeNormalize(std::move(values), std::move(mask), options, fixed_scale);
}

PreprocessedFrame Preprocess(const Image& frame, const Image& reference,
                             const PreprocessOptions& options, double sensor_scale) {
  const SensorKind sensor = frame.channels == 1 ? SensorKind::kSoftBubble : SensorKind::kGelSlim;
  return Preprocess(frame, reference, sensor, options, sensor_scale);
}

PreprocessedFrame PreprocessFrame(const Dataset& dataset, std::size_t index,
                                  const PreprocessOptions& options) {
  const Image frame = dataset.LoadFrame(index);
  const SensorKind sensor = dataset.frames()[index].sensor;
  const SensorInfo& info = dataset.sensor_info(sensor);
  const double scale =
      info.normalization_scale > 0 ? info.normalization_scale : DefaultNormalizationScale(sensor);
  return Preprocess(frame, dataset.FrameReference(index), sensor, options, scale);
}

}  // namespace tactfunc
