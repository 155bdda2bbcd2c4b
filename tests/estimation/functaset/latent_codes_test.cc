// Copyright 2026 The tactfunc Authors.
#include "estimation/functaset/latent_codes.h"

#include <algorithm>
#include <cmath>
#include <numeric>
#include <random>
#include <vector>

#include "gtest/gtest.h"

namespace tactfunc {
namespace {

// n values of a Laplace distribution of scale `scale` (heavy tails, like a latent
// dimension over frames of weak and strong contacts), from a fixed seed.
std::vector<float> LaplaceValues(int n, double scale, unsigned seed) {
  std::mt19937 rng(seed);
  std::exponential_distribution<double> exponential(1.0);
  std::bernoulli_distribution sign(0.5);
  std::vector<float> values(n);
  for (float& v : values) {
    v = static_cast<float>((sign(rng) ? 1 : -1) * scale * exponential(rng));
  }
  return values;
}

TEST(LatentCodes, TheRangeGridKeepsEveryValueWithinHalfAStep) {
  const std::vector<float> values = LaplaceValues(500, 2.0, 1);
  for (int bits : {1, 4, 8, 16}) {
    const LatentGrid grid = RangeGrid(values, bits);
    EXPECT_EQ(grid.offset, *std::min_element(values.begin(), values.end()));
    for (float z : values) {
      EXPECT_NEAR(Dequantise(Quantise(z, grid), grid), z, grid.step / 2 * (1 + 1e-5) + 1e-6);
    }
  }
}

TEST(LatentCodes, TheLeastSquaresGridIsWithinAFewPercentOfTheBestGridFoundByBruteForce) {
  // Brute force: every grid whose ends are two of the values (a fine enough search for
  // 2- and 3-bit grids of 300 values).
  const std::vector<float> values = LaplaceValues(300, 1.0, 2);
  std::vector<float> sorted = values;
  std::sort(sorted.begin(), sorted.end());
  for (int bits : {2, 3}) {
    const double levels = (1 << bits) - 1;
    double best = GridError(values, RangeGrid(values, bits));
    for (std::size_t i = 0; i < sorted.size(); ++i) {
      for (std::size_t j = i + 1; j < sorted.size(); ++j) {
        const float step = static_cast<float>((sorted[j] - sorted[i]) / levels);
        const LatentGrid grid{sorted[i], step, bits};
        best = std::min(best, GridError(values, grid));
      }
    }
    const double found = GridError(values, LeastSquaresGrid(values, bits));
    EXPECT_LE(found, 1.03 * best) << bits << " bits";
    // Far below the [min, max] grid's error on such tails.
    EXPECT_LT(found, 0.75 * GridError(values, RangeGrid(values, bits))) << bits << " bits";
  }
}

TEST(LatentCodes, TheLeastSquaresGridNeverLosesToTheRangeGridAndDependsOnTheValuesAlone) {
  for (unsigned seed = 3; seed < 8; ++seed) {
    std::vector<float> values = LaplaceValues(1000, 0.5 * seed, seed);
    for (int bits : {1, 2, 4, 6, 8, 12, 16}) {
      const LatentGrid grid = LeastSquaresGrid(values, bits);
      EXPECT_EQ(grid.bits, bits);
      EXPECT_LE(GridError(values, grid), GridError(values, RangeGrid(values, bits)));
      std::vector<float> shuffled = values;
      std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(seed));
      const LatentGrid again = LeastSquaresGrid(shuffled, bits);
      EXPECT_EQ(again.offset, grid.offset);
      EXPECT_EQ(again.step, grid.step);
    }
  }
}

TEST(LatentCodes, ZeroBitsStoreTheMeanAndAConstantDimensionIsExact) {
  const std::vector<float> values = {1.0f, 2.0f, 6.0f};
  const LatentGrid none = LeastSquaresGrid(values, 0);
  EXPECT_FLOAT_EQ(none.offset, 3.0f);
  for (float z : values) EXPECT_FLOAT_EQ(Dequantise(Quantise(z, none), none), 3.0f);
  const LatentGrid constant = LeastSquaresGrid({0.375f, 0.375f}, 8);
  EXPECT_EQ(constant.step, 0.0f);
  EXPECT_EQ(Dequantise(Quantise(0.375f, constant), constant), 0.375f);
  EXPECT_THROW(LeastSquaresGrid(values, 17), std::invalid_argument);
  EXPECT_THROW(RangeGrid(values, -1), std::invalid_argument);
}

// Total squared error of the dimensions on their least-squares grids of the given bits.
double TotalError(const std::vector<std::vector<float>>& dims, const std::vector<int>& bits) {
  double sum = 0;
  for (std::size_t k = 0; k < dims.size(); ++k) {
    sum += GridError(dims[k], LeastSquaresGrid(dims[k], bits[k]));
  }
  return sum;
}

TEST(LatentCodes, BitsGoWhereTheyLowerTheErrorMost) {
  // Scales 8, 4, 2, 1 and a constant dimension: each halving of the scale is worth about
  // one bit (the error of a b-bit grid falls about 4x per bit).
  const std::vector<double> scales = {8, 4, 2, 1, 0};
  std::vector<std::vector<float>> dims;
  for (std::size_t k = 0; k < scales.size(); ++k) {
    dims.push_back(LaplaceValues(2000, scales[k], 10 + k));
  }
  const std::vector<int> bits = AllocateBits(dims, 24);
  ASSERT_EQ(bits.size(), dims.size());
  EXPECT_EQ(std::accumulate(bits.begin(), bits.end(), 0), 24);
  for (std::size_t k = 0; k + 2 < scales.size(); ++k) {
    EXPECT_GE(bits[k], bits[k + 1]) << "dimension " << k;
    EXPECT_NEAR(bits[k] - bits[k + 1], 1, 1) << "dimension " << k;
  }
  EXPECT_EQ(bits[4], 0);  // a constant dimension: no bit lowers its error
  // No other allocation of the 24 bits with at most 3 bits moved does better (greedy
  // allocation is optimal when each dimension's error falls convexly with its bits).
  const double greedy = TotalError(dims, bits);
  for (std::size_t from = 0; from < 4; ++from) {
    for (std::size_t to = 0; to < 4; ++to) {
      for (int moved = 1; moved <= 3 && moved <= bits[from]; ++moved) {
        if (from == to) continue;
        std::vector<int> other = bits;
        other[from] -= moved;
        other[to] += moved;
        EXPECT_GE(TotalError(dims, other), greedy * (1 - 1e-9))
            << moved << " bits from " << from << " to " << to;
      }
    }
  }
  // Bits beyond max_bits per dimension, or that lower nothing, stay unspent.
  const std::vector<int> capped = AllocateBits(dims, 100, 6);
  EXPECT_EQ(capped, (std::vector<int>{6, 6, 6, 6, 0}));
}

TEST(LatentCodes, CodesOfMixedWidthsPackOneAfterAnotherAndUnpackExactly) {
  const std::vector<int> bits = {3, 16, 0, 1, 13, 8, 5};
  const std::vector<std::uint32_t> codes = {5, 0xbeef, 0, 1, 0x1abc, 0xa5, 17};
  ASSERT_EQ(PackedBytes(bits), 6);  // 46 bits
  std::vector<double> row(PackedBytes(bits), 0.0);
  PackCodes(codes, bits, row.data());
  std::int64_t position = 0;
  for (std::size_t k = 0; k < bits.size(); ++k) {
    EXPECT_EQ(UnpackCode(row.data(), position, bits[k]), codes[k]) << "code " << k;
    position += bits[k];
  }
  // LSB-first: the first byte holds code 0 in bits 0-2 and the low 5 bits of code 1.
  EXPECT_EQ(static_cast<int>(row[0]), 5 | ((0xbeef & 0x1f) << 3));
  for (double byte : row) EXPECT_TRUE(byte >= 0 && byte <= 255 && byte == std::floor(byte));
}

}  // namespace
}  // namespace tactfunc
