// Copyright 2026 The tactfunc Authors.
#include "models/trunk/internal/small_gemm.h"

#include <algorithm>
#include <array>
#include <utility>
#include <vector>

#if defined(__AVX512F__) || (defined(__AVX2__) && defined(__FMA__))
#include <immintrin.h>

#include "models/trunk/internal/small_gemm_tile.h"
#endif

namespace tactfunc {
namespace internal {

#if defined(__AVX512F__) || (defined(__AVX2__) && defined(__FMA__))
namespace {

// A (rows x depth at a[i * a_row_stride + k * a_col_stride]) as the tiles read it:
// column-major, its columns contiguous. A already so is returned as it is (*lda its
// column stride); a transposed (or strided) A is copied once, so that the tiles read its
// columns contiguously, into one buffer per thread, grown and kept.
const float* ColumnMajor(long rows, long depth, const float* a, long a_row_stride,
                         long a_col_stride, long* lda) {
  *lda = a_col_stride;
  if (a_row_stride == 1) return a;
  thread_local std::vector<float> packed;
  packed.resize(static_cast<size_t>(rows) * static_cast<size_t>(std::max<long>(depth, 1)));
  // In 16 x 16 tiles: a row-by-row copy of a transposed 256 x 256 matrix, each read or
  // each write a stride apart, cost a third of the product's time.
  constexpr long kSide = 16;
  for (long i0 = 0; i0 < rows; i0 += kSide) {
    const long i1 = std::min(rows, i0 + kSide);
    for (long k0 = 0; k0 < depth; k0 += kSide) {
      const long k1 = std::min(depth, k0 + kSide);
      for (long i = i0; i < i1; ++i) {
        for (long k = k0; k < k1; ++k) {
          packed[k * rows + i] = a[i * a_row_stride + k * a_col_stride];
        }
      }
    }
  }
  *lda = rows;
  return packed.data();
}

}  // namespace
#endif

#if defined(__AVX512F__)
namespace {

using small_gemm_tile::kTileColumns;

// One tile: C's rows [0, 16 RZ) (the last register masked by `last`) x NC columns,
// A column-major with leading dimension lda; B's value (k, j) at b[k + j * ldb]
// (kBRows false: B column-major) or b[k * ldb + j] (kBRows true: B row-major, a
// transposed block of activations), each layout its own instantiation so that the
// broadcasts walk NC pointers by a fixed step. The register loops are unrolled by
// pragma: without it GCC 12 kept the accumulators in memory, at 72 GFLOP/s against
// 190-200 (docs/BUILD.md).
// The sums start from C (accumulate), from `offset` (not null: the same rows in every
// column) or from 0.
template <int RZ, int NC, bool kBRows>
void Tile(long depth, const float* a, long lda, const float* b, long ldb, float* c, long ldc,
          __mmask16 last, bool accumulate, const float* offset) {
  __m512 acc[RZ][NC];
  small_gemm_tile::StartSums<RZ, NC>(acc, c, ldc, last, accumulate, offset);
  const float* b_column[NC];
#pragma GCC unroll 8
  for (int j = 0; j < NC; ++j) b_column[j] = kBRows ? b + j : b + j * ldb;
  const long b_step = kBRows ? ldb : 1;
  for (long k = 0; k < depth; ++k) {
    __m512 column[RZ];
#pragma GCC unroll 8
    for (int i = 0; i < RZ; ++i) {
      column[i] =
          i < RZ - 1 ? _mm512_loadu_ps(a + 16 * i) : _mm512_maskz_loadu_ps(last, a + 16 * i);
    }
    a += lda;
#pragma GCC unroll 8
    for (int j = 0; j < NC; ++j) {
      const __m512 value = _mm512_set1_ps(*b_column[j]);
      b_column[j] += b_step;
#pragma GCC unroll 8
      for (int i = 0; i < RZ; ++i) acc[i][j] = _mm512_fmadd_ps(column[i], value, acc[i][j]);
    }
  }
  small_gemm_tile::StoreSums<RZ, NC>(acc, c, ldc, last);
}

using TileFunction = void (*)(long, const float*, long, const float*, long, float*, long, __mmask16,
                              bool, const float*);
using TileTable = std::array<std::array<TileFunction, kTileColumns>, 4>;

template <bool kBRows, int RZ, int... NC>
constexpr std::array<TileFunction, kTileColumns> TileRow(std::integer_sequence<int, NC...>) {
  return {&Tile<RZ, NC + 1, kBRows>...};
}
template <bool kBRows>
constexpr TileTable Tiles() {
  constexpr auto columns = std::make_integer_sequence<int, kTileColumns>();
  return {TileRow<kBRows, 1>(columns), TileRow<kBRows, 2>(columns), TileRow<kBRows, 3>(columns),
          TileRow<kBRows, 4>(columns)};
}
// [B row-major][RZ - 1][NC - 1].
constexpr TileTable kTiles[2] = {Tiles<false>(), Tiles<true>()};

// C = A B (+ row_offset) or C += A B by tiles, A column-major (lda), B column-major or,
// with b_rows, row-major (ldb its stride): SmallGemm's work once the operands are checked.
void RunTiles(long rows, long depth, long cols, const float* a, long lda, const float* b,
              bool b_rows, long ldb, float* c, long c_col_stride, bool accumulate,
              const float* row_offset) {
  const TileTable& tiles = kTiles[b_rows ? 1 : 0];
  small_gemm_tile::ForEachTile(
      rows, cols, [&](long r0, int registers, __mmask16 last, long j0, int width) {
        const float* b_tile = b_rows ? b + j0 : b + j0 * ldb;
        tiles[registers - 1][width - 1](depth, a + r0, lda, b_tile, ldb,
                                        c + r0 + j0 * c_col_stride, c_col_stride, last,
                                        accumulate,
                                        row_offset == nullptr ? nullptr : row_offset + r0);
      });
}

}  // namespace

#elif defined(__AVX2__) && defined(__FMA__)
namespace {

// The AVX2 kernel: the AVX-512 one's scheme in 16 registers of 8 floats. A tile of
// kRegisters x 8 rows x up to kColumns columns keeps its kRegisters x kColumns sums in
// registers, beside kRegisters columns of A and a broadcast. Its Tile is its own, not one
// template over both instruction sets: the AVX-512 tile's start and end
// (small_gemm_tile.h) are shared with the bfloat16 kernel, which every x86-64 build
// compiles for AVX-512 by function attribute, and a template over a class of intrinsics
// cannot carry that attribute where the build itself targets AVX2 only.
constexpr int kLanes = 8;
constexpr int kRegisters = 2;
constexpr int kColumns = 6;

// Lanes [0, tail) set: the rows the last register of a tile holds.
__m256i TailMask(int tail) {
  return _mm256_cmpgt_epi32(_mm256_set1_epi32(tail), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
}

// One tile, as the AVX-512 Tile: C's rows [0, 8 (RZ - 1) + tail) x NC columns, the last
// register's lanes [tail, 8) masked when kMasked (tail 8 otherwise, every lane loaded as
// it is); the register loops unrolled by pragma for the same reason.
template <int RZ, int NC, bool kBRows, bool kMasked>
void Tile(long depth, const float* a, long lda, const float* b, long ldb, float* c, long ldc,
          int tail, bool accumulate, const float* offset) {
  const __m256i last = TailMask(tail);
  const auto load = [last](int i, const float* p) {
    return kMasked && i == RZ - 1 ? _mm256_maskload_ps(p, last) : _mm256_loadu_ps(p);
  };
  __m256 acc[RZ][NC];
#pragma GCC unroll 8
  for (int j = 0; j < NC; ++j) {
    const float* start = accumulate ? c + j * ldc : offset;
#pragma GCC unroll 8
    for (int i = 0; i < RZ; ++i) {
      acc[i][j] = start == nullptr ? _mm256_setzero_ps() : load(i, start + kLanes * i);
    }
  }
  const float* b_column[NC];
#pragma GCC unroll 8
  for (int j = 0; j < NC; ++j) b_column[j] = kBRows ? b + j : b + j * ldb;
  const long b_step = kBRows ? ldb : 1;
  for (long k = 0; k < depth; ++k) {
    __m256 column[RZ];
#pragma GCC unroll 8
    for (int i = 0; i < RZ; ++i) column[i] = load(i, a + kLanes * i);
    a += lda;
#pragma GCC unroll 8
    for (int j = 0; j < NC; ++j) {
      const __m256 value = _mm256_broadcast_ss(b_column[j]);
      b_column[j] += b_step;
#pragma GCC unroll 8
      for (int i = 0; i < RZ; ++i) acc[i][j] = _mm256_fmadd_ps(column[i], value, acc[i][j]);
    }
  }
#pragma GCC unroll 8
  for (int j = 0; j < NC; ++j) {
#pragma GCC unroll 8
    for (int i = 0; i < RZ; ++i) {
      float* out = c + j * ldc + kLanes * i;
      if (kMasked && i == RZ - 1) {
        _mm256_maskstore_ps(out, last, acc[i][j]);
      } else {
        _mm256_storeu_ps(out, acc[i][j]);
      }
    }
  }
}

using TileFunction = void (*)(long, const float*, long, const float*, long, float*, long, int,
                              bool, const float*);
using TileTable = std::array<std::array<TileFunction, kColumns>, kRegisters>;

template <bool kBRows, bool kMasked, int RZ, int... NC>
constexpr std::array<TileFunction, kColumns> TileRow(std::integer_sequence<int, NC...>) {
  return {&Tile<RZ, NC + 1, kBRows, kMasked>...};
}
template <bool kBRows, bool kMasked, int... RZ>
constexpr TileTable Tiles(std::integer_sequence<int, RZ...>) {
  return {TileRow<kBRows, kMasked, RZ + 1>(std::make_integer_sequence<int, kColumns>())...};
}
// [B row-major][last register masked][RZ - 1][NC - 1].
constexpr auto kRegisterCounts = std::make_integer_sequence<int, kRegisters>();
constexpr TileTable kTiles[2][2] = {
    {Tiles<false, false>(kRegisterCounts), Tiles<false, true>(kRegisterCounts)},
    {Tiles<true, false>(kRegisterCounts), Tiles<true, true>(kRegisterCounts)}};

// As the AVX-512 RunTiles.
void RunTiles(long rows, long depth, long cols, const float* a, long lda, const float* b,
              bool b_rows, long ldb, float* c, long c_col_stride, bool accumulate,
              const float* row_offset) {
  small_gemm_tile::ForEachTileOf<kLanes, kRegisters, kColumns>(
      rows, cols, [&](long r0, int registers, int tail, long j0, int width) {
        const float* b_tile = b_rows ? b + j0 : b + j0 * ldb;
        const bool masked = tail != kLanes;
        kTiles[b_rows ? 1 : 0][masked ? 1 : 0][registers - 1][width - 1](
            depth, a + r0, lda, b_tile, ldb, c + r0 + j0 * c_col_stride, c_col_stride,
            tail, accumulate, row_offset == nullptr ? nullptr : row_offset + r0);
      });
}

}  // namespace
#endif

#if defined(__AVX512F__) || (defined(__AVX2__) && defined(__FMA__))
bool HaveSmallGemm() { return true; }

bool SmallGemm(long rows, long depth, long cols, const float* a, long a_row_stride,
               long a_col_stride, const float* b, long b_row_stride, long b_col_stride, float* c,
               long c_col_stride, bool accumulate, const float* row_offset) {
  if (b_row_stride != 1 && b_col_stride != 1) return false;  // neither layout: Eigen's
  if (rows <= 0 || cols <= 0) return true;
  if (accumulate) row_offset = nullptr;
  long lda = 0;
  a = ColumnMajor(rows, depth, a, a_row_stride, a_col_stride, &lda);
  // B column-major (b_row_stride 1) or row-major (b_col_stride 1), read as it is.
  const bool b_rows = b_row_stride != 1;
  const long ldb = b_rows ? b_row_stride : b_col_stride;
  RunTiles(rows, depth, cols, a, lda, b, b_rows, ldb, c, c_col_stride, accumulate, row_offset);
  return true;
}

#else  // neither AVX-512 nor AVX2 with FMA: the callers use Eigen's product

bool HaveSmallGemm() { return false; }

bool SmallGemm(long, long, long, const float*, long, long, const float*, long, long, float*, long,
               bool, const float*) {
  return false;
}

#endif

}  // namespace internal
}  // namespace tactfunc
