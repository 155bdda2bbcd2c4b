// Copyright 2026 The tactfunc Authors.
//
// Preprocessing: from a raw tactile frame and its sensor's reference frame to the
// normalised difference image the neural fields are fitted to.
//
//   1. Difference with the reference (the undeformed sensor):
//        Soft Bubble (depth):  d = reference - frame   (metres; pressing the
//                              membrane towards the camera makes d positive)
//        GelSlim (rgb):        d = frame - reference   (intensity)
//      A pixel is valid where every channel of both images is finite; invalid pixels
//      (the bubble camera's dropouts) are carried as a mask, never as NaN.
//   2. Optional grayscale: d becomes 0.299 R + 0.587 G + 0.114 B (ITU-R BT.601 luma,
//      linear, so the luma of the difference is the difference of the lumas).
//   3. Optional resize to rows x cols with area interpolation (cv::INTER_AREA),
//      mask-aware: resize d * mask and mask, a pixel is valid where the resized mask
//      (the fraction of valid source area) is >= 0.5, and its value is
//      resized(d * mask) / resized(mask) -- so invalid pixels never bleed in as zeros.
//   4. Normalisation, values = (d - offset) / scale:
//        kFixedScale (default): offset 0, scale = a fixed physical scale (from the
//          options, else the sensor's). A blank frame (frame == reference) stays
//          exactly 0 and two frames keep the ratio of their indentations, so the
//          absolute depth of a contact is preserved.
//        kPerImageMinMax: offset = min, scale = max - min over the valid pixels, so
//          values span [0, 1]. If the range is below min_range_epsilon (a blank frame)
//          or there is no valid pixel, the frame is flagged `flat`, values are all 0
//          and scale = 1, offset = min (or 0): nothing is divided by ~0.
//      Invalid pixels hold 0. No NaN or infinity ever leaves Preprocess.
#ifndef TACTFUNC_ESTIMATION_DATA_PREPROCESS_H_
#define TACTFUNC_ESTIMATION_DATA_PREPROCESS_H_

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

#include "models/core/image.h"
#include "models/core/sensor.h"

namespace tactfunc {

class Dataset;

struct PreprocessOptions {
  // Working resolution in pixels; both 0 (default) keeps the frame's, else both > 0.
  int rows = 0;
  int cols = 0;
  // Convert rgb differences to one channel (luma). No effect on one-channel frames.
  bool grayscale = false;
  enum class Normalization { kFixedScale, kPerImageMinMax };
  // Default kFixedScale: a blank frame stays blank and absolute indentation is kept.
  Normalization normalization = Normalization::kFixedScale;
  // kFixedScale: physical units (metres of depth, or intensity) mapping to 1.0; > 0,
  // or 0 (default) = use the sensor's scale (SensorInfo::normalization_scale).
  double fixed_scale = 0;
  // kPerImageMinMax: a range below this (physical units) marks the frame flat. > 0.
  double min_range_epsilon = 1e-6;
  bool IsValid(std::string* error) const;
};

// "fixed_scale" / "per_image_min_max".
const char* ToString(PreprocessOptions::Normalization normalization);
// Parses the names above; returns false and leaves *normalization untouched otherwise.
bool NormalizationFromString(const std::string& name,
                             PreprocessOptions::Normalization* normalization);

struct PreprocessedFrame {
  // rows x cols x channels: the normalised difference; invalid pixels hold 0.
  Image values;
  // rows * cols, row-major: 1 where the pixel is valid (all channels), else 0.
  std::vector<std::uint8_t> valid;
  // kPerImageMinMax only: the range was < min_range_epsilon; values are all 0.
  bool flat = false;
  // values = (difference - offset) / scale, so difference = values * scale + offset.
  double scale = 1;
  double offset = 0;
  // Range (max - min over valid pixels and channels) of the difference after step 2
  // and BEFORE the resize, in physical units (0 without valid pixels). The paper's
  // release min-max normalises each frame at this source resolution and then resizes,
  // so its PSNR peak is this range (PsnrSourcePeak in estimation/data/trunk_targets.h).
  double source_range = 0;
  std::size_t num_valid() const;
};

// Step 1 alone, for pictures: the raw difference of `frame` with `reference` (same
// shape, else std::invalid_argument) in physical units, with Preprocess's sign per
// sensor: reference - frame for Soft Bubble depth (a press, which brings the membrane
// closer to the camera, is positive), frame - reference for GelSlim intensity.
// Non-finite pixels stay non-finite (no mask, no resize, no normalisation).
Image Difference(const Image& frame, const Image& reference, SensorKind sensor);

// Preprocesses `frame` against `reference` (same shape, else std::invalid_argument)
// for a sensor of the given kind. sensor_scale: the sensor's normalisation scale, used
// in kFixedScale mode when options.fixed_scale is 0. Throws std::invalid_argument if
// the options are invalid or kFixedScale has no scale (both 0).
PreprocessedFrame Preprocess(const Image& frame, const Image& reference, SensorKind sensor,
                             const PreprocessOptions& options, double sensor_scale = 0);

// As above, with the sensor inferred from the channel count: one channel is taken as
// bubble depth (reference - frame), three as GelSlim rgb (frame - reference). Prefer
// the overload with SensorKind (or the Dataset one) for grayscale GelSlim data, whose
// one channel would otherwise get the bubble's sign.
PreprocessedFrame Preprocess(const Image& frame, const Image& reference,
                             const PreprocessOptions& options, double sensor_scale = 0);

// Steps 2-4 alone, on `image` itself (no reference subtracted): a pixel is valid where
// every channel is finite; grayscale, mask-aware area resize and normalisation exactly
// as Preprocess does them to a difference. E.g. a sensor's reference in the units and
// at the working resolution of its targets (`tactfunc export`). Throws
// std::invalid_argument like Preprocess (invalid options, an empty image, kFixedScale
// without a scale).
PreprocessedFrame PreprocessImage(const Image& image, const PreprocessOptions& options,
                                  double sensor_scale = 0);

// Loads frame `index` of `dataset` and preprocesses it against its sensor's reference
// with the sensor's kind and normalisation scale (DefaultNormalizationScale if the
// dataset records none). Throws like Dataset::LoadFrame and Preprocess.
PreprocessedFrame PreprocessFrame(const Dataset& dataset, std::size_t index,
                                  const PreprocessOptions& options);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_DATA_PREPROCESS_H_
