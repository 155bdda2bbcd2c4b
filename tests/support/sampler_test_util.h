// Copyright 2026 The tactfunc Authors.
//
// Tiny hand-built trunks and frames for the sampler tests (no trainer needed): an
// untrained SIREN trunk from a seed, targets the trunk itself generates at a known
// latent (plus optional Gaussian pixel noise, drawn with Boost.Random), and an untrained
// pose generator.
#ifndef TACTFUNC_TESTS_SUPPORT_SAMPLER_TEST_UTIL_H_
#define TACTFUNC_TESTS_SUPPORT_SAMPLER_TEST_UTIL_H_

#include <cstdint>

#include <Eigen/Core>
#include <boost/random/mersenne_twister.hpp>
#include <boost/random/normal_distribution.hpp>

#include "estimation/data/trunk_targets.h"
#include "models/pose/pose_generator.h"
#include "models/trunk/functa_model.h"

namespace tactfunc::testing_util {

// How far, in standard errors, the samplers' tests let a sample moment stray from its
// exact value.
inline constexpr double kSigmas = 4.5;

inline SensorTrunk MakeTinyTrunk(int rows, int cols, int width, int layers, int latent_dim,
                                 std::uint64_t seed, double residual_sigma = 0.05) {
  LatentModulatedSiren::Options options;
  options.width = width;
  options.num_hidden_layers = layers;
  options.latent_dim = latent_dim;
  options.output_channels = 1;
  SensorTrunk trunk;
  trunk.format.rows = rows;
  trunk.format.cols = cols;
  trunk.format.scale = 0.01;
  trunk.siren = LatentModulatedSiren(options, seed);
  trunk.alpha = Eigen::VectorXd::Constant(latent_dim, 0.1);
  trunk.meta_sgd.inner_steps = 3;
  trunk.residual_sigma = residual_sigma;
  return trunk;
}

// The trunk's own image at z (rows x cols, all pixels valid) plus N(0, noise^2) noise.
inline TrunkTargets MakeTargets(const SensorTrunk& trunk, const Eigen::VectorXd& z, double noise,
                                std::uint64_t seed) {
  TrunkTargets t;
  t.rows = trunk.format.rows;
  t.cols = trunk.format.cols;
  const Eigen::MatrixXd y =
      trunk.siren.Forward<double>(trunk.siren.Grid<double>(t.rows, t.cols), z);
  boost::random::mt19937_64 rng(seed);
  boost::random::normal_distribution<double> normal(0.0, noise > 0 ? noise : 1.0);
  t.values = y.cast<float>();
  if (noise > 0) {
    for (Eigen::Index i = 0; i < t.values.size(); ++i) t.values(i) += static_cast<float>(normal(rng));
  }
  t.weights = Eigen::VectorXf::Ones(y.rows());
  return t;
}

// An untrained pose generator of two tools ("l_shape", C_1; "rod", C_2) onto latents of
// size latent_dim, one tanh layer of `hidden` units, 2 yaw harmonics, from `seed`.
inline PoseGenerator MakeTinyGenerator(int latent_dim, int hidden, std::uint64_t seed) {
  PoseGenerator::Options o;
  o.tools = {"l_shape", "rod"};
  o.symmetry_orders = {1, 2};
  o.latent_dim = latent_dim;
  o.hidden_sizes = {hidden};
  o.yaw_harmonics = 2;
  return PoseGenerator(o, seed);
}

}  // namespace tactfunc::testing_util

#endif  // TACTFUNC_TESTS_SUPPORT_SAMPLER_TEST_UTIL_H_
