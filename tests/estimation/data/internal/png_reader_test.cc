// Copyright 2026 The tactfunc Authors.
//
// The libpng reader (estimation/data/internal/png_reader.h) decodes what OpenCV writes
// exactly as cv::imdecode(IMREAD_UNCHANGED) does, for every depth and channel count
// OpenCV writes, including palettes and bit depths under 8 written by libpng itself;
// damaged data is an empty Mat with libpng's reason, never a crash.
#include "estimation/data/internal/png_reader.h"

#include <png.h>

#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace tactfunc::internal {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

cv::Mat RandomMat(int rows, int cols, int type, unsigned seed) {
  cv::Mat m(rows, cols, type);
  cv::RNG rng(seed);
  rng.fill(m, cv::RNG::UNIFORM, 0, CV_MAT_DEPTH(type) == CV_16U ? 65536 : 256);
  return m;
}

cv::Mat Decode(const std::vector<std::uint8_t>& bytes, std::string* error = nullptr) {
  return DecodePngSamples(bytes.data(), bytes.size(), error);
}

bool Identical(const cv::Mat& a, const cv::Mat& b) {
  return a.type() == b.type() && a.size() == b.size() && cv::norm(a, b, cv::NORM_INF) == 0;
}

TEST(PngReader, DecodesWhatOpenCvWritesAsOpenCvReadsIt) {
  for (int type : {CV_8UC1, CV_8UC3, CV_8UC4, CV_16UC1, CV_16UC3, CV_16UC4}) {
    for (int level : {0, 1, 9}) {
      const cv::Mat original = RandomMat(17, 23, type, 7 + type + level);
      std::vector<std::uint8_t> png;
      ASSERT_TRUE(cv::imencode(".png", original, png, {cv::IMWRITE_PNG_COMPRESSION, level}));
      const cv::Mat ours = Decode(png);
      const cv::Mat opencv = cv::imdecode(png, cv::IMREAD_UNCHANGED);
      EXPECT_TRUE(Identical(ours, opencv)) << "type " << type << " level " << level;
      EXPECT_TRUE(Identical(ours, original)) << "type " << type << " level " << level;
    }
  }
}

