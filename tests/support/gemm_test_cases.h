// Copyright 2026 The tactfunc Authors.
//
// The cases the GEMM kernels' tests run (tests/models/trunk/small_gemm_test.cc and
// bfloat16_products_test.cc): for each shape, A and B each stored as itself or
// transposed, "=" and "+=", every operand a block of a larger matrix so that no stride
// equals the block's own size, with deterministic values in [-1, 1).
#ifndef TACTFUNC_TESTS_SUPPORT_GEMM_TEST_CASES_H_
#define TACTFUNC_TESTS_SUPPORT_GEMM_TEST_CASES_H_

#include <initializer_list>
#include <string>

#include <Eigen/Core>

#include "tests/support/uniform_numbers.h"

namespace tactfunc::testing_util {

struct GemmShape {
  long rows, depth, cols;
};

// rows x cols floats in [-1, 1), the same for the same seed everywhere.
inline Eigen::MatrixXf Numbers(long rows, long cols, unsigned seed) {
  return Uniform(static_cast<int>(rows), static_cast<int>(cols), seed).cast<float>();
}

// One product C (+)= A B: A rows x depth, B depth x cols, C rows x cols.
struct GemmCase {
  GemmShape shape;
  bool transpose_a, transpose_b, accumulate;
  std::string what;  // "RxDxC A^T B^T +=", for failure messages
  // A's store holds A (or A^T) at (1, 2), B's holds B (or B^T) at (1, 3), C's holds C
  // at (2, 1); c_before is C's store before the product.
  Eigen::MatrixXf a_store, b_store, c_store, c_before;

  // The blocks as stored (A or A^T, B or B^T) and C's block.
  auto a_block() const {
    return a_store.block(1, 2, transpose_a ? shape.depth : shape.rows,
                         transpose_a ? shape.rows : shape.depth);
  }
  auto b_block() const {
    return b_store.block(1, 3, transpose_b ? shape.cols : shape.depth,
                         transpose_b ? shape.depth : shape.cols);
  }
  auto c_block() { return c_store.block(2, 1, shape.rows, shape.cols); }
  // A and B as dense matrices.
  Eigen::MatrixXf A() const {
    return transpose_a ? Eigen::MatrixXf(a_block().transpose()) : Eigen::MatrixXf(a_block());
  }
  Eigen::MatrixXf B() const {
    return transpose_b ? Eigen::MatrixXf(b_block().transpose()) : Eigen::MatrixXf(b_block());
  }
  // The kernels' raw arguments: A(i, k) at a[i * row_stride + k * col_stride], B alike.
  const float* a() const { return &a_store(1, 2); }
  long a_row_stride() const { return transpose_a ? a_store.rows() : 1; }
  long a_col_stride() const { return transpose_a ? 1 : a_store.rows(); }
  const float* b() const { return &b_store(1, 3); }
  long b_row_stride() const { return transpose_b ? b_store.rows() : 1; }
  long b_col_stride() const { return transpose_b ? 1 : b_store.rows(); }
  float* c() { return &c_store(2, 1); }
  long c_col_stride() const { return c_store.rows(); }
  // C's store outside C's block as it was before.
  bool OnlyCChanged() const {
    Eigen::MatrixXf outside = c_store;
    outside.block(2, 1, shape.rows, shape.cols) = c_before.block(2, 1, shape.rows, shape.cols);
    return outside == c_before;
  }
  // C's block before the product, in double.
  Eigen::MatrixXd CBefore() const {
    return c_before.block(2, 1, shape.rows, shape.cols).cast<double>();
  }
};

// Calls f(GemmCase&) for every shape, layout and "=" / "+=", drawing values from *seed on.
template <typename F>
void ForEachGemmCase(std::initializer_list<GemmShape> shapes, unsigned* seed, F&& f) {
  for (const GemmShape& s : shapes) {
    for (const bool transpose_a : {false, true}) {
      for (const bool transpose_b : {false, true}) {
        for (const bool accumulate : {false, true}) {
          GemmCase g{s, transpose_a, transpose_b, accumulate,
                     std::to_string(s.rows) + "x" + std::to_string(s.depth) + "x" +
                         std::to_string(s.cols) + (transpose_a ? " A^T" : "") +
                         (transpose_b ? " B^T" : "") + (accumulate ? " +=" : " ="),
                     {}, {}, {}, {}};
          g.a_store = transpose_a ? Numbers(s.depth + 3, s.rows + 2, (*seed)++)
                                  : Numbers(s.rows + 3, s.depth + 2, (*seed)++);
          g.b_store = transpose_b ? Numbers(s.cols + 1, s.depth + 4, (*seed)++)
                                  : Numbers(s.depth + 1, s.cols + 4, (*seed)++);
          g.c_store = Numbers(s.rows + 5, s.cols + 2, (*seed)++);
          g.c_before = g.c_store;
          f(g);
        }
      }
    }
  }
}

}  // namespace tactfunc::testing_util

#endif  // TACTFUNC_TESTS_SUPPORT_GEMM_TEST_CASES_H_
