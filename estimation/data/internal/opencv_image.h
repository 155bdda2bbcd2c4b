// Copyright 2026 The tactfunc Authors.
//
// OpenCV <-> Image conversions shared by estimation/*.cc (private: OpenCV stays out
// of the public headers).
#ifndef TACTFUNC_ESTIMATION_DATA_INTERNAL_OPENCV_IMAGE_H_
#define TACTFUNC_ESTIMATION_DATA_INTERNAL_OPENCV_IMAGE_H_

#include <opencv2/core.hpp>
#include <string>

#include "models/core/image.h"

namespace tactfunc::internal {

// An 8-bit image as OpenCV decodes it (1 channel gray, 3 BGR, 4 BGRA) -> an Image
// with intensities v / 255 in R, G, B order (alpha dropped). Throws DatasetError
// naming `name` for another depth or channel count.
Image ImageFromRgb8Mat(const cv::Mat& mat, const std::string& name);

// A cv::Mat header over an Image's data (no copy): CV_32FC(channels).
inline cv::Mat MatView(Image& image) {
  return cv::Mat(image.rows, image.cols, CV_32FC(image.channels), image.data.data());
}
inline cv::Mat MatView(const Image& image) {
  return cv::Mat(image.rows, image.cols, CV_32FC(image.channels),
                 const_cast<float*>(image.data.data()));
}

}  // namespace tactfunc::internal

#endif  // TACTFUNC_ESTIMATION_DATA_INTERNAL_OPENCV_IMAGE_H_
