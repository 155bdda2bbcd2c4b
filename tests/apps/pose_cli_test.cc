// Copyright 2026 The tactfunc Authors.
//
// `tactfunc train-pose`, `tactfunc pose` and `tactfunc bench posterior` as a user runs
// them: a tiny hand-built model (tests/support/functa_test_util.h), a tiny dataset, its
// functaset from `tactfunc encode`, and a tiny pose model from `train-pose`; exit codes,
// the --json last line, the files written, and bad input that fails with a message
// naming the file or flag.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include "estimation/data/image_io.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "estimation/posterior/pose_posterior.h"
#include "tests/apps/cli_test_util.h"
#include "models/pose/pose_generator.h"
#include "models/pose/pose_mlp.h"
#include "models/trunk/functa_model.h"
#include "nlohmann/json.hpp"
#include "tests/support/dataset_test_util.h"
#include "tests/support/functa_test_util.h"
#include "tests/support/test_dir.h"

namespace tactfunc {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

using Result = testing_util::CliResult;
using testing_util::Slurp;

// One model, dataset, functaset and pose model for the suite.
class PoseCliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    Result encode;
    root_ = new fs::path(testing_util::MakeEncodedFixture("tactfunc_pose_cli", &encode));
    ASSERT_EQ(encode.exit_code, 0) << encode.err;
    train_pose_ = new Result(Run("train-pose --functaset " + Root("f.tfs") + " --out " +
                                 Root("p.tpm") + " --hidden 16,16 --epochs 20 --batch 4 --json"));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*root_);
    delete root_;
    delete train_pose_;
  }
  static std::string Root(const std::string& name) { return (*root_ / name).string(); }

  static Result Run(const std::string& args) {
    return testing_util::RunTactfunc(*root_, args);
  }

  // `pose` on labelled bubble test frame 3 of the dataset.
  static std::string PoseArgs(const std::string& sampler) {
    return "pose --model " + Root("m.tfm") + " --pose-model " + Root("p.tpm") + " --functaset " +
           Root("f.tfs") + " --data " + Root("d") + " --id 000003 --samples 20 --sampler " +
           sampler;
  }

  static fs::path* root_;
  static Result* train_pose_;
};

fs::path* PoseCliTest::root_ = nullptr;
Result* PoseCliTest::train_pose_ = nullptr;

TEST_F(PoseCliTest, TrainPoseReportsRmsePerToolAndWritesTheModel) {
  const Result& r = *train_pose_;
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("all (bubble)"));  // the table's total row
  EXPECT_THAT(r.err, HasSubstr("unknown tool 'pen'"));  // tiny data's tools are not ToolSet()'s
  const nlohmann::json j = r.LastJson();
  EXPECT_EQ(j["sensor"], "bubble");  // the default when the functaset has both
  for (const char* key : {"rmse_mm", "rmse_deg"}) {
    ASSERT_TRUE(j.contains(key)) << key;
    EXPECT_TRUE(j[key].contains("train")) << key;
    EXPECT_TRUE(j[key].contains("test")) << key;
  }
  EXPECT_GT(j["rmse_mm"]["train"].get<double>(), 0.0);
  ASSERT_TRUE(j.contains("per_tool"));
  EXPECT_TRUE(j["per_tool"].contains("pen"));
  EXPECT_TRUE(j["per_tool"].contains("hex_key"));
  EXPECT_EQ(j["per_tool"]["pen"]["symmetry_order"], 1);  // unknown tool -> 1
  EXPECT_EQ(j["out"], Root("p.tpm"));
  const PoseMlp model = PoseMlp::Load(Root("p.tpm"));
  EXPECT_EQ(model.input_dim(), 8);  // the bubble trunk's latent_dim
  EXPECT_EQ(nlohmann::json::parse(model.info_json())["sensor"], "bubble");
}

