// Copyright 2026 The tactfunc Authors.
//
// `tactfunc train` as a user runs it: a short tiny-preset run on simulated contacts
// writes a model whose trunk carries the inner-loop knobs given on the command line
// (K, the rates' clip bound and start) and its training curves; `encode` uses that
// model; bad knobs fail before any data is read with a message naming the flag or
// field, and a diverging run fails naming the learning rate. On the result, `recon`
// writes a per-frame CSV that agrees with its own summary and pictures the worst
// frames, and `info` describes the model, functaset and checkpoint files; an 8-bit
// functaset is reported as such, its latent bytes as on disk.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <string>
#include <utility>
#include <vector>

#include <unistd.h>

#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>

#include "gmock/gmock.h"
#include "estimation/functaset/functaset.h"
#include "gtest/gtest.h"
#include "models/pose/pose_mlp.h"
#include "models/pose/pose_model_provenance.h"
#include "models/trunk/functa_model.h"
#include "models/trunk/product_precision.h"
#include "nlohmann/json.hpp"
#include "tests/apps/cli_test_util.h"

namespace tactfunc {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;
using Result = testing_util::CliResult;

class TrainCliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = new fs::path(fs::path(::testing::TempDir()) /
                         ("tactfunc_train_cli_" + std::to_string(::getpid())));
    fs::remove_all(*root_);
    fs::create_directories(*root_);
    const Result synth = Run("synth --out " + Root("d") +
                             " --frames-per-tool 4 --tools rod,square --sensors bubble --seed 3");
    ASSERT_EQ(synth.exit_code, 0) << synth.err;
  }
  static void TearDownTestSuite() {
    fs::remove_all(*root_);
    delete root_;
  }
  static std::string Root(const std::string& name) { return (*root_ / name).string(); }
  static Result Run(const std::string& args) { return testing_util::RunTactfunc(*root_, args); }
  // A 3-step tiny model NAME.tfm of the fixture's data and its functaset NAME.tfs.
  static void TrainAndEncode(const std::string& name) {
    const Result train = Run("train --data " + Root("d") + " --out " + Root(name + ".tfm") +
                             " --preset tiny --steps 3 --seed 2");
    ASSERT_EQ(train.exit_code, 0) << train.err;
    const Result encode = Run("encode --model " + Root(name + ".tfm") + " --data " + Root("d") +
                              " --out " + Root(name + ".tfs") + " --threads 1");
    ASSERT_EQ(encode.exit_code, 0) << encode.err;
  }

  // GelSlim frames of `synth --seed 6` in folder NAME (3 frames of a rod and of a
  // square) whose band of rows 1/3 to 1/2 is brightened by brighten(k) grey levels in
  // the k-th frame (directory order), a change of the gel's image the contact does not
  // draw.
  static void BandedGelSlimFrames(const std::string& name, int (*brighten)(int)) {
    ASSERT_EQ(Run("synth --out " + Root(name) + " --frames-per-tool 3 --tools rod,square "
                  "--sensors gelslim --seed 6").exit_code, 0);
    int frame = 0;
    for (const auto& entry : fs::directory_iterator(Root(name + "/gelslim"))) {
      const std::string file = entry.path().filename().string();
      if (entry.path().extension() != ".png" || file.rfind("reference", 0) == 0) continue;
      cv::Mat image = cv::imread(entry.path().string(), cv::IMREAD_UNCHANGED);
      ASSERT_FALSE(image.empty()) << file;
      cv::Mat band = image.rowRange(image.rows / 3, image.rows / 2);
      band += cv::Scalar::all(brighten(frame++));
      ASSERT_TRUE(cv::imwrite(entry.path().string(), image));
    }
  }
  // `train` of a tiny photometric trunk (d 8, width 8, 2 layers, seed 1, JSON) on folder
  // DATA for STEPS steps, MARKER_WARMUP of them with working-resolution markers; the
  // caller appends its flags and `--out FILE` last.
  static std::string TinyPhotometricTrain(const std::string& data, int steps,
                                          int marker_warmup) {
    return "train --data " + data + " --head photometric --steps " + std::to_string(steps) +
           " --marker-warmup " + std::to_string(marker_warmup) +
           " --latent-dim 8 --width 8 --layers 2 --threads 2 --seed 1 --json ";
  }
  // The mean PSNR of `encode --strategy adam:30` of folder DATA with model MODEL.tfm
  // (written to MODEL.tfs); NaN, with a test failure, if encode fails.
  static double EncodedPsnr(const std::string& model, const std::string& data) {
    const Result encode = Run("encode --model " + model + ".tfm --data " + data + " --out " +
                              model + ".tfs --strategy adam:30 --threads 2 --json");
    if (encode.exit_code != 0) {
      ADD_FAILURE() << encode.err;
      return std::nan("");
    }
    return encode.LastJson()["psnr_mean"]["gelslim"].get<double>();
  }

  static fs::path* root_;
};

fs::path* TrainCliTest::root_ = nullptr;

TEST_F(TrainCliTest, TheInnerLoopKnobsReachTheModelAndEncodeUsesIt) {
  const Result train = Run("train --data " + Root("d") + " --out " + Root("m.tfm") +
                           " --preset tiny --steps 4 --inner-steps 2 --alpha-max 2" +
                           " --alpha-init 1.5 --seed 1 --json");
  ASSERT_EQ(train.exit_code, 0) << train.err;
  EXPECT_EQ(train.LastJson()["sensors"]["bubble"]["steps"].get<int>(), 4);
  // The training curves are drawn beside the model, in the bubble's colour (BGR 40, 140,
  // 255): its thick line and point marks cover well over a hundred pixels.
  EXPECT_EQ(train.LastJson()["curves"].get<std::string>(), Root("m.tfm.training.png"));
  const cv::Mat curves = cv::imread(Root("m.tfm.training.png"), cv::IMREAD_COLOR);
  ASSERT_FALSE(curves.empty());
  cv::Mat bubble_colour;
  cv::inRange(curves, cv::Scalar(40, 140, 255), cv::Scalar(40, 140, 255), bubble_colour);
  EXPECT_GT(cv::countNonZero(bubble_colour), 100);

  const FunctaModel model = FunctaModel::Load(Root("m.tfm"));
  const SensorTrunk& trunk = model.Trunk(SensorKind::kSoftBubble);
  EXPECT_EQ(trunk.meta_sgd.inner_steps, 2);
  EXPECT_GE(trunk.alpha.minCoeff(), 0.0);
  EXPECT_LE(trunk.alpha.maxCoeff(), 2.0);
  EXPECT_GT(trunk.alpha.maxCoeff(), 1.0);  // started at 1.5, four small Adam steps away

  const Result encode = Run("encode --model " + Root("m.tfm") + " --data " + Root("d") +
                            " --out " + Root("f.tfs") + " --threads 1 --json");
  EXPECT_EQ(encode.exit_code, 0) << encode.err;
}

