// Copyright 2026 The tactfunc Authors.
#include "estimation/data/image_io.h"

#include <cmath>
#include <filesystem>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/support/image_test_util.h"
#include "tests/support/test_dir.h"

namespace tactfunc {
namespace {

using ::testing::HasSubstr;
using testing_util::ListDir;
using testing_util::TestDir;
using testing_util::WriteText;

using testing_util::kNaN;

using testing_util::BitIdentical;

// A depth image on the micrometre grid with some invalid pixels.
Image GridDepth(int rows, int cols, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> code(1, 65534);
  Image image(rows, cols, 1);
  for (float& v : image.data) v = static_cast<float>(code(rng) / 1e6);
  image.data[0] = kNaN;
  image.data[image.size() / 2] = kNaN;
  return image;
}

Image GridRgb(int rows, int cols, int channels, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> code(0, 255);
  Image image(rows, cols, channels);
  for (float& v : image.data) v = code(rng) / 255.0f;
  return image;
}

TEST(PixelEncoding, NamesRoundTrip) {
  for (PixelEncoding encoding : {PixelEncoding::kDepthU16Micrometres, PixelEncoding::kRgb8}) {
    PixelEncoding parsed = PixelEncoding::kRgb8;
    ASSERT_TRUE(PixelEncodingFromString(ToString(encoding), &parsed));
    EXPECT_EQ(parsed, encoding);
  }
  EXPECT_STREQ(ToString(PixelEncoding::kDepthU16Micrometres), "depth_u16_um");
  EXPECT_STREQ(ToString(PixelEncoding::kRgb8), "rgb8");
  PixelEncoding untouched = PixelEncoding::kRgb8;
  EXPECT_FALSE(PixelEncodingFromString("depth", &untouched));
  EXPECT_EQ(untouched, PixelEncoding::kRgb8);
}

TEST(EncodePng, DepthOnTheMicrometreGridRoundTripsBitExactly) {
  const Image depth = GridDepth(14, 17, 1);
  const Image decoded = DecodeImage(EncodePng(depth, PixelEncoding::kDepthU16Micrometres),
                                    PixelEncoding::kDepthU16Micrometres, "depth");
  EXPECT_TRUE(BitIdentical(depth, decoded));
}

TEST(EncodePng, ArbitraryDepthIsQuantisedToHalfAMicrometreAndThenStable) {
  Image depth(5, 7, 1);
  for (std::size_t i = 0; i < depth.size(); ++i) depth.data[i] = 0.02f + 1.234567e-7f * i;
  const Image once = DecodeImage(EncodePng(depth, PixelEncoding::kDepthU16Micrometres),
                                 PixelEncoding::kDepthU16Micrometres, "once");
  for (std::size_t i = 0; i < depth.size(); ++i) {
    EXPECT_NEAR(once.data[i], depth.data[i], 0.5e-6 + 1e-9);
  }
  const Image twice = DecodeImage(EncodePng(once, PixelEncoding::kDepthU16Micrometres),
                                  PixelEncoding::kDepthU16Micrometres, "twice");
  EXPECT_TRUE(BitIdentical(once, twice));
}

TEST(EncodePng, RgbAndGrayRoundTripBitExactly) {
  for (int channels : {3, 1}) {
    const Image rgb = GridRgb(9, 11, channels, 2);
    for (int level : {0, 1, 9}) {
      const Image decoded =
          DecodeImage(EncodePng(rgb, PixelEncoding::kRgb8, level), PixelEncoding::kRgb8, "rgb");
      EXPECT_TRUE(BitIdentical(rgb, decoded)) << channels << " channels, level " << level;
    }
  }
}

TEST(EncodePng, RgbIsStoredInFileOrderSoOtherToolsSeeRed) {
  TestDir dir;
  Image red(2, 2, 3, 0.0f);
  for (std::size_t p = 0; p < red.pixels(); ++p) red.data[p * 3] = 1.0f;
  WritePngAtomically(dir / "red.png", red, PixelEncoding::kRgb8);
  const cv::Mat bgr = cv::imread(dir / "red.png", cv::IMREAD_UNCHANGED);
  ASSERT_EQ(bgr.type(), CV_8UC3);
  EXPECT_EQ(bgr.at<cv::Vec3b>(0, 0), cv::Vec3b(0, 0, 255));
  const Image back = ReadImage(dir / "red.png", PixelEncoding::kRgb8);
  EXPECT_EQ(back.at(1, 1, 0), 1.0f);
  EXPECT_EQ(back.at(1, 1, 2), 0.0f);
}

TEST(EncodePng, RgbValuesOutsideTheUnitRangeAreClamped) {
  Image image(1, 2, 1);
  image.data = {-0.5f, 1.7f};
  const Image back =
      DecodeImage(EncodePng(image, PixelEncoding::kRgb8), PixelEncoding::kRgb8, "clamped");
  EXPECT_EQ(back.data[0], 0.0f);
  EXPECT_EQ(back.data[1], 1.0f);
}

TEST(WritePngAtomically, DepthOutOfRangeIsAnErrorNamingTheFileAndPixel) {
  TestDir dir;
  for (float bad : {0.0656f, -0.001f, 0.0f, std::numeric_limits<float>::infinity()}) {
    Image depth(3, 4, 1, 0.03f);
    depth.at(2, 1) = bad;
    try {
      WritePngAtomically(dir / "deep.png", depth, PixelEncoding::kDepthU16Micrometres);
      ADD_FAILURE() << "no error for depth " << bad;
    } catch (const DatasetError& e) {
      EXPECT_THAT(e.what(), HasSubstr("deep.png"));
      EXPECT_THAT(e.what(), HasSubstr("pixel (row 2, col 1)"));
      EXPECT_THAT(e.what(), HasSubstr("expected a depth"));
    }
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "deep.png"));
  EXPECT_TRUE(ListDir(dir.path()).empty());
}

TEST(EncodePng, NanRgbAndWrongChannelCountsAreErrors) {
  Image rgb(2, 2, 3, 0.5f);
  rgb.data[4] = kNaN;
  EXPECT_THROW(EncodePng(rgb, PixelEncoding::kRgb8), DatasetError);
  EXPECT_THROW(EncodePng(Image(2, 2, 3), PixelEncoding::kDepthU16Micrometres), DatasetError);
  EXPECT_THROW(EncodePng(Image(2, 2, 2), PixelEncoding::kRgb8), DatasetError);
  EXPECT_THROW(EncodePng(Image(), PixelEncoding::kRgb8), DatasetError);
  EXPECT_THROW(EncodePng(Image(2, 2, 1), PixelEncoding::kRgb8, 10), std::invalid_argument);
}

TEST(ReadImage, MissingFileIsAnErrorNamingIt) {
  TestDir dir;
  try {
    ReadImage(dir / "absent.png", PixelEncoding::kRgb8);
    ADD_FAILURE() << "no error";
  } catch (const DatasetError& e) {
    EXPECT_THAT(e.what(), HasSubstr("absent.png"));
  }
}

TEST(ReadImage, CorruptOrTruncatedPngIsAnErrorNamingIt) {
  TestDir dir;
  WriteText(dir / "garbage.png", "this is not a png");
  const std::string png = EncodePng(GridRgb(40, 40, 3, 3), PixelEncoding::kRgb8, 0);
  WriteText(dir / "truncated.png", png.substr(0, png.size() / 3));
  WriteText(dir / "empty.png", "");
  for (const char* name : {"garbage.png", "truncated.png", "empty.png"}) {
    try {
      ReadImage(dir / name, PixelEncoding::kRgb8);
      ADD_FAILURE() << "no error for " << name;
    } catch (const DatasetError& e) {
      EXPECT_THAT(e.what(), HasSubstr(name));
      EXPECT_THAT(e.what(), HasSubstr("expected a PNG or JPEG image"));
    }
  }
}

TEST(ReadImage, WrongBitDepthIsAnErrorSayingWhatWasFound) {
  TestDir dir;
  WritePngAtomically(dir / "rgb.png", GridRgb(3, 3, 1, 4), PixelEncoding::kRgb8);
  WritePngAtomically(dir / "depth.png", GridDepth(3, 3, 5), PixelEncoding::kDepthU16Micrometres);
  try {
    ReadImage(dir / "rgb.png", PixelEncoding::kDepthU16Micrometres);
    ADD_FAILURE() << "no error";
  } catch (const DatasetError& e) {
    EXPECT_THAT(e.what(), HasSubstr("rgb.png"));
    EXPECT_THAT(e.what(), HasSubstr("expects a 16-bit"));
    EXPECT_THAT(e.what(), HasSubstr("got 8-bit"));
  }
  try {
    ReadImage(dir / "depth.png", PixelEncoding::kRgb8);
    ADD_FAILURE() << "no error";
  } catch (const DatasetError& e) {
    EXPECT_THAT(e.what(), HasSubstr("depth.png"));
    EXPECT_THAT(e.what(), HasSubstr("got 16-bit"));
  }
}

TEST(ReadImage, JpegReadsAsRgbCloseToTheOriginal) {
  TestDir dir;
  cv::Mat bgr(16, 16, CV_8UC3, cv::Scalar(40, 120, 200));  // B, G, R
  ASSERT_TRUE(cv::imwrite(dir / "frame.JPG", bgr));
  const Image image = ReadImage(dir / "frame.JPG", PixelEncoding::kRgb8);
  ASSERT_EQ(image.ShapeString(), "16x16x3");
  EXPECT_NEAR(image.at(8, 8, 0), 200 / 255.0, 3 / 255.0);
  EXPECT_NEAR(image.at(8, 8, 2), 40 / 255.0, 3 / 255.0);
}

TEST(ReadImage, AlphaChannelIsDropped) {
  TestDir dir;
  cv::Mat bgra(4, 4, CV_8UC4, cv::Scalar(0, 0, 255, 128));
  ASSERT_TRUE(cv::imwrite(dir / "alpha.png", bgra));
  const Image image = ReadImage(dir / "alpha.png", PixelEncoding::kRgb8);
  EXPECT_EQ(image.ShapeString(), "4x4x3");
  EXPECT_EQ(image.at(0, 0, 0), 1.0f);
}

TEST(WriteFileAtomically, ReplacesAnExistingFileWholeAndLeavesNoTemporaryFiles) {
  TestDir dir;
  const std::string path = dir / "labels.csv";
  WriteText(path, std::string(10000, 'x'));
  WriteFileAtomically(path, "short\n");
  EXPECT_EQ(ReadFile(path), "short\n");
  EXPECT_EQ(ListDir(dir.path()), std::vector<std::string>{"labels.csv"});
}

TEST(WriteFileAtomically, ConcurrentWritersEachLeaveOneWholeFile) {
  TestDir dir;
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      for (int i = 0; i < 20; ++i) {
        WriteFileAtomically(dir / ("f" + std::to_string(t) + ".bin"),
                            std::string(1000 + i, static_cast<char>('a' + t)));
        WriteFileAtomically(dir / "shared.bin", std::string(5000, static_cast<char>('a' + t)));
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_EQ(ListDir(dir.path()).size(), 5u);
  const std::string shared = ReadFile(dir / "shared.bin");
  ASSERT_EQ(shared.size(), 5000u);
  EXPECT_EQ(shared.find_first_not_of(shared[0]), std::string::npos);
  EXPECT_EQ(ReadFile(dir / "f2.bin"), std::string(1019, 'c'));
}

TEST(WriteFileAtomically, MissingDirectoryIsAnErrorNamingThePath) {
  TestDir dir;
  try {
    WriteFileAtomically(dir / "no/such/dir/file.txt", "x");
    ADD_FAILURE() << "no error";
  } catch (const std::runtime_error& e) {
    EXPECT_THAT(e.what(), HasSubstr("no/such/dir/file.txt"));
  }
}

using testing_util::PngHeaderOnly;

TEST(ReadImageHeader, ReadsPngAndJpegSizesWithoutDecoding) {
  TestDir dir;
  WritePngAtomically(dir / "depth.png", GridDepth(7, 9, 1), PixelEncoding::kDepthU16Micrometres);
  ImageHeader h = ReadImageHeader(dir / "depth.png");
  EXPECT_EQ(h.format, ImageHeader::Format::kPng);
  EXPECT_EQ(h.rows, 7);
  EXPECT_EQ(h.cols, 9);
  EXPECT_EQ(h.channels, 1);
  EXPECT_EQ(h.bit_depth, 16);
  std::vector<std::uint8_t> jpeg;
  cv::imencode(".jpg", cv::Mat(30, 50, CV_8UC3, cv::Scalar(10, 200, 30)), jpeg);
  WriteText(dir / "frame.jpg", std::string(jpeg.begin(), jpeg.end()));
  h = ReadImageHeader(dir / "frame.jpg");
  EXPECT_EQ(h.format, ImageHeader::Format::kJpeg);
  EXPECT_EQ(h.rows, 30);
  EXPECT_EQ(h.cols, 50);
  EXPECT_EQ(h.channels, 3);
  EXPECT_EQ(h.bit_depth, 8);
  // The same from bytes in memory.
  EXPECT_EQ(ParseImageHeader(std::string(jpeg.begin(), jpeg.end()), "mem").cols, 50);
}

TEST(ReadImage, AFrameBeyondThePixelLimitIsRefusedFromItsHeaderNamingTheFile) {
  TestDir dir;
  // A header claiming 100000 x 100000 with nothing behind it: refused on the header's
  // word, before any decoder sees it (OpenCV's own assertion named no file).
  WriteText(dir / "huge.png", PngHeaderOnly(100000, 100000, 16, 0));
  for (PixelEncoding encoding : {PixelEncoding::kDepthU16Micrometres, PixelEncoding::kRgb8}) {
    try {
      ReadImage(dir / "huge.png", encoding);
      ADD_FAILURE() << "no error";
    } catch (const DatasetError& e) {
      EXPECT_THAT(e.what(), HasSubstr("huge.png: expected a frame of at most 16777216 pixels "
                                      "(4096x4096), got a header claiming 100000x100000"));
    }
  }
  EXPECT_THROW(ReadImageHeader(dir / "huge.png"), DatasetError);
  // 4097 x 4096 is one row too many; 4096 x 4096 passes the header check (and then
  // fails to decode, having no pixel data).
  WriteText(dir / "over.png", PngHeaderOnly(4097, 4096, 8, 0));
  EXPECT_THROW(ReadImageHeader(dir / "over.png"), DatasetError);
  WriteText(dir / "limit.png", PngHeaderOnly(4096, 4096, 8, 0));
  EXPECT_EQ(ReadImageHeader(dir / "limit.png").rows, 4096);
  // A JPEG's SOF is read the same way.
  std::vector<std::uint8_t> jpeg;
  cv::imencode(".jpg", cv::Mat(8, 8, CV_8UC1, cv::Scalar(1)), jpeg);
  std::string bytes(jpeg.begin(), jpeg.end());
  const std::size_t sof = bytes.find("\xff\xc0");
  ASSERT_NE(sof, std::string::npos);
  bytes[sof + 5] = bytes[sof + 6] = bytes[sof + 7] = bytes[sof + 8] = '\xff';  // 65535 x 65535
  WriteText(dir / "huge.jpg", bytes);
  try {
    ReadImage(dir / "huge.jpg", PixelEncoding::kRgb8);
    ADD_FAILURE() << "no error";
  } catch (const DatasetError& e) {
    EXPECT_THAT(e.what(), HasSubstr("huge.jpg: expected a frame of at most"));
    EXPECT_THAT(e.what(), HasSubstr("65535x65535"));
  }
}

TEST(ReadImage, DamagedHeadersAndOtherFormatsAreRefusedNamingTheFile) {
  TestDir dir;
  WriteText(dir / "short.png", PngHeaderOnly(10, 10, 8, 0).substr(0, 20));
  WriteText(dir / "zero.png", PngHeaderOnly(0, 10, 8, 0));
  WriteText(dir / "colour.png", PngHeaderOnly(10, 10, 8, 5));
  WriteText(dir / "nosof.jpg", std::string("\xff\xd8\xff\xd9", 4));
  WriteText(dir / "image.bmp", "BM" + std::string(60, '\0'));
  for (const char* name : {"short.png", "zero.png", "colour.png", "nosof.jpg", "image.bmp"}) {
    try {
      ReadImage(dir / name, PixelEncoding::kRgb8);
      ADD_FAILURE() << "no error for " << name;
    } catch (const DatasetError& e) {
      EXPECT_THAT(e.what(), HasSubstr(name));
    }
  }
}

TEST(ReadFile, ReturnsTheBytesAndNamesAMissingFile) {
  TestDir dir;
  const std::string bytes("a\0b\xff", 4);
  WriteFileAtomically(dir / "bin", bytes);
  EXPECT_EQ(ReadFile(dir / "bin"), bytes);
  EXPECT_THROW(ReadFile(dir / "missing"), DatasetError);
  try {
    ReadFile(dir / "missing");
  } catch (const std::runtime_error& e) {
    EXPECT_THAT(e.what(), HasSubstr("missing"));
  }
}

}  // namespace
}  // namespace tactfunc
