// Copyright 2026 The tactfunc Authors.
//
// The one way tactfunc includes FLANN's headers (estimation/knn/knn_index.cc only; every
// translation unit that includes FLANN must come through here, or two different
// instantiations of FLANN's templates would meet at link time).
//
// Why a wrapper. FLANN 1.9.2 as Debian 12 ships it compiles cleanly as C++17 (GCC 12,
// -Wall -Wextra), but its builds are NOT reproducible: KDTreeIndex::buildIndexImpl
// shuffles the points of every tree with `std::mt19937 g(std::random_device()())`
// (Debian's replacement of the C++17-removed std::random_shuffle), and UniqueRandom
// (k-means centre choice, autotuning's samples) does the same. flann::seed_random only
// seeds std::rand, which the rest of FLANN uses. Measured: two kd-forests built with
// the same seed_random over the same 2,000 points returned different neighbours.
//
// The workaround: while FLANN's headers are read, the token `random_device` names
// std::tactfunc_seeded_random_device instead, a generator drawing from a sequence that
// internal::SeedFlann(seed) restarts before each build. <random> is included first so
// that the real std::random_device is declared untouched. (Declaring a name in
// namespace std is formally undefined behaviour; it is confined to this header, FLANN's
// code is the only user of the name, and the knn_index tests check that builds
// with one seed agree.)
//
// Builds use process-wide state (std::rand and this sequence): internal::FlannBuildLock()
// serialises them; another thread calling std::rand during a build would still perturb
// it.
#ifndef TACTFUNC_ESTIMATION_KNN_INTERNAL_FLANN_INCLUDE_H_
#define TACTFUNC_ESTIMATION_KNN_INTERNAL_FLANN_INCLUDE_H_

#include <cstdint>
#include <cstdlib>
#include <mutex>
#include <random>

namespace tactfunc {
namespace internal {

// The state behind std::tactfunc_seeded_random_device (defined in knn_index.cc).
std::uint64_t NextFlannDeviceValue();
// Seeds std::rand (flann::seed_random) and restarts the device sequence from `seed`.
void SeedFlann(std::uint32_t seed);
// Held for the duration of every FLANN build.
std::mutex& FlannBuildLock();

}  // namespace internal
}  // namespace tactfunc

namespace std {
struct tactfunc_seeded_random_device {
  using result_type = unsigned int;
  static constexpr result_type min() { return 0; }
  static constexpr result_type max() { return 0xffffffffu; }
  result_type operator()() {
    return static_cast<result_type>(::tactfunc::internal::NextFlannDeviceValue());
  }
  double entropy() const noexcept { return 0.0; }
};
}  // namespace std

#define random_device tactfunc_seeded_random_device
#include <flann/flann.hpp>
#undef random_device

#endif  // TACTFUNC_ESTIMATION_KNN_INTERNAL_FLANN_INCLUDE_H_