TEST_F(PoseCliTest, TrainPoseCanRefitTheLatentsWithThePosteriorsFit) {
  const Result r = Run("train-pose --functaset " + Root("f.tfs") + " --model " + Root("m.tfm") +
                       " --data " + Root("d") + " --refit ceres:3 --out " + Root("p_refit.tpm") +
                       " --hidden 8 --epochs 5 --batch 4 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("re-fitted 12 latents with ceres:3"));
  EXPECT_EQ(nlohmann::json::parse(PoseMlp::Load(Root("p_refit.tpm")).info_json())["latents"],
            "refit ceres:3");
  // The refit reports its progress where no bar is drawn, and its checkpoint is gone once
  // the model is written.
  EXPECT_THAT(r.err, HasSubstr("train-pose refit: 12/12 latents (100%)"));
  EXPECT_FALSE(fs::exists(Root("p_refit.tpm.refit.ckpt")));
  // --resume from a checkpoint that is not one: refused by name, nothing written.
  testing_util::WriteText(Root("p_resume.tpm.refit.ckpt"), "not a checkpoint");
  const Result foreign = Run("train-pose --functaset " + Root("f.tfs") + " --model " +
                             Root("m.tfm") + " --data " + Root("d") + " --refit ceres:3 --out " +
                             Root("p_resume.tpm") + " --hidden 8 --epochs 5 --batch 4 --resume");
  EXPECT_NE(foreign.exit_code, 0);
  EXPECT_THAT(foreign.err, HasSubstr("cannot resume from checkpoint"));
  EXPECT_THAT(foreign.err, HasSubstr("p_resume.tpm.refit.ckpt"));
  EXPECT_FALSE(fs::exists(Root("p_resume.tpm")));
  // An MLP that diverges writes nothing but keeps the complete refit; info names it, and
  // --resume takes it (nothing fitted again) to the model of a run never stopped.
  const std::string refit_args = "train-pose --functaset " + Root("f.tfs") + " --model " +
                                 Root("m.tfm") + " --data " + Root("d") +
                                 " --refit ceres:3 --out " + Root("p_kept.tpm") +
                                 " --hidden 8 --epochs 5 --batch 4";
  const Result diverged = Run(refit_args + " --lr 1e30");
  EXPECT_NE(diverged.exit_code, 0);
  EXPECT_THAT(diverged.err, HasSubstr("p_kept.tpm.refit.ckpt, which --resume takes"));
  EXPECT_FALSE(fs::exists(Root("p_kept.tpm")));
  const Result described = Run("info " + Root("p_kept.tpm.refit.ckpt"));
  ASSERT_EQ(described.exit_code, 0) << described.err;
  EXPECT_THAT(described.out, HasSubstr("bubble latents re-fitted: the first 12 of 12 entries"));
  const Result kept = Run(refit_args + " --resume");
  ASSERT_EQ(kept.exit_code, 0) << kept.err;
  EXPECT_THAT(kept.out, HasSubstr("(12 taken from " + Root("p_kept.tpm.refit.ckpt") + ")"));
  EXPECT_EQ(testing_util::Slurp(Root("p_kept.tpm")), testing_util::Slurp(Root("p_refit.tpm")));
  EXPECT_FALSE(fs::exists(Root("p_kept.tpm.refit.ckpt")));
  // Without --resume the run starts anew (and replaces the stale file when it is done).
  const Result anew = Run("train-pose --functaset " + Root("f.tfs") + " --model " +
                          Root("m.tfm") + " --data " + Root("d") + " --refit ceres:3 --out " +
                          Root("p_resume.tpm") + " --hidden 8 --epochs 5 --batch 4");
  ASSERT_EQ(anew.exit_code, 0) << anew.err;
  EXPECT_EQ(testing_util::Slurp(Root("p_resume.tpm")), testing_util::Slurp(Root("p_refit.tpm")));
  EXPECT_FALSE(fs::exists(Root("p_resume.tpm.refit.ckpt")));

  // A larger pixel sigma gives the latent prior more weight: other latents, another fit
  // of the MLP, and the sigma recorded with the model.
  const Result wide = Run("train-pose --functaset " + Root("f.tfs") + " --model " +
                          Root("m.tfm") + " --data " + Root("d") + " --refit ceres:3" +
                          " --refit-sigma 0.5 --out " + Root("p_refit_wide.tpm") +
                          " --hidden 8 --epochs 5 --batch 4 --json");
  ASSERT_EQ(wide.exit_code, 0) << wide.err;
  const auto info = nlohmann::json::parse(PoseMlp::Load(Root("p_refit.tpm")).info_json());
  const auto wide_info =
      nlohmann::json::parse(PoseMlp::Load(Root("p_refit_wide.tpm")).info_json());
  EXPECT_FALSE(info.contains("refit_sigma"));
  EXPECT_EQ(wide_info["refit_sigma"].get<double>(), 0.5);
  EXPECT_NE(wide_info["final_loss"].get<double>(), info["final_loss"].get<double>());

  const Result bad = Run("train-pose --functaset " + Root("f.tfs") + " --refit ceres:3 --out " +
                         Root("p_bad.tpm"));
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_THAT(bad.err, HasSubstr("--refit needs --model and --data"));
  EXPECT_FALSE(fs::exists(Root("p_bad.tpm")));
}

TEST_F(PoseCliTest, PoseWithEachSamplerPrintsMeanCovarianceAndWritesFiles) {
  ASSERT_EQ(train_pose_->exit_code, 0) << train_pose_->err;
  for (const std::string sampler : {"sgld", "laplace", "knn"}) {
    SCOPED_TRACE(sampler);
    const std::string out = Root("pose_" + sampler);
    const Result r = Run(PoseArgs(sampler) + " --out " + out + " --json");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    EXPECT_THAT(r.out, HasSubstr("tangent space at the mean"));
    EXPECT_THAT(r.out, HasSubstr("[35]"));  // the ROS yaw-yaw index
    const nlohmann::json j = r.LastJson();
    for (const char* key : {"mean", "covariance", "ms", "sampler", "samples", "truth"}) {
      EXPECT_TRUE(j.contains(key)) << key;
    }
    for (const char* key : {"x_m", "y_m", "yaw_rad"}) EXPECT_TRUE(j["mean"].contains(key)) << key;
    EXPECT_EQ(j["sampler"], sampler);
    ASSERT_EQ(j["covariance"].size(), 3u);
    EXPECT_EQ(j["covariance"][0].size(), 3u);
    EXPECT_GE(j["covariance"][2][2].get<double>(), 0.0);
    // knn returns --knn-k (8) labelled neighbours (the unlabelled frame 2 is searched
    // past); the latent samplers what was asked.
    EXPECT_EQ(j["samples"].get<int>(), sampler == "knn" ? 8 : 20);
    ASSERT_TRUE(fs::exists(out + "/posterior.png"));
    ASSERT_TRUE(fs::exists(out + "/posterior.json"));
    const nlohmann::json record = nlohmann::json::parse(Slurp(out + "/posterior.json"));
    EXPECT_EQ(record["samples"].size(), j["samples"].get<std::size_t>());
    EXPECT_EQ(record["samples"][0].size(), 4u);  // x, y, yaw, weight
    EXPECT_DOUBLE_EQ(record["mean"]["x_m"].get<double>(), j["mean"]["x_m"].get<double>());
    const Image picture = ReadImage(out + "/posterior.png", PixelEncoding::kRgb8);
    EXPECT_GT(picture.cols, 400);  // image panel + zoom panel side by side
  }
}

TEST_F(PoseCliTest, SgldRunsOnMinibatchesWithTheControlVariateUnlessToldOtherwise) {
  ASSERT_EQ(train_pose_->exit_code, 0) << train_pose_->err;
  // By default batches of kDefaultSgldMinibatch pixels, or every pixel of a smaller frame.
  Result r = Run(PoseArgs("sgld") + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  nlohmann::json sgld = r.LastJson()["sgld"];
  const int pixels = sgld["pixels"].get<int>();
  ASSERT_GT(pixels, 20);
  EXPECT_EQ(sgld["minibatched"].get<bool>(), pixels > PosePosterior::kDefaultSgldMinibatch);
  // A batch smaller than the frame: minibatches anchored at the fit (the control variate).
  const int batch = pixels / 4;
  r = Run(PoseArgs("sgld") + " --json --sgld-minibatch " + std::to_string(batch));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  sgld = r.LastJson()["sgld"];
  EXPECT_TRUE(sgld["minibatched"].get<bool>());
  EXPECT_TRUE(sgld["control_variate"].get<bool>());
  EXPECT_EQ(sgld["pixels_per_gradient"].get<int>(), batch);
  EXPECT_EQ(sgld["termination"], "COMPLETED");
  // 0: full batches.
  r = Run(PoseArgs("sgld") + " --json --sgld-minibatch 0");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  sgld = r.LastJson()["sgld"];
  EXPECT_FALSE(sgld["minibatched"].get<bool>());
  EXPECT_FALSE(sgld["control_variate"].get<bool>());
  EXPECT_EQ(sgld["pixels_per_gradient"].get<int>(), pixels);
  // A negative batch is refused naming the flag.
  r = Run(PoseArgs("sgld") + " --sgld-minibatch -3");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--sgld-minibatch"));
}

// --max-pixels thins the latent path's problem (fit and sampler) to N evenly spaced
// valid pixels; 0 keeps every one, a negative count is refused naming the flag.
TEST_F(PoseCliTest, MaxPixelsThinsTheLatentProblemToThatManyPixels) {
  ASSERT_EQ(train_pose_->exit_code, 0) << train_pose_->err;
  Result r = Run(PoseArgs("sgld") + " --json --sgld-minibatch 0");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const int pixels = r.LastJson()["sgld"]["pixels"].get<int>();
  ASSERT_GT(pixels, 20);
  const int fewer = pixels / 3;
  r = Run(PoseArgs("sgld") + " --json --sgld-minibatch 0 --max-pixels " + std::to_string(fewer));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.LastJson()["sgld"]["pixels"].get<int>(), fewer);
  r = Run(PoseArgs("sgld") + " --json --sgld-minibatch 0 --max-pixels 0");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.LastJson()["sgld"]["pixels"].get<int>(), pixels);
  r = Run(PoseArgs("laplace") + " --max-pixels -1");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--max-pixels"));
}

