// Copyright 2026 The tactfunc Authors.
#include "estimation/data/preprocess.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>

#include "estimation/data/dataset.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/support/image_test_util.h"
#include "tests/support/test_dir.h"

namespace tactfunc {
namespace {

using ::testing::HasSubstr;
using Normalization = PreprocessOptions::Normalization;

using testing_util::kNaN;

Image FlatDepth(int rows, int cols, float depth_m) { return Image(rows, cols, 1, depth_m); }

// A bubble frame pressed in by `indentation_m` over a centred disc of radius 3 px.
Image PressedDepth(const Image& reference, float indentation_m) {
  Image frame = reference;
  for (int r = 0; r < frame.rows; ++r) {
    for (int c = 0; c < frame.cols; ++c) {
      const double dr = r - frame.rows / 2.0;
      const double dc = c - frame.cols / 2.0;
      if (dr * dr + dc * dc <= 9.0) frame.at(r, c) -= indentation_m;
    }
  }
  return frame;
}

bool AllFinite(const Image& image) {
  for (float v : image.data) {
    if (!std::isfinite(v)) return false;
  }
  return true;
}

TEST(PreprocessOptions, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(PreprocessOptions().IsValid(&error)) << error;
}

TEST(PreprocessOptions, BadOptionsNameTheField) {
  std::string error;
  PreprocessOptions options;
  options.rows = 32;  // cols left 0
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("rows/cols"));
  options = PreprocessOptions();
  options.fixed_scale = -1;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("fixed_scale"));
  options = PreprocessOptions();
  options.min_range_epsilon = 0;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("min_range_epsilon"));
  const Image frame = FlatDepth(4, 4, 0.03f);
  EXPECT_THROW(Preprocess(frame, frame, options, 0.01), std::invalid_argument);
}

TEST(PreprocessOptions, NormalizationNamesRoundTrip) {
  for (Normalization n : {Normalization::kFixedScale, Normalization::kPerImageMinMax}) {
    Normalization parsed = Normalization::kFixedScale;
    ASSERT_TRUE(NormalizationFromString(ToString(n), &parsed));
    EXPECT_EQ(parsed, n);
  }
}

TEST(Preprocess, BlankFrameBecomesZerosWithoutNanInBothModes) {
  Image reference = FlatDepth(8, 10, 0.04f);
  reference.at(2, 3) = kNaN;  // a dropout
  for (Normalization mode : {Normalization::kFixedScale, Normalization::kPerImageMinMax}) {
    PreprocessOptions options;
    options.normalization = mode;
    const PreprocessedFrame out = Preprocess(reference, reference, options, 0.01);
    ASSERT_EQ(out.values.ShapeString(), "8x10x1");
    for (float v : out.values.data) EXPECT_EQ(v, 0.0f);
    EXPECT_EQ(out.valid[2 * 10 + 3], 0);
    EXPECT_EQ(out.num_valid(), 79u);
    EXPECT_EQ(out.flat, mode == Normalization::kPerImageMinMax) << ToString(mode);
    EXPECT_TRUE(std::isfinite(out.scale) && out.scale > 0);
  }
}

TEST(Preprocess, EntirelyInvalidFrameIsFlatAndFinite) {
  const Image frame(6, 6, 1, kNaN);
  const Image reference = FlatDepth(6, 6, 0.04f);
  PreprocessOptions options;
  options.normalization = Normalization::kPerImageMinMax;
  options.rows = options.cols = 3;
  const PreprocessedFrame out = Preprocess(frame, reference, options);
  EXPECT_TRUE(out.flat);
  EXPECT_EQ(out.num_valid(), 0u);
  EXPECT_TRUE(AllFinite(out.values));
}

TEST(Preprocess, FixedScaleKeepsTheRatioOfIndentations) {
  const Image reference = FlatDepth(16, 16, 0.04f);
  const Image shallow = PressedDepth(reference, 0.002f);
  const Image deep = PressedDepth(reference, 0.006f);
  PreprocessOptions options;  // kFixedScale, scale from the sensor
  const PreprocessedFrame a =
      Preprocess(shallow, reference, SensorKind::kSoftBubble, options, 0.01);
  const PreprocessedFrame b = Preprocess(deep, reference, SensorKind::kSoftBubble, options, 0.01);
  EXPECT_EQ(a.scale, 0.01);
  EXPECT_EQ(a.offset, 0.0);
  // Pressing in is positive: reference - frame.
  EXPECT_NEAR(a.values.at(8, 8), 0.2, 1e-5);
  EXPECT_NEAR(b.values.at(8, 8), 0.6, 1e-5);
  EXPECT_NEAR(b.values.at(8, 8) / a.values.at(8, 8), 3.0, 1e-4);
  EXPECT_EQ(a.values.at(0, 0), 0.0f);
  // Options override the sensor's scale.
  options.fixed_scale = 0.002;
  EXPECT_NEAR(Preprocess(shallow, reference, options, 0.01).values.at(8, 8), 1.0, 1e-5);
}