// --outer-clean meta-learns against the noise-free copies: refused, naming a frame and
// writing nothing, on data without them; recorded in the model's training options; a
// readout trunk's start gains kept in its file.
TEST_F(TrainCliTest, TheOuterLossOnNoiseFreeCopiesNeedsThemAndIsRecorded) {
  // The training options a model NAME records for its bubble trunk.
  const auto options_of = [](const std::string& name) {
    const nlohmann::json info =
        nlohmann::json::parse(FunctaModel::Load(Root(name)).info_json());
    return info["trunks"]["bubble"]["options"];
  };
  const Result noisy_only = Run("train --data " + Root("d") + " --out " + Root("oc0.tfm") +
                                " --preset tiny --steps 3 --seed 2 --outer-clean");
  EXPECT_NE(noisy_only.exit_code, 0);
  EXPECT_THAT(noisy_only.err, HasSubstr("clean copy"));
  EXPECT_THAT(noisy_only.err, HasSubstr("synth --clean"));
  EXPECT_FALSE(fs::exists(Root("oc0.tfm")));
  const Result synth = Run("synth --out " + Root("dc") + " --frames-per-tool 4 --tools rod,square" +
                           " --sensors bubble --seed 3 --clean");
  ASSERT_EQ(synth.exit_code, 0) << synth.err;
  const Result train = Run("train --data " + Root("dc") + " --out " + Root("oc.tfm") +
                           " --preset tiny --steps 3 --seed 2 --outer-clean");
  ASSERT_EQ(train.exit_code, 0) << train.err;
  EXPECT_TRUE(options_of("oc.tfm")["outer_loss_on_clean"].get<bool>());
  const Result plain = Run("train --data " + Root("dc") + " --out " + Root("oc_plain.tfm") +
                           " --preset tiny --steps 3 --seed 2");
  ASSERT_EQ(plain.exit_code, 0) << plain.err;
  EXPECT_FALSE(options_of("oc_plain.tfm").contains("outer_loss_on_clean"));
  // A readout trunk trained so (here with no inner steps: every fit is the branch's
  // projection) starts its fits from projections shrunk by the copies' Wiener gains,
  // which its file keeps; encode then fits with its K = 0.
  const Result readout = Run("train --data " + Root("dc") + " --out " + Root("oc_r.tfm") +
                             " --preset tiny --steps 3 --seed 2 --outer-clean --readout" +
                             " --inner-steps 0");
  ASSERT_EQ(readout.exit_code, 0) << readout.err;
  const SensorTrunk trunk = FunctaModel::Load(Root("oc_r.tfm")).Trunk(SensorKind::kSoftBubble);
  EXPECT_EQ(trunk.meta_sgd.inner_steps, 0);
  ASSERT_EQ(trunk.siren.start_gains().size(), trunk.siren.latent_dim());
  EXPECT_LE(trunk.siren.start_gains().maxCoeff(), 1.0);
  EXPECT_GT(trunk.siren.start_gains().minCoeff(), 0.0);
  EXPECT_THAT(Run("info " + Root("oc_r.tfm")).out, HasSubstr("projection times gains in ["));
  EXPECT_EQ(Run("info " + Root("oc_r.tfm") + " --json")
                .LastJson()["model"]["trunks"]["bubble"]["readout"]["start_gains"]
                .size(),
            static_cast<std::size_t>(trunk.siren.latent_dim()));
  const Result encode = Run("encode --model " + Root("oc_r.tfm") + " --data " + Root("dc") +
                            " --out " + Root("oc_r.tfs") + " --threads 1");
  ASSERT_EQ(encode.exit_code, 0) << encode.err;
  EXPECT_THAT(Run("info " + Root("oc_r.tfs")).out, HasSubstr("fit meta_sgd:0"));
  // Without the branch no step would leave z = 0: refused before any data is read.
  const Result no_branch = Run("train --data " + Root("dc") + " --out " + Root("oc_k0.tfm") +
                               " --preset tiny --steps 3 --inner-steps 0");
  EXPECT_EQ(no_branch.exit_code, 2);
  EXPECT_THAT(no_branch.err, HasSubstr("--inner-steps 0"));
  EXPECT_FALSE(fs::exists(Root("oc_k0.tfm")));
  const Result pca_frames = Run("train --data " + Root("dc") + " --out " + Root("oc_k0.tfm") +
                                " --preset tiny --steps 3 --readout-pca-frames 5");
  EXPECT_EQ(pca_frames.exit_code, 2);
  EXPECT_THAT(pca_frames.err, HasSubstr("--readout-pca-frames needs --readout"));
  const Result with_branch = Run("train --data " + Root("dc") + " --out " + Root("oc_p.tfm") +
                                 " --preset tiny --steps 3 --readout --readout-pca-frames 5" +
                                 " --divergence-drop-db 0");
  ASSERT_EQ(with_branch.exit_code, 0) << with_branch.err;
  EXPECT_EQ(options_of("oc_p.tfm")["readout_pca_frames"].get<int>(), 5);
  // The storage preset brings its own branch: the readout flags apply to it as they are.
  const Result storage = Run("train --data " + Root("dc") + " --out " + Root("oc_s.tfm") +
                             " --preset storage --steps 2 --latent-dim 8 --readout-pca-frames 6" +
                             " --readout-rate 0.5 --sensors bubble --divergence-drop-db 0");
  ASSERT_EQ(storage.exit_code, 0) << storage.err;
  EXPECT_EQ(options_of("oc_s.tfm")["readout_pca_frames"].get<int>(), 6);
  EXPECT_EQ(options_of("oc_s.tfm")["readout_learning_rate_scale"].get<double>(), 0.5);
  EXPECT_TRUE(options_of("oc_s.tfm")["outer_loss_on_clean"].get<bool>());
}

// --products bf16 (where the CPU has AVX512_BF16) trains and encodes with bfloat16
// products, and the model says so: `info` names them, its JSON carries "products"
// (a float model's reads "float"); its checkpoint resumes only in bfloat16; a
// functaset encoded with them says so too.
TEST_F(TrainCliTest, AModelTrainedWithBfloat16ProductsSaysSo) {
  if (!ProductPrecisionAvailable(ProductPrecision::kBfloat16)) {
    GTEST_SKIP() << "this CPU lacks AVX512_BF16";
  }
  const Result train = Run("train --data " + Root("d") + " --out " + Root("bf16.tfm") +
                           " --preset tiny --steps 3 --seed 2 --products bf16");
  ASSERT_EQ(train.exit_code, 0) << train.err;
  const Result info = Run("info " + Root("bf16.tfm"));
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_THAT(info.out, HasSubstr("trained with bf16 products"));
  EXPECT_EQ(Run("info " + Root("bf16.tfm") + " --json").LastJson()["model"]["products"], "bf16");
  // Its checkpoint resumes in bfloat16 only: the precision shapes the trajectory.
  const std::string more = "train --data " + Root("d") + " --out " + Root("bf16.tfm") +
                           " --preset tiny --steps 4 --seed 2 --resume";
  const Result as_float = Run(more);
  EXPECT_NE(as_float.exit_code, 0);
  EXPECT_THAT(as_float.err, HasSubstr("option 'products'"));
  const Result resumed = Run(more + " --products bf16");
  EXPECT_EQ(resumed.exit_code, 0) << resumed.err;
  const Result encode = Run("encode --model " + Root("bf16.tfm") + " --data " + Root("d") +
                            " --out " + Root("bf16.tfs") + " --threads 1 --products bf16");
  EXPECT_EQ(encode.exit_code, 0) << encode.err;
  // Bit-identical whatever --threads, as in float.
  ASSERT_EQ(Run("encode --model " + Root("bf16.tfm") + " --data " + Root("d") + " --out " +
                Root("bf16_2.tfs") + " --threads 2 --products bf16")
                .exit_code,
            0);
  EXPECT_EQ(testing_util::Slurp(Root("bf16_2.tfs")), testing_util::Slurp(Root("bf16.tfs")));
  // recon renders in the precision the functaset was encoded with unless told otherwise,
  // and so reproduces the encode's PSNRs (the functaset holds its latents in float16,
  // hence the tolerance); fit and eval take the flag as well.
  const Result encoded = Run("encode --model " + Root("bf16.tfm") + " --data " + Root("d") +
                             " --out " + Root("bf16_3.tfs") + " --threads 1 --products bf16" +
                             " --json");
  ASSERT_EQ(encoded.exit_code, 0) << encoded.err;
  const Result recon = Run("recon --model " + Root("bf16.tfm") + " --functaset " +
                           Root("bf16_3.tfs") + " --data " + Root("d") + " --out " +
                           Root("recon_bf16") + " --json");
  ASSERT_EQ(recon.exit_code, 0) << recon.err;
  EXPECT_THAT(recon.out, HasSubstr("bf16 products, as " + Root("bf16_3.tfs") + " was encoded"));
  EXPECT_NEAR(recon.LastJson()["groups"][0]["noisy"]["mean"].get<double>(),
              encoded.LastJson()["psnr_mean"]["bubble"].get<double>(), 1e-3);
  for (const std::string command : {"fit", "recon", "eval"}) {
    const Result bad = Run(command + " --products half");
    EXPECT_EQ(bad.exit_code, 2) << command;
    EXPECT_THAT(bad.err, HasSubstr("--products")) << command;
  }
  // An encode resumed from it in float is refused: the precision shapes the latents.
  const Result resume = Run("encode --model " + Root("bf16.tfm") + " --data " + Root("d") +
                            " --out " + Root("bf16.tfs") + " --threads 1 --resume");
  EXPECT_NE(resume.exit_code, 0);
  EXPECT_THAT(resume.err, HasSubstr("with bf16 products, this run with float"));
  // The functaset records the precision its latents were fitted with, per sensor.
  EXPECT_THAT(Run("info " + Root("bf16.tfs")).out, HasSubstr("with bf16 products"));
  EXPECT_EQ(
      Run("info " + Root("bf16.tfs") + " --json").LastJson()["functaset"]["sensors"]["bubble"]
                                                            ["products"],
      "bf16");
  TrainAndEncode("plain");
  const Result float_info = Run("info " + Root("plain.tfm") + " --json");
  EXPECT_EQ(float_info.LastJson()["model"]["products"], "float");
  EXPECT_THAT(Run("info " + Root("plain.tfm")).out, Not(HasSubstr("products")));
  EXPECT_THAT(Run("info " + Root("plain.tfs")).out, Not(HasSubstr("products")));
}