// A single video is a dataset too: --data names the file, --reference-index its
// no-contact frame; the frame ids are the other frames' indices.
TEST_F(PoseCliTest, PoseReadsAFrameOfAVideo) {
  std::vector<cv::Mat> frames;
  for (int i = 0; i < 4; ++i) frames.push_back(testing_util::PatternFrame(i));
  const std::string video = Root("clip.avi");
  if (!testing_util::WriteMjpgVideo(video, frames)) GTEST_SKIP() << "no MJPG writer in this OpenCV";
  const Result info = Run("info " + video + " --reference-index 1 --json");
  ASSERT_EQ(info.exit_code, 0) << info.err;
  const Result train = Run("train-pose --functaset " + Root("f.tfs") + " --sensor gelslim --out " +
                           Root("pg.tpm") + " --hidden 8 --epochs 3 --batch 4");
  ASSERT_EQ(train.exit_code, 0) << train.err;
  const std::string args = "pose --model " + Root("m.tfm") + " --pose-model " + Root("pg.tpm") +
                           " --data " + video + " --sensor gelslim --sampler laplace --samples 10 "
                           "--allow-other-frames --json";
  Result r = Run(args + " --reference-index 1 --id 000002");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(r.LastJson().contains("mean"));
  // Frame 1 is the reference there, not a frame.
  r = Run(args + " --reference-index 1 --id 000001");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("000001"));
}

