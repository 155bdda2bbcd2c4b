// Copyright 2026 The tactfunc Authors.
//
// `tactfunc eval` as a user runs it: a tiny hand-built model and dataset, its functaset
// from `tactfunc encode` and a tiny pose model from `train-pose`
// (tests/apps/cli_test_util.h); the --json shape, the files written, and bad input that
// fails with a message naming the file.
#include <filesystem>
#include <set>
#include <string>

#include <opencv2/imgcodecs.hpp>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "nlohmann/json.hpp"
#include "tests/apps/cli_test_util.h"

namespace tactfunc {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using Result = testing_util::CliResult;

class EvalCliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    Result encode;
    root_ = new fs::path(testing_util::MakeEncodedFixture("tactfunc_eval_cli", &encode));
    ASSERT_EQ(encode.exit_code, 0) << encode.err;
    train_pose_ = new Result(Run("train-pose --functaset " + Root("f.tfs") + " --out " +
                                 Root("p.tpm") + " --hidden 16,16 --epochs 20 --batch 4 --json"));
    // The same functaset again as an "extra" point: two TactFunc points in the picture.
    eval_ = new Result(Run(EvalArgs() + " --out " + Root("table") + " --threads 1 --json" +
                           " --extra-functaset " + Root("f.tfs") + " --extra-model " +
                           Root("m.tfm")));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*root_);
    delete root_;
    delete train_pose_;
    delete eval_;
  }
  static std::string Root(const std::string& name) { return (*root_ / name).string(); }
  static Result Run(const std::string& args) { return testing_util::RunTactfunc(*root_, args); }
  static std::string EvalArgs() {
    return "eval --data " + Root("d") + " --model " + Root("m.tfm") + " --functaset " +
           Root("f.tfs") + " --pose-model " + Root("p.tpm");
  }

  static fs::path* root_;
  static Result* train_pose_;
  static Result* eval_;
};

fs::path* EvalCliTest::root_ = nullptr;
Result* EvalCliTest::train_pose_ = nullptr;
Result* EvalCliTest::eval_ = nullptr;

TEST_F(EvalCliTest, JsonHasARowPerApproachSensorAndSplitWithTheTableColumns) {
  ASSERT_EQ(train_pose_->exit_code, 0) << train_pose_->err;
  const Result& r = *eval_;
  ASSERT_EQ(r.exit_code, 0) << r.err << r.out;
  EXPECT_THAT(r.out, HasSubstr("| approach |"));  // the markdown table on stdout
  const nlohmann::json j = r.LastJson();
  ASSERT_TRUE(j["rows"].is_array());
  std::set<std::string> seen;
  for (const nlohmann::json& row : j["rows"]) {
    for (const char* key : {"approach", "sensor", "split", "rep_size_mb", "bytes_per_frame", "psnr",
                            "pose_mse", "rmse_mm", "rmse_deg"}) {
      EXPECT_TRUE(row.contains(key)) << key << " in " << row.dump();
    }
    seen.insert(row["approach"].get<std::string>() + "/" + row["sensor"].get<std::string>() + "/" +
                row["split"].get<std::string>());
    EXPECT_GT(row["rep_size_mb"].get<double>(), 0) << row.dump();
    if (row["approach"] == "Raw frames") {
      EXPECT_TRUE(row["psnr"].is_null()) << row.dump();  // lossless: not applicable
    } else {
      EXPECT_TRUE(row["psnr"].is_number()) << row.dump();
    }
    // Poses on the pose model's sensor (bubble) except for JPEG; none on gelslim.
    const bool posed = row["sensor"] == "bubble" && row["approach"] != "JPEG";
    EXPECT_EQ(row["pose_mse"].is_number(), posed) << row.dump();
    EXPECT_EQ(row["rmse_mm"].is_number(), posed) << row.dump();
  }
  for (const char* approach : {"TactFunc", "PCA", "JPEG", "Raw frames"}) {
    for (const char* sensor : {"bubble", "gelslim"}) {
      for (const char* split : {"train", "test"}) {
        EXPECT_TRUE(seen.count(std::string(approach) + "/" + sensor + "/" + split))
            << approach << " " << sensor << " " << split;
      }
    }
  }
  // Bytes per frame: TactFunc stores its latent's floats as float16 (encode's default),
  // PCA as many float32 components (bubble d = 8, gelslim d = 6).
  for (const nlohmann::json& row : j["rows"]) {
    const int d = row["sensor"] == "bubble" ? 8 : 6;
    if (row["approach"] == "TactFunc") {
      EXPECT_EQ(row["bytes_per_frame"].get<double>(), 2 * d);
    }
    if (row["approach"] == "PCA") {
      EXPECT_EQ(row["bytes_per_frame"].get<double>(), 4 * d);
    }
  }
}

