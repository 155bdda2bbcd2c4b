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

#if defined(__AVX512F__)
#include <immintrin.h>
#endif

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

#if defined(__AVX512F__)
// Sine and cosine together from a table of 32 (a register pair, read with one permute):
// y = k pi/16 + r, |r| <= pi/32, and
//   sin y = sin(k pi/16) cos r + cos(k pi/16) sin r,
//   cos y = cos(k pi/16) cos r - sin(k pi/16) sin r,
// with sin r = r - r^3/6 + r^5/120 and cos r = 1 - r^2/2 + r^4/24 (the next terms are
// below 2e-11 and 2e-9 at |r| = pi/32). About 17 vector operations per 16 values
// against about 25 for SinCosOf's two polynomials and quadrant swap.
// sin(k pi/16), k = 0..8 (the rest by symmetry), as floats.
constexpr float kSinSixteenth[9] = {
    0.0f,  0.19509032201612825f, 0.3826834323650898f, 0.5555702330196022f, 0.7071067811865475f,
    0.8314696123025452f, 0.9238795325112867f, 0.9807852804032304f, 1.0f};
constexpr float kSixteenOverPi = 5.09295797f;
// pi/16 = kPi16A + kPi16B + kPi16C; the products k * part are exact inside the fused
// multiply-adds whatever their bits, and the first two parts are short (12 bits) anyway.
constexpr float kPi16A = 0x1.922p-3f;
constexpr float kPi16B = -0x1.2aep-21f;
constexpr float kPi16C = -0x1.de974p-34f;

struct SixteenthTables {
  alignas(64) float sine[32];
  alignas(64) float cosine[32];
  SixteenthTables() {
    for (int k = 0; k < 32; ++k) {
      const int q = k % 16;  // sin(k pi/16) = +-sin(q pi/16), q folded into [0, 8]
      const float s = kSinSixteenth[q <= 8 ? q : 16 - q];
      sine[k] = k < 16 ? s : -s;
    }
    for (int k = 0; k < 32; ++k) cosine[k] = sine[(k + 8) % 32];  // cos a = sin(a + pi/2)
  }
};

void TableSinCos(long n, float scale, const float* x, float* sin_out, float* cos_out) {
  static const SixteenthTables tables;
  const __m512 s_lo = _mm512_load_ps(tables.sine), s_hi = _mm512_load_ps(tables.sine + 16);
  const __m512 c_lo = _mm512_load_ps(tables.cosine);
  const __m512 c_hi = _mm512_load_ps(tables.cosine + 16);
  const __m512 vscale = _mm512_set1_ps(scale);
  const __m512 sixteen_over_pi = _mm512_set1_ps(kSixteenOverPi);
  const __m512 round_shift = _mm512_set1_ps(kRoundShift);
  const __m512 a = _mm512_set1_ps(kPi16A), b = _mm512_set1_ps(kPi16B);
  const __m512 c = _mm512_set1_ps(kPi16C);
  const __m512 s3 = _mm512_set1_ps(-1.0f / 6), s5 = _mm512_set1_ps(1.0f / 120);
  const __m512 c2 = _mm512_set1_ps(-0.5f), c4 = _mm512_set1_ps(1.0f / 24);
  const __m512 one = _mm512_set1_ps(1.0f);
  // One vector of 16 at x + i; `mask` selects the values of the last, shorter one. (x
  // may be sin_out: each vector is read before it is written.)
  auto vector = [&](long i, __mmask16 mask, bool full) {
    const __m512 in = full ? _mm512_loadu_ps(x + i) : _mm512_maskz_loadu_ps(mask, x + i);
    const __m512 y = _mm512_mul_ps(vscale, in);
    const __m512 shifted = _mm512_fmadd_ps(y, sixteen_over_pi, round_shift);
    const __m512 k = _mm512_sub_ps(shifted, round_shift);
    const __m512 r = _mm512_fnmadd_ps(k, c, _mm512_fnmadd_ps(k, b, _mm512_fnmadd_ps(k, a, y)));
    const __m512 z = _mm512_mul_ps(r, r);
    const __m512 sin_r = _mm512_fmadd_ps(_mm512_mul_ps(r, z), _mm512_fmadd_ps(z, s5, s3), r);
    const __m512 cos_r = _mm512_fmadd_ps(z, _mm512_fmadd_ps(z, c4, c2), one);
    // The permutes read the low 5 bits of each index: k mod 32, from shifted's mantissa.
    const __m512i index = _mm512_castps_si512(shifted);
    const __m512 sin_k = _mm512_permutex2var_ps(s_lo, index, s_hi);
    const __m512 cos_k = _mm512_permutex2var_ps(c_lo, index, c_hi);
    const __m512 sine = _mm512_fmadd_ps(sin_k, cos_r, _mm512_mul_ps(cos_k, sin_r));
    const __m512 cosine = _mm512_fmsub_ps(cos_k, cos_r, _mm512_mul_ps(sin_k, sin_r));
    if (full) {  // masked stores are slow on some CPUs (AMD Zen 4): only the last is
      _mm512_storeu_ps(sin_out + i, sine);
      _mm512_storeu_ps(cos_out + i, cosine);
    } else {
      _mm512_mask_storeu_ps(sin_out + i, mask, sine);
      _mm512_mask_storeu_ps(cos_out + i, mask, cosine);
    }
  };
  long i = 0;
  for (; i + 16 <= n; i += 16) vector(i, 0xffff, true);
  if (i < n) vector(i, static_cast<__mmask16>((1u << (n - i)) - 1), false);
}
#else
// Without AVX-512: sine and cosine from one reduction by pi/2 and two polynomials.
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
#endif  // defined(__AVX512F__)

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
#if defined(__AVX512F__)
  TableSinCos(n, scale, x, sin_out, cos_out);
#else
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
#endif
}

}  // namespace internal
}  // namespace tactfunc