TEST_F(PoseCliTest, PoseWithTheGeneratorMethodPrintsTheModeAndToolProbabilities) {
  ASSERT_EQ(train_pose_->exit_code, 0) << train_pose_->err;
  // The generator knows the simulator's tools: a small synthetic bubble dataset of them.
  const Result synth = Run("synth --out " + Root("gd") + " --frames-per-tool 6 --sensors bubble "
                           "--seed 3 --threads 1");
  ASSERT_EQ(synth.exit_code, 0) << synth.err;
  const Result encode = Run("encode --model " + Root("m.tfm") + " --data " + Root("gd") +
                            " --out " + Root("gf.tfs") + " --threads 1");
  ASSERT_EQ(encode.exit_code, 0) << encode.err;
  const Result train = Run("train-generator --model " + Root("m.tfm") + " --functaset " +
                           Root("gf.tfs") + " --data " + Root("gd") + " --out " + Root("g.tpg") +
                           " --mode latents --epochs 5 --hidden 16 --calibration-frames 4");
  ASSERT_EQ(train.exit_code, 0) << train.err;
  // Its stage checkpoints are gone once the generator is written; --resume without one
  // trains anew, to the same bytes.
  EXPECT_FALSE(fs::exists(Root("g.tpg.regression.ckpt")));
  EXPECT_THAT(train.err, HasSubstr("train-generator regression: 5/5 epochs"));
  const Result again = Run("train-generator --model " + Root("m.tfm") + " --functaset " +
                           Root("gf.tfs") + " --data " + Root("gd") + " --out " + Root("g2.tpg") +
                           " --mode latents --epochs 5 --hidden 16 --calibration-frames 4 --resume");
  ASSERT_EQ(again.exit_code, 0) << again.err;
  EXPECT_EQ(Slurp(Root("g2.tpg")), Slurp(Root("g.tpg")));
  // The posterior's calibration is said, and stored: info reads it back.
  EXPECT_THAT(train.out, HasSubstr("train-generator: mode weight temperature"));
  const Result info = Run("info " + Root("g.tpg"));
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_THAT(info.out, HasSubstr("pose generator: 12 tools, latent"));
  EXPECT_THAT(info.out, HasSubstr("mode weight temperature"));
  EXPECT_THAT(info.out, HasSubstr("calibrated with no final stage"));
  // --recalibrate calibrates a trained generator again, here with the final stage on,
  // which it records (info shows it) and keeps the training's parameters and record.
  const Result recal = Run("train-generator --model " + Root("m.tfm") + " --functaset " +
                           Root("gf.tfs") + " --data " + Root("gd") + " --out " +
                           Root("g_staged.tpg") + " --recalibrate " + Root("g.tpg") +
                           " --final-pixels 600 --calibration-frames 4 --temperature-frames 8");
  ASSERT_EQ(recal.exit_code, 0) << recal.err;
  EXPECT_THAT(recal.out, HasSubstr("final stage on 600 pixels"));
  EXPECT_THAT(recal.err, ::testing::Not(HasSubstr("regression")));
  const PoseGenerator staged = PoseGenerator::Load(Root("g_staged.tpg"));
  const PoseGenerator trained = PoseGenerator::Load(Root("g.tpg"));
  EXPECT_EQ(staged.parameters(), trained.parameters());
  EXPECT_EQ(staged.final_pixels(), 600);
  EXPECT_EQ(nlohmann::json::parse(staged.info_json())["recalibrated_from"], Root("g.tpg"));
  EXPECT_EQ(nlohmann::json::parse(staged.info_json())["regression_epochs"], 5);
  EXPECT_THAT(Run("info " + Root("g_staged.tpg")).out,
              HasSubstr("calibrated with a final stage on 600 pixels"));
  // info says what a temperature tempers: a file calibrated when it tempered the whole
  // evidence says so, in its line and in --json.
  PoseGenerator legacy = trained;
  legacy.set_weight_temperature(0.5, false);
  legacy.Save(Root("g_legacy.tpg"));
  const Result legacy_info = Run("info " + Root("g_legacy.tpg"));
  ASSERT_EQ(legacy_info.exit_code, 0) << legacy_info.err;
  EXPECT_THAT(legacy_info.out, HasSubstr("mode weight temperature 0.500 on the whole evidence"));
  EXPECT_THAT(Run("info --json " + Root("g_legacy.tpg")).out,
              HasSubstr("\"weight_temperature_on\":\"evidence\""));
  PoseGenerator tempered = trained;
  tempered.set_weight_temperature(0.5);
  tempered.Save(Root("g_tempered.tpg"));
  EXPECT_THAT(Run("info " + Root("g_tempered.tpg")).out,
              HasSubstr("mode weight temperature 0.500 on the likelihood"));
  // A generator of another latent size is refused, naming the flag and both sizes.
  const Result wider = Run("train-generator --model " + Root("m.tfm") + " --functaset " +
                           Root("gf.tfs") + " --data " + Root("gd") + " --out " +
                           Root("g_bad.tpg") + " --recalibrate " +
                           TACTFUNC_SOURCE_DIR "/models/pretrained/pose_generator_bubble.tpg");
  EXPECT_EQ(wider.exit_code, 2);
  EXPECT_THAT(wider.err, HasSubstr("--recalibrate"));
  EXPECT_THAT(wider.err, HasSubstr("latent_dim is 128"));
  EXPECT_FALSE(fs::exists(Root("g_bad.tpg")));
  const std::string out = Root("pose_generator");
  const std::string args = "pose --method generator --model " + Root("m.tfm") + " --pose-model " +
                           Root("p.tpm") + " --functaset " + Root("gf.tfs") + " --data " +
                           Root("gd") + " --id 000003 --samples 20";
  Result r = Run(args + " --generator " + Root("g.tpg") + " --out " + out + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("tangent space at the mode"));
  const nlohmann::json j = r.LastJson();
  EXPECT_EQ(j["method"], "generator");
  for (const char* key : {"mean", "posterior_mean", "covariance", "ms", "tool",
                          "tool_probabilities", "truth"}) {
    EXPECT_TRUE(j.contains(key)) << key;
  }
  EXPECT_EQ(j["samples"].get<int>(), 20);
  ASSERT_TRUE(fs::exists(out + "/posterior.png"));
  const nlohmann::json record = nlohmann::json::parse(Slurp(out + "/posterior.json"));
  EXPECT_GE(record["components"].size(), 1u);
  EXPECT_EQ(record["samples"].size(), 20u);
  // One mode of the tool: the posterior mean is that mode.
  if (j["modes"].get<int>() == 1) {
    EXPECT_NEAR(record["posterior_mean"]["x_m"].get<double>(), record["mean"]["x_m"].get<double>(),
                1e-12);
  }
  // --final-pixels refines the generator path's modes on more pixels (here every pixel);
  // the latent path has no modes to refine and refuses it, naming the flag.
  r = Run(args + " --generator " + Root("g.tpg") + " --final-pixels 100000 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_GE(r.LastJson()["modes"].get<int>(), 1);
  r = Run("pose --model " + Root("m.tfm") + " --pose-model " + Root("p.tpm") + " --data " +
          Root("gd") + " --id 000003 --final-pixels 512");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--final-pixels"));
  // MCMC over the pose: 4 chains of 5 kept samples, their diagnostics in the record.
  r = Run(args + " --generator " + Root("g.tpg") + " --sampler rwm --out " + out + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("split R-hat"));
  const nlohmann::json mcmc = nlohmann::json::parse(Slurp(out + "/posterior.json"));
  EXPECT_EQ(mcmc["sampler"], "rwm");
  EXPECT_EQ(mcmc["samples"].size(), 20u);
  EXPECT_EQ(mcmc["mcmc"]["split_rhat"].size(), 4u);
  r = Run("pose --model " + Root("m.tfm") + " --pose-model " + Root("p.tpm") + " --data " +
          Root("gd") + " --id 000003 --sampler mala");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--method generator"));
  // Both paths on the same frame: each record in its subfolder, one stacked picture.
  const std::string both = Root("pose_both");
  r = Run("pose --method both --sampler laplace --model " + Root("m.tfm") + " --pose-model " +
          Root("p.tpm") + " --data " + Root("gd") + " --id 000003 --samples 20 --generator " +
          Root("g.tpg") + " --out " + both);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("latent path"));
  EXPECT_THAT(r.out, HasSubstr("generator path"));
  EXPECT_EQ(nlohmann::json::parse(Slurp(both + "/latent/posterior.json"))["sampler"], "laplace");
  EXPECT_EQ(nlohmann::json::parse(Slurp(both + "/generator/posterior.json"))["method"],
            "generator");
  const Image upper = ReadImage(both + "/latent/posterior.png", PixelEncoding::kRgb8);
  const Image lower = ReadImage(both + "/generator/posterior.png", PixelEncoding::kRgb8);
  const Image stacked = ReadImage(both + "/posterior.png", PixelEncoding::kRgb8);
  EXPECT_GT(stacked.rows, upper.rows + lower.rows);  // one above the other
  EXPECT_GE(stacked.cols, std::max(upper.cols, lower.cols));
  r = Run("pose --method both --model " + Root("m.tfm") + " --pose-model " + Root("p.tpm") +
          " --data " + Root("gd") + " --id 000003");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--generator"));
  r = Run("pose --method both --sampler mala --generator " + Root("g.tpg") + " --model " +
          Root("m.tfm") + " --pose-model " + Root("p.tpm") + " --data " + Root("gd") +
          " --id 000003");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("latent path's sampler"));
  // Every tool fitted: probabilities over the generator's tools sum to 1.
  r = Run(args + " --generator " + Root("g.tpg") + " --unknown-tool --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  double total = 0;
  const nlohmann::json unknown = r.LastJson();
  ASSERT_GE(unknown["tool_probabilities"].size(), 2u);
  for (const auto& p : unknown["tool_probabilities"]) total += p.get<double>();
  EXPECT_NEAR(total, 1.0, 1e-9);
  // eval-generator on fresh contacts, one row per contact in --contacts-csv, with each
  // contact's Cramer-Rao bound from the simulator (--information).
  const std::string contacts = Root("contacts.csv");
  r = Run("eval-generator --model " + Root("m.tfm") + " --generator " + Root("g.tpg") +
          " --contacts-per-tool 1 --information --picture " + Root("bound.png") +
          " --contacts-csv " + contacts + " --diagnose --diagnose-picture " +
          Root("wrong.png") + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json eval = r.LastJson();
  for (const char* key : {"rmse_mm", "position_median_mm", "position_p90_mm", "coverage_90"}) {
    EXPECT_TRUE(eval.contains(key)) << key;
  }
  std::istringstream rows(Slurp(contacts));
  std::string line;
  ASSERT_TRUE(std::getline(rows, line));
  EXPECT_THAT(line, HasSubstr("truth_x_mm,truth_y_mm,truth_yaw_deg"));
  EXPECT_THAT(line, HasSubstr("position_error_mm,yaw_error_deg"));
  EXPECT_THAT(line, HasSubstr("mode_sd_x_mm,mode_sd_y_mm,mode_sd_yaw_deg"));
  EXPECT_THAT(line, HasSubstr("bound_sd_along_mm,bound_sd_across_mm,bound_sd_yaw_deg"));
  EXPECT_THAT(line, HasSubstr("frame_llr_truth_over_mode,trunk_llr_truth_over_mode"));
  EXPECT_THAT(line, HasSubstr(",mode_weight"));
  int count = 0, judged = 0, several_modes = 0, several_held = 0;
  double sum_sq = 0, bound_sq = 0;
  while (std::getline(rows, line)) {
    std::vector<double> v;
    std::istringstream cells(line);
    std::string cell;
    while (std::getline(cells, cell, ',')) v.push_back(std::atof(cell.c_str()));
    ASSERT_EQ(v.size(), 31u) << line;
    // position_error_mm is the distance between the truth's and the mode's positions.
    EXPECT_NEAR(v[14], std::hypot(v[7] - v[3], v[8] - v[4]), 2e-4) << line;
    // The mode's Laplace sd along, across and in yaw (none for a C_inf tool, n = v[2] = 0).
    for (int c : {18, 19, 20}) {
      if (c < 20 || v[2] != 0) {
        EXPECT_GT(v[c], 0) << "column " << c << ", " << line;
      }
    }
    // The bound's sd along, across, in yaw (none for a C_inf tool) and in depth; the
    // frame's log-likelihood ratio only for a wrong mode.
    for (int c : {21, 22, 23, 24}) {
      if (c != 23 || v[2] != 0) {
        EXPECT_GT(v[c], 0) << "column " << c << ", " << line;
      }
    }
    const bool wrong = (v[2] != 0 && v[15] > 5) || v[14] > 1;
    EXPECT_EQ(wrong, !std::isnan(v[25])) << line;
    // And through the trunk (TrunkLogLikelihoodRatio), for the same wrong modes only.
    EXPECT_EQ(wrong, !std::isnan(v[26])) << line;
    // --diagnose's whole-frame objectives (truth, mode, the trunk's best), for the same;
    // the trunk's own best latent, fitted from the truth's rendering, fits the frame at
    // least as well as that rendering.
    for (int c : {27, 28, 29}) {
      EXPECT_EQ(wrong, !std::isnan(v[c])) << "column " << c << ", " << line;
    }
    if (wrong) {
      EXPECT_LE(v[29], v[27] + 0.01) << line;
    }
    // The mode's weight among the true tool's modes (v[16] of them): all of it when it is
    // the only one, and the heaviest share otherwise.
    if (v[16] == 1) {
      EXPECT_NEAR(v[30], 1.0, 1e-4) << line;
    } else {
      EXPECT_GE(v[30], 1.0 / v[16] - 1e-4) << line;
      EXPECT_LE(v[30], 1.0) << line;
      ++several_modes;
      several_held += (v[2] == 0 || v[15] <= 10) && v[14] <= 1;
    }
    judged += wrong;
    sum_sq += v[14] * v[14];
    bound_sq += v[21] * v[21] + v[22] * v[22];
    ++count;
  }
  // The weights' reliability counts the contacts with two or more modes, and whether
  // their heaviest holds the truth, as the rows do.
  int reliability_contacts = 0, reliability_held = 0;
  for (const auto& bin : eval["mode_weight_reliability"]) {
    EXPECT_LT(bin["from"].get<double>(), bin["to"].get<double>());
    EXPECT_GE(bin["mean_weight"].get<double>(), bin["from"].get<double>());
    EXPECT_LE(bin["mean_weight"].get<double>(), bin["to"].get<double>());
    reliability_contacts += bin["contacts"].get<int>();
    reliability_held += bin["held_truth"].get<int>();
  }
  EXPECT_EQ(reliability_contacts, several_modes);
  EXPECT_GT(several_modes, 0) << "the small test generator leaves contacts with several modes";
  EXPECT_EQ(reliability_held, several_held);
  // The printed bound is the contacts' RMS; every wrong mode gets a verdict.
  const nlohmann::json& information = eval["information"];
  EXPECT_NEAR(std::sqrt(bound_sq / count), information["bound_rmse_mm"].get<double>(),
              1e-3 + 1e-3 * information["bound_rmse_mm"].get<double>());
  EXPECT_EQ(information["wrong_modes"]["count"].get<int>(), judged);
  ASSERT_GT(judged, 0) << "the small test trunk has wrong modes to judge";
  EXPECT_LE(information["wrong_modes"]["trunk_prefers_truth"].get<int>() +
                information["wrong_modes"]["trunk_prefers_mode"].get<int>(),
            judged);
  // --diagnose: every wrong mode's whole-frame objectives, the trunk's own best latent
  // (Ceres from the truth's generated latent) never above the truth's rendering.
  int whole_frames = 0;
  std::istringstream out_lines(r.out);
  while (std::getline(out_lines, line)) {
    double mode_cost = 0, truth_cost = 0, trunk_cost = 0, truth_pct = 0, mode_pct = 0;
    if (std::sscanf(line.c_str(),
                    "    whole frame: mode %lf, truth %lf, the trunk's own best latent %lf (truth "
                    "%lf %%, mode %lf %% above it)",
                    &mode_cost, &truth_cost, &trunk_cost, &truth_pct, &mode_pct) != 5) {
      continue;
    }
    ++whole_frames;
    EXPECT_GT(trunk_cost, 0) << line;
    EXPECT_LE(trunk_cost, truth_cost * (1 + 1e-6)) << line;
    // The percentages from the printed costs, within their rounding (0.05 each).
    const auto tolerance = [&](double cost) {
      return 0.06 + 100 * 0.05 * (1 / trunk_cost + cost / (trunk_cost * trunk_cost));
    };
    EXPECT_NEAR(truth_pct, 100 * (truth_cost / trunk_cost - 1), tolerance(truth_cost)) << line;
    EXPECT_NEAR(mode_pct, 100 * (mode_cost / trunk_cost - 1), tolerance(mode_cost)) << line;
  }
  EXPECT_EQ(whole_frames, judged);
  // --diagnose-picture: the wrong modes' renderings, or a word that there were none.
  if (judged > 0) {
    EXPECT_EQ(Slurp(Root("wrong.png")).substr(1, 3), "PNG");
    EXPECT_THAT(r.out, HasSubstr("wrong modes)"));
  } else {
    EXPECT_FALSE(fs::exists(Root("wrong.png")));
    EXPECT_THAT(r.out, HasSubstr("no wrong mode"));
  }
  EXPECT_EQ(Slurp(Root("bound.png")).substr(1, 3), "PNG");
  // The picture needs the bound.
  r = Run("eval-generator --model " + Root("m.tfm") + " --generator " + Root("g.tpg") +
          " --contacts-per-tool 1 --picture " + Root("bound2.png"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--information"));
  r = Run("eval-generator --model " + Root("m.tfm") + " --generator " + Root("g.tpg") +
          " --contacts-per-tool 1 --diagnose-picture " + Root("wrong2.png"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--diagnose"));
  // --tools: only those tools, each contact the one the run over every tool drew (rod is
  // the generator's 7th tool: row 6 of the run above).
  const std::string rod_csv = Root("contacts_rod.csv");
  r = Run("eval-generator --model " + Root("m.tfm") + " --generator " + Root("g.tpg") +
          " --contacts-per-tool 1 --tools rod --contacts-csv " + rod_csv + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.LastJson()["contacts"].get<int>(), 1);
  {
    std::istringstream all(Slurp(contacts)), one(Slurp(rod_csv));
    std::string header, row, rod_row;
    std::getline(one, header);
    std::getline(one, rod_row);
    std::getline(all, header);
    std::string truth_of_rod;
    while (std::getline(all, row)) {
      if (row.find(",rod,") != std::string::npos) truth_of_rod = row.substr(row.find(",rod,"), 40);
    }
    EXPECT_EQ(rod_row.substr(rod_row.find(",rod,"), 40), truth_of_rod);
  }
  // --data: a labelled dataset's frames instead of fresh contacts, each label the truth.
  // gd's frames are all in its train split: each of its rod and square frames is scored
  // once, with its own label's pose and depth.
  std::vector<std::string> train_truths;  // "tool,x_mm,y_mm,depth_mm" as the CSV rounds them
  {
    std::istringstream labels(Slurp(Root("gd") + "/labels.csv"));
    std::string header, row;
    std::getline(labels, header);
    while (std::getline(labels, row)) {
      const std::vector<std::string> f = testing_util::CsvFields(row);
      ASSERT_EQ(f.size(), 8u) << row;
      if (f[7] != "train" || (f[2] != "rod" && f[2] != "square")) continue;
      char truth[128];
      std::snprintf(truth, sizeof(truth), "%s,%.4f,%.4f,%.4f", f[2].c_str(),
                    1e3 * std::atof(f[3].c_str()), 1e3 * std::atof(f[4].c_str()),
                    1e3 * std::atof(f[6].c_str()));
      train_truths.push_back(truth);
    }
  }
  ASSERT_EQ(train_truths.size(), 12u);
  const std::string data_csv = Root("contacts_data.csv");
  r = Run("eval-generator --model " + Root("m.tfm") + " --generator " + Root("g.tpg") +
          " --functaset " + Root("gf.tfs") + " --data " + Root("gd") +
          " --split train --tools rod,square --contacts-csv " + data_csv + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("labelled frames of " + Root("gd") + " (train)"));
  EXPECT_EQ(r.LastJson()["contacts"].get<int>(), 12);
  {
    std::vector<std::string> scored;
    std::istringstream rows_of_data(Slurp(data_csv));
    std::string row;
    std::getline(rows_of_data, row);
    while (std::getline(rows_of_data, row)) {
      const std::vector<std::string> f = testing_util::CsvFields(row);
      ASSERT_GE(f.size(), 7u) << row;
      scored.push_back(f[1] + "," + f[3] + "," + f[4] + "," + f[6]);
    }
    std::sort(scored.begin(), scored.end());
    std::sort(train_truths.begin(), train_truths.end());
    EXPECT_EQ(scored, train_truths);
  }
  // At most --contacts-per-tool frames of each tool.
  r = Run("eval-generator --model " + Root("m.tfm") + " --generator " + Root("g.tpg") +
          " --data " + Root("gd") + " --split all --tools rod,square --contacts-per-tool 2 "
          "--json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.LastJson()["contacts"].get<int>(), 4);
  // A split without frames (gd has no test split), the simulator's bound (it needs its own
  // contacts) and a bad split are refused, naming what is wrong.
  r = Run("eval-generator --model " + Root("m.tfm") + " --generator " + Root("g.tpg") +
          " --data " + Root("gd"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("no labelled bubble frames of the test split"));
  r = Run("eval-generator --model " + Root("m.tfm") + " --generator " + Root("g.tpg") +
          " --data " + Root("gd") + " --information");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--information"));
  r = Run("eval-generator --model " + Root("m.tfm") + " --generator " + Root("g.tpg") +
          " --data " + Root("gd") + " --split validation");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--split: expected train, test or all, got 'validation'"));
  r = Run("eval-generator --model " + Root("m.tfm") + " --generator " + Root("g.tpg") +
          " --contacts-per-tool 1 --tools spoon");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--tools: 'spoon'"));
  // The tool unknown: how many tools went past the screening and the coarse stage, all of
  // them without pruning; a ratio between 0 and 1 is refused.
  const std::string unknown_eval = "eval-generator --model " + Root("m.tfm") + " --generator " +
                              Root("g.tpg") + " --contacts-per-tool 1 --tools rod,square " +
                              "--unknown-tool --json";
  r = Run(unknown_eval + " --tool-prune-ratio 0");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("12.00 past the screening, 12.00 refined past the coarse stage"));
  EXPECT_DOUBLE_EQ(r.LastJson()["tools_screened_in_per_frame"].get<double>(), 12.0);
  EXPECT_DOUBLE_EQ(r.LastJson()["tools_refined_per_frame"].get<double>(), 12.0);
  r = Run(unknown_eval + " --tool-prune-ratio 1 --tool-screen false");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_DOUBLE_EQ(r.LastJson()["tools_screened_in_per_frame"].get<double>(), 12.0);
  const double refined_unscreened = r.LastJson()["tools_refined_per_frame"].get<double>();
  EXPECT_GE(refined_unscreened, 1.0);
  EXPECT_LT(refined_unscreened, 12.0);
  r = Run(unknown_eval + " --tool-prune-ratio 1");  // screened, the default
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const double screened_in = r.LastJson()["tools_screened_in_per_frame"].get<double>();
  EXPECT_LT(screened_in, 12.0);
  EXPECT_GE(screened_in, r.LastJson()["tools_refined_per_frame"].get<double>());
  EXPECT_GE(r.LastJson()["tools_refined_per_frame"].get<double>(), 1.0);
  r = Run(unknown_eval + " --tool-prune-ratio 0.5");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("must be 0 (off) or >= 1, got 0.5"));
  EXPECT_EQ(count, eval["contacts"].get<int>() - eval["failures"].get<int>());  // usable ones
  EXPECT_GT(count, 0);
  EXPECT_NEAR(std::sqrt(sum_sq / count), eval["rmse_mm"].get<double>(),
              1e-3 * (1 + eval["rmse_mm"].get<double>()));
  // Errors name the flag.
  r = Run(args);
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--generator"));
  r = Run(args + " --generator " + Root("g.tpg") + " --method pixels");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("--method"));
  r = Run(args + " --generator " + Root("g.tpg") + " --tool spoon");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("spoon"));
  // A frame whose labelled tool the generator never saw.
  r = Run("pose --method generator --generator " + Root("g.tpg") + " --model " + Root("m.tfm") +
          " --pose-model " + Root("p.tpm") + " --data " + Root("d") + " --id 000003");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("does not know it"));
  // --generator-model: the generator renders through that model's trunk and the pose
  // model's start reads --model's latents through its own trunk; the same model given
  // again gives the same mode. Given the latent path's functaset, the generator path says
  // it starts without k-NN; a model that sees the frame at another format is refused.
  const std::string plain = "pose --method generator --model " + Root("m.tfm") + " --pose-model " +
                            Root("p.tpm") + " --data " + Root("gd") + " --id 000003 --generator " +
                            Root("g.tpg") + " --json";
  r = Run(plain);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json alone = r.LastJson();
  r = Run(plain + " --generator-model " + Root("m.tfm"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.LastJson()["mean"], alone["mean"]);
  r = Run(plain + " --generator-model " + Root("m.tfm") + " --functaset " + Root("gf.tfs"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("--functaset holds --model's latents"));
  r = Run(plain + " --generator-model " TACTFUNC_SOURCE_DIR "/models/pretrained/bubble.tfm");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("both must see the frame alike"));
  // A generator renders through the trunk it was trained with: one that recorded another
  // model's checksum is refused by every command that loads one, naming the file.
  PoseGenerator other = PoseGenerator::Load(Root("g.tpg"));
  nlohmann::json recorded = nlohmann::json::parse(other.info_json());
  ASSERT_TRUE(recorded.contains("model_checksum"));
  recorded["model_checksum"] = recorded["model_checksum"].get<std::uint64_t>() ^ 1u;
  other.set_info_json(recorded.dump());
  other.Save(Root("g_other.tpg"));
  for (const std::string& command :
       {args + " --generator " + Root("g_other.tpg"),
        "eval-generator --model " + Root("m.tfm") + " --generator " + Root("g_other.tpg") +
            " --contacts-per-tool 1"}) {
    r = Run(command);
    EXPECT_NE(r.exit_code, 0) << command;
    EXPECT_THAT(r.err, HasSubstr("g_other.tpg' was trained through the trunk of model checksum"))
        << command;
  }
}

// --tune-trunk trains the trunk along with the generator in the pixel stage and writes it
// as the generator's own trunk: the generator records that model, `pose` renders through it
// with --generator-model and refuses --model's trunk alone.
TEST_F(PoseCliTest, TrainGeneratorTunesATrunkOfItsOwn) {
  const Result synth = Run("synth --out " + Root("td") + " --frames-per-tool 6 --sensors bubble "
                           "--seed 5 --threads 1");
  ASSERT_EQ(synth.exit_code, 0) << synth.err;
  const Result encode = Run("encode --model " + Root("m.tfm") + " --data " + Root("td") +
                            " --out " + Root("tf.tfs") + " --threads 1");
  ASSERT_EQ(encode.exit_code, 0) << encode.err;
  const std::string train = "train-generator --model " + Root("m.tfm") + " --functaset " +
                            Root("tf.tfs") + " --data " + Root("td") + " --mode pixels "
                            "--epochs 3 --pixel-epochs 2 --pixel-frames 6 --hidden 16 "
                            "--calibration-frames 4 --temperature-frames 4";
  Result r = Run(train + " --out " + Root("gt.tpg") + " --tune-trunk 0.5 --out-model " +
                 Root("gt.tfm"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("wrote the generator's own trunk to " + Root("gt.tfm")));
  const FunctaModel base = FunctaModel::Load(Root("m.tfm"));
  const FunctaModel tuned = FunctaModel::Load(Root("gt.tfm"));
  const SensorTrunk& a = base.Trunk(SensorKind::kSoftBubble);
  const SensorTrunk& b = tuned.Trunk(SensorKind::kSoftBubble);
  ASSERT_EQ(a.siren.NumParameters(), b.siren.NumParameters());
  EXPECT_NE(a.siren.parameters(), b.siren.parameters());
  EXPECT_TRUE(a.format.SameAs(b.format));
  const nlohmann::json record = nlohmann::json::parse(tuned.info_json());
  EXPECT_EQ(record["tuned_with_generator"]["from_model"], Root("m.tfm"));
  EXPECT_EQ(record["tuned_with_generator"]["trunk_step_fraction"], 0.5);
  const PoseGenerator generator = PoseGenerator::Load(Root("gt.tpg"));
  EXPECT_EQ(nlohmann::json::parse(generator.info_json())["model"], Root("gt.tfm"));
  // The gelslim trunk (not tuned) is the same as --model's.
  if (base.HasSensor(SensorKind::kGelSlim)) {
    EXPECT_EQ(base.Trunk(SensorKind::kGelSlim).siren.parameters(),
              tuned.Trunk(SensorKind::kGelSlim).siren.parameters());
  }
  const std::string pose = "pose --method generator --model " + Root("m.tfm") + " --pose-model " +
                           Root("p.tpm") + " --data " + Root("td") + " --id 000003 --samples 10 " +
                           "--generator " + Root("gt.tpg");
  r = Run(pose + " --generator-model " + Root("gt.tfm") + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.LastJson()["method"], "generator");
  r = Run(pose);
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("trained through the trunk of model"));
  // Misuse: each flag without the other, and with regression only.
  r = Run(train + " --out " + Root("gx.tpg") + " --tune-trunk 0.5");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--out-model"));
  r = Run(train + " --out " + Root("gx.tpg") + " --out-model " + Root("gx.tfm"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--tune-trunk"));
  r = Run("train-generator --model " + Root("m.tfm") + " --functaset " + Root("tf.tfs") +
          " --data " + Root("td") + " --mode latents --epochs 2 --out " + Root("gx.tpg") +
          " --tune-trunk 0.5 --out-model " + Root("gx.tfm"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--mode pixels"));
  EXPECT_FALSE(fs::exists(Root("gx.tpg")));
  EXPECT_FALSE(fs::exists(Root("gx.tfm")));
}

TEST_F(PoseCliTest, PoseReadsAFrameAndReferenceFromFiles) {
  ASSERT_EQ(train_pose_->exit_code, 0) << train_pose_->err;
  const Result r = Run("pose --model " + Root("m.tfm") + " --pose-model " + Root("p.tpm") +
                       " --frame " + Root("d/bubble/000007.png") + " --reference " +
                       Root("d/bubble/reference.png") + " --sampler laplace --samples 10 --tool rod"
                       " --out " + Root("pose_files") + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = r.LastJson();
  EXPECT_EQ(j["sensor"], "bubble");  // inferred from the 16-bit frame
  EXPECT_EQ(j["symmetry_order"], 2);  // the rod
  EXPECT_FALSE(j.contains("truth"));
  EXPECT_TRUE(fs::exists(Root("pose_files/posterior.png")));
  // A tool of the user's own, its symmetry given on the command line.
  const Result own = Run("pose --model " + Root("m.tfm") + " --pose-model " + Root("p.tpm") +
                         " --frame " + Root("d/bubble/000007.png") + " --reference " +
                         Root("d/bubble/reference.png") +
                         " --sampler laplace --samples 10 --tool edge --symmetry-order 4 --json");
  ASSERT_EQ(own.exit_code, 0) << own.err;
  EXPECT_EQ(own.LastJson()["symmetry_order"], 4);
  EXPECT_THAT(own.err, ::testing::Not(HasSubstr("unknown tool")));
}

TEST_F(PoseCliTest, BenchPosteriorReportsCoverageErrorsAndTimes) {
  ASSERT_EQ(train_pose_->exit_code, 0) << train_pose_->err;
  const Result r = Run("bench posterior --model " + Root("m.tfm") + " --pose-model " +
                       Root("p.tpm") + " --functaset " + Root("f.tfs") + " --data " + Root("d") +
                       " --frames 2 --samples 10 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = r.LastJson();
  EXPECT_EQ(j["frames"], 2);
  ASSERT_TRUE(j.contains("machine"));
  ASSERT_EQ(j["samplers"].size(), 3u);
  for (const nlohmann::json& s : j["samplers"]) {
    SCOPED_TRACE(s.dump());
    for (const char* key : {"name", "coverage", "coverage_bounds_99", "rmse_mm", "rmse_deg",
                            "ms_median", "point_rmse_mm", "point_rmse_deg"}) {
      EXPECT_TRUE(s.contains(key)) << key;
    }
    for (const char* p : {"0.5", "0.9"}) {
      const double c = s["coverage"][p].get<double>();
      EXPECT_GE(c, 0.0);
      EXPECT_LE(c, 1.0);
      ASSERT_EQ(s["coverage_bounds_99"][p].size(), 2u);
      EXPECT_LE(s["coverage_bounds_99"][p][0].get<double>(), p == std::string("0.5") ? 0.5 : 0.9);
      EXPECT_GE(s["coverage_bounds_99"][p][1].get<double>(), p == std::string("0.5") ? 0.5 : 0.9);
    }
    EXPECT_GT(s["ms_median"].get<double>(), 0.0);
  }
  EXPECT_EQ(j["samplers"][0]["name"], "sgld");
  EXPECT_EQ(j["samplers"][2]["name"], "knn");
}

TEST_F(PoseCliTest, BadInputFailsWithAMessageNamingTheFileOrFlag) {
  ASSERT_EQ(train_pose_->exit_code, 0) << train_pose_->err;
  Result r = Run("train-pose --functaset " + Root("none.tfs") + " --out " + Root("x.tpm"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("none.tfs"));
  EXPECT_FALSE(fs::exists(Root("x.tpm")));

  r = Run("train-pose --functaset " + Root("f.tfs") + " --out " + Root("x.tpm") + " --hidden 8,x");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--hidden"));

  r = Run(PoseArgs("mcmc"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--sampler"));
  EXPECT_THAT(r.err, HasSubstr("mcmc"));

  r = Run("pose --model " + Root("m.tfm") + " --pose-model " + Root("p.tpm") + " --data " +
          Root("d") + " --id 000003 --sampler knn");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--functaset"));

  r = Run(PoseArgs("laplace") + " --frame " + Root("d/bubble/000003.png"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--frame"));

  r = Run("pose --model " + Root("m.tfm") + " --pose-model " + Root("nope.tpm") + " --data " +
          Root("d") + " --id 000003");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("--pose-model"));
  EXPECT_THAT(r.err, HasSubstr("nope.tpm"));

  r = Run(PoseArgs("laplace") + " --id 999999");
  EXPECT_THAT(r.err, HasSubstr("--id"));  // (PoseArgs' --id 000003 is overridden or rejected)
  EXPECT_NE(r.exit_code, 0);

  // A bubble pose model used on gelslim frames: the latent dimensions differ (8 vs 6).
  r = Run("pose --model " + Root("m.tfm") + " --pose-model " + Root("p.tpm") + " --data " +
          Root("d") + " --id 000003 --sensor gelslim --sampler laplace");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("p.tpm"));
  EXPECT_THAT(r.err, HasSubstr("latent dimension"));

  r = Run("bench posterior --model " + Root("m.tfm") + " --pose-model " + Root("p.tpm") +
          " --functaset " + Root("f.tfs") + " --data " + Root("d") + " --samplers sgld,hmc");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--samplers"));
}

}  // namespace
}  // namespace tactfunc