TEST_F(EvalCliTest, TargetsSayPlainlyWhetherEachIsMetWithTheNumbers) {
  const Result& r = *eval_;
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = r.LastJson();
  const nlohmann::json& t = j["targets"];
  ASSERT_TRUE(t.contains("bubble"));
  for (const char* key : {"psnr_3db_above_pca", "psnr_above_jpeg", "pose_beats_pca_codes",
                          "pose_not_worse_than_raw"}) {
    ASSERT_TRUE(t["bubble"].contains(key)) << key;
    EXPECT_TRUE(t["bubble"][key]["met"].is_boolean()) << key;
  }
  EXPECT_TRUE(t["bubble"]["psnr_3db_above_pca"]["pca_db"].is_number());
  // The fixture has noise-free frames: the same target against them, with the figures of
  // the TactFunc and PCA test rows' clean PSNR (PCA at equal bytes: 2 * d / 4 components).
  for (const char* sensor : {"bubble", "gelslim"}) {
    const nlohmann::json& c = t[sensor]["psnr_3db_above_pca_clean"];
    ASSERT_TRUE(c.is_object()) << sensor << ": " << t[sensor].dump();
    EXPECT_TRUE(c["met"].is_boolean());
    for (const nlohmann::json& row : j["rows"]) {
      if (row["sensor"] != sensor || row["split"] != "test") continue;
      if (row["approach"] == "TactFunc") {
        ASSERT_TRUE(row["psnr_clean"].is_number()) << row.dump();
        EXPECT_DOUBLE_EQ(c["tactfunc_db"].get<double>(), row["psnr_clean"].get<double>());
        EXPECT_NE(row["psnr_clean"].get<double>(), row["psnr"].get<double>());  // other frames
      }
      if (row["approach"] == "PCA") {
        EXPECT_TRUE(row["psnr_clean"].is_number()) << row.dump();
      }
      if (row["approach"] == "JPEG") {
        EXPECT_TRUE(row["psnr_clean"].is_null()) << row.dump();
      }
    }
    EXPECT_DOUBLE_EQ(c["margin_db"].get<double>(),
                     c["tactfunc_db"].get<double>() - c["pca_db"].get<double>());
    EXPECT_EQ(c["met"].get<bool>(), c["margin_db"].get<double>() >= 3);
  }
  EXPECT_THAT(r.out, HasSubstr("PSNR clean (dB)"));
  EXPECT_THAT(r.out, HasSubstr("noise-free frames (test)"));
  EXPECT_FALSE(t["gelslim"].contains("pose_beats_pca_codes"));  // no pose model for gelslim
  EXPECT_TRUE(j["all_targets_met"].is_boolean());
  EXPECT_THAT(r.out, HasSubstr("Targets:"));
}

TEST_F(EvalCliTest, PcaCodesInTheSameBytesSharedAmongTheirValuesAreReportedBesideTheTargets) {
  // The fixture's functaset stores float16 latents (2 d bytes per frame): the strongest
  // PCA baseline takes those bytes through the allocation of `encode --latent-bytes`.
  const Result& r = *eval_;
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = r.LastJson();
  const std::set<int> ladder = {1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48};
  for (const auto& [sensor, d] : {std::pair<std::string, int>{"bubble", 8}, {"gelslim", 6}}) {
    for (const char* key :
         {"psnr_3db_above_pca_shared_bytes", "psnr_3db_above_pca_shared_bytes_clean"}) {
      const nlohmann::json& t = j["targets"][sensor][key];
      ASSERT_TRUE(t.is_object()) << sensor << " " << key << ": " << j["targets"].dump();
      EXPECT_EQ(t["bytes_per_frame"], 2 * d) << t.dump();
      const int n = t["pca_components"].get<int>();
      EXPECT_TRUE(n == d || ladder.count(n)) << t.dump();
      EXPECT_LE(n, 8 * 2 * d) << t.dump();
      EXPECT_DOUBLE_EQ(t["margin_db"].get<double>(),
                       t["tactfunc_db"].get<double>() - t["pca_db"].get<double>());
      EXPECT_EQ(t["met"].get<bool>(), t["margin_db"].get<double>() >= 3) << t.dump();
    }
    // The same TactFunc figure as the same-bits target's, against another PCA.
    EXPECT_DOUBLE_EQ(
        j["targets"][sensor]["psnr_3db_above_pca_shared_bytes_clean"]["tactfunc_db"].get<double>(),
        j["targets"][sensor]["psnr_3db_above_pca_same_bits_clean"]["tactfunc_db"].get<double>());
  }
  EXPECT_THAT(r.out, HasSubstr("PCA codes in the same bytes shared among their values, "
                               "noise-free frames (test; reported, not counted in all targets)"));
}

