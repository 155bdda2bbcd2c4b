// Copyright 2026 The tactfunc Authors.
//
// The codecs module (estimation/data/codecs.h): loaded only when a pixel is decoded or
// encoded, never to refuse a frame from its header. ctest runs every test in a process
// of its own, so each starts with nothing loaded; this binary links none of OpenCV's
// codec libraries itself.
#include "estimation/data/codecs.h"

#include <cstdint>
#include <fstream>
#include <opencv2/core.hpp>
#include <sstream>
#include <string>
#include <vector>

#include "estimation/data/image_io.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/support/image_test_util.h"
#include "tests/support/test_dir.h"

namespace tactfunc {
namespace {

using ::testing::HasSubstr;
using testing_util::PngHeaderOnly;
using testing_util::TestDir;
using testing_util::WriteText;

// Whether a shared library whose file name contains `name` is mapped into this process.
bool Mapped(const std::string& name) {
  std::ifstream maps("/proc/self/maps");
  std::stringstream text;
  text << maps.rdbuf();
  return text.str().find(name) != std::string::npos;
}

TEST(Codecs, AnOversizedFrameIsRefusedWithoutLoadingTheCodecs) {
  if (codecs::Loaded()) GTEST_SKIP() << "this build links the codecs in";
  TestDir dir;
  WriteText(dir / "huge.png", PngHeaderOnly(20000, 20000, 8, 0));
  EXPECT_THROW(ReadImage(dir / "huge.png", PixelEncoding::kRgb8), DatasetError);
  EXPECT_FALSE(codecs::Loaded());
  EXPECT_FALSE(Mapped("libopencv_imgcodecs"));
  EXPECT_FALSE(Mapped("libopencv_videoio"));
}

TEST(Codecs, PngFramesDecodeWithoutTheModuleAndTheFirstJpegLoadsIt) {
  const bool linked = codecs::Loaded();
  Image image(5, 7, 3);
  for (std::size_t i = 0; i < image.data.size(); ++i) image.data[i] = (i % 256) / 255.0f;
  const std::string png = EncodePng(image, PixelEncoding::kRgb8, 1);
  EXPECT_EQ(DecodeImage(png, PixelEncoding::kRgb8, "mem.png").data, image.data);
  if (!linked) {
    EXPECT_FALSE(codecs::Loaded());
    EXPECT_FALSE(Mapped("libopencv_imgcodecs"));
  }
  // A JPEG at quality 95 of a flat grey image, through the module both ways.
  cv::Mat grey(16, 16, CV_8UC1, cv::Scalar(100));
  std::vector<std::uint8_t> jpeg;
  ASSERT_TRUE(codecs::Encode(".jpg", grey, {codecs::kJpegQuality, 95}, &jpeg));
  EXPECT_TRUE(codecs::Loaded());
  EXPECT_TRUE(Mapped("libopencv_imgcodecs"));
  if (!linked) {
    EXPECT_THAT(codecs::ModulePath(), HasSubstr("libtactfunc_codecs.so"));
    EXPECT_TRUE(Mapped(codecs::ModulePath().substr(codecs::ModulePath().rfind('/') + 1)));
  }
  const Image back =
      DecodeImage(std::string(jpeg.begin(), jpeg.end()), PixelEncoding::kRgb8, "mem.jpg");
  ASSERT_EQ(back.rows, 16);
  EXPECT_NEAR(back.data[8 * 16 + 8], 100 / 255.0f, 2 / 255.0f);
  // Bytes that are no image: an empty Mat, not an exception.
  const std::string junk = "not an image at all";
  EXPECT_TRUE(codecs::Decode(reinterpret_cast<const std::uint8_t*>(junk.data()), junk.size(),
                             codecs::DecodeMode::kUnchanged)
                  .empty());
}

TEST(Codecs, AVideoThatDoesNotExistDoesNotOpenAndAWrittenOneReadsBack) {
  TestDir dir;
  codecs::VideoCapture missing;
  EXPECT_FALSE(missing.open(dir / "missing.avi"));
  EXPECT_FALSE(missing.isOpened());
  codecs::VideoWriter writer;
  ASSERT_TRUE(writer.open(dir / "clip.avi", "MJPG", 30.0, 24, 32));
  for (int i = 0; i < 3; ++i) {
    ASSERT_TRUE(writer.write(cv::Mat(24, 32, CV_8UC3, cv::Scalar(40 * i, 80, 120))));
  }
  writer.release();
  codecs::VideoCapture capture;
  ASSERT_TRUE(capture.open(dir / "clip.avi"));
  cv::Mat frame;
  int frames = 0;
  while (capture.read(&frame)) ++frames;
  EXPECT_EQ(frames, 3);
  EXPECT_TRUE(capture.seek(1));
  EXPECT_TRUE(capture.read(&frame));
  EXPECT_EQ(frame.cols, 32);
}

}  // namespace
}  // namespace tactfunc
