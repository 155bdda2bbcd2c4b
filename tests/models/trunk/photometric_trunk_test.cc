// Copyright 2026 The tactfunc Authors.
//
// The photometric trunk's reverse pass (latent with its rigid motion, SIREN parameters,
// shading network and marker scale) is checked against central differences of its loss
// with both marker samplings; the at-rest markers are the reference's area resize; a
// SIREN that draws nothing gives an empty difference; float agrees with double; bad
// options and references are refused by name.
#include "models/trunk/photometric_trunk.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "gtest/gtest.h"

namespace tactfunc {
namespace {

using Eigen::MatrixXd;
using Eigen::MatrixXf;
using Eigen::VectorXd;
using Eigen::VectorXf;

double Uniform(unsigned* state) {
  *state = *state * 1664525u + 1013904223u;
  return 2.0 * (*state >> 8) / double(1u << 24) - 1.0;
}

PhotometricTrunk::Options SmallPhotometricTrunk() {
  PhotometricTrunk::Options o;
  o.rows = 8;
  o.cols = 10;
  o.channels = 1;
  o.width = 12;
  o.num_hidden_layers = 2;
  o.latent_dim = 9;
  o.shading_width = 6;
  o.supersample = 3;
  return o;
}

// A sensor-resolution reference (2x the working size) with marker-like dark dots.
Image DottedReference(int rows, int cols, int channels) {
  Image image(rows, cols, channels);
  unsigned state = 7;
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      for (int ch = 0; ch < channels; ++ch) {
        const bool dot = (r % 4 == 1) && (c % 4 == 2);
        image.at(r, c, ch) = static_cast<float>(0.5 + 0.1 * Uniform(&state) - (dot ? 0.4 : 0));
      }
    }
  }
  return image;
}

struct PhotometricProblem {
  std::vector<int> pixels;
  VectorXd z;
  MatrixXd targets;
  VectorXd weights;
};

PhotometricProblem MakePhotometricProblem(const PhotometricTrunk& trunk) {
  PhotometricProblem p;
  unsigned state = 99;
  // Interior pixels and a few on the border (the marker sampling clamps there).
  p.pixels = {0, 3, 11, 14, 25, 33, 38, 42, 47, 56, 61, 79};
  p.z.resize(trunk.latent_dim());
  for (int k = 0; k < p.z.size(); ++k) p.z[k] = 0.8 * Uniform(&state);
  p.z[2] = 0.6;  // a turned contact
  p.targets.resize(p.pixels.size(), trunk.channels());
  for (int i = 0; i < p.targets.size(); ++i) p.targets.data()[i] = 0.2 * Uniform(&state);
  p.weights.resize(p.pixels.size());
  for (int i = 0; i < p.weights.size(); ++i) p.weights[i] = i == 4 ? 0.0 : 1.0 + 0.5 * Uniform(&state);
  return p;
}

// A trunk whose markers move visibly (m = 1.5 working pixels per unit of slope) and
// whose SIREN draws a slope of O(1) per pixel; with lighting_components K > 0, K
// lighting images of random values weighed by the latent's last K values (latent_dim 9:
// pose 3, code 9 - 3 - K).
PhotometricTrunk MovingTrunk(PhotometricTrunk::MarkerSampling sampling, int channels = 1,
                             int lighting_components = 0) {
  PhotometricTrunk::Options o = SmallPhotometricTrunk();
  o.channels = channels;
  o.lighting_components = lighting_components;
  PhotometricTrunk trunk(o, DottedReference(2 * o.rows, 2 * o.cols, channels), 5);
  VectorXd head = trunk.head_parameters();
  head[head.size() - 1] = 1.5;
  trunk.SetHeadParameters(head);
  trunk.set_marker_sampling(sampling);
  if (lighting_components > 0) {
    MatrixXf lighting(o.rows * o.cols * channels, lighting_components);
    unsigned state = 17;
    for (int i = 0; i < lighting.size(); ++i) lighting.data()[i] = 0.3f * Uniform(&state);
    trunk.SetLighting(lighting);
  }
  return trunk;
}