TEST_F(EvalCliTest, PoseRowsReadLatentsOfThePoseModelsOwnMap) {
  // The fixture's pose model was trained on the functaset's own latents: used as stored.
  const nlohmann::json j = eval_->LastJson();
  for (const nlohmann::json& row : j["rows"]) {
    if (row["approach"] == "TactFunc" && row["sensor"] == "bubble") {
      EXPECT_EQ(row["pose_from"], "pose MLP on meta_sgd:3 latents") << row.dump();
    }
  }
  EXPECT_THAT(eval_->out, ::testing::Not(HasSubstr("re-fitted")));
  // A pose model trained on re-fitted latents (train-pose --refit) gets latents of that
  // map: eval re-fits the frames and says so, instead of feeding it the stored ones.
  const Result refit_pose =
      Run("train-pose --functaset " + Root("f.tfs") + " --model " + Root("m.tfm") + " --data " +
          Root("d") + " --refit ceres:3 --out " + Root("pr.tpm") +
          " --hidden 16,16 --epochs 20 --batch 4");
  ASSERT_EQ(refit_pose.exit_code, 0) << refit_pose.err;
  const Result r = Run("eval --data " + Root("d") + " --model " + Root("m.tfm") + " --functaset " +
                       Root("f.tfs") + " --pose-model " + Root("pr.tpm") + " --out " +
                       Root("table_refit") + " --threads 1 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("the pose model reads ceres:3 latents, the functaset holds "
                               "meta_sgd:3 ones"));
  int rows = 0;
  const nlohmann::json refit_json = r.LastJson();
  for (const nlohmann::json& row : refit_json["rows"]) {
    if (row["approach"] != "TactFunc" || row["sensor"] != "bubble") continue;
    ++rows;
    EXPECT_EQ(row["pose_from"], "pose MLP on ceres:3 latents") << row.dump();
    EXPECT_TRUE(row["pose_mse"].is_number()) << row.dump();
  }
  EXPECT_EQ(rows, 2);  // train and test
}

TEST_F(EvalCliTest, WritesTheTableJsonAndTheRateDistortionPicture) {
  const Result& r = *eval_;
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* name : {"table.md", "table.json", "rate_distortion.png"}) {
    EXPECT_TRUE(fs::is_regular_file(*root_ / "table" / name)) << name;
  }
  const std::string md = testing_util::Slurp(Root("table/table.md"));
  EXPECT_THAT(md, HasSubstr("Command: `tactfunc eval"));
  EXPECT_THAT(md, HasSubstr("| TactFunc |"));
  const nlohmann::json file = nlohmann::json::parse(testing_util::Slurp(Root("table/table.json")));
  EXPECT_EQ(file["rows"], r.LastJson()["rows"]);
  const nlohmann::json& rd = file["rate_distortion"]["bubble"];
  EXPECT_EQ(rd["tactfunc"].size(), 2u);  // the main functaset and the extra one
  EXPECT_GE(rd["pca"].size(), 2u);
  EXPECT_GE(rd["jpeg"].size(), 5u);
  const std::string png = testing_util::Slurp(Root("table/rate_distortion.png"));
  EXPECT_EQ(png.substr(1, 3), "PNG");
}

