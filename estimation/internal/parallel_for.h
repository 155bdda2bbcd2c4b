// Copyright 2026 The tactfunc Authors.
//
// ParallelFor: runs fn(i) for i in [0, count) on `threads` workers (the calling thread
// is one of them), handing out indices through an atomic counter. Callers that need
// results independent of the thread count write item i's result to slot i and reduce
// the slots in index order afterwards. The first exception thrown by any fn is
// rethrown in the caller once every worker has stopped.
#ifndef TACTFUNC_ESTIMATION_INTERNAL_PARALLEL_FOR_H_
#define TACTFUNC_ESTIMATION_INTERNAL_PARALLEL_FOR_H_

#include <algorithm>
#include <atomic>
#include <exception>
#include <mutex>
#include <thread>
#include <vector>

namespace tactfunc::internal {

template <typename Fn>
void ParallelFor(int count, int threads, const Fn& fn) {
  if (count <= 0) return;
  const int workers = std::max(1, std::min(threads, count));
  if (workers == 1) {
    for (int i = 0; i < count; ++i) fn(i);
    return;
  }
  std::atomic<int> next{0};
  std::atomic<bool> failed{false};
  std::exception_ptr error;
  std::mutex error_mutex;
  auto work = [&]() {
    for (int i = next++; i < count && !failed.load(); i = next++) {
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

#endif  // TACTFUNC_ESTIMATION_INTERNAL_PARALLEL_FOR_H_
