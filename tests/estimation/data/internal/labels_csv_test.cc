// Copyright 2026 The tactfunc Authors.
//
// labels.csv text (estimation/data/internal/labels_csv.h, docs/DATASET_FORMAT.md):
// writing and reading back bit-exactly, the tolerated variations, quoting (not part of
// the format), and bad rows rejected with a message naming the line and the field.
#include "estimation/data/internal/labels_csv.h"

#include <cmath>
#include <optional>
#include <string>
#include <vector>

#include "estimation/data/internal/path_util.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"

namespace tactfunc::internal {
namespace {

using ::testing::HasSubstr;

constexpr const char* kPath = "DIR/labels.csv";

LabelRow Row(const std::string& frame, SensorKind sensor, Split split) {
  LabelRow row;
  row.frame = frame;
  row.sensor = sensor;
  row.split = split;
  return row;
}

LabelRow LabelledRow(const std::string& frame, SensorKind sensor, const std::string& tool,
                     double x, double y, double yaw, double depth, Split split) {
  LabelRow row = Row(frame, sensor, split);
  row.label = PoseLabel{tool, SE2d::FromXYYaw(x, y, yaw), depth};
  return row;
}

// The DatasetError message of parsing `text`, or "" if it parsed.
std::string ParseError(const std::string& text) {
  try {
    ParseLabelsCsv(text, kPath);
  } catch (const DatasetError& e) {
    return e.what();
  }
  return "";
}

std::string WithHeader(const std::string& rows) { return std::string(kLabelsHeader) + "\n" + rows; }

TEST(LabelsCsv, FormatThenParseRoundTripsBitExactly) {
  // Numbers without a short exact decimal form, a yaw of exactly pi, an unlabelled row
  // that only carries its split, both sensors.
  const std::vector<LabelRow> rows = {
      LabelledRow("000000", SensorKind::kSoftBubble, "rod", 0.1, -1.0 / 3.0, M_PI, 0.0,
                  Split::kTrain),
      LabelledRow("000000", SensorKind::kGelSlim, "l_shape", -2.5e-3, 1e-17, -M_PI / 7,
                  0.004321, Split::kTest),
      Row("000001", SensorKind::kSoftBubble, Split::kTest),
  };
  const std::string text = FormatLabelsCsv(rows);
  EXPECT_THAT(text, ::testing::StartsWith(std::string(kLabelsHeader) + "\n"));
  EXPECT_THAT(text, HasSubstr("\n000001,bubble,,,,,,test\n"));

  const std::vector<LabelRow> parsed = ParseLabelsCsv(text, kPath);
  ASSERT_EQ(parsed.size(), rows.size());
  for (std::size_t i = 0; i < rows.size(); ++i) {
    SCOPED_TRACE(i);
    EXPECT_EQ(parsed[i].line, static_cast<int>(i) + 2);  // the header is line 1
    EXPECT_EQ(parsed[i].frame, rows[i].frame);
    EXPECT_EQ(parsed[i].sensor, rows[i].sensor);
    EXPECT_EQ(parsed[i].split, rows[i].split);
    ASSERT_EQ(parsed[i].label.has_value(), rows[i].label.has_value());
    if (rows[i].label) {
      EXPECT_TRUE(*parsed[i].label == *rows[i].label);  // operator== compares exactly
      EXPECT_EQ(parsed[i].label->sensor_T_object.x(), rows[i].label->sensor_T_object.x());
      EXPECT_EQ(parsed[i].label->sensor_T_object.y(), rows[i].label->sensor_T_object.y());
    }
  }
  // Writing what was read gives the same text (deterministic output).
  EXPECT_EQ(FormatLabelsCsv(parsed), text);
}

TEST(LabelsCsv, ReadsThePoseIntoAnSe2dOnceWithItsYawInMinusPiToPi) {
  // The yaw column accepts [-pi, pi] with 1e-9 slack; in memory the pose is an SE2d,
  // whose yaw is in (-pi, pi]: -pi reads as pi and a yaw in the slack wraps around.
  const std::vector<LabelRow> parsed = ParseLabelsCsv(
      WithHeader("a,bubble,rod,0.001,-0.002,-3.141592653589793,0.003,train\n"
                 "b,bubble,rod,0,0,0.5,0,test\n"),
      kPath);
  ASSERT_EQ(parsed.size(), 2u);
  ASSERT_TRUE(parsed[0].label.has_value());
  EXPECT_EQ(parsed[0].label->sensor_T_object.x(), 0.001);
  EXPECT_EQ(parsed[0].label->sensor_T_object.y(), -0.002);
  EXPECT_EQ(parsed[0].label->sensor_T_object.yaw(), M_PI);
  EXPECT_EQ(parsed[0].label->depth_m, 0.003);
  EXPECT_EQ(parsed[1].label->sensor_T_object.yaw(), 0.5);
  EXPECT_THAT(ParseError(WithHeader("a,bubble,rod,0,0,3.2,0,train\n")),
              HasSubstr("field 'yaw_rad': expected a finite number in "
                        "[-3.1416, 3.1416], got '3.2'"));
}

TEST(LabelsCsv, AcceptsCrLfBlankLinesAByteOrderMarkAndSensorAliases) {
  const std::string text = "\xEF\xBB\xBF" + std::string(kLabelsHeader) +
                           "\r\n"
                           "\r\n"
                           "a,soft_bubble,rod,0,0,0,0,train\r\n"
                           "   \n"
                           "b,gel_slim,,,,,,test";  // no final line break
  const std::vector<LabelRow> rows = ParseLabelsCsv(text, kPath);
  ASSERT_EQ(rows.size(), 2u);
  EXPECT_EQ(rows[0].line, 3);
  EXPECT_EQ(rows[0].sensor, SensorKind::kSoftBubble);
  EXPECT_EQ(rows[1].line, 5);
  EXPECT_EQ(rows[1].sensor, SensorKind::kGelSlim);
  EXPECT_FALSE(rows[1].label.has_value());
  EXPECT_EQ(rows[1].split, Split::kTest);
}

TEST(LabelsCsv, QuotedFieldsAreNotPartOfTheFormatAndAreRejectedNamingTheLine) {
  // CSV-style quoting of a field with a comma: the comma still splits it, so the row
  // has too many fields.
  std::string error = ParseError(WithHeader("a,bubble,\"rod, long\",0,0,0,0,train\n"));
  EXPECT_THAT(error, HasSubstr("DIR/labels.csv:2: "));
  EXPECT_THAT(error, HasSubstr("expected 8 comma-separated fields"));
  EXPECT_THAT(error, HasSubstr("got 9"));
  // Quotes around a single field are kept as text and fail that field's check.
  error = ParseError(WithHeader("a,bubble,rod,0,0,0,0,train\nb,bubble,\"rod\",0,0,0,0,test\n"));
  EXPECT_THAT(error, HasSubstr("DIR/labels.csv:3: field 'tool'"));
  EXPECT_THAT(error, HasSubstr("'\"rod\"'"));
  error = ParseError(WithHeader("a,\"bubble\",rod,0,0,0,0,train\n"));
  EXPECT_THAT(error, HasSubstr("DIR/labels.csv:2: field 'sensor'"));
  error = ParseError(WithHeader("a,bubble,rod,\"0.001\",0,0,0,train\n"));
  EXPECT_THAT(error, HasSubstr("DIR/labels.csv:2: field 'x_m': expected a finite number"));
  EXPECT_FALSE(IsCsvSafe("\"rod\""));
  EXPECT_FALSE(IsCsvSafe("rod,long"));
  EXPECT_FALSE(IsCsvSafe("rod\nlong"));
  EXPECT_TRUE(IsCsvSafe("l_shape"));
}

TEST(LabelsCsv, BadRowsAreErrorsNamingTheLineTheFieldAndWhatWasFound) {
  struct Case {
    std::string row;
    std::string message;
  };
  const std::vector<Case> cases = {
      {"a,bubble,rod,0,0,0,0", "DIR/labels.csv:3: expected 8 comma-separated fields"},
      {",bubble,rod,0,0,0,0,train", "DIR/labels.csv:3: field 'frame': expected a frame id"},
      {"a,digit,rod,0,0,0,0,train", "DIR/labels.csv:3: field 'sensor': expected 'bubble' or "
                                    "'gelslim', got 'digit'"},
      {"a,bubble,rod,0,0,0,0,val", "DIR/labels.csv:3: field 'split': expected 'train' or "
                                   "'test', got 'val'"},
      {"a,bubble,,0,0,0,0,train", "DIR/labels.csv:3: field 'tool': expected a tool name"},
      {"a,bubble,rod,0.1x,0,0,0,train", "field 'x_m': expected a finite number, got '0.1x'"},
      {"a,bubble,rod,0, 0,0,0,train", "field 'y_m': expected a finite number, got ' 0'"},
      {"a,bubble,rod,0,0,nan,0,train", "field 'yaw_rad': expected a finite number, got 'nan'"},
      {"a,bubble,rod,0,0,7.2,0,train", "DIR/labels.csv:3: field 'yaw_rad': expected a finite "
                                       "number in [-3.1416, 3.1416], got '7.2'"},
      {"a,bubble,rod,0,0,0,-0.001,train", "field 'depth_m': expected a finite number in [0, "
                                          "0.1], got '-0.001'"},
      {"a,bubble,rod,2,0,0,0,train", "field 'x_m': expected a finite number in [-1, 1] (pixel "
                                     "pitch unknown), got '2'"},
      {"b,bubble,rod,0,0,0,0,test", "DIR/labels.csv:3: duplicate label for frame 'b', sensor "
                                    "'bubble'"},
  };
  for (const Case& c : cases) {
    // Line 2 is a good row for frame b, so the bad row is line 3.
    const std::string error = ParseError(WithHeader("b,bubble,rod,0,0,0,0,train\n" + c.row));
    EXPECT_THAT(error, HasSubstr(c.message)) << c.row;
  }
}

TEST(LabelsCsv, AMissingOrWrongHeaderIsAnErrorOnLineOne) {
  EXPECT_THAT(ParseError(""), HasSubstr("DIR/labels.csv:1: header: expected '" +
                                        std::string(kLabelsHeader) + "', got an empty file"));
  EXPECT_THAT(ParseError("frame,x,y\na,b,c\n"),
              HasSubstr("DIR/labels.csv:1: header: expected '" + std::string(kLabelsHeader) +
                        "', got 'frame,x,y'"));
  // Header only: no rows, no error.
  EXPECT_TRUE(ParseLabelsCsv(std::string(kLabelsHeader) + "\n", kPath).empty());
}

TEST(FindPoseLabelProblem, ChecksPositionsAgainstTheSensorsExtentWhenThePitchIsKnown) {
  PoseLabel label;
  label.tool = "rod";
  // A 100-pixel-wide sensor at 0.2 mm: half width 10 mm.
  label.sensor_T_object = SE2d::Trans(0.009, -0.005);
  EXPECT_FALSE(FindPoseLabelProblem(label, 50, 100, 2e-4).has_value());
  label.sensor_T_object = SE2d::Trans(0.011, -0.005);
  std::optional<PoseLabelProblem> problem = FindPoseLabelProblem(label, 50, 100, 2e-4);
  ASSERT_TRUE(problem.has_value());
  EXPECT_EQ(problem->column, 3);
  EXPECT_STREQ(LabelsColumnName(problem->column), "x_m");
  EXPECT_THAT(problem->expected, HasSubstr("half the sensor's extent"));
  label.sensor_T_object = SE2d::Trans(0, 0.006);  // half height 5 mm
  problem = FindPoseLabelProblem(label, 50, 100, 2e-4);
  ASSERT_TRUE(problem.has_value());
  EXPECT_EQ(problem->column, 4);
  // Without a pitch the bound is 1 m.
  EXPECT_FALSE(FindPoseLabelProblem(label, 0, 0, 0).has_value());
  label.tool = "rod,2";
  problem = FindPoseLabelProblem(label, 0, 0, 0);
  ASSERT_TRUE(problem.has_value());
  EXPECT_EQ(problem->column, 2);
}

TEST(LabelsCsv, ColumnNamesAndFieldTextFollowTheHeader) {
  const char* expected[] = {"frame", "sensor", "tool", "x_m", "y_m", "yaw_rad", "depth_m",
                            "split"};
  for (int c = 0; c < 8; ++c) EXPECT_STREQ(LabelsColumnName(c), expected[c]);
  EXPECT_STREQ(LabelsColumnName(8), "?");
  PoseLabel label;
  label.tool = "square";
  label.sensor_T_object = SE2d::Trans(0.1, 0);
  label.depth_m = 0.002;
  EXPECT_EQ(PoseFieldText(label, 2), "square");
  double x = 0;
  ASSERT_TRUE(ParseDouble(PoseFieldText(label, 3), &x));
  EXPECT_EQ(x, 0.1);
  EXPECT_EQ(PoseFieldText(label, 7), "");
}

}  // namespace
}  // namespace tactfunc::internal
