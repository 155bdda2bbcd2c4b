// Copyright 2026 The tactfunc Authors.
#include "models/core/sensor_description.h"

#include <cmath>
#include <string>
#include <vector>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace tactfunc {
namespace {

using ::testing::HasSubstr;

constexpr const char* kFile = "dir/sensor.json";

// A valid optical description with a crop; each bad-field case replaces one piece.
std::string CropJson(const std::string& crop = R"({"x": 20, "y": 10, "width": 120, "height": 90})") {
  return R"({"format": "tactfunc-sensor", "version": 1, "name": "gelsight_wedge",
             "kind": "optical", "channels": 3, "crop": )" +
         crop + R"(, "working_size": {"rows": 45, "cols": 60}, "aspect": "crop",
             "pixel_pitch_mm": 0.1245, "normalization_scale": 0.5, "markers": false})";
}

TEST(SensorDescription, ParsesEveryFieldOfACropDescription) {
  const SensorDescription d = ParseSensorDescription(CropJson(), kFile);
  EXPECT_EQ(d.name, "gelsight_wedge");
  EXPECT_EQ(d.kind, SensorKind::kGelSlim);
  EXPECT_EQ(d.channels, 3);
  EXPECT_EQ(d.geometry, SensorDescription::Geometry::kCrop);
  EXPECT_EQ(d.crop_x, 20);
  EXPECT_EQ(d.crop_y, 10);
  EXPECT_EQ(d.crop_width, 120);
  EXPECT_EQ(d.crop_height, 90);
  EXPECT_EQ(d.working_rows, 45);
  EXPECT_EQ(d.working_cols, 60);
  EXPECT_EQ(d.aspect, SensorDescription::Aspect::kCrop);
  EXPECT_DOUBLE_EQ(d.pixel_pitch_m, 0.1245e-3);
  EXPECT_DOUBLE_EQ(d.normalization_scale, 0.5);
  EXPECT_FALSE(d.markers);
}

TEST(SensorDescription, ParsesAPerspectiveDepthDescriptionWithDefaults) {
  const SensorDescription d = ParseSensorDescription(
      R"({"name": "bubble2", "kind": "depth",
          "perspective": {"corners": [[10, 5], [150, 8], [148, 110], [12, 112]],
                          "rows": 100, "cols": 140},
          "pixel_pitch_mm": 0.45, "normalization_scale": 0.01})",
      kFile);
  EXPECT_EQ(d.kind, SensorKind::kSoftBubble);
  EXPECT_EQ(d.channels, 1);  // the default of a depth sensor
  EXPECT_EQ(d.geometry, SensorDescription::Geometry::kPerspective);
  EXPECT_EQ(d.corners[2][0], 148);
  EXPECT_EQ(d.corners[3][1], 112);
  EXPECT_EQ(d.warp_rows, 100);
  EXPECT_EQ(d.warp_cols, 140);
  EXPECT_EQ(d.working_rows, 0);
  EXPECT_FALSE(d.markers);
}

struct BadField {
  std::string json;
  std::string field;     // named in the message
  std::string expected;  // part of what the message says was expected
};

