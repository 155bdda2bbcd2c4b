// Copyright 2026 The tactfunc Authors.
#include "estimation/functaset/latent_codes.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>

namespace tactfunc {
namespace {

std::uint32_t Levels(int bits) { return (1u << bits) - 1; }

void CheckBits(int bits, const char* where) {
  if (bits < 0 || bits > kMaxCodeBits) {
    throw std::invalid_argument(std::string(where) + ": bits " + std::to_string(bits) +
                                " outside [0, " + std::to_string(kMaxCodeBits) + "]");
  }
}

// The grid whose ends are lo and hi.
LatentGrid Between(float lo, float hi, int bits) {
  return {lo, static_cast<float>((static_cast<double>(hi) - lo) / Levels(bits)), bits};
}

}  // namespace

std::uint32_t Quantise(float z, const LatentGrid& grid) {
  if (!(grid.step > 0) || grid.bits == 0) return 0;
  const double q = std::round((static_cast<double>(z) - grid.offset) / grid.step);
  if (!(q > 0)) return 0;  // also NaN
  return static_cast<std::uint32_t>(std::min(q, static_cast<double>(Levels(grid.bits))));
}

float Dequantise(std::uint32_t q, const LatentGrid& grid) {
  return static_cast<float>(grid.offset + static_cast<double>(q) * grid.step);
}

LatentGrid RangeGrid(const std::vector<float>& values, int bits) {
  CheckBits(bits, "RangeGrid");
  if (values.empty()) return {0, 0, bits};
  const auto [lo, hi] = std::minmax_element(values.begin(), values.end());
  return bits == 0 ? LatentGrid{*lo, 0, 0} : Between(*lo, *hi, bits);
}

double GridError(const std::vector<float>& values, const LatentGrid& grid) {
  double sum = 0;
  for (float z : values) {
    const double e = static_cast<double>(z) - Dequantise(Quantise(z, grid), grid);
    sum += e * e;
  }
  return sum;
}

namespace {

// A grid and its squared error over the values it was fitted to.
struct FittedGrid {
  LatentGrid grid;
  double error = 0;
};

// LeastSquaresGrid of values already sorted ascending (not empty), with its error.
FittedGrid FitSorted(const std::vector<float>& values, int bits) {
  const std::size_t n = values.size();
  if (bits == 0 || values.front() == values.back()) {
    double mean = 0;
    for (float z : values) mean += z;
    const LatentGrid grid{static_cast<float>(mean / static_cast<double>(n)), 0, bits};
    return {grid, GridError(values, grid)};
  }
  LatentGrid best = Between(values.front(), values.back(), bits);
  double best_error = GridError(values, best);
  constexpr double kTails[] = {0, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2};
  for (double p : kTails) {
    for (double q : kTails) {
      const std::size_t lo = static_cast<std::size_t>(p * static_cast<double>(n - 1));
      const std::size_t hi = n - 1 - static_cast<std::size_t>(q * static_cast<double>(n - 1));
      if (!(values[lo] < values[hi])) continue;
      const LatentGrid grid = Between(values[lo], values[hi], bits);
      const double error = GridError(values, grid);
      if (error < best_error) best = grid, best_error = error;
    }
  }
  const double count = static_cast<double>(n);
  for (int round = 0; round < 20; ++round) {
    // Least squares of z ~ offset + q step over the current codes q.
    double s_q = 0, s_qq = 0, s_z = 0, s_qz = 0;
    for (float z : values) {
      const double q = Quantise(z, best);
      s_q += q, s_qq += q * q, s_z += z, s_qz += q * z;
    }
    const double det = count * s_qq - s_q * s_q;
    if (!(det > 0)) break;
    const double step = (count * s_qz - s_q * s_z) / det;
    const LatentGrid grid{static_cast<float>((s_z - step * s_q) / count),
                          static_cast<float>(step), bits};
    if (!(grid.step > 0)) break;
    const double error = GridError(values, grid);
    if (!(error < best_error)) break;
    best = grid, best_error = error;
  }
  return {best, best_error};
}

}  // namespace

LatentGrid LeastSquaresGrid(std::vector<float> values, int bits) {
  CheckBits(bits, "LeastSquaresGrid");
  if (values.empty()) return {0, 0, bits};
  std::sort(values.begin(), values.end());
  return FitSorted(values, bits).grid;
}

std::vector<int> AllocateBits(const std::vector<std::vector<float>>& dims, int budget_bits,
                              int max_bits) {
  CheckBits(max_bits, "AllocateBits");
  constexpr std::size_t kMaxValues = 4096;
  const std::size_t d = dims.size();
  // Each dimension's values, sorted, thinned to at most kMaxValues evenly spaced ones.
  std::vector<std::vector<float>> sample(d);
  for (std::size_t k = 0; k < d; ++k) {
    std::vector<float> sorted = dims[k];
    std::sort(sorted.begin(), sorted.end());
    if (sorted.size() <= kMaxValues) {
      sample[k] = std::move(sorted);
      continue;
    }
    sample[k].resize(kMaxValues);
    for (std::size_t i = 0; i < kMaxValues; ++i) {
      sample[k][i] = sorted[i * (sorted.size() - 1) / (kMaxValues - 1)];
    }
  }
  // Each sample is sorted and fitted once per bit count, its error kept from the fit.
  auto error = [&](std::size_t k, int bits) {
    return sample[k].empty() ? 0.0 : FitSorted(sample[k], bits).error;
  };
  std::vector<int> bits(d, 0);
  std::vector<double> now(d), next(d);
  for (std::size_t k = 0; k < d; ++k) {
    now[k] = error(k, 0);
    next[k] = max_bits > 0 ? error(k, 1) : now[k];
  }
  for (int spent = 0; spent < budget_bits; ++spent) {
    std::size_t best = d;
    double gain = 0;
    for (std::size_t k = 0; k < d; ++k) {
      if (bits[k] < max_bits && now[k] - next[k] > gain) gain = now[k] - next[k], best = k;
    }
    if (best == d) break;
    ++bits[best];
    now[best] = next[best];
    next[best] = bits[best] < max_bits ? error(best, bits[best] + 1) : now[best];
  }
  return bits;
}

std::int64_t PackedBytes(const std::vector<int>& bits) {
  std::int64_t total = 0;
  for (int b : bits) total += b;
  return (total + 7) / 8;
}

void PackCodes(const std::vector<std::uint32_t>& codes, const std::vector<int>& bits,
               double* out) {
  std::int64_t position = 0;
  for (std::size_t k = 0; k < codes.size(); ++k) {
    // At most 16 bits starting anywhere in a byte: up to three bytes.
    std::uint32_t shifted = codes[k] << (position % 8);
    for (std::int64_t byte = position / 8; shifted != 0; ++byte, shifted >>= 8) {
      out[byte] = static_cast<double>(static_cast<std::uint32_t>(out[byte]) | (shifted & 0xff));
    }
    position += bits[k];
  }
}

std::uint32_t UnpackCode(const double* row, std::int64_t position, int bits) {
  if (bits == 0) return 0;
  std::uint32_t word = 0;
  const std::int64_t first = position / 8, last = (position + bits - 1) / 8;
  for (std::int64_t byte = last; byte >= first; --byte) {
    word = (word << 8) | static_cast<std::uint32_t>(row[byte]);
  }
  return (word >> (position % 8)) & Levels(bits);
}

}  // namespace tactfunc
