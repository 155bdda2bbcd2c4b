// Copyright 2026 The tactfunc Authors.
//
// Trunk targets and THE PSNR of tactfunc (estimation/data/trunk_targets.h): the
// definition on hand-made targets with known MSE and range, the pixels it leaves out,
// its peak, MakeTrunkTargets' layout of a frame, and the draw of a frame's pixels towards
// its contact.
#include "estimation/data/trunk_targets.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <vector>

#include "gtest/gtest.h"

#include "tests/support/image_test_util.h"

namespace tactfunc {
namespace {

using testing_util::kNaN;

// One-channel targets holding `values`, every pixel valid.
TrunkTargets Targets(std::initializer_list<float> values) {
  TrunkTargets t;
  t.values = Eigen::MatrixXf(static_cast<Eigen::Index>(values.size()), 1);
  Eigen::Index j = 0;
  for (float v : values) t.values(j++, 0) = v;
  t.weights = Eigen::VectorXf::Ones(t.values.rows());
  t.rows = 1;
  t.cols = static_cast<int>(values.size());
  return t;
}

// ---- The definition ----------------------------------------------------------------

TEST(Psnr, KnownMseAndRangeGiveTheKnownDecibels) {
  // Range R = 2 (from 0 to 2); every prediction off by 0.1: MSE = 0.01, so
  // PSNR = 10 log10(4 / 0.01) = 26.0206 dB.
  const TrunkTargets t = Targets({0.0f, 0.5f, 2.0f, 1.0f});
  const Eigen::MatrixXf p = t.values.array() + 0.1f;
  EXPECT_NEAR(Psnr(p, t), 10 * std::log10(4.0 / 0.01), 1e-4);
  EXPECT_NEAR(Psnr(p, t), 26.0206, 1e-4);
  EXPECT_NEAR(TargetRange(t), 2.0, 1e-7);
  EXPECT_NEAR(Rmse(p, t), 0.1, 1e-6);
}

TEST(Psnr, MseAveragesOverPixelsAndChannels) {
  // Two pixels x two channels; one entry off by 0.2, the rest exact: MSE = 0.04 / 4.
  TrunkTargets t;
  t.values = Eigen::MatrixXf(2, 2);
  t.values << 0.0f, 1.0f,  //
      0.5f, 0.25f;
  t.weights = Eigen::VectorXf::Ones(2);
  Eigen::MatrixXf p = t.values;
  p(1, 0) += 0.2f;
  EXPECT_NEAR(Psnr(p, t), 10 * std::log10(1.0 / (0.04 / 4)), 1e-4);  // R = 1 - 0 = 1
}

TEST(Psnr, AnExactFitIsPlusInfinity) {
  const TrunkTargets t = Targets({0.1f, -0.3f, 0.7f});
  const double psnr = Psnr(t.values, t);
  EXPECT_TRUE(std::isinf(psnr));
  EXPECT_GT(psnr, 0);
  EXPECT_EQ(Rmse(t.values, t), 0.0);
}

TEST(Psnr, InvalidPixelsAreLeftOutOfTheErrorAndTheRange) {
  // The middle pixel has weight 0: its value (which would set the range) and its
  // prediction (NaN, which would poison the error) must not count.
  TrunkTargets t = Targets({0.0f, 50.0f, 1.0f});
  t.weights(1) = 0.0f;
  Eigen::MatrixXf p = t.values;
  p(0, 0) += 0.1f;
  p(1, 0) = kNaN;
  p(2, 0) -= 0.1f;
  EXPECT_NEAR(TargetRange(t), 1.0, 1e-7);
  EXPECT_NEAR(Psnr(p, t), 10 * std::log10(1.0 / 0.01), 1e-4);
  // The same frame without the invalid pixel gives the same PSNR.
  const TrunkTargets valid_only = Targets({0.0f, 1.0f});
  Eigen::MatrixXf q(2, 1);
  q << 0.1f, 0.9f;
  EXPECT_NEAR(Psnr(p, t), Psnr(q, valid_only), 1e-9);
}

TEST(Psnr, ThePeakIsTheTargetsRangeNotItsMaximumOrOne) {
  const TrunkTargets t = Targets({0.0f, 0.5f});  // R = 0.5
  Eigen::MatrixXf p = t.values.array() + 0.05f;  // MSE = 0.0025
  const double psnr = Psnr(p, t);
  EXPECT_NEAR(psnr, 10 * std::log10(0.25 / 0.0025), 1e-4);  // 20 dB, not 26 (peak 1)

  // Shifting target and prediction together changes neither range nor error.
  TrunkTargets shifted = t;
  shifted.values.array() += 3.0f;
  EXPECT_NEAR(Psnr(p.array() + 3.0f, shifted), psnr, 1e-4);

  // Doubling the range at the same error adds 20 log10(2) = 6.02 dB.
  const TrunkTargets wider = Targets({0.0f, 1.0f});
  EXPECT_NEAR(Psnr(wider.values.array() + 0.05f, wider) - psnr, 20 * std::log10(2.0), 1e-4);
}

TEST(Psnr, ABlankTargetUsesAPeakOfOne) {
  // Range below 1e-9: R = 1, so an error of 0.1 everywhere reads 20 dB.
  const TrunkTargets t = Targets({0.3f, 0.3f, 0.3f});
  EXPECT_EQ(TargetRange(t), 0.0);
  EXPECT_NEAR(Psnr(t.values.array() + 0.1f, t), 20.0, 1e-4);
}

TEST(Psnr, NoValidPixelIsNan) {
  TrunkTargets t = Targets({0.0f, 1.0f});
  t.weights.setZero();
  EXPECT_TRUE(std::isnan(Psnr(t.values, t)));
  EXPECT_TRUE(std::isnan(PsnrSourcePeak(t.values, t)));
}

TEST(Psnr, APredictionOfAnotherShapeIsAnError) {
  const TrunkTargets t = Targets({0.0f, 1.0f, 2.0f});
  EXPECT_THROW(Psnr(Eigen::MatrixXf::Zero(2, 1), t), std::invalid_argument);
  EXPECT_THROW(Psnr(Eigen::MatrixXf::Zero(3, 2), t), std::invalid_argument);
  EXPECT_THROW(Rmse(Eigen::MatrixXf::Zero(4, 1), t), std::invalid_argument);
}

TEST(PsnrSourcePeak, DiffersFromPsnrOnlyByThePeak) {
  // A 2-pixel target of range 0.5 whose source frame had range 2: the same MSE, a
  // peak four times larger, so 20 log10(4) = 12.04 dB more.
  TrunkTargets t = Targets({0.0f, 0.5f});
  t.source_range = 2.0;
  Eigen::MatrixXf p(2, 1);
  p << 0.05f, 0.45f;
  EXPECT_NEAR(Psnr(p, t), 10 * std::log10(0.25 / 0.0025), 1e-5);
  EXPECT_NEAR(PsnrSourcePeak(p, t) - Psnr(p, t), 20 * std::log10(4.0), 1e-9);
  // No recorded source range (hand-made targets) falls back to a peak of 1.
  t.source_range = 0;
  EXPECT_NEAR(PsnrSourcePeak(p, t), 10 * std::log10(1 / 0.0025), 1e-5);
  EXPECT_TRUE(std::isinf(PsnrSourcePeak(t.values, t)));
}

TEST(Rmse, IsTheRootMeanSquareOverValidPixelsAndPsnrFollowsFromItAndTheRange) {
  // Three pixels, the middle one invalid (its huge error must not count).
  TrunkTargets t = Targets({-0.2f, 9.0f, 0.6f});
  t.weights(1) = 0.0f;
  Eigen::MatrixXf p(3, 1);
  p << -0.1f, -50.0f, 0.4f;
  EXPECT_NEAR(TargetRange(t), 0.8, 1e-6);
  EXPECT_NEAR(Rmse(p, t), std::sqrt((0.01 + 0.04) / 2), 1e-6);
  EXPECT_NEAR(Psnr(p, t), 20 * std::log10(TargetRange(t) / Rmse(p, t)), 1e-5);
  // No valid pixel: no range, no error.
  t.weights.setZero();
  EXPECT_EQ(TargetRange(t), 0.0);
  EXPECT_TRUE(std::isnan(Rmse(p, t)));
}

// ---- MakeTrunkTargets ----------------------------------------------------------------

// A 4x6 Soft Bubble pair: a flat reference at 50 mm, the frame pressed in by
// (row + col) x 0.1 mm, one dropped-out (NaN) pixel at row 1, col 2.
struct BubblePair {
  Image reference{4, 6, 1, 0.05f};
  Image frame{4, 6, 1, 0.05f};
  BubblePair() {
    for (int r = 0; r < frame.rows; ++r) {
      for (int c = 0; c < frame.cols; ++c) frame.at(r, c) -= 1e-4f * (r + c);
    }
    frame.at(1, 2) = kNaN;
  }
};

FrameFormat FixedScale(double scale) {
  FrameFormat format;
  format.rows = 4;
  format.cols = 6;
  format.scale = scale;
  return format;
}

TEST(MakeTrunkTargets, OneRowPerPixelInRowMajorOrderWithAValidityWeight) {
  const BubblePair pair;
  const TrunkTargets t =
      MakeTrunkTargets(pair.frame, pair.reference, SensorKind::kSoftBubble, FixedScale(1e-3));
  ASSERT_EQ(t.values.rows(), 24);
  ASSERT_EQ(t.values.cols(), 1);
  ASSERT_EQ(t.weights.size(), 24);
  EXPECT_EQ(t.rows, 4);
  EXPECT_EQ(t.cols, 6);
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 6; ++c) {
      const int j = r * 6 + c;
      if (r == 1 && c == 2) {
        EXPECT_EQ(t.weights(j), 0.0f);
        EXPECT_EQ(t.values(j, 0), 0.0f) << "invalid pixels hold 0";
      } else {
        EXPECT_EQ(t.weights(j), 1.0f) << j;
        // Depth difference reference - frame, in units of the 1 mm scale.
        EXPECT_NEAR(t.values(j, 0) * t.scale + t.offset, 1e-4 * (r + c), 1e-7) << j;
      }
    }
  }
}