TEST(Preprocess, FixedScaleWithoutAnyScaleIsAnError) {
  const Image frame = FlatDepth(4, 4, 0.03f);
  try {
    Preprocess(frame, frame, PreprocessOptions());
    ADD_FAILURE() << "no error";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("fixed_scale"));
  }
}

TEST(Preprocess, MinMaxMapsTheValidRangeToTheUnitInterval) {
  const Image reference = FlatDepth(16, 16, 0.04f);
  Image frame = PressedDepth(reference, 0.004f);
  frame.at(0, 0) = kNaN;
  PreprocessOptions options;
  options.normalization = Normalization::kPerImageMinMax;
  const PreprocessedFrame out = Preprocess(frame, reference, options);
  EXPECT_FALSE(out.flat);
  EXPECT_NEAR(out.scale, 0.004, 1e-8);
  EXPECT_NEAR(out.offset, 0.0, 1e-9);
  EXPECT_NEAR(out.values.at(8, 8), 1.0, 1e-5);
  EXPECT_EQ(out.values.at(1, 1), 0.0f);
  EXPECT_EQ(out.values.at(0, 0), 0.0f);
  EXPECT_EQ(out.valid[0], 0);
}

TEST(Preprocess, ResizeOfAMaskedFrameKeepsNanOutAndMarksMostlyInvalidPixelsInvalid) {
  // 8x8 -> 4x4: each output pixel averages a 2x2 block.
  const Image reference = FlatDepth(8, 8, 0.04f);
  Image frame = FlatDepth(8, 8, 0.038f);  // 2 mm everywhere
  // Block (0, 0): 3 of 4 invalid -> invalid. Block (0, 1): 2 of 4 -> valid, and its
  // value is the mean of the valid pixels only (not pulled towards 0).
  frame.at(0, 0) = kNaN;
  frame.at(0, 1) = kNaN;
  frame.at(1, 0) = kNaN;
  frame.at(0, 2) = kNaN;
  frame.at(1, 2) = kNaN;
  frame.at(0, 3) = 0.036f;  // 4 mm
  PreprocessOptions options;
  options.rows = options.cols = 4;
  const PreprocessedFrame out = Preprocess(frame, reference, options, 0.01);
  ASSERT_EQ(out.values.ShapeString(), "4x4x1");
  ASSERT_EQ(out.valid.size(), 16u);
  EXPECT_TRUE(AllFinite(out.values));
  EXPECT_EQ(out.valid[0], 0);
  EXPECT_EQ(out.values.at(0, 0), 0.0f);
  EXPECT_EQ(out.valid[1], 1);
  EXPECT_NEAR(out.values.at(0, 1), 0.3, 1e-5);  // mean of 2 mm and 4 mm over 1 cm
  EXPECT_NEAR(out.values.at(3, 3), 0.2, 1e-5);
  EXPECT_EQ(out.num_valid(), 15u);
}

TEST(Preprocess, SourceRangeIsTheRangeOfTheValidDifferenceBeforeTheResize) {
  // One 4 mm pixel in an 8x8 frame of 2 mm (and a NaN that must not count): at source
  // resolution the range is 2 mm; averaged into a 4x4 frame the spike shrinks to a
  // quarter of its excess, a range of 0.5 mm.
  const Image reference = FlatDepth(8, 8, 0.04f);
  Image frame = FlatDepth(8, 8, 0.038f);
  frame.at(5, 5) = 0.036f;
  frame.at(0, 0) = kNaN;
  PreprocessOptions options;
  options.rows = options.cols = 4;
  const PreprocessedFrame out = Preprocess(frame, reference, options, 0.01);
  EXPECT_NEAR(out.source_range, 0.002, 1e-7);
  float lo = 1e9f, hi = -1e9f;
  for (std::size_t p = 0; p < out.valid.size(); ++p) {
    if (!out.valid[p]) continue;
    lo = std::min(lo, out.values.data[p]);
    hi = std::max(hi, out.values.data[p]);
  }
  EXPECT_NEAR((hi - lo) * out.scale, 0.0005, 1e-7);
  // Without a resize both ranges agree; a blank frame has none.
  EXPECT_NEAR(Preprocess(frame, reference, PreprocessOptions(), 0.01).source_range, 0.002, 1e-7);
  EXPECT_EQ(Preprocess(reference, reference, options, 0.01).source_range, 0.0);
}

