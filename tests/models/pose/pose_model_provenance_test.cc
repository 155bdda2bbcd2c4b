// Copyright 2026 The tactfunc Authors.
#include "models/pose/pose_model_provenance.h"

#include <cmath>
#include <stdexcept>
#include <string>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "models/pose/pose_mlp.h"

namespace tactfunc {
namespace {

using ::testing::HasSubstr;

PoseModelProvenance Example() {
  PoseModelProvenance p;
  p.sensor = "bubble";
  p.functaset = "/data/train.tfs";
  p.model_checksum = 358848617u;
  p.latents = "refit ceres:10";
  p.latent_map = "ceres:10";
  p.posterior_sigma = 0.002;
  p.refit_sigma = 0.003;
  p.train_samples = 9720;
  p.calibration_samples = 1080;
  p.calibration_tools = "triangle,lines3_40";
  p.excluded_tools = "l_shape";
  p.epochs = 100;
  p.batch = 256;
  p.learning_rate = 1e-3;
  p.seed = 7;
  p.final_loss = 0.0093;
  p.termination = "COMPLETED";
  p.rmse_mm = {0.22, 0.85};
  p.rmse_deg = {2.3, std::nan("")};
  return p;
}

TEST(PoseModelProvenance, RoundTripsEveryField) {
  const PoseModelProvenance p = Example();
  const PoseModelProvenance q = PoseModelProvenance::FromJson(p.ToJson(), "p.tpm");
  EXPECT_EQ(q.version, PoseModelProvenance::kVersion);
  EXPECT_EQ(q.sensor, p.sensor);
  EXPECT_EQ(q.functaset, p.functaset);
  EXPECT_EQ(q.model_checksum, p.model_checksum);
  EXPECT_EQ(q.latents, p.latents);
  EXPECT_EQ(q.latent_map, p.latent_map);
  EXPECT_EQ(q.posterior_sigma, p.posterior_sigma);
  EXPECT_EQ(q.refit_sigma, p.refit_sigma);
  EXPECT_EQ(q.train_samples, p.train_samples);
  EXPECT_EQ(q.calibration_samples, p.calibration_samples);
  EXPECT_EQ(q.calibration_tools, p.calibration_tools);
  EXPECT_EQ(q.excluded_tools, p.excluded_tools);
  EXPECT_EQ(q.epochs, p.epochs);
  EXPECT_EQ(q.batch, p.batch);
  EXPECT_EQ(q.learning_rate, p.learning_rate);
  EXPECT_EQ(q.seed, p.seed);
  EXPECT_EQ(q.final_loss, p.final_loss);
  EXPECT_EQ(q.termination, p.termination);
  EXPECT_EQ(q.rmse_mm.train, p.rmse_mm.train);
  EXPECT_EQ(q.rmse_mm.test, p.rmse_mm.test);
  EXPECT_EQ(q.rmse_deg.train, p.rmse_deg.train);
  EXPECT_TRUE(std::isnan(q.rmse_deg.test));  // written as null
  EXPECT_EQ(q.ToJson(), p.ToJson());
}

TEST(PoseModelProvenance, ItsJsonIsAPoseModelInfo) {
  PoseMlp::Options options;
  options.input_dim = 4;
  options.hidden_sizes = {8};
  PoseMlp mlp(options, 1);
  mlp.set_info_json(Example().ToJson());
  EXPECT_EQ(PoseModelProvenance::FromJson(mlp.info_json(), "p.tpm").latent_map, "ceres:10");
}

TEST(PoseModelProvenance, AWrongTypeNamesTheFieldAndTheFile) {
  for (const auto& [json, field] :
       std::vector<std::pair<std::string, std::string>>{
           {R"({"posterior_sigma": "0.002"})", "posterior_sigma"},
           {R"({"sensor": 3})", "sensor"},
           {R"({"model_checksum": -1})", "model_checksum"},
           {R"({"epochs": 1.5})", "epochs"},
           {R"({"rmse_mm": {"train": "x"}})", "rmse_mm"},
           {R"({"provenance_version": 99})", "provenance_version"}}) {
    try {
      PoseModelProvenance::FromJson(json, "bad.tpm");
      ADD_FAILURE() << "expected std::invalid_argument for " << json;
    } catch (const std::invalid_argument& e) {
      EXPECT_THAT(e.what(), HasSubstr("'" + field + "'")) << json;
      EXPECT_THAT(e.what(), HasSubstr("bad.tpm")) << json;
    }
  }
  EXPECT_THROW(PoseModelProvenance::FromJson("[1, 2]", "bad.tpm"), std::invalid_argument);
}

TEST(PoseModelProvenance, AnInfoOfTheReleasedPoseModelsStillParses) {
  // The info of models/pretrained/pose_bubble.tpm as train-pose wrote it (no version).
  const std::string old_info =
      R"({"batch":256,"calibration_samples":1080,"calibration_tools":"","epochs":100,)"
      R"("excluded_tools":"","final_loss":0.00927815103727113,"functaset":"/tmp/p1k.tfs",)"
      R"("latent_map":"ceres:10","latents":"refit ceres:10","learning_rate":0.001,)"
      R"("model_checksum":358848617,"posterior_sigma":0.002,"rmse_deg":{"test":35.67,)"
      R"("train":2.33},"rmse_mm":{"test":0.85,"train":0.22},"seed":1,"sensor":"bubble",)"
      R"("termination":"COMPLETED","train_samples":9720})";
  const PoseModelProvenance p = PoseModelProvenance::FromJson(old_info, "pose_bubble.tpm");
  EXPECT_EQ(p.version, 0);
  EXPECT_EQ(p.sensor, "bubble");
  EXPECT_EQ(p.latent_map, "ceres:10");
  EXPECT_EQ(p.posterior_sigma, 0.002);
  EXPECT_EQ(p.model_checksum, 358848617u);
  EXPECT_EQ(p.epochs, 100);
  EXPECT_EQ(p.seed, 1u);
  EXPECT_EQ(p.rmse_mm.test, 0.85);
}

TEST(PoseModelProvenance, AbsentFieldsGetTheirDefaults) {
  const PoseModelProvenance empty = PoseModelProvenance::FromJson("{}", "old.tpm");
  EXPECT_EQ(empty.version, 0);
  EXPECT_EQ(empty.sensor, "");
  EXPECT_FALSE(empty.model_checksum.has_value());
  EXPECT_EQ(empty.latent_map, "functaset");
  EXPECT_EQ(empty.posterior_sigma, 0);
  EXPECT_FALSE(empty.epochs.has_value());
  // Before "latent_map" was written, a refit showed only in "latents".
  EXPECT_EQ(PoseModelProvenance::FromJson(R"({"latents": "refit ceres:5"})", "old.tpm").latent_map,
            "ceres:5");
}

}  // namespace
}  // namespace tactfunc
