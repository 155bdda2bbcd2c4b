// Copyright 2026 The tactfunc Authors.
// Storing latents as codes: uniform grids per dimension, their choice, and how many bits
// each dimension gets when a byte budget per frame is shared among the dimensions.
#ifndef TACTFUNC_ESTIMATION_FUNCTASET_LATENT_CODES_H_
#define TACTFUNC_ESTIMATION_FUNCTASET_LATENT_CODES_H_

#include <cstdint>
#include <vector>

namespace tactfunc {

// The widest code one latent dimension gets, in bits; a latent of d values therefore
// fills at most MaxCodeBytes(d) = 2 d bytes per frame, the largest byte budget allocated
// codes take.
constexpr int kMaxCodeBits = 16;
constexpr int MaxCodeBytes(int latent_dim) { return latent_dim * kMaxCodeBits / 8; }

// The values offset + q step, q in [0, 2^bits - 1], one latent dimension's code book.
// bits = 0 (or step = 0) stores nothing per frame: every value reads back as offset.
struct LatentGrid {
  float offset = 0;
  float step = 0;
  int bits = 0;
};

// The code of z: the nearest grid value's q (values beyond the ends take the nearest end;
// NaN takes 0).
std::uint32_t Quantise(float z, const LatentGrid& grid);
float Dequantise(std::uint32_t q, const LatentGrid& grid);

// The grid over [min, max] of `values`: every value reads back within step / 2 of itself
// (the uniform b-bit codes' grid; a constant dimension gets step 0).
LatentGrid RangeGrid(const std::vector<float>& values, int bits);

// The grid of 2^bits values with (close to) the least squared error over `values`. A grid
// over [min, max] spends its levels on a dimension's few extreme latents (the strongest
// contacts) while most latents sit near its middle; letting the extremes clip to the
// grid's ends buys a finer step for the rest. Candidates: the ranges between the sorted
// values' quantiles p and 1 - q, p and q from {0, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2}; the
// best is refined by alternating the codes and the least-squares offset and step for them
// (each round lowers the error, or the refinement stops). bits = 0: offset = the mean.
// Deterministic: the result depends on the multiset of values alone. bits in [0, 16].
LatentGrid LeastSquaresGrid(std::vector<float> values, int bits);

// Sum over `values` of (z - Dequantise(Quantise(z))^2.
double GridError(const std::vector<float>& values, const LatentGrid& grid);

// Bits per dimension, at most `max_bits` each and `budget_bits` in all, handed out one at
// a time to the dimension whose least-squares grid loses the most squared error by it
// (greedy marginal allocation, as transform coders share their bits; dims[k] holds
// dimension k's values over the frames). Every dimension counts the same: right for an
// orthonormal basis (PCA codes, and a readout trunk whose branch starts as one), an
// approximation for a trunk whose dimensions weigh differently. Ties go to the lower
// dimension; each dimension's error is measured on at most 4,096 of its values (evenly
// spaced in sorted order), so the allocation costs about budget_bits grids of that size.
// Bits that lower no dimension's error stay unspent.
std::vector<int> AllocateBits(const std::vector<std::vector<float>>& dims, int budget_bits,
                              int max_bits = kMaxCodeBits);

// Bytes of one frame's codes of the given widths, packed LSB-first and padded to a byte.
std::int64_t PackedBytes(const std::vector<int>& bits);
// Packs codes[k] (< 2^bits[k], bits[k] <= kMaxCodeBits) LSB-first, one after another, into `out`
// (PackedBytes(bits) values, zeroed by the caller, each a byte 0..255; doubles because
// tensor files hold their values so).
void PackCodes(const std::vector<std::uint32_t>& codes, const std::vector<int>& bits,
               double* out);
// The `bits`-bit code starting at bit `position` of a packed row.
std::uint32_t UnpackCode(const double* row, std::int64_t position, int bits);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_FUNCTASET_LATENT_CODES_H_