TEST(Preprocess, UpsamplingAMaskedFrameStaysFinite) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> depth(0.035f, 0.04f);
  Image frame(7, 9, 1);
  for (float& v : frame.data) v = depth(rng);
  for (int i = 0; i < 20; ++i) frame.data[rng() % frame.size()] = kNaN;
  PreprocessOptions options;
  options.rows = 20;
  options.cols = 25;
  options.normalization = Normalization::kPerImageMinMax;
  const PreprocessedFrame out = Preprocess(frame, FlatDepth(7, 9, 0.04f), options);
  EXPECT_TRUE(AllFinite(out.values));
  EXPECT_GT(out.num_valid(), 0u);
  for (std::size_t p = 0; p < out.valid.size(); ++p) {
    if (out.valid[p]) {
      EXPECT_GE(out.values.data[p], -1e-5f);
      EXPECT_LE(out.values.data[p], 1 + 1e-5f);
    } else {
      EXPECT_EQ(out.values.data[p], 0.0f);
    }
  }
}

TEST(Preprocess, GrayscaleGivesOneChannelOfLuma) {
  const Image reference(4, 5, 3, 0.2f);
  Image frame = reference;
  for (std::size_t p = 0; p < frame.pixels(); ++p) {
    frame.data[p * 3 + 0] += 0.1f;  // R up
    frame.data[p * 3 + 2] -= 0.1f;  // B down
  }
  PreprocessOptions options;
  options.grayscale = true;
  options.fixed_scale = 1.0;
  const PreprocessedFrame out = Preprocess(frame, reference, SensorKind::kGelSlim, options);
  ASSERT_EQ(out.values.ShapeString(), "4x5x1");
  EXPECT_NEAR(out.values.at(2, 2), 0.299 * 0.1 - 0.114 * 0.1, 1e-6);
  options.grayscale = false;
  const PreprocessedFrame rgb = Preprocess(frame, reference, options);
  ASSERT_EQ(rgb.values.ShapeString(), "4x5x3");
  EXPECT_NEAR(rgb.values.at(0, 0, 0), 0.1, 1e-6);  // rgb: frame - reference
  EXPECT_NEAR(rgb.values.at(0, 0, 2), -0.1, 1e-6);
}

TEST(Preprocess, MismatchedShapesAreAnError) {
  EXPECT_THROW(Preprocess(Image(4, 4, 1, 0.03f), Image(4, 5, 1, 0.03f), PreprocessOptions(), 0.01),
               std::invalid_argument);
  EXPECT_THROW(Preprocess(Image(), Image(), PreprocessOptions(), 0.01), std::invalid_argument);
}

TEST(Preprocess, InfinitePixelsAreTreatedAsInvalid) {
  Image frame = FlatDepth(3, 3, 0.03f);
  frame.at(1, 1) = std::numeric_limits<float>::infinity();
  const PreprocessedFrame out =
      Preprocess(frame, FlatDepth(3, 3, 0.04f), PreprocessOptions(), 0.01);
  EXPECT_EQ(out.valid[4], 0);
  EXPECT_TRUE(AllFinite(out.values));
}

TEST(PreprocessFrame, UsesTheDatasetSensorAndItsScale) {
  testing_util::TestDir dir;
  SensorInfo info;
  info.kind = SensorKind::kSoftBubble;
  info.rows = info.cols = 16;
  info.encoding = PixelEncoding::kDepthU16Micrometres;
  info.normalization_scale = 0.004;
  const Image reference = FlatDepth(16, 16, 0.04f);
  {
    DatasetWriter writer(dir.path(), DatasetWriter::Options());
    writer.AddSensor(info, reference);
    writer.AddFrame("a", SensorKind::kSoftBubble, PressedDepth(reference, 0.002f), nullptr,
                    std::nullopt, Split::kTrain);
    writer.Finish();
  }
  const Dataset dataset = Dataset::Open(dir.path());
  const PreprocessedFrame out = PreprocessFrame(dataset, 0, PreprocessOptions());
  EXPECT_EQ(out.scale, 0.004);
  EXPECT_NEAR(out.values.at(8, 8), 0.5, 1e-4);
}