TEST_F(TrainCliTest, ThePhotometricHeadDrawsEachClipAgainstItsOwnReference) {
  // A set of two clips: a, the simulated frames with their reference; b, the same
  // frames and reference mirrored, so that b's markers lie elsewhere.
  ASSERT_EQ(Run("synth --out " + Root("clip_source") +
                " --frames-per-tool 2 --tools rod,square --sensors gelslim --seed 4")
                .exit_code, 0);
  std::vector<std::string> stems;
  for (const auto& entry : fs::directory_iterator(Root("clip_source/gelslim"))) {
    if (entry.path().extension() == ".png") stems.push_back(entry.path().stem().string());
  }
  std::sort(stems.begin(), stems.end());
  ASSERT_GE(stems.size(), 3u);
  for (const std::string clip : {"a", "b"}) {
    fs::create_directories(Root("clips/" + clip));
    for (const std::string& stem : stems) {
      cv::Mat image =
          cv::imread(Root("clip_source/gelslim/" + stem + ".png"), cv::IMREAD_UNCHANGED);
      ASSERT_FALSE(image.empty()) << stem;
      if (clip == "b") cv::flip(image, image, 1);
      ASSERT_TRUE(cv::imwrite(Root("clips/" + clip + "/" + stem + ".png"), image));
    }
  }
  const Result train = Run("train --data " + Root("clips") + " --out " + Root("c.tfm") +
                           " --head photometric --steps 4 --marker-warmup 2 --latent-dim 8 "
                           "--width 8 --layers 2 --threads 1 --seed 1");
  ASSERT_EQ(train.exit_code, 0) << train.err;
  EXPECT_THAT(train.out, HasSubstr("2 clips, each frame drawn against its own clip's reference"));
  const Result encode = Run("encode --model " + Root("c.tfm") + " --data " + Root("clips") +
                            " --out " + Root("c.tfs") + " --strategy adam:5 --threads 2");
  ASSERT_EQ(encode.exit_code, 0) << encode.err;
  const Result recon = Run("recon --model " + Root("c.tfm") + " --data " + Root("clips") +
                           " --functaset " + Root("c.tfs") + " --out " + Root("cr"));
  ASSERT_EQ(recon.exit_code, 0) << recon.err;
  // A frame of clip b: encode fitted it against b's reference, as fit does given it, and
  // fit given clip a's reference instead fits another latent.
  const std::string frame = Root("clips/b/" + stems[1] + ".png");
  const std::string fit = "fit --model " + Root("c.tfm") + " --frame " + frame +
                          " --sensor gelslim --strategy adam:5 --json --reference ";
  const Result own = Run(fit + Root("clips/b/reference.png") + " --out " + Root("fit_b"));
  ASSERT_EQ(own.exit_code, 0) << own.err;
  const Result other = Run(fit + Root("clips/a/reference.png") + " --out " + Root("fit_a"));
  ASSERT_EQ(other.exit_code, 0) << other.err;
  const auto latent = [&](const std::string& dir) {
    return nlohmann::json::parse(testing_util::Slurp(Root(dir + "/latent.json")))["latent"];
  };
  ASSERT_EQ(latent("fit_b").size(), 8u);
  EXPECT_NE(latent("fit_b"), latent("fit_a"));
  const Functaset functaset = Functaset::Load(Root("c.tfs"));
  const auto index = functaset.Find(SensorKind::kGelSlim, "b/" + stems[1]);
  ASSERT_TRUE(index.has_value());
  const FunctasetEntry& entry = functaset.entries(SensorKind::kGelSlim)[*index];
  EXPECT_EQ(entry.psnr, static_cast<float>(own.LastJson()["psnr"].get<double>()));
  EXPECT_NE(entry.psnr, static_cast<float>(other.LastJson()["psnr"].get<double>()));
}

// A background the contact cannot draw (a brighter band across every frame): --background
// stores it in the model, `info` shows it, and the frames the trunk was trained on
// reconstruct better with it than the same training without. The direct head refuses it.
TEST_F(TrainCliTest, ThePhotometricBackgroundDrawsWhatEveryFrameShares) {
  ASSERT_NO_FATAL_FAILURE(BandedGelSlimFrames("bg", [](int) { return 24; }));
  const std::string train = TinyPhotometricTrain(Root("bg"), 30, 10) + "--out ";
  const Result with = Run(train + Root("bg_with.tfm") + " --background");
  ASSERT_EQ(with.exit_code, 0) << with.err;
  EXPECT_THAT(with.out, HasSubstr("background learned along"));
  EXPECT_GT(with.LastJson()["sensors"]["gelslim"]["background_rms"].get<double>(), 0.01);
  const Result without = Run(train + Root("bg_without.tfm"));
  ASSERT_EQ(without.exit_code, 0) << without.err;
  EXPECT_THAT(Run("info " + Root("bg_with.tfm")).out, HasSubstr("background: 80x107x1"));
  EXPECT_THAT(Run("info " + Root("bg_without.tfm")).out, ::testing::Not(HasSubstr("background")));
  const double psnr[2] = {EncodedPsnr(Root("bg_with"), Root("bg")),
                          EncodedPsnr(Root("bg_without"), Root("bg"))};
  EXPECT_GT(psnr[0], psnr[1] + 1.0) << "with " << psnr[0] << " dB, without " << psnr[1];
  const Result direct = Run("train --data " + Root("bg") + " --out " + Root("d.tfm") +
                            " --preset small --steps 2 --background");
  EXPECT_NE(direct.exit_code, 0);
  EXPECT_THAT(direct.err, HasSubstr("--background applies to --head photometric"));
}

