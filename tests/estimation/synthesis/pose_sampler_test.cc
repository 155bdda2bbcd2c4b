// Copyright 2026 The tactfunc Authors.
//
// MCMC over the pose (estimation/synthesis/pose_sampler.h) on 6 fresh simulated Soft
// Bubble contacts with the committed generator (pose_generator_bubble.tpg), the trunk
// it renders through (bubble.tfm) and the pose MLP (pose_bubble.tpm, on default.tfm's
// latents): 4 MALA chains of 300 + 500 iterations from the heaviest Laplace component mix
// (split R-hat < 1.1 on x, y, yaw and depth) on at least 5 of the 6 contacts, and the 90%
// interval of the yaw samples holds the true yaw modulo the tool's symmetry on at least 4
// of them (both counts are printed). Measured: 6 of 6 and 5 of 6; the sixth interval
// (lines3_40) is the mirrored mode's, where the search's heaviest mode lies. With 150 +
// 250 iterations, enough for the generator through default.tfm committed before, the
// chains mixed on 4 of 6 (lines2_60's read R-hat 1.22). Random-walk Metropolis with the
// same budget misses R-hat < 1.1 on some of the others (docs/POSES.md, "MCMC over the
// pose", compares the kernels). One seed
// gives one set of samples. The kernels' correctness on targets with known moments is
// tests/samplers/metropolis_test.cc.
#include "estimation/synthesis/pose_sampler.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "estimation/data/image_io.h"
#include "models/core/seed.h"
#include "models/simulator/contact_simulator.h"
#include "models/simulator/tool.h"
#include "tests/support/stored_frame_util.h"

