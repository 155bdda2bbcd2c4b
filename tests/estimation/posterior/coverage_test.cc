// Copyright 2026 The tactfunc Authors.
//
// Calibration of the pose posteriors on synthetic contacts (docs/POSES.md,
// "Calibration"): fresh Soft Bubble contacts (a seed no training run used) of tools the
// pose model was trained on, and of tools it never saw, go through the committed
// pretrained trunk and pose models (models/pretrained/, scripts/train_pretrained_pose.sh)
// and the sgld / laplace posteriors; the fraction of true poses inside the nominal 50%
// and 90% credible regions must lie in the binomial 99% interval around nominal for the
// number of contacts (BinomialInterval99). The interval follows from the count alone.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "estimation/data/image_io.h"
#include "models/core/parallel_for.h"
#include "estimation/pose/pose_distribution.h"
#include "estimation/data/trunk_targets.h"
#include "models/simulator/contact_simulator.h"
#include "models/trunk/functa_model.h"
#include "models/pose/pose_mlp.h"
#include "models/core/seed.h"
#include "models/simulator/tool.h"
#include "estimation/posterior/pose_posterior.h"
#include "tests/support/stored_frame_util.h"

namespace tactfunc {
namespace {

using testing_util::AsStoredDepth;

const std::string kPretrained = std::string(TACTFUNC_SOURCE_DIR) + "/models/pretrained/";

// Tools the held-out pose model never saw (scripts/train_pretrained_pose.sh).
const std::vector<std::string> kHeldOutTools = {"l_shape", "lines2_60"};

struct Coverage {
  int contacts = 0, failures = 0, covered_50 = 0, covered_90 = 0;
  double position_sq = 0;
};

// Posteriors of `contacts_per_tool` fresh contacts of each tool, on two threads.
Coverage Measure(const SensorTrunk& trunk, const PoseMlp& pose_mlp, PosteriorSampler sampler,
                 const std::vector<std::string>& tools, int contacts_per_tool) {
  const ContactSimulator simulator;
  const Image reference = AsStoredDepth(simulator.Reference(SensorKind::kSoftBubble));
  PosePosterior::Options options;
  options.sampler = sampler;
  options.num_samples = 100;
  options.fit.strategy = LatentMapOfPoseModel(pose_mlp, trunk);
  const int total = static_cast<int>(tools.size()) * contacts_per_tool;
  std::vector<Coverage> per_contact(total);  // summed in contact order below
  internal::ParallelFor(total, 2, [&](int k) {
    Coverage& c = per_contact[k];
    const std::string& tool = tools[k / contacts_per_tool];
    const int n = GetTool(tool).symmetry_order();
    // Seed 0x5eed0000 + k: no dataset of the training scripts uses these.
    const std::uint64_t seed = DeriveSeed(0x5eed0000u, k);
    const Contact contact = simulator.SamplePairedContact(tool, seed).bubble;
    const Image frame =
        AsStoredDepth(simulator.Render(SensorKind::kSoftBubble, contact, seed).frame);
    const TrunkTargets targets =
        MakeTrunkTargets(frame, reference, SensorKind::kSoftBubble, trunk.format);
    PosePosterior::Options o = options;
    o.seed = seed;
    std::optional<PoseDistribution> posterior;
    const PosePosterior::Summary summary =
        PosePosterior(trunk, pose_mlp, o).Estimate(targets, n, &posterior);
    ++c.contacts;
    if (!summary.IsSolutionUsable()) {
      ++c.failures;
      return;
    }
    // The truth's yaw modulo the symmetry, the copy nearest the posterior mean.
    const SE2d& pose = contact.sensor_T_object;
    const SE2d truth =
        SE2d::FromXYYaw(pose.x(), pose.y(), FoldYawNear(pose.yaw(), summary.mean.yaw(), n));
    c.covered_50 += posterior->Region(0.5).Contains(truth);
    c.covered_90 += posterior->Region(0.9).Contains(truth);
    c.position_sq += std::pow(summary.mean.x() - pose.x(), 2) +
                     std::pow(summary.mean.y() - pose.y(), 2);
  });
  Coverage all;
  for (const Coverage& c : per_contact) {
    all.contacts += c.contacts;
    all.failures += c.failures;
    all.covered_50 += c.covered_50;
    all.covered_90 += c.covered_90;
    all.position_sq += c.position_sq;
  }
  return all;
}

void ExpectCalibrated(const Coverage& c, const std::string& what) {
  const double c50 = static_cast<double>(c.covered_50) / c.contacts;
  const double c90 = static_cast<double>(c.covered_90) / c.contacts;
  const auto band50 = BinomialInterval99(c.contacts, 0.5);
  const auto band90 = BinomialInterval99(c.contacts, 0.9);
  std::printf("%s: %d contacts, %d failed, coverage 50%%: %.3f [%.3f, %.3f], 90%%: %.3f "
              "[%.3f, %.3f], mean position RMSE %.3f mm\n",
              what.c_str(), c.contacts, c.failures, c50, band50.first, band50.second, c90,
              band90.first, band90.second,
              1e3 * std::sqrt(c.position_sq / std::max(1, c.contacts - c.failures)));
  EXPECT_EQ(c.failures, 0) << what;
  EXPECT_GE(c50, band50.first) << what;
  EXPECT_LE(c50, band50.second) << what;
  EXPECT_GE(c90, band90.first) << what;
  EXPECT_LE(c90, band90.second) << what;
}

class CoverageTest : public ::testing::TestWithParam<PosteriorSampler> {
 protected:
  void SetUp() override {
    for (const char* file : {"default.tfm", "pose_bubble.tpm", "pose_bubble_heldout.tpm"}) {
      ASSERT_TRUE(std::filesystem::is_regular_file(kPretrained + file))
          << kPretrained + file << " is committed with the repository";
    }
    model_ = FunctaModel::Load(kPretrained + "default.tfm");
  }
  FunctaModel model_;
};

TEST_P(CoverageTest, RegionsCoverTheTruthAtTheirNominalRateOnToolsSeenInTraining) {
  const PoseMlp pose_mlp = PoseMlp::Load(kPretrained + "pose_bubble.tpm");
  ASSERT_GT(pose_mlp.calibration_residuals().rows(), 0);
  // 12 tools x 20 = 240 contacts (>= 200), every tool the pose model was trained on.
  ExpectCalibrated(Measure(model_.Trunk(SensorKind::kSoftBubble), pose_mlp, GetParam(),
                           ToolNames(), 20),
                   std::string(ToString(GetParam())) + ", seen tools");
}

TEST_P(CoverageTest, RegionsCoverTheTruthAtTheirNominalRateOnToolsHeldOutOfTraining) {
  // The held-out model's calibration residuals come from other tools it never saw
  // (train-pose --calibration-tools), so they measure the error on a new shape.
  const PoseMlp pose_mlp = PoseMlp::Load(kPretrained + "pose_bubble_heldout.tpm");
  ASSERT_GT(pose_mlp.calibration_residuals().rows(), 0);
  // 2 tools x 100 = 200 contacts.
  ExpectCalibrated(Measure(model_.Trunk(SensorKind::kSoftBubble), pose_mlp, GetParam(),
                           kHeldOutTools, 100),
                   std::string(ToString(GetParam())) + ", held-out tools");
}

INSTANTIATE_TEST_SUITE_P(Samplers, CoverageTest,
                         ::testing::Values(PosteriorSampler::kLaplace, PosteriorSampler::kSgld),
                         [](const auto& info) { return std::string(ToString(info.param)); });

}  // namespace
}  // namespace tactfunc
