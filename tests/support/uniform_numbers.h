// Copyright 2026 The tactfunc Authors.
//
// Deterministic pseudo-random numbers for tests (Eigen's Random uses rand(), whose
// sequence the C library decides): one linear congruential stream per seed.
#ifndef TACTFUNC_TESTS_SUPPORT_UNIFORM_NUMBERS_H_
#define TACTFUNC_TESTS_SUPPORT_UNIFORM_NUMBERS_H_

#include <Eigen/Core>

namespace tactfunc::testing_util {

// rows x cols numbers in [-1, 1), the same for the same seed on every platform.
inline Eigen::MatrixXd Uniform(int rows, int cols, unsigned seed) {
  Eigen::MatrixXd m(rows, cols);
  unsigned state = seed * 2654435761u + 12345u;
  for (int i = 0; i < m.size(); ++i) {
    state = state * 1664525u + 1013904223u;
    m.data()[i] = 2.0 * (state >> 8) / double(1u << 24) - 1.0;
  }
  return m;
}

}  // namespace tactfunc::testing_util

#endif  // TACTFUNC_TESTS_SUPPORT_UNIFORM_NUMBERS_H_
