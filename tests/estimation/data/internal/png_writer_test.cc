// Copyright 2026 The tactfunc Authors.
//
// The libpng writer (estimation/data/internal/png_writer.h): what it encodes must read
// back bit-exactly through OpenCV's reader at 16 and 8 bits, one and three channels and
// every compression level, with native-endian 16-bit samples; unsupported shapes are
// errors; and written through WritePngAtomically a file appears whole or not at all.
#include "estimation/data/internal/png_writer.h"

#include <cstdint>
#include <filesystem>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

#include "estimation/data/image_io.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/support/test_dir.h"

namespace tactfunc::internal {
namespace {

using ::testing::HasSubstr;
using testing_util::ListDir;
using testing_util::TestDir;

// Random samples of the given type, with the extremes and byte-order-sensitive values
// (0x0102 and 0x0201 differ only by their byte order) at the start.
template <typename T>
std::vector<T> Samples(int rows, int cols, int channels, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> code(0, std::numeric_limits<T>::max());
  std::vector<T> samples(static_cast<std::size_t>(rows) * cols * channels);
  for (T& v : samples) v = static_cast<T>(code(rng));
  const std::vector<int> special = {0, std::numeric_limits<T>::max(), 0x0102, 0x0201, 1};
  for (std::size_t i = 0; i < special.size() && i < samples.size(); ++i) {
    samples[i] = static_cast<T>(special[i] & std::numeric_limits<T>::max());
  }
  return samples;
}

// Decodes PNG bytes with OpenCV, unchanged (no conversion of depth or channels).
cv::Mat Decode(const std::string& png) {
  const cv::Mat buffer(1, static_cast<int>(png.size()), CV_8U, const_cast<char*>(png.data()));
  return cv::imdecode(buffer, cv::IMREAD_UNCHANGED);
}

// True if `mat` holds exactly `samples` (interleaved, channels in file order: OpenCV
// hands three-channel files back as BGR).
template <typename T>
::testing::AssertionResult Holds(const cv::Mat& mat, const std::vector<T>& samples, int rows,
                                 int cols, int channels) {
  const int type = CV_MAKETYPE(sizeof(T) == 2 ? CV_16U : CV_8U, channels);
  if (mat.empty() || mat.rows != rows || mat.cols != cols || mat.type() != type) {
    return ::testing::AssertionFailure()
           << "decoded " << mat.rows << "x" << mat.cols << " type " << mat.type()
           << ", expected " << rows << "x" << cols << " type " << type;
  }
  for (int r = 0; r < rows; ++r) {
    const T* row = mat.ptr<T>(r);
    for (int c = 0; c < cols; ++c) {
      for (int k = 0; k < channels; ++k) {
        const T got = row[c * channels + (channels == 3 ? 2 - k : k)];
        const T want = samples[(static_cast<std::size_t>(r) * cols + c) * channels + k];
        if (got != want) {
          return ::testing::AssertionFailure() << "pixel (" << r << ", " << c << ") channel "
                                               << k << ": " << got << " vs " << want;
        }
      }
    }
  }
  return ::testing::AssertionSuccess();
}

// Random samples of type T encoded at 1 and 3 channels and every compression level
// decode to themselves.
template <typename T>
void ExpectRoundTripsAtEveryLevel(int rows, int cols) {
  for (int channels : {1, 3}) {
    const std::vector<T> samples = Samples<T>(rows, cols, channels, 1);
    for (int level : {0, 1, 6, 9}) {
      SCOPED_TRACE("channels " + std::to_string(channels) + " level " + std::to_string(level));
      const std::string png =
          EncodePngSamples(samples.data(), rows, cols, channels, 8 * sizeof(T), level);
      EXPECT_TRUE(Holds(Decode(png), samples, rows, cols, channels));
    }
  }
}

TEST(EncodePngSamples, SixteenBitSamplesRoundTripThroughOpenCvAtEveryLevel) {
  ExpectRoundTripsAtEveryLevel<std::uint16_t>(13, 17);
}

TEST(EncodePngSamples, EightBitSamplesRoundTripThroughOpenCvAtEveryLevel) {
  ExpectRoundTripsAtEveryLevel<std::uint8_t>(9, 31);
}

TEST(EncodePngSamples, SmoothFramesCompressAndAOnePixelImageWorks) {
  // A smooth ramp is what the SUB filter at level 1 turns into runs of small residuals.
  std::vector<std::uint16_t> ramp(64 * 64);
  for (int r = 0; r < 64; ++r) {
    for (int c = 0; c < 64; ++c) ramp[r * 64 + c] = static_cast<std::uint16_t>(1000 + r + c);
  }
  const std::string png = EncodePngSamples(ramp.data(), 64, 64, 1, 16, 1);
  EXPECT_LT(png.size(), ramp.size() * 2 / 4);
  EXPECT_TRUE(Holds(Decode(png), ramp, 64, 64, 1));

  const std::uint8_t one[3] = {10, 20, 30};
  EXPECT_TRUE(Holds(Decode(EncodePngSamples(one, 1, 1, 3, 8, 1)),
                    std::vector<std::uint8_t>(one, one + 3), 1, 1, 3));
}

TEST(EncodePngSamples, UnsupportedShapesAreErrorsSayingWhatWasAsked) {
  const std::vector<std::uint16_t> samples(4 * 4 * 4, 7);
  try {
    EncodePngSamples(samples.data(), 4, 4, 4, 16, 1);
    ADD_FAILURE() << "no error for 4 channels";
  } catch (const std::runtime_error& e) {
    EXPECT_THAT(e.what(), HasSubstr("4x4x4 at 16 bits"));
  }
  EXPECT_THROW(EncodePngSamples(samples.data(), 4, 4, 2, 8, 1), std::runtime_error);
  EXPECT_THROW(EncodePngSamples(samples.data(), 4, 4, 1, 12, 1), std::runtime_error);
  EXPECT_THROW(EncodePngSamples(samples.data(), 0, 4, 1, 8, 1), std::runtime_error);
  EXPECT_THROW(EncodePngSamples(samples.data(), 4, -1, 1, 8, 1), std::runtime_error);
}

TEST(WritePngAtomically, WritesTheWholeFileAndLeavesNoTemporaryFile) {
  TestDir dir;
  Image depth(6, 5, 1, 0.0123f);  // 12300 um: a 16-bit code above 255
  WritePngAtomically(dir / "frame.png", depth, PixelEncoding::kDepthU16Micrometres);
  EXPECT_EQ(ListDir(dir.path()), std::vector<std::string>{"frame.png"});
  const cv::Mat read = cv::imread(dir / "frame.png", cv::IMREAD_UNCHANGED);
  ASSERT_EQ(read.type(), CV_16UC1);
  EXPECT_EQ(read.at<std::uint16_t>(5, 4), 12300);
}

TEST(WritePngAtomically, AnUnwritablePathIsAnErrorNamingItAndLeavesNoTemporaryFile) {
  TestDir dir;
  const Image gray(3, 3, 1, 0.5f);
  // The target is an existing, non-empty directory: the temporary file is written,
  // the rename over the directory fails, and the temporary file must go.
  std::filesystem::create_directories(dir / "taken.png/inside");
  try {
    WritePngAtomically(dir / "taken.png", gray, PixelEncoding::kRgb8);
    ADD_FAILURE() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_THAT(e.what(), HasSubstr("taken.png"));
  }
  EXPECT_EQ(ListDir(dir.path()), std::vector<std::string>{"taken.png"});
  // A folder that does not exist: nothing can be created at all.
  EXPECT_THROW(WritePngAtomically(dir / "missing/frame.png", gray, PixelEncoding::kRgb8),
               std::runtime_error);
  EXPECT_EQ(ListDir(dir.path()), std::vector<std::string>{"taken.png"});
}

}  // namespace
}  // namespace tactfunc::internal
