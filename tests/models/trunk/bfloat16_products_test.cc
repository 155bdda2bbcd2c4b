// Copyright 2026 The tactfunc Authors.
//
// The bfloat16 products (ProductPrecision::kBfloat16): exactly the double product of the
// operands rounded to bfloat16, up to float rounding of the sums, over the shapes and
// layouts the passes use; measurably not the float product; deterministic; the setting
// parsed, refused where the CPU lacks it, and float again when set back. A trunk's loss
// and latent gradient under bfloat16 products stay within bfloat16's error of float's.
#include <cmath>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>

#include "gtest/gtest.h"
#include "models/trunk/internal/small_gemm.h"
#include "models/trunk/latent_modulated_siren.h"
#include "models/trunk/product_precision.h"
#include "tests/support/gemm_test_cases.h"

namespace tactfunc {
namespace {

using Eigen::MatrixXd;
using Eigen::MatrixXf;
using testing_util::ForEachGemmCase;
using testing_util::GemmCase;
using testing_util::GemmShape;
using testing_util::Numbers;

// Round to nearest bfloat16, ties to even (finite values), written from the format's
// definition: keep the top 16 bits of the float.
double Bfloat16(float x) {
  std::uint32_t u;
  std::memcpy(&u, &x, 4);
  u += 0x7FFFu + ((u >> 16) & 1u);
  u &= 0xFFFF0000u;
  float y;
  std::memcpy(&y, &u, 4);
  return y;
}

MatrixXd Rounded(const MatrixXf& m) {
  return m.cast<double>().unaryExpr([](double x) { return Bfloat16(static_cast<float>(x)); });
}

TEST(Bfloat16Products, AreTheDoubleProductOfTheRoundedOperandsOverShapesAndLayouts) {
  if (!internal::HaveBfloat16Gemm()) GTEST_SKIP() << "this CPU lacks AVX512_BF16";
  // The kernel itself, on every shape (internal::Product sends it only products of 16
  // or more inner terms and columns).
  unsigned seed = 1;
  ForEachGemmCase(
      {{1, 1, 1},
       {5, 3, 7},
       {16, 64, 6},
       {17, 2, 128},
       {48, 65, 13},
       {64, 64, 128},
       {65, 7, 5},
       {100, 33, 12},
       {130, 128, 19},
       {256, 256, 128},
       {64, 128, 64},
       {33, 0, 8}},
      &seed, [](GemmCase& g) {
        const GemmShape& s = g.shape;
        ASSERT_TRUE(internal::SmallGemmBfloat16(
            s.rows, s.depth, s.cols, g.a(), g.a_row_stride(), g.a_col_stride(), g.b(),
            g.b_row_stride(), g.b_col_stride(), g.c(), g.c_col_stride(), g.accumulate))
            << g.what;
        const MatrixXd ra = Rounded(g.A()), rb = Rounded(g.B());
        MatrixXd want = ra * rb;
        MatrixXd magnitude = ra.cwiseAbs() * rb.cwiseAbs();
        if (g.accumulate) {
          want += g.CBefore();
          magnitude += g.CBefore().cwiseAbs();
        }
        // The products of bfloat16 values are exact in float; what remains is the
        // float rounding of the sums.
        const double eps = 1.2e-7;
        const auto c = g.c_block();
        for (long j = 0; j < s.cols; ++j) {
          for (long i = 0; i < s.rows; ++i) {
            ASSERT_LE(std::abs(c(i, j) - want(i, j)),
                      (s.depth + 2) * eps * magnitude(i, j) + 1e-30)
                << g.what << " at (" << i << ", " << j << ")";
          }
        }
        ASSERT_TRUE(g.OnlyCChanged()) << g.what;
      });
}

TEST(Bfloat16Products, LeaveShortProductsSuchAsTheCoordinatesOnesInFloat) {
  if (!internal::HaveBfloat16Gemm()) GTEST_SKIP() << "this CPU lacks AVX512_BF16";
  // A first layer's product (depth 2: the pixel coordinates) and its weight gradient
  // (2 columns) are the float kernel's, bit for bit; a product of 16 terms and columns
  // is not.
  const MatrixXf w = Numbers(64, 2, 1), coords = Numbers(2, 128, 2);
  const MatrixXf delta = Numbers(64, 128, 3), h = Numbers(64, 16, 4);
  MatrixXf first_float(64, 128), first_bf16(64, 128), grad_float(64, 2), grad_bf16(64, 2);
  MatrixXf square_float(64, 16), square_bf16(64, 16);
  internal::Product(w, coords, first_float, false);
  internal::Product(delta, coords.transpose(), grad_float, false);
  internal::Product(delta.leftCols(16), h.topRows(16), square_float, false);
  {
    const ScopedProductPrecision bf16(ProductPrecision::kBfloat16);
    internal::Product(w, coords, first_bf16, false);
    internal::Product(delta, coords.transpose(), grad_bf16, false);
    internal::Product(delta.leftCols(16), h.topRows(16), square_bf16, false);
  }
  EXPECT_EQ(first_bf16, first_float);
  EXPECT_EQ(grad_bf16, grad_float);
  EXPECT_NE(square_bf16, square_float);
}

TEST(Bfloat16Products, StartFromTheOffsetAndDifferFromFloatByBfloat16sError) {
  if (!internal::HaveBfloat16Gemm()) GTEST_SKIP() << "this CPU lacks AVX512_BF16";
  const MatrixXf a = Numbers(256, 256, 7), b = Numbers(256, 128, 8);
  const Eigen::VectorXf offset = Numbers(256, 1, 9);
  MatrixXf as_float(256, 128), as_bf16(256, 128), again(256, 128);
  internal::ProductPlusOffset(a, b, offset, as_float);
  {
    const ScopedProductPrecision bf16(ProductPrecision::kBfloat16);
    internal::ProductPlusOffset(a, b, offset, as_bf16);
    internal::ProductPlusOffset(a, b, offset, again);
  }
  EXPECT_EQ(as_bf16, again);  // deterministic
  const MatrixXd exact = (a.cast<double>() * b.cast<double>()).colwise() + offset.cast<double>();
  const MatrixXd magnitude = a.cast<double>().cwiseAbs() * b.cast<double>().cwiseAbs();
  const double float_error =
      ((as_float.cast<double>() - exact).cwiseAbs().array() / magnitude.array()).maxCoeff();
  const double bf16_error =
      ((as_bf16.cast<double>() - exact).cwiseAbs().array() / magnitude.array()).maxCoeff();
  // Each operand's rounding moves a term by at most 2^-9 of itself: the sum by at most
  // 2 x 2^-9 of the sum of magnitudes; float's error is three orders smaller.
  EXPECT_LE(bf16_error, 2.0 / 512 + 1e-6);
  EXPECT_GT(bf16_error, 100 * float_error);
  // Float again once the scope ends.
  MatrixXf after(256, 128);
  internal::ProductPlusOffset(a, b, offset, after);
  EXPECT_EQ(after, as_float);
}

TEST(Bfloat16Products, ThePrecisionIsParsedNamedAndRefusedWhereTheCpuLacksIt) {
  EXPECT_EQ(ParseProductPrecision("float"), ProductPrecision::kFloat);
  EXPECT_EQ(ParseProductPrecision("bf16"), ProductPrecision::kBfloat16);
  EXPECT_EQ(ProductPrecisionName(ProductPrecision::kBfloat16), "bf16");
  EXPECT_EQ(ProductPrecisionName(ProductPrecision::kFloat), "float");
  EXPECT_THROW(ParseProductPrecision("half"), std::invalid_argument);
  EXPECT_TRUE(ProductPrecisionAvailable(ProductPrecision::kFloat));
  EXPECT_EQ(ProductPrecisionAvailable(ProductPrecision::kBfloat16), internal::HaveBfloat16Gemm());
  EXPECT_EQ(GetProductPrecision(), ProductPrecision::kFloat);
  if (internal::HaveBfloat16Gemm()) {
    SetProductPrecision(ProductPrecision::kBfloat16);
    EXPECT_EQ(GetProductPrecision(), ProductPrecision::kBfloat16);
    SetProductPrecision(ProductPrecision::kFloat);
    {  // a scope puts back the precision before it, nested too
      const ScopedProductPrecision outer(ProductPrecision::kBfloat16);
      {
        const ScopedProductPrecision inner(ProductPrecision::kFloat);
        EXPECT_EQ(GetProductPrecision(), ProductPrecision::kFloat);
      }
      EXPECT_EQ(GetProductPrecision(), ProductPrecision::kBfloat16);
    }
  } else {
    EXPECT_THROW(SetProductPrecision(ProductPrecision::kBfloat16), std::invalid_argument);
  }
  EXPECT_EQ(GetProductPrecision(), ProductPrecision::kFloat);
}

TEST(Bfloat16Products, KeepATrunksLossAndLatentGradientWithinBfloat16sError) {
  if (!internal::HaveBfloat16Gemm()) GTEST_SKIP() << "this CPU lacks AVX512_BF16";
  LatentModulatedSiren::Options options;
  options.latent_dim = 32;
  options.width = 128;
  options.num_hidden_layers = 4;
  const LatentModulatedSiren siren(options, /*seed=*/3);
  const long rows = 24, cols = 30;
  const MatrixXf coords = LatentModulatedSiren::GridCoordinates(rows, cols).cast<float>();
  const Eigen::VectorXf z = 0.5f * Numbers(options.latent_dim, 1, 4);
  const MatrixXf targets = 0.1f * Numbers(rows * cols, 1, 5);
  const Eigen::VectorXf weights;  // every pixel
  Eigen::VectorXf g_float, g_bf16, t_float, t_bf16;
  const double loss_float =
      siren.LossAndGradient<float>(coords, z, targets, weights, &g_float, &t_float);
  double loss_bf16 = 0;
  {
    const ScopedProductPrecision bf16(ProductPrecision::kBfloat16);
    loss_bf16 = siren.LossAndGradient<float>(coords, z, targets, weights, &g_bf16, &t_bf16);
  }
  EXPECT_NE(loss_bf16, loss_float);
  EXPECT_NEAR(loss_bf16, loss_float, 0.01 * loss_float);
  // The gradients are sums over the pixels whose terms cancel in part, so their relative
  // errors exceed a product's: 0.8 % for z and 0.5 % for theta here, 2e-4 for the loss
  // (measured when this test was written; the first layer's products, of the pixel
  // coordinates, stay float).
  EXPECT_LE((g_bf16 - g_float).norm(), 0.02 * g_float.norm());
  EXPECT_LE((t_bf16 - t_float).norm(), 0.02 * t_float.norm());
}

TEST(Bfloat16Products, ATrunksPackedWeightsGiveTheBitsOfPackingThemPerProduct) {
  if (!internal::HaveBfloat16Gemm()) GTEST_SKIP() << "this CPU lacks AVX512_BF16";
  // A trunk made under bfloat16 packs its weights once (and again whenever they change);
  // one made under float has no packs and its bfloat16 products pack per call. Both
  // must give the same bits, at the start, after SetParameters and in a copy.
  LatentModulatedSiren::Options options;
  options.latent_dim = 24;
  options.width = 64;
  options.num_hidden_layers = 3;
  // Made under float: no packs, now or after SetParameters.
  const LatentModulatedSiren unpacked(options, /*seed=*/5);
  const Eigen::VectorXd moved =
      unpacked.parameters() + 0.01 * Numbers(unpacked.NumParameters(), 1, 9).cast<double>();
  LatentModulatedSiren unpacked_moved(options, /*seed=*/5);
  unpacked_moved.SetParameters(moved);
  const ScopedProductPrecision bf16(ProductPrecision::kBfloat16);
  LatentModulatedSiren packed(options, /*seed=*/5);
  const MatrixXf coords = LatentModulatedSiren::GridCoordinates(20, 33).cast<float>();
  const Eigen::VectorXf z = 0.5f * Numbers(options.latent_dim, 1, 6);
  const Eigen::VectorXf v_z = Numbers(options.latent_dim, 1, 7);
  const MatrixXf targets = 0.1f * Numbers(20 * 33, 1, 8);
  const Eigen::VectorXf weights;
  auto passes = [&](const LatentModulatedSiren& trunk) {
    Eigen::VectorXf dz, dtheta, hv_z, hv_theta;
    const float loss = trunk.LossGradientAndHessianProduct<float>(
        coords, z, targets, weights, nullptr, v_z, &dz, &dtheta, &hv_z, &hv_theta);
    Eigen::VectorXf all(1 + dz.size() + dtheta.size() + hv_z.size() + hv_theta.size());
    all << loss, dz, dtheta, hv_z, hv_theta;
    return all;
  };
  const Eigen::VectorXf before = passes(packed);
  EXPECT_EQ(before, passes(unpacked));
  packed.SetParameters(moved);
  const Eigen::VectorXf after = passes(packed);
  EXPECT_EQ(after, passes(unpacked_moved));
  EXPECT_NE(after, before);
  EXPECT_EQ(passes(LatentModulatedSiren(packed)), after);
}

}  // namespace
}  // namespace tactfunc