TEST(MakeTrunkTargets, PsnrDoesNotDependOnTheNormalisation) {
  // The same frame under a fixed 1 mm scale and under per-image min-max; the same
  // physical prediction (the truth plus a pattern of physical errors) in each
  // normalisation's units must give the same PSNR.
  const BubblePair pair;
  const TrunkTargets fixed =
      MakeTrunkTargets(pair.frame, pair.reference, SensorKind::kSoftBubble, FixedScale(1e-3));
  FrameFormat min_max = FixedScale(1e-3);
  min_max.per_image_min_max = true;
  const TrunkTargets normalised =
      MakeTrunkTargets(pair.frame, pair.reference, SensorKind::kSoftBubble, min_max);
  ASSERT_NE(fixed.scale, normalised.scale);
  Eigen::MatrixXf p_fixed(24, 1), p_normalised(24, 1);
  for (int j = 0; j < 24; ++j) {
    const double physical = fixed.values(j, 0) * fixed.scale + fixed.offset +
                            2e-5 * ((j % 3) - 1);
    p_fixed(j, 0) = static_cast<float>((physical - fixed.offset) / fixed.scale);
    p_normalised(j, 0) = static_cast<float>((physical - normalised.offset) / normalised.scale);
  }
  const double psnr = Psnr(p_fixed, fixed);
  EXPECT_TRUE(std::isfinite(psnr));
  EXPECT_NEAR(Psnr(p_normalised, normalised), psnr, 1e-3);
}