// Frames whose band brightens by a different amount in each frame: lighting images drawn
// by each frame's own value encode them better than the background alone.
TEST_F(TrainCliTest, PhotometricLightingImagesDrawWhatChangesFromFrameToFrame) {
  ASSERT_NO_FATAL_FAILURE(BandedGelSlimFrames("lit", [](int k) { return 12 * (k % 6); }));
  const std::string train = TinyPhotometricTrain(Root("lit"), 200, 10) + "--background --out ";
  const Result with = Run(train + Root("lit_with.tfm") + " --lighting 1");
  ASSERT_EQ(with.exit_code, 0) << with.err;
  EXPECT_THAT(with.out, HasSubstr("1 lighting images learned"));
  EXPECT_GT(with.LastJson()["sensors"]["gelslim"]["lighting_rms"].get<double>(), 0.0);
  ASSERT_EQ(Run(train + Root("lit_without.tfm")).exit_code, 0);
  const std::string info = Run("info " + Root("lit_with.tfm")).out;
  EXPECT_THAT(info, HasSubstr("latent 8 = rigid motion 3 + code 4 + lighting 1,"));
  EXPECT_THAT(info, HasSubstr("lighting: 1 images of 80x107x1"));
  EXPECT_EQ(FunctaModel::Load(Root("lit_with.tfm")).Trunk(SensorKind::kGelSlim).siren.latent_dim(),
            4);  // 8 = pose 3 + code 4 + lighting 1
  const double psnr[2] = {EncodedPsnr(Root("lit_with"), Root("lit")),
                          EncodedPsnr(Root("lit_without"), Root("lit"))};
  EXPECT_GT(psnr[0], psnr[1] + 1.0) << "with " << psnr[0] << " dB, without " << psnr[1];
  // The Levenberg-Marquardt fit takes the lighting values' Jacobian columns too.
  const Result ceres = Run("encode --model " + Root("lit_with.tfm") + " --data " + Root("lit") +
                           " --out " + Root("lit_ceres.tfs") + " --strategy knn+ceres:3 --json");
  ASSERT_EQ(ceres.exit_code, 0) << ceres.err;
  EXPECT_GT(ceres.LastJson()["psnr_mean"]["gelslim"].get<double>(), psnr[1]);
  // Refused: a latent with no code value left, and the direct head.
  const Result small = Run("train --data " + Root("lit") + " --out " + Root("s.tfm") +
                           " --head photometric --steps 2 --latent-dim 5 --lighting 2");
  EXPECT_NE(small.exit_code, 0);
  EXPECT_THAT(small.err, HasSubstr("expected at least 6"));
  const Result direct = Run("train --data " + Root("lit") + " --out " + Root("d.tfm") +
                            " --preset small --steps 2 --lighting 2");
  EXPECT_NE(direct.exit_code, 0);
  EXPECT_THAT(direct.err, HasSubstr("--lighting applies to --head photometric"));
}

// --latent-noise reaches the trainer (a run with it differs from one without, the same
// run twice is the same model) and is recorded; the direct head and a negative value
// are refused.
TEST_F(TrainCliTest, LatentNoiseIsAPhotometricTrainingOptionRecordedInTheModel) {
  ASSERT_NO_FATAL_FAILURE(BandedGelSlimFrames("noise", [](int) { return 24; }));
  const std::string train = TinyPhotometricTrain(Root("noise"), 4, 2) + "--out ";
  const Result noisy = Run(train + Root("noisy.tfm") + " --latent-noise 0.5");
  ASSERT_EQ(noisy.exit_code, 0) << noisy.err;
  EXPECT_THAT(noisy.out, HasSubstr(", noise 0.5 on its code values"));
  EXPECT_EQ(nlohmann::json::parse(FunctaModel::Load(Root("noisy.tfm")).info_json())
                ["trunks"]["gelslim"]["options"]["latent_noise"]
                    .get<double>(),
            0.5);
  ASSERT_EQ(Run(train + Root("noisy_again.tfm") + " --latent-noise 0.5").exit_code, 0);
  const Result plain = Run(train + Root("plain.tfm"));
  ASSERT_EQ(plain.exit_code, 0) << plain.err;
  EXPECT_THAT(plain.out, ::testing::Not(HasSubstr("noise")));
  const auto weights = [&](const std::string& file) {
    return FunctaModel::Load(Root(file)).Trunk(SensorKind::kGelSlim).siren.parameters();
  };
  EXPECT_EQ(weights("noisy.tfm"), weights("noisy_again.tfm"));
  EXPECT_NE(weights("noisy.tfm"), weights("plain.tfm"));
  const Result direct = Run("train --data " + Root("noise") + " --out " + Root("d.tfm") +
                            " --preset small --steps 2 --latent-noise 0.5");
  EXPECT_NE(direct.exit_code, 0);
  EXPECT_THAT(direct.err, HasSubstr("--latent-noise applies to --head photometric"));
  const Result negative = Run(train + Root("n.tfm") + " --latent-noise -1");
  EXPECT_NE(negative.exit_code, 0);
  EXPECT_THAT(negative.err, HasSubstr("--latent-noise"));
}

