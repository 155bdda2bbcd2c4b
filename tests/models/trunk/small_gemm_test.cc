// Copyright 2026 The tactfunc Authors.
//
// SmallGemm against a double-precision product over the shapes the SIREN's passes use and
// their edges: strips of 64 rows (AVX-512) or 16 (AVX2) with a masked tail, tiles of 6
// columns with a remainder, an empty inner dimension, transposed operands, blocks of
// larger matrices, "=" and "+=".
#include "models/trunk/internal/small_gemm.h"

#include <cmath>
#include <string>

#include "gtest/gtest.h"
#include "tests/support/gemm_test_cases.h"

namespace tactfunc {
namespace {

using Eigen::MatrixXd;
using Eigen::MatrixXf;
using testing_util::ForEachGemmCase;
using testing_util::GemmCase;
using testing_util::GemmShape;
using testing_util::Numbers;

// Within float rounding of the double product: each value's error is bounded by
// depth * eps * sum_k |a_ik b_kj| (a sum in order, one rounding per multiply-add).
void ExpectClose(const MatrixXf& got, const MatrixXd& want, const MatrixXd& magnitude, long depth,
                 const std::string& what) {
  ASSERT_EQ(got.rows(), want.rows()) << what;
  ASSERT_EQ(got.cols(), want.cols()) << what;
  const double eps = 1.2e-7;
  for (long j = 0; j < got.cols(); ++j) {
    for (long i = 0; i < got.rows(); ++i) {
      const double bound = (depth + 2) * eps * (magnitude(i, j) + 1e-30);
      ASSERT_LE(std::abs(got(i, j) - want(i, j)), bound)
          << what << " at (" << i << ", " << j << ")";
    }
  }
}

TEST(SmallGemm, MatchesADoubleProductOverShapesTransposesAndBlocks) {
  unsigned seed = 1;
  ForEachGemmCase(
      {{1, 1, 1},
       {5, 3, 7},
       {16, 64, 6},
       {17, 2, 256},
       {48, 64, 13},
       {64, 64, 256},
       {65, 7, 5},
       {100, 33, 12},
       {128, 128, 256},
       {130, 256, 19},
       {256, 256, 64},
       {64, 256, 64},
       {64, 32, 128},
       {33, 16, 8},
       {64, 0, 9}},
      &seed, [](GemmCase& g) {
        auto c = g.c_block();
        if (g.transpose_a && g.transpose_b) {
          internal::Product(g.a_block().transpose(), g.b_block().transpose(), c, g.accumulate);
        } else if (g.transpose_a) {
          internal::Product(g.a_block().transpose(), g.b_block(), c, g.accumulate);
        } else if (g.transpose_b) {
          internal::Product(g.a_block(), g.b_block().transpose(), c, g.accumulate);
        } else {
          internal::Product(g.a_block(), g.b_block(), c, g.accumulate);
        }
        const MatrixXd a = g.A().cast<double>(), b = g.B().cast<double>();
        MatrixXd want = a * b;
        MatrixXd magnitude = a.cwiseAbs() * b.cwiseAbs();
        if (g.accumulate) {
          want += g.CBefore();
          magnitude += g.CBefore().cwiseAbs();
        }
        ExpectClose(MatrixXf(c), want, magnitude, g.shape.depth, g.what);
        ASSERT_TRUE(g.OnlyCChanged()) << g.what;  // nothing outside C's block written
      });
}

TEST(SmallGemm, LeavesARightHandSideOfNeitherLayoutToEigen) {
  // B with no unit stride (every other value of a buffer, down and across): SmallGemm
  // declines it and Product computes it through Eigen.
  const MatrixXf a = Numbers(20, 9, 7), store = Numbers(2 * 9, 2 * 5, 8);
  const Eigen::Map<const MatrixXf, 0, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>> b(
      store.data(), 9, 5, Eigen::Stride<Eigen::Dynamic, Eigen::Dynamic>(2 * 2 * 9, 2));
  float c0 = 0.0f;
  EXPECT_FALSE(internal::SmallGemm(20, 9, 5, a.data(), 1, 20, b.data(), 2, 4 * 9, &c0, 20,
                                   /*accumulate=*/false));
  MatrixXf c(20, 5);
  internal::Product(a, b, c, /*accumulate=*/false);
  const MatrixXf b_copy = b;
  ExpectClose(c, a.cast<double>() * b_copy.cast<double>(),
              a.cast<double>().cwiseAbs() * b_copy.cast<double>().cwiseAbs(), 9, "strided B");
}

TEST(SmallGemm, StartsTheSumsFromAnOffsetColumn) {
  // c = offset 1^T + a b, with the offset contiguous (the kernel's start) or a strided row
  // of a matrix (Eigen's path); c starts as NaN, which neither path may read.
  unsigned seed = 100;
  for (const GemmShape& s : {GemmShape{64, 64, 256}, {17, 2, 13}, {130, 33, 7}, {5, 0, 3}}) {
    const MatrixXf a = Numbers(s.rows, s.depth, seed++), b = Numbers(s.depth, s.cols, seed++);
    const MatrixXf offsets = Numbers(3, s.rows, seed++);
    const Eigen::VectorXf offset = offsets.row(1).transpose();
    MatrixXd want = a.cast<double>() * b.cast<double>();
    want.colwise() += offset.cast<double>();
    MatrixXd magnitude = a.cast<double>().cwiseAbs() * b.cast<double>().cwiseAbs();
    magnitude.colwise() += offset.cast<double>().cwiseAbs();
    MatrixXf c = MatrixXf::Constant(s.rows, s.cols, std::nanf(""));
    internal::ProductPlusOffset(a, b, offset, c);
    ExpectClose(c, want, magnitude, s.depth, "contiguous offset " + std::to_string(s.rows));
    c.setConstant(std::nanf(""));
    internal::ProductPlusOffset(a, b, offsets.row(1).transpose(), c);
    ExpectClose(c, want, magnitude, s.depth, "strided offset " + std::to_string(s.rows));
  }
}

TEST(SmallGemm, OverwritesNonFiniteValuesWhenNotAccumulating) {
  // "=" must not read C (Eigen's noalias() = does not either).
  const MatrixXf a = Numbers(20, 8, 3), b = Numbers(8, 7, 4);
  MatrixXf c = MatrixXf::Constant(20, 7, std::nanf(""));
  internal::Product(a, b, c, /*accumulate=*/false);
  EXPECT_TRUE(c.allFinite());
  EXPECT_LE((c.cast<double>() - a.cast<double>() * b.cast<double>()).cwiseAbs().maxCoeff(), 1e-5);
}

TEST(SmallGemm, IsDeterministic) {
  const MatrixXf a = Numbers(64, 64, 5), b = Numbers(64, 256, 6);
  MatrixXf c1(64, 256), c2(64, 256);
  internal::Product(a, b, c1, false);
  internal::Product(a, b, c2, false);
  EXPECT_EQ(c1, c2);
}

TEST(SmallGemm, HasItsKernelInAnAvx512OrAvx2Build) {
#if defined(__AVX512F__) || (defined(__AVX2__) && defined(__FMA__))
  EXPECT_TRUE(internal::HaveSmallGemm());
#else
  EXPECT_FALSE(internal::HaveSmallGemm());
  float c = 0.0f;
  const float one = 1.0f;
  EXPECT_FALSE(internal::SmallGemm(1, 1, 1, &one, 1, 1, &one, 1, 1, &c, 1, false));
#endif
}

}  // namespace
}  // namespace tactfunc
