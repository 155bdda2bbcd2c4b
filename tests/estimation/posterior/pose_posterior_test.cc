// Copyright 2026 The tactfunc Authors.
#include "estimation/posterior/pose_posterior.h"

#include <cmath>
#include <string>
#include <optional>

#include <gtest/gtest.h>

#include "tests/support/sampler_test_util.h"

namespace tactfunc {
namespace {

constexpr int kDim = 4;

struct PosteriorFixture {
  SensorTrunk trunk = testing_util::MakeTinyTrunk(8, 9, 16, 2, kDim, 5);
  PoseMlp mlp{[] {
                PoseMlp::Options o;
                o.input_dim = kDim;
                o.hidden_sizes = {8, 8};
                return o;
              }(),
              9};
  Eigen::Vector4d z_true{0.3, -0.2, 0.1, 0.4};
  TrunkTargets targets = testing_util::MakeTargets(trunk, z_true, 0.05, 3);
};

TEST(PosePosterior, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(PosePosterior::Options().IsValid(&error)) << error;
  EXPECT_EQ(PosePosterior::Options().num_samples, 100);
}

TEST(PosePosterior, BadOptionsNameTheField) {
  std::string error;
  PosePosterior::Options options;
  options.num_samples = 0;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("num_samples"), std::string::npos) << error;
  options = PosePosterior::Options();
  options.sgld.burn_in = -1;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("sgld: Sgld::Options::burn_in"), std::string::npos) << error;
  PosteriorFixture f;
  EXPECT_THROW(PosePosterior(f.trunk, f.mlp, options), std::invalid_argument);
  options = PosePosterior::Options();
  options.sampler = PosteriorSampler::kKnn;
  EXPECT_THROW(PosePosterior(f.trunk, f.mlp, options), std::invalid_argument);  // no k-NN
}

TEST(PosePosterior, SamplerNamesRoundTrip) {
  for (auto s : {PosteriorSampler::kSgld, PosteriorSampler::kLaplace, PosteriorSampler::kKnn}) {
    PosteriorSampler parsed;
    ASSERT_TRUE(PosteriorSamplerFromString(ToString(s), &parsed));
    EXPECT_EQ(parsed, s);
  }
  PosteriorSampler parsed;
  EXPECT_FALSE(PosteriorSamplerFromString("mcmc", &parsed));
}

TEST(PosePosterior, SgldAndLaplaceGiveFiniteDistributions) {
  PosteriorFixture f;
  for (auto sampler : {PosteriorSampler::kSgld, PosteriorSampler::kLaplace}) {
    SCOPED_TRACE(ToString(sampler));
    PosePosterior::Options options;
    options.sampler = sampler;
    options.sgld.num_threads = 2;
    std::optional<PoseDistribution> posterior;
    Eigen::MatrixXd latents;
    const PosePosterior::Summary summary =
        EstimatePosePosterior(f.trunk, f.mlp, f.targets, 1, options, &posterior);
    ASSERT_TRUE(summary.IsSolutionUsable()) << summary.FullReport();
    ASSERT_TRUE(posterior.has_value());
    EXPECT_EQ(posterior->size(), 100);
    EXPECT_EQ(summary.num_samples, 100);
    EXPECT_TRUE(summary.fit_ran);
    EXPECT_TRUE(summary.mean.translation().allFinite());
    EXPECT_TRUE(std::isfinite(summary.mean.yaw()));
    EXPECT_TRUE(summary.covariance.allFinite());
    EXPECT_TRUE(summary.covariance.isApprox(summary.covariance.transpose(), 1e-12));
    EXPECT_GT(summary.covariance.diagonal().minCoeff(), 0.0);
    // Every sample is the pose MLP's prediction for a latent sample.
    const PosePosterior posterior_estimator(f.trunk, f.mlp, options);
    std::optional<PoseDistribution> again;
    posterior_estimator.Estimate(f.targets, f.z_true, 1, &again, &latents);
    ASSERT_EQ(latents.rows(), 100);
    const SE2d pose = f.mlp.Predict(latents.row(7).transpose(), 1);
    EXPECT_NEAR(again->samples()[7].x(), pose.x(), 1e-6);
    EXPECT_NEAR(again->samples()[7].yaw(), pose.yaw(), 1e-4);
  }
}

TEST(PosePosterior, FoldsBySymmetryOrder) {
  PosteriorFixture f;
  PosePosterior::Options options;
  options.sampler = PosteriorSampler::kLaplace;
  const PosePosterior estimator(f.trunk, f.mlp, options);
  std::optional<PoseDistribution> posterior;
  const PosePosterior::Summary summary = estimator.Estimate(f.targets, 4, &posterior);
  ASSERT_TRUE(summary.IsSolutionUsable()) << summary.FullReport();
  for (const SE2d& pose : posterior->samples()) {
    // One representative modulo 2 pi / 4: within pi / 4 of the folded mean.
    EXPECT_LE(std::abs((summary.mean.Inverse() * pose).yaw()), M_PI / 4 + 1e-9);
  }
  EXPECT_THROW(estimator.Estimate(f.targets, -1, &posterior), std::invalid_argument);
}

