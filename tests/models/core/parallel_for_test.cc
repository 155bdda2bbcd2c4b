// Copyright 2026 The tactfunc Authors.
//
// internal::ParallelFor: every index is visited exactly once whatever the thread count,
// the index keeps the integer type of the count (int64 counts beyond 2^31 are how
// Synthesize numbers its contacts), and the first exception reaches the caller only
// after every worker has stopped.
#include "models/core/parallel_for.h"

#include <atomic>
#include <cstdint>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "gtest/gtest.h"

namespace tactfunc::internal {
namespace {

TEST(ParallelFor, VisitsEveryIndexExactlyOnceWhateverTheThreadCount) {
  for (int threads : {1, 2, 3, 8, 100}) {
    std::vector<std::atomic<int>> visits(257);
    ParallelFor(257, threads, [&](int i) { ++visits[i]; });
    for (int i = 0; i < 257; ++i) {
      EXPECT_EQ(visits[i].load(), 1) << "index " << i << ", threads " << threads;
    }
  }
}

TEST(ParallelFor, DoesNothingForAnEmptyOrNegativeCount) {
  int calls = 0;
  ParallelFor(0, 4, [&](int) { ++calls; });
  ParallelFor(-3, 4, [&](int) { ++calls; });
  EXPECT_EQ(calls, 0);
}

TEST(ParallelFor, HandsOutIndicesOfTheCountsIntegerType) {
  const std::int64_t offset = std::int64_t{1} << 33;  // beyond any int
  std::vector<std::atomic<int>> visits(64);
  ParallelFor(std::int64_t{64}, 2, [&](auto i) {
    static_assert(std::is_same_v<decltype(i), std::int64_t>);
    const std::int64_t shifted = i + offset;  // arithmetic stays 64-bit
    ++visits[static_cast<std::size_t>(shifted - offset)];
  });
  for (const auto& v : visits) EXPECT_EQ(v.load(), 1);
}

TEST(ParallelFor, RethrowsTheFirstExceptionAfterEveryWorkerStopped) {
  std::atomic<int> running{0};
  auto body = [&](int i) {
    ++running;
    if (i == 5) {
      --running;
      throw std::runtime_error("item 5 failed");
    }
    --running;
  };
  EXPECT_THROW(ParallelFor(1000, 3, body), std::runtime_error);
  EXPECT_EQ(running.load(), 0);  // no worker still inside fn when the caller resumes
}

// How many items run after a failure depends on scheduling when only one item fails
// (the other workers may race through many cheap items before it is reached), so the
// stop is checked where it is deterministic: one worker stops at once, and when every
// item fails each worker stops at its first.
TEST(ParallelFor, WorkersStopTakingItemsOnceAnItemFailed) {
  std::atomic<int> started{0};
  auto fail_at_5 = [&](int i) {
    ++started;
    if (i == 5) throw std::runtime_error("item 5 failed");
  };
  EXPECT_THROW(ParallelFor(1000, 1, fail_at_5), std::runtime_error);
  EXPECT_EQ(started.load(), 6);

  started = 0;
  auto always_fail = [&](int i) {
    ++started;
    throw std::runtime_error("item " + std::to_string(i) + " failed");
  };
  EXPECT_THROW(ParallelFor(1000, 3, always_fail), std::runtime_error);
  EXPECT_GE(started.load(), 1);
  EXPECT_LE(started.load(), 3);  // at most one item per worker
}

}  // namespace
}  // namespace tactfunc::internal