TEST(SensorDescription, EachBadFieldIsNamedWithTheFileAndWhatWasExpected) {
  const std::string pitch = R"("pixel_pitch_mm": 0.1, "normalization_scale": 0.5)";
  const std::vector<BadField> cases = {
      {"[1, 2]", "(top level)", "a JSON object"},
      {"{", "", "valid JSON"},
      {R"({"format": "other", "name": "a", "kind": "optical", )" + pitch + "}", "format",
       "tactfunc-sensor"},
      {R"({"version": 2, "name": "a", "kind": "optical", )" + pitch + "}", "version", "1"},
      {R"({"kind": "optical", )" + pitch + "}", "name", "a name"},
      {R"({"name": "a b", "kind": "optical", )" + pitch + "}", "name", "[A-Za-z0-9_.-]"},
      {R"({"name": "a", )" + pitch + "}", "kind", "\"depth\""},
      {R"({"name": "a", "kind": "tactile", )" + pitch + "}", "kind", "\"optical\""},
      {R"({"name": "a", "kind": "depth", "channels": 3, )" + pitch + "}", "channels",
       "a depth sensor has one channel"},
      {R"({"name": "a", "kind": "optical", "channels": 2, )" + pitch + "}", "channels",
       "3 (RGB) or 1 (luma)"},
      {CropJson(R"({"x": 20, "y": 10, "width": 0, "height": 90})"), "crop.width",
       "an integer in [1, "},
      {CropJson(R"({"x": -1, "y": 10, "width": 5, "height": 90})"), "crop.x",
       "an integer in [0, "},
      {CropJson(R"({"x": 0, "y": 10, "width": 5})"), "crop.height", "got no such field"},
      {CropJson(R"({"x": 0, "y": 0, "width": 5, "height": 5, "w": 1})"), "crop.w",
       "one of the fields"},
      {CropJson("[0, 0, 5, 5]"), "crop", "an object"},
      {R"({"name": "a", "kind": "optical", "crop": {"x": 0, "y": 0, "width": 5, "height": 5},
           "perspective": {"corners": [[0,0],[5,0],[5,5],[0,5]], "rows": 5, "cols": 5}, )" +
           pitch + "}",
       "perspective", "either 'crop' or 'perspective'"},
      {R"({"name": "a", "kind": "optical", "perspective": {"corners": [[0,0],[5,0],[5,5]],
           "rows": 5, "cols": 5}, )" + pitch + "}",
       "perspective.corners", "four [x, y] points"},
      {R"({"name": "a", "kind": "optical", "perspective": {"corners": [[0,0],[5,0],[5,5],[0,"x"]],
           "rows": 5, "cols": 5}, )" + pitch + "}",
       "perspective.corners[3]", "[x, y] with finite x, y"},
      // Listed counter-clockwise: bottom-left where top-right belongs.
      {R"({"name": "a", "kind": "optical", "perspective": {"corners": [[0,0],[0,5],[5,5],[5,0]],
           "rows": 5, "cols": 5}, )" + pitch + "}",
       "perspective.corners", "a convex quadrilateral"},
      {R"({"name": "a", "kind": "optical", "perspective": {"corners": [[0,0],[5,0],[5,5],[0,5]],
           "cols": 5}, )" + pitch + "}",
       "perspective.rows", "an integer in [1, "},
      {R"({"name": "a", "kind": "optical", "working_size": {"rows": 0, "cols": 5}, )" + pitch + "}",
       "working_size.rows", "an integer in [1, 4096]"},
      {R"({"name": "a", "kind": "optical", "working_size": "60x80", )" + pitch + "}",
       "working_size", "an object"},
      {R"({"name": "a", "kind": "optical", "working_size": {"rows": 6, "cols": 8},
           "aspect": "fit", )" + pitch + "}",
       "aspect", "\"crop\", \"pad\" or \"stretch\""},
      {R"({"name": "a", "kind": "optical", "aspect": "crop", )" + pitch + "}", "aspect",
       "only with 'working_size'"},
      {R"({"name": "a", "kind": "optical", "normalization_scale": 0.5})", "pixel_pitch_mm",
       "got no such field"},
      {R"({"name": "a", "kind": "optical", "pixel_pitch_mm": 0, "normalization_scale": 0.5})",
       "pixel_pitch_mm", "a finite number > 0"},
      {R"({"name": "a", "kind": "optical", "pixel_pitch_mm": 1000, "normalization_scale": 0.5})",
       "pixel_pitch_mm", "at most 100 mm"},
      {R"({"name": "a", "kind": "optical", "pixel_pitch_mm": 0.1, "normalization_scale": -1})",
       "normalization_scale", "a finite number > 0"},
      {R"({"name": "a", "kind": "optical", )" + pitch + R"(, "markers": "yes"})", "markers",
       "true or false"},
      {R"({"name": "a", "kind": "optical", )" + pitch + R"(, "pitch": 1})", "pitch",
       "one of the fields"},
  };
  for (const BadField& c : cases) {
    SCOPED_TRACE(c.json);
    try {
      ParseSensorDescription(c.json, kFile);
      ADD_FAILURE() << "accepted";
    } catch (const SensorDescriptionError& e) {
      const std::string message = e.what();
      EXPECT_THAT(message, HasSubstr(kFile));
      if (!c.field.empty()) {
        EXPECT_THAT(message, HasSubstr("field '" + c.field + "'"));
      }
      EXPECT_THAT(message, HasSubstr(c.expected));
    }
  }
}

