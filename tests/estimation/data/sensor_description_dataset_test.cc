// Copyright 2026 The tactfunc Authors.
//
// Sensor descriptions in datasets: a folder's sensor.json (or OpenOptions::sensor_file)
// crops / warps every frame and the reference before they are differenced, sets the
// pitch and scale, and is refused with the file and field named when it does not fit the
// data; without one, nothing changes (the built-ins).
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>

#include "estimation/data/dataset.h"
#include "estimation/data/image_io.h"
#include "estimation/data/preprocess.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "models/core/sensor_description.h"

namespace tactfunc {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

// 8-bit-exact random intensities (so the PNG round trip is lossless).
Image RandomRgb(int rows, int cols, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> level(0, 255);
  Image image(rows, cols, 3);
  for (float& v : image.data) v = level(rng) / 255.0f;
  return image;
}

// Depth in micrometre steps with a dropout block.
Image RandomDepth(int rows, int cols, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> um(40000, 60000);
  Image image(rows, cols, 1);
  for (float& v : image.data) v = um(rng) * 1e-6f;
  for (int r = 2; r < 5; ++r) {
    for (int c = 3; c < 7; ++c) image.at(r, c) = std::nanf("");
  }
  return image;
}

class SensorDescriptionDatasetTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::path(::testing::TempDir()) /
           ("tactfunc_sensor_desc_" + std::to_string(::getpid()) + "_" +
            ::testing::UnitTest::GetInstance()->current_test_info()->name());
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "optical");
    fs::create_directories(dir_ / "depth");
    WritePngAtomically((dir_ / "optical/reference.png").string(), RandomRgb(30, 40, 1),
                       PixelEncoding::kRgb8);
    for (int k = 0; k < 3; ++k) {
      WritePngAtomically((dir_ / "optical" / ("f" + std::to_string(k) + ".png")).string(),
                         RandomRgb(30, 40, 10 + k), PixelEncoding::kRgb8);
    }
    WritePngAtomically((dir_ / "depth/reference.png").string(), RandomDepth(24, 32, 2),
                       PixelEncoding::kDepthU16Micrometres);
    for (int k = 0; k < 3; ++k) {
      WritePngAtomically((dir_ / "depth" / ("f" + std::to_string(k) + ".png")).string(),
                         RandomDepth(24, 32, 20 + k), PixelEncoding::kDepthU16Micrometres);
    }
  }
  void TearDown() override { fs::remove_all(dir_); }

  void WriteDescription(const fs::path& path, const std::string& json) {
    std::ofstream(path) << json;
  }
  std::string Dir(const std::string& sub) const { return (dir_ / sub).string(); }

  fs::path dir_;
};

// Every byte of two preprocessed frames is the same.
void ExpectBitIdentical(const PreprocessedFrame& a, const PreprocessedFrame& b) {
  ASSERT_TRUE(a.values.SameShape(b.values));
  EXPECT_EQ(std::memcmp(a.values.data.data(), b.values.data.data(),
                        a.values.data.size() * sizeof(float)),
            0);
  EXPECT_EQ(a.valid, b.valid);
  EXPECT_EQ(a.scale, b.scale);
  EXPECT_EQ(a.offset, b.offset);
  EXPECT_EQ(a.source_range, b.source_range);
}

TEST_F(SensorDescriptionDatasetTest, TheBuiltInsPreprocessBitIdentically) {
  for (const char* sub : {"optical", "depth"}) {
    SCOPED_TRACE(sub);
    const Dataset plain = Dataset::Open(Dir(sub));
    ASSERT_EQ(plain.sensors().size(), 1u);
    const SensorKind kind = plain.sensors()[0];
    const SensorInfo& info = plain.sensor_info(kind);
    EXPECT_FALSE(info.description);
    // The data's description is the built-in of its kind, with today's scale.
    const SensorDescription described = DataSensorDescription(info);
    EXPECT_TRUE(SameFrames(described, [&] {
      SensorDescription d = BuiltInSensorDescription(kind);
      d.pixel_pitch_m = 0;
      return d;
    }()));
    EXPECT_EQ(described.normalization_scale, DefaultNormalizationScale(kind));
    // The same data with a sensor.json of the built-in's values (and a pitch) reads and
    // preprocesses to the same bits, resized or not.
    WriteDescription(dir_ / sub / "sensor.json",
                     std::string(R"({"name": "same", "kind": ")") +
                         SensorKindDescriptionName(kind) + R"(", "pixel_pitch_mm": 0.2,
                         "normalization_scale": )" +
                         (kind == SensorKind::kSoftBubble ? "0.01" : "0.5") + "}");
    const Dataset described_data = Dataset::Open(Dir(sub));
    ASSERT_TRUE(described_data.sensor_info(kind).description);
    EXPECT_EQ(described_data.sensor_info(kind).pixel_pitch_m, 0.2e-3);
    for (std::size_t i = 0; i < plain.frames().size(); ++i) {
      for (int rows : {0, 12}) {
        PreprocessOptions options;
        options.rows = rows;
        options.cols = rows * 4 / 3;
        ExpectBitIdentical(PreprocessFrame(plain, i, options),
                           PreprocessFrame(described_data, i, options));
      }
    }
    // And the built-in description applied by hand changes no bit of today's Preprocess.
    const Image frame = plain.LoadFrame(0);
    const Image& reference = plain.FrameReference(0);
    const SensorDescription builtin = BuiltInSensorDescription(kind);
    PreprocessOptions options;
    options.rows = 12;
    options.cols = 16;
    ExpectBitIdentical(
        Preprocess(frame, reference, kind, options, DefaultNormalizationScale(kind)),
        Preprocess(ApplySensorGeometry(frame, builtin, "b"),
                   ApplySensorGeometry(reference, builtin, "b"), kind, options,
                   builtin.normalization_scale));
  }
}