// A PNG written by libpng directly, for the layouts OpenCV does not write.
// `filters`: libpng's PNG_FILTER_* mask (its default choice if 0); `transparent`
// writes a tRNS chunk (gray or RGB).
std::vector<std::uint8_t> WriteWithLibpng(int rows, int cols, int color_type, int bit_depth,
                                          const std::vector<std::uint8_t>& packed_rows,
                                          bool interlaced, int filters = 0,
                                          bool transparent = false) {
  std::vector<std::uint8_t> out;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png_create_info_struct(png);
  png_set_write_fn(
      png, &out,
      [](png_structp p, png_bytep data, png_size_t n) {
        auto* o = static_cast<std::vector<std::uint8_t>*>(png_get_io_ptr(p));
        o->insert(o->end(), data, data + n);
      },
      [](png_structp) {});
  png_set_IHDR(png, info, cols, rows, bit_depth, color_type,
               interlaced ? PNG_INTERLACE_ADAM7 : PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_color palette[3] = {{255, 0, 0}, {0, 255, 0}, {10, 20, 30}};
  if (color_type == PNG_COLOR_TYPE_PALETTE) png_set_PLTE(png, info, palette, 3);
  png_color_16 transparent_colour{};
  if (transparent) png_set_tRNS(png, info, nullptr, 0, &transparent_colour);
  if (filters != 0) png_set_filter(png, PNG_FILTER_TYPE_BASE, filters);
  png_write_info(png, info);
  const std::size_t row_bytes = packed_rows.size() / rows;
  std::vector<png_bytep> pointers(rows);
  for (int r = 0; r < rows; ++r) {
    pointers[r] = const_cast<png_bytep>(packed_rows.data() + r * row_bytes);
  }
  png_write_image(png, pointers.data());
  png_write_end(png, info);
  png_destroy_write_struct(&png, &info);
  return out;
}

TEST(PngReader, ExpandsPalettesLowBitDepthsAndInterlacingLikeOpenCv) {
  // 4 x 8 pixels: palette indices 0..2 at 8 bits; 1-bit gray; 8-bit gray interlaced.
  std::vector<std::uint8_t> indices(32);
  for (std::size_t i = 0; i < indices.size(); ++i) indices[i] = static_cast<std::uint8_t>(i % 3);
  std::vector<std::uint8_t> bits(4, 0xA5);  // one byte = 8 one-bit pixels per row
  std::vector<std::uint8_t> gray(32);
  for (std::size_t i = 0; i < gray.size(); ++i) gray[i] = static_cast<std::uint8_t>(7 * i);
  for (const auto& png : {WriteWithLibpng(4, 8, PNG_COLOR_TYPE_PALETTE, 8, indices, false),
                          WriteWithLibpng(4, 8, PNG_COLOR_TYPE_GRAY, 1, bits, false),
                          WriteWithLibpng(4, 8, PNG_COLOR_TYPE_GRAY, 8, gray, true)}) {
    const cv::Mat ours = Decode(png);
    const cv::Mat opencv = cv::imdecode(png, cv::IMREAD_UNCHANGED);
    ASSERT_FALSE(ours.empty());
    EXPECT_TRUE(Identical(ours, opencv))
        << "ours " << ours.channels() << " channels, OpenCV " << opencv.channels();
  }
  // The palette's third colour (10, 20, 30) arrives as B, G, R = 30, 20, 10.
  const cv::Mat palette = Decode(WriteWithLibpng(4, 8, PNG_COLOR_TYPE_PALETTE, 8, indices, false));
  EXPECT_EQ(palette.at<cv::Vec3b>(0, 2), cv::Vec3b(30, 20, 10));
}

// Every filter type, alone and mixed, for every layout the libdeflate path takes: the
// same samples as OpenCV's decoder (libpng), and the path is taken.
TEST(PngReader, CommonFramesDecodeOnTheLibdeflatePathAsLibpngDoes) {
  const int rows = 9, cols = 13;
  struct Layout {
    int color_type, bit_depth, channels;
  };
  for (const Layout& layout : {Layout{PNG_COLOR_TYPE_GRAY, 8, 1}, Layout{PNG_COLOR_TYPE_RGB, 8, 3},
                               Layout{PNG_COLOR_TYPE_RGB_ALPHA, 8, 4},
                               Layout{PNG_COLOR_TYPE_GRAY, 16, 1},
                               Layout{PNG_COLOR_TYPE_RGB, 16, 3},
                               Layout{PNG_COLOR_TYPE_RGB_ALPHA, 16, 4}}) {
    // A smooth ramp plus noise, so that every predictor has work to do.
    std::mt19937 rng(layout.color_type * 100 + layout.bit_depth);
    const int bytes = layout.channels * layout.bit_depth / 8;
    std::vector<std::uint8_t> packed(static_cast<std::size_t>(rows) * cols * bytes);
    for (std::size_t i = 0; i < packed.size(); ++i) {
      packed[i] = static_cast<std::uint8_t>(3 * (i % (cols * bytes)) + 5 * (i / (cols * bytes)) +
                                            rng() % 17);
    }
    for (int filters : {PNG_FILTER_NONE, PNG_FILTER_SUB, PNG_FILTER_UP, PNG_FILTER_AVG,
                        PNG_FILTER_PAETH, PNG_ALL_FILTERS}) {
      const auto png = WriteWithLibpng(rows, cols, layout.color_type, layout.bit_depth, packed,
                                       false, filters);
      const cv::Mat fast = DecodeCommonPng(png.data(), png.size());
      const cv::Mat opencv = cv::imdecode(png, cv::IMREAD_UNCHANGED);
      ASSERT_FALSE(fast.empty()) << "colour type " << layout.color_type << ", "
                                 << layout.bit_depth << " bits, filters " << filters;
      EXPECT_TRUE(Identical(fast, opencv)) << "colour type " << layout.color_type << ", "
                                           << layout.bit_depth << " bits, filters " << filters;
      EXPECT_TRUE(Identical(Decode(png), opencv));
    }
  }
}

// Real sensor frames (the GelSight presses of tests/data/taxim_ballpress, written by
// another program than tactfunc): every one on the libdeflate path, as OpenCV reads it.
TEST(PngReader, RealGelSightFramesDecodeOnTheLibdeflatePathAsOpenCvReadsThem) {
  const std::filesystem::path dir =
      std::filesystem::path(TACTFUNC_SOURCE_DIR) / "tests/data/taxim_ballpress";
  int frames = 0;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    if (entry.path().extension() != ".png") continue;
    std::ifstream in(entry.path(), std::ios::binary);
    const std::vector<std::uint8_t> png((std::istreambuf_iterator<char>(in)),
                                        std::istreambuf_iterator<char>());
    const cv::Mat fast = DecodeCommonPng(png.data(), png.size());
    ASSERT_FALSE(fast.empty()) << entry.path();
    EXPECT_TRUE(Identical(fast, cv::imdecode(png, cv::IMREAD_UNCHANGED))) << entry.path();
    ++frames;
  }
  EXPECT_EQ(frames, 50);  // 49 presses and their reference
}