TEST(SensorDescription, AMissingFileIsNamed) {
  try {
    ReadSensorDescriptionFile("/nonexistent/sensor.json");
    ADD_FAILURE() << "accepted";
  } catch (const SensorDescriptionError& e) {
    EXPECT_THAT(e.what(), HasSubstr("/nonexistent/sensor.json"));
  }
}

TEST(SensorDescription, RoundTripsThroughItsJson) {
  for (const std::string& json :
       {CropJson(), std::string(R"({"name": "p", "kind": "depth", "perspective":
          {"corners": [[10.5, 5], [150, 8.25], [148, 110], [12, 112]], "rows": 100, "cols": 140},
          "working_size": {"rows": 50, "cols": 70}, "aspect": "stretch",
          "pixel_pitch_mm": 0.45, "normalization_scale": 0.01, "markers": true})")}) {
    const SensorDescription d = ParseSensorDescription(json, kFile);
    const SensorDescription back = ParseSensorDescription(SensorDescriptionToJson(d), "again");
    EXPECT_TRUE(SameFrames(d, back)) << SensorDescriptionToJson(d);
    EXPECT_EQ(back.name, d.name);
    EXPECT_EQ(back.markers, d.markers);
    EXPECT_EQ(SensorDescriptionToJson(back), SensorDescriptionToJson(d));
  }
  // A built-in's unknown pitch reads back only where allowed (model files).
  const SensorDescription builtin = BuiltInSensorDescription(SensorKind::kGelSlim);
  EXPECT_THROW(ParseSensorDescription(SensorDescriptionToJson(builtin), "m"),
               SensorDescriptionError);
  EXPECT_TRUE(SameFrames(
      ParseSensorDescription(SensorDescriptionToJson(builtin), "m", /*allow_unknown_pitch=*/true),
      builtin));
}

TEST(SensorDescription, FrameDifferencesNameEachDifferingField) {
  const SensorDescription a = ParseSensorDescription(CropJson(), kFile);
  SensorDescription b = a;
  b.name = "other";
  b.markers = true;
  EXPECT_TRUE(SameFrames(a, b));  // name and markers do not change the frames
  b.crop_x = 21;
  b.pixel_pitch_m = 0.2e-3;
  b.working_cols = 61;
  const std::vector<std::string> d = FrameDifferences(a, b);
  ASSERT_EQ(d.size(), 3u);
  EXPECT_THAT(d[0], HasSubstr("geometry: crop x 20 y 10 -> 90x120 vs crop x 21"));
  EXPECT_THAT(d[1], HasSubstr("working_size: 45x60 (aspect crop) vs 45x61"));
  EXPECT_THAT(d[2], HasSubstr("pixel_pitch_mm: 0.1245 vs 0.2"));
}

TEST(SensorDescription, BuiltInsAreTheTwoSensorsAsTheyWereAlwaysRead) {
  const SensorDescription bubble = BuiltInSensorDescription(SensorKind::kSoftBubble);
  EXPECT_EQ(bubble.kind, SensorKind::kSoftBubble);
  EXPECT_EQ(bubble.channels, SensorChannels(SensorKind::kSoftBubble));
  EXPECT_EQ(bubble.geometry, SensorDescription::Geometry::kNone);
  EXPECT_EQ(bubble.working_rows, 0);
  const SensorDescription gelslim = BuiltInSensorDescription(SensorKind::kGelSlim);
  EXPECT_EQ(gelslim.channels, SensorChannels(SensorKind::kGelSlim));
  EXPECT_TRUE(gelslim.markers);
  // No geometry: the very same pixels come back.
  Image depth(7, 9, 1, 0.05f);
  depth.at(3, 4) = std::nanf("");
  const Image out = ApplySensorGeometry(depth, bubble, "b");
  ASSERT_TRUE(out.SameShape(depth));
  EXPECT_TRUE(std::isnan(out.at(3, 4)));
  for (std::size_t i = 0; i < depth.size(); ++i) {
    if (i != 3 * 9 + 4) {
      EXPECT_EQ(out.data[i], depth.data[i]);
    }
  }
}

