// Copyright 2026 The tactfunc Authors.
#include "estimation/data/synthetic_dataset.h"

#include <filesystem>
#include <fstream>
#include <sstream>

#include "estimation/data/dataset.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "models/simulator/tool.h"

namespace tactfunc {
namespace {

namespace fs = std::filesystem;

std::string TempDir(const std::string& name) {
  const fs::path dir = fs::path(testing::TempDir()) / ("tactfunc_synth_" + name);
  fs::remove_all(dir);
  return dir.string();
}

std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

// Every file of the folder, name -> bytes.
std::map<std::string, std::string> Files(const std::string& dir) {
  std::map<std::string, std::string> files;
  for (const auto& entry : fs::recursive_directory_iterator(dir)) {
    if (entry.is_regular_file()) {
      files[fs::relative(entry.path(), dir).string()] = Slurp(entry.path().string());
    }
  }
  return files;
}

SynthesisPlan SmallPlan(const std::string& out) {
  SynthesisPlan plan;
  plan.out = out;
  plan.tools = {"rod", "l_shape"};
  plan.frames_per_tool = 10;
  plan.seed = 11;
  return plan;
}

TEST(Synthesize, DefaultPlanIsValidOnceItNamesAFolderAndTools) {
  SynthesisPlan plan = SmallPlan("x");
  std::string error;
  EXPECT_TRUE(plan.IsValid(&error)) << error;
  plan.frames_per_tool = 0;
  EXPECT_FALSE(plan.IsValid(&error));
  EXPECT_THAT(error, ::testing::HasSubstr("frames_per_tool"));
}

TEST(Synthesize, TheSameSeedGivesBitIdenticalFilesWhateverTheThreadCount) {
  SynthesisPlan one = SmallPlan(TempDir("one"));
  one.threads = 1;
  SynthesisPlan two = SmallPlan(TempDir("two"));
  two.threads = 2;
  Synthesize(one, ContactSimulator::Options());
  Synthesize(two, ContactSimulator::Options());
  EXPECT_EQ(Files(one.out), Files(two.out));
  SynthesisPlan other = SmallPlan(TempDir("other"));
  other.seed = 12;
  Synthesize(other, ContactSimulator::Options());
  EXPECT_NE(Files(one.out).at("labels.csv"), Files(other.out).at("labels.csv"));
}

TEST(Synthesize, WritesPairedLabelledFramesWithEveryTenthContactInTest) {
  SynthesisPlan plan = SmallPlan(TempDir("paired"));
  plan.write_clean = true;
  const SynthesisReport report = Synthesize(plan, ContactSimulator::Options());
  EXPECT_EQ(report.contacts, 20);
  EXPECT_EQ(report.frames, 40);
  const Dataset dataset = Dataset::Open(plan.out);
  EXPECT_TRUE(dataset.has_clean());
  EXPECT_EQ(dataset.FrameIndices(SensorKind::kSoftBubble, Split::kTest).size(), 2u);
  EXPECT_EQ(dataset.FrameIndices(SensorKind::kGelSlim, Split::kTrain).size(), 18u);
  // Paired frames share the id and the pose; depths differ per sensor.
  const auto bubble = dataset.FrameIndices(SensorKind::kSoftBubble);
  const auto gel = dataset.FrameIndices(SensorKind::kGelSlim);
  ASSERT_EQ(bubble.size(), gel.size());
  for (std::size_t k = 0; k < bubble.size(); ++k) {
    const FrameRecord& b = dataset.frames()[bubble[k]];
    const FrameRecord& g = dataset.frames()[gel[k]];
    EXPECT_EQ(b.id, g.id);
    ASSERT_TRUE(b.label && g.label);
    EXPECT_EQ(b.label->sensor_T_object.x(), g.label->sensor_T_object.x());
    EXPECT_EQ(b.label->sensor_T_object.yaw(), g.label->sensor_T_object.yaw());
    EXPECT_GT(b.label->depth_m, g.label->depth_m);
    EXPECT_EQ(b.split, g.split);
  }
  EXPECT_EQ(report.bytes, dataset.BytesOnDisk());
}

TEST(Synthesize, AGelSlimWithoutMarkersHasAnEvenReferenceAndSaysSoInTheMeta) {
  SynthesisPlan plan = SmallPlan(TempDir("no_markers"));
  plan.sensors = {SensorKind::kGelSlim};
  plan.frames_per_tool = 1;
  ContactSimulator::Options options;
  options.gelslim.marker_darkness = 0;
  Synthesize(plan, options);
  const Dataset dataset = Dataset::Open(plan.out);
  // Without dots the reference is the vignetted grey only: along the centre row it
  // falls monotonically from the centre (a dot would dip and recover).
  const Image& reference = dataset.Reference(SensorKind::kGelSlim);
  const int r = reference.rows / 2;
  for (int c = reference.cols / 2 + 1; c < reference.cols; ++c) {
    ASSERT_LE(reference.at(r, c, 1), reference.at(r, c - 1, 1) + 1.0f / 255) << c;
  }
  EXPECT_THAT(Slurp(plan.out + "/dataset.json"),
              ::testing::HasSubstr("\"gelslim_marker_darkness\": 0"));
  // The default simulator records nothing extra.
  SynthesisPlan with_markers = SmallPlan(TempDir("markers"));
  with_markers.sensors = {SensorKind::kGelSlim};
  with_markers.frames_per_tool = 1;
  Synthesize(with_markers, ContactSimulator::Options());
  EXPECT_THAT(Slurp(with_markers.out + "/dataset.json"),
              ::testing::Not(::testing::HasSubstr("marker")));
}

TEST(Synthesize, RejectsUnknownToolsBeforeWritingAnything) {
  SynthesisPlan plan = SmallPlan(TempDir("bad_tool"));
  plan.tools = {"rod", "teapot"};
  EXPECT_THROW(Synthesize(plan, ContactSimulator::Options()), std::invalid_argument);
  EXPECT_FALSE(fs::exists(fs::path(plan.out) / "dataset.json"));
}

}  // namespace
}  // namespace tactfunc