TEST_F(TrainCliTest, ThePhotometricHeadTrainsEncodesAndReconstructsAnOpticalSensor) {
  ASSERT_EQ(Run("synth --out " + Root("g") + " --frames-per-tool 2 --tools rod,square "
                "--sensors gelslim --seed 4").exit_code, 0);
  const Result train = Run("train --data " + Root("g") + " --out " + Root("p.tfm") +
                           " --head photometric --steps 4 --marker-warmup 2 --latent-dim 8 "
                           "--width 8 --layers 2 --threads 1 --seed 1 --json");
  ASSERT_EQ(train.exit_code, 0) << train.err;
  EXPECT_EQ(train.LastJson()["sensors"]["gelslim"]["head"], "photometric");
  EXPECT_EQ(train.LastJson()["sensors"]["gelslim"]["steps"].get<int>(), 4);
  const FunctaModel model = FunctaModel::Load(Root("p.tfm"));
  const SensorTrunk& trunk = model.Trunk(SensorKind::kGelSlim);
  ASSERT_NE(trunk.photometric, nullptr);
  EXPECT_EQ(TrunkLatentDim(trunk), 8);
  EXPECT_EQ(trunk.siren.latent_dim(), 5);
  EXPECT_GT(trunk.residual_sigma, 0.0);
  // The reference the head moves is the dataset's, at the sensor's resolution.
  EXPECT_EQ(trunk.photometric->reference().rows, 320);
  EXPECT_THAT(Run("info " + Root("p.tfm")).out, HasSubstr("photometric head: latent 8"));

  const Result encode = Run("encode --model " + Root("p.tfm") + " --data " + Root("g") +
                            " --out " + Root("p.tfs") + " --strategy adam:5 --threads 1 --json");
  ASSERT_EQ(encode.exit_code, 0) << encode.err;
  const Functaset functaset = Functaset::Load(Root("p.tfs"));
  EXPECT_EQ(functaset.latent_dim(SensorKind::kGelSlim), 8);
  EXPECT_EQ(functaset.fit_strategy(SensorKind::kGelSlim), "adam:5");
  const Result recon = Run("recon --model " + Root("p.tfm") + " --data " + Root("g") +
                           " --functaset " + Root("p.tfs") + " --out " + Root("pr"));
  ASSERT_EQ(recon.exit_code, 0) << recon.err;
  EXPECT_TRUE(fs::exists(Root("pr/recon_gelslim.png")));

  // The model carries the training latents as its fits' warm-start table, one row per
  // training frame; knn+adam:N and knn start from it.
  ASSERT_NE(trunk.warm_start, nullptr);
  EXPECT_EQ(trunk.warm_start->latents.rows(),
            train.LastJson()["sensors"]["gelslim"]["train_frames"].get<int>());
  EXPECT_EQ(trunk.warm_start->latents.cols(), 8);
  for (const char* strategy : {"knn+adam:3", "knn", "knn+ceres:2"}) {
    const Result warm = Run("encode --model " + Root("p.tfm") + " --data " + Root("g") +
                            " --out " + Root("w.tfs") + " --strategy " + strategy +
                            " --threads 2 --json");
    ASSERT_EQ(warm.exit_code, 0) << warm.err;
    EXPECT_EQ(Functaset::Load(Root("w.tfs")).fit_strategy(SensorKind::kGelSlim), strategy);
  }
  // `fit` on one frame runs encode's own fit: the same latent, to the bit, for the same
  // strategy; by default encode's default. The direct trunk's Ceres knobs are refused.
  const Result warm = Run("encode --model " + Root("p.tfm") + " --data " + Root("g") +
                          " --out " + Root("fw.tfs") + " --strategy knn+adam:3 --threads 1 "
                          "--latent-precision float32");
  ASSERT_EQ(warm.exit_code, 0) << warm.err;
  const Functaset warm_set = Functaset::Load(Root("fw.tfs"));
  const FunctasetEntry& first = warm_set.entries(SensorKind::kGelSlim)[0];
  const std::string fit_args = "fit --model " + Root("p.tfm") + " --frame " + Root("g/gelslim/") +
                               first.id + ".png --reference " + Root("g/gelslim/reference.png");
  const Result fit = Run(fit_args + " --strategy knn+adam:3 --out " + Root("pf") + " --json");
  ASSERT_EQ(fit.exit_code, 0) << fit.err;
  EXPECT_EQ(fit.LastJson()["strategy"], "knn+adam:3");
  EXPECT_NEAR(fit.LastJson()["psnr"].get<double>(), first.psnr, 1e-4);
  const nlohmann::json record = nlohmann::json::parse(testing_util::Slurp(Root("pf/latent.json")));
  EXPECT_EQ(record["trunk"], "photometric");
  ASSERT_EQ(record["latent"].size(), 8u);
  for (int k = 0; k < 8; ++k) {
    EXPECT_EQ(static_cast<float>(record["latent"][k].get<double>()), first.latent[k]) << k;
  }
  EXPECT_TRUE(fs::exists(Root("pf/fit.png")));
  const Result fit_default = Run(fit_args + " --json");
  ASSERT_EQ(fit_default.exit_code, 0) << fit_default.err;
  EXPECT_THAT(fit_default.LastJson()["strategy"].get<std::string>(), HasSubstr("knn+adam:"));
  const Result knobs = Run(fit_args + " --max-pixels 100");
  EXPECT_EQ(knobs.exit_code, 2);
  EXPECT_THAT(knobs.err, HasSubstr("--max-pixels"));
  const Result ceres = Run(fit_args + " --strategy ceres:3");
  EXPECT_EQ(ceres.exit_code, 2);
  EXPECT_THAT(ceres.err, HasSubstr("photometric"));

  // Pose posteriors on photometric latents: a pose MLP on the functaset, then each
  // latent sampler about encode's fit of one frame.
  const Result pose_train = Run("train-pose --functaset " + Root("fw.tfs") + " --out " +
                                Root("p.tpm") + " --epochs 2 --hidden 8 --batch 4");
  ASSERT_EQ(pose_train.exit_code, 0) << pose_train.err;
  EXPECT_EQ(PoseModelProvenance::FromJson(PoseMlp::Load(Root("p.tpm")).info_json(), "p.tpm")
                .latent_map,
            "knn+adam:3");
  const Result refit = Run("train-pose --functaset " + Root("fw.tfs") + " --out " +
                           Root("p2.tpm") + " --model " + Root("p.tfm") + " --data " +
                           Root("g") + " --refit ceres:3");
  EXPECT_EQ(refit.exit_code, 2);
  EXPECT_THAT(refit.err, HasSubstr("photometric"));
  EXPECT_FALSE(fs::exists(Root("p2.tpm")));
  const Result bench_fit = Run("bench fit --model " + Root("p.tfm") + " --data " + Root("g") +
                               " --functaset " + Root("fw.tfs") + " --sensors gelslim");
  EXPECT_EQ(bench_fit.exit_code, 2);
  EXPECT_THAT(bench_fit.err, HasSubstr("bench photometric"));
  for (const char* sampler : {"laplace", "sgld", "knn"}) {
    const Result pose = Run("pose --model " + Root("p.tfm") + " --pose-model " + Root("p.tpm") +
                            " --functaset " + Root("fw.tfs") + " --data " + Root("g") +
                            " --id " + first.id + " --sampler " + sampler +
                            " --samples 8 --json");
    ASSERT_EQ(pose.exit_code, 0) << sampler << ": " << pose.err;
    EXPECT_EQ(pose.LastJson()["sampler"], sampler);
    // The pose MLP saw the functaset's knn+adam:3 latents, so the frame is fitted so,
    // not with encode's default knn+adam:140.
    EXPECT_THAT(pose.out, HasSubstr("the latent fitted as encode fits it (knn+adam:3,"))
        << sampler;
  }
  // eval's pose rows read the functaset's own latents (encode's fits, what train-pose saw).
  const Result eval = Run("eval --data " + Root("g") + " --model " + Root("p.tfm") +
                          " --functaset " + Root("fw.tfs") + " --pose-model " + Root("p.tpm") +
                          " --out " + Root("pe") + " --threads 1");
  ASSERT_EQ(eval.exit_code, 0) << eval.err;
  EXPECT_THAT(testing_util::Slurp(Root("pe/table.md")),
              HasSubstr("pose MLP on knn+adam:3 latents"));
  const Result pose_default = Run("pose --model " + Root("p.tfm") + " --pose-model " +
                                  Root("p.tpm") + " --data " + Root("g") + " --id " + first.id +
                                  " --samples 8 --json");
  ASSERT_EQ(pose_default.exit_code, 0) << pose_default.err;
  EXPECT_EQ(pose_default.LastJson()["sampler"], "laplace");
  // The sampler that ran, not only the label: the posterior's own report names it, and
  // laplace leaves no sgld record.
  EXPECT_THAT(pose_default.out, HasSubstr("Pose posterior (laplace)"));
  EXPECT_FALSE(pose_default.LastJson().contains("sgld"));
  const Result pose_pixels = Run("pose --model " + Root("p.tfm") + " --pose-model " +
                                 Root("p.tpm") + " --data " + Root("g") + " --id " + first.id +
                                 " --sampler laplace --max-pixels 10");
  EXPECT_EQ(pose_pixels.exit_code, 2);
  EXPECT_THAT(pose_pixels.err, HasSubstr("photometric"));

  // A model without the table (--no-warm-start, or trained before tables) refuses them
  // by name, and is smaller by the table.
  ASSERT_EQ(Run("train --data " + Root("g") + " --out " + Root("p_old.tfm") +
                " --head photometric --steps 4 --marker-warmup 2 --latent-dim 8 --width 8 "
                "--layers 2 --threads 1 --seed 1 --no-warm-start").exit_code, 0);
  EXPECT_EQ(FunctaModel::Load(Root("p_old.tfm")).Trunk(SensorKind::kGelSlim).warm_start, nullptr);
  EXPECT_LT(fs::file_size(Root("p_old.tfm")), fs::file_size(Root("p.tfm")));
  const Result old = Run("encode --model " + Root("p_old.tfm") + " --data " + Root("g") +
                         " --out " + Root("w.tfs") + " --strategy knn+adam:3");
  EXPECT_NE(old.exit_code, 0);
  EXPECT_THAT(old.err, HasSubstr("warm-start table"));

  // The direct trunk's strategies do not fit a photometric trunk, nor adam:N a direct one.
  const Result meta = Run("encode --model " + Root("p.tfm") + " --data " + Root("g") +
                          " --out " + Root("q.tfs") + " --strategy meta_sgd:3");
  EXPECT_NE(meta.exit_code, 0);
  EXPECT_THAT(meta.err, HasSubstr("photometric"));
  ASSERT_NO_FATAL_FAILURE(TrainAndEncode("direct_for_adam"));
  const Result adam = Run("encode --model " + Root("direct_for_adam.tfm") + " --data " +
                          Root("d") + " --out " + Root("q.tfs") + " --strategy adam:3");
  EXPECT_NE(adam.exit_code, 0);
  EXPECT_THAT(adam.err, HasSubstr("adam:3"));
  const Result knn_adam = Run("encode --model " + Root("direct_for_adam.tfm") + " --data " +
                              Root("d") + " --out " + Root("q.tfs") + " --strategy knn+adam:3");
  EXPECT_NE(knn_adam.exit_code, 0);
  EXPECT_THAT(knn_adam.err, HasSubstr("knn+adam:3"));
  // A depth sensor and the direct trunk's knobs are refused by name.
  const Result bubble = Run("train --data " + Root("d") + " --out " + Root("b.tfm") +
                            " --head photometric --sensors bubble --steps 2");
  EXPECT_NE(bubble.exit_code, 0);
  EXPECT_THAT(bubble.err, HasSubstr("depth sensor"));
  const Result resume = Run("train --data " + Root("g") + " --out " + Root("b.tfm") +
                            " --head photometric --steps 2 --resume");
  EXPECT_NE(resume.exit_code, 0);
  EXPECT_THAT(resume.err, HasSubstr("--resume: no checkpoint found"));
  EXPECT_FALSE(fs::exists(Root("b.tfm")));
}