TEST(TargetsToImage, InvertsTheRowPerPixelLayout) {
  Eigen::MatrixXf values(6, 2);  // 2x3 pixels, 2 channels
  for (int j = 0; j < 6; ++j) values.row(j) << j, 10 + j;
  const Image image = TargetsToImage(values, 2, 3);
  EXPECT_EQ(image.rows, 2);
  EXPECT_EQ(image.cols, 3);
  EXPECT_EQ(image.channels, 2);
  EXPECT_EQ(image.at(1, 2, 0), 5.0f);
  EXPECT_EQ(image.at(1, 2, 1), 15.0f);
  EXPECT_EQ(image.at(0, 1, 1), 11.0f);
  EXPECT_THROW(TargetsToImage(values, 3, 3), std::invalid_argument);
}

// ---- Drawing towards the contact -----------------------------------------------------

TEST(ContactDrawProbabilities, MixEvenAndEnergyWeightedAndSumToOne) {
  TrunkTargets t = Targets({0, 0, 1, 0, 2, 0, 0, 0});
  t.weights[4] = 0.5f;  // weighted energies: 0, 0, 1, 0, 2, 0, 0, 0 (sum 3)
  const std::vector<int> all{0, 1, 2, 3, 4, 5, 6, 7};
  const std::vector<double> p = ContactDrawProbabilities(t, all, 0.6);
  ASSERT_EQ(p.size(), 8u);
  EXPECT_NEAR(p[0], 0.4 / 8, 1e-15);
  EXPECT_NEAR(p[2], 0.4 / 8 + 0.6 * 1 / 3, 1e-15);
  EXPECT_NEAR(p[4], 0.4 / 8 + 0.6 * 2 / 3, 1e-15);
  EXPECT_NEAR(std::accumulate(p.begin(), p.end(), 0.0), 1.0, 1e-15);
  // Over a subset, the subset's energies alone.
  const std::vector<double> q = ContactDrawProbabilities(t, {1, 2}, 1.0);
  EXPECT_EQ(q, (std::vector<double>{0.0, 1.0}));
  // No energy (or no finite energy): evenly.
  for (float v : {0.0f, std::numeric_limits<float>::infinity()}) {
    TrunkTargets blank = Targets({0, 0, 0, 0});
    blank.values(1, 0) = v;
    for (double pi : ContactDrawProbabilities(blank, {0, 1, 2, 3}, 0.9)) EXPECT_EQ(pi, 0.25);
  }
}

