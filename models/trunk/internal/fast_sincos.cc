// Copyright 2026 The tactfunc Authors.
//
// Compiled with -ffast-math (models/CMakeLists.txt). Keep sin and cos in separate
// loops: GCC 12 stops vectorising a loop that calls both (docs/BUILD.md). The float
// ScaledSinCos is in fast_sincos_float.cc, compiled without -ffast-math.
#include "models/trunk/internal/fast_sincos.h"

#include <cmath>

namespace tactfunc {
namespace internal {
namespace {

template <typename Scalar>
void ScaledSinCosImpl(long n, Scalar scale, const Scalar* x, Scalar* sin_out,
                      Scalar* cos_out) {
  if (cos_out != nullptr) {
    const Scalar* __restrict in = x;
    Scalar* __restrict out = cos_out;
    for (long i = 0; i < n; ++i) out[i] = std::cos(scale * in[i]);
  }
  if (x == sin_out) {
    Scalar* __restrict inout = sin_out;
    for (long i = 0; i < n; ++i) inout[i] = std::sin(scale * inout[i]);
  } else {
    const Scalar* __restrict in = x;
    Scalar* __restrict out = sin_out;
    for (long i = 0; i < n; ++i) out[i] = std::sin(scale * in[i]);
  }
}

}  // namespace

void LibmvecScaledSinCos(long n, float scale, const float* x, float* sin_out,
                         float* cos_out) {
  ScaledSinCosImpl(n, scale, x, sin_out, cos_out);
}

void ScaledSinCos(long n, double scale, const double* x, double* sin_out,
                  double* cos_out) {
  ScaledSinCosImpl(n, scale, x, sin_out, cos_out);
}

}  // namespace internal
}  // namespace tactfunc
