// Copyright 2026 The tactfunc Authors.
//
// The float matrix products of the SIREN's batched passes: C = A B or C += A B with A
// a layer's weights (width x width, or transposed) or a block's gradients (width x 256
// pixels), B a block of activations. Eigen 3.4's general product runs these shapes
// below its own large-matrix rate: its AVX-512 micro-kernel covers 48 rows x 4 columns,
// so a 64-row product leaves a 16-row strip with four accumulators (FMA-latency bound),
// and it packs the right-hand block on every call. SmallGemm's AVX-512 kernel keeps a
// tile of up to 64 rows x 6 columns of C in 24 registers, reads A's columns where they
// are (a layer's weights: contiguous) and broadcasts B's values from where they are,
// so nothing is packed unless A is transposed (then A is copied once per call, a
// width^2 copy against width^2 x 256 multiply-adds; the passes keep W^T instead). On a
// CPU with AVX2 and FMA but not AVX-512 the same scheme runs in 16 registers of 8 floats:
// 16 rows x 6 columns in 12. docs/BUILD.md, "The passes' GEMM kernel", and
// docs/BENCHMARKS.md, "Against PyTorch on the CPU", have the measurements.
//
// The sums run over the inner dimension in order, one rounding per multiply-add, so a
// product's values can differ from Eigen's by float rounding (a few ulps); they are the
// same on every run and thread count.
#ifndef TACTFUNC_MODELS_TRUNK_INTERNAL_SMALL_GEMM_H_
#define TACTFUNC_MODELS_TRUNK_INTERNAL_SMALL_GEMM_H_

#include <cstdint>
#include <type_traits>
#include <vector>

#include "Eigen/Core"
#include "models/trunk/product_precision.h"

