// Copyright 2026 The tactfunc Authors.
//
// Vectorised sin / cos for the SIREN's batched passes.
//
// - Double: Eigen 3.4 evaluates sin and cos one element at a time; fast_sincos.cc is
//   compiled with -ffast-math (see models/CMakeLists.txt), under which glibc declares
//   SIMD variants of sin/cos (libmvec, <= 4 ulp) and GCC vectorises the plain loops there
//   (docs/BUILD.md: about 25x faster for double). That TU includes only <cmath> so no
//   inline function built with -ffast-math can be merged into the rest of the program
//   (ODR).
// - Float (fast_sincos_float.cc), sine and cosine together (the passes that keep the
//   cosines for a reverse pass): each argument reduced once. Where the compiler targets
//   AVX-512, by pi/16 in three parts (Cody-Waite), sin and cos of k pi/16 read from a
//   table of 32 held in two registers and combined with short Taylor polynomials of the
//   remainder (|r| <= pi/32); elsewhere by pi/2, with Cephes' sinf/cosf minimax
//   polynomials and a quadrant swap. Both within two float ulps of 1 of the exact
//   values, as libmvec's sinf and cosf are, and faster than those called one after the
//   other (docs/BUILD.md).
// - Float sine alone (forward-only passes): reduced by pi in three parts, one odd
//   polynomial of degree 9 over [-pi/2, pi/2]; within 1.5e-7 (about a float ulp of 1)
//   of the exact sine, as libmvec's sinf, and faster (docs/BUILD.md).
// - Float blocks with any |scale * x| > 8192 (where the three-part reductions lose
//   bits) or a non-finite value go through libmvec instead, whole.
#ifndef TACTFUNC_MODELS_TRUNK_INTERNAL_FAST_SINCOS_H_
#define TACTFUNC_MODELS_TRUNK_INTERNAL_FAST_SINCOS_H_

namespace tactfunc {
namespace internal {

// sin_out[i] = sin(scale * x[i]) and, if cos_out is not null,
// cos_out[i] = cos(scale * x[i]), for i in [0, n). x may equal sin_out (in place);
// otherwise the three buffers must not overlap.
void ScaledSinCos(long n, float scale, const float* x, float* sin_out, float* cos_out);
void ScaledSinCos(long n, double scale, const double* x, double* sin_out,
                  double* cos_out);

// The libmvec loops of fast_sincos.cc, which ScaledSinCos(float) uses for blocks
// outside the polynomials' range. Same contract as ScaledSinCos.
void LibmvecScaledSinCos(long n, float scale, const float* x, float* sin_out,
                         float* cos_out);

}  // namespace internal
}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_TRUNK_INTERNAL_FAST_SINCOS_H_
