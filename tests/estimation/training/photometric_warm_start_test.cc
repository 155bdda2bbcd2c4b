// Copyright 2026 The tactfunc Authors.
//
// PhotometricWarmStart: the descriptor does not change when a contact moves or turns
// on the grid (it is taken in the moment frame); a table built from frames and their
// latents gives a frame of the table back its own latent, and a frame turned by pi the
// latent turned by pi; BestStart picks the candidate with the lower loss; a short fit
// from the table's start reaches a lower loss than the same fit from the moment pose;
// bad options, latents and tables are refused by name.
#include "estimation/training/photometric_warm_start.h"

#include <cmath>
#include <limits>
#include <stdexcept>
#include <string>
#include <vector>

#include "estimation/training/photometric_trainer.h"
#include "gtest/gtest.h"
#include "models/core/internal/checks.h"
#include "models/core/se2.h"
#include "tests/support/photometric_test_util.h"

namespace tactfunc {
namespace {

using internal::kPi;

PhotometricTrunk::Options WarmStartTrunk() { return testing_util::SmallPhotometricOptions(24, 32); }

using testing_util::MarkerReference;
using testing_util::WholeFrameTargets;

// An elongated blob (3 x 1 pixels' scale) centred at (row0, col0), its long axis along
// the columns, with a bump at its right end so that the two turns differ.
TrunkTargets Blob(int rows, int cols, double row0, double col0) {
  Eigen::MatrixXf values(rows * cols, 1);
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      const double dr = r - row0, dc = c - col0;
      values(r * cols + c, 0) =
          static_cast<float>(std::exp(-(dc * dc / 18.0 + dr * dr / 2.0)) +
                             0.5 * std::exp(-((dc - 3) * (dc - 3) + dr * dr) / 1.5));
    }
  }
  return WholeFrameTargets(values, rows, cols);
}

// The same frame turned by pi about the grid's centre (pixel (r, c) -> (R-1-r, C-1-c)).
TrunkTargets TurnedByPi(const TrunkTargets& frame) {
  TrunkTargets out = frame;
  const Eigen::Index n = frame.values.rows();
  for (Eigen::Index j = 0; j < n; ++j) out.values.row(n - 1 - j) = frame.values.row(j);
  return out;
}

TEST(PhotometricWarmStartTest, TheDescriptorFollowsTheContactAcrossTheGrid) {
  const PhotometricTrunk::Options o = WarmStartTrunk();
  const PhotometricTrunk trunk(o, MarkerReference(2 * o.rows, 2 * o.cols), 1);
  PhotometricWarmStart::Options options;
  options.grid = 8;
  options.extent = 0.6;
  const TrunkTargets a = Blob(o.rows, o.cols, 11.0, 14.0);
  const TrunkTargets moved = Blob(o.rows, o.cols, 13.0, 17.0);  // whole pixels away
  const TrunkTargets turned = TurnedByPi(a);
  const Eigen::VectorXf da =
      PhotometricWarmStart::Descriptor(trunk, a, MomentPose(trunk, a), options);
  const Eigen::VectorXf dm =
      PhotometricWarmStart::Descriptor(trunk, moved, MomentPose(trunk, moved), options);
  ASSERT_EQ(da.size(), 64);
  EXPECT_GT(da.norm(), 1.0);
  EXPECT_LT((da - dm).norm(), 1e-3 * da.norm());
  // Turned by pi, the moment angle is the same modulo pi and the descriptor is the
  // original's in reverse cell order (or the original itself, if atan2 turned it back).
  const Eigen::VectorXf dt =
      PhotometricWarmStart::Descriptor(trunk, turned, MomentPose(trunk, turned), options);
  const Eigen::VectorXf reversed = da.reverse();
  EXPECT_LT(std::min((dt - reversed).norm(), (dt - da).norm()), 1e-3 * da.norm());
  // The bump makes the two turns differ, so the flipped lookup matters.
  EXPECT_GT((da - reversed).norm(), 0.1 * da.norm());
}

struct Table {
  PhotometricTrunk trunk;
  std::vector<TrunkTargets> frames;
  Eigen::MatrixXd latents;  // one row per frame
};

Table MakeTable() {
  const PhotometricTrunk::Options o = WarmStartTrunk();
  Table t{PhotometricTrunk(o, MarkerReference(2 * o.rows, 2 * o.cols), 7), {}, {}};
  const int n = 6;
  t.latents.resize(n, o.latent_dim);
  for (int i = 0; i < n; ++i) {
    // Blobs of different lengths and places; latents with arbitrary contact frames.
    TrunkTargets frame = Blob(o.rows, o.cols, 8.0 + 2 * i, 10.0 + 3 * i);
    frame.values *= 1.0f + 0.5f * i;
    t.frames.push_back(frame);
    for (int k = 0; k < o.latent_dim; ++k) {
      t.latents(i, k) = 0.1 * (k + 1) * (i % 2 ? -1 : 1) + 0.05 * i;
    }
    t.latents(i, 2) = -2.5 + 0.9 * i;
  }
  return t;
}

