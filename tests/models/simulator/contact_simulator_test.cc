// Copyright 2026 The tactfunc Authors.
#include "models/simulator/contact_simulator.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <stdexcept>
#include <string>
#include <thread>

#include "gtest/gtest.h"
#include "models/core/internal/checks.h"
#include "models/simulator/internal/membrane.h"
#include "tests/support/simulator_test_util.h"

namespace tactfunc {
namespace {

using internal::kPi;

using testing_util::MakeContact;
using testing_util::Simulator;

// Per-pixel change from the reference, summed over channels: how far the membrane came
// towards the camera (bubble, metres) or |intensity change| (GelSlim).
std::vector<double> Change(SensorKind sensor, const Image& clean) {
  const Image& reference = Simulator().Reference(sensor);
  std::vector<double> change(clean.pixels(), 0.0);
  for (std::size_t p = 0; p < clean.pixels(); ++p) {
    for (int k = 0; k < clean.channels; ++k) {
      const std::size_t i = p * clean.channels + k;
      change[p] += sensor == SensorKind::kSoftBubble
                       ? reference.data[i] - clean.data[i]
                       : std::abs(clean.data[i] - reference.data[i]);
    }
  }
  return change;
}

struct Moments {
  double mass = 0, x = 0, y = 0, xx = 0, xy = 0, yy = 0;
  // Direction of the principal axis, radians in (-pi/2, pi/2].
  double axis() const { return 0.5 * std::atan2(2.0 * xy, xx - yy); }
};

// Centroid (sensor frame, metres) and central second moments of the contact in a
// change map. The GelSlim's change is local, so all of it counts; the bubble's
// membrane dents most of the frame and is clamped at the rectangular rim, so only
// the part within half the peak of the deepest point (where the membrane wraps the
// tool) counts.
Moments ComputeMoments(SensorKind sensor, const Image& clean) {
  const std::vector<double> change = Change(sensor, clean);
  const double floor = sensor == SensorKind::kSoftBubble
                           ? 0.5 * *std::max_element(change.begin(), change.end())
                           : 0.0;
  const double pitch = Simulator().PixelPitch(sensor);
  Moments m;
  for (int r = 0; r < clean.rows; ++r) {
    for (int c = 0; c < clean.cols; ++c) {
      const double w =
          std::max(0.0, change[static_cast<std::size_t>(r) * clean.cols + c] - floor);
      const double x = (c + 0.5 - 0.5 * clean.cols) * pitch;
      const double y = (0.5 * clean.rows - r - 0.5) * pitch;
      m.mass += w;
      m.x += w * x;
      m.y += w * y;
      m.xx += w * x * x;
      m.xy += w * x * y;
      m.yy += w * y * y;
    }
  }
  m.x /= m.mass;
  m.y /= m.mass;
  m.xx = m.xx / m.mass - m.x * m.x;
  m.xy = m.xy / m.mass - m.x * m.y;
  m.yy = m.yy / m.mass - m.y * m.y;
  return m;
}

double LargestDifference(const Image& a, const Image& b) {
  double largest = 0.0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    largest = std::max(largest, static_cast<double>(std::abs(a.data[i] - b.data[i])));
  }
  return largest;
}

bool BitIdentical(const Image& a, const Image& b) {
  return a.SameShape(b) &&
         std::memcmp(a.data.data(), b.data.data(), a.size() * sizeof(float)) == 0;
}

const SensorKind kSensors[] = {SensorKind::kSoftBubble, SensorKind::kGelSlim};
// A typical press per sensor.
double Depth(SensorKind sensor) { return sensor == SensorKind::kSoftBubble ? 8e-3 : 0.8e-3; }

TEST(SoftBubbleOptions, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(SoftBubbleOptions().IsValid(&error)) << error;
}

TEST(GelSlimOptions, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(GelSlimOptions().IsValid(&error)) << error;
}

TEST(ContactSamplingOptions, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(ContactSamplingOptions().IsValid(&error)) << error;
}

TEST(ContactSimulatorOptions, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(ContactSimulator::Options().IsValid(&error)) << error;
}

TEST(ContactSimulatorOptions, BadOptionsNameTheField) {
  std::string error;
  ContactSimulator::Options options;
  options.bubble.pixel_pitch_m = 0.0;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("pixel_pitch_m"), std::string::npos) << error;

