// Copyright 2026 The tactfunc Authors.
#include "estimation/data/dataset.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/support/image_test_util.h"
#include "tests/support/dataset_test_util.h"
#include "tests/support/test_dir.h"

namespace tactfunc {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using testing_util::TestDir;
using testing_util::WriteText;

using testing_util::kNaN;
constexpr int kBubbleRows = 12;
constexpr int kBubbleCols = 15;
constexpr double kBubblePitch = 0.0004;  // half extent: 3 mm x 2.4 mm
constexpr int kGelRows = 10;
constexpr int kGelCols = 14;
constexpr int kNumIds = 5;

using testing_util::BitIdentical;
using testing_util::ExpectDatasetError;

std::string Id(int i) {
  char id[16];
  std::snprintf(id, sizeof(id), "%06d", i);
  return id;
}

Image BubbleFrame(unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> code(30000, 40000);
  Image image(kBubbleRows, kBubbleCols, 1);
  for (float& v : image.data) v = static_cast<float>(code(rng) / 1e6);
  image.data[seed % image.size()] = kNaN;
  return image;
}

Image GelFrame(unsigned seed, int channels = 3, int rows = kGelRows, int cols = kGelCols) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> code(0, 255);
  Image image(rows, cols, channels);
  for (float& v : image.data) v = code(rng) / 255.0f;
  return image;
}

SensorInfo BubbleInfo() {
  SensorInfo info;
  info.kind = SensorKind::kSoftBubble;
  info.rows = kBubbleRows;
  info.cols = kBubbleCols;
  info.channels = 1;
  info.encoding = PixelEncoding::kDepthU16Micrometres;
  info.pixel_pitch_m = kBubblePitch;
  info.normalization_scale = 0.01;
  return info;
}

SensorInfo GelInfo() {
  SensorInfo info;
  info.kind = SensorKind::kGelSlim;
  info.rows = kGelRows;
  info.cols = kGelCols;
  info.channels = 3;
  info.encoding = PixelEncoding::kRgb8;
  info.pixel_pitch_m = 0.0005;
  info.normalization_scale = 0.25;
  return info;
}

// What a written dataset should hold, for comparison after Open.
struct Written {
  Image bubble_reference;
  Image gel_reference;
  std::map<std::pair<std::string, SensorKind>, Image> frames;
  std::map<std::pair<std::string, SensorKind>, Image> clean;
  std::map<std::pair<std::string, SensorKind>, std::optional<PoseLabel>> labels;
  std::map<std::pair<std::string, SensorKind>, Split> splits;
};

// Both sensors, ids 000000..000004; the bubble frames have clean versions; frame
// 000003 is unlabelled (and in the test split), frame 000001 is a test frame.
Written WriteDataset(const std::string& dir) {
  Written w;
  DatasetWriter::Options options;
  options.source = "dataset_test";
  options.meta_json = R"({"seed": 7})";
  DatasetWriter writer(dir, options);
  w.bubble_reference = BubbleFrame(100);
  w.gel_reference = GelFrame(101);
  writer.AddSensor(BubbleInfo(), w.bubble_reference);
  writer.AddSensor(GelInfo(), w.gel_reference);
  for (int i = kNumIds - 1; i >= 0; --i) {  // out of order on purpose
    for (SensorKind sensor : {SensorKind::kGelSlim, SensorKind::kSoftBubble}) {
      const auto key = std::make_pair(Id(i), sensor);
      const bool bubble = sensor == SensorKind::kSoftBubble;
      w.frames[key] = bubble ? BubbleFrame(i) : GelFrame(i);
      std::optional<PoseLabel> label;
      if (i != 3) {
        // i == 4: yaw pi, the edge of the range.
        label = PoseLabel{i % 2 ? "hex_key" : "pen",
                          SE2d::FromXYYaw(0.0001 * i - 0.0002, -0.0003 * i + 0.001,
                                          i == 4 ? M_PI : 0.7 * i - 1.4),
                          0.001 + 0.0005 * i};
      }
      w.labels[key] = label;
      w.splits[key] = (i == 1 || i == 3) ? Split::kTest : Split::kTrain;
      const Image* clean = nullptr;
      if (bubble) {
        w.clean[key] = BubbleFrame(50 + i);
        clean = &w.clean[key];
      }
      writer.AddFrame(Id(i), sensor, w.frames[key], clean, label, w.splits[key]);
    }
  }
  writer.Finish();
  return w;
}

std::uint64_t SumOfFileSizes(const std::string& dir) {
  std::uint64_t total = 0;
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (entry.is_regular_file()) total += entry.file_size();
  }
  return total;
}

// labels.csv of the written dataset replaced by the header and `rows`.
void ReplaceLabels(const std::string& dir, const std::string& rows) {
  WriteText(dir + "/labels.csv", "frame,sensor,tool,x_m,y_m,yaw_rad,depth_m,split\n" + rows);
}

// ---------------------------------------------------------------------------------
// Options and small types.

TEST(Dataset, DefaultOpenOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(Dataset::OpenOptions().IsValid(&error)) << error;
}

TEST(DatasetWriter, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(DatasetWriter::Options().IsValid(&error)) << error;
}

TEST(Dataset, BadOpenOptionsNameTheField) {
  Dataset::OpenOptions options;
  options.reference_index = -1;
  std::string error;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("reference_index"));
  options = Dataset::OpenOptions();
  options.pixel_pitch_m = -0.001;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("pixel_pitch_m"));
  TestDir dir;
  EXPECT_THROW(Dataset::Open(dir.path(), options), std::invalid_argument);
}

TEST(DatasetWriter, BadOptionsNameTheField) {
  DatasetWriter::Options options;
  options.png_compression = 12;
  std::string error;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("png_compression"));
  options = DatasetWriter::Options();
  options.meta_json = "[1, 2]";
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("meta_json"));
  TestDir dir;
  EXPECT_THROW(DatasetWriter(dir / "out", options), std::invalid_argument);
}