TEST(PhotometricWarmStartTest, AFrameOfTheTableGetsItsOwnLatentBackAndTurnedItsLatentTurned) {
  Table t = MakeTable();
  auto table = std::make_shared<WarmStartTable>(PhotometricWarmStart::BuildTable(
      t.trunk, t.frames, t.latents, PhotometricWarmStart::Options(), 2));
  ASSERT_EQ(table->descriptors.rows(), 6);
  ASSERT_EQ(table->latents.cols(), t.trunk.latent_dim());
  const PhotometricWarmStart warm(t.trunk, table);
  for (int i = 0; i < 6; ++i) {
    const std::vector<Eigen::VectorXd> starts = warm.Starts(t.frames[i], 3);
    ASSERT_EQ(starts.size(), 3u);
    const Eigen::VectorXd& z = starts[0];
    EXPECT_NEAR(z[0], t.latents(i, 0), 1e-5) << "frame " << i;
    EXPECT_NEAR(z[1], t.latents(i, 1), 1e-5) << "frame " << i;
    EXPECT_NEAR(std::remainder(z[2] - t.latents(i, 2), 2 * kPi), 0.0, 1e-5) << "frame " << i;
    EXPECT_LT((z.tail(5) - t.latents.row(i).tail(5).transpose()).norm(), 1e-5) << "frame " << i;
    // Turned by pi about the grid's centre (the origin of the trunk's coordinates): the
    // contact frame turns with it, T -> Rot(pi) T, and the code stays.
    const std::vector<Eigen::VectorXd> turned = warm.Starts(TurnedByPi(t.frames[i]), 1);
    const SE2d expected =
        SE2d::Rot(kPi) * SE2d::FromXYYaw(t.latents(i, 0), t.latents(i, 1), t.latents(i, 2));
    EXPECT_NEAR(turned[0][0], expected.x(), 1e-4) << "frame " << i;
    EXPECT_NEAR(turned[0][1], expected.y(), 1e-4) << "frame " << i;
    EXPECT_NEAR(std::remainder(turned[0][2] - expected.yaw(), 2 * kPi), 0.0, 1e-4)
        << "frame " << i;
    EXPECT_LT((turned[0].tail(5) - t.latents.row(i).tail(5).transpose()).norm(), 1e-5);
  }
}

TEST(PhotometricWarmStartTest, BestStartPicksTheCandidateWithTheLowerLoss) {
  // Frames drawn by the trunk itself from known latents: the table's own latent draws
  // the frame exactly, so among the candidates it has the lowest loss even where another
  // frame's descriptor were nearer.
  const PhotometricTrunk::Options o = WarmStartTrunk();
  PhotometricTrunk trunk(o, MarkerReference(2 * o.rows, 2 * o.cols), 3);
  std::vector<TrunkTargets> frames;
  Eigen::MatrixXd latents(5, o.latent_dim);
  for (int i = 0; i < 5; ++i) {
    for (int k = 0; k < o.latent_dim; ++k) latents(i, k) = 0.3 * std::sin(1.7 * i + 0.9 * k);
    frames.push_back(WholeFrameTargets(
        trunk.Forward<float>(trunk.AllPixels(), latents.row(i).transpose().cast<float>()),
        o.rows, o.cols));
  }
  auto table = std::make_shared<WarmStartTable>(PhotometricWarmStart::BuildTable(
      trunk, frames, latents, PhotometricWarmStart::Options()));
  const PhotometricWarmStart warm(trunk, table);
  for (int i = 0; i < 5; ++i) {
    const Eigen::VectorXd best = warm.BestStart(frames[i], 5, 10000);
    const double loss = trunk.LossAndGradient<float>(trunk.AllPixels(), best.cast<float>(),
                                                     frames[i].values, frames[i].weights,
                                                     nullptr, nullptr, nullptr);
    EXPECT_LT(loss, 1e-8) << "frame " << i;
    for (const Eigen::VectorXd& other : warm.Starts(frames[i], 5)) {
      EXPECT_LE(loss, trunk.LossAndGradient<float>(trunk.AllPixels(), other.cast<float>(),
                                                    frames[i].values, frames[i].weights,
                                                    nullptr, nullptr, nullptr) + 1e-12);
    }
  }
}

TEST(PhotometricWarmStartTest, BadOptionsLatentsAndTablesAreRefusedByName) {
  Table t = MakeTable();
  PhotometricWarmStart::Options bad;
  bad.grid = 0;
  try {
    PhotometricWarmStart::BuildTable(t.trunk, t.frames, t.latents, bad);
    FAIL() << "grid 0 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("grid"), std::string::npos) << e.what();
  }
  try {
    PhotometricWarmStart::BuildTable(t.trunk, t.frames, t.latents.leftCols(4),
                                     PhotometricWarmStart::Options());
    FAIL() << "latents of 4 columns accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("one row per frame"), std::string::npos) << e.what();
  }
  auto table = std::make_shared<WarmStartTable>(PhotometricWarmStart::BuildTable(
      t.trunk, t.frames, t.latents, PhotometricWarmStart::Options()));
  auto other = std::make_shared<WarmStartTable>(*table);
  other->latents.conservativeResize(Eigen::NoChange, 5);
  EXPECT_THROW(PhotometricWarmStart(t.trunk, other), std::invalid_argument);
  const PhotometricWarmStart warm(t.trunk, table);
  EXPECT_THROW(warm.Starts(t.frames[0], 0), std::invalid_argument);
  TrunkTargets small = t.frames[0];
  small.rows = 12;
  EXPECT_THROW(warm.Starts(small, 1), std::invalid_argument);
  // A frame with a NaN has no neighbour; BestStart falls back to a finite start.
  TrunkTargets broken = t.frames[0];
  broken.values(5, 0) = std::numeric_limits<float>::quiet_NaN();
  EXPECT_TRUE(warm.Starts(broken, 2).empty());
  EXPECT_EQ(warm.BestStart(broken, 2).size(), t.trunk.latent_dim());
}

}  // namespace
}  // namespace tactfunc
