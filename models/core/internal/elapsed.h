// Copyright 2026 The tactfunc Authors.
//
// Milliseconds of steady-clock time since `start`: the timings the fits, samplers and
// filters report in their summaries.
#ifndef TACTFUNC_MODELS_CORE_INTERNAL_ELAPSED_H_
#define TACTFUNC_MODELS_CORE_INTERNAL_ELAPSED_H_

#include <chrono>

namespace tactfunc::internal {

inline double MsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start)
      .count();
}

}  // namespace tactfunc::internal

#endif  // TACTFUNC_MODELS_CORE_INTERNAL_ELAPSED_H_
