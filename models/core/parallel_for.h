// Copyright 2026 The tactfunc Authors.
//
// ParallelFor: runs fn(i) for i in [0, count) on `threads` workers (the calling thread
// is one of them), handing out indices through an atomic counter. The index has the
// integer type of `count` (int, or std::int64_t for counts that may exceed 2^31).
// Callers that need results independent of the thread count write item i's result to
// slot i and reduce the slots in index order afterwards. The first exception thrown by
// any fn is rethrown in the caller once every worker has stopped.
#ifndef TACTFUNC_MODELS_CORE_PARALLEL_FOR_H_
#define TACTFUNC_MODELS_CORE_PARALLEL_FOR_H_

#include <algorithm>
#include <atomic>
#include <exception>
#include <mutex>
#include <thread>
#include <type_traits>
#include <vector>

namespace tactfunc::internal {

template <typename Index, typename Fn>
void ParallelFor(Index count, int threads, const Fn& fn) {
  static_assert(std::is_integral_v<Index>, "ParallelFor: count must be an integer");
  if (count <= 0) return;
  const int workers =
      static_cast<int>(std::max<Index>(1, std::min<Index>(static_cast<Index>(threads), count)));
  if (workers == 1) {
    for (Index i = 0; i < count; ++i) fn(i);
    return;
  }
  std::atomic<Index> next{0};
  std::atomic<bool> failed{false};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto work = [&]() {
    for (Index i = next++; i < count && !failed.load(); i = next++) {
      try {
        fn(i);
      } catch (...) {
        std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
        failed = true;
      }
    }
  };
  std::vector<std::thread> pool;
  pool.reserve(workers - 1);
  for (int t = 1; t < workers; ++t) pool.emplace_back(work);
  work();
  for (std::thread& thread : pool) thread.join();
  if (error) std::rethrow_exception(error);
}

}  // namespace tactfunc::internal

#endif  // TACTFUNC_MODELS_CORE_PARALLEL_FOR_H_