TEST(ContactSample, ItsWeightedEnergyEstimatesTheFramesWithoutBias) {
  TrunkTargets t = Targets({0.1f, 0, 3, 0.2f, 0, 1, 0, 0.5f, 0, 0, 2, 0});
  const double total = t.values.squaredNorm();
  for (double share : {0.0, 0.5, 1.0}) {
    std::vector<int> pixels(12);
    std::iota(pixels.begin(), pixels.end(), 0);
    std::vector<double> factor;
    ContactSample(t, 6, share, &pixels, &factor);
    ASSERT_EQ(pixels.size(), factor.size());
    ASSERT_FALSE(pixels.empty());
    EXPECT_TRUE(std::is_sorted(pixels.begin(), pixels.end()));
    double estimate = 0;
    for (size_t i = 0; i < pixels.size(); ++i) {
      estimate += factor[i] * t.values.row(pixels[i]).squaredNorm();
    }
    // At share 1 the draw is proportional to the energy: the estimate is exact.
    if (share == 1.0) {
      EXPECT_NEAR(estimate, 6.0 / 12 * total, 1e-5);
    }
    // Evenly (share 0): 6 pixels, each weighing 1.
    if (share == 0.0) {
      EXPECT_EQ(pixels.size(), 6u);
      for (double f : factor) EXPECT_NEAR(f, 1.0, 1e-12);
    }
  }
  // The contact gets most of the draws at share 1: pixels without energy are never drawn.
  std::vector<int> pixels(12);
  std::iota(pixels.begin(), pixels.end(), 0);
  std::vector<double> factor;
  ContactSample(t, 6, 1.0, &pixels, &factor);
  for (int j : pixels) EXPECT_GT(t.values(j, 0), 0.0f) << "pixel " << j;
}

TEST(ContactDraw, TheGuideDrawsThePixelTheBinarySearchDraws) {
  // A draw with zero-probability pixels (share 1), pixels that hold most of the mass,
  // and the uniforms that land on the cumulative sums themselves, just beside them, and
  // at the ends.
  TrunkTargets t = Targets({0, 0, 3, 0.2f, 0, 1, 0, 0.5f, 0, 0, 2, 0, 0, 0, 0.01f, 0});
  for (double share : {0.0, 0.5, 1.0}) {
    const ContactDraw plain(t, share, /*with_guide=*/false);
    const ContactDraw guided(t, share, /*with_guide=*/true);
    ASSERT_EQ(guided.guide.size(), 16u);
    ASSERT_EQ(plain.cdf, guided.cdf);
    EXPECT_EQ(guided.cdf.back(), 1.0);
    std::vector<double> us{0.0, std::nextafter(1.0, 0.0)};
    for (double c : guided.cdf) {
      us.insert(us.end(), {c, std::nextafter(c, 0.0), std::nextafter(c, 1.0)});
    }
    for (int b = 0; b <= 16; ++b) us.push_back(b / 16.0);
    for (int i = 0; i < 1000; ++i) us.push_back((i + 0.5) / 1000);
    for (double u : us) {
      if (!(u >= 0 && u < 1)) continue;
      const int j = plain.Pixel(u);
      EXPECT_EQ(guided.Pixel(u), j) << "share " << share << ", u " << u;
      // The first pixel whose cumulative probability exceeds u.
      EXPECT_GT(guided.cdf[j], u);
      if (j > 0) {
        EXPECT_LE(guided.cdf[j - 1], u);
      }
    }
    // Share 1: a pixel without energy is never drawn.
    if (share == 1.0) {
      for (int i = 0; i < 1000; ++i) EXPECT_GT(t.values(guided.Pixel((i + 0.5) / 1000), 0), 0);
    }
  }
}

}  // namespace
}  // namespace tactfunc