TEST_F(SensorDescriptionDatasetTest, ACropAppliesToFramesAndReferenceBeforeDifferencing) {
  WriteDescription(dir_ / "optical/sensor.json",
                   R"({"name": "wedge", "kind": "optical", "crop": {"x": 5, "y": 3,
                       "width": 24, "height": 18}, "pixel_pitch_mm": 0.1,
                       "normalization_scale": 0.25, "markers": true})");
  const Dataset data = Dataset::Open(Dir("optical"));
  const SensorInfo& info = data.sensor_info(SensorKind::kGelSlim);
  ASSERT_TRUE(info.description);
  EXPECT_EQ(info.rows, 18);
  EXPECT_EQ(info.cols, 24);
  EXPECT_EQ(info.channels, 3);
  EXPECT_EQ(info.pixel_pitch_m, 0.1e-3);
  EXPECT_EQ(info.normalization_scale, 0.25);
  EXPECT_EQ(info.description_path, Dir("optical/sensor.json"));
  const Image raw_reference = ReadImage(Dir("optical/reference.png"), PixelEncoding::kRgb8);
  const Image& reference = data.Reference(SensorKind::kGelSlim);
  ASSERT_EQ(reference.rows, 18);
  ASSERT_EQ(reference.cols, 24);
  for (std::size_t i = 0; i < data.frames().size(); ++i) {
    const Image raw = ReadImage(Dir("optical/" + data.frames()[i].path), PixelEncoding::kRgb8);
    const Image frame = data.LoadFrame(i);
    ASSERT_EQ(frame.rows, 18);
    for (int r = 0; r < 18; ++r) {
      for (int c = 0; c < 24; ++c) {
        for (int k = 0; k < 3; ++k) {
          ASSERT_EQ(frame.at(r, c, k), raw.at(r + 3, c + 5, k));
          ASSERT_EQ(reference.at(r, c, k), raw_reference.at(r + 3, c + 5, k));
        }
      }
    }
    // The difference is that of the cropped pixels, at the description's scale.
    const PreprocessedFrame p = PreprocessFrame(data, i, PreprocessOptions());
    EXPECT_EQ(p.scale, 0.25);
    EXPECT_FLOAT_EQ(p.values.at(4, 7, 1),
                    (raw.at(7, 12, 1) - raw_reference.at(7, 12, 1)) / 0.25f);
  }
  const std::vector<std::string> files = data.Files();
  EXPECT_NE(std::find(files.begin(), files.end(), Dir("optical/sensor.json")), files.end());
}

TEST_F(SensorDescriptionDatasetTest, SensorFileOptionAndDepthPerspectiveKeepTheMask) {
  const fs::path file = dir_ / "bubble_desc.json";
  WriteDescription(file, R"({"name": "bubble_warped", "kind": "depth", "perspective":
                            {"corners": [[1, 1], [31, 2], [30, 23], [2, 22]], "rows": 20,
                             "cols": 28}, "pixel_pitch_mm": 0.5, "normalization_scale": 0.01})");
  Dataset::OpenOptions options;
  options.sensor_file = file.string();
  const Dataset data = Dataset::Open(Dir("depth"), options);
  const SensorInfo& info = data.sensor_info(SensorKind::kSoftBubble);
  EXPECT_EQ(info.rows, 20);
  EXPECT_EQ(info.cols, 28);
  const PreprocessedFrame p = PreprocessFrame(data, 0, PreprocessOptions());
  ASSERT_EQ(p.values.rows, 20);
  // The dropout block of frame and reference stays invalid; the rest is valid.
  EXPECT_LT(p.num_valid(), 20u * 28u);
  EXPECT_GT(p.num_valid(), 20u * 28u - 40u);
  for (float v : p.values.data) EXPECT_TRUE(std::isfinite(v));
}