TEST(Split, NamesRoundTrip) {
  for (Split split : {Split::kTrain, Split::kTest}) {
    Split parsed = Split::kTest;
    ASSERT_TRUE(SplitFromString(ToString(split), &parsed));
    EXPECT_EQ(parsed, split);
  }
  Split untouched = Split::kTest;
  EXPECT_FALSE(SplitFromString("validation", &untouched));
  EXPECT_EQ(untouched, Split::kTest);
}

TEST(PoseLabel, ValidityNamesTheFieldAndTheValue) {
  PoseLabel label{"pen", SE2d::FromXYYaw(0.001, 0.0, 0.5), 0.2};
  std::string error;
  EXPECT_FALSE(IsValidPoseLabel(label, 0, 0, 0, &error));
  EXPECT_EQ(error, "field 'depth_m': expected a finite number in [0, 0.1], got '0.2'");
  label.depth_m = 0.002;
  EXPECT_TRUE(IsValidPoseLabel(label, 0, 0, 0, &error)) << error;
  // The yaw of an SE2d is always in (-pi, pi]; labels.csv's yaw range is checked by its
  // reader (labels_csv_test.cc).
  label.sensor_T_object = SE2d::FromXYYaw(0.004, 0.0, 0.5);  // beyond 15 * 0.4 mm / 2 = 3 mm
  EXPECT_FALSE(IsValidPoseLabel(label, kBubbleRows, kBubbleCols, kBubblePitch, &error));
  EXPECT_THAT(error, HasSubstr("field 'x_m'"));
  EXPECT_TRUE(IsValidPoseLabel(label, kBubbleRows, kBubbleCols, 0, &error)) << error;
}

// ---------------------------------------------------------------------------------
// Writing and reading back.

TEST(Dataset, WrittenDatasetRoundTripsBitExactly) {
  TestDir dir;
  const Written w = WriteDataset(dir.path());
  const Dataset dataset = Dataset::Open(dir.path());
  EXPECT_TRUE(dataset.has_metadata());
  EXPECT_TRUE(dataset.has_clean());
  EXPECT_EQ(dataset.source(), "dataset_test");
  EXPECT_EQ(dataset.meta_json(), R"({"seed":7})");
  ASSERT_EQ(dataset.sensors(),
            (std::vector<SensorKind>{SensorKind::kSoftBubble, SensorKind::kGelSlim}));
  for (const SensorInfo& expected : {BubbleInfo(), GelInfo()}) {
    const SensorInfo& info = dataset.sensor_info(expected.kind);
    EXPECT_EQ(info.rows, expected.rows);
    EXPECT_EQ(info.cols, expected.cols);
    EXPECT_EQ(info.channels, expected.channels);
    EXPECT_EQ(info.encoding, expected.encoding);
    EXPECT_EQ(info.pixel_pitch_m, expected.pixel_pitch_m);
    EXPECT_EQ(info.normalization_scale, expected.normalization_scale);
    EXPECT_EQ(info.reference, std::string(ToString(expected.kind)) + "/reference.png");
  }
  EXPECT_TRUE(BitIdentical(dataset.Reference(SensorKind::kSoftBubble), w.bubble_reference));
  EXPECT_TRUE(BitIdentical(dataset.Reference(SensorKind::kGelSlim), w.gel_reference));
  ASSERT_EQ(dataset.frames().size(), w.frames.size());
  std::size_t index = 0;
  for (const auto& [key, frame] : w.frames) {  // map order = (id, sensor) order
    const FrameRecord& record = dataset.frames()[index];
    EXPECT_EQ(record.id, key.first);
    EXPECT_EQ(record.sensor, key.second);
    EXPECT_EQ(record.path, std::string(ToString(key.second)) + "/" + key.first + ".png");
    EXPECT_TRUE(BitIdentical(dataset.LoadFrame(index), frame)) << key.first;
    EXPECT_EQ(record.label, w.labels.at(key)) << key.first;
    EXPECT_EQ(record.split, w.splits.at(key)) << key.first;
    const auto clean = w.clean.find(key);
    if (clean != w.clean.end()) {
      EXPECT_TRUE(BitIdentical(dataset.LoadCleanFrame(index), clean->second));
    } else {
      EXPECT_EQ(record.clean_path, "");
      EXPECT_THROW(dataset.LoadCleanFrame(index), DatasetError);
    }
    ++index;
  }
  EXPECT_NO_THROW(dataset.ValidateAllFrames());
}

TEST(Dataset, WritingIsDeterministic) {
  TestDir a;
  TestDir b;
  WriteDataset(a.path());
  WriteDataset(b.path());
  EXPECT_EQ(ReadFile(a / "labels.csv"), ReadFile(b / "labels.csv"));
  EXPECT_EQ(ReadFile(a / "dataset.json"), ReadFile(b / "dataset.json"));
  EXPECT_EQ(ReadFile(a / "bubble/000002.png"), ReadFile(b / "bubble/000002.png"));
}

TEST(Dataset, FrameIndicesSelectTheSensorAndSplit) {
  TestDir dir;
  WriteDataset(dir.path());
  const Dataset dataset = Dataset::Open(dir.path());
  const auto all = dataset.FrameIndices(SensorKind::kGelSlim);
  const auto test = dataset.FrameIndices(SensorKind::kGelSlim, Split::kTest);
  const auto train = dataset.FrameIndices(SensorKind::kGelSlim, Split::kTrain);
  EXPECT_EQ(all.size(), 5u);
  ASSERT_EQ(test.size(), 2u);
  EXPECT_EQ(train.size(), 3u);
  EXPECT_EQ(dataset.frames()[test[0]].id, "000001");
  EXPECT_EQ(dataset.frames()[test[1]].id, "000003");
  for (std::size_t i : all) EXPECT_EQ(dataset.frames()[i].sensor, SensorKind::kGelSlim);
  EXPECT_EQ(dataset.FindFrame("000002", SensorKind::kSoftBubble), std::optional<std::size_t>(4));
  EXPECT_FALSE(dataset.FindFrame("000009", SensorKind::kSoftBubble));
}

