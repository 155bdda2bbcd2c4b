// Copyright 2026 The tactfunc Authors.
#include "models/pose/pose_generator.h"

#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <vector>

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "ceres/jet.h"
#include "models/core/tensor_file.h"
#include "nlohmann/json.hpp"

namespace tactfunc {
namespace {

PoseGenerator::Options SmallOptions() {
  PoseGenerator::Options o;
  o.tools = {"rod", "l_shape", "hemisphere"};
  o.symmetry_orders = {2, 1, 0};
  o.latent_dim = 5;
  o.hidden_sizes = {7, 6};
  o.yaw_harmonics = 3;
  return o;
}

PoseGenerator Trained() {
  PoseGenerator g(SmallOptions(), 3);
  Eigen::VectorXd mean(5), stddev(5);
  mean << 0.1, -0.2, 0.3, 0, 0.5;
  stddev << 1, 2, 0.5, 1.5, 0.7;
  g.SetLatentStandardization(mean, stddev);
  return g;
}

TEST(PoseGenerator, RejectsBadOptionsNamingTheField) {
  PoseGenerator::Options o = SmallOptions();
  o.symmetry_orders.pop_back();
  std::string error;
  EXPECT_FALSE(o.IsValid(&error));
  EXPECT_THAT(error, ::testing::HasSubstr("symmetry_orders"));
  EXPECT_THROW(PoseGenerator(o, 0), std::invalid_argument);
  o = SmallOptions();
  o.tools[1] = "rod";
  EXPECT_FALSE(o.IsValid(&error));
  EXPECT_THAT(error, ::testing::HasSubstr("twice"));
}

// Layers wider than the Jacobian pass's blocks of 32 rows, with remainders (70 = 2 x 32 + 6,
// 40 = 32 + 8, 33 = 32 + 1).
PoseGenerator Wide() {
  PoseGenerator::Options o = SmallOptions();
  o.latent_dim = 33;
  o.hidden_sizes = {70, 40};
  PoseGenerator g(o, 5);
  Eigen::VectorXd mean = Eigen::VectorXd::LinSpaced(33, -0.5, 0.5);
  Eigen::VectorXd stddev = Eigen::VectorXd::LinSpaced(33, 0.5, 2.0);
  g.SetLatentStandardization(mean, stddev);
  return g;
}

TEST(PoseGenerator, IsInvariantUnderTheToolsSymmetryAndDeterministicFromItsSeed) {
  const PoseGenerator g = Trained();
  const SE2d a = SE2d::FromXYYaw(1e-3, -2e-3, 0.4);
  const SE2d b = SE2d::FromXYYaw(1e-3, -2e-3, 0.4 + M_PI);
  EXPECT_TRUE(g.Generate(0, a, 0.008).isApprox(g.Generate(0, b, 0.008), 1e-12));  // rod, n = 2
  EXPECT_FALSE(g.Generate(1, a, 0.008).isApprox(g.Generate(1, b, 0.008), 1e-6));  // n = 1
  EXPECT_TRUE(g.Generate(2, a, 0.008).isApprox(
      g.Generate(2, SE2d::FromXYYaw(1e-3, -2e-3, -2.0), 0.008), 1e-12));  // hemisphere
  EXPECT_EQ(PoseGenerator(SmallOptions(), 3).parameters(), g.parameters());
  EXPECT_NE(PoseGenerator(SmallOptions(), 4).parameters(), g.parameters());
}

TEST(PoseGenerator, BatchedForwardAndTheJetPathAgreeWithGenerate) {
  const PoseGenerator g = Trained();
  const SE2d pose = SE2d::FromXYYaw(2e-3, 1e-3, -1.1);
  const Eigen::VectorXd z = g.Generate(1, pose, 0.01);
  const Eigen::MatrixXd batch = g.Forward(g.Features(1, pose, 0.01).transpose());
  EXPECT_TRUE(batch.row(0).transpose().isApprox(z, 1e-12));
  double xyyaw[3] = {pose.x(), pose.y(), pose.yaw()};
  Eigen::VectorXd zt(5);
  g.GenerateT<double>(1, xyyaw, 0.01, zt.data());
  EXPECT_TRUE(zt.isApprox(z, 1e-12));
}

TEST(PoseGenerator, GenerateManyAndTheJacobianPassGiveGeneratesLatents) {
  for (const PoseGenerator& g : {Trained(), Wide()}) {
    const std::vector<SE2d> poses = {SE2d::FromXYYaw(2e-3, 1e-3, -1.1),
                                     SE2d::FromXYYaw(-3e-3, 0.5e-3, 2.9),
                                     SE2d::FromXYYaw(0, 0, 0)};
    const std::vector<double> depths = {0.01, 0.004, 0.016};
    for (int tool = 0; tool < 3; ++tool) {
      const Eigen::MatrixXd Z = g.GenerateMany(tool, poses, depths);
      ASSERT_EQ(Z.rows(), 3);
      ASSERT_EQ(Z.cols(), g.latent_dim());
      for (int i = 0; i < 3; ++i) {
        const Eigen::VectorXd z = g.Generate(tool, poses[i], depths[i]);
        EXPECT_TRUE(Z.row(i).transpose().isApprox(z, 1e-12)) << "tool " << tool << " row " << i;
        PoseGenerator::PoseJacobian J;
        EXPECT_TRUE(g.Generate(tool, poses[i], depths[i], &J).isApprox(z, 1e-12));
      }
    }
    EXPECT_EQ(g.GenerateMany(0, {}, {}).rows(), 0);
    EXPECT_THROW(g.GenerateMany(0, poses, {0.01}), std::invalid_argument);
    EXPECT_THROW(g.GenerateMany(7, poses, depths), std::invalid_argument);
  }
}

TEST(PoseGenerator, PoseJacobianMatchesAutodiffAndCentralDifferences) {
  for (const PoseGenerator& g : {Trained(), Wide()}) {
  for (int tool = 0; tool < 3; ++tool) {
    const SE2d pose = SE2d::FromXYYaw(-1e-3, 2.5e-3, 2.3);
    const double depth = 0.007;
    PoseGenerator::PoseJacobian J;
    g.Generate(tool, pose, depth, &J);
    using Jet = ceres::Jet<double, 4>;
    Jet p[3] = {Jet(pose.x(), 0), Jet(pose.y(), 1), Jet(pose.yaw(), 2)};
    std::vector<Jet> zj(g.latent_dim());
    g.GenerateT<Jet>(tool, p, Jet(depth, 3), zj.data());
    const double h[4] = {1e-7, 1e-7, 1e-6, 1e-7};
    for (int k = 0; k < g.latent_dim(); ++k) {
      for (int c = 0; c < 4; ++c) EXPECT_NEAR(J(k, c), zj[k].v[c], 1e-9 * (1 + std::abs(J(k, c))));
    }
    for (int c = 0; c < 4; ++c) {
      double v[4] = {pose.x(), pose.y(), pose.yaw(), depth};
      double w[4] = {pose.x(), pose.y(), pose.yaw(), depth};
      v[c] += h[c];
      w[c] -= h[c];
      const Eigen::VectorXd d =
          (g.Generate(tool, SE2d::FromXYYaw(v[0], v[1], v[2]), v[3]) -
           g.Generate(tool, SE2d::FromXYYaw(w[0], w[1], w[2]), w[3])) / (2 * h[c]);
      EXPECT_TRUE(d.isApprox(J.col(c), 1e-5)) << "tool " << tool << " column " << c;
    }
  }
  }
}

TEST(PoseGenerator, BackwardMatchesCentralDifferencesOfTheParameters) {
  const PoseGenerator g = Trained();
  Eigen::MatrixXd f(2, g.feature_dim());
  f.row(0) = g.Features(0, SE2d::FromXYYaw(1e-3, 0, 0.3), 0.01).transpose();
  f.row(1) = g.Features(1, SE2d::FromXYYaw(0, -1e-3, 2.0), 0.005).transpose();
  Eigen::MatrixXd w = Eigen::MatrixXd::Random(2, 5);  // L = sum w .* Z
  Eigen::VectorXd grad;
  Eigen::MatrixXd dfeat;
  g.Backward(g.parameters(), f, w, &grad, &dfeat);
  const Eigen::VectorXd theta = g.parameters();
  for (int k = 0; k < theta.size(); k += 7) {
    Eigen::VectorXd a = theta, b = theta;
    a[k] += 1e-6;
    b[k] -= 1e-6;
    const double d = ((g.Forward(a, f).array() * w.array()).sum() -
                      (g.Forward(b, f).array() * w.array()).sum()) / 2e-6;
    EXPECT_NEAR(grad[k], d, 1e-6 * (1 + std::abs(d))) << "parameter " << k;
  }
  Eigen::MatrixXd fa = f;
  fa(1, 4) += 1e-6;
  Eigen::MatrixXd fb = f;
  fb(1, 4) -= 1e-6;
  const double d = ((g.Forward(fa).array() * w.array()).sum() -
                    (g.Forward(fb).array() * w.array()).sum()) / 2e-6;
  EXPECT_NEAR(dfeat(1, 4), d, 1e-6);
}

// Parsing `file` as `source` throws a TensorFileError naming the source and `field`.
void ExpectParseErrorNaming(const TensorFile& file, const std::string& source,
                            const std::string& field) {
  try {
    PoseGenerator::Parse(file.Serialize(), source);
    ADD_FAILURE() << "expected TensorFileError naming " << field;
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), ::testing::HasSubstr(source));
    EXPECT_THAT(e.what(), ::testing::HasSubstr(field));
  }
}