TEST(Difference, ABubblePressHasTheSignPreprocessGivesIt) {
  // Pressing the membrane brings it closer to the camera: smaller depth.
  const Image reference = FlatDepth(8, 8, 0.05f);
  const Image frame = PressedDepth(reference, 0.004f);
  PreprocessOptions options;
  const PreprocessedFrame preprocessed =
      Preprocess(frame, reference, SensorKind::kSoftBubble, options, 0.01);
  const Image difference = Difference(frame, reference, SensorKind::kSoftBubble);
  ASSERT_TRUE(difference.SameShape(frame));
  EXPECT_GT(difference.at(4, 4), 0.0f);  // a press is positive, as in Preprocess
  EXPECT_NEAR(difference.at(4, 4), 0.004f, 1e-6f);
  EXPECT_EQ(difference.at(0, 0), 0.0f);
  for (std::size_t i = 0; i < difference.size(); ++i) {
    EXPECT_NEAR(difference.data[i] / 0.01, preprocessed.values.data[i], 1e-6) << i;
  }
}

TEST(Difference, GelSlimIsFrameMinusReferenceAsInPreprocess) {
  Image reference(2, 2, 3, 0.25f), frame(2, 2, 3, 0.25f);
  frame.data[5] = 0.75f;
  const Image difference = Difference(frame, reference, SensorKind::kGelSlim);
  EXPECT_FLOAT_EQ(difference.data[5], 0.5f);
  const PreprocessedFrame preprocessed =
      Preprocess(frame, reference, SensorKind::kGelSlim, PreprocessOptions(), 1.0);
  EXPECT_FLOAT_EQ(preprocessed.values.data[5], 0.5f);
}

TEST(Difference, AShapeMismatchThrowsNamingTheShapes) {
  try {
    Difference(Image(2, 2, 1, 0.0f), Image(2, 3, 1, 0.0f), SensorKind::kSoftBubble);
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("reference"));
  }
}

// ---- PreprocessImage: steps 2-4 on an image itself ----------------------------------

// A 3-channel image with a gradient, a few NaN pixels and a few large values.
Image RgbTestImage(int rows, int cols) {
  Image image(rows, cols, 3);
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      for (int k = 0; k < 3; ++k) image.at(r, c, k) = 0.1f * k + 0.01f * r - 0.02f * c;
    }
  }
  image.at(1, 2, 0) = kNaN;
  image.at(4, 4, 2) = kNaN;
  image.at(0, 5, 1) = 7.5f;
  return image;
}

TEST(PreprocessImage, EqualsPreprocessOfTheImageAgainstAZeroReference) {
  const Image image = RgbTestImage(9, 13);
  const Image zeros(image.rows, image.cols, image.channels, 0.0f);
  for (bool grayscale : {false, true}) {
    for (int rows : {0, 4}) {
      for (Normalization normalization :
           {Normalization::kFixedScale, Normalization::kPerImageMinMax}) {
        PreprocessOptions options;
        options.rows = rows;
        options.cols = rows == 0 ? 0 : 6;
        options.grayscale = grayscale;
        options.normalization = normalization;
        options.fixed_scale = 0.5;
        // GelSlim's difference is frame - reference: the image itself against zeros.
        const PreprocessedFrame expected =
            Preprocess(image, zeros, SensorKind::kGelSlim, options);
        const PreprocessedFrame got = PreprocessImage(image, options);
        EXPECT_EQ(got.values.data, expected.values.data) << grayscale << " " << rows;
        EXPECT_TRUE(got.values.SameShape(expected.values));
        EXPECT_EQ(got.valid, expected.valid);
        EXPECT_EQ(got.scale, expected.scale);
        EXPECT_EQ(got.offset, expected.offset);
        EXPECT_EQ(got.source_range, expected.source_range);
      }
    }
  }
}

TEST(PreprocessImage, DepthIsTheImageNotAPressAndNaNPixelsAreInvalid) {
  Image depth(4, 5, 1, 0.05f);
  depth.at(2, 3) = kNaN;
  const PreprocessedFrame out = PreprocessImage(depth, PreprocessOptions(), 0.01);
  EXPECT_EQ(out.valid[2 * 5 + 3], 0);
  EXPECT_EQ(out.values.at(2, 3), 0.0f);
  EXPECT_EQ(out.num_valid(), 19u);
  EXPECT_NEAR(out.values.at(0, 0), 5.0f, 1e-6);  // 0.05 m over 0.01 m, positive
}

TEST(PreprocessImage, FixedScaleWithoutAScaleThrowsNamingIt) {
  try {
    PreprocessImage(Image(2, 2, 1, 0.05f), PreprocessOptions(), 0);
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("PreprocessImage: kFixedScale needs a scale"));
  }
}

}  // namespace
}  // namespace tactfunc
