// Copyright 2026 The tactfunc Authors.
//
// A fast, deterministic source of sensor noise (private helper).
//
// A frame needs up to ~400k Gaussian samples; drawing each through
// boost::random::normal_distribution costs more than the rest of the rendering. Each
// 64-bit output of boost::random::mt19937_64 is split into four 16-bit indices into a
// table of the 65536 equiprobable standard-normal quantiles
//   z_i = Phi^-1((i + 1/2) / 65536),
// which is a Gaussian quantised to 1/65536 in probability (|z| <= 4.17). The same
// 16-bit draws give uniforms in (0, 1) for dropouts.
#ifndef TACTFUNC_MODELS_SIMULATOR_INTERNAL_NOISE_STREAM_H_
#define TACTFUNC_MODELS_SIMULATOR_INTERNAL_NOISE_STREAM_H_

#include <cstdint>

#include <boost/random/mersenne_twister.hpp>

namespace tactfunc::internal {

// The 65536 standard-normal quantiles, built once (thread-safe static).
const float* StandardNormalQuantiles();

class NoiseStream {
 public:
  explicit NoiseStream(std::uint64_t seed)
      : engine_(seed), table_(StandardNormalQuantiles()) {}

  std::uint32_t NextIndex() {
    if (left_ == 0) {
      bits_ = engine_();
      left_ = 4;
    }
    const std::uint32_t index = static_cast<std::uint32_t>(bits_ & 0xFFFFu);
    bits_ >>= 16;
    --left_;
    return index;
  }
  // Four standard normal samples from one fresh 64-bit draw.
  void Normal4(float* z) {
    const std::uint64_t bits = engine_();
    z[0] = table_[bits & 0xFFFFu];
    z[1] = table_[(bits >> 16) & 0xFFFFu];
    z[2] = table_[(bits >> 32) & 0xFFFFu];
    z[3] = table_[bits >> 48];
  }
  // A standard normal sample.
  float Normal() { return table_[NextIndex()]; }
  // Uniform on (0, 1), in steps of 1/65536.
  float Uniform() { return (static_cast<float>(NextIndex()) + 0.5f) * (1.0f / 65536.0f); }

 private:
  boost::random::mt19937_64 engine_;
  const float* table_;
  std::uint64_t bits_ = 0;
  int left_ = 0;
};

}  // namespace tactfunc::internal

#endif  // TACTFUNC_MODELS_SIMULATOR_INTERNAL_NOISE_STREAM_H_
