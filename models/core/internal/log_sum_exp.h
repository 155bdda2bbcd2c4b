// Copyright 2026 The tactfunc Authors.
//
// log sum_k exp(a_k) with the largest term factored out, so that neither overflows nor
// underflows: the one implementation behind the particle filter's weights, the mixture
// density of the Metropolis proposals and the mode weights' temperature.
#ifndef TACTFUNC_MODELS_CORE_INTERNAL_LOG_SUM_EXP_H_
#define TACTFUNC_MODELS_CORE_INTERNAL_LOG_SUM_EXP_H_

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

namespace tactfunc::internal {

// -infinity for no terms or when every a_k is -infinity; +infinity or NaN when the
// largest term is.
inline double LogSumExp(const std::vector<double>& a) {
  double m = -std::numeric_limits<double>::infinity();
  for (double v : a) m = std::max(m, v);
  if (!std::isfinite(m)) return m;
  double s = 0;
  for (double v : a) s += std::exp(v - m);
  return m + std::log(s);
}

}  // namespace tactfunc::internal

#endif  // TACTFUNC_MODELS_CORE_INTERNAL_LOG_SUM_EXP_H_
