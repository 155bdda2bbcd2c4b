// Copyright 2026 The tactfunc Authors.
//
// What the gradient checks of the trunk's suites share: a 4th-order central difference
// and a max-norm comparison of two vectors relative to the expected one's largest entry.
#ifndef TACTFUNC_TESTS_SUPPORT_DERIVATIVE_CHECKS_H_
#define TACTFUNC_TESTS_SUPPORT_DERIVATIVE_CHECKS_H_

#include <functional>
#include <string>

#include <Eigen/Core>

#include "gtest/gtest.h"

namespace tactfunc::testing_util {

// 4th-order central difference of f at 0 with step h.
inline double Derivative(const std::function<double(double)>& f, double h) {
  return (-f(2 * h) + 8 * f(h) - 8 * f(-h) + f(-2 * h)) / (12 * h);
}

// max |actual - expected| <= rel * max |expected| + floor, reported with `what`.
inline void ExpectClose(const Eigen::VectorXd& actual, const Eigen::VectorXd& expected,
                        double rel, double floor, const std::string& what) {
  ASSERT_EQ(actual.size(), expected.size()) << what;
  const double error = (actual - expected).cwiseAbs().maxCoeff();
  const double scale = expected.cwiseAbs().maxCoeff();
  EXPECT_LE(error, rel * scale + floor)
      << what << ": max error " << error << ", max |expected| " << scale;
}

}  // namespace tactfunc::testing_util

#endif  // TACTFUNC_TESTS_SUPPORT_DERIVATIVE_CHECKS_H_
