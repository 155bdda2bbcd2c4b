// Copyright 2026 The tactfunc Authors.
//
// The generator pose posterior on fresh simulated Soft Bubble contacts (docs/POSES.md,
// "The generator path"): the committed generator (pose_generator_bubble.tpg,
// scripts/train_pretrained_generator.sh), the trunk it renders through (bubble.tfm) and
// the pose MLP (pose_bubble.tpm on default.tfm's latents, one start), contacts seeded
// 0x5eed0000 + k (no training data uses them), the tool given. Without the training functaset the k-NN starts are replaced
// by a yaw grid. One test checks the 90% regions against the binomial 99% interval, one
// guards the accuracy the method reaches here (with a margin, so that a regression
// fails): the median yaw error, the share of yaws within 5 deg and the position RMSE.
// The product targets (0.3 mm position RMSE, 3 deg yaw RMSE modulo symmetry) are not met
// yet; docs/POSES.md states the measured miss and the command that measures it.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "estimation/data/image_io.h"
#include "estimation/pose/pose_distribution.h"
#include "estimation/synthesis/generator_posterior.h"
#include "models/core/seed.h"
#include "models/simulator/contact_simulator.h"
#include "models/simulator/tool.h"
#include "tests/support/stored_frame_util.h"

namespace tactfunc {
namespace {

using testing_util::AsStoredDepth;

const std::string kPretrained = std::string(TACTFUNC_SOURCE_DIR) + "/models/pretrained/";

struct Result {
  int contacts = 0, failures = 0, covered_90 = 0, yaw_count = 0;
  double position_sq = 0, yaw_sq = 0, ms = 0;
  std::vector<double> yaw_errors_deg;
};

double Median(const Result& r) {
  return r.yaw_errors_deg.empty() ? 0 : r.yaw_errors_deg[r.yaw_errors_deg.size() / 2];
}

double WithinFive(const Result& r) {
  return r.yaw_errors_deg.empty()
             ? 0
             : static_cast<double>(std::count_if(r.yaw_errors_deg.begin(), r.yaw_errors_deg.end(),
                                                 [](double e) { return e <= 5; })) /
                   r.yaw_errors_deg.size();
}

const Result& Measure() {
  static const Result result = [] {
    const FunctaModel model = FunctaModel::Load(kPretrained + "bubble.tfm");
    const SensorTrunk& trunk = model.Trunk(SensorKind::kSoftBubble);
    const FunctaModel mlp_model = FunctaModel::Load(kPretrained + "default.tfm");
    const PoseGenerator generator = PoseGenerator::Load(kPretrained + "pose_generator_bubble.tpg");
    const PoseMlp mlp = PoseMlp::Load(kPretrained + "pose_bubble.tpm");
    GeneratorPosterior::Options options;
    const GeneratorPosterior posterior(trunk, generator, options, nullptr, &mlp,
                                       &mlp_model.Trunk(SensorKind::kSoftBubble));
    const ContactSimulator simulator;
    const Image reference = AsStoredDepth(simulator.Reference(SensorKind::kSoftBubble));
    Result r;
    const int per_tool = 17;  // 12 x 17 = 204 contacts (>= 200)
    const std::vector<std::string>& tools = generator.options().tools;
    for (std::size_t t = 0; t < tools.size(); ++t) {
      for (int j = 0; j < per_tool; ++j) {
        const std::uint64_t seed = DeriveSeed(0x5eed0000u, t * per_tool + j);
        const Contact contact = simulator.SamplePairedContact(tools[t], seed).bubble;
        const Image frame = AsStoredDepth(simulator.Render(SensorKind::kSoftBubble, contact, seed).frame);
        const TrunkTargets targets =
            MakeTrunkTargets(frame, reference, SensorKind::kSoftBubble, trunk.format);
        PoseMixture mixture;
        const GeneratorPosterior::Summary s = posterior.Estimate(targets, tools[t], &mixture);
        ++r.contacts;
        if (!s.usable) {
          ++r.failures;
          continue;
        }
        r.ms += s.total_time_ms;
        const SE2d& truth = contact.sensor_T_object;
        r.covered_90 += mixture.Contains(truth, 0.9, options.num_region_samples, seed);
        r.position_sq += std::pow(s.mean.x() - truth.x(), 2) + std::pow(s.mean.y() - truth.y(), 2);
        const int n = generator.SymmetryOrder(static_cast<int>(t));
        if (n != 0) {
          const double e = YawErrorModuloSymmetry(s.mean.yaw(), truth.yaw(), n);
          r.yaw_sq += e * e;
          r.yaw_errors_deg.push_back(e * 180 / M_PI);
          ++r.yaw_count;
        }
      }
    }
    const int ok = std::max(1, r.contacts - r.failures);
    std::sort(r.yaw_errors_deg.begin(), r.yaw_errors_deg.end());
    std::printf("generator posterior, seen tools: %d contacts, %d failed, 90%% coverage %.3f, "
                "position RMSE %.3f mm, yaw RMSE %.2f deg, median %.2f deg, within 5 deg %.3f, "
                "%.1f ms per frame\n",
                r.contacts, r.failures, static_cast<double>(r.covered_90) / ok,
                1e3 * std::sqrt(r.position_sq / ok),
                180 / M_PI * std::sqrt(r.yaw_sq / std::max(1, r.yaw_count)), Median(r),
                WithinFive(r), r.ms / ok);
    return r;
  }();
  return result;
}

class GeneratorCoverageTest : public ::testing::Test {
 protected:
  void SetUp() override {
    for (const char* file :
         {"bubble.tfm", "default.tfm", "pose_generator_bubble.tpg", "pose_bubble.tpm"}) {
      ASSERT_TRUE(std::filesystem::is_regular_file(kPretrained + file))
          << kPretrained + file << " is committed with the repository";
    }
  }
};

TEST_F(GeneratorCoverageTest, NinetyPercentRegionsCoverTheTruthAtTheirNominalRate) {
  const Result& r = Measure();
  EXPECT_EQ(r.failures, 0);
  const double c90 = static_cast<double>(r.covered_90) / (r.contacts - r.failures);
  const auto band = BinomialInterval99(r.contacts - r.failures, 0.9);
  EXPECT_GE(c90, band.first);
  EXPECT_LE(c90, band.second);
}

TEST_F(GeneratorCoverageTest, PosteriorModeKeepsItsMeasuredAccuracy) {
  // Measured on these contacts: see the printed line and docs/POSES.md (2026-11-29, with
  // the final stage the generator records: 0.293 mm, median 0.68 deg, 0.973 within 5 deg;
  // 0.331 mm, 0.67 deg, 0.979 without it). The bounds leave a margin above the
  // measured figures; the product's position target (0.3 mm RMSE, met with the k-NN
  // starts this test goes without) is stricter.
  const Result& r = Measure();
  const int ok = std::max(1, r.contacts - r.failures);
  EXPECT_LE(Median(r), 1.0) << "median yaw error, deg";
  EXPECT_GE(WithinFive(r), 0.94) << "share of yaw errors within 5 deg";
  EXPECT_LE(1e3 * std::sqrt(r.position_sq / ok), 0.40) << "position RMSE, mm";
}

}  // namespace
}  // namespace tactfunc