  options = ContactSimulator::Options();
  options.bubble.apex_depth_m = 70e-3;  // deeper than 16-bit micrometres can hold
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("apex_depth_m"), std::string::npos) << error;

  options = ContactSimulator::Options();
  options.gelslim.marker_radius_m = 1.0;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("marker_radius_m"), std::string::npos) << error;

  options = ContactSimulator::Options();
  options.sampling.gelslim_depth_min_m = 2e-3;  // above the maximum
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("gelslim_depth_min_m"), std::string::npos) << error;

  options = ContactSimulator::Options();
  options.sampling.bubble_depth_min_m = -1e-3;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("bubble_depth_min_m"), std::string::npos) << error;
}

TEST(ContactSimulator, ConstructorThrowsWithTheBadField) {
  ContactSimulator::Options options;
  options.gelslim.noise_stddev = -1.0;
  try {
    ContactSimulator simulator(options);
    FAIL() << "no exception";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("noise_stddev"), std::string::npos) << e.what();
  }
}

TEST(ContactSimulator, ReferencesHaveTheDocumentedShapesAndPitches) {
  const Image& bubble = Simulator().Reference(SensorKind::kSoftBubble);
  const Image& gel = Simulator().Reference(SensorKind::kGelSlim);
  EXPECT_EQ(bubble.ShapeString(), "140x175x1");
  EXPECT_EQ(gel.ShapeString(), "320x427x3");
  EXPECT_DOUBLE_EQ(Simulator().PixelPitch(SensorKind::kSoftBubble), 0.45e-3);
  EXPECT_DOUBLE_EQ(Simulator().PixelPitch(SensorKind::kGelSlim), 0.07e-3);
}

TEST(ContactSimulator, BubbleReferenceIsADomeThatFitsIn16BitMicrometres) {
  const Image& bubble = Simulator().Reference(SensorKind::kSoftBubble);
  for (float d : bubble.data) {
    ASSERT_GT(d, 0.0f);
    ASSERT_LT(d, 65.535e-3f);
  }
  // The apex (centre) is farthest from the camera; the rim comes closer.
  EXPECT_GT(bubble.at(70, 87), bubble.at(70, 5));
  EXPECT_GT(bubble.at(70, 87), bubble.at(5, 87));
  EXPECT_GT(bubble.at(70, 5), bubble.at(0, 0));
}

TEST(ContactSimulator, GelSlimReferenceShowsTheMarkerGrid) {
  const Image& gel = Simulator().Reference(SensorKind::kGelSlim);
  double sum = 0, sum2 = 0, lowest = 1, highest = 0;
  for (float v : gel.data) {
    sum += v;
    sum2 += v * v;
    lowest = std::min<double>(lowest, v);
    highest = std::max<double>(highest, v);
  }
  const double mean = sum / gel.size();
  EXPECT_GT(std::sqrt(sum2 / gel.size() - mean * mean), 0.05);
  EXPECT_GE(lowest, 0.0);
  EXPECT_LE(highest, 1.0);
  EXPECT_LT(lowest, 0.5 * mean);  // the dark dots
}

TEST(ContactSimulator, SameSeedGivesBitIdenticalFramesAndOtherSeedsOtherNoise) {
  for (SensorKind sensor : kSensors) {
    SCOPED_TRACE(ToString(sensor));
    const Contact contact = MakeContact("lines3_40", 1e-3, -0.5e-3, 0.7, Depth(sensor));
    const auto a = Simulator().Render(sensor, contact, 42);
    const auto b = Simulator().Render(sensor, contact, 42);
    const auto c = Simulator().Render(sensor, contact, 43);
    EXPECT_TRUE(BitIdentical(a.frame, b.frame));
    EXPECT_TRUE(BitIdentical(a.clean, b.clean));
    EXPECT_TRUE(BitIdentical(a.clean, c.clean));
    EXPECT_FALSE(BitIdentical(a.frame, c.frame));
  }
}

TEST(ContactSimulator, RendersTheSameFramesConcurrentlyAsSerially) {
  const Contact contact = MakeContact("triangle", 0.0, 1e-3, 0.2, 0.6e-3);
  const auto serial = Simulator().Render(SensorKind::kGelSlim, contact, 5);
  ContactSimulator::Rendering parallel[2];
  std::thread first([&] { parallel[0] = Simulator().Render(SensorKind::kGelSlim, contact, 5); });
  std::thread second([&] { parallel[1] = Simulator().Render(SensorKind::kGelSlim, contact, 5); });
  first.join();
  second.join();
  EXPECT_TRUE(BitIdentical(serial.frame, parallel[0].frame));
  EXPECT_TRUE(BitIdentical(serial.frame, parallel[1].frame));
}

