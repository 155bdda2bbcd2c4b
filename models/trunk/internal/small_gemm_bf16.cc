// Copyright 2026 The tactfunc Authors.
//
// SmallGemm's bfloat16 kernel: the same products with A and B rounded to bfloat16 (8
// significant bits) and the sums kept in float. AVX512_BF16's VDPBF16PS multiplies 32
// pairs of bfloat16 and adds each pair's two products to one of 16 float sums, twice the
// multiply-adds per instruction of a float FMA: the passes' products run 1.6-1.8x the
// float kernel's rate on an AMD EPYC, packing included (`tactfunc bench kernels`;
// docs/BENCHMARKS.md, "bfloat16 products"). The operands are packed into bfloat16 pairs
// along the inner dimension: B (a block's activations or gradients) per call, A per
// call too unless the caller packed it once (PackBfloat16Pairs: a trunk's weights).
//
// Compiled for AVX512_BF16 by function attribute, whatever the build's -march, and
// chosen at run time only where the CPU has it (ProductPrecisionAvailable).
#include <algorithm>
#include <array>
#include <cstdint>
#include <utility>
#include <vector>

#include "models/trunk/internal/small_gemm.h"

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>

#include "models/trunk/internal/small_gemm_tile.h"
#define TACTFUNC_BF16_KERNEL 1
#define TACTFUNC_BF16_TARGET __attribute__((target("avx512f,avx512bw,avx512vl,avx512bf16")))
#endif

