// Copyright 2026 The tactfunc Authors.
//
// FitPhotometricLatentCeres on frames the trunk drew itself: from a start near the
// frame's latent, Levenberg-Marquardt with the trunk's exact Jacobian must find a latent
// that redraws the frame (the cost falls by orders of magnitude), on every valid pixel
// and on an evenly spaced subset; more iterations never end higher; bad input is refused.
#include "estimation/fitting/photometric_ceres_fit.h"

#include <limits>
#include <stdexcept>

#include "gtest/gtest.h"

namespace tactfunc {
namespace {

double Uniform(unsigned* state) {
  *state = *state * 1664525u + 1013904223u;
  return 2.0 * (*state >> 8) / double(1u << 24) - 1.0;
}

// A 12 x 14 photometric trunk with moving markers, the frame it draws at `z` (a few
// pixels invalid) and z itself.
struct Drawn {
  PhotometricTrunk trunk;
  TrunkTargets frame;
  Eigen::VectorXd z;
};

Drawn Draw() {
  PhotometricTrunk::Options o;
  o.rows = 12;
  o.cols = 14;
  o.width = 16;
  o.num_hidden_layers = 2;
  o.latent_dim = 8;
  o.shading_width = 8;
  o.supersample = 2;
  o.omega_0 = 6.0;  // a smooth trunk: the start below lies in the frame's basin
  unsigned state = 11;
  Image reference(24, 28, 1);
  for (float& v : reference.data) v = static_cast<float>(0.5 + 0.2 * Uniform(&state));
  Drawn d{PhotometricTrunk(o, reference, 4), {}, Eigen::VectorXd(o.latent_dim)};
  Eigen::VectorXd head = d.trunk.head_parameters();
  head[head.size() - 1] = 1.0;
  d.trunk.SetHeadParameters(head);
  for (int k = 0; k < o.latent_dim; ++k) d.z[k] = 0.5 * Uniform(&state);
  const int n = o.rows * o.cols;
  d.frame.rows = o.rows;
  d.frame.cols = o.cols;
  d.frame.values = d.trunk.Forward<float>(d.trunk.AllPixels(), d.z.cast<float>());
  d.frame.weights = Eigen::VectorXf::Ones(n);
  for (int j = 5; j < n; j += 17) {
    d.frame.weights[j] = 0.0f;
    d.frame.values(j, 0) = 0.0f;  // an invalid pixel holds 0 and must not count
  }
  return d;
}

TEST(PhotometricCeresFit, RecoversTheLatentThatDrewTheFrame) {
  const Drawn d = Draw();
  Eigen::VectorXd start = d.z;
  unsigned state = 5;
  for (int k = 0; k < start.size(); ++k) start[k] += 0.05 * Uniform(&state);
  for (int pixels : {0, 60}) {
    PhotometricCeresOptions options;
    options.pixels = pixels;
    options.iterations = 15;
    const PhotometricCeresFit fit = FitPhotometricLatentCeres(d.trunk, d.frame, start, options);
    EXPECT_GT(fit.initial_cost, 1e-5) << pixels;
    EXPECT_LT(fit.final_cost, 1e-4 * fit.initial_cost) << pixels << ": " << fit.message;
    EXPECT_LT((fit.latent - d.z).norm(), 0.1 * (start - d.z).norm()) << pixels;
    EXPECT_GE(fit.iterations, 2) << pixels;
    options.iterations = 1;
    const PhotometricCeresFit one = FitPhotometricLatentCeres(d.trunk, d.frame, start, options);
    EXPECT_LE(fit.final_cost, one.final_cost) << pixels;
    EXPECT_LT(one.final_cost, one.initial_cost) << pixels;
  }
}

TEST(PhotometricCeresFit, RefusesBadOptionsFramesAndStarts) {
  const Drawn d = Draw();
  PhotometricCeresOptions options;
  options.iterations = 0;
  EXPECT_THROW(FitPhotometricLatentCeres(d.trunk, d.frame, d.z, options), std::invalid_argument);
  options = PhotometricCeresOptions();
  options.pixels = -1;
  EXPECT_THROW(FitPhotometricLatentCeres(d.trunk, d.frame, d.z, options), std::invalid_argument);
  options = PhotometricCeresOptions();
  EXPECT_THROW(FitPhotometricLatentCeres(d.trunk, d.frame, Eigen::VectorXd::Zero(3), options),
               std::invalid_argument);
  Eigen::VectorXd bad = d.z;
  bad[1] = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(FitPhotometricLatentCeres(d.trunk, d.frame, bad, options), std::invalid_argument);
  TrunkTargets small = d.frame;
  small.values.conservativeResize(20, 1);
  EXPECT_THROW(FitPhotometricLatentCeres(d.trunk, small, d.z, options), std::invalid_argument);
  // No valid pixel: the start comes back.
  TrunkTargets empty = d.frame;
  empty.weights.setZero();
  const PhotometricCeresFit fit = FitPhotometricLatentCeres(d.trunk, empty, d.z, options);
  EXPECT_EQ(fit.latent, d.z);
}

}  // namespace
}  // namespace tactfunc