void ExpectGradientsMatchDifferences(PhotometricTrunk trunk) {
  const PhotometricProblem p = MakePhotometricProblem(trunk);
  VectorXd dz, dsiren, dhead;
  trunk.LossAndGradient<double>(p.pixels, p.z, p.targets, p.weights, &dz, &dsiren, &dhead);
  const double eps = 1e-6;
  auto loss = [&](const PhotometricTrunk& t, const VectorXd& z) {
    return t.LossAndGradient<double>(p.pixels, z, p.targets, p.weights, nullptr, nullptr,
                                     nullptr);
  };
  auto expect_near = [](double analytic, double numeric, const std::string& what) {
    EXPECT_NEAR(analytic, numeric, 2e-6 + 1e-4 * std::abs(numeric)) << what;
  };
  for (int k = 0; k < p.z.size(); ++k) {
    VectorXd up = p.z, down = p.z;
    up[k] += eps;
    down[k] -= eps;
    expect_near(dz[k], (loss(trunk, up) - loss(trunk, down)) / (2 * eps),
                "dL/dz[" + std::to_string(k) + "]");
  }
  const VectorXd head = trunk.head_parameters();
  for (int k = 0; k + 1 < head.size(); k += 7) {
    PhotometricTrunk moved = trunk;
    VectorXd h = head;
    h[k] += eps;
    moved.SetHeadParameters(h);
    const double plus = loss(moved, p.z);
    h[k] -= 2 * eps;
    moved.SetHeadParameters(h);
    expect_near(dhead[k], (plus - loss(moved, p.z)) / (2 * eps),
                "dL/dhead[" + std::to_string(k) + "]");
  }
  expect_near(dhead[head.size() - 1], [&] {
    PhotometricTrunk moved = trunk;
    VectorXd h = head;
    h[h.size() - 1] += eps;
    moved.SetHeadParameters(h);
    const double plus = loss(moved, p.z);
    h[h.size() - 1] -= 2 * eps;
    moved.SetHeadParameters(h);
    return (plus - loss(moved, p.z)) / (2 * eps);
  }(), "dL/dm");
  const VectorXd theta = trunk.siren().parameters();
  for (int k = 0; k < theta.size(); k += 5) {
    PhotometricTrunk moved = trunk;
    VectorXd t = theta;
    t[k] += eps;
    moved.mutable_siren().SetParameters(t);
    const double plus = loss(moved, p.z);
    t[k] -= 2 * eps;
    moved.mutable_siren().SetParameters(t);
    expect_near(dsiren[k], (plus - loss(moved, p.z)) / (2 * eps),
                "dL/dtheta[" + std::to_string(k) + "]");
  }
}

TEST(PhotometricTrunkTest, GradientsMatchCentralDifferencesWithSensorResolutionMarkers) {
  ExpectGradientsMatchDifferences(
      MovingTrunk(PhotometricTrunk::MarkerSampling::kSensorResolution));
}

TEST(PhotometricTrunkTest, GradientsMatchCentralDifferencesWithWorkingResolutionMarkers) {
  ExpectGradientsMatchDifferences(
      MovingTrunk(PhotometricTrunk::MarkerSampling::kWorkingResolution));
}

TEST(PhotometricTrunkTest, GradientsMatchCentralDifferencesWithThreeChannels) {
  ExpectGradientsMatchDifferences(
      MovingTrunk(PhotometricTrunk::MarkerSampling::kSensorResolution, 3));
}

TEST(PhotometricTrunkTest, GradientsMatchCentralDifferencesWithLightingImages) {
  // The lighting values' gradients (the latent's last two) and every other one.
  ExpectGradientsMatchDifferences(
      MovingTrunk(PhotometricTrunk::MarkerSampling::kSensorResolution, 3, 2));
}

TEST(PhotometricTrunkTest, EachLightingValueAddsItsImageToEveryPixel) {
  const PhotometricTrunk lit =
      MovingTrunk(PhotometricTrunk::MarkerSampling::kSensorResolution, 2, 2);
  EXPECT_EQ(lit.CodeValues(), 9 - 3 - 2);
  EXPECT_EQ(lit.siren().options().latent_dim, lit.CodeValues());
  const std::vector<int> all = lit.AllPixels();
  VectorXf z = MakePhotometricProblem(lit).z.cast<float>();
  const MatrixXf base = lit.Forward<float>(all, z);
  // The code drives the SIREN only, the lighting values the images only: moving the
  // second lighting value by 0.5 adds half its image, whatever the code.
  VectorXf moved = z;
  moved[8] += 0.5f;
  const MatrixXf with = lit.Forward<float>(all, moved);
  for (int j = 0; j < static_cast<int>(all.size()); ++j) {
    for (int ch = 0; ch < 2; ++ch) {
      ASSERT_NEAR(with(j, ch) - base(j, ch), 0.5f * lit.lighting()(j * 2 + ch, 1), 1e-5) << j;
    }
  }
  // With the images at zero the trunk draws what a trunk without them draws.
  PhotometricTrunk dark = lit;
  dark.SetLighting(MatrixXf::Zero(lit.lighting().rows(), 2));
  const MatrixXf dark_y = dark.Forward<float>(all, z);
  moved = z;
  moved.tail(2) << 3.0f, -2.0f;
  EXPECT_EQ(dark.Forward<float>(all, moved), dark_y);
  // Refused: another shape, a non-finite value; options whose code would be empty.
  EXPECT_THROW(dark.SetLighting(MatrixXf::Zero(lit.lighting().rows(), 3)), std::invalid_argument);
  MatrixXf bad = lit.lighting();
  bad(4, 1) = std::nanf("");
  EXPECT_THROW(dark.SetLighting(bad), std::invalid_argument);
  PhotometricTrunk::Options o = SmallPhotometricTrunk();
  o.lighting_components = 6;  // 3 + 6 = latent_dim 9: no code value left
  try {
    PhotometricTrunk trunk(o, DottedReference(16, 20, 1));
    FAIL() << "a latent without code values accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("lighting"), std::string::npos) << e.what();
  }
}

