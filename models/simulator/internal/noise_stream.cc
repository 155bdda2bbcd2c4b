// Copyright 2026 The tactfunc Authors.
#include "models/simulator/internal/noise_stream.h"

#include <cmath>
#include <vector>

#include <boost/math/special_functions/erf.hpp>

namespace tactfunc::internal {

const float* StandardNormalQuantiles() {
  static const std::vector<float> table = [] {
    std::vector<float> t(65536);
    for (int i = 0; i < 65536; ++i) {
      const double p = (i + 0.5) / 65536.0;
      t[i] = static_cast<float>(std::sqrt(2.0) * boost::math::erf_inv(2.0 * p - 1.0));
    }
    return t;
  }();
  return table.data();
}

}  // namespace tactfunc::internal
