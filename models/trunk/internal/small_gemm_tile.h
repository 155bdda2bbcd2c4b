// Copyright 2026 The tactfunc Authors.
//
// What SmallGemm's float and bfloat16 kernels share (small_gemm.cc, small_gemm_bf16.cc):
// how C is cut into tiles, and how an AVX-512 tile's sums start and end. Included only
// by those two files; the AVX-512 kernels are compiled for it by -march (float) or by
// function attribute (bfloat16): these functions carry the attribute themselves, so that
// both can inline them.
#ifndef TACTFUNC_MODELS_TRUNK_INTERNAL_SMALL_GEMM_TILE_H_
#define TACTFUNC_MODELS_TRUNK_INTERNAL_SMALL_GEMM_TILE_H_

#include <immintrin.h>

#include <algorithm>

namespace tactfunc {
namespace internal {
namespace small_gemm_tile {

constexpr int kTileColumns = 6;  // 4 x 6 accumulators + 4 columns of A + a broadcast
constexpr long kStripRows = 64;  // 4 registers of 16 floats

// Calls tile(r0, registers, tail, j0, width) for every tile of a rows x cols C: strips of
// kRegisters x kLanes rows (`registers` vector registers, the last holding `tail` rows,
// 1..kLanes), and in each the columns in as few tiles of at most kColumns as possible,
// their widths differing by at most one: a block of 128 pixels as 18 tiles of 6 and 4 of
// 5, not 21 of 6 and one of 2 (whose 8 multiply-adds per 6 loads showed as 1.5 % of a
// width-256 meta-training step's profile; the step's time did not move measurably, 1355 /
// 1362 ms). Shared by the AVX-512 kernels and the AVX2 one (small_gemm.cc).
template <int kLanes, int kRegisters, int kColumns, typename Tile>
inline void ForEachTileOf(long rows, long cols, Tile&& tile) {
  constexpr long kStrip = static_cast<long>(kLanes) * kRegisters;
  for (long r0 = 0; r0 < rows; r0 += kStrip) {
    const long strip = std::min(kStrip, rows - r0);
    const int registers = static_cast<int>((strip + kLanes - 1) / kLanes);
    const int tail = static_cast<int>(strip - static_cast<long>(registers - 1) * kLanes);
    const long num_tiles = (cols + kColumns - 1) / kColumns;
    const long base = cols / num_tiles, wider = cols % num_tiles;  // `wider` tiles of base + 1
    for (long t = 0, j0 = 0; t < num_tiles; ++t) {
      const int width = static_cast<int>(base + (t < wider ? 1 : 0));
      tile(r0, registers, tail, j0, width);
      j0 += width;
    }
  }
}

// The AVX-512 kernels' tiles: strips of kStripRows rows in registers of 16 floats, the
// last masked by `last`.
template <typename Tile>
inline void ForEachTile(long rows, long cols, Tile&& tile) {
  ForEachTileOf<16, kStripRows / 16, kTileColumns>(
      rows, cols, [&](long r0, int registers, int tail, long j0, int width) {
        const __mmask16 last = __mmask16((1u << tail) - 1);  // tail in [1, 16]
        tile(r0, registers, last, j0, width);
      });
}

// A tile's sums start from C (accumulate), from `offset` (not null: the same rows in
// every column) or from 0. The register loops are unrolled by pragma: without it GCC 12
// kept the accumulators in memory, at 72 GFLOP/s against 190-200 (docs/BUILD.md).
template <int RZ, int NC>
__attribute__((target("avx512f"), always_inline)) inline void StartSums(
    __m512 (&acc)[RZ][NC], const float* c, long ldc, __mmask16 last, bool accumulate,
    const float* offset) {
#pragma GCC unroll 8
  for (int j = 0; j < NC; ++j) {
    const float* start = accumulate ? c + j * ldc : offset;
#pragma GCC unroll 8
    for (int i = 0; i < RZ; ++i) {
      acc[i][j] = start == nullptr ? _mm512_setzero_ps()
                  : i < RZ - 1     ? _mm512_loadu_ps(start + 16 * i)
                                   : _mm512_maskz_loadu_ps(last, start + 16 * i);
    }
  }
}

// Writes a tile's sums to C, the last register of each column masked by `last`.
template <int RZ, int NC>
__attribute__((target("avx512f"), always_inline)) inline void StoreSums(
    const __m512 (&acc)[RZ][NC], float* c, long ldc, __mmask16 last) {
#pragma GCC unroll 8
  for (int j = 0; j < NC; ++j) {
#pragma GCC unroll 8
    for (int i = 0; i < RZ; ++i) {
      if (i < RZ - 1) {
        _mm512_storeu_ps(c + j * ldc + 16 * i, acc[i][j]);
      } else {
        _mm512_mask_storeu_ps(c + j * ldc + 16 * i, last, acc[i][j]);
      }
    }
  }
}

}  // namespace small_gemm_tile
}  // namespace internal
}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_TRUNK_INTERNAL_SMALL_GEMM_TILE_H_