// An image whose value encodes its position, so a crop can be checked pixel by pixel.
Image Ramp(int rows, int cols, int channels) {
  Image image(rows, cols, channels);
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      for (int k = 0; k < channels; ++k) image.at(r, c, k) = (r * 1000 + c) * 1e-5f + k * 0.1f;
    }
  }
  return image;
}

TEST(SensorGeometry, CropCutsTheRectangleExactly) {
  const SensorDescription d = ParseSensorDescription(
      R"({"name": "c", "kind": "optical", "crop": {"x": 20, "y": 10, "width": 120, "height": 90},
          "pixel_pitch_mm": 0.1, "normalization_scale": 0.5})",
      kFile);
  const Image raw = Ramp(120, 160, 3);
  const Image out = ApplySensorGeometry(raw, d, kFile);
  ASSERT_EQ(out.rows, 90);
  ASSERT_EQ(out.cols, 120);
  ASSERT_EQ(out.channels, 3);
  for (int r = 0; r < 90; ++r) {
    for (int c = 0; c < 120; ++c) {
      for (int k = 0; k < 3; ++k) ASSERT_EQ(out.at(r, c, k), raw.at(r + 10, c + 20, k));
    }
  }
  int rows = 0, cols = 0;
  GeometryOutputSize(d, 120, 160, kFile, &rows, &cols);
  EXPECT_EQ(rows, 90);
  EXPECT_EQ(cols, 120);
  // A rectangle that does not fit the frames is refused, naming the field.
  try {
    GeometryOutputSize(d, 99, 160, kFile, &rows, &cols);
    ADD_FAILURE() << "accepted";
  } catch (const SensorDescriptionError& e) {
    EXPECT_THAT(e.what(), HasSubstr("dir/sensor.json: field 'crop': expected a rectangle inside "
                                    "the 99x160 (rows x cols) frames"));
  }
}

TEST(SensorGeometry, APerspectiveOfAnAxisAlignedRectangleIsItsCrop) {
  const SensorDescription d = ParseSensorDescription(
      R"({"name": "p", "kind": "optical", "perspective":
          {"corners": [[20, 10], [140, 10], [140, 100], [20, 100]], "rows": 90, "cols": 120},
          "pixel_pitch_mm": 0.1, "normalization_scale": 0.5})",
      kFile);
  const Image raw = Ramp(120, 160, 3);
  const Image out = ApplySensorGeometry(raw, d, kFile);
  ASSERT_EQ(out.rows, 90);
  ASSERT_EQ(out.cols, 120);
  for (int r = 0; r < 90; ++r) {
    for (int c = 0; c < 120; ++c) {
      for (int k = 0; k < 3; ++k) ASSERT_NEAR(out.at(r, c, k), raw.at(r + 10, c + 20, k), 1e-5);
    }
  }
}