namespace tactfunc {
namespace internal {

#if defined(TACTFUNC_BF16_KERNEL)
namespace {

using small_gemm_tile::kTileColumns;

// Rounds 16 floats of x and 16 of y to bfloat16 (nearest, ties to even, as the hardware
// rounds) and interleaves them: 32-bit lane i holds x[i] in its low half and y[i] in its
// high half, the pair VDPBF16PS multiplies in lane i.
TACTFUNC_BF16_TARGET inline __m512i Interleave(__m512 x, __m512 y) {
  // cvtne2ps(y, x): x's 16 values in the low 256 bits, y's in the high.
  const __m512i both = reinterpret_cast<__m512i>(_mm512_cvtne2ps_pbh(y, x));
  const __m512i index = _mm512_set_epi16(31, 15, 30, 14, 29, 13, 28, 12, 27, 11, 26, 10, 25, 9,
                                         24, 8, 23, 7, 22, 6, 21, 5, 20, 4, 19, 3, 18, 2, 17,
                                         1, 16, 0);
  return _mm512_permutexvar_epi16(index, both);
}

// Two contiguous runs of n values, x and y (null: zeros), as n_padded pairs at out (a
// multiple of 16; the pairs beyond n are zero): out[i] = (x[i], y[i]).
TACTFUNC_BF16_TARGET void InterleaveRows(const float* x, const float* y, long n, long n_padded,
                                         uint32_t* out) {
  for (long i = 0; i < n_padded; i += 16) {
    const long count = std::min<long>(16, std::max<long>(0, n - i));
    const __mmask16 m = count == 16 ? __mmask16(0xFFFF) : __mmask16((1u << count) - 1);
    const __m512 vx = _mm512_maskz_loadu_ps(m, x + i);
    const __m512 vy = y == nullptr ? _mm512_setzero_ps() : _mm512_maskz_loadu_ps(m, y + i);
    _mm512_storeu_si512(out + i, Interleave(vx, vy));
  }
}

// A (rows x depth, a[i * rs + k * cs]) as pairs: p[kp * rows_padded + i] = (A(i, 2 kp),
// A(i, 2 kp + 1)), rows padded with zeros to a multiple of 16, an odd depth's last pair
// completed with a zero.
TACTFUNC_BF16_TARGET void PackA(long rows, long depth, const float* a, long rs, long cs,
                                long rows_padded, uint32_t* p) {
  const long pairs = (depth + 1) / 2;
  if (rs == 1) {
    for (long kp = 0; kp < pairs; ++kp) {
      InterleaveRows(a + (2 * kp) * cs, 2 * kp + 1 < depth ? a + (2 * kp + 1) * cs : nullptr,
                     rows, rows_padded, p + kp * rows_padded);
    }
    return;
  }
  // Strided A (a transposed matrix): value by value, through the same rounding.
  std::fill(p, p + pairs * rows_padded, 0u);
  alignas(64) float x[16], y[16];
  for (long kp = 0; kp < pairs; ++kp) {
    for (long i = 0; i < rows; i += 16) {
      const long n = std::min<long>(16, rows - i);
      for (long r = 0; r < 16; ++r) {
        x[r] = r < n ? a[(i + r) * rs + (2 * kp) * cs] : 0.0f;
        y[r] = r < n && 2 * kp + 1 < depth ? a[(i + r) * rs + (2 * kp + 1) * cs] : 0.0f;
      }
      _mm512_storeu_si512(p + kp * rows_padded + i,
                          Interleave(_mm512_load_ps(x), _mm512_load_ps(y)));
    }
  }
}

// B (depth x cols) as pairs along k. Column-major B (b[k + j * ldb]): p[j * pairs + kp],
// each column's values already in pair order. Row-major B (b[k * ldb + j]): p[kp * cols16
// + j], cols16 = cols rounded up to 16, two rows interleaved.
TACTFUNC_BF16_TARGET void PackB(long depth, long cols, const float* b, long ldb, bool b_rows,
                                long pairs, long cols16, uint32_t* p) {
  if (!b_rows) {
    for (long j = 0; j < cols; ++j) {
      const float* column = b + j * ldb;
      for (long k = 0; k < 2 * pairs; k += 32) {
        const long n1 = std::min<long>(16, std::max<long>(0, depth - k));
        const long n2 = std::min<long>(16, std::max<long>(0, depth - k - 16));
        const __mmask16 m1 = n1 == 16 ? __mmask16(0xFFFF) : __mmask16((1u << n1) - 1);
        const __mmask16 m2 = n2 == 16 ? __mmask16(0xFFFF) : __mmask16((1u << n2) - 1);
        const __m512i both = reinterpret_cast<__m512i>(_mm512_cvtne2ps_pbh(
            _mm512_maskz_loadu_ps(m2, column + k + 16), _mm512_maskz_loadu_ps(m1, column + k)));
        // Pairs k / 2 ... of this column: 16 of them, fewer at the end.
        const long count = std::min<long>(16, pairs - k / 2);
        const __mmask16 store = count == 16 ? __mmask16(0xFFFF) : __mmask16((1u << count) - 1);
        _mm512_mask_storeu_epi32(p + j * pairs + k / 2, store, both);
      }
    }
    return;
  }
  for (long kp = 0; kp < pairs; ++kp) {
    InterleaveRows(b + (2 * kp) * ldb, 2 * kp + 1 < depth ? b + (2 * kp + 1) * ldb : nullptr,
                   cols, cols16, p + kp * cols16);
  }
}

// One tile of C, as SmallGemm's float Tile: RZ registers of 16 rows x NC columns, over
// `pairs` pairs of A's packed columns (leading dimension lda, in pairs) and B's packed
// pairs (column j's pair kp at b[j * b_col + kp * b_pair]).
template <int RZ, int NC>
TACTFUNC_BF16_TARGET void Tile(long pairs, const uint32_t* a, long lda, const uint32_t* b,
                               long b_col, long b_pair, float* c, long ldc, __mmask16 last,
                               bool accumulate, const float* offset) {
  __m512 acc[RZ][NC];
  small_gemm_tile::StartSums<RZ, NC>(acc, c, ldc, last, accumulate, offset);
  const uint32_t* b_column[NC];
#pragma GCC unroll 8
  for (int j = 0; j < NC; ++j) b_column[j] = b + j * b_col;
  for (long kp = 0; kp < pairs; ++kp) {
    __m512bh column[RZ];
#pragma GCC unroll 8
    for (int i = 0; i < RZ; ++i) {
      column[i] = reinterpret_cast<__m512bh>(_mm512_loadu_si512(a + 16 * i));
    }
    a += lda;
#pragma GCC unroll 8
    for (int j = 0; j < NC; ++j) {
      const __m512bh value =
          reinterpret_cast<__m512bh>(_mm512_set1_epi32(static_cast<int>(*b_column[j])));
      b_column[j] += b_pair;
#pragma GCC unroll 8
      for (int i = 0; i < RZ; ++i) acc[i][j] = _mm512_dpbf16_ps(acc[i][j], column[i], value);
    }
  }
  small_gemm_tile::StoreSums<RZ, NC>(acc, c, ldc, last);
}

using TileFunction = void (*)(long, const uint32_t*, long, const uint32_t*, long, long, float*,
                              long, __mmask16, bool, const float*);
using TileTable = std::array<std::array<TileFunction, kTileColumns>, 4>;

template <int RZ, int... NC>
constexpr std::array<TileFunction, kTileColumns> TileRow(std::integer_sequence<int, NC...>) {
  return {&Tile<RZ, NC + 1>...};
}
constexpr TileTable Tiles() {
  constexpr auto columns = std::make_integer_sequence<int, kTileColumns>();
  return {TileRow<1>(columns), TileRow<2>(columns), TileRow<3>(columns), TileRow<4>(columns)};
}
constexpr TileTable kTiles = Tiles();  // [RZ - 1][NC - 1]

}  // namespace

bool HaveBfloat16Gemm() {
  static const bool have = __builtin_cpu_supports("avx512f") &&
                           __builtin_cpu_supports("avx512bw") &&
                           __builtin_cpu_supports("avx512vl") &&
                           __builtin_cpu_supports("avx512bf16");
  return have;
}

bool PackBfloat16Pairs(long rows, long depth, const float* a, long a_row_stride,
                       long a_col_stride, Bfloat16Pairs* out) {
  if (!HaveBfloat16Gemm()) return false;
  out->rows = rows;
  out->depth = depth;
  out->rows_padded = (std::max<long>(rows, 0) + 15) / 16 * 16;
  out->pairs.resize(static_cast<size_t>(std::max<long>((depth + 1) / 2, 1) * out->rows_padded));
  PackA(rows, depth, a, a_row_stride, a_col_stride, out->rows_padded, out->pairs.data());
  return true;
}

bool SmallGemmBfloat16Packed(const Bfloat16Pairs& a, long cols, const float* b, long b_row_stride,
                             long b_col_stride, float* c, long c_col_stride, bool accumulate,
                             const float* row_offset) {
  if (!HaveBfloat16Gemm()) return false;
  if (b_row_stride != 1 && b_col_stride != 1) return false;
  const long rows = a.rows, depth = a.depth;
  if (rows <= 0 || cols <= 0) return true;
  if (accumulate) row_offset = nullptr;
  const long pairs = (depth + 1) / 2;
  const long cols16 = (cols + 15) / 16 * 16;
  const bool b_rows = b_row_stride != 1;
  // One buffer per thread, grown and kept.
  thread_local std::vector<uint32_t> packed_b;
  packed_b.resize(static_cast<size_t>(std::max<long>(pairs, 1) * (b_rows ? cols16 : cols)));
  PackB(depth, cols, b, b_rows ? b_row_stride : b_col_stride, b_rows, pairs, cols16,
        packed_b.data());
  const long b_col = b_rows ? 1 : pairs;
  const long b_pair = b_rows ? cols16 : 1;
  small_gemm_tile::ForEachTile(
      rows, cols, [&](long r0, int registers, __mmask16 last, long j0, int width) {
        kTiles[registers - 1][width - 1](pairs, a.pairs.data() + r0, a.rows_padded,
                                         packed_b.data() + j0 * b_col, b_col, b_pair,
                                         c + r0 + j0 * c_col_stride, c_col_stride, last,
                                         accumulate,
                                         row_offset == nullptr ? nullptr : row_offset + r0);
      });
  return true;
}

bool SmallGemmBfloat16(long rows, long depth, long cols, const float* a, long a_row_stride,
                       long a_col_stride, const float* b, long b_row_stride, long b_col_stride,
                       float* c, long c_col_stride, bool accumulate, const float* row_offset) {
  if (b_row_stride != 1 && b_col_stride != 1) return false;
  thread_local Bfloat16Pairs packed_a;  // grown and kept
  return PackBfloat16Pairs(rows, depth, a, a_row_stride, a_col_stride, &packed_a) &&
         SmallGemmBfloat16Packed(packed_a, cols, b, b_row_stride, b_col_stride, c, c_col_stride,
                                 accumulate, row_offset);
}

#else  // not x86-64 GCC/Clang: no bfloat16 kernel

bool HaveBfloat16Gemm() { return false; }

bool PackBfloat16Pairs(long, long, const float*, long, long, Bfloat16Pairs*) { return false; }

bool SmallGemmBfloat16Packed(const Bfloat16Pairs&, long, const float*, long, long, float*, long,
                             bool, const float*) {
  return false;
}

bool SmallGemmBfloat16(long, long, long, const float*, long, long, const float*, long, long,
                       float*, long, bool, const float*) {
  return false;
}

#endif

}  // namespace internal
}  // namespace tactfunc