// Allocated codes: encode spends exactly the bytes asked for, info says how they were
// shared, and eval holds PCA codes to the same bytes through the same allocation, with
// the component count (d, d / 2, ...) that serves PCA best.
TEST_F(EvalCliTest, AllocatedCodesAreComparedWithPcaCodesInTheSameBytes) {
  const Result encode = Run("encode --model " + Root("m.tfm") + " --data " + Root("d") +
                            " --out " + Root("a6.tfs") + " --threads 1 --latent-bytes 6");
  ASSERT_EQ(encode.exit_code, 0) << encode.err;
  const Result info = Run("info " + Root("a6.tfs") + " --json");
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_THAT(info.out, HasSubstr("latents allocated"));
  EXPECT_THAT(info.out, HasSubstr("6 B each on disk ("));
  const nlohmann::json f = info.LastJson()["functaset"];
  EXPECT_EQ(f["latent_precision"], "allocated");
  EXPECT_EQ(f["latent_bytes"], 6);
  for (const auto& [sensor, d] : {std::pair<std::string, int>{"bubble", 8}, {"gelslim", 6}}) {
    const nlohmann::json& bits = f["sensors"][sensor]["latent_bits"];
    ASSERT_EQ(bits.size(), static_cast<std::size_t>(d)) << sensor;
    int total = 0;
    for (const nlohmann::json& b : bits) total += b.get<int>();
    EXPECT_LE(total, 48) << sensor;
    EXPECT_GT(total, 40) << sensor;  // the bytes are spent, not left empty
  }
  const Result encode3 = Run("encode --model " + Root("m.tfm") + " --data " + Root("d") +
                             " --out " + Root("a3.tfs") + " --threads 1 --latent-bytes 3");
  ASSERT_EQ(encode3.exit_code, 0) << encode3.err;
  // eval of one allocated functaset with the other beside it, into table_<main>.
  const auto eval_led_by = [&](const std::string& main, const std::string& extra) {
    return Run("eval --data " + Root("d") + " --model " + Root("m.tfm") + " --functaset " +
               Root(main + ".tfs") + " --out " + Root("table_" + main) + " --extra-functaset " +
               Root(extra + ".tfs") + " --extra-model " + Root("m.tfm") + " --threads 1 --json");
  };
  const Result r = eval_led_by("a6", "a3");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = r.LastJson();
  // The picture's points: PCA stored as each functaset stores its latents, at its bytes,
  // with PSNRs against the frames and (the fixture has them) the noise-free copies.
  for (const char* sensor : {"bubble", "gelslim"}) {
    const nlohmann::json& stored = j["rate_distortion"][sensor]["pca_same_storage"];
    ASSERT_EQ(stored.size(), 2u) << stored.dump();
    EXPECT_EQ(stored[0]["bytes_per_frame"], 6);
    EXPECT_EQ(stored[1]["bytes_per_frame"], 3);
    for (const nlohmann::json& p : stored) {
      EXPECT_TRUE(p["psnr_test"].is_number()) << p.dump();
      EXPECT_TRUE(p["psnr_test_clean"].is_number()) << p.dump();
    }
    // The main point is the clean target's PCA figure.
    EXPECT_DOUBLE_EQ(stored[0]["psnr_test_clean"].get<double>(),
                     j["targets"][sensor]["psnr_3db_above_pca_same_bits_clean"]["pca_db"]
                         .get<double>());
    for (const nlohmann::json& p : j["rate_distortion"][sensor]["tactfunc"]) {
      EXPECT_TRUE(p["psnr_test_clean"].is_number()) << p.dump();
    }
  }
  // Two panels per sensor side by side, against the frames and against the noise-free
  // copies: twice the 1400-pixel width of a plot (LogXPlot's canvas, apps/pictures.h).
  const cv::Mat picture = cv::imread(Root("table_a6/rate_distortion.png"));
  ASSERT_FALSE(picture.empty());
  EXPECT_EQ(picture.cols, 2 * 1400);
  for (const nlohmann::json& row : j["rows"]) {
    if (row["approach"] == "TactFunc") {
      EXPECT_EQ(row["bytes_per_frame"], 6) << row.dump();
    }
  }
  for (const auto& [sensor, d] : {std::pair<std::string, int>{"bubble", 8}, {"gelslim", 6}}) {
    for (const char* key :
         {"psnr_3db_above_pca_same_bits", "psnr_3db_above_pca_same_bits_clean"}) {
      const nlohmann::json& t = j["targets"][sensor][key];
      ASSERT_TRUE(t.is_object()) << sensor << " " << key;
      EXPECT_EQ(t["bytes_per_frame"], 6) << t.dump();
      // d, or a count of the ladder 1, 2, 3, 4, 6, 8, ... that 6 bytes fit (up to 48:
      // eval's PCA keeps that many components where the train frames allow).
      const std::set<int> ladder = {1, 2, 3, 4, 6, 8, 12, 16, 24, 32, 48};
      const int n = t["pca_components"].get<int>();
      EXPECT_TRUE(n == d || ladder.count(n)) << t.dump();
      EXPECT_TRUE(t["pca_db"].is_number()) << t.dump();
      EXPECT_LE(n, 48) << t.dump();
      // For allocated codes the shared-bytes baseline is the same-bits one.
      const std::string shared = std::string(key).find("clean") != std::string::npos
                                     ? "psnr_3db_above_pca_shared_bytes_clean"
                                     : "psnr_3db_above_pca_shared_bytes";
      EXPECT_EQ(j["targets"][sensor][shared], t) << sensor << " " << key;
    }
  }
  // A budget's PCA baseline does not depend on which functaset is the main one: the 6 B
  // point of a run led by the 3 B functaset is the 6 B run's own.
  const Result swapped = eval_led_by("a3", "a6");
  ASSERT_EQ(swapped.exit_code, 0) << swapped.err;
  const nlohmann::json led_by_3 = swapped.LastJson();
  for (const char* sensor : {"bubble", "gelslim"}) {
    const nlohmann::json& stored = led_by_3["rate_distortion"][sensor]["pca_same_storage"];
    ASSERT_EQ(stored.size(), 2u) << stored.dump();
    EXPECT_EQ(stored[1]["bytes_per_frame"], 6);
    EXPECT_EQ(stored[1], j["rate_distortion"][sensor]["pca_same_storage"][0]) << sensor;
  }
  // More bytes than 16 bits per value fill, or both storage flags: refused, nothing written.
  for (const std::string& flags : {std::string("--latent-bytes 13 --sensors gelslim"),
                                   std::string("--latent-bytes 6 --latent-precision uint8")}) {
    const Result bad = Run("encode --model " + Root("m.tfm") + " --data " + Root("d") +
                           " --out " + Root("bad.tfs") + " --threads 1 " + flags);
    EXPECT_EQ(bad.exit_code, 2) << flags << ": " << bad.err;
    EXPECT_THAT(bad.err, HasSubstr("--latent-bytes")) << flags;
    EXPECT_FALSE(fs::exists(Root("bad.tfs"))) << flags;
  }
}

