// Copyright 2026 The tactfunc Authors.
//
// Vectorised sin / cos for the SIREN's batched passes. Eigen 3.4 evaluates double sin
// and cos one element at a time; fast_sincos.cc is compiled with -ffast-math (see
// models/CMakeLists.txt), under which glibc declares SIMD variants of sin/cos
// (libmvec, <= 4 ulp) and GCC vectorises the plain loops below (docs/BUILD.md: about
// 25x faster for double). That TU includes only <cmath> so no inline function built
// with -ffast-math can be merged into the rest of the program (ODR).
#ifndef TACTFUNC_MODELS_TRUNK_INTERNAL_FAST_SINCOS_H_
#define TACTFUNC_MODELS_TRUNK_INTERNAL_FAST_SINCOS_H_

namespace tactfunc {
namespace internal {

// sin_out[i] = sin(scale * x[i]) and, if cos_out is not null,
// cos_out[i] = cos(scale * x[i]), for i in [0, n). x may equal sin_out (in place;
// cos is computed first); otherwise the three buffers must not overlap.
void ScaledSinCos(long n, float scale, const float* x, float* sin_out, float* cos_out);
void ScaledSinCos(long n, double scale, const double* x, double* sin_out,
                  double* cos_out);

}  // namespace internal
}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_TRUNK_INTERNAL_FAST_SINCOS_H_
