// Copyright 2026 The tactfunc Authors.
//
// ProcessGroup's per-item sharing (OwnItems, GatherItems) on a group of threads that
// stand in for processes: each thread is one rank, and AllGather hands every rank the
// buffers all of them passed, as MPI_Allgatherv does (apps/distributed.cc).
#include "models/core/process_group.h"

#include <condition_variable>
#include <exception>
#include <functional>
#include <mutex>
#include <stdexcept>
#include <string>
#include <thread>
#include <vector>

#include "gtest/gtest.h"

namespace tactfunc {
namespace {

// The buffers of one AllGather at a time, shared by the ranks' threads.
class Board {
 public:
  explicit Board(int size) : size_(size), slots_(size) {}
  int size() const { return size_; }
  std::vector<Bytes> Exchange(int rank, const Bytes& mine) {
    std::unique_lock<std::mutex> lock(mutex_);
    // Wait until the previous exchange's buffers were read by everyone.
    changed_.wait(lock, [&] { return readers_ == 0; });
    slots_[rank] = mine;
    const long round = round_;
    if (++written_ == size_) {
      written_ = 0;
      readers_ = size_;
      ++round_;
      changed_.notify_all();
    } else {
      changed_.wait(lock, [&] { return round_ != round; });
    }
    std::vector<Bytes> all = slots_;
    if (--readers_ == 0) changed_.notify_all();
    return all;
  }

 private:
  const int size_;
  std::vector<Bytes> slots_;
  std::mutex mutex_;
  std::condition_variable changed_;
  int written_ = 0, readers_ = 0;
  long round_ = 0;
};

class ThreadRank final : public ProcessGroup {
 public:
  ThreadRank(Board* board, int rank) : board_(board), rank_(rank) {}
  int rank() const override { return rank_; }
  int size() const override { return board_->size(); }
  std::vector<Bytes> AllGather(const Bytes& mine) const override {
    return board_->Exchange(rank_, mine);
  }
  void Broadcast(Bytes* data) const override { *data = AllGather(*data)[0]; }

 private:
  Board* board_;
  int rank_;
};

// Runs body(group) on `size` ranks at once; returns each rank's exception (or null).
std::vector<std::exception_ptr> OnRanks(int size,
                                        const std::function<void(const ProcessGroup&)>& body) {
  Board board(size);
  std::vector<std::exception_ptr> errors(size);
  std::vector<std::thread> threads;
  for (int r = 0; r < size; ++r) {
    threads.emplace_back([&, r] {
      const ThreadRank group(&board, r);
      try {
        body(group);
      } catch (...) {
        errors[r] = std::current_exception();
      }
    });
  }
  for (std::thread& t : threads) t.join();
  return errors;
}

// Item i's result: i + 1 bytes of value i (lengths differ between items).
Bytes ItemResult(std::int64_t i) { return Bytes(static_cast<std::size_t>(i + 1), std::uint8_t(i)); }

TEST(ProcessGroupTest, OwnItemsAreRoundRobinAndCoverEveryItemOnce) {
  std::vector<std::vector<std::int64_t>> own(3);
  std::mutex mutex;
  OnRanks(3, [&](const ProcessGroup& group) {
    const std::vector<std::int64_t> items = group.OwnItems(10);
    std::lock_guard<std::mutex> lock(mutex);
    own[group.rank()] = items;
  });
  EXPECT_EQ(own[0], (std::vector<std::int64_t>{0, 3, 6, 9}));
  EXPECT_EQ(own[1], (std::vector<std::int64_t>{1, 4, 7}));
  EXPECT_EQ(own[2], (std::vector<std::int64_t>{2, 5, 8}));
  EXPECT_EQ(SingleProcess().OwnItems(4), (std::vector<std::int64_t>{0, 1, 2, 3}));
}

TEST(ProcessGroupTest, GatherItemsGivesEveryRankEveryItemInItemOrder) {
  // More items than ranks, fewer (rank 2 owns none), and none.
  for (const std::int64_t count : {std::int64_t{11}, std::int64_t{2}, std::int64_t{0}}) {
    std::vector<std::vector<Bytes>> received(3);
    std::mutex mutex;
    const std::vector<std::exception_ptr> errors = OnRanks(3, [&](const ProcessGroup& group) {
      std::vector<Bytes> mine;
      for (const std::int64_t i : group.OwnItems(count)) mine.push_back(ItemResult(i));
      std::vector<Bytes> all = group.GatherItems(count, mine);
      std::lock_guard<std::mutex> lock(mutex);
      received[group.rank()] = std::move(all);
    });
    for (int r = 0; r < 3; ++r) {
      EXPECT_EQ(errors[r], nullptr) << "rank " << r;
      ASSERT_EQ(received[r].size(), static_cast<std::size_t>(count)) << "rank " << r;
      for (std::int64_t i = 0; i < count; ++i) {
        EXPECT_EQ(received[r][i], ItemResult(i)) << "rank " << r << ", item " << i;
      }
    }
  }
}

TEST(ProcessGroupTest, GatherItemsRefusesRanksThatShareOutOtherCounts) {
  // Rank 1 selected 9 items where the others selected 10 (other data at the same path).
  const std::vector<std::exception_ptr> errors = OnRanks(3, [](const ProcessGroup& group) {
    const std::int64_t count = group.rank() == 1 ? 9 : 10;
    std::vector<Bytes> mine;
    for (const std::int64_t i : group.OwnItems(count)) mine.push_back(ItemResult(i));
    group.GatherItems(count, mine);
  });
  for (int r = 0; r < 3; ++r) {
    ASSERT_NE(errors[r], nullptr) << "rank " << r;
    try {
      std::rethrow_exception(errors[r]);
    } catch (const std::runtime_error& e) {
      // Every rank names a rank whose count differs from its own.
      const std::string other = r == 1 ? "process 0 of 3 has 10 items" : "process 1 of 3 has 9 items";
      EXPECT_NE(std::string(e.what()).find(other), std::string::npos) << e.what();
    }
  }
}

TEST(ProcessGroupTest, GatherItemsRefusesAnotherNumberOfResultsThanOwnItems) {
  EXPECT_THROW(SingleProcess().GatherItems(3, {ItemResult(0)}), std::runtime_error);
  const std::vector<Bytes> three = {ItemResult(0), ItemResult(1), ItemResult(2)};
  EXPECT_EQ(SingleProcess().GatherItems(3, three), three);
}

}  // namespace
}  // namespace tactfunc