namespace tactfunc {
namespace {

using testing_util::AsStoredDepth;

const std::string kPretrainedDir = std::string(TACTFUNC_SOURCE_DIR) + "/models/pretrained/";

struct Models {
  FunctaModel model = FunctaModel::Load(kPretrainedDir + "bubble.tfm");  // the generator's trunk
  const SensorTrunk& trunk = model.Trunk(SensorKind::kSoftBubble);
  FunctaModel mlp_model = FunctaModel::Load(kPretrainedDir + "default.tfm");  // the pose MLP's
  const SensorTrunk& mlp_trunk = mlp_model.Trunk(SensorKind::kSoftBubble);
  PoseGenerator generator = PoseGenerator::Load(kPretrainedDir + "pose_generator_bubble.tpg");
  PoseMlp mlp = PoseMlp::Load(kPretrainedDir + "pose_bubble.tpm");
  GeneratorPosterior posterior{trunk, generator, GeneratorPosterior::Options(), nullptr, &mlp,
                               &mlp_trunk};
  ContactSimulator simulator;
  Image reference = AsStoredDepth(simulator.Reference(SensorKind::kSoftBubble));
};

const Models& Shared() {
  static const Models* models = new Models();
  return *models;
}

// One fresh contact of a tool with an observable yaw, its posterior and problem.
struct Frame {
  std::string tool;
  int tool_index = 0, symmetry_order = 1;
  SE2d truth;
  TrunkTargets targets;
  GeneratorPosterior::Summary summary;
  PoseMixture mixture;
};

Frame MakeFrame(int k) {
  const Models& m = Shared();
  std::vector<int> observable;
  for (int t = 0; t < m.generator.num_tools(); ++t) {
    if (m.generator.SymmetryOrder(t) != 0) observable.push_back(t);
  }
  Frame f;
  f.tool_index = observable[(3 * k) % observable.size()];
  f.tool = m.generator.options().tools[f.tool_index];
  f.symmetry_order = m.generator.SymmetryOrder(f.tool_index);
  const std::uint64_t seed = DeriveSeed(0x5a3b1e00u, k);
  const Contact contact = m.simulator.SamplePairedContact(f.tool, seed).bubble;
  f.truth = contact.sensor_T_object;
  f.targets = MakeTrunkTargets(AsStoredDepth(m.simulator.Render(SensorKind::kSoftBubble, contact, seed).frame),
                               m.reference, SensorKind::kSoftBubble, m.trunk.format);
  f.summary = m.posterior.Estimate(f.targets, f.tool, &f.mixture);
  return f;
}

PoseSamples Sample(const Frame& f, MetropolisKernel kernel, int burn_in, int samples,
                   std::uint64_t seed) {
  const Models& m = Shared();
  const LatentProblem problem(m.trunk, f.targets, m.posterior.options().problem);
  PoseSamplerOptions o;
  o.chain.kernel = kernel;
  o.chain.burn_in = burn_in;
  o.chain.num_samples_per_chain = samples;
  o.chain.seed = seed;
  // Every mode the search found for the tool, as pose and bench pose-mcmc pass them.
  std::vector<LaplaceComponent> modes;
  for (const LaplaceComponent& c : f.mixture.components()) {
    if (c.tool == f.tool) modes.push_back(c);
  }
  return SamplePosePosterior(problem, m.generator, f.tool_index, f.summary.sigma, modes, o);
}

class PoseSamplerTest : public ::testing::Test {
 protected:
  void SetUp() override {
    for (const char* file :
         {"bubble.tfm", "default.tfm", "pose_generator_bubble.tpg", "pose_bubble.tpm"}) {
      ASSERT_TRUE(std::filesystem::is_regular_file(kPretrainedDir + file))
          << kPretrainedDir + file << " is committed with the repository";
    }
  }
};

TEST_F(PoseSamplerTest, ChainsMixAndYawIntervalsHoldTheTruth) {
  const int kContacts = 6;
  int held = 0, mixed = 0;
  const MetropolisKernel kernel = MetropolisKernel::kMala;
  for (int k = 0; k < kContacts; ++k) {
    const Frame f = MakeFrame(k);
    ASSERT_TRUE(f.summary.usable) << f.summary.message;
    const PoseSamples s = Sample(f, kernel, 300, 500, 11 + k);
    mixed += s.chains.MaxSplitRhat() < 1.1;
    // 90% interval of the yaw, folded near the start's yaw by the tool's symmetry.
    const double period = 2 * M_PI / f.symmetry_order;
    const double centre = f.mixture.components().front().mean.yaw();
    auto fold = [&](double yaw) { return centre + period * std::remainder((yaw - centre) / period, 1.0); };
    std::vector<double> yaws;
    for (const SE2d& p : s.Poses()) yaws.push_back(fold(p.yaw()));
    std::sort(yaws.begin(), yaws.end());
    const double lo = yaws[static_cast<std::size_t>(0.05 * (yaws.size() - 1))];
    const double hi = yaws[static_cast<std::size_t>(0.95 * (yaws.size() - 1))];
    const double truth = fold(f.truth.yaw());
    const bool inside = truth >= lo && truth <= hi;
    held += inside;
    std::printf("%s %s: yaw 90%% [%.2f, %.2f] deg, truth %.2f deg (%s), max R-hat %.3f, "
                "acceptance %.2f, %ld evaluations, %.0f ms\n",
                f.tool.c_str(), ToString(kernel), lo * 180 / M_PI, hi * 180 / M_PI,
                truth * 180 / M_PI, inside ? "inside" : "outside", s.chains.MaxSplitRhat(),
                s.chains.MeanAcceptance(), s.trunk_evaluations, s.chains.time_ms);
  }
  std::printf("split R-hat < 1.1 on every coordinate: %d of %d; yaw 90%% intervals holding "
              "the truth: %d of %d\n", mixed, kContacts, held, kContacts);
  EXPECT_GE(mixed, 5);
  EXPECT_GE(held, 4);
}

TEST_F(PoseSamplerTest, SameSeedSameSamples) {
  const Frame f = MakeFrame(0);
  ASSERT_TRUE(f.summary.usable) << f.summary.message;
  for (MetropolisKernel kernel : {MetropolisKernel::kMala, MetropolisKernel::kRandomWalk}) {
    const PoseSamples a = Sample(f, kernel, 10, 10, 5);
    const PoseSamples b = Sample(f, kernel, 10, 10, 5);
    EXPECT_EQ(a.chains.Stacked(), b.chains.Stacked());
    EXPECT_EQ(a.trunk_evaluations, b.trunk_evaluations);
    const PoseSamples c = Sample(f, kernel, 10, 10, 6);
    EXPECT_NE(a.chains.Stacked(), c.chains.Stacked());
    const Eigen::MatrixXd all = a.chains.Stacked();
    EXPECT_GE(all.col(3).minCoeff(), PoseFitOptions().depth_min_m);
    EXPECT_LE(all.col(3).maxCoeff(), PoseFitOptions().depth_max_m);
  }
}

TEST_F(PoseSamplerTest, RejectsBadSigma) {
  const Frame f = MakeFrame(0);
  ASSERT_TRUE(f.summary.usable) << f.summary.message;
  Frame bad = f;
  bad.summary.sigma = 0;
  EXPECT_THROW(Sample(bad, MetropolisKernel::kMala, 10, 10, 1), std::invalid_argument);
}

}  // namespace
}  // namespace tactfunc
