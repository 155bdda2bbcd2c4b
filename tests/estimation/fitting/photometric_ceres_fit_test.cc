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
#include "tests/support/photometric_test_util.h"

namespace tactfunc {
namespace {

// A 12 x 14 photometric trunk (the support's small one, at a low omega_0 so that the
// start below lies in the frame's basin) with moving markers, the frame it draws at z
// (every 17th pixel invalid, holding 0) and z itself.
struct Drawn {
  PhotometricTrunk trunk;
  TrunkTargets frame;
  Eigen::VectorXd z;
};

Drawn Draw() {
  PhotometricTrunk::Options o = testing_util::SmallPhotometricOptions(12, 14);
  o.omega_0 = 6.0;
  Drawn d{PhotometricTrunk(o, testing_util::MarkerReference(24, 28), 4), {},
          Eigen::VectorXd(o.latent_dim)};
  Eigen::VectorXd head = d.trunk.head_parameters();
  head[head.size() - 1] = 1.0;
  d.trunk.SetHeadParameters(head);
  d.z = 0.5 * Eigen::VectorXd::LinSpaced(o.latent_dim, -1.0, 1.0).array().sin();
  d.frame = testing_util::WholeFrameTargets(
      d.trunk.Forward<float>(d.trunk.AllPixels(), d.z.cast<float>()), o.rows, o.cols);
  for (int j = 5; j < o.rows * o.cols; j += 17) {
    d.frame.weights[j] = 0.0f;
    d.frame.values(j, 0) = 0.0f;
  }
  return d;
}

TEST(PhotometricCeresFit, RecoversTheLatentThatDrewTheFrame) {
  const Drawn d = Draw();
  const Eigen::VectorXd start =
      d.z + 0.05 * Eigen::VectorXd::LinSpaced(d.z.size(), 0.0, 3.0).array().cos().matrix();
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