TEST_F(SensorDescriptionDatasetTest, ADescriptionThatDoesNotFitTheDataIsRefusedNamingIt) {
  struct Case {
    std::string json;
    std::string message;
  };
  const std::vector<Case> cases = {
      {R"({"name": "d", "kind": "depth", "pixel_pitch_mm": 0.1, "normalization_scale": 0.01})",
       "field 'kind': expected the kind of"},
      {R"({"name": "o", "kind": "optical", "crop": {"x": 30, "y": 0, "width": 20, "height": 10},
           "pixel_pitch_mm": 0.1, "normalization_scale": 0.5})",
       "field 'crop': expected a rectangle inside the 30x40 (rows x cols) frames"},
      {R"({"name": "o", "kind": "optical", "perspective": {"corners": [[0, 0], [50, 0], [40, 30],
           [0, 30]], "rows": 10, "cols": 10}, "pixel_pitch_mm": 0.1, "normalization_scale": 0.5})",
       "field 'perspective.corners[1]': expected a point inside the 30x40"},
      {R"({"name": "o", "kind": "optical", "channels": 2, "pixel_pitch_mm": 0.1,
           "normalization_scale": 0.5})",
       "field 'channels'"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.json);
    WriteDescription(dir_ / "optical/sensor.json", c.json);
    try {
      Dataset::Open(Dir("optical"));
      ADD_FAILURE() << "accepted";
    } catch (const DatasetError& e) {
      EXPECT_THAT(e.what(), HasSubstr(Dir("optical/sensor.json")));
      EXPECT_THAT(e.what(), HasSubstr(c.message));
    }
  }
  // A pitch given twice must agree.
  WriteDescription(dir_ / "optical/sensor.json",
                   R"({"name": "o", "kind": "optical", "pixel_pitch_mm": 0.1,
                       "normalization_scale": 0.5})");
  Dataset::OpenOptions options;
  options.pixel_pitch_m = 0.2e-3;
  try {
    Dataset::Open(Dir("optical"), options);
    ADD_FAILURE() << "accepted";
  } catch (const DatasetError& e) {
    EXPECT_THAT(e.what(), HasSubstr("field 'pixel_pitch_mm'"));
  }
  options.pixel_pitch_m = 0.1e-3;
  EXPECT_NO_THROW(Dataset::Open(Dir("optical"), options));
}

TEST_F(SensorDescriptionDatasetTest, EachClipOfAClipSetAndItsReferenceIsCropped) {
  // Two recordings, each with its own reference; one sensor.json for the set.
  for (const char* clip : {"a", "b"}) {
    fs::create_directories(dir_ / "clips" / clip);
    WritePngAtomically((dir_ / "clips" / clip / "reference.png").string(),
                       RandomRgb(30, 40, clip[0]), PixelEncoding::kRgb8);
    WritePngAtomically((dir_ / "clips" / clip / "f0.png").string(), RandomRgb(30, 40, clip[0] + 7),
                       PixelEncoding::kRgb8);
  }
  WriteDescription(dir_ / "clips/sensor.json",
                   R"({"name": "clip_sensor", "kind": "optical", "crop": {"x": 4, "y": 2,
                       "width": 32, "height": 24}, "pixel_pitch_mm": 0.1,
                       "normalization_scale": 0.5})");
  const Dataset data = Dataset::Open(Dir("clips"));
  ASSERT_EQ(data.clips().size(), 2u);
  EXPECT_EQ(data.sensor_info(SensorKind::kGelSlim).rows, 24);
  EXPECT_EQ(data.sensor_info(SensorKind::kGelSlim).cols, 32);
  for (std::size_t i = 0; i < data.frames().size(); ++i) {
    const std::string clip = data.clips()[data.frames()[i].clip].name;
    const Image raw_reference =
        ReadImage(Dir("clips/" + clip + "/reference.png"), PixelEncoding::kRgb8);
    const Image raw = ReadImage(Dir("clips/" + clip + "/f0.png"), PixelEncoding::kRgb8);
    const Image& reference = data.FrameReference(i);
    const Image frame = data.LoadFrame(i);
    ASSERT_EQ(reference.rows, 24);
    ASSERT_EQ(frame.cols, 32);
    EXPECT_EQ(reference.at(0, 0, 2), raw_reference.at(2, 4, 2));
    EXPECT_EQ(reference.at(23, 31, 0), raw_reference.at(25, 35, 0));
    EXPECT_EQ(frame.at(10, 20, 1), raw.at(12, 24, 1));
  }
}

}  // namespace
}  // namespace tactfunc