TEST_F(TrainCliTest, ThePhotometricHeadCheckpointsAndResumes) {
  ASSERT_EQ(Run("synth --out " + Root("gr") + " --frames-per-tool 2 --tools rod,square "
                "--sensors gelslim --seed 4").exit_code, 0);
  const std::string args = "train --data " + Root("gr") + " --head photometric --marker-warmup 2 "
                           "--latent-dim 8 --width 8 --layers 2 --threads 1 --seed 1";
  const Result whole = Run(args + " --steps 6 --out " + Root("whole.tfm"));
  ASSERT_EQ(whole.exit_code, 0) << whole.err;
  EXPECT_TRUE(fs::exists(Root("whole.tfm.gelslim.ckpt")));
  // A checkpoint of other options is refused by name; nothing is written.
  const Result other = Run(args + " --steps 8 --out " + Root("whole.tfm") + " --resume");
  EXPECT_NE(other.exit_code, 0);
  EXPECT_THAT(other.err, HasSubstr("option 'steps' differs"));
  // Resuming the finished run writes the same model without another step.
  fs::copy_file(Root("whole.tfm.gelslim.ckpt"), Root("again.tfm.gelslim.ckpt"));
  const Result again = Run(args + " --steps 6 --out " + Root("again.tfm") + " --resume");
  ASSERT_EQ(again.exit_code, 0) << again.err;
  EXPECT_THAT(again.out, HasSubstr("resuming from " + Root("again.tfm.gelslim.ckpt")));
  EXPECT_EQ(testing_util::Slurp(Root("again.tfm")), testing_util::Slurp(Root("whole.tfm")));

  // --default-fit records the fit encode then uses without --strategy (here on resuming the
  // finished run: the same trunk, the fit recorded); info shows it.
  fs::copy_file(Root("whole.tfm.gelslim.ckpt"), Root("fit.tfm.gelslim.ckpt"));
  const Result fit = Run(args + " --steps 6 --out " + Root("fit.tfm") +
                         " --resume --default-fit knn+adam:3");
  ASSERT_EQ(fit.exit_code, 0) << fit.err;
  EXPECT_EQ(FunctaModel::Load(Root("fit.tfm")).Trunk(SensorKind::kGelSlim).default_fit,
            "knn+adam:3");
  EXPECT_EQ(FunctaModel::Load(Root("whole.tfm")).Trunk(SensorKind::kGelSlim).default_fit, "");
  EXPECT_THAT(Run("info " + Root("fit.tfm")).out, HasSubstr("default fit knn+adam:3"));
  const Result encode = Run("encode --model " + Root("fit.tfm") + " --data " + Root("gr") +
                            " --out " + Root("fit.tfs") + " --threads 1");
  ASSERT_EQ(encode.exit_code, 0) << encode.err;
  EXPECT_EQ(Functaset::Load(Root("fit.tfs")).fit_strategy(SensorKind::kGelSlim), "knn+adam:3");
  // A fit the trunk could not use is refused before training, naming the flag.
  for (const std::string& bad : {std::string(" --default-fit meta_sgd:3"),
                                 std::string(" --default-fit knn --no-warm-start"),
                                 std::string(" --default-fit lbfgs:2")}) {
    const Result refused = Run(args + " --steps 2 --out " + Root("bad.tfm") + bad);
    EXPECT_NE(refused.exit_code, 0) << bad;
    EXPECT_THAT(refused.err, HasSubstr("--default-fit")) << bad;
    EXPECT_FALSE(fs::exists(Root("bad.tfm"))) << bad;
    EXPECT_FALSE(fs::exists(Root("bad.tfm.gelslim.ckpt"))) << bad;
  }
  // A direct trunk has no recorded fit (`fit` has its own default for it).
  const Result direct = Run("train --data " + Root("gr") + " --out " + Root("bad.tfm") +
                            " --preset tiny --steps 2 --default-fit meta_sgd:3");
  EXPECT_NE(direct.exit_code, 0);
  EXPECT_THAT(direct.err, HasSubstr("--default-fit applies to --head photometric"));
  EXPECT_FALSE(fs::exists(Root("bad.tfm")));
}

TEST_F(TrainCliTest, ReconWritesOneCsvRowPerFrameThatAgreesWithItsSummary) {
  ASSERT_NO_FATAL_FAILURE(TrainAndEncode("r"));
  const Result recon = Run("recon --model " + Root("r.tfm") + " --functaset " + Root("r.tfs") +
                           " --data " + Root("d") + " --out " + Root("recon") + " --json");
  ASSERT_EQ(recon.exit_code, 0) << recon.err;
  EXPECT_EQ(recon.LastJson()["per_frame"].get<std::string>(), Root("recon") + "/frames.csv");

  std::ifstream csv(Root("recon") + "/frames.csv");
  std::string line;
  ASSERT_TRUE(std::getline(csv, line));
  EXPECT_EQ(line,
            "frame,sensor,split,tool,depth_m,target_range,source_range,rmse,psnr,psnr_clean,"
            "psnr_zero,psnr_source_peak,contact,contact_score,contact_row,contact_col,"
            "recon_contact_row,recon_contact_col");
  int rows = 0, train_rows = 0;
  double train_psnr_sum = 0;
  while (std::getline(csv, line)) {
    const std::vector<std::string> f = testing_util::CsvFields(line);
    ASSERT_EQ(f.size(), 18u) << line;
    // Every simulated frame is a press, its centre inside the 140 x 175 frame.
    EXPECT_EQ(f[12], "1") << line;
    EXPECT_GE(std::stod(f[13]), 6.0) << line;
    EXPECT_TRUE(std::stod(f[14]) >= 0 && std::stod(f[14]) < 140) << line;
    EXPECT_TRUE(std::stod(f[15]) >= 0 && std::stod(f[15]) < 175) << line;
    ++rows;
    EXPECT_EQ(f[1], "bubble");
    EXPECT_THAT(f[3], ::testing::AnyOf("rod", "square"));
    // PSNR = 20 log10(range / RMSE), each column as printed (9 significant digits).
    EXPECT_NEAR(std::stod(f[8]), 20 * std::log10(std::stod(f[5]) / std::stod(f[7])), 1e-5);
    EXPECT_GE(std::stod(f[6]), std::stod(f[5]) * (1 - 1e-6));  // source range >= resized
    if (f[2] == "train") {
      ++train_rows;
      train_psnr_sum += std::stod(f[8]);
    }
  }
  EXPECT_EQ(rows, 8);  // 2 tools x 4 contacts
  ASSERT_GT(train_rows, 0);
  EXPECT_NEAR(train_psnr_sum / train_rows,
              recon.LastJson()["psnr_train"]["bubble"].get<double>(), 1e-6);
}

