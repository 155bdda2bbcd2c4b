// Copyright 2026 The tactfunc Authors.
//
// Image: the one pixel container that crosses tactfunc's public headers.
//
// A tactile frame is a small dense grid of floats: a Soft Bubble depth image (one
// channel, metres, NaN where the time-of-flight camera dropped out) or a GelSlim RGB
// image (three channels, intensities in [0, 1]). Keeping OpenCV out of the public
// headers (docs/ARCHITECTURE.md) means the library passes this plain struct around;
// the .cc files wrap `data` in a cv::Mat header without copying when they need OpenCV.
//
// Layout: row-major, channels interleaved ("HWC"):
//   data[(row * cols + col) * channels + channel],  size rows * cols * channels.
// Row 0 is the top of the picture; see models/core/sensor.h for the sensor frame.
#ifndef TACTFUNC_MODELS_CORE_IMAGE_H_
#define TACTFUNC_MODELS_CORE_IMAGE_H_

#include <cstddef>
#include <string>
#include <vector>

namespace tactfunc {

struct Image {
  Image() = default;
  // A rows x cols x channels image filled with `fill`. Throws std::invalid_argument
  // on a negative size or a channel count outside [1, 4].
  Image(int rows, int cols, int channels, float fill = 0.0f);

  int rows = 0;
  int cols = 0;
  int channels = 1;
  std::vector<float> data;  // rows * cols * channels, HWC, row-major.

  bool empty() const { return data.empty(); }
  std::size_t size() const { return data.size(); }
  std::size_t pixels() const { return static_cast<std::size_t>(rows) * cols; }
  bool SameShape(const Image& other) const {
    return rows == other.rows && cols == other.cols && channels == other.channels;
  }
  float& at(int row, int col, int channel = 0) {
    return data[(static_cast<std::size_t>(row) * cols + col) * channels + channel];
  }
  float at(int row, int col, int channel = 0) const {
    return data[(static_cast<std::size_t>(row) * cols + col) * channels + channel];
  }
  // "140x175x1": rows x cols x channels, for error messages.
  std::string ShapeString() const;
};

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_CORE_IMAGE_H_
