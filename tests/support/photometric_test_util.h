// Copyright 2026 The tactfunc Authors.
//
// Small photometric trunks, references and targets for the photometric trainer and
// warm-start tests.
#ifndef TACTFUNC_TESTS_SUPPORT_PHOTOMETRIC_TEST_UTIL_H_
#define TACTFUNC_TESTS_SUPPORT_PHOTOMETRIC_TEST_UTIL_H_

#include <Eigen/Core>

#include "estimation/data/trunk_targets.h"
#include "models/core/image.h"
#include "models/trunk/photometric_trunk.h"

namespace tactfunc::testing_util {

// A one-channel trunk of width 16 and 2 layers, d = 8, on a rows x cols grid.
inline PhotometricTrunk::Options SmallPhotometricOptions(int rows, int cols) {
  PhotometricTrunk::Options o;
  o.rows = rows;
  o.cols = cols;
  o.channels = 1;
  o.width = 16;
  o.num_hidden_layers = 2;
  o.latent_dim = 8;
  o.shading_width = 8;
  o.supersample = 2;
  return o;
}

// A one-channel reference with a dark marker every 4 pixels along both axes.
inline Image MarkerReference(int rows, int cols) {
  Image image(rows, cols, 1);
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) image.at(r, c) = (r % 4 == 1 && c % 4 == 2) ? 0.2f : 0.6f;
  }
  return image;
}

// Targets of a rows x cols frame, every pixel valid.
inline TrunkTargets WholeFrameTargets(const Eigen::MatrixXf& values, int rows, int cols) {
  TrunkTargets t;
  t.values = values;
  t.weights = Eigen::VectorXf::Ones(values.rows());
  t.rows = rows;
  t.cols = cols;
  return t;
}

}  // namespace tactfunc::testing_util

#endif  // TACTFUNC_TESTS_SUPPORT_PHOTOMETRIC_TEST_UTIL_H_