TEST_F(TrainCliTest, ReconWorstPicturesTheLowestPsnrFrames) {
  ASSERT_NO_FATAL_FAILURE(TrainAndEncode("w"));
  const Result recon = Run("recon --model " + Root("w.tfm") + " --functaset " + Root("w.tfs") +
                           " --data " + Root("d") + " --out " + Root("worst") +
                           " --examples 3 --worst --json");
  ASSERT_EQ(recon.exit_code, 0) << recon.err;
  const auto shown = recon.LastJson()["pictured"]["bubble"].get<std::vector<std::string>>();
  ASSERT_EQ(shown.size(), 3u);
  EXPECT_TRUE(fs::exists(Root("worst") + "/recon_bubble.png"));

  // The three lowest PSNRs of frames.csv (every frame is in the train split here), in
  // order.
  std::ifstream csv(Root("worst") + "/frames.csv");
  std::string line;
  std::getline(csv, line);
  std::vector<std::pair<double, std::string>> by_psnr;
  while (std::getline(csv, line)) {
    const std::vector<std::string> f = testing_util::CsvFields(line);
    ASSERT_EQ(f[2], "train");
    by_psnr.emplace_back(std::stod(f[8]), f[0]);
  }
  std::sort(by_psnr.begin(), by_psnr.end());
  ASSERT_GE(by_psnr.size(), 3u);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(shown[k], by_psnr[k].second) << k;

  // Without --worst the picture spreads over the frames instead.
  const Result spread = Run("recon --model " + Root("w.tfm") + " --functaset " + Root("w.tfs") +
                            " --data " + Root("d") + " --out " + Root("spread") +
                            " --examples 3 --json");
  ASSERT_EQ(spread.exit_code, 0) << spread.err;
  EXPECT_NE(spread.LastJson()["pictured"]["bubble"].get<std::vector<std::string>>(), shown);
}

TEST_F(TrainCliTest, InfoDescribesTheModelTheFunctasetAndTheCheckpointItIsGiven) {
  ASSERT_NO_FATAL_FAILURE(TrainAndEncode("i"));
  const Result model = Run("info " + Root("i.tfm") + " --json");
  ASSERT_EQ(model.exit_code, 0) << model.err;
  const auto m = model.LastJson();
  EXPECT_EQ(m["kind"], "model");
  const auto& trunk = m["model"]["trunks"]["bubble"];
  EXPECT_EQ(trunk["width"], 32);  // the tiny preset
  EXPECT_EQ(trunk["layers"], 2);
  EXPECT_EQ(trunk["latent_dim"], 16);
  EXPECT_EQ(trunk["steps"], 3);
  EXPECT_EQ(m["checksum"].get<std::uint32_t>(), FunctaModel::Load(Root("i.tfm")).checksum());

  const Result functaset = Run("info " + Root("i.tfs") + " --json");
  ASSERT_EQ(functaset.exit_code, 0) << functaset.err;
  const auto f = functaset.LastJson();
  EXPECT_EQ(f["kind"], "functaset");
  EXPECT_EQ(f["functaset"]["model_checksum"], m["checksum"]);
  EXPECT_EQ(f["functaset"]["sensors"]["bubble"]["count"], 8);
  EXPECT_EQ(f["functaset"]["sensors"]["bubble"]["latent_dim"], 16);
  EXPECT_TRUE(f["functaset"]["complete"].get<bool>());

  const Result checkpoint = Run("info " + Root("i.tfm") + ".bubble.ckpt --json");
  ASSERT_EQ(checkpoint.exit_code, 0) << checkpoint.err;
  EXPECT_EQ(checkpoint.LastJson()["checkpoint"]["step"], 3);
  EXPECT_THAT(checkpoint.out, HasSubstr("--resume"));

  // A damaged file is refused with the reason, naming it.
  {
    std::ifstream in(Root("i.tfm"), std::ios::binary);
    std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
    std::ofstream(Root("cut.tfm"), std::ios::binary) << bytes.substr(0, bytes.size() / 2);
  }
  const Result cut = Run("info " + Root("cut.tfm"));
  EXPECT_EQ(cut.exit_code, 1);
  EXPECT_THAT(cut.err, HasSubstr(Root("cut.tfm")));
  EXPECT_THAT(cut.err, HasSubstr("truncated"));
}

TEST_F(TrainCliTest, EncodeWritesEightBitLatentsThatInfoAndReconReport) {
  ASSERT_NO_FATAL_FAILURE(TrainAndEncode("q"));
  const Result encode = Run("encode --model " + Root("q.tfm") + " --data " + Root("d") +
                            " --out " + Root("q8.tfs") + " --threads 1 --latent-precision uint8");
  ASSERT_EQ(encode.exit_code, 0) << encode.err;
  const Result info = Run("info " + Root("q8.tfs") + " --json");
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_THAT(info.out, HasSubstr("latents uint8"));
  EXPECT_EQ(info.LastJson()["functaset"]["latent_precision"], "uint8");
  EXPECT_EQ(info.LastJson()["functaset"]["sensors"]["bubble"]["count"], 8);
  // 8 frames x 16 one-byte codes, plus the 16 float32 offsets and steps.
  const Result recon = Run("recon --model " + Root("q.tfm") + " --functaset " + Root("q8.tfs") +
                           " --data " + Root("d") + " --out " + Root("q8_recon") +
                           " --examples 1 --threads 1 --json");
  ASSERT_EQ(recon.exit_code, 0) << recon.err;
  EXPECT_EQ(recon.LastJson()["latent_bytes"], 8 * 16 + 2 * 16 * 4);
  EXPECT_TRUE(recon.LastJson()["psnr_train"]["bubble"].is_number());
  const Result bad = Run("encode --model " + Root("q.tfm") + " --data " + Root("d") + " --out " +
                         Root("q2.tfs") + " --latent-precision uint2");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_THAT(bad.err, HasSubstr("--latent-precision"));
  EXPECT_FALSE(fs::exists(Root("q2.tfs")));
}

// A user folder of 16-bit one-channel PNGs (read as bubble frames) of rows x cols:
// reference.png and a few frames with a bump.
void WriteUserBubbleFolder(const fs::path& dir, int rows, int cols) {
  fs::create_directories(dir);
  cv::Mat reference(rows, cols, CV_16UC1, cv::Scalar(50000));
  ASSERT_TRUE(cv::imwrite((dir / "reference.png").string(), reference));
  for (int k = 0; k < 3; ++k) {
    cv::Mat frame = reference.clone();
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < cols; ++c) {
        const double d2 = std::pow(r - rows / 2.0, 2) + std::pow(c - cols / (2.0 + k), 2);
        frame.at<std::uint16_t>(r, c) =
            static_cast<std::uint16_t>(50000 - 3000 * std::exp(-d2 / (0.02 * rows * cols)));
      }
    }
    ASSERT_TRUE(cv::imwrite((dir / ("f" + std::to_string(k) + ".png")).string(), frame));
  }
}

