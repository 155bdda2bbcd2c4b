// Copyright 2026 The tactfunc Authors.
//
// VideoReader: frames decoded on demand, by seeking or by reading forward, always the
// pixels seen when the video was opened.
#include "estimation/data/internal/video_reader.h"

#include <algorithm>
#include <memory>
#include <random>
#include <vector>

#include "estimation/data/internal/opencv_image.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/support/dataset_test_util.h"
#include "tests/support/test_dir.h"

namespace tactfunc::internal {
namespace {

using testing_util::BitIdentical;
using testing_util::ExpectDatasetError;
using testing_util::PatternFrame;
using testing_util::TestDir;
using testing_util::WriteMjpgVideo;

constexpr int kFrames = 80;

// Writes a video of kFrames PatternFrames; false if MJPG cannot be written here.
bool WriteVideo(const std::string& path) {
  std::vector<cv::Mat> frames;
  for (int i = 0; i < kFrames; ++i) frames.push_back(PatternFrame(i));
  return WriteMjpgVideo(path, frames);
}

std::vector<std::size_t> ShuffledOrder(unsigned seed) {
  std::vector<std::size_t> order(kFrames);
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  std::shuffle(order.begin(), order.end(), std::mt19937(seed));
  return order;
}

TEST(VideoReader, OpensByCountingAndKeepsOnlyTheReference) {
  TestDir dir;
  if (!WriteVideo(dir / "v.avi")) GTEST_SKIP() << "no MJPG writer in this OpenCV build";
  Image reference;
  VideoReader reader(dir / "v.avi", 5, &reference, VideoReader::Options());
  EXPECT_EQ(reader.num_frames(), static_cast<std::size_t>(kFrames));
  EXPECT_EQ(reader.rows(), 24);
  EXPECT_EQ(reader.cols(), 32);
  // Nothing is decoded until a frame is asked for.
  EXPECT_EQ(reader.stats().frames_decoded, 0u);
  EXPECT_TRUE(BitIdentical(reader.Frame(5), reference));
  EXPECT_EQ(reader.stats().frames_decoded, 6u);  // read forward from the start
  EXPECT_FALSE(BitIdentical(reader.Frame(6), reference));
  ExpectDatasetError([&] { VideoReader(dir / "v.avi", kFrames, &reference, {}); },
                     {"v.avi", "reference_index", "< 80"});
}

TEST(VideoReader, SeekingAndReadingForwardGiveTheSameFrames) {
  TestDir dir;
  if (!WriteVideo(dir / "v.avi")) GTEST_SKIP() << "no MJPG writer in this OpenCV build";
  Image reference;
  VideoReader::Options forward_only;
  forward_only.seek = false;
  forward_only.cache_frames = 0;
  VideoReader forward(dir / "v.avi", 0, &reference, forward_only);
  VideoReader seeking(dir / "v.avi", 0, &reference, VideoReader::Options());
  for (std::size_t i : ShuffledOrder(3)) {
    ASSERT_TRUE(BitIdentical(seeking.Frame(i), forward.Frame(i))) << "frame " << i;
  }
  // The seeking reader seeked (and, for MJPG in AVI, landed where asked); the other
  // only ever read forward.
  const VideoReader::Stats seeks = seeking.stats();
  EXPECT_GT(seeks.seeks, 0u);
  EXPECT_EQ(seeks.seek_misses, 0u) << "seeks in an MJPG .avi should land on the frame";
  EXPECT_EQ(forward.stats().seeks, 0u);
  EXPECT_GT(forward.stats().rewinds, 0u);
  // Decoding on demand: the seeking reader decoded far fewer frames than reading
  // forward from the start each time it goes back.
  EXPECT_LT(seeks.frames_decoded, forward.stats().frames_decoded);
}

TEST(VideoReader, NeighboursAskedOutOfOrderComeFromTheCache) {
  TestDir dir;
  if (!WriteVideo(dir / "v.avi")) GTEST_SKIP() << "no MJPG writer in this OpenCV build";
  Image reference;
  VideoReader reader(dir / "v.avi", 0, &reference, VideoReader::Options());
  const Image ten = reader.Frame(10);
  const VideoReader::Stats before = reader.stats();
  const Image nine = reader.Frame(9);  // read on the way to 10
  EXPECT_EQ(reader.stats().cache_hits, before.cache_hits + 1);
  EXPECT_EQ(reader.stats().frames_decoded, before.frames_decoded);
  EXPECT_FALSE(BitIdentical(nine, ten));
}

TEST(VideoReader, TheBudgetClosesTheLeastRecentlyUsedDecoder) {
  TestDir dir;
  if (!WriteVideo(dir / "v.avi")) GTEST_SKIP() << "no MJPG writer in this OpenCV build";
  Image reference;
  VideoReader::Options options;
  options.budget = std::make_shared<VideoDecoderBudget>(1);
  VideoReader a(dir / "v.avi", 0, &reference, options);
  VideoReader b(dir / "v.avi", 0, &reference, options);
  a.Frame(3);
  b.Frame(3);  // closes a's decoder (and drops its cache)
  const VideoReader::Stats before = a.stats();
  EXPECT_TRUE(BitIdentical(a.Frame(3), b.Frame(3)));
  EXPECT_EQ(a.stats().cache_hits, before.cache_hits);        // not served from a cache
  EXPECT_EQ(a.stats().frames_decoded, before.frames_decoded + 4);  // reopened, read again
}

TEST(VideoReader, AFileThatIsNotAVideoIsAnErrorNamingIt) {
  TestDir dir;
  testing_util::WriteText(dir / "junk.avi", "not a video");
  Image reference;
  ExpectDatasetError([&] { VideoReader(dir / "junk.avi", 0, &reference, {}); }, {"junk.avi"});
}

}  // namespace
}  // namespace tactfunc::internal