TEST(Dataset, SensorOptionKeepsOnlyThatSensor) {
  TestDir dir;
  WriteDataset(dir.path());
  Dataset::OpenOptions options;
  options.sensor = SensorKind::kGelSlim;
  const Dataset dataset = Dataset::Open(dir.path(), options);
  EXPECT_EQ(dataset.sensors(), std::vector<SensorKind>{SensorKind::kGelSlim});
  EXPECT_EQ(dataset.frames().size(), 5u);
  EXPECT_FALSE(dataset.has_clean());
  EXPECT_THROW(dataset.sensor_info(SensorKind::kSoftBubble), DatasetError);
}

TEST(Dataset, BytesOnDiskIsTheSumOfTheFileSizes) {
  TestDir dir;
  WriteDataset(dir.path());
  EXPECT_EQ(Dataset::Open(dir.path()).BytesOnDisk(), SumOfFileSizes(dir.path()));
}

TEST(DatasetWriter, RefusesAFolderHoldingADatasetUnlessOverwriting) {
  TestDir dir;
  WriteDataset(dir.path());
  WriteText(dir / "notes.txt", "keep me");
  ExpectDatasetError([&] { DatasetWriter(dir.path(), DatasetWriter::Options()); },
                     {"dataset.json", "overwrite"});
  DatasetWriter::Options options;
  options.overwrite = true;
  DatasetWriter writer(dir.path(), options);
  EXPECT_FALSE(fs::exists(dir / "dataset.json"));
  EXPECT_FALSE(fs::exists(dir / "bubble"));
  EXPECT_TRUE(fs::exists(dir / "notes.txt"));
  writer.AddSensor(GelInfo(), GelFrame(1));
  writer.AddFrame("a", SensorKind::kGelSlim, GelFrame(2), nullptr, std::nullopt, Split::kTrain);
  writer.Finish();
  const Dataset dataset = Dataset::Open(dir.path());
  EXPECT_EQ(dataset.frames().size(), 1u);
  EXPECT_FALSE(dataset.has_clean());
  EXPECT_FALSE(dataset.frames()[0].label);
  EXPECT_THROW(writer.Finish(), std::logic_error);
}

TEST(DatasetWriter, RejectsBadIdsUnknownSensorsDuplicatesWrongShapesAndBadLabels) {
  TestDir dir;
  DatasetWriter writer(dir.path(), DatasetWriter::Options());
  writer.AddSensor(BubbleInfo(), BubbleFrame(1));
  const Image frame = BubbleFrame(2);
  const PoseLabel good{"pen", SE2d(), 0.002};
  ExpectDatasetError([&] { writer.AddSensor(BubbleInfo(), BubbleFrame(1)); }, {"twice"});
  SensorInfo bad_gel = GelInfo();
  bad_gel.channels = 2;
  ExpectDatasetError([&] { writer.AddSensor(bad_gel, GelFrame(1, 2)); }, {"channels"});
  ExpectDatasetError([&] { writer.AddSensor(GelInfo(), GelFrame(1, 3, 9)); },
                     {"reference", "10x14x3", "9x14x3"});
  for (const char* id : {"", "../x", "a,b", "reference", ".hidden"}) {
    ExpectDatasetError(
        [&] { writer.AddFrame(id, SensorKind::kSoftBubble, frame, nullptr, good, Split::kTrain); },
        {"field 'id'"});
  }
  ExpectDatasetError(
      [&] {
        writer.AddFrame("x", SensorKind::kGelSlim, GelFrame(1), nullptr, good, Split::kTrain);
      },
      {"field 'sensor'"});
  writer.AddFrame("x", SensorKind::kSoftBubble, frame, nullptr, good, Split::kTrain);
  ExpectDatasetError(
      [&] { writer.AddFrame("x", SensorKind::kSoftBubble, frame, nullptr, good, Split::kTrain); },
      {"duplicate"});
  ExpectDatasetError(
      [&] {
        writer.AddFrame("y", SensorKind::kSoftBubble, GelFrame(1, 1), nullptr, good, Split::kTrain);
      },
      {"expected 12x15x1", "got 10x14x1"});
  PoseLabel far = good;
  far.sensor_T_object = SE2d::Trans(0.0, 0.0025);  // beyond 12 * 0.4 mm / 2 = 2.4 mm
  ExpectDatasetError(
      [&] { writer.AddFrame("z", SensorKind::kSoftBubble, frame, nullptr, far, Split::kTrain); },
      {"AddFrame(z, bubble)", "field 'y_m'", "0.0025"});
  PoseLabel comma = good;
  comma.tool = "a,b";
  ExpectDatasetError(
      [&] { writer.AddFrame("z", SensorKind::kSoftBubble, frame, nullptr, comma, Split::kTrain); },
      {"field 'tool'"});
  Image deep = frame;
  deep.data[3] = 0.07f;
  ExpectDatasetError(
      [&] { writer.AddFrame("z", SensorKind::kSoftBubble, deep, nullptr, good, Split::kTrain); },
      {"z.png", "pixel (row 0, col 3)"});
  // A failed frame does not block its id.
  writer.AddFrame("z", SensorKind::kSoftBubble, frame, nullptr, good, Split::kTrain);
  writer.Finish();
  EXPECT_EQ(Dataset::Open(dir.path()).frames().size(), 2u);
}

