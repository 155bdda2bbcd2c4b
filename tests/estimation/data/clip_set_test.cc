// Copyright 2026 The tactfunc Authors.
//
// Sets of recordings ("clips") opened by Dataset::Open, each clip with its own
// reference, and videos decoded on demand by LoadFrame.
#include <algorithm>
#include <filesystem>
#include <functional>
#include <map>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "estimation/data/contact.h"
#include "estimation/data/dataset.h"
#include "estimation/data/preprocess.h"
#include "estimation/data/trunk_targets.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/support/dataset_test_util.h"
#include "tests/support/test_dir.h"

namespace tactfunc {
namespace {

namespace fs = std::filesystem;
using ::testing::ElementsAre;
using ::testing::HasSubstr;
using testing_util::BitIdentical;
using testing_util::ExpectDatasetError;
using testing_util::PatternFrame;
using testing_util::TestDir;
using testing_util::WriteMjpgVideo;
using testing_util::WriteText;

constexpr int kRows = 24;
constexpr int kCols = 32;

// A folder clip `name` in `dir`: reference.png = PatternFrame(reference_pattern) and
// one frame per entry of `frames` (stem -> pattern index).
void WriteFolderClip(const TestDir& dir, const std::string& name, int reference_pattern,
                     const std::map<std::string, int>& frames, int rows = kRows,
                     int cols = kCols) {
  fs::create_directories(dir / name);
  ASSERT_TRUE(cv::imwrite(dir / (name + "/reference.png"),
                          PatternFrame(reference_pattern, rows, cols)));
  for (const auto& [stem, pattern] : frames) {
    ASSERT_TRUE(cv::imwrite(dir / (name + "/" + stem + ".png"), PatternFrame(pattern, rows, cols)));
  }
}

std::vector<std::string> Ids(const Dataset& dataset) {
  std::vector<std::string> ids;
  for (const FrameRecord& record : dataset.frames()) ids.push_back(record.id);
  return ids;
}

// Two folder clips: "grasp_a" (reference pattern 1; frames t0 = pattern 1, i.e. its
// own reference, and t1 = pattern 2) and "grasp_b" (reference pattern 5; frame t0 =
// pattern 6).
void WriteTwoFolderClips(const TestDir& dir) {
  WriteFolderClip(dir, "grasp_a", 1, {{"t0", 1}, {"t1", 2}});
  WriteFolderClip(dir, "grasp_b", 5, {{"t0", 6}});
}

// ---------------------------------------------------------------------------------
// Folder clips.

TEST(ClipSet, FolderClipsLoadWithClipQualifiedIdsAndTheirOwnReferences) {
  TestDir dir;
  WriteTwoFolderClips(dir);
  fs::create_directories(dir / "notes");  // no images: not a clip
  WriteText(dir / "notes/readme.txt", "ignored");
  const Dataset dataset = Dataset::Open(dir.path());
  EXPECT_FALSE(dataset.has_metadata());
  ASSERT_EQ(dataset.sensors(), std::vector<SensorKind>{SensorKind::kGelSlim});
  const SensorInfo& info = dataset.sensor_info(SensorKind::kGelSlim);
  EXPECT_EQ(info.rows, kRows);
  EXPECT_EQ(info.cols, kCols);
  EXPECT_EQ(info.channels, 3);
  EXPECT_EQ(info.reference, "");
  ASSERT_EQ(dataset.clips().size(), 2u);
  EXPECT_EQ(dataset.clips()[0].name, "grasp_a");
  EXPECT_EQ(dataset.clips()[0].path, "grasp_a");
  EXPECT_EQ(dataset.clips()[0].reference, "grasp_a/reference.png");
  EXPECT_FALSE(dataset.clips()[0].video);
  EXPECT_FALSE(dataset.clips()[0].split);
  EXPECT_THAT(Ids(dataset), ElementsAre("grasp_a/t0", "grasp_a/t1", "grasp_b/t0"));
  EXPECT_EQ(dataset.frames()[1].path, "grasp_a/t1.png");
  EXPECT_EQ(dataset.frames()[1].clip, 0);
  EXPECT_EQ(dataset.frames()[2].clip, 1);
  EXPECT_EQ(dataset.frames()[2].video_frame, -1);
  EXPECT_EQ(dataset.FindFrame("grasp_b/t0", SensorKind::kGelSlim), std::size_t{2});
  // Each frame is differenced against its own clip's reference.
  EXPECT_TRUE(BitIdentical(dataset.FrameReference(0), dataset.FrameReference(1)));
  EXPECT_FALSE(BitIdentical(dataset.FrameReference(0), dataset.FrameReference(2)));
  EXPECT_TRUE(BitIdentical(dataset.FrameReference(2),
                           ReadImage(dir / "grasp_b/reference.png", PixelEncoding::kRgb8)));
  // There is no one sensor reference to hand out.
  ExpectDatasetError([&] { dataset.Reference(SensorKind::kGelSlim); },
                     {dir.path().c_str(), "2 clips", "FrameReference"});
  EXPECT_THROW(dataset.FrameReference(3), std::out_of_range);
  EXPECT_EQ(dataset.BytesOnDisk(),
            fs::file_size(dir / "grasp_a/reference.png") + fs::file_size(dir / "grasp_a/t0.png") +
                fs::file_size(dir / "grasp_a/t1.png") +
                fs::file_size(dir / "grasp_b/reference.png") +
                fs::file_size(dir / "grasp_b/t0.png"));
}

TEST(ClipSet, AFrameEqualToItsOwnReferencePreprocessesToExactlyZero) {
  TestDir dir;
  WriteTwoFolderClips(dir);
  const Dataset dataset = Dataset::Open(dir.path());
  const std::size_t own = *dataset.FindFrame("grasp_a/t0", SensorKind::kGelSlim);
  const PreprocessedFrame pre = PreprocessFrame(dataset, own, PreprocessOptions());
  ASSERT_FALSE(pre.values.data.empty());
  EXPECT_TRUE(std::all_of(pre.values.data.begin(), pre.values.data.end(),
                          [](float v) { return v == 0.0f; }));
  // The same pixels against the other clip's reference are not zero: the reference
  // really is the frame's clip's.
  const std::size_t other = *dataset.FindFrame("grasp_b/t0", SensorKind::kGelSlim);
  const PreprocessedFrame against_other =
      Preprocess(dataset.LoadFrame(own), dataset.FrameReference(other), SensorKind::kGelSlim,
                 PreprocessOptions(), DefaultNormalizationScale(SensorKind::kGelSlim));
  EXPECT_TRUE(std::any_of(against_other.values.data.begin(), against_other.values.data.end(),
                          [](float v) { return v != 0.0f; }));
  // Contact detection compares with the same reference: nothing changed, no contact.
  EXPECT_EQ(DetectFrameContact(dataset, own).score, 0.0);
  // The model's targets take the same reference.
  FrameFormat format;
  format.rows = 12;
  format.cols = 16;
  format.grayscale = true;
  format.scale = 0.5;
  const TrunkTargets targets = LoadTrunkTargets(dataset, own, format);
  EXPECT_EQ(targets.values.cwiseAbs().maxCoeff(), 0.0f);
  EXPECT_GT(LoadTrunkTargets(dataset, other, format).values.cwiseAbs().maxCoeff(), 0.0f);
}

TEST(ClipSet, ClipsCsvGivesEveryFrameOfAClipItsSplitAndLabelsMustAgree) {
  TestDir dir;
  WriteTwoFolderClips(dir);
  WriteText(dir / "clips.csv", "\xEF\xBB\xBF" "clip,split\r\ngrasp_b,test\r\n\r\n");
  WriteText(dir / "labels.csv",
            "frame,sensor,tool,x_m,y_m,yaw_rad,depth_m,split\n"
            "grasp_a/t1,gelslim,pen,0.001,0,0.5,0.002,test\n"
            "grasp_b/t0,gelslim,hex_key,0,0.001,0,0.003,test\n");
  const Dataset dataset = Dataset::Open(dir.path());
  ASSERT_EQ(dataset.frames().size(), 3u);
  EXPECT_EQ(dataset.frames()[0].split, Split::kTrain);  // no row anywhere
  EXPECT_EQ(dataset.frames()[1].split, Split::kTest);   // labels.csv, clip not listed
  ASSERT_TRUE(dataset.frames()[1].label);
  EXPECT_EQ(dataset.frames()[1].label->tool, "pen");
  EXPECT_EQ(dataset.frames()[2].split, Split::kTest);  // clips.csv
  ASSERT_TRUE(dataset.clips()[1].split);
  EXPECT_EQ(*dataset.clips()[1].split, Split::kTest);
  EXPECT_FALSE(dataset.clips()[0].split);
  EXPECT_EQ(dataset.FrameIndices(SensorKind::kGelSlim, Split::kTest).size(), 2u);
  const std::vector<std::string> files = dataset.Files();
  EXPECT_NE(std::find(files.begin(), files.end(), dir / "clips.csv"), files.end());

  // A label row whose split contradicts its clip's.
  WriteText(dir / "labels.csv",
            "frame,sensor,tool,x_m,y_m,yaw_rad,depth_m,split\n"
            "grasp_b/t0,gelslim,hex_key,0,0.001,0,0.003,train\n");
  ExpectDatasetError([&] { Dataset::Open(dir.path()); },
                     {"labels.csv:2:", "field 'split'", "expected 'test'", "grasp_b", "clips.csv",
                      "got 'train'"});
  fs::remove(dir / "labels.csv");
  WriteText(dir / "clips.csv", "clip,split\ngrasp_c,test\n");
  ExpectDatasetError([&] { Dataset::Open(dir.path()); },
                     {"clips.csv:2:", "field 'clip'", "grasp_c"});
  WriteText(dir / "clips.csv", "clip,split\ngrasp_a,validation\n");
  ExpectDatasetError([&] { Dataset::Open(dir.path()); },
                     {"clips.csv:2:", "field 'split'", "validation"});
  WriteText(dir / "clips.csv", "clip,split\ngrasp_a,test\ngrasp_a,train\n");
  ExpectDatasetError([&] { Dataset::Open(dir.path()); }, {"clips.csv:3:", "grasp_a"});
  WriteText(dir / "clips.csv", "name,split\n");
  ExpectDatasetError([&] { Dataset::Open(dir.path()); },
                     {"clips.csv:1:", "header", "clip,split"});
}

TEST(ClipSet, LabelsNameClipQualifiedIds) {
  TestDir dir;
  WriteTwoFolderClips(dir);
  // The bare stem is not an id of a clip set: t0 exists in both clips.
  WriteText(dir / "labels.csv",
            "frame,sensor,tool,x_m,y_m,yaw_rad,depth_m,split\n"
            "t0,gelslim,pen,0,0,0,0.002,train\n");
  ExpectDatasetError([&] { Dataset::Open(dir.path()); },
                     {"labels.csv:2:", "field 'frame'", "'t0'"});
}

TEST(ClipSet, ClipsOfAnotherSizeOrSensorAreRefusedNamingTheClip) {
  TestDir dir;
  WriteFolderClip(dir, "a", 1, {{"t0", 2}});
  WriteFolderClip(dir, "b", 3, {{"t0", 4}}, kRows + 2, kCols);
  ExpectDatasetError([&] { Dataset::Open(dir.path()); },
                     {"clip 'b'", "expected gelslim frames of 24x32x3", "like clip 'a'",
                      "got gelslim frames of 26x32x3"});
  fs::remove_all(dir / "b");
  fs::create_directories(dir / "b");
  WritePngAtomically(dir / "b/reference.png", Image(kRows, kCols, 1, 0.03f),
                     PixelEncoding::kDepthU16Micrometres);
  WritePngAtomically(dir / "b/t0.png", Image(kRows, kCols, 1, 0.031f),
                     PixelEncoding::kDepthU16Micrometres);
  ExpectDatasetError([&] { Dataset::Open(dir.path()); },
                     {"clip 'b'", "expected gelslim frames", "got bubble frames of 24x32x1"});
  // A clip without a reference names itself.
  fs::remove(dir / "b/reference.png");
  ExpectDatasetError([&] { Dataset::Open(dir.path()); }, {(dir / "b").c_str(), "reference"});
}

TEST(ClipSet, OneNameForTwoClipsIsAnError) {
  TestDir dir;
  WriteFolderClip(dir, "a", 1, {{"t0", 2}});
  WriteText(dir / "a.avi", "a video file by its name");
  ExpectDatasetError([&] { Dataset::Open(dir.path()); }, {"clip 'a'", "a.avi"});
}

TEST(ClipSet, AFolderWithImagesOfItsOwnStaysAFlatFolder) {
  TestDir dir;
  WriteFolderClip(dir, "a", 1, {{"t0", 2}});
  ASSERT_TRUE(cv::imwrite(dir / "reference.png", PatternFrame(0)));
  ASSERT_TRUE(cv::imwrite(dir / "t9.png", PatternFrame(9)));
  const Dataset dataset = Dataset::Open(dir.path());
  EXPECT_TRUE(dataset.clips().empty());
  EXPECT_THAT(Ids(dataset), ElementsAre("t9"));
  EXPECT_EQ(dataset.frames()[0].clip, -1);
  EXPECT_TRUE(BitIdentical(dataset.FrameReference(0), dataset.Reference(SensorKind::kGelSlim)));
}

// ---------------------------------------------------------------------------------
// Video clips and videos.

// A video of `count` PatternFrames (frame i = pattern pattern_of(i)). False if this
// OpenCV build cannot write MJPG.
bool WritePatternVideo(const std::string& path, int count,
                       const std::function<int(int)>& pattern_of = [](int i) { return i; }) {
  std::vector<cv::Mat> frames;
  for (int i = 0; i < count; ++i) frames.push_back(PatternFrame(pattern_of(i)));
  return WriteMjpgVideo(path, frames);
}

constexpr const char* kNoMjpg =
    "this OpenCV build cannot write MJPG .avi (no videoio backend with the codec), so "
    "video clips cannot be exercised here";

TEST(ClipSet, VideoAndFolderClipsMixWithEachVideosFrameAsItsReference) {
  TestDir dir;
  WriteTwoFolderClips(dir);
  // Frame 2 repeats frame 0 (the reference) exactly.
  if (!WritePatternVideo(dir / "press.AVI", 4, [](int i) { return i == 2 ? 20 : 20 + i; })) {
    GTEST_SKIP() << kNoMjpg;
  }
  const Dataset dataset = Dataset::Open(dir.path());
  ASSERT_EQ(dataset.clips().size(), 3u);
  EXPECT_EQ(dataset.clips()[2].name, "press");
  EXPECT_EQ(dataset.clips()[2].path, "press.AVI");
  EXPECT_EQ(dataset.clips()[2].reference, "press.AVI#000000");
  EXPECT_TRUE(dataset.clips()[2].video);
  EXPECT_THAT(Ids(dataset), ElementsAre("grasp_a/t0", "grasp_a/t1", "grasp_b/t0", "press/000001",
                                        "press/000002", "press/000003"));
  const std::size_t repeat = *dataset.FindFrame("press/000002", SensorKind::kGelSlim);
  EXPECT_EQ(dataset.frames()[repeat].path, "press.AVI#000002");
  EXPECT_EQ(dataset.frames()[repeat].video_frame, 2);
  EXPECT_EQ(dataset.frames()[repeat].clip, 2);
  // The repeated frame decodes to its clip's reference, so its difference is zero;
  // against a folder clip's reference it is not.
  const PreprocessedFrame pre = PreprocessFrame(dataset, repeat, PreprocessOptions());
  EXPECT_TRUE(std::all_of(pre.values.data.begin(), pre.values.data.end(),
                          [](float v) { return v == 0.0f; }));
  EXPECT_FALSE(BitIdentical(dataset.FrameReference(repeat), dataset.FrameReference(0)));
  EXPECT_FALSE(BitIdentical(dataset.LoadFrame(repeat + 1), dataset.FrameReference(repeat)));
  const std::vector<std::string> files = dataset.Files();
  EXPECT_NE(std::find(files.begin(), files.end(), dir / "press.AVI"), files.end());
  EXPECT_EQ(std::count_if(files.begin(), files.end(),
                          [](const std::string& f) { return f.find('#') != std::string::npos; }),
            0);

  Dataset::OpenOptions options;
  options.reference_index = 3;
  const Dataset shifted = Dataset::Open(dir.path(), options);
  EXPECT_TRUE(shifted.FindFrame("press/000000", SensorKind::kGelSlim));
  EXPECT_FALSE(shifted.FindFrame("press/000003", SensorKind::kGelSlim));
  options.reference_index = 4;
  ExpectDatasetError([&] { Dataset::Open(dir.path(), options); },
                     {"press.AVI", "reference_index"});
  options = Dataset::OpenOptions();
  options.sensor = SensorKind::kSoftBubble;
  ExpectDatasetError([&] { Dataset::Open(dir.path(), options); },
                     {"grasp_a/reference.png", "16-bit"});
}

TEST(ClipSet, AFolderOfVideosIsAClipSetWithSplitsPerClip) {
  TestDir dir;
  if (!WritePatternVideo(dir / "b.avi", 3) || !WritePatternVideo(dir / "a.mp4.avi", 2)) {
    GTEST_SKIP() << kNoMjpg;
  }
  WriteText(dir / "clips.csv", "clip,split\nb,test\na.mp4,train\n");
  const Dataset dataset = Dataset::Open(dir.path());
  EXPECT_THAT(Ids(dataset), ElementsAre("a.mp4/000001", "b/000001", "b/000002"));
  EXPECT_EQ(dataset.frames()[0].split, Split::kTrain);
  EXPECT_EQ(dataset.frames()[1].split, Split::kTest);
  EXPECT_EQ(dataset.frames()[2].split, Split::kTest);
  EXPECT_TRUE(BitIdentical(dataset.LoadFrame(2), dataset.LoadFrame(2)));
  Dataset::OpenOptions options;
  options.sensor = SensorKind::kSoftBubble;
  ExpectDatasetError([&] { Dataset::Open(dir.path(), options); },
                     {"a.mp4.avi", "expected sensor 'gelslim', got 'bubble'"});
}

// Every frame of a long enough video read in order, for comparison.
std::vector<Image> ReadInOrder(const Dataset& dataset) {
  std::vector<Image> frames;
  for (std::size_t i = 0; i < dataset.frames().size(); ++i) frames.push_back(dataset.LoadFrame(i));
  return frames;
}

constexpr int kLongVideo = 90;  // more than the decoder's forward reach (32) twice over

TEST(VideoStreaming, RandomAccessInShuffledOrderGivesTheSequentialFrames) {
  TestDir dir;
  if (!WritePatternVideo(dir / "long.avi", kLongVideo)) GTEST_SKIP() << kNoMjpg;
  const std::vector<Image> sequential = ReadInOrder(Dataset::OpenVideo(dir / "long.avi"));
  ASSERT_EQ(sequential.size(), static_cast<std::size_t>(kLongVideo - 1));
  // Every frame is different: a reader that returned a neighbour would be caught.
  for (std::size_t i = 1; i < sequential.size(); ++i) {
    ASSERT_FALSE(BitIdentical(sequential[i - 1], sequential[i])) << i;
  }
  const Dataset dataset = Dataset::OpenVideo(dir / "long.avi");
  std::vector<std::size_t> order(sequential.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::mt19937 rng(11);
  std::shuffle(order.begin(), order.end(), rng);
  order.insert(order.end(), {0, sequential.size() - 1, 0, 40, 39, 38});  // back and forth
  for (std::size_t i : order) {
    ASSERT_TRUE(BitIdentical(dataset.LoadFrame(i), sequential[i])) << "frame " << i;
  }
}

TEST(VideoStreaming, ConcurrentLoadFrameFromSeveralThreadsGivesTheSequentialFrames) {
  TestDir dir;
  if (!WritePatternVideo(dir / "long.avi", kLongVideo)) GTEST_SKIP() << kNoMjpg;
  const Dataset dataset = Dataset::OpenVideo(dir / "long.avi");
  const std::vector<Image> sequential = ReadInOrder(Dataset::OpenVideo(dir / "long.avi"));
  constexpr int kThreads = 4;
  std::vector<int> mismatches(kThreads, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < kThreads; ++t) {
    threads.emplace_back([&, t] {
      // Interleaved (t, t + 4, ...) in one thread, shuffled in another.
      std::vector<std::size_t> order;
      for (std::size_t i = t % 2; i < sequential.size(); i += 2) order.push_back(i);
      if (t >= 2) std::shuffle(order.begin(), order.end(), std::mt19937(t));
      for (std::size_t i : order) {
        if (!BitIdentical(dataset.LoadFrame(i), sequential[i])) ++mismatches[t];
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_THAT(mismatches, ElementsAre(0, 0, 0, 0));
}

TEST(VideoStreaming, ClipsOfAFolderOfVideosAreReadConcurrently) {
  TestDir dir;
  for (const char* name : {"c0.avi", "c1.avi", "c2.avi", "c3.avi", "c4.avi", "c5.avi"}) {
    if (!WritePatternVideo(dir / name, 12, [name](int i) { return 7 * (name[1] - '0') + i; })) {
      GTEST_SKIP() << kNoMjpg;
    }
  }
  const Dataset dataset = Dataset::Open(dir.path());
  ASSERT_EQ(dataset.clips().size(), 6u);  // more clips than decoders kept open (4)
  const std::vector<Image> sequential = ReadInOrder(Dataset::Open(dir.path()));
  std::vector<int> mismatches(3, 0);
  std::vector<std::thread> threads;
  for (int t = 0; t < 3; ++t) {
    threads.emplace_back([&, t] {
      std::vector<std::size_t> order(sequential.size());
      for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
      std::shuffle(order.begin(), order.end(), std::mt19937(100 + t));
      for (std::size_t i : order) {
        if (!BitIdentical(dataset.LoadFrame(i), sequential[i])) ++mismatches[t];
      }
    });
  }
  for (std::thread& thread : threads) thread.join();
  EXPECT_THAT(mismatches, ElementsAre(0, 0, 0));
}

TEST(VideoStreaming, AVideoChangedAfterOpenIsAnErrorNotOtherPixels) {
  TestDir dir;
  if (!WritePatternVideo(dir / "v.avi", 6)) GTEST_SKIP() << kNoMjpg;
  const Dataset dataset = Dataset::OpenVideo(dir / "v.avi");
  ASSERT_TRUE(WritePatternVideo(dir / "v.avi", 6, [](int i) { return 50 + i; }));
  ExpectDatasetError([&] { dataset.LoadFrame(2); },
                     {"v.avi#3", "expected the frame seen when the video was opened"});
}

}  // namespace
}  // namespace tactfunc