TEST(ContactSimulator, BubbleFramesHaveDropoutsAndCleanFramesNone) {
  const auto r = Simulator().Render(SensorKind::kSoftBubble,
                                    MakeContact("rod", 0.0, 0.0, 0.0, 5e-3), 1);
  int nan_frame = 0, nan_clean = 0;
  for (float d : r.frame.data) nan_frame += std::isnan(d);
  for (float d : r.clean.data) nan_clean += std::isnan(d);
  EXPECT_GT(nan_frame, 0);
  EXPECT_LT(nan_frame, static_cast<int>(r.frame.size() / 10));
  EXPECT_EQ(nan_clean, 0);
  for (float d : r.frame.data) {
    if (!std::isnan(d)) {
      ASSERT_LT(d, 65.535e-3f);
    }
  }
}

TEST(ContactSimulator, GelSlimFramesStayInTheUnitRange) {
  const auto r = Simulator().Render(SensorKind::kGelSlim,
                                    MakeContact("lines5", 0.0, 0.0, 0.4, 1.5e-3), 1);
  for (const Image* image : {&r.frame, &r.clean}) {
    for (float v : image->data) {
      ASSERT_GE(v, 0.0f);
      ASSERT_LE(v, 1.0f);
    }
  }
}

TEST(ContactSimulator, NoPressLeavesTheReference) {
  for (SensorKind sensor : kSensors) {
    const auto r = Simulator().Render(sensor, MakeContact("square", 1e-3, 0.0, 0.3, 0.0), 9);
    EXPECT_TRUE(BitIdentical(r.clean, Simulator().Reference(sensor))) << ToString(sensor);
  }
}

TEST(ContactSimulator, GelSlimIsUnchangedFarFromTheContact) {
  // A hemisphere pressed 0.5 mm at x = -8 mm touches a disc of radius ~2.4 mm; the
  // right half of the frame (x > 0) is more than 5 gel decay lengths away.
  const auto r = Simulator().Render(SensorKind::kGelSlim,
                                    MakeContact("hemisphere", -8e-3, 0.0, 0.0, 0.5e-3), 3);
  const Image& reference = Simulator().Reference(SensorKind::kGelSlim);
  double far = 0.0, near = 0.0;
  for (int row = 0; row < r.clean.rows; ++row) {
    for (int col = 0; col < r.clean.cols; ++col) {
      for (int k = 0; k < 3; ++k) {
        const double d = std::abs(r.clean.at(row, col, k) - reference.at(row, col, k));
        (col > r.clean.cols / 2 ? far : near) = std::max(col > r.clean.cols / 2 ? far : near, d);
      }
    }
  }
  EXPECT_EQ(far, 0.0);
  EXPECT_GT(near, 0.1);
}

TEST(ContactSimulator, BubbleChangeFadesFarFromTheContact) {
  const auto r = Simulator().Render(SensorKind::kSoftBubble,
                                    MakeContact("hemisphere", -20e-3, 0.0, 0.0, 6e-3), 3);
  const std::vector<double> change = Change(SensorKind::kSoftBubble, r.clean);
  const int row = r.clean.rows / 2;
  const int contact_col = static_cast<int>(-20e-3 / 0.45e-3 + 0.5 * r.clean.cols);
  const double at_contact = change[row * r.clean.cols + contact_col];
  EXPECT_NEAR(at_contact, 6e-3, 0.5e-3);
  EXPECT_LT(change[row * r.clean.cols + r.clean.cols - 1], 0.05 * at_contact);
}

TEST(ContactSimulator, ContactCentroidFollowsThePosition) {
  for (SensorKind sensor : kSensors) {
    SCOPED_TRACE(ToString(sensor));
    const double pitch = Simulator().PixelPitch(sensor);
    const Moments a = ComputeMoments(
        sensor, Simulator().Render(sensor, MakeContact("half_disc", -1e-3, 0.5e-3, 0.3,
                                                       Depth(sensor)), 0).clean);
    const Moments b = ComputeMoments(
        sensor, Simulator().Render(sensor, MakeContact("half_disc", 1.5e-3, -1.5e-3, 0.3,
                                                       Depth(sensor)), 0).clean);
    EXPECT_NEAR(b.x - a.x, 2.5e-3, 2.0 * pitch);
    EXPECT_NEAR(b.y - a.y, -2.0e-3, 2.0 * pitch);
  }
}