// A square seen through a known perspective: the raw frame shows the image of a 50 x 50
// square under the homography that maps the 100 x 100 rectangle onto `corners`; warping
// the quadrilateral back must give the square, square and where it was.
TEST(SensorGeometry, AWarpedSquareComesOutSquare) {
  const std::vector<cv::Point2f> corners = {{40, 30}, {205, 52}, {190, 175}, {28, 150}};
  const std::vector<cv::Point2f> rectangle = {{0, 0}, {100, 0}, {100, 100}, {0, 100}};
  // Raw (edge coordinates) -> rectangle (edge coordinates).
  const cv::Mat to_rectangle = cv::getPerspectiveTransform(corners, rectangle);
  Image raw(200, 240, 3, 0.2f);
  for (int r = 0; r < raw.rows; ++r) {
    for (int c = 0; c < raw.cols; ++c) {
      std::vector<cv::Point2f> p = {{c + 0.5f, r + 0.5f}}, q;
      cv::perspectiveTransform(p, q, to_rectangle);
      if (q[0].x >= 25 && q[0].x < 75 && q[0].y >= 25 && q[0].y < 75) {
        for (int k = 0; k < 3; ++k) raw.at(r, c, k) = 0.9f;
      }
    }
  }
  const SensorDescription d = ParseSensorDescription(
      R"({"name": "w", "kind": "optical", "perspective":
          {"corners": [[40, 30], [205, 52], [190, 175], [28, 150]], "rows": 100, "cols": 100},
          "pixel_pitch_mm": 0.1, "normalization_scale": 0.5})",
      kFile);
  const Image out = ApplySensorGeometry(raw, d, kFile);
  ASSERT_EQ(out.rows, 100);
  ASSERT_EQ(out.cols, 100);
  int top = 100, bottom = -1, left = 100, right = -1, area = 0;
  for (int r = 0; r < 100; ++r) {
    for (int c = 0; c < 100; ++c) {
      if (out.at(r, c, 1) < 0.55f) continue;
      ++area;
      top = std::min(top, r);
      bottom = std::max(bottom, r);
      left = std::min(left, c);
      right = std::max(right, c);
    }
  }
  // Where it was, to a pixel (the raw frame's own sampling blurs each edge by about one).
  EXPECT_NEAR(top, 25, 1);
  EXPECT_NEAR(left, 25, 1);
  EXPECT_NEAR(bottom, 74, 1);
  EXPECT_NEAR(right, 74, 1);
  // Square: as tall as wide, and filling its bounding box (not a rhombus).
  EXPECT_NEAR(bottom - top, right - left, 1);
  EXPECT_NEAR(area, 2500, 0.06 * 2500);
  // Without the warp (a plain crop of the quadrilateral's bounding box) the same pixels
  // are no square: the test can fail.
  const Image raw_crop = ApplySensorGeometry(
      raw,
      ParseSensorDescription(
          R"({"name": "c", "kind": "optical", "crop": {"x": 28, "y": 30, "width": 177, "height": 145},
              "pixel_pitch_mm": 0.1, "normalization_scale": 0.5})",
          kFile),
      kFile);
  int crop_top = raw_crop.rows, crop_bottom = -1, crop_left = raw_crop.cols, crop_right = -1;
  for (int r = 0; r < raw_crop.rows; ++r) {
    for (int c = 0; c < raw_crop.cols; ++c) {
      if (raw_crop.at(r, c, 1) < 0.55f) continue;
      crop_top = std::min(crop_top, r);
      crop_bottom = std::max(crop_bottom, r);
      crop_left = std::min(crop_left, c);
      crop_right = std::max(crop_right, c);
    }
  }
  EXPECT_GT(std::abs((crop_bottom - crop_top) - (crop_right - crop_left)), 5);
}

TEST(SensorGeometry, DepthIsWarpedMaskAware) {
  // A flat membrane 0.05 m away with a dropout block: the warp keeps the valid depth
  // exactly (no zeros pulled in at the hole's edge) and the hole stays a hole.
  Image raw(60, 80, 1, 0.05f);
  for (int r = 20; r < 30; ++r) {
    for (int c = 30; c < 45; ++c) raw.at(r, c) = std::nanf("");
  }
  const SensorDescription d = ParseSensorDescription(
      R"({"name": "b", "kind": "depth", "perspective":
          {"corners": [[5, 4], [75, 6], [74, 57], [6, 55]], "rows": 50, "cols": 70},
          "pixel_pitch_mm": 0.45, "normalization_scale": 0.01})",
      kFile);
  const Image out = ApplySensorGeometry(raw, d, kFile);
  ASSERT_EQ(out.rows, 50);
  ASSERT_EQ(out.cols, 70);
  int invalid = 0;
  for (float v : out.data) {
    if (std::isnan(v)) {
      ++invalid;
    } else {
      EXPECT_NEAR(v, 0.05f, 1e-6f);
    }
  }
  // The hole: 10 x 15 raw pixels, at about the same scale (70 / 70 by 50 / 51).
  EXPECT_GT(invalid, 100);
  EXPECT_LT(invalid, 200);
}