TEST_F(TrainCliTest, TrainSaysWhatItWillRunAndEncodeRefusesFramesOfAnotherSensor) {
  const Result train = Run("train --data " + Root("d") + " --out " + Root("s.tfm") +
                           " --preset tiny --steps 3 --seed 2 --json");
  ASSERT_EQ(train.exit_code, 0) << train.err;
  // Before the first step: how many steps, of which preset, at which resolution.
  EXPECT_THAT(train.out, HasSubstr("train bubble: 3 steps (preset tiny, --steps) at 16x20"));
  EXPECT_EQ(train.out.find("train bubble: 3 steps (preset tiny"), train.out.find("train bubble:"));
  // The model records the frames its trunk was trained on (synth: 140 x 175 depth).
  const FunctaModel model = FunctaModel::Load(Root("s.tfm"));
  const nlohmann::json info = nlohmann::json::parse(model.info_json());
  const nlohmann::json& frames = info["trunks"]["bubble"]["data_frames"];
  EXPECT_EQ(frames["rows"], 140) << frames.dump();
  EXPECT_EQ(frames["cols"], 175) << frames.dump();
  EXPECT_EQ(frames["channels"], 1) << frames.dump();

  // Square 48 x 48 frames: another size than the trunk's (refused, naming both files
  // and both sizes), and another aspect than its 16 x 20 working resolution.
  WriteUserBubbleFolder(*root_ / "square", 48, 48);
  const std::string encode = "encode --model " + Root("s.tfm") + " --data " + Root("square") +
                             " --out " + Root("square.tfs") + " --threads 1";
  Result r = Run(encode);
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_THAT(r.err, HasSubstr(Root("s.tfm")));
  EXPECT_THAT(r.err, HasSubstr(Root("square")));
  EXPECT_THAT(r.err, HasSubstr("140x175x1"));
  EXPECT_THAT(r.err, HasSubstr("48x48x1"));
  EXPECT_THAT(r.err, HasSubstr("--allow-other-frames"));
  EXPECT_FALSE(fs::exists(Root("square.tfs")));
  r = Run(encode + " --allow-other-frames");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.err, HasSubstr("warning (--allow-other-frames)"));
  EXPECT_THAT(r.err, HasSubstr("48x48 (rows x cols, aspect 1.00) but are resized to 16x20 "
                               "(aspect 1.25): stretched"));
  // Progress lines, not a bar, when stderr is not a terminal.
  EXPECT_THAT(r.err, HasSubstr("encode: 3/3 frames (100%)"));
  EXPECT_EQ(r.err.find('\r'), std::string::npos);
  // The training data itself: no warning at all.
  r = Run("encode --model " + Root("s.tfm") + " --data " + Root("d") + " --out " +
          Root("s.tfs") + " --threads 1");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.err, ::testing::Not(HasSubstr("warning")));
}

TEST_F(TrainCliTest, ASpatialLatentTrunkTrainsAndEveryCommandUsesIt) {
  // A 2 x 2 grid of 3-value latents (12 values) beside 4 global ones: d = 16.
  const Result train = Run("train --data " + Root("d") + " --out " + Root("sp.tfm") +
                           " --preset tiny --steps 3 --seed 2 --spatial-latent 2x2x3");
  ASSERT_EQ(train.exit_code, 0) << train.err;
  EXPECT_THAT(train.out, HasSubstr("spatial latents 2x2x3 + 4 global"));
  const FunctaModel model = FunctaModel::Load(Root("sp.tfm"));
  const LatentModulatedSiren::Options& o = model.Trunk(SensorKind::kSoftBubble).siren.options();
  EXPECT_EQ(o.spatial_rows, 2);
  EXPECT_EQ(o.spatial_cols, 2);
  EXPECT_EQ(o.spatial_channels, 3);
  EXPECT_EQ(o.latent_dim, 16);
  EXPECT_EQ(o.global_latent_dim(), 4);
  const Result info = Run("info " + Root("sp.tfm") + " --json");
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_THAT(info.out, HasSubstr("spatial latents: a 2 x 2 grid of 3 values (12) + 4 global"));
  EXPECT_EQ(info.LastJson()["model"]["trunks"]["bubble"]["spatial"]["channels"].get<int>(), 3);
  for (const std::string strategy : {"meta_sgd:3", "ceres:3"}) {
    const std::string name = strategy == "ceres:3" ? "sp_ceres" : "sp";
    const Result encode = Run("encode --model " + Root("sp.tfm") + " --data " + Root("d") +
                              " --out " + Root(name + ".tfs") + " --threads 1 --strategy " +
                              strategy);
    ASSERT_EQ(encode.exit_code, 0) << encode.err;
    const Result recon = Run("recon --model " + Root("sp.tfm") + " --functaset " +
                             Root(name + ".tfs") + " --data " + Root("d") + " --out " +
                             Root(name + "_recon") + " --json");
    ASSERT_EQ(recon.exit_code, 0) << recon.err;
    const Result eval = Run("eval --data " + Root("d") + " --model " + Root("sp.tfm") +
                            " --functaset " + Root(name + ".tfs") + " --out " +
                            Root(name + "_eval") + " --threads 1");
    EXPECT_EQ(eval.exit_code, 0) << eval.err;
  }
  const Result fit = Run("fit --model " + Root("sp.tfm") + " --frame " +
                         Root("d/bubble/000003.png") + " --reference " +
                         Root("d/bubble/reference.png") + " --strategy ceres:3 --out " +
                         Root("sp_fit") + " --json");
  EXPECT_EQ(fit.exit_code, 0) << fit.err;
  // A grid with more values than the latent fails before any data is read, naming both.
  const Result bad = Run("train --data " + Root("d") + " --out " + Root("bad_sp.tfm") +
                         " --preset tiny --steps 2 --spatial-latent 3x3x2");
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_THAT(bad.err, HasSubstr("--spatial-latent 3x3x2"));
  EXPECT_THAT(bad.err, HasSubstr("--latent-dim >= 18"));
  const Result malformed = Run("train --data " + Root("d") + " --out " + Root("bad_sp.tfm") +
                               " --preset tiny --steps 2 --spatial-latent 3x3");
  EXPECT_EQ(malformed.exit_code, 2);
  EXPECT_THAT(malformed.err, HasSubstr("GHxGWxC"));
  EXPECT_FALSE(fs::exists(Root("bad_sp.tfm")));
}

TEST_F(TrainCliTest, ADivergingRunFailsNamingTheLearningRateAndWritesNoModel) {
  const Result r = Run("train --data " + Root("d") + " --out " + Root("div.tfm") +
                       " --preset tiny --learning-rate 0.03 --seed 1");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("diverged"));
  EXPECT_THAT(r.err, HasSubstr("--learning-rate was 0.03"));
  EXPECT_THAT(r.err, HasSubstr("--divergence-drop-db"));
  EXPECT_FALSE(fs::exists(Root("div.tfm")));
}

TEST_F(TrainCliTest, BadInnerLoopKnobsFailNamingThemAndWriteNothing) {
  const std::string base = "train --data " + Root("d") + " --out " + Root("bad.tfm") +
                           " --preset tiny --steps 2";
  Result r = Run(base + " --alpha-init 3");  // above the default bound 1
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("alpha_max"));
  r = Run(base + " --inner-steps 0");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("--inner-steps"));
  r = Run(base + " --alpha-max -1");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("--alpha-max"));
  EXPECT_FALSE(fs::exists(Root("bad.tfm")));
}

}  // namespace
}  // namespace tactfunc