TEST(ContactSimulator, RodContactAxisFollowsTheYaw) {
  for (SensorKind sensor : kSensors) {
    SCOPED_TRACE(ToString(sensor));
    for (double yaw : {0.0, 0.5, -0.6, 2.7}) {
      const Moments m = ComputeMoments(
          sensor,
          Simulator().Render(sensor, MakeContact("rod", 0.0, 0.0, yaw, Depth(sensor)), 0).clean);
      EXPECT_LT(YawErrorModuloSymmetry(m.axis(), yaw, 2), 3.0 * kPi / 180.0) << yaw;
    }
  }
}

TEST(ContactSimulator, DeeperPressGivesLargerContactAndLargerChange) {
  for (SensorKind sensor : kSensors) {
    SCOPED_TRACE(ToString(sensor));
    const double base = Depth(sensor);
    // Contact area: pixels that changed by a tenth of the shallowest press (bubble)
    // or by 0.05 in intensity (GelSlim).
    const double threshold = sensor == SensorKind::kSoftBubble ? 0.05 * base : 0.05;
    double last_area = -1, last_peak = -1, last_total = -1;
    for (double depth : {0.5 * base, base, 1.5 * base}) {
      const std::vector<double> change = Change(
          sensor,
          Simulator().Render(sensor, MakeContact("l_shape", 0.0, 0.0, 1.0, depth), 0).clean);
      double area = 0, peak = 0, total = 0;
      for (double c : change) {
        area += c > threshold;
        peak = std::max(peak, c);
        total += c;
      }
      EXPECT_GT(area, last_area) << depth;
      EXPECT_GT(total, last_total) << depth;
      if (sensor == SensorKind::kSoftBubble) {
        EXPECT_GT(peak, last_peak) << depth;
        EXPECT_NEAR(peak, depth, 0.02 * depth);  // the membrane reaches the press depth
      }
      last_area = area;
      last_peak = peak;
      last_total = total;
    }
  }
}

TEST(ContactSimulator, SymmetricToolsRenderTheSameUnderTheirSymmetry) {
  for (SensorKind sensor : kSensors) {
    const double tolerance = sensor == SensorKind::kSoftBubble ? 1e-8 : 1e-5;
    for (const Tool& tool : ToolSet()) {
      const int n = tool.symmetry_order();
      if (n < 2) continue;
      SCOPED_TRACE(std::string(ToString(sensor)) + " " + tool.name());
      const double yaw = 0.4;
      const auto a = Simulator().Render(
          sensor, MakeContact(tool.name(), 0.5e-3, -0.3e-3, yaw, Depth(sensor)), 0);
      const auto b = Simulator().Render(
          sensor, MakeContact(tool.name(), 0.5e-3, -0.3e-3, yaw + 2.0 * kPi / n, Depth(sensor)),
          0);
      EXPECT_LT(LargestDifference(a.clean, b.clean), tolerance);
    }
  }
}

TEST(ContactSimulator, AsymmetricToolsDoNotRenderTheSameUnderAHalfTurn) {
  for (SensorKind sensor : kSensors) {
    for (const char* name : {"l_shape", "half_disc", "lines3_20"}) {
      SCOPED_TRACE(std::string(ToString(sensor)) + " " + name);
      const auto a = Simulator().Render(sensor, MakeContact(name, 0.0, 0.0, 0.4, Depth(sensor)), 0);
      const auto b =
          Simulator().Render(sensor, MakeContact(name, 0.0, 0.0, 0.4 + kPi, Depth(sensor)), 0);
      EXPECT_GT(LargestDifference(a.clean, b.clean),
                sensor == SensorKind::kSoftBubble ? 1e-3 : 0.1);
    }
  }
}

TEST(ContactSimulator, RenderRejectsUnknownToolsAndBadDepths) {
  EXPECT_THROW(Simulator().Render(SensorKind::kGelSlim, MakeContact("spoon", 0, 0, 0, 1e-3), 0),
               std::invalid_argument);
  EXPECT_THROW(Simulator().Render(SensorKind::kSoftBubble, MakeContact("rod", 0, 0, 0, -1e-3), 0),
               std::invalid_argument);
  EXPECT_THROW(Simulator().Render(SensorKind::kGelSlim,
                                  MakeContact("rod", 0, 0, 0, std::nan("")), 0),
               std::invalid_argument);
  EXPECT_THROW(Simulator().Render(SensorKind::kGelSlim,
                                  MakeContact("rod", INFINITY, 0, 0, 1e-3), 0),
               std::invalid_argument);
}