TEST(PosePosterior, KnnReturnsTheNeighboursPoses) {
  PosteriorFixture f;
  BruteForceKnnIndex index(kDim);
  std::vector<std::optional<SE2d>> poses;
  std::vector<float> data;
  for (int i = 0; i < 20; ++i) {
    for (int k = 0; k < kDim; ++k) data.push_back(0.1f * ((i * (k + 3)) % 7) - 0.3f);
    poses.emplace_back(SE2d::FromXYYaw(1e-3 * i, -1e-3 * i, 0.05 * i));
  }
  index.Add(data.data(), 20);
  const KnnPosterior knn(index, poses, KnnPosterior::Options());
  PosePosterior::Options options;
  options.sampler = PosteriorSampler::kKnn;
  std::optional<PoseDistribution> posterior;
  const PosePosterior::Summary summary =
      EstimatePosePosterior(f.trunk, f.mlp, f.targets, 1, options, &posterior, &knn);
  ASSERT_TRUE(summary.IsSolutionUsable()) << summary.FullReport();
  EXPECT_EQ(posterior->size(), 8);
  EXPECT_EQ(summary.fit_summary.strategy.ToString(), "meta_sgd:3");
  for (size_t i = 0; i < summary.knn_summary.labels.size(); ++i) {
    EXPECT_EQ(posterior->samples()[i].x(), poses[summary.knn_summary.labels[i]]->x());
  }
  EXPECT_TRUE(summary.covariance.allFinite());
}

TEST(PosePosterior, CalibrationResidualsOfTheModelsOwnPredictionsAreZeroModuloSymmetry) {
  PosteriorFixture f;
  Eigen::MatrixXf inputs = Eigen::MatrixXf::Random(6, kDim);
  PoseTargets targets;
  targets.poses.resize(6, 3);
  targets.symmetry_orders.resize(6);
  for (int i = 0; i < 6; ++i) {
    const int n = i % 3 + 1;  // 1, 2, 3
    targets.symmetry_orders[i] = n;
    const SE2d p = f.mlp.Predict(inputs.row(i).transpose().cast<double>(), n);
    // The truth is the prediction turned by a whole number of symmetry periods.
    targets.poses.row(i) << p.x(), p.y(), p.yaw() + (i % 2) * 2 * M_PI / n;
  }
  const Eigen::MatrixXd r = CalibrationResiduals(f.mlp, inputs, targets);
  ASSERT_EQ(r.rows(), 6);
  EXPECT_LT(r.cwiseAbs().maxCoeff(), 1e-9) << r;
  // A known offset in the body frame comes back as the residual.
  const SE2d p = f.mlp.Predict(inputs.row(0).transpose().cast<double>(), 1);
  const Eigen::Vector3d offset(1e-3, -2e-3, 0.2);
  const SE2d truth = p * SE2d::Exp(offset);
  targets.poses.row(0) << truth.x(), truth.y(), truth.yaw();
  EXPECT_LT((CalibrationResiduals(f.mlp, inputs, targets).row(0).transpose() - offset).norm(), 1e-9);
}

TEST(PosePosterior, ModelErrorComposesEverySampleWithAStoredResidual) {
  PosteriorFixture f;
  PosePosterior::Options options;
  options.sampler = PosteriorSampler::kLaplace;
  options.num_samples = 50;
  std::optional<PoseDistribution> plain, shifted;
  ASSERT_TRUE(PosePosterior(f.trunk, f.mlp, options).Estimate(f.targets, 1, &plain)
                  .IsSolutionUsable());
  // One residual: every sample moves by exactly Exp(r) in its own frame.
  const Eigen::Vector3d r(2e-3, 1e-3, 0.3);
  PoseMlp calibrated = f.mlp;
  calibrated.SetCalibrationResiduals(r.transpose());
  ASSERT_TRUE(PosePosterior(f.trunk, calibrated, options).Estimate(f.targets, 1, &shifted)
                  .IsSolutionUsable());
  ASSERT_EQ(plain->size(), shifted->size());
  for (int i = 0; i < plain->size(); ++i) {
    const SE2d expected = plain->samples()[i] * SE2d::Exp(r);
    EXPECT_NEAR(shifted->samples()[i].x(), expected.x(), 1e-12);
    EXPECT_NEAR(shifted->samples()[i].y(), expected.y(), 1e-12);
    EXPECT_NEAR(shifted->samples()[i].yaw(), expected.yaw(), 1e-12);
  }
  // Switched off, the calibrated model gives the plain posterior.
  options.model_error = false;
  std::optional<PoseDistribution> off;
  PosePosterior(f.trunk, calibrated, options).Estimate(f.targets, 1, &off);
  EXPECT_EQ(off->samples()[0].x(), plain->samples()[0].x());
}

TEST(PosePosterior, PoseModelsCarryTheirLatentMapAndPosteriorSigma) {
  PosteriorFixture f;
  PoseMlp mlp = f.mlp;
  // No info: the functaset's map, K meta-SGD steps of the trunk.
  EXPECT_EQ(LatentMapOfPoseModel(mlp, f.trunk).ToString(),
            "meta_sgd:" + std::to_string(f.trunk.meta_sgd.inner_steps));
  EXPECT_EQ(PosteriorSigmaOfPoseModel(mlp), 0);
  mlp.set_info_json(R"({"latents": "refit ceres:7"})");  // older files
  EXPECT_EQ(LatentMapOfPoseModel(mlp, f.trunk).ToString(), "ceres:7");
  mlp.set_info_json(R"({"latent_map": "ceres:10", "posterior_sigma": 0.002})");
  EXPECT_EQ(LatentMapOfPoseModel(mlp, f.trunk).ToString(), "ceres:10");
  EXPECT_EQ(PosteriorSigmaOfPoseModel(mlp), 0.002);
  mlp.set_info_json(R"({"latent_map": "newton:3"})");
  EXPECT_THROW(LatentMapOfPoseModel(mlp, f.trunk), std::invalid_argument);
}

}  // namespace
}  // namespace tactfunc
