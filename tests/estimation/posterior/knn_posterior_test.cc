// Copyright 2026 The tactfunc Authors.
#include "estimation/posterior/knn_posterior.h"

#include <cmath>
#include <string>

#include <gtest/gtest.h>

namespace tactfunc {
namespace {

// Latents on a line in 2-D: entry i at (i, 0), pose (i mm, 0, 0.1 i rad).
struct Fixture {
  BruteForceKnnIndex index{2};
  std::vector<std::optional<SE2d>> poses;
  Fixture() {
    std::vector<float> data;
    for (int i = 0; i < 10; ++i) {
      data.push_back(static_cast<float>(i));
      data.push_back(0.0f);
      poses.emplace_back(SE2d::FromXYYaw(1e-3 * i, 0.0, 0.1 * i));
    }
    index.Add(data.data(), 10);
  }
};

TEST(KnnPosterior, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(KnnPosterior::Options().IsValid(&error)) << error;
}

TEST(KnnPosterior, BadOptionsNameTheField) {
  std::string error;
  KnnPosterior::Options options;
  options.k = 0;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("k must"), std::string::npos) << error;
  options.k = 4;
  options.search_k = 2;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("search_k"), std::string::npos) << error;
  Fixture f;
  EXPECT_THROW(KnnPosterior(f.index, f.poses, options), std::invalid_argument);
  f.poses.pop_back();
  EXPECT_THROW(KnnPosterior(f.index, f.poses, KnnPosterior::Options()), std::invalid_argument);
}

TEST(KnnPosterior, GaussianKernelWeightsTheNeighboursPoses) {
  Fixture f;
  KnnPosterior::Options options;
  options.k = 3;
  const KnnPosterior knn(f.index, f.poses, options);
  std::optional<PoseDistribution> posterior;
  // Query at (4.2, 0): neighbours 4, 5, 3 at distances 0.2, 0.8, 1.2.
  const KnnPosterior::Summary summary = knn.Posterior(Eigen::Vector2d(4.2, 0), &posterior);
  ASSERT_TRUE(summary.IsSolutionUsable()) << summary.message;
  ASSERT_TRUE(posterior.has_value());
  ASSERT_EQ(summary.labels, (std::vector<std::int64_t>{4, 5, 3}));
  const double h = 1.2;
  EXPECT_NEAR(summary.bandwidth, h, 1e-6);
  std::vector<double> w = {std::exp(-0.5 * 0.04 / (h * h)), std::exp(-0.5 * 0.64 / (h * h)),
                           std::exp(-0.5)};
  const double total = w[0] + w[1] + w[2];
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(summary.weights[i], w[i] / total, 1e-6);
    EXPECT_NEAR(posterior->weights()[i], w[i] / total, 1e-6);
    EXPECT_EQ(posterior->samples()[i].x(), f.poses[summary.labels[i]]->x());
    EXPECT_EQ(posterior->samples()[i].yaw(), f.poses[summary.labels[i]]->yaw());
  }
}

TEST(KnnPosterior, InverseDistanceWeightsAndExactMatches) {
  Fixture f;
  KnnPosterior::Options options;
  options.k = 3;
  options.weighting = KnnPosterior::Weighting::kInverseDistance;
  const KnnPosterior knn(f.index, f.poses, options);
  std::optional<PoseDistribution> posterior;
  KnnPosterior::Summary summary = knn.Posterior(Eigen::Vector2d(4.2, 0), &posterior);
  const double total = 1 / 0.2 + 1 / 0.8 + 1 / 1.2;
  EXPECT_NEAR(summary.weights[0], (1 / 0.2) / total, 1e-5);
  EXPECT_NEAR(summary.weights[1], (1 / 0.8) / total, 1e-5);
  EXPECT_NEAR(summary.weights[2], (1 / 1.2) / total, 1e-5);
  summary = knn.Posterior(Eigen::Vector2d(6, 0), &posterior);  // an exact match
  EXPECT_EQ(summary.labels[0], 6);
  EXPECT_EQ(summary.weights[0], 1.0);
  EXPECT_EQ(posterior->Mean().x(), f.poses[6]->x());
}

TEST(KnnPosterior, SkipsUnlabelledEntries) {
  Fixture f;
  f.poses[4].reset();
  KnnPosterior::Options options;
  options.k = 2;
  options.search_k = 4;
  const KnnPosterior knn(f.index, f.poses, options);
  std::optional<PoseDistribution> posterior;
  const KnnPosterior::Summary summary = knn.Posterior(Eigen::Vector2d(4.2, 0), &posterior);
  EXPECT_EQ(summary.labels, (std::vector<std::int64_t>{5, 3}));
  EXPECT_EQ(summary.num_unlabelled_skipped, 1);
  for (auto& p : f.poses) p.reset();
  const KnnPosterior none(f.index, f.poses, options);
  const KnnPosterior::Summary failed = none.Posterior(Eigen::Vector2d(4.2, 0), &posterior);
  EXPECT_EQ(failed.termination_type, KnnPosteriorTermination::kNoLabelledNeighbors);
  EXPECT_FALSE(posterior.has_value());
}

TEST(KnnPosterior, PosesOfAFunctasetFollowItsLatentRows) {
  Functaset functaset;
  functaset.AddSensor(SensorKind::kSoftBubble, 2);
  for (int i = 0; i < 3; ++i) {
    FunctasetEntry entry;
    entry.id = "f" + std::to_string(i);
    entry.split = i == 1 ? Split::kTest : Split::kTrain;
    entry.latent = Eigen::Vector2f(i, 0);
    if (i != 2) entry.label = PoseLabel{"rod", SE2d::FromXYYaw(0.001 * i, 0.002, 0.3), 0.0};
    functaset.Add(SensorKind::kSoftBubble, entry);
  }
  const auto all = KnnPosterior::PosesOf(functaset, SensorKind::kSoftBubble);
  ASSERT_EQ(all.size(), 3u);
  EXPECT_EQ(all[1]->x(), 0.001);
  EXPECT_EQ(all[1]->yaw(), 0.3);
  EXPECT_FALSE(all[2].has_value());
  const auto train = KnnPosterior::PosesOf(functaset, SensorKind::kSoftBubble, Split::kTrain);
  ASSERT_EQ(train.size(), 2u);
  EXPECT_EQ(train[0]->x(), 0.0);
}

TEST(KnnPosterior, ThrowsForAQueryOfTheWrongSize) {
  Fixture f;
  const KnnPosterior knn(f.index, f.poses, KnnPosterior::Options());
  std::optional<PoseDistribution> posterior;
  EXPECT_THROW(knn.Posterior(Eigen::Vector3d::Zero(), &posterior), std::invalid_argument);
}

}  // namespace
}  // namespace tactfunc