TEST(PoseGenerator, FileRoundTripIsExactAndCorruptFieldsAreNamed) {
  PoseGenerator g = Trained();
  g.set_sigma_inflation(4.5);
  g.set_info_json(R"({"mode": "pixels"})");
  const std::string bytes = g.Serialize();
  const PoseGenerator back = PoseGenerator::Parse(bytes, "g.tpg");
  EXPECT_EQ(back.parameters(), g.parameters());
  EXPECT_EQ(back.latent_mean(), g.latent_mean());
  EXPECT_EQ(back.latent_stddev(), g.latent_stddev());
  EXPECT_EQ(back.sigma_inflation(), 4.5);
  EXPECT_EQ(back.weight_temperature(), 0);  // never calibrated: not written, read as 0
  EXPECT_EQ(back.options().tools, g.options().tools);
  EXPECT_EQ(back.info_json(), g.info_json());
  PoseGenerator tempered = g;
  tempered.set_weight_temperature(0.25);
  EXPECT_EQ(PoseGenerator::Parse(tempered.Serialize(), "g.tpg").weight_temperature(), 0.25);
  // What tau tempers is stored: the likelihood by default, the whole evidence for a
  // generator calibrated before; a file without the field reads as the evidence.
  EXPECT_TRUE(
      PoseGenerator::Parse(tempered.Serialize(), "g.tpg").weight_temperature_on_likelihood());
  PoseGenerator legacy = g;
  legacy.set_weight_temperature(0.25, false);
  EXPECT_FALSE(
      PoseGenerator::Parse(legacy.Serialize(), "g.tpg").weight_temperature_on_likelihood());
  {
    TensorFile file = TensorFile::Parse(tempered.Serialize(), "g.tpg");
    nlohmann::json meta = nlohmann::json::parse(file.meta_json());
    ASSERT_EQ(meta.at("weight_temperature_on"), "likelihood");
    meta.erase("weight_temperature_on");
    file.set_meta_json(meta.dump());
    const PoseGenerator old = PoseGenerator::Parse(file.Serialize(), "old.tpg");
    EXPECT_EQ(old.weight_temperature(), 0.25);
    EXPECT_FALSE(old.weight_temperature_on_likelihood());
    meta["weight_temperature_on"] = "pixels";
    file.set_meta_json(meta.dump());
    ExpectParseErrorNaming(file, "odd.tpg", "weight_temperature_on");
  }
  EXPECT_THROW(tempered.set_weight_temperature(-1), std::invalid_argument);
  EXPECT_THROW(tempered.set_weight_temperature(std::nan("")), std::invalid_argument);
  {
    // A stored temperature must be positive and finite; the error names the field.
    TensorFile file = TensorFile::Parse(tempered.Serialize(), "g.tpg");
    nlohmann::json meta = nlohmann::json::parse(file.meta_json());
    meta["weight_temperature"] = -0.5;
    file.set_meta_json(meta.dump());
    ExpectParseErrorNaming(file, "cold.tpg", "weight_temperature");
  }
  // The final stage the calibration ran with: absent = 0, else stored and read back; a
  // negative or fractional count is refused, naming the field.
  EXPECT_EQ(back.final_pixels(), 0);
  PoseGenerator staged = g;
  staged.set_final_pixels(1024);
  EXPECT_EQ(PoseGenerator::Parse(staged.Serialize(), "g.tpg").final_pixels(), 1024);
  EXPECT_THROW(staged.set_final_pixels(-1), std::invalid_argument);
  for (const nlohmann::json& bad : {nlohmann::json(-3), nlohmann::json(2.5)}) {
    TensorFile file = TensorFile::Parse(staged.Serialize(), "g.tpg");
    nlohmann::json meta = nlohmann::json::parse(file.meta_json());
    meta["final_pixels"] = bad;
    file.set_meta_json(meta.dump());
    ExpectParseErrorNaming(file, "staged.tpg", "final_pixels");
  }

  const std::string path =
      (std::filesystem::path(testing::TempDir()) / "pose_generator_test.tpg").string();
  g.Save(path);
  EXPECT_EQ(PoseGenerator::Load(path).parameters(), g.parameters());
  std::filesystem::remove(path);

  // A file with a missing field, and one of another kind.
  TensorFile file = TensorFile::Parse(bytes, "g.tpg");
  file.set_meta_json(R"({"format": "tactfunc-pose-generator", "version": 1, "tools": ["rod"]})");
  ExpectParseErrorNaming(file, "broken.tpg", "symmetry_orders");
  TensorFile other("pose_model");
  EXPECT_THROW(PoseGenerator::Parse(other.Serialize(), "other.tpm"), TensorFileError);
}

}  // namespace
}  // namespace tactfunc
