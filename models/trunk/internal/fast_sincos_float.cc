// Copyright 2026 The tactfunc Authors.
//
// Float sine and cosine from one argument reduction, and the sine alone from one
// reduction by pi (fast_sincos.h). Compiled WITHOUT -ffast-math: the reductions'
// rounding trick (adding and subtracting 1.5 * 2^23) and their three-part subtractions
// must not be reassociated. The loops are written without branches (selects as bit
// masks) so that GCC vectorises them.
#include <cmath>
#include <cstdint>
#include <cstring>

#include "models/trunk/internal/fast_sincos.h"

namespace tactfunc {
namespace internal {
namespace {

// Beyond this |argument| the three-part reduction below loses bits (Cephes' bound).
constexpr float kLargestReduced = 8192.0f;
constexpr float kTwoOverPi = 0.636619772367581343f;
// pi/2 = kPio2A + kPio2B + kPio2C, kPio2A and kPio2B with few significant bits, so
// that k * kPio2A is exact for the |k| < 2^13 of arguments within kLargestReduced
// (Cephes' DP1..DP3, doubled).
constexpr float kPio2A = 1.5703125f;
constexpr float kPio2B = 4.837512969970703125e-4f;
constexpr float kPio2C = 7.54978995489188216e-8f;
// pi = 2 (kPio2A + kPio2B + kPio2C): doubling keeps each part's few significant bits,
// and |k| < 2^12 for the sine alone's k = round(y / pi) within kLargestReduced.
constexpr float kOneOverPi = 0.318309886183790671f;
constexpr float kPiA = 2 * kPio2A;
constexpr float kPiB = 2 * kPio2B;
constexpr float kPiC = 2 * kPio2C;
// Adding 1.5 * 2^23 rounds a float of magnitude < 2^22 to an integer, which then sits in
// the low bits of the sum's mantissa.
constexpr float kRoundShift = 12582912.0f;

inline std::uint32_t Bits(float f) {
  std::uint32_t b;
  std::memcpy(&b, &f, sizeof b);
  return b;
}

inline float FromBits(std::uint32_t b) {
  float f;
  std::memcpy(&f, &b, sizeof f);
  return f;
}

// y = k pi/2 + r, |r| <= pi/4; the low two bits of *quadrant are k mod 4.
inline float Reduce(float y, std::uint32_t* quadrant) {
  const float shifted = y * kTwoOverPi + kRoundShift;
  const float k = shifted - kRoundShift;
  *quadrant = Bits(shifted);
  // Plain products and differences, not std::fma: without FMA instructions (a portable
  // build) std::fma is a library call; where they exist the compiler contracts these.
  return ((y - k * kPio2A) - k * kPio2B) - k * kPio2C;
}

// sin and cos of r in [-pi/4, pi/4], z = r^2 (Cephes' minimax coefficients).
inline float SinOfReduced(float r, float z) {
  return ((-1.9515295891e-4f * z + 8.3321608736e-3f) * z - 1.6666654611e-1f) * z * r + r;
}
inline float CosOfReduced(float z) {
  return ((2.443315711809948e-5f * z - 1.388731625493765e-3f) * z + 4.166664568298827e-2f) *
             z * z -
         0.5f * z + 1.0f;
}

// (sin, cos) of k pi/2 + r from (sin r, cos r): swapped for odd k, then sin negated for
// k mod 4 in {2, 3} and cos for k mod 4 in {1, 2}.
inline void Rotate(std::uint32_t quadrant, float s, float c, float* sin_out, float* cos_out) {
  const std::uint32_t odd = 0u - (quadrant & 1u);
  const std::uint32_t sb = Bits(s), cb = Bits(c);
  *sin_out = FromBits(((cb & odd) | (sb & ~odd)) ^ ((quadrant & 2u) << 30));
  *cos_out = FromBits(((sb & odd) | (cb & ~odd)) ^ (((quadrant + 1u) & 2u) << 30));
}

inline void SinCosOf(float y, float* sin_out, float* cos_out) {
  std::uint32_t quadrant;
  const float r = Reduce(y, &quadrant);
  const float z = r * r;
  Rotate(quadrant, SinOfReduced(r, z), CosOfReduced(z), sin_out, cos_out);
}

// sin y alone: y = k pi + r, |r| <= pi/2, sin y = (-1)^k sin r, with one odd polynomial
// of degree 9 over [-pi/2, pi/2] (minimax in relative error, 6e-9;
// scripts/fit_sine_polynomial.py). One polynomial instead of SinCosOf's two and its
// swap; within 1.5e-7 of the exact sine, about one float ulp of 1 (FastSin's test).
inline float SinOf(float y) {
  const float shifted = y * kOneOverPi + kRoundShift;
  const float k = shifted - kRoundShift;
  const std::uint32_t sign = (Bits(shifted) & 1u) << 31;  // k odd: negate
  const float r = ((y - k * kPiA) - k * kPiB) - k * kPiC;
  const float z = r * r;
  const float p = ((2.6057932700496167e-6f * z - 1.9809608056675643e-4f) * z +
                   8.33306647837162e-3f) * z - 1.6666659712791443e-1f;
  return FromBits(Bits(p * z * r + r) ^ sign);
}

// True if every |scale * x[i]| <= kLargestReduced (false for NaN).
bool InRange(long n, float scale, const float* x) {
  unsigned outside = 0;
  for (long i = 0; i < n; ++i) outside |= !(std::fabs(scale * x[i]) <= kLargestReduced);
  return outside == 0;
}

}  // namespace

void ScaledSinCos(long n, float scale, const float* x, float* sin_out, float* cos_out) {
  if (!InRange(n, scale, x)) {
    LibmvecScaledSinCos(n, scale, x, sin_out, cos_out);
    return;
  }
  if (cos_out == nullptr) {
    if (x == sin_out) {
      float* __restrict inout = sin_out;
      for (long i = 0; i < n; ++i) inout[i] = SinOf(scale * inout[i]);
    } else {
      const float* __restrict in = x;
      float* __restrict sine = sin_out;
      for (long i = 0; i < n; ++i) sine[i] = SinOf(scale * in[i]);
    }
    return;
  }
  if (x == sin_out) {
    float* __restrict inout = sin_out;
    float* __restrict cosine = cos_out;
    for (long i = 0; i < n; ++i) SinCosOf(scale * inout[i], &inout[i], &cosine[i]);
  } else {
    const float* __restrict in = x;
    float* __restrict sine = sin_out;
    float* __restrict cosine = cos_out;
    for (long i = 0; i < n; ++i) SinCosOf(scale * in[i], &sine[i], &cosine[i]);
  }
}

}  // namespace internal
}  // namespace tactfunc