TEST(ContactSimulator, SamplesOnePoseForBothSensorsAndOnePressFraction) {
  const ContactSamplingOptions& o = Simulator().options().sampling;
  for (std::uint64_t seed = 0; seed < 200; ++seed) {
    const PairedContact p = Simulator().SamplePairedContact("rod", seed);
    EXPECT_EQ(p.bubble.tool, "rod");
    EXPECT_EQ(p.gelslim.tool, "rod");
    const SE2d& pose = p.bubble.sensor_T_object;
    EXPECT_EQ(pose.x(), p.gelslim.sensor_T_object.x());
    EXPECT_EQ(pose.y(), p.gelslim.sensor_T_object.y());
    EXPECT_EQ(pose.yaw(), p.gelslim.sensor_T_object.yaw());
    EXPECT_GE(pose.x(), o.x_min_m);
    EXPECT_LE(pose.x(), o.x_max_m);
    EXPECT_GE(pose.y(), o.y_min_m);
    EXPECT_LE(pose.y(), o.y_max_m);
    EXPECT_GE(pose.yaw(), -kPi);
    EXPECT_LT(pose.yaw(), kPi);
    const double fb = (p.bubble.depth_m - o.bubble_depth_min_m) /
                      (o.bubble_depth_max_m - o.bubble_depth_min_m);
    const double fg = (p.gelslim.depth_m - o.gelslim_depth_min_m) /
                      (o.gelslim_depth_max_m - o.gelslim_depth_min_m);
    EXPECT_GE(fb, 0.0);
    EXPECT_LE(fb, 1.0);
    EXPECT_NEAR(fb, fg, 1e-9);
  }
}

TEST(ContactSimulator, SamplingIsDeterministicInTheSeed) {
  const PairedContact a = Simulator().SamplePairedContact("square", 11);
  const PairedContact b = Simulator().SamplePairedContact("square", 11);
  const PairedContact c = Simulator().SamplePairedContact("square", 12);
  EXPECT_EQ(a.bubble.sensor_T_object.x(), b.bubble.sensor_T_object.x());
  EXPECT_EQ(a.gelslim.depth_m, b.gelslim.depth_m);
  EXPECT_NE(a.bubble.sensor_T_object.x(), c.bubble.sensor_T_object.x());
  EXPECT_THROW(Simulator().SamplePairedContact("spoon", 1), std::invalid_argument);
}

// The cascadic multigrid with its default schedule against a solve run to
// convergence (thousands of sweeps on every level): the approximation the renderer
// makes for speed, bounded.
TEST(MembraneSolver, MatchesAFullyConvergedSolveWithinAFewPercentOfThePress) {
  const int rows = 120, cols = 160;
  std::vector<float> obstacle(rows * cols, 0.0f);
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      const double d = std::abs((r - 60) * 0.6 - (c - 80) * 0.8);
      if (d < 3 && std::abs(c - 80) < 40) obstacle[r * cols + c] = 1.0f - d * d / 18;
      if (std::hypot(r - 30, c - 130) < 3) obstacle[r * cols + c] = 0.8f;
    }
  }
  for (double decay_px : {14.0, 33.0}) {
    SCOPED_TRACE(decay_px);
    std::vector<float> fast, converged;
    internal::SolveMembraneObstacle(obstacle, rows, cols, decay_px,
                                    internal::MembraneSchedule(), &fast);
    internal::MembraneSchedule slow;
    slow.coarsest_sweeps = slow.coarse_sweeps = slow.finest_sweeps = 4000;
    internal::SolveMembraneObstacle(obstacle, rows, cols, decay_px, slow, &converged);
    double largest = 0, mean = 0;
    for (std::size_t i = 0; i < fast.size(); ++i) {
      ASSERT_GE(fast[i], obstacle[i]);
      ASSERT_GE(converged[i], obstacle[i]);
      largest = std::max(largest, static_cast<double>(std::abs(fast[i] - converged[i])));
      mean += std::abs(fast[i] - converged[i]) / fast.size();
    }
    EXPECT_LT(largest, 0.10);
    EXPECT_LT(mean, 0.035);
    // The surface spreads beyond the contact, decaying with distance.
    EXPECT_GT(converged[60 * cols + 125], 0.05f);
    EXPECT_LT(converged[60 * cols + 125], converged[60 * cols + 110]);
  }
}

}  // namespace
}  // namespace tactfunc
