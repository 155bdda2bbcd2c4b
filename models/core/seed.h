// Copyright 2026 The tactfunc Authors.
//
// Seeds. Randomness in tactfunc is always injected (a seed or a generator), never taken
// from the clock, so every result is reproducible.
#ifndef TACTFUNC_MODELS_CORE_SEED_H_
#define TACTFUNC_MODELS_CORE_SEED_H_

#include <cstdint>

namespace tactfunc {

// A decorrelated 64-bit seed for item `index` of a run seeded with `seed`: one SplitMix64
// step (Steele, Lea & Flood 2014) of seed + golden-ratio increments. Item i's seed does
// not depend on how many threads processed the items before it.
inline std::uint64_t DeriveSeed(std::uint64_t seed, std::uint64_t index) {
  std::uint64_t z = seed + 0x9E3779B97F4A7C15ull * (index + 1);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
}

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_CORE_SEED_H_
