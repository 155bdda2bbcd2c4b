// Copyright 2026 The tactfunc Authors.
#include "models/simulator/pose_information.h"

#include <cmath>
#include <stdexcept>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "models/core/seed.h"
#include "tests/support/simulator_test_util.h"

namespace tactfunc {
namespace {

constexpr double kDegree = 3.14159265358979323846 / 180;

using testing_util::MakeContact;
using testing_util::Simulator;

// Render draws the noise BubbleNoiseStddev and BubbleDropoutProbability describe: the
// standardised noise of a frame has unit variance, and its dropouts come at the stated
// rate.
TEST(PoseInformationTest, TheNoiseModelIsTheOneRenderDraws) {
  const Contact contact = MakeContact("square", 1e-3, -0.5e-3, 0.3, 8e-3);
  const std::vector<float>& dropout = Simulator().BubbleDropoutProbability();
  double sum = 0, sum_sq = 0, expected_dropouts = 0;
  int read = 0, dropouts = 0;
  for (int draw = 0; draw < 4; ++draw) {
    const ContactSimulator::Rendering r =
        Simulator().Render(SensorKind::kSoftBubble, contact, DeriveSeed(11, draw));
    ASSERT_EQ(dropout.size(), r.frame.size());
    for (std::size_t i = 0; i < r.frame.size(); ++i) {
      expected_dropouts += dropout[i];
      if (std::isnan(r.frame.data[i])) {
        ++dropouts;
        continue;
      }
      const double z =
          (r.frame.data[i] - r.clean.data[i]) / Simulator().BubbleNoiseStddev(r.clean.data[i]);
      sum += z;
      sum_sq += z * z;
      ++read;
    }
  }
  // About 98,000 pixels: the variance is known to about 0.5%, the rate to about 1%.
  EXPECT_NEAR(sum / read, 0.0, 0.02);
  EXPECT_NEAR(sum_sq / read, 1.0, 0.03);
  EXPECT_NEAR(dropouts / expected_dropouts, 1.0, 0.05);
}

// The Fisher information is the covariance of the score: over noisy frames of one
// contact, sum_i (frame_i - mu_i) g_i / sigma_i^2 (the pixels read) varies by the
// information's diagonal. A wrong noise model, dropout weight or derivative scale moves
// that far more than the 400 draws' spread (about 7%).
TEST(PoseInformationTest, InformationIsTheVarianceOfTheScore) {
  const Contact contact = MakeContact("l_shape", -1e-3, 0.8e-3, 1.1, 6e-3);
  const PoseInformation info = SoftBubblePoseInformation(Simulator(), contact);
  const PoseInformationOptions steps;
  const double step[4] = {steps.position_step_m, steps.position_step_m, steps.yaw_step_rad,
                          steps.depth_step_m};
  const Image centre = Simulator().Render(SensorKind::kSoftBubble, contact, 0).clean;
  std::vector<std::vector<double>> gradient(4);
  for (int k = 0; k < 4; ++k) {
    Contact plus = contact, minus = contact;
    const SE2d& t = contact.sensor_T_object;
    const double dx = k == 0 ? step[k] : 0, dy = k == 1 ? step[k] : 0, dyaw = k == 2 ? step[k] : 0,
                 dd = k == 3 ? step[k] : 0;
    plus.sensor_T_object = SE2d::FromXYYaw(t.x() + dx, t.y() + dy, t.yaw() + dyaw);
    minus.sensor_T_object = SE2d::FromXYYaw(t.x() - dx, t.y() - dy, t.yaw() - dyaw);
    plus.depth_m += dd;
    minus.depth_m -= dd;
    const Image a = Simulator().Render(SensorKind::kSoftBubble, plus, 0).clean;
    const Image b = Simulator().Render(SensorKind::kSoftBubble, minus, 0).clean;
    for (std::size_t i = 0; i < a.size(); ++i) {
      gradient[k].push_back((static_cast<double>(a.data[i]) - b.data[i]) / (2 * step[k]));
    }
  }
  constexpr int kDraws = 400;
  Eigen::Vector4d sum_sq = Eigen::Vector4d::Zero();
  for (int draw = 0; draw < kDraws; ++draw) {
    const Image frame =
        Simulator().Render(SensorKind::kSoftBubble, contact, DeriveSeed(5, draw)).frame;
    Eigen::Vector4d score = Eigen::Vector4d::Zero();
    for (std::size_t i = 0; i < frame.size(); ++i) {
      if (std::isnan(frame.data[i])) continue;
      const double sigma = Simulator().BubbleNoiseStddev(centre.data[i]);
      const double r = (frame.data[i] - centre.data[i]) / (sigma * sigma);
      for (int k = 0; k < 4; ++k) score[k] += r * gradient[k][i];
    }
    sum_sq += score.cwiseProduct(score);
  }
  for (int k = 0; k < 4; ++k) {
    EXPECT_NEAR(sum_sq[k] / kDraws / info.fisher(k, k), 1.0, 0.2) << "parameter " << k;
  }
}

// Within the steps the bound is meant for (from a little under half a pixel to a whole
// one) it hardly moves: the position floor of each of six contacts by under a quarter,
// their RMS by under a tenth. Much smaller steps read the simulator's pixel-centre jumps
// instead (a rod's flat ends: its frame is piecewise constant along its axis), which is
// why the steps are not smaller.
TEST(PoseInformationTest, TheBoundDoesNotDependOnTheStepWithinItsRange) {
  const Contact contacts[] = {MakeContact("rod", -1e-3, 0, 0.4, 4e-3),
                              MakeContact("triangle", -0.5e-3, 0.3e-3, 1.4, 11e-3),
                              MakeContact("square", 0, 0.6e-3, 2.4, 5e-3),
                              MakeContact("lines3_40", 0.5e-3, 0.9e-3, 3.4, 3.5e-3),
                              MakeContact("lines5", 1e-3, 1.2e-3, 4.4, 8e-3),
                              MakeContact("half_disc", 1.5e-3, 1.5e-3, 5.4, 6e-3)};
  PoseInformationOptions fine, coarse;
  fine.position_step_m = fine.depth_step_m = 0.2e-3;
  fine.yaw_step_rad = 0.02;
  coarse.position_step_m = coarse.depth_step_m = 0.45e-3;
  coarse.yaw_step_rad = 0.045;
  double sum_fine = 0, sum_coarse = 0;
  for (const Contact& contact : contacts) {
    const double a = SoftBubblePoseInformation(Simulator(), contact, fine).PositionRmse();
    const double b = SoftBubblePoseInformation(Simulator(), contact, coarse).PositionRmse();
    EXPECT_NEAR(a / b, 1.0, 0.25) << contact.tool << ": " << a << " against " << b << " m";
    sum_fine += a * a;
    sum_coarse += b * b;
  }
  EXPECT_NEAR(std::sqrt(sum_fine / sum_coarse), 1.0, 0.1);
}

// The frames the product works on (area-resized to half the sensor's size) carry less
// information than the sensor's, but not much less: the signal is smooth at the scale of
// a pixel, so averaging four pixels loses little but their noise.
TEST(PoseInformationTest, HalvingTheFrameKeepsMostOfTheInformation) {
  const Contact contact = MakeContact("lines3_40", 1.5e-3, -1e-3, 2.2, 5e-3);
  const PoseInformation full = SoftBubblePoseInformation(Simulator(), contact);
  PoseInformationOptions half;
  half.rows = 70;
  half.cols = 88;
  const PoseInformation working = SoftBubblePoseInformation(Simulator(), contact, half);
  EXPECT_GE(working.PositionRmse(), 0.97 * full.PositionRmse());
  EXPECT_LE(working.PositionRmse(), 1.3 * full.PositionRmse());
  EXPECT_GE(working.YawSd(), 0.97 * full.YawSd());
  EXPECT_LE(working.YawSd(), 1.3 * full.YawSd());
}

// A deeper press shows more of the tool against the same noise: its bound is tighter.
// A hemisphere's yaw is not observable: NaN, and its position bound still finite.
TEST(PoseInformationTest, DeeperPressesSayMoreAndASymmetricYawIsLeftOut) {
  const double shallow =
      SoftBubblePoseInformation(Simulator(), MakeContact("half_disc", 0, 0, 0.7, 3.5e-3))
          .PositionRmse();
  const double deep =
      SoftBubblePoseInformation(Simulator(), MakeContact("half_disc", 0, 0, 0.7, 12e-3))
          .PositionRmse();
  EXPECT_LT(deep, shallow);
  const PoseInformation hemisphere =
      SoftBubblePoseInformation(Simulator(), MakeContact("hemisphere", 1e-3, 0, 0, 8e-3));
  EXPECT_TRUE(std::isnan(hemisphere.YawSd()));
  EXPECT_TRUE(std::isfinite(hemisphere.PositionRmse()));
  EXPECT_GT(hemisphere.PositionRmse(), 0);
  EXPECT_LE(hemisphere.PositionWorstSd(), hemisphere.PositionRmse());
}

// With the simulator's own models, a fit from a start half a millimetre and 5 degrees
// off comes back to the truth's basin on a noisy frame: within a few bound standard
// deviations of the truth, and at least as likely as the truth.
TEST(PoseInformationTest, TheSimulatorsOwnFitFindsTheTruthsBasin) {
  const Contact truth = MakeContact("triangle", 1e-3, -0.5e-3, 0.9, 7e-3);
  const Image frame = Simulator().Render(SensorKind::kSoftBubble, truth, 77).frame;
  Contact start = truth;
  start.sensor_T_object = SE2d::FromXYYaw(1.4e-3, -0.2e-3, 0.9 + 5 * kDegree);
  start.depth_m = 6.6e-3;
  const ContactFit fit = FitSoftBubbleContact(Simulator(), frame, start);
  const PoseInformation info = SoftBubblePoseInformation(Simulator(), truth);
  const SE2d& t = fit.contact.sensor_T_object;
  EXPECT_LT(std::hypot(t.x() - 1e-3, t.y() + 0.5e-3), 5 * info.PositionRmse());
  EXPECT_LT(std::abs(t.yaw() - 0.9), 5 * info.YawSd());
  EXPECT_GE(fit.log_likelihood, SoftBubbleLogLikelihood(Simulator(), frame, truth));
  EXPECT_GT(fit.log_likelihood, SoftBubbleLogLikelihood(Simulator(), frame, start));
  EXPECT_GE(fit.iterations, 1);
  // The frame must be the sensor's own size.
  EXPECT_THROW(SoftBubbleLogLikelihood(Simulator(), Image(70, 88, 1), truth),
               std::invalid_argument);
}

TEST(PoseInformationTest, RejectsBadOptions) {
  const Contact contact = MakeContact("square", 0, 0, 0, 5e-3);
  PoseInformationOptions zero_step;
  zero_step.yaw_step_rad = 0;
  EXPECT_THROW(SoftBubblePoseInformation(Simulator(), contact, zero_step), std::invalid_argument);
  PoseInformationOptions one_side;
  one_side.rows = 70;
  EXPECT_THROW(SoftBubblePoseInformation(Simulator(), contact, one_side), std::invalid_argument);
  Contact unknown = contact;
  unknown.tool = "spoon";
  EXPECT_THROW(SoftBubblePoseInformation(Simulator(), unknown), std::invalid_argument);
}

}  // namespace
}  // namespace tactfunc