TEST(PhotometricTrunkTest, MarkersMoveTheOutput) {
  // The same trunk with the markers held at rest (m = 0) draws a different frame: the
  // marker term is live, not cancelled.
  PhotometricTrunk moving = MovingTrunk(PhotometricTrunk::MarkerSampling::kSensorResolution);
  PhotometricTrunk still = moving;
  VectorXd head = still.head_parameters();
  head[head.size() - 1] = 0.0;
  still.SetHeadParameters(head);
  const PhotometricProblem p = MakePhotometricProblem(moving);
  const MatrixXd a = moving.Forward<double>(moving.AllPixels(), p.z);
  const MatrixXd b = still.Forward<double>(still.AllPixels(), p.z);
  EXPECT_GT((a - b).cwiseAbs().maxCoeff(), 1e-3);
}

TEST(PhotometricTrunkTest, AFramesOwnMarkersDrawItAsATrunkOfThatReference) {
  // A trunk drawing against other markers (MakeMarkers of a clip's reference) equals,
  // in every pass, the same trunk built on that reference: to the bit.
  for (const auto sampling : {PhotometricTrunk::MarkerSampling::kSensorResolution,
                              PhotometricTrunk::MarkerSampling::kWorkingResolution}) {
    const PhotometricTrunk trunk = MovingTrunk(sampling);
    // Another reference: the markers shifted by two sensor pixels, another brightness.
    const Image own = trunk.reference();
    Image other(own.rows, own.cols, 1);
    for (int r = 0; r < own.rows; ++r) {
      for (int c = 0; c < own.cols; ++c) other.at(r, c) = 0.8f * own.at(r, (c + 2) % own.cols);
    }
    PhotometricTrunk built(trunk.options(), other);
    built.mutable_siren().SetParameters(trunk.siren().parameters());
    built.SetHeadParameters(trunk.head_parameters());
    built.set_marker_sampling(sampling);
    const auto markers = trunk.MakeMarkers(other);
    const PhotometricProblem p = MakePhotometricProblem(trunk);
    const MatrixXd a = trunk.Forward<double>(trunk.AllPixels(), p.z, markers.get());
    EXPECT_EQ(a, built.Forward<double>(built.AllPixels(), p.z));
    // The frame's own markers matter: its own reference draws another frame.
    EXPECT_GT((a - trunk.Forward<double>(trunk.AllPixels(), p.z)).cwiseAbs().maxCoeff(), 1e-3);
    VectorXd dz_a, ds_a, dh_a, dz_b, ds_b, dh_b;
    const double la = trunk.LossAndGradient<double>(p.pixels, p.z, p.targets, p.weights, &dz_a,
                                                    &ds_a, &dh_a, nullptr, markers.get());
    const double lb =
        built.LossAndGradient<double>(p.pixels, p.z, p.targets, p.weights, &dz_b, &ds_b, &dh_b);
    EXPECT_EQ(la, lb);
    EXPECT_EQ(dz_a, dz_b);
    EXPECT_EQ(ds_a, ds_b);
    EXPECT_EQ(dh_a, dh_b);
    MatrixXd ya, Ja, yb, Jb;
    trunk.ForwardAndLatentJacobian<double>(p.pixels, p.z, &ya, &Ja, markers.get());
    built.ForwardAndLatentJacobian<double>(p.pixels, p.z, &yb, &Jb);
    EXPECT_EQ(ya, yb);
    EXPECT_EQ(Ja, Jb);
  }
}