TEST(DatasetWriter, AddFrameFromSeveralThreadsWritesEveryFrame) {
  TestDir dir;
  DatasetWriter writer(dir.path(), DatasetWriter::Options());
  writer.AddSensor(GelInfo(), GelFrame(1));
  std::vector<std::thread> threads;
  for (int t = 0; t < 4; ++t) {
    threads.emplace_back([&, t] {
      for (int i = t; i < 40; i += 4) {
        writer.AddFrame(Id(i), SensorKind::kGelSlim, GelFrame(i), nullptr,
                        PoseLabel{"pen", SE2d(), 0.001 * (i % 10)}, Split::kTrain);
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  writer.Finish();
  const Dataset dataset = Dataset::Open(dir.path());
  ASSERT_EQ(dataset.frames().size(), 40u);
  EXPECT_TRUE(BitIdentical(dataset.LoadFrame(17), GelFrame(17)));
  EXPECT_EQ(dataset.frames()[17].label->depth_m, 0.007);
}

// ---------------------------------------------------------------------------------
// Bad input: every case raises DatasetError naming the file and line or field.

TEST(Dataset, MissingDirectoryIsAnErrorNamingIt) {
  TestDir dir;
  ExpectDatasetError([&] { Dataset::Open(dir / "nowhere"); }, {"nowhere", "no such directory"});
}

TEST(Dataset, MalformedLabelsAreErrorsNamingTheLineAndField) {
  struct Case {
    std::string rows;
    std::vector<const char*> pieces;
  };
  const std::vector<Case> cases = {
      {"000000,bubble,pen,0,0,0\n", {"labels.csv:2:", "expected 8 comma-separated fields"}},
      {"000000,bubble,pen,0,0,0,0.001,train\n000001,bubble,pen,0,abc,0,0.001,train\n",
       {"labels.csv:3:", "field 'y_m'", "'abc'"}},
      {"000000,bubble,pen,0,0,7.2,0.001,train\n",
       {"labels.csv:2: field 'yaw_rad': expected a finite number in [-3.1416, 3.1416], "
        "got '7.2'"}},
      {"000000,bubble,pen,0.0031,0,0,0.001,train\n",
       {"labels.csv:2:", "field 'x_m'", "[-0.003, 0.003]", "0.0031"}},
      {"000000,gelslim,pen,1.5,0,0,0.001,train\n", {"labels.csv:2:", "field 'x_m'"}},
      {"000000,bubble,pen,0,0,0,0.2,train\n", {"labels.csv:2:", "field 'depth_m'", "0.2"}},
      {"000000,bubble,pen,0,0,0,-0.001,train\n", {"labels.csv:2:", "field 'depth_m'"}},
      {"000000,bubble,pen,0,0,0,nan,train\n", {"labels.csv:2:", "field 'depth_m'"}},
      {"000000,bubble,pen,0,0,0,0.001,val\n", {"labels.csv:2:", "field 'split'", "'val'"}},
      {"000000,digit,pen,0,0,0,0.001,train\n", {"labels.csv:2:", "field 'sensor'", "'digit'"}},
      {"000042,bubble,pen,0,0,0,0.001,train\n", {"labels.csv:2:", "field 'frame'", "000042"}},
      {"000000,bubble,pen,0,0,0,0.001,train\n\n000000,bubble,pen,0,0,0,0.002,test\n",
       {"labels.csv:4:", "duplicate", "000000"}},
      {"000000,bubble,,0,0,0,0.001,train\n", {"labels.csv:2:", "field 'tool'"}},
      {"000000,bubble,pen,,,,,train\n", {"labels.csv:2:", "field 'x_m'"}},
  };
  TestDir dir;
  WriteDataset(dir.path());
  for (const Case& c : cases) {
    ReplaceLabels(dir.path(), c.rows);
    try {
      Dataset::Open(dir.path());
      ADD_FAILURE() << "no error for rows:\n" << c.rows;
    } catch (const DatasetError& e) {
      for (const char* piece : c.pieces) {
        EXPECT_THAT(e.what(), HasSubstr(piece)) << "rows:\n" << c.rows;
      }
    }
  }
}

// tools.csv declares the symmetry of the data's own tools; built-in tools keep theirs.
TEST(Dataset, ToolsCsvDeclaresTheSymmetryOfUserToolsAndBadRowsNameLineAndField) {
  TestDir dir;
  WriteDataset(dir.path());
  EXPECT_TRUE(Dataset::Open(dir.path()).tool_symmetries().empty());
  WriteText(dir / "tools.csv", "\xEF\xBB\xBFtool,symmetry_order\r\nedge,2\r\n\nball,0\nrod,2\n");
  const Dataset dataset = Dataset::Open(dir.path());
  bool known = false;
  EXPECT_EQ(dataset.ToolSymmetryOrder("edge", &known), 2);
  EXPECT_TRUE(known);
  EXPECT_EQ(dataset.ToolSymmetryOrder("ball"), 0);
  EXPECT_EQ(dataset.ToolSymmetryOrder("rod"), 2);             // built in, declared alike
  EXPECT_EQ(dataset.ToolSymmetryOrder("l_shape", &known), 1);  // built in
  EXPECT_TRUE(known);
  EXPECT_EQ(dataset.ToolSymmetryOrder("mystery", &known), 1);
  EXPECT_FALSE(known);
  EXPECT_EQ(dataset.tool_symmetries().size(), 3u);
  const std::vector<std::string> files = dataset.Files();
  EXPECT_NE(std::find(files.begin(), files.end(), dir / "tools.csv"), files.end());
  // The same file named by the option, from elsewhere.
  std::filesystem::rename(dir / "tools.csv", dir / "my_tools.csv");
  Dataset::OpenOptions options;
  options.tools = dir / "my_tools.csv";
  EXPECT_EQ(Dataset::Open(dir.path(), options).ToolSymmetryOrder("edge"), 2);
  std::filesystem::remove(dir / "my_tools.csv");

  const struct {
    const char* text;
    std::vector<const char*> pieces;
  } cases[] = {
      {"tool,order\n", {"tools.csv:1:", "header", "tool,symmetry_order"}},
      {"tool,symmetry_order\nedge,two\n", {"tools.csv:2:", "field 'symmetry_order'", "'two'"}},
      {"tool,symmetry_order\nedge,-1\n", {"tools.csv:2:", "field 'symmetry_order'"}},
      {"tool,symmetry_order\nrod,3\n", {"tools.csv:2:", "built-in", "order 2", "got 3"}},
      {"tool,symmetry_order\nedge,2\nedge,2\n", {"tools.csv:3:", "field 'tool'", "edge"}},
      {"tool,symmetry_order\n,2\n", {"tools.csv:2:", "field 'tool'"}},
      {"tool,symmetry_order\nedge,2,1\n", {"tools.csv:2:", "2 fields"}},
      {"", {"tools.csv", "empty file"}},
  };
  for (const auto& c : cases) {
    SCOPED_TRACE(c.text);
    WriteText(dir / "tools.csv", c.text);
    try {
      Dataset::Open(dir.path());
      ADD_FAILURE() << "no error";
    } catch (const DatasetError& e) {
      for (const char* piece : c.pieces) EXPECT_THAT(e.what(), HasSubstr(piece));
    }
  }
}

TEST(Dataset, WrongLabelsHeaderIsAnError) {
  TestDir dir;
  WriteDataset(dir.path());
  WriteText(dir / "labels.csv", "frame,sensor,tool,x,y,yaw,depth,split\n");
  ExpectDatasetError(
      [&] { Dataset::Open(dir.path()); },
      {"labels.csv:1:", "header", "frame,sensor,tool,x_m,y_m,yaw_rad,depth_m,split"});
  WriteText(dir / "labels.csv", "");
  ExpectDatasetError([&] { Dataset::Open(dir.path()); }, {"labels.csv:1:", "empty file"});
}

TEST(Dataset, LabelsWithCrLfAndBlankRowsAreRead) {
  TestDir dir;
  WriteDataset(dir.path());
  WriteText(dir / "labels.csv",
            "\xEF\xBB\xBF"
            "frame,sensor,tool,x_m,y_m,yaw_rad,depth_m,split\r\n"
            "000002,gelslim,pen,0.001,-0.002,-3.14159265359,0.1,test\r\n\r\n");
  const Dataset dataset = Dataset::Open(dir.path());
  const FrameRecord& record = dataset.frames()[*dataset.FindFrame("000002", SensorKind::kGelSlim)];
  ASSERT_TRUE(record.label);
  EXPECT_EQ(record.label->sensor_T_object.y(), -0.002);
  EXPECT_EQ(record.split, Split::kTest);
  EXPECT_FALSE(dataset.frames()[0].label);
}

TEST(Dataset, CorruptFrameIsAnErrorNamingTheFile) {
  TestDir dir;
  WriteDataset(dir.path());
  WriteText(dir / "bubble/000002.png", "\x89PNG garbage");
  const Dataset dataset = Dataset::Open(dir.path());
  const std::size_t index = *dataset.FindFrame("000002", SensorKind::kSoftBubble);
  ExpectDatasetError([&] { dataset.LoadFrame(index); }, {"bubble/000002.png", "PNG"});
  ExpectDatasetError([&] { dataset.ValidateAllFrames(); }, {"bubble/000002.png"});
  EXPECT_THROW(dataset.LoadFrame(dataset.frames().size()), std::out_of_range);
}

TEST(Dataset, FrameOfTheWrongSizeChannelsOrBitDepthIsAnError) {
  TestDir dir;
  WriteDataset(dir.path());
  WritePngAtomically(dir / "gelslim/000001.png", GelFrame(1, 3, 9, 14), PixelEncoding::kRgb8);
  WritePngAtomically(dir / "gelslim/000002.png", GelFrame(1, 1), PixelEncoding::kRgb8);
  WritePngAtomically(dir / "bubble/000003.png", GelFrame(1, 1, kBubbleRows, kBubbleCols),
                     PixelEncoding::kRgb8);
  const Dataset dataset = Dataset::Open(dir.path());
  ExpectDatasetError([&] { dataset.LoadFrame(*dataset.FindFrame("000001", SensorKind::kGelSlim)); },
                     {"gelslim/000001.png", "expected a 10x14x3 frame", "got 9x14x3"});
  ExpectDatasetError([&] { dataset.LoadFrame(*dataset.FindFrame("000002", SensorKind::kGelSlim)); },
                     {"gelslim/000002.png", "got 10x14x1"});
  ExpectDatasetError(
      [&] { dataset.LoadFrame(*dataset.FindFrame("000003", SensorKind::kSoftBubble)); },
      {"bubble/000003.png", "16-bit", "got 8-bit"});
}

TEST(Dataset, AFrameOfAnotherSizeIsRefusedFromItsHeaderBeforeDecoding) {
  TestDir dir;
  WriteDataset(dir.path());
  // A valid header of the wrong size followed by garbage: the size is what is
  // reported, so the pixels were never handed to the decoder.
  const std::string png = EncodePng(GelFrame(1, 3, 9, 14), PixelEncoding::kRgb8);
  WriteText(dir / "gelslim/000001.png", png.substr(0, 33) + "not pixel data");
  const Dataset dataset = Dataset::Open(dir.path());
  ExpectDatasetError([&] { dataset.LoadFrame(*dataset.FindFrame("000001", SensorKind::kGelSlim)); },
                     {"gelslim/000001.png", "expected a 10x14x3 frame", "got 9x14x3",
                      "from the file's header, not decoded"});
}

TEST(Dataset, DeeplyNestedMetadataIsAnErrorNotACrash) {
  TestDir dir;
  WriteDataset(dir.path());
  // 100000 nested arrays: parsed, then dumped recursively into the error message.
  WriteText(dir / "dataset.json", std::string(100000, '['));
  ExpectDatasetError([&] { Dataset::Open(dir.path()); },
                     {"dataset.json: expected JSON nested at most 64 levels deep"});
  WriteText(dir / "dataset.json", "{\"format\": " + std::string(100000, '[') +
                                      std::string(100000, ']') + "}");
  ExpectDatasetError([&] { Dataset::Open(dir.path()); }, {"dataset.json", "nested at most 64"});
}

TEST(Dataset, BadMetadataValuesAreQuotedAsShortExcerpts) {
  TestDir dir;
  WriteDataset(dir.path());
  std::string text = ReadFile(dir / "dataset.json");
  const std::string from = "\"tactfunc-dataset\"";
  text.replace(text.find(from), from.size(), "\"" + std::string(1 << 20, 'x') + "\"");
  WriteText(dir / "dataset.json", text);
  try {
    Dataset::Open(dir.path());
    ADD_FAILURE() << "no error";
  } catch (const DatasetError& e) {
    EXPECT_THAT(e.what(), HasSubstr("field 'format'"));
    EXPECT_THAT(e.what(), HasSubstr("xxxx... (1048578 bytes)"));
    EXPECT_LT(std::string(e.what()).size(), 600u);
  }
  // A syntax error deep inside a long string: the parser's own message is cut too.
  WriteText(dir / "dataset.json", "{\"format\": \"" + std::string(1 << 20, 'y') + "\x01\"}");
  try {
    Dataset::Open(dir.path());
    ADD_FAILURE() << "no error";
  } catch (const DatasetError& e) {
    EXPECT_THAT(e.what(), HasSubstr("expected valid JSON"));
    EXPECT_LT(std::string(e.what()).size(), 600u);
  }
}

TEST(Dataset, AHugeBadLabelsLineIsQuotedAsAShortExcerpt) {
  TestDir dir;
  WriteDataset(dir.path());
  ReplaceLabels(dir.path(), "000000,bubble,pen,0,0,0,0.001,train\n" + std::string(10 << 20, 'z') +
                                "\n");
  try {
    Dataset::Open(dir.path());
    ADD_FAILURE() << "no error";
  } catch (const DatasetError& e) {
    EXPECT_THAT(e.what(), HasSubstr("labels.csv:3: expected 8 comma-separated fields"));
    EXPECT_THAT(e.what(), HasSubstr("... (10485760 bytes)"));
    EXPECT_LT(std::string(e.what()).size(), 600u);
  }
  ReplaceLabels(dir.path(), "000000,bubble,pen,0," + std::string(10 << 20, '7') + ",0,0.001,train\n");
  try {
    Dataset::Open(dir.path());
    ADD_FAILURE() << "no error";
  } catch (const DatasetError& e) {
    EXPECT_THAT(e.what(), HasSubstr("labels.csv:2: field 'y_m'"));
    EXPECT_LT(std::string(e.what()).size(), 600u);
  }
}

TEST(Dataset, NonUtf8ToolNamesAndFrameIdsAreRefusedAtOpenNamingFileAndLine) {
  TestDir dir;
  WriteDataset(dir.path());
  ReplaceLabels(dir.path(), "000000,bubble,pen,0,0,0,0.001,train\n"
                            "000001,bubble,h\xff\xfek,0,0,0,0.001,train\n");
  ExpectDatasetError([&] { Dataset::Open(dir.path()); },
                     {"labels.csv:3: field 'tool': expected a tool name in UTF-8, got 'h\\xff\\xfek'"});
  ReplaceLabels(dir.path(), "0000\xc0\xaf,bubble,pen,0,0,0,0.001,train\n");
  ExpectDatasetError([&] { Dataset::Open(dir.path()); },
                     {"labels.csv:2: field 'frame': expected UTF-8 text"});
  // A user folder whose file name is not UTF-8 (frame ids become JSON text).
  TestDir flat;
  WritePngAtomically(flat / "reference.png", GelFrame(1), PixelEncoding::kRgb8);
  WritePngAtomically(flat / "ok.png", GelFrame(2), PixelEncoding::kRgb8);
  WritePngAtomically(flat / "bad\xff.png", GelFrame(3), PixelEncoding::kRgb8);
  ExpectDatasetError([&] { Dataset::Open(flat.path()); },
                     {"bad\\xff.png: frame id: expected a file name in UTF-8"});
}

TEST(Dataset, ReferenceOfAnotherSizeThanTheMetadataIsAnError) {
  TestDir dir;
  WriteDataset(dir.path());
  WritePngAtomically(dir / "bubble/reference.png", Image(kBubbleRows + 1, kBubbleCols, 1, 0.03f),
                     PixelEncoding::kDepthU16Micrometres);
  ExpectDatasetError([&] { Dataset::Open(dir.path()); },
                     {"bubble/reference.png", "expected 12x15x1", "got 13x15x1"});
  fs::remove(dir / "bubble/reference.png");
  ExpectDatasetError([&] { Dataset::Open(dir.path()); }, {"bubble/reference.png"});
}

TEST(Dataset, BadMetadataIsAnErrorNamingTheField) {
  struct Case {
    std::string from;
    std::string to;
    std::vector<const char*> pieces;
  };
  const std::vector<Case> cases = {
      {"\"tactfunc-dataset\"",
       "\"other-format\"",
       {"dataset.json", "field 'format'", "other-format"}},
      {"\"version\": 1", "\"version\": 2", {"dataset.json", "field 'version'", "got 2"}},
      {"\"cols\": 15,", "", {"dataset.json", "field 'sensors.bubble.cols'", "no such field"}},
      {"\"cols\": 15,", "\"cols\": \"15\",", {"field 'sensors.bubble.cols'", "\"15\""}},
      {"\"encoding\": \"rgb8\"",
       "\"encoding\": \"jpeg\"",
       {"field 'sensors.gelslim.encoding'", "jpeg"}},
      {"\"bubble\": {", "\"digit\": {", {"field 'sensors.digit'", "'digit'"}},
      {"\"has_clean\": true,", "", {"field 'has_clean'"}},
      {"{", "[", {"dataset.json", "valid JSON"}},
      {"\"bubble/reference.png\"",
       "\"/reference.png\"",
       {"dataset.json", "field 'sensors.bubble.reference'", "a path relative to the dataset"}},
  };
  TestDir dir;
  WriteDataset(dir.path());
  const std::string good = ReadFile(dir / "dataset.json");
  for (const Case& c : cases) {
    std::string text = good;
    const std::size_t at = text.find(c.from);
    ASSERT_NE(at, std::string::npos) << c.from << " in\n" << good;
    text.replace(at, c.from.size(), c.to);
    WriteText(dir / "dataset.json", text);
    try {
      Dataset::Open(dir.path());
      ADD_FAILURE() << "no error for " << c.from << " -> " << c.to;
    } catch (const DatasetError& e) {
      for (const char* piece : c.pieces) {
        EXPECT_THAT(e.what(), HasSubstr(piece)) << c.from << " -> " << c.to;
      }
    }
  }
}

TEST(Dataset, MissingFrameCountedInTheMetadataIsAnError) {
  TestDir dir;
  WriteDataset(dir.path());
  fs::remove(dir / "gelslim/000004.png");
  ExpectDatasetError([&] { Dataset::Open(dir.path()); },
                     {"dataset.json", "sensors.gelslim.num_frames", "expected 5", "got 4"});
}

// ---------------------------------------------------------------------------------
// Folders users bring without metadata.

TEST(Dataset, FlatUserFolderOfJpegAndPngWithReferenceAndLabelsLoads) {
  TestDir dir;
  cv::Mat bgr(8, 10, CV_8UC3, cv::Scalar(10, 20, 30));
  ASSERT_TRUE(cv::imwrite(dir / "reference.png", bgr));
  ASSERT_TRUE(cv::imwrite(dir / "b_touch.JPG", bgr));
  ASSERT_TRUE(cv::imwrite(dir / "a_touch.jpeg", bgr));
  ASSERT_TRUE(cv::imwrite(dir / "c_touch.png", bgr));
  WriteText(dir / "notes.txt", "ignored");
  WriteText(dir / ".hidden.png", "ignored");
  WriteText(dir / "labels.csv",
            "frame,sensor,tool,x_m,y_m,yaw_rad,depth_m,split\n"
            "b_touch,gelslim,pen,0.01,0.02,1.5,0.003,test\n");
  const Dataset dataset = Dataset::Open(dir.path());
  EXPECT_FALSE(dataset.has_metadata());
  ASSERT_EQ(dataset.sensors(), std::vector<SensorKind>{SensorKind::kGelSlim});
  const SensorInfo& info = dataset.sensor_info(SensorKind::kGelSlim);
  EXPECT_EQ(info.rows, 8);
  EXPECT_EQ(info.cols, 10);
  EXPECT_EQ(info.channels, 3);
  EXPECT_EQ(info.encoding, PixelEncoding::kRgb8);
  EXPECT_EQ(info.pixel_pitch_m, 0.0);
  EXPECT_EQ(info.normalization_scale, DefaultNormalizationScale(SensorKind::kGelSlim));
  EXPECT_EQ(info.reference, "reference.png");
  ASSERT_EQ(dataset.frames().size(), 3u);
  EXPECT_EQ(dataset.frames()[0].id, "a_touch");
  EXPECT_EQ(dataset.frames()[1].id, "b_touch");
  EXPECT_EQ(dataset.frames()[1].path, "b_touch.JPG");
  EXPECT_EQ(dataset.frames()[2].id, "c_touch");
  EXPECT_FALSE(dataset.frames()[0].label);
  ASSERT_TRUE(dataset.frames()[1].label);
  EXPECT_EQ(dataset.frames()[1].label->tool, "pen");
  EXPECT_EQ(dataset.frames()[1].split, Split::kTest);
  EXPECT_EQ(dataset.Reference(SensorKind::kGelSlim).at(0, 0, 0), 30 / 255.0f);
  EXPECT_NO_THROW(dataset.ValidateAllFrames());
  EXPECT_NEAR(dataset.LoadFrame(0).at(4, 4, 0), 30 / 255.0, 3 / 255.0);
  EXPECT_EQ(dataset.BytesOnDisk(), SumOfFileSizes(dir.path()) - fs::file_size(dir / "notes.txt") -
                                       fs::file_size(dir / ".hidden.png"));
}

TEST(Dataset, FlatDepthFolderUsesTheNamedReferenceAndTheGivenPitch) {
  TestDir dir;
  for (int i = 0; i < 3; ++i) {
    WritePngAtomically(dir / (Id(i) + ".png"), BubbleFrame(i), PixelEncoding::kDepthU16Micrometres);
  }
  ExpectDatasetError([&] { Dataset::Open(dir.path()); }, {"reference", dir.path().c_str()});
  Dataset::OpenOptions options;
  options.reference = "000000.png";
  options.pixel_pitch_m = kBubblePitch;
  const Dataset dataset = Dataset::Open(dir.path(), options);
  ASSERT_EQ(dataset.sensors(), std::vector<SensorKind>{SensorKind::kSoftBubble});
  EXPECT_EQ(dataset.sensor_info(SensorKind::kSoftBubble).pixel_pitch_m, kBubblePitch);
  ASSERT_EQ(dataset.frames().size(), 2u);
  EXPECT_EQ(dataset.frames()[0].id, "000001");
  EXPECT_TRUE(BitIdentical(dataset.Reference(SensorKind::kSoftBubble), BubbleFrame(0)));
  EXPECT_TRUE(BitIdentical(dataset.LoadFrame(1), BubbleFrame(2)));
  // The pitch bounds the label positions.
  WriteText(dir / "labels.csv",
            "frame,sensor,tool,x_m,y_m,yaw_rad,depth_m,split\n"
            "000001,bubble,pen,0.5,0,0,0.001,train\n");
  ExpectDatasetError([&] { Dataset::Open(dir.path(), options); }, {"labels.csv:2:", "field 'x_m'"});
  options.reference = "absent.png";
  ExpectDatasetError([&] { Dataset::Open(dir.path(), options); }, {"absent.png"});
}

TEST(Dataset, FlatFolderSensorKindMustMatchTheFiles) {
  TestDir dir;
  WritePngAtomically(dir / "reference.png", GelFrame(1), PixelEncoding::kRgb8);
  Dataset::OpenOptions options;
  options.sensor = SensorKind::kSoftBubble;
  ExpectDatasetError([&] { Dataset::Open(dir.path(), options); }, {"reference.png", "16-bit"});
}

TEST(Dataset, GrayscaleUserFolderHasOneChannel) {
  TestDir dir;
  WritePngAtomically(dir / "reference.png", GelFrame(1, 1), PixelEncoding::kRgb8);
  WritePngAtomically(dir / "t0.png", GelFrame(2, 1), PixelEncoding::kRgb8);
  const Dataset dataset = Dataset::Open(dir.path());
  ASSERT_EQ(dataset.sensors(), std::vector<SensorKind>{SensorKind::kGelSlim});
  EXPECT_EQ(dataset.sensor_info(SensorKind::kGelSlim).channels, 1);
  EXPECT_TRUE(BitIdentical(dataset.LoadFrame(0), GelFrame(2, 1)));
}

TEST(Dataset, TwoFilesWithTheSameStemAreAnError) {
  TestDir dir;
  WritePngAtomically(dir / "reference.png", GelFrame(1), PixelEncoding::kRgb8);
  WritePngAtomically(dir / "t0.png", GelFrame(2), PixelEncoding::kRgb8);
  WritePngAtomically(dir / "t0.jpg", GelFrame(2), PixelEncoding::kRgb8);
  ExpectDatasetError([&] { Dataset::Open(dir.path()); }, {"t0.png", "t0.jpg"});
}

TEST(Dataset, SensorSubfolderUserLayoutLoadsBothSensorsPaired) {
  TestDir dir;
  fs::create_directories(dir / "bubble");
  fs::create_directories(dir / "gelslim");
  WritePngAtomically(dir / "bubble/reference.png", BubbleFrame(9),
                     PixelEncoding::kDepthU16Micrometres);
  WritePngAtomically(dir / "gelslim/Reference.PNG", GelFrame(9), PixelEncoding::kRgb8);
  for (int i = 0; i < 3; ++i) {
    WritePngAtomically(dir / ("bubble/" + Id(i) + ".png"), BubbleFrame(i),
                       PixelEncoding::kDepthU16Micrometres);
    WritePngAtomically(dir / ("gelslim/" + Id(i) + ".png"), GelFrame(i), PixelEncoding::kRgb8);
  }
  WriteText(dir / "labels.csv",
            "frame,sensor,tool,x_m,y_m,yaw_rad,depth_m,split\n"
            "000001,bubble,pen,0.001,0,0,0.004,train\n"
            "000001,gelslim,pen,0.001,0,0,0.004,train\n");
  const Dataset dataset = Dataset::Open(dir.path());
  ASSERT_EQ(dataset.sensors().size(), 2u);
  ASSERT_EQ(dataset.frames().size(), 6u);
  EXPECT_EQ(dataset.frames()[2].id, "000001");
  EXPECT_EQ(dataset.frames()[2].sensor, SensorKind::kSoftBubble);
  EXPECT_EQ(dataset.frames()[3].id, "000001");
  EXPECT_EQ(dataset.frames()[3].sensor, SensorKind::kGelSlim);
  EXPECT_TRUE(dataset.frames()[3].label);
  EXPECT_EQ(dataset.sensor_info(SensorKind::kGelSlim).reference, "gelslim/Reference.PNG");
  EXPECT_TRUE(BitIdentical(dataset.LoadFrame(3), GelFrame(1)));
  EXPECT_EQ(dataset.BytesOnDisk(), SumOfFileSizes(dir.path()));
  Dataset::OpenOptions options;
  options.sensor = SensorKind::kSoftBubble;
  EXPECT_EQ(Dataset::Open(dir.path(), options).frames().size(), 3u);
  // A bubble frame of another size is caught when it is loaded.
  WritePngAtomically(dir / "bubble/000002.png", Image(5, 5, 1, 0.03f),
                     PixelEncoding::kDepthU16Micrometres);
  ExpectDatasetError([&] { Dataset::Open(dir.path()).ValidateAllFrames(); },
                     {"bubble/000002.png", "expected a 12x15x1 frame", "got 5x5x1"});
}

// ---------------------------------------------------------------------------------
// Video.

TEST(Dataset, VideoLoadsWithTheFirstFrameAsReference) {
  TestDir dir;
  const std::string path = dir / "touch.avi";
  constexpr int kFrames = 5;
  {
    cv::VideoWriter writer(path, cv::VideoWriter::fourcc('M', 'J', 'P', 'G'), 10.0,
                           cv::Size(32, 24), /*isColor=*/true);
    if (!writer.isOpened()) {
      GTEST_SKIP() << "this OpenCV build cannot write MJPG .avi (no videoio backend "
                      "with the codec), so OpenVideo cannot be exercised here";
    }
    for (int i = 0; i < kFrames; ++i) {
      writer.write(cv::Mat(24, 32, CV_8UC3, cv::Scalar(20 * i, 100, 200 - 20 * i)));
    }
  }
  const Dataset dataset = Dataset::OpenVideo(path);
  ASSERT_EQ(dataset.sensors(), std::vector<SensorKind>{SensorKind::kGelSlim});
  const SensorInfo& info = dataset.sensor_info(SensorKind::kGelSlim);
  EXPECT_EQ(info.rows, 24);
  EXPECT_EQ(info.cols, 32);
  EXPECT_EQ(info.channels, 3);
  ASSERT_EQ(dataset.frames().size(), static_cast<std::size_t>(kFrames - 1));
  EXPECT_EQ(dataset.frames()[0].id, "000001");
  EXPECT_EQ(dataset.frames()[3].id, "000004");
  EXPECT_NEAR(dataset.Reference(SensorKind::kGelSlim).at(5, 5, 0), 200 / 255.0, 0.05);
  const Image last = dataset.LoadFrame(3);  // B = 80, G = 100, R = 120
  EXPECT_NEAR(last.at(5, 5, 0), 120 / 255.0, 0.05);
  EXPECT_NEAR(last.at(5, 5, 2), 80 / 255.0, 0.05);
  EXPECT_EQ(dataset.BytesOnDisk(), fs::file_size(path));

  Dataset::OpenOptions options;
  options.reference_index = 2;
  const Dataset shifted = Dataset::OpenVideo(path, options);
  EXPECT_EQ(shifted.frames()[1].id, "000001");
  EXPECT_EQ(shifted.frames()[2].id, "000003");
  options.reference_index = kFrames;
  ExpectDatasetError([&] { Dataset::OpenVideo(path, options); }, {"touch.avi", "reference_index"});
  options = Dataset::OpenOptions();
  options.sensor = SensorKind::kSoftBubble;
  ExpectDatasetError([&] { Dataset::OpenVideo(path, options); }, {"touch.avi", "gelslim"});
}

TEST(Dataset, MissingOrUndecodableVideoIsAnErrorNamingIt) {
  TestDir dir;
  ExpectDatasetError([&] { Dataset::OpenVideo(dir / "absent.avi"); }, {"absent.avi"});
  WriteText(dir / "junk.avi", "not a video at all");
  ExpectDatasetError([&] { Dataset::OpenVideo(dir / "junk.avi"); }, {"junk.avi"});
}

}  // namespace
}  // namespace tactfunc