TEST(SensorGeometry, AspectCropKeepsTheCentredWindowAndLumaMakesOneChannel) {
  const SensorDescription d = ParseSensorDescription(
      R"({"name": "a", "kind": "optical", "channels": 1, "working_size": {"rows": 60, "cols": 60},
          "pixel_pitch_mm": 0.1, "normalization_scale": 0.5})",
      kFile);
  const Image raw = Ramp(120, 160, 3);
  const Image out = ApplySensorGeometry(raw, d, kFile);
  ASSERT_EQ(out.rows, 120);
  ASSERT_EQ(out.cols, 120);  // the square window of a 4:3 frame
  ASSERT_EQ(out.channels, 1);
  for (int r = 0; r < 120; r += 7) {
    for (int c = 0; c < 120; c += 5) {
      const float expected = 0.299f * raw.at(r, c + 20, 0) + 0.587f * raw.at(r, c + 20, 1) +
                             0.114f * raw.at(r, c + 20, 2);
      EXPECT_FLOAT_EQ(out.at(r, c), expected);
    }
  }
  // "stretch" keeps the whole frame.
  SensorDescription stretch = d;
  stretch.aspect = SensorDescription::Aspect::kStretch;
  EXPECT_EQ(ApplySensorGeometry(raw, stretch, kFile).cols, 160);
  // Three channels cannot come from one.
  SensorDescription rgb = d;
  rgb.channels = 3;
  EXPECT_THROW(ApplySensorGeometry(Image(10, 10, 1), rgb, kFile), SensorDescriptionError);
}

TEST(SensorGeometry, AspectPadKeepsEveryPixelInsideAZeroOrInvalidBorder) {
  // A 4:3 optical frame padded to a square: 20 rows above, 20 below, nothing cut.
  SensorDescription d = ParseSensorDescription(
      R"({"name": "a", "kind": "optical", "working_size": {"rows": 60, "cols": 60},
          "aspect": "pad", "pixel_pitch_mm": 0.1, "normalization_scale": 0.5})",
      kFile);
  EXPECT_EQ(d.aspect, SensorDescription::Aspect::kPad);
  EXPECT_THAT(SensorDescriptionToJson(d), HasSubstr("\"aspect\":\"pad\""));
  EXPECT_THAT(DescribeSensor(d), HasSubstr("(aspect pad)"));
  const Image raw = Ramp(120, 160, 3);
  const Image out = ApplySensorGeometry(raw, d, kFile);
  ASSERT_EQ(out.rows, 160);
  ASSERT_EQ(out.cols, 160);
  int rows = 0, cols = 0;
  GeometryOutputSize(d, 120, 160, kFile, &rows, &cols);
  EXPECT_EQ(rows, 160);
  EXPECT_EQ(cols, 160);
  for (int c = 0; c < 160; c += 3) {
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(out.at(0, c, k), 0.0f);
      EXPECT_EQ(out.at(19, c, k), 0.0f);
      EXPECT_EQ(out.at(20, c, k), raw.at(0, c, k));
      EXPECT_EQ(out.at(139, c, k), raw.at(119, c, k));
      EXPECT_EQ(out.at(140, c, k), 0.0f);
      EXPECT_EQ(out.at(159, c, k), 0.0f);
    }
  }
  // A tall depth frame gains columns, invalid: 5 rows x 2 cols to 1:1 -> 5 x 5, the odd
  // column at the right.
  d.kind = SensorKind::kSoftBubble;
  d.channels = 1;
  const Image depth = Ramp(5, 2, 1);
  const Image padded = ApplySensorGeometry(depth, d, kFile);
  ASSERT_EQ(padded.rows, 5);
  ASSERT_EQ(padded.cols, 5);
  for (int r = 0; r < 5; ++r) {
    EXPECT_TRUE(std::isnan(padded.at(r, 0)));
    EXPECT_EQ(padded.at(r, 1), depth.at(r, 0));
    EXPECT_EQ(padded.at(r, 2), depth.at(r, 1));
    EXPECT_TRUE(std::isnan(padded.at(r, 3)));
    EXPECT_TRUE(std::isnan(padded.at(r, 4)));
  }
  // A frame already of the working aspect is returned as read.
  EXPECT_EQ(ApplySensorGeometry(Ramp(6, 6, 1), d, kFile).data, Ramp(6, 6, 1).data);
}

}  // namespace
}  // namespace tactfunc