namespace tactfunc {
namespace internal {

// C (rows x cols, column j at c + j * c_col_stride) = A B, or += A B if accumulate, with
// A (rows x depth) at a[i * a_row_stride + k * a_col_stride] and B (depth x cols) at
// b[k * b_row_stride + j * b_col_stride]; without accumulate and with row_offset not null,
// C = A B + row_offset 1^T (row_offset: rows values, added to every column as the sums'
// start). C must not overlap A, B or row_offset. Returns false and leaves C untouched
// when this build has no kernel (compiled for neither AVX-512 nor AVX2 with FMA) or B
// is neither column- nor row-major (neither stride 1); the caller then computes the
// product itself.
bool SmallGemm(long rows, long depth, long cols, const float* a, long a_row_stride,
               long a_col_stride, const float* b, long b_row_stride, long b_col_stride, float* c,
               long c_col_stride, bool accumulate, const float* row_offset = nullptr);

// True when SmallGemm has a kernel in this build.
bool HaveSmallGemm();

// SmallGemm with A and B rounded to bfloat16 and the sums in float
// (small_gemm_bf16.cc): the same arguments and contract; false where the CPU lacks
// AVX512_BF16 (HaveBfloat16Gemm) or B has neither layout.
bool SmallGemmBfloat16(long rows, long depth, long cols, const float* a, long a_row_stride,
                       long a_col_stride, const float* b, long b_row_stride, long b_col_stride,
                       float* c, long c_col_stride, bool accumulate,
                       const float* row_offset = nullptr);

// True when this CPU runs SmallGemmBfloat16's kernel.
bool HaveBfloat16Gemm();

// A left-hand side rounded to bfloat16 and packed as SmallGemmBfloat16 reads it, made
// once for many products (a layer's weights, for every block of pixels of a pass):
// rows x depth as pairs along the inner dimension, rows padded to a multiple of 16.
struct Bfloat16Pairs {
  long rows = 0, depth = 0, rows_padded = 0;
  std::vector<std::uint32_t> pairs;
};
// Packs A (rows x depth at a[i * a_row_stride + k * a_col_stride]) into *out; false
// (out untouched) where the CPU lacks AVX512_BF16.
bool PackBfloat16Pairs(long rows, long depth, const float* a, long a_row_stride,
                       long a_col_stride, Bfloat16Pairs* out);
// SmallGemmBfloat16 with A packed: the same bits as SmallGemmBfloat16 on the A packed.
bool SmallGemmBfloat16Packed(const Bfloat16Pairs& a, long cols, const float* b, long b_row_stride,
                             long b_col_stride, float* c, long c_col_stride, bool accumulate,
                             const float* row_offset = nullptr);

// Under ProductPrecision::kBfloat16, products with fewer inner terms or columns than this
// stay float: they gain nothing from pairs of terms, and they are the products whose
// operands are pixel coordinates (a first layer's, depth 2, and its weight gradient, 2
// columns), which bfloat16 would move by up to 2^-9 of their value (near the edge,
// 0.002 in (-1, 1): a twelfth of a pixel across 88 columns), and the output layer's few
// channels.
inline constexpr long kMinBfloat16Extent = 16;

namespace small_gemm_internal {
// SmallGemm on Eigen operands where the types allow it (float, direct access, c
// column-major, row_offset contiguous), in the process's product precision, reading A
// from a_pairs (not null: A packed) under bfloat16; false where the caller must use Eigen.
template <typename Lhs, typename Rhs, typename Dst>
bool Kernel(const Eigen::MatrixBase<Lhs>& a, const Eigen::MatrixBase<Rhs>& b, Dst& c,
            bool accumulate, const float* row_offset, const Bfloat16Pairs* a_pairs) {
  using D = std::decay_t<Dst>;
  constexpr bool kDirect =
      bool(Lhs::Flags & Eigen::DirectAccessBit) && bool(Rhs::Flags & Eigen::DirectAccessBit) &&
      bool(D::Flags & Eigen::DirectAccessBit) && bool(D::Flags & Eigen::LvalueBit);
  if constexpr (kDirect && std::is_same_v<typename D::Scalar, float> &&
                std::is_same_v<typename Lhs::Scalar, float> &&
                std::is_same_v<typename Rhs::Scalar, float>) {
    eigen_assert(c.rows() == a.rows() && c.cols() == b.cols() && a.cols() == b.rows());
    if (c.rowStride() != 1) return false;
    const bool bf16 = GetProductPrecision() == ProductPrecision::kBfloat16 &&
                      a.cols() >= kMinBfloat16Extent && b.cols() >= kMinBfloat16Extent;
    if (bf16 && a_pairs != nullptr) {
      eigen_assert(a_pairs->rows == a.rows() && a_pairs->depth == a.cols());
      return SmallGemmBfloat16Packed(*a_pairs, b.cols(), b.derived().data(), b.rowStride(),
                                     b.colStride(), c.derived().data(), c.colStride(),
                                     accumulate, row_offset);
    }
    const auto kernel = bf16 ? &SmallGemmBfloat16 : &SmallGemm;
    return kernel(a.rows(), a.cols(), b.cols(), a.derived().data(), a.rowStride(), a.colStride(),
                  b.derived().data(), b.rowStride(), b.colStride(), c.derived().data(),
                  c.colStride(), accumulate, row_offset);
  } else {
    return false;
  }
}
}  // namespace small_gemm_internal

// c = a * b (accumulate false) or c += a * b, with c not aliasing a or b (as Eigen's
// noalias()). Float products of directly accessible operands with c column-major go
// through SmallGemm; everything else (double, expressions) through Eigen. a_pairs, if
// not null, is a packed (PackBfloat16Pairs) for bfloat16 products, which then skip
// packing it: the same bits, less time.
template <typename Lhs, typename Rhs, typename Dst>
void Product(const Eigen::MatrixBase<Lhs>& a, const Eigen::MatrixBase<Rhs>& b, Dst&& c,
             bool accumulate, const Bfloat16Pairs* a_pairs = nullptr) {
  if (small_gemm_internal::Kernel(a, b, c, accumulate, nullptr, a_pairs)) return;
  if (accumulate) {
    c.noalias() += a * b;
  } else {
    c.noalias() = a * b;
  }
}

// c = offset 1^T + a * b (offset: a column of c.rows() values, the start of every
// column's sums), with c not aliasing a, b or offset. The kernel starts its sums from
// offset instead of reading c back; Eigen adds the product onto c set to offset. a_pairs
// as for Product.
template <typename Lhs, typename Rhs, typename Offset, typename Dst>
void ProductPlusOffset(const Eigen::MatrixBase<Lhs>& a, const Eigen::MatrixBase<Rhs>& b,
                       const Eigen::DenseBase<Offset>& offset, Dst&& c,
                       const Bfloat16Pairs* a_pairs = nullptr) {
  eigen_assert(offset.size() == c.rows());
  if constexpr (bool(Offset::Flags & Eigen::DirectAccessBit) &&
                std::is_same_v<typename Offset::Scalar, float>) {
    if (offset.innerStride() == 1 &&
        small_gemm_internal::Kernel(a, b, c, /*accumulate=*/false, offset.derived().data(),
                                    a_pairs)) {
      return;
    }
  }
  c.colwise() = offset.derived();
  c.noalias() += a * b;
}

}  // namespace internal
}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_TRUNK_INTERNAL_SMALL_GEMM_H_