// Interlacing, palettes, low bit depths, transparency and damaged files are left to
// libpng (an empty Mat from the libdeflate path), which decodes them as before.
TEST(PngReader, TheLibdeflatePathLeavesEverythingElseToLibpng) {
  std::vector<std::uint8_t> gray(32);
  for (std::size_t i = 0; i < gray.size(); ++i) gray[i] = static_cast<std::uint8_t>(7 * i);
  std::vector<std::uint8_t> indices(32, 1), bits(4, 0xA5);
  const auto transparent = WriteWithLibpng(4, 8, PNG_COLOR_TYPE_GRAY, 8, gray, false, 0, true);
  for (const auto& png : {WriteWithLibpng(4, 8, PNG_COLOR_TYPE_GRAY, 8, gray, true),
                          WriteWithLibpng(4, 8, PNG_COLOR_TYPE_PALETTE, 8, indices, false),
                          WriteWithLibpng(4, 8, PNG_COLOR_TYPE_GRAY, 1, bits, false),
                          transparent}) {
    EXPECT_TRUE(DecodeCommonPng(png.data(), png.size()).empty());
    EXPECT_FALSE(Decode(png).empty());
  }
  // The transparent gray frame: libpng's alpha channel (gray with alpha becomes BGRA).
  EXPECT_EQ(Decode(transparent).channels(), 4);
  const auto plain = WriteWithLibpng(4, 8, PNG_COLOR_TYPE_GRAY, 8, gray, false);
  ASSERT_FALSE(DecodeCommonPng(plain.data(), plain.size()).empty());
  // Any byte changed after the signature breaks a CRC (or the header): libpng's turn.
  for (std::size_t at = 8; at < plain.size(); at += 5) {
    std::vector<std::uint8_t> damaged = plain;
    damaged[at] ^= 0x10;
    EXPECT_TRUE(DecodeCommonPng(damaged.data(), damaged.size()).empty()) << "byte " << at;
  }
  for (std::size_t size = 0; size < plain.size(); size += 7) {
    EXPECT_TRUE(DecodeCommonPng(plain.data(), size).empty()) << size << " bytes";
  }
}

TEST(PngReader, DamagedDataIsAnEmptyMatWithTheReason) {
  const cv::Mat original = RandomMat(20, 30, CV_16UC1, 3);
  std::vector<std::uint8_t> png;
  ASSERT_TRUE(cv::imencode(".png", original, png));
  std::string error;
  EXPECT_TRUE(Decode({png.begin(), png.begin() + png.size() / 2}, &error).empty());
  EXPECT_THAT(error, Not(::testing::IsEmpty()));
  std::vector<std::uint8_t> flipped = png;
  flipped[png.size() / 2] ^= 0x40;  // inside the image data: a CRC or zlib error
  error.clear();
  EXPECT_TRUE(Decode(flipped, &error).empty());
  EXPECT_THAT(error, Not(::testing::IsEmpty()));
  error.clear();
  EXPECT_TRUE(Decode({'n', 'o', 't', ' ', 'p', 'n', 'g', '!', '!'}, &error).empty());
  EXPECT_THAT(error, HasSubstr("signature"));
}

}  // namespace
}  // namespace tactfunc::internal