TEST_F(EvalCliTest, WithoutAPoseModelTheTableHoldsTheReconstructionColumnsAlone) {
  const Result r = Run("eval --data " + Root("d") + " --model " + Root("m.tfm") +
                       " --functaset " + Root("f.tfs") + " --out " + Root("table_nopose") +
                       " --threads 1 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err << r.out;
  // Said once on stderr and in table.md.
  const std::string said = "no --pose-model";
  ASSERT_NE(r.err.find(said), std::string::npos) << r.err;
  EXPECT_EQ(r.err.find(said, r.err.find(said) + 1), std::string::npos) << r.err;
  const std::string md = testing_util::Slurp(Root("table_nopose/table.md"));
  EXPECT_THAT(md, HasSubstr("No pose model was given"));
  EXPECT_THAT(md, HasSubstr("| TactFunc |"));
  EXPECT_THAT(md, ::testing::Not(HasSubstr("pose MSE")));
  EXPECT_THAT(md, ::testing::Not(HasSubstr("pose from")));
  const nlohmann::json j = r.LastJson();
  std::set<std::string> approaches;
  for (const nlohmann::json& row : j["rows"]) {
    approaches.insert(row["approach"].get<std::string>());
    EXPECT_TRUE(row["pose_mse"].is_null()) << row.dump();
    EXPECT_TRUE(row["rmse_mm"].is_null()) << row.dump();
    EXPECT_TRUE(row["pose_from"].is_null()) << row.dump();
    if (row["approach"] != "Raw frames") {
      EXPECT_TRUE(row["psnr"].is_number()) << row.dump();
    }
  }
  EXPECT_EQ(approaches, (std::set<std::string>{"TactFunc", "PCA", "JPEG", "Raw frames"}));
  EXPECT_TRUE(j["pose_sensor"].is_null());
  for (const char* sensor : {"bubble", "gelslim"}) {
    const nlohmann::json& t = j["targets"][sensor];
    EXPECT_TRUE(t["psnr_3db_above_pca"]["pca_db"].is_number()) << sensor;
    EXPECT_TRUE(t["psnr_above_jpeg"]["met"].is_boolean()) << sensor;
    ASSERT_TRUE(t.contains("pose_beats_pca_codes")) << sensor;
    EXPECT_TRUE(t["pose_beats_pca_codes"].is_null()) << sensor;
    EXPECT_TRUE(t["pose_not_worse_than_raw"].is_null()) << sensor;
  }
  EXPECT_TRUE(fs::is_regular_file(Root("table_nopose/rate_distortion.png")));
  // Progress lines (stderr is a file here), not a carriage-return bar.
  EXPECT_THAT(r.err, HasSubstr("eval: TactFunc bubble: "));
  EXPECT_THAT(r.err, HasSubstr(" frames (100%) in "));
  EXPECT_EQ(r.err.find('\r'), std::string::npos);
  // The same reconstruction figures as the run with a pose model.
  const nlohmann::json with_pose = eval_->LastJson();
  for (const nlohmann::json& row : j["rows"]) {
    for (const nlohmann::json& other : with_pose["rows"]) {
      if (other["approach"] == row["approach"] && other["sensor"] == row["sensor"] &&
          other["split"] == row["split"] && other["approach"] != "Raw frames") {
        EXPECT_EQ(other["psnr"], row["psnr"]) << row.dump();
      }
    }
  }
}

TEST_F(EvalCliTest, ATestOnlyFunctasetFitsTheBaselinesOnTheDatasetsTrainFrames) {
  // encode --split test holds no train entries; the baselines are fitted on the
  // dataset's train-split frames, the same frames the full functaset's train entries are.
  const Result encode = Run("encode --model " + Root("m.tfm") + " --data " + Root("d") +
                            " --out " + Root("f_test.tfs") + " --split test --threads 1");
  ASSERT_EQ(encode.exit_code, 0) << encode.err;
  const Result r = Run("eval --data " + Root("d") + " --model " + Root("m.tfm") +
                       " --functaset " + Root("f_test.tfs") + " --out " + Root("table_test") +
                       " --threads 1 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err << r.out;
  EXPECT_THAT(r.err, HasSubstr("eval: loading bubble train frames for the baselines: 9/9"));
  const nlohmann::json j = r.LastJson();
  const nlohmann::json full = eval_->LastJson();
  int compared = 0;
  for (const nlohmann::json& row : j["rows"]) {
    EXPECT_EQ(row["split"], "test") << row.dump();  // no train rows without train entries
    for (const nlohmann::json& other : full["rows"]) {
      if (other["split"] != "test" || other["sensor"] != row["sensor"] ||
          other["approach"] != row["approach"] || row["approach"] == "Raw frames") {
        continue;
      }
      // TactFunc: the same test latents; PCA and JPEG: the same train frames (PCA's
      // codes come from a product of another row count: equal to rounding).
      EXPECT_NEAR(other["psnr"].get<double>(), row["psnr"].get<double>(), 1e-6) << row.dump();
      if (row["approach"] != "JPEG") {
        EXPECT_NEAR(other["psnr_clean"].get<double>(), row["psnr_clean"].get<double>(), 1e-6)
            << row.dump();
      }
      ++compared;
    }
  }
  EXPECT_EQ(compared, 6);  // TactFunc, PCA and JPEG on both sensors
  for (const char* sensor : {"bubble", "gelslim"}) {
    EXPECT_NEAR(j["targets"][sensor]["psnr_3db_above_pca_clean"]["pca_db"].get<double>(),
                full["targets"][sensor]["psnr_3db_above_pca_clean"]["pca_db"].get<double>(), 1e-6)
        << sensor;
  }
}

TEST_F(EvalCliTest, TakesTheDataFlagsOfTheOtherCommands) {
  const Result help = Run("eval --help");
  for (const char* flag : {"--sensor ", "--sensors", "--labels", "--pixel-pitch-mm", "--reference"}) {
    EXPECT_THAT(help.out, HasSubstr(flag)) << flag;
  }
  // A --labels file that does not exist is named.
  const Result r = Run("eval --data " + Root("d") + " --model " + Root("m.tfm") + " --functaset " +
                       Root("f.tfs") + " --out " + Root("x") + " --labels " + Root("none.csv"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("none.csv"));
}

TEST_F(EvalCliTest, MissingOrMismatchedFilesFailWithAMessageNamingThem) {
  Result r = Run("eval --data " + Root("d") + " --model " + Root("m.tfm") + " --functaset " +
                 Root("none.tfs") + " --pose-model " + Root("p.tpm") + " --out " + Root("x"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("none.tfs"));
  EXPECT_THAT(r.err, HasSubstr("no such file"));
  // A pose model given as the functaset: the file is named.
  r = Run("eval --data " + Root("d") + " --model " + Root("m.tfm") + " --functaset " +
          Root("p.tpm") + " --pose-model " + Root("p.tpm") + " --out " + Root("x"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("p.tpm"));
  // Unpaired extras are a usage error.
  r = Run(EvalArgs() + " --out " + Root("x") + " --extra-functaset " + Root("f.tfs"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--extra-model"));
}

}  // namespace
}  // namespace tactfunc
