// Copyright 2026 The tactfunc Authors.
//
// Helpers of the dataset tests: DatasetError expectations and small MJPG videos.
#ifndef TACTFUNC_TESTS_SUPPORT_DATASET_TEST_UTIL_H_
#define TACTFUNC_TESTS_SUPPORT_DATASET_TEST_UTIL_H_

#include <functional>
#include <initializer_list>
#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>
#include <string>
#include <vector>

#include "estimation/data/image_io.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace tactfunc::testing_util {

// Runs `body` and checks it raises DatasetError whose message holds every piece.
inline void ExpectDatasetError(const std::function<void()>& body,
                               std::initializer_list<const char*> pieces) {
  try {
    body();
    ADD_FAILURE() << "expected a DatasetError, got none";
  } catch (const DatasetError& e) {
    for (const char* piece : pieces) EXPECT_THAT(e.what(), ::testing::HasSubstr(piece));
  }
}

// Writes `frames` (8-bit BGR, all of one size) as an MJPG .avi at `path`. Returns false
// if this OpenCV build has no writer for it (callers skip their test then).
inline bool WriteMjpgVideo(const std::string& path, const std::vector<cv::Mat>& frames) {
  cv::VideoWriter writer(path, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10.0,
                         frames.front().size(), /*isColor=*/true);
  if (!writer.isOpened()) return false;
  for (const cv::Mat& frame : frames) writer.write(frame);
  return true;
}

// A frame that differs from every other index: a gradient whose offset and a bright
// square whose position depend on `index` (rows x cols, 8-bit BGR).
inline cv::Mat PatternFrame(int index, int rows = 24, int cols = 32) {
  cv::Mat frame(rows, cols, CV_8UC3);
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      frame.at<cv::Vec3b>(r, c) = cv::Vec3b(static_cast<uchar>((4 * c + 7 * index) % 256),
                                            static_cast<uchar>((5 * r + 3 * index) % 256),
                                            static_cast<uchar>((40 + 11 * index) % 256));
    }
  }
  const int side = 6;
  const int r0 = (index * 5) % (rows - side);
  const int c0 = (index * 7) % (cols - side);
  frame(cv::Rect(c0, r0, side, side)).setTo(cv::Scalar(255, 255, 255));
  return frame;
}

}  // namespace tactfunc::testing_util

#endif  // TACTFUNC_TESTS_SUPPORT_DATASET_TEST_UTIL_H_