TEST(PhotometricTrunkTest, RowSummedMarkersEqualTheirSamplesTakenOneByOne) {
  // K = 3 rows of samples one reference row apart (3x the working rows) and a column
  // ratio that is not a whole number, as the GelSlim's 320 x 427 over 80 x 107: each
  // pixel reads K sums of K reference rows instead of K^2 samples, away from the
  // borders. Against the same markers without the sums, every pass agrees to float
  // rounding of the sums, the border pixels included.
  PhotometricTrunk::Options o = SmallPhotometricTrunk();
  o.supersample = 3;
  const Image reference = DottedReference(3 * o.rows, 3 * o.cols + 1, 1);
  PhotometricTrunk trunk(o, reference, 5);
  VectorXd head = trunk.head_parameters();
  head[head.size() - 1] = 1.5;
  trunk.SetHeadParameters(head);
  const auto summed = trunk.MakeMarkers(reference);
  ASSERT_FALSE(summed->row_sums.empty());
  EXPECT_EQ(summed->row_sums.rows, 3 * o.rows - 2);  // sums of 3 rows, 1 row apart
  PhotometricTrunk::Markers one_by_one = *summed;
  one_by_one.row_sums = Image();
  const PhotometricProblem p = MakePhotometricProblem(trunk);
  const MatrixXd a = trunk.Forward<double>(trunk.AllPixels(), p.z, summed.get());
  const MatrixXd b = trunk.Forward<double>(trunk.AllPixels(), p.z, &one_by_one);
  EXPECT_LT((a - b).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_GT((a - trunk.Forward<double>(trunk.AllPixels(), VectorXd::Zero(p.z.size()),
                                       summed.get()))
                .cwiseAbs()
                .maxCoeff(),
            1e-3);  // the contact moves the markers: the sums are read, not skipped
  VectorXd dz_a, ds_a, dh_a, dz_b, ds_b, dh_b;
  trunk.LossAndGradient<double>(p.pixels, p.z, p.targets, p.weights, &dz_a, &ds_a, &dh_a,
                                nullptr, summed.get());
  trunk.LossAndGradient<double>(p.pixels, p.z, p.targets, p.weights, &dz_b, &ds_b, &dh_b,
                                nullptr, &one_by_one);
  EXPECT_LT((dz_a - dz_b).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_LT((ds_a - ds_b).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_LT((dh_a - dh_b).cwiseAbs().maxCoeff(), 1e-6);
  MatrixXd ya, Ja, yb, Jb;
  trunk.ForwardAndLatentJacobian<double>(p.pixels, p.z, &ya, &Ja, summed.get());
  trunk.ForwardAndLatentJacobian<double>(p.pixels, p.z, &yb, &Jb, &one_by_one);
  EXPECT_LT((Ja - Jb).cwiseAbs().maxCoeff(), 1e-6);
  // Other shapes keep the samples one by one: K = 3 at twice the working rows.
  const PhotometricTrunk two(o, DottedReference(2 * o.rows, 2 * o.cols, 1));
  EXPECT_TRUE(two.markers().row_sums.empty());
}

TEST(PhotometricTrunkTest, GradientsMatchCentralDifferencesWithRowSummedMarkers) {
  PhotometricTrunk::Options o = SmallPhotometricTrunk();
  o.supersample = 2;  // twice the working rows: the sums of 2 rows, one row apart
  PhotometricTrunk trunk(o, DottedReference(2 * o.rows, 2 * o.cols + 1, 1), 5);
  ASSERT_FALSE(trunk.markers().row_sums.empty());
  VectorXd head = trunk.head_parameters();
  head[head.size() - 1] = 1.5;
  trunk.SetHeadParameters(head);
  ExpectGradientsMatchDifferences(trunk);
}

TEST(PhotometricTrunkTest, MarkersOfAnotherGridOrChannelsAreRefused) {
  const PhotometricTrunk trunk = MovingTrunk(PhotometricTrunk::MarkerSampling::kSensorResolution);
  PhotometricTrunk::Options o = trunk.options();
  o.cols += 1;
  const PhotometricTrunk wider(o, trunk.reference());
  const auto foreign = wider.MakeMarkers(trunk.reference());
  const PhotometricProblem p = MakePhotometricProblem(trunk);
  EXPECT_THROW(trunk.Forward<double>(p.pixels, p.z, foreign.get()), std::invalid_argument);
  EXPECT_THROW(trunk.MakeMarkers(DottedReference(4, 4, 3)), std::invalid_argument);
  EXPECT_THROW(trunk.MakeMarkers(Image()), std::invalid_argument);
}

TEST(PhotometricTrunkTest, AtRestMarkersAreTheAreaResizedReference) {
  // K = 2 at a 2x reference samples each sensor pixel's centre exactly: the at-rest
  // table is the 2 x 2 block mean.
  PhotometricTrunk::Options o = SmallPhotometricTrunk();
  o.supersample = 2;
  const Image reference = DottedReference(2 * o.rows, 2 * o.cols, 1);
  const PhotometricTrunk trunk(o, reference);
  for (int r = 0; r < o.rows; ++r) {
    for (int c = 0; c < o.cols; ++c) {
      const double mean = (reference.at(2 * r, 2 * c) + reference.at(2 * r + 1, 2 * c) +
                           reference.at(2 * r, 2 * c + 1) + reference.at(2 * r + 1, 2 * c + 1)) /
                          4.0;
      EXPECT_NEAR(trunk.at_rest().at(r, c), mean, 1e-6) << r << ", " << c;
    }
  }
}

TEST(PhotometricTrunkTest, ASirenThatDrawsNothingGivesAnEmptyDifference) {
  PhotometricTrunk trunk = MovingTrunk(PhotometricTrunk::MarkerSampling::kSensorResolution);
  VectorXd theta = trunk.siren().parameters();
  for (ParameterGroup group : {ParameterGroup::kOutputWeight, ParameterGroup::kOutputBias}) {
    LatentModulatedSiren::View<double>(&theta, trunk.siren().Block(group)).setZero();
  }
  trunk.mutable_siren().SetParameters(theta);
  const PhotometricProblem p = MakePhotometricProblem(trunk);
  const MatrixXd y = trunk.Forward<double>(trunk.AllPixels(), p.z);
  EXPECT_EQ(y.rows(), 80);
  // The at-rest table is stored in float: the markers cancel to its rounding.
  EXPECT_LT(y.cwiseAbs().maxCoeff(), 1e-6);
}

// The background is added to every output, whatever the pass, and nothing else changes:
// the loss and gradients against targets + B equal those without it against the targets.
TEST(PhotometricTrunkTest, TheBackgroundIsAddedToEveryPixelAndChangesNoGradient) {
  const PhotometricTrunk plain =
      MovingTrunk(PhotometricTrunk::MarkerSampling::kSensorResolution, 2);
  PhotometricTrunk with = plain;
  Image background(plain.options().rows, plain.options().cols, 2);
  unsigned state = 3;
  for (float& v : background.data) v = static_cast<float>(0.05 * Uniform(&state));
  with.SetBackground(background);
  const PhotometricProblem p = MakePhotometricProblem(plain);
  MatrixXd shifted = p.targets;
  for (std::size_t i = 0; i < p.pixels.size(); ++i) {
    const int r = p.pixels[i] / plain.options().cols, c = p.pixels[i] % plain.options().cols;
    for (int ch = 0; ch < 2; ++ch) shifted(i, ch) += background.at(r, c, ch);
  }
  MatrixXd y_plain, y_with;
  VectorXd dz_plain, dz_with, dsiren_plain, dsiren_with, dhead_plain, dhead_with;
  const double l_plain = plain.LossAndGradient<double>(p.pixels, p.z, p.targets, p.weights,
                                                       &dz_plain, &dsiren_plain, &dhead_plain,
                                                       &y_plain);
  const double l_with = with.LossAndGradient<double>(p.pixels, p.z, shifted, p.weights,
                                                     &dz_with, &dsiren_with, &dhead_with, &y_with);
  EXPECT_NEAR(l_with, l_plain, 1e-12 + 1e-9 * l_plain);
  EXPECT_LT((dz_with - dz_plain).norm(), 1e-9 * dz_plain.norm());
  EXPECT_LT((dsiren_with - dsiren_plain).norm(), 1e-9 * dsiren_plain.norm());
  EXPECT_LT((dhead_with - dhead_plain).norm(), 1e-9 * dhead_plain.norm());
  EXPECT_LT((y_with - y_plain - (shifted - p.targets)).cwiseAbs().maxCoeff(), 1e-7);
  // Forward and the Jacobian's outputs over the whole grid add it too.
  const std::vector<int> all = plain.AllPixels();
  const MatrixXf f_plain = plain.Forward<float>(all, p.z.cast<float>());
  const MatrixXf f_with = with.Forward<float>(all, p.z.cast<float>());
  MatrixXd j_plain, j_with, o_plain, o_with;
  plain.ForwardAndLatentJacobian<double>(p.pixels, p.z, &o_plain, &j_plain);
  with.ForwardAndLatentJacobian<double>(p.pixels, p.z, &o_with, &j_with);
  EXPECT_EQ(j_with, j_plain);
  EXPECT_LT((o_with - o_plain - (shifted - p.targets)).cwiseAbs().maxCoeff(), 1e-7);
  for (int j = 0; j < static_cast<int>(all.size()); ++j) {
    for (int ch = 0; ch < 2; ++ch) {
      ASSERT_NEAR(f_with(j, ch) - f_plain(j, ch), background.data[j * 2 + ch], 1e-6) << j;
    }
  }
  // A table of another shape or with a non-finite value is refused; an empty one removes it.
  EXPECT_THROW(with.SetBackground(Image(plain.options().rows, plain.options().cols, 1)),
               std::invalid_argument);
  Image bad = background;
  bad.data[5] = std::nanf("");
  EXPECT_THROW(with.SetBackground(bad), std::invalid_argument);
  with.SetBackground(Image());
  EXPECT_TRUE(with.background().empty());
  EXPECT_EQ(with.Forward<float>(all, p.z.cast<float>()), f_plain);
}

TEST(PhotometricTrunkTest, TheLossGradientWithRespectToTheOutputsMatchesDifferences) {
  // dL/dY (the background's and the lighting images' gradient at the pixels) against
  // central differences of the loss in the targets (L depends on y - t), and the same
  // pass's other gradients unchanged by asking for it.
  const PhotometricTrunk trunk =
      MovingTrunk(PhotometricTrunk::MarkerSampling::kSensorResolution, 2);
  const PhotometricProblem p = MakePhotometricProblem(trunk);
  MatrixXd dY;
  VectorXd dz, dz_alone;
  trunk.LossAndGradient<double>(p.pixels, p.z, p.targets, p.weights, &dz, nullptr, nullptr,
                                nullptr, nullptr, &dY);
  trunk.LossAndGradient<double>(p.pixels, p.z, p.targets, p.weights, &dz_alone, nullptr,
                                nullptr);
  EXPECT_EQ(dz, dz_alone);
  ASSERT_EQ(dY.rows(), static_cast<Eigen::Index>(p.pixels.size()));
  ASSERT_EQ(dY.cols(), 2);
  const double eps = 1e-6;
  for (Eigen::Index i = 0; i < dY.rows(); ++i) {
    for (int ch = 0; ch < 2; ++ch) {
      MatrixXd up = p.targets, down = p.targets;
      up(i, ch) += eps;
      down(i, ch) -= eps;
      const double numeric =
          (trunk.LossAndGradient<double>(p.pixels, p.z, down, p.weights, nullptr, nullptr,
                                         nullptr) -
           trunk.LossAndGradient<double>(p.pixels, p.z, up, p.weights, nullptr, nullptr,
                                         nullptr)) /
          (2 * eps);
      EXPECT_NEAR(dY(i, ch), numeric, 1e-8 + 1e-5 * std::abs(numeric)) << i << " " << ch;
    }
  }
  EXPECT_EQ(dY.row(4).norm(), 0.0);  // the pixel of weight 0
}

TEST(PhotometricTrunkTest, FloatAgreesWithDouble) {
  const PhotometricTrunk trunk =
      MovingTrunk(PhotometricTrunk::MarkerSampling::kSensorResolution);
  const PhotometricProblem p = MakePhotometricProblem(trunk);
  VectorXd dz;
  VectorXf dzf;
  const double loss =
      trunk.LossAndGradient<double>(p.pixels, p.z, p.targets, p.weights, &dz, nullptr, nullptr);
  const float lossf = trunk.LossAndGradient<float>(p.pixels, p.z.cast<float>(),
                                                   p.targets.cast<float>(),
                                                   p.weights.cast<float>(), &dzf, nullptr,
                                                   nullptr);
  EXPECT_NEAR(lossf, loss, 1e-5 * loss + 1e-7);
  EXPECT_LT((dzf.cast<double>() - dz).norm(), 1e-4 * dz.norm());
}

TEST(PhotometricTrunkTest, TheWholeGridSharesNeighboursAndAgreesWithThePerPixelPass) {
  // Forward over AllPixels() evaluates the SIREN once per pixel and border pixel; the
  // same pixels in another order (or with a reverse pass to follow) take the per-pixel
  // pass with five evaluations each. Both draw the same frame, border pixels included.
  for (int channels : {1, 3}) {
    const PhotometricTrunk trunk =
        MovingTrunk(PhotometricTrunk::MarkerSampling::kSensorResolution, channels);
    const PhotometricProblem p = MakePhotometricProblem(trunk);
    const std::vector<int> all = trunk.AllPixels();
    std::vector<int> reversed(all.rbegin(), all.rend());
    const MatrixXd dense = trunk.Forward<double>(all, p.z);
    const MatrixXd per_pixel = trunk.Forward<double>(reversed, p.z).colwise().reverse();
    ASSERT_EQ(dense.rows(), static_cast<Eigen::Index>(all.size()));
    EXPECT_GT(dense.cwiseAbs().maxCoeff(), 1e-2);
    EXPECT_LT((dense - per_pixel).cwiseAbs().maxCoeff(), 1e-9) << channels << " channel(s)";
    // The loss over the whole grid without gradients takes the shared pass too.
    const MatrixXd targets = MatrixXd::Constant(all.size(), channels, 0.05);
    const VectorXd weights = VectorXd::Ones(all.size());
    VectorXd dz;
    MatrixXd outputs;
    const double shared = trunk.LossAndGradient<double>(all, p.z, targets, weights, nullptr,
                                                        nullptr, nullptr);
    const double with_gradient = trunk.LossAndGradient<double>(all, p.z, targets, weights, &dz,
                                                               nullptr, nullptr, &outputs);
    EXPECT_NEAR(shared, with_gradient, 1e-12 * with_gradient);
    EXPECT_LT((outputs - per_pixel).cwiseAbs().maxCoeff(), 1e-9);
    // The whole-grid pass caches the flat input's shading; a new head starts afresh.
    PhotometricTrunk changed = trunk;
    VectorXd head = changed.head_parameters();
    head.head(head.size() - 1) *= 1.3;
    changed.SetHeadParameters(head);
    const MatrixXd dense_changed = changed.Forward<double>(all, p.z);
    const MatrixXd per_pixel_changed =
        changed.Forward<double>(reversed, p.z).colwise().reverse();
    EXPECT_GT((dense_changed - dense).cwiseAbs().maxCoeff(), 1e-3);
    EXPECT_LT((dense_changed - per_pixel_changed).cwiseAbs().maxCoeff(), 1e-9);
  }
}

TEST(PhotometricTrunkTest, NeighbouringAndRepeatedPixelsShareEvaluationsWithTheSameGradients) {
  // A 3 x 3 block, a pixel drawn twice and a pixel on the grid's edge: their five
  // coordinate sets share grid positions, which the pass evaluates once and whose
  // gradients it sums. Each pixel alone shares nothing; the outputs must agree with the
  // single-pixel passes and the gradients with their sums (the loss is a sum over pixels).
  const PhotometricTrunk trunk =
      MovingTrunk(PhotometricTrunk::MarkerSampling::kSensorResolution, 1);
  const PhotometricProblem p = MakePhotometricProblem(trunk);
  const int cols = trunk.options().cols;
  std::vector<int> pixels;
  for (int r = 4; r < 7; ++r) {
    for (int c = 5; c < 8; ++c) pixels.push_back(r * cols + c);
  }
  pixels.push_back(5 * cols + 6);  // again
  pixels.push_back(0);             // the corner
  const int n = static_cast<int>(pixels.size());
  MatrixXd dY(n, 1);
  for (int i = 0; i < n; ++i) dY(i, 0) = 0.3 - 0.07 * i;
  const MatrixXd shared = trunk.Forward<double>(pixels, p.z);
  VectorXd dz, dsiren, dhead;
  trunk.Backward<double>(pixels, p.z, dY, &dz, &dsiren, &dhead);
  VectorXd sum_dz = VectorXd::Zero(dz.size()), sum_dsiren = VectorXd::Zero(dsiren.size()),
           sum_dhead = VectorXd::Zero(dhead.size());
  for (int i = 0; i < n; ++i) {
    const std::vector<int> one{pixels[i]};
    const MatrixXd alone = trunk.Forward<double>(one, p.z);
    EXPECT_NEAR(shared(i, 0), alone(0, 0), 1e-10) << "pixel " << pixels[i];
    VectorXd a, b, c;
    trunk.Backward<double>(one, p.z, dY.row(i), &a, &b, &c);
    sum_dz += a;
    sum_dsiren += b;
    sum_dhead += c;
  }
  EXPECT_GT(dz.cwiseAbs().maxCoeff(), 1e-4);
  EXPECT_LT((dz - sum_dz).cwiseAbs().maxCoeff(), 1e-10 * (1 + dz.cwiseAbs().maxCoeff()));
  EXPECT_LT((dsiren - sum_dsiren).cwiseAbs().maxCoeff(),
            1e-10 * (1 + dsiren.cwiseAbs().maxCoeff()));
  EXPECT_LT((dhead - sum_dhead).cwiseAbs().maxCoeff(), 1e-10 * (1 + dhead.cwiseAbs().maxCoeff()));
}

TEST(PhotometricTrunkTest, TheLatentJacobianHasTheReversePassesRows) {
  // Every row of ForwardAndLatentJacobian against the reverse pass of that one output
  // (dL/dY = e_c at pixel i alone), with three channels, moving markers, a turned
  // contact, pixels whose neighbours are other pixels of the set (shared positions) and
  // the grid's corner. The pose's columns come from the SIREN's coordinate Jacobian and
  // the code's from its shifts, so a wrong sign or a missed neighbour fails.
  // The lit trunk's last two columns are its lighting images at the pixels.
  for (const auto& [sampling, lighting] :
       {std::pair{PhotometricTrunk::MarkerSampling::kSensorResolution, 0},
        std::pair{PhotometricTrunk::MarkerSampling::kWorkingResolution, 0},
        std::pair{PhotometricTrunk::MarkerSampling::kSensorResolution, 2}}) {
    const PhotometricTrunk trunk = MovingTrunk(sampling, 3, lighting);
    const PhotometricProblem p = MakePhotometricProblem(trunk);
    const int cols = trunk.options().cols, c = trunk.channels();
    std::vector<int> pixels = p.pixels;
    for (int r = 4; r < 6; ++r) {
      for (int col = 5; col < 7; ++col) pixels.push_back(r * cols + col);
    }
    const int n = static_cast<int>(pixels.size());
    MatrixXd y, J;
    trunk.ForwardAndLatentJacobian<double>(pixels, p.z, &y, &J);
    const MatrixXd expected_y = trunk.Forward<double>(pixels, p.z);
    EXPECT_LT((y - expected_y).cwiseAbs().maxCoeff(), 1e-12);
    ASSERT_EQ(J.rows(), n * c);
    ASSERT_EQ(J.cols(), trunk.latent_dim());
    double largest_pose = 0;
    for (int i = 0; i < n; ++i) {
      for (int ch = 0; ch < c; ++ch) {
        MatrixXd dY = MatrixXd::Zero(1, c);
        dY(0, ch) = 1.0;
        VectorXd row;
        trunk.Backward<double>({pixels[i]}, p.z, dY, &row, nullptr, nullptr);
        const VectorXd got = J.row(i * c + ch).transpose();
        EXPECT_LT((got - row).cwiseAbs().maxCoeff(), 1e-9 * (1 + row.cwiseAbs().maxCoeff()))
            << "pixel " << pixels[i] << " channel " << ch;
        largest_pose = std::max(largest_pose, row.head(3).cwiseAbs().maxCoeff());
      }
    }
    EXPECT_GT(largest_pose, 1e-3);  // the pose's columns are tested, not all zero
    // The output-column layout holds the same values, transposed.
    MatrixXd JT;
    trunk.ForwardAndLatentJacobian<double>(pixels, p.z, nullptr, &JT, nullptr,
                                           JacobianLayout::kOutputColumns);
    EXPECT_EQ(JT, J.transpose());
  }
  // Without a Jacobian asked for it is Forward's pass.
  const PhotometricTrunk trunk =
      MovingTrunk(PhotometricTrunk::MarkerSampling::kSensorResolution, 1);
  const PhotometricProblem p = MakePhotometricProblem(trunk);
  MatrixXd y;
  trunk.ForwardAndLatentJacobian<double>(p.pixels, p.z, &y, nullptr);
  EXPECT_LT((y - trunk.Forward<double>(p.pixels, p.z)).cwiseAbs().maxCoeff(), 1e-12);
  EXPECT_THROW(trunk.ForwardAndLatentJacobian<double>({-1}, p.z, &y, nullptr),
               std::invalid_argument);
}

TEST(PhotometricTrunkTest, RefusesBadOptionsAndReferences) {
  PhotometricTrunk::Options o = SmallPhotometricTrunk();
  o.latent_dim = 3;
  try {
    PhotometricTrunk trunk(o, DottedReference(16, 20, 1));
    FAIL() << "latent_dim 3 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("latent_dim"), std::string::npos) << e.what();
  }
  try {
    PhotometricTrunk trunk(SmallPhotometricTrunk(), DottedReference(16, 20, 3));
    FAIL() << "a 3-channel reference accepted for 1 channel";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("16x20x3"), std::string::npos) << e.what();
  }
  const PhotometricTrunk trunk(SmallPhotometricTrunk(), DottedReference(16, 20, 1));
  EXPECT_THROW(trunk.Forward<double>({80}, VectorXd::Zero(9)), std::invalid_argument);
  EXPECT_THROW(trunk.Forward<double>({0}, VectorXd::Zero(8)), std::invalid_argument);
}

}  // namespace
}  // namespace tactfunc
