// Copyright 2026 The tactfunc Authors.
#include "models/core/image.h"

#include <stdexcept>

namespace tactfunc {

Image::Image(int rows_in, int cols_in, int channels_in, float fill)
    : rows(rows_in), cols(cols_in), channels(channels_in) {
  if (rows < 0 || cols < 0) {
    throw std::invalid_argument("Image: rows and cols must be >= 0, got " +
                                ShapeString());
  }
  if (channels < 1 || channels > 4) {
    throw std::invalid_argument("Image: channels must be in [1, 4], got " +
                                std::to_string(channels));
  }
  data.assign(static_cast<std::size_t>(rows) * cols * channels, fill);
}

std::string Image::ShapeString() const {
  return std::to_string(rows) + "x" + std::to_string(cols) + "x" +
         std::to_string(channels);
}

}  // namespace tactfunc
