// Copyright 2026 The tactfunc Authors.
//
// A sensor description through the program: the real GelSight ball presses
// (tests/data/taxim_ballpress, MIT, LICENSE beside the frames) with a sensor.json that
// crops a 96 x 128 window out of the 120 x 160 frames and sets a 24 x 32 working size.
// `info` prints the description of the data and of the model trained on it; `train`,
// `encode`, `recon` and `fit` run on the cropped frames; and every model-using command
// refuses data described otherwise (another crop, or no description), naming both sides,
// unless --allow-other-frames is given.
#include <filesystem>
#include <fstream>
#include <string>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "nlohmann/json.hpp"
#include "tests/apps/cli_test_util.h"

namespace tactfunc {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;
using Result = testing_util::CliResult;

std::string Description(int crop_x) {
  return R"({"name": "gelsight_taxim", "kind": "optical", "channels": 3,
             "crop": {"x": )" +
         std::to_string(crop_x) + R"(, "y": 12, "width": 128, "height": 96},
             "working_size": {"rows": 24, "cols": 32}, "aspect": "crop",
             "pixel_pitch_mm": 0.1245, "normalization_scale": 0.5, "markers": false})";
}

class SensorFileCliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = new fs::path(fs::path(::testing::TempDir()) /
                         ("tactfunc_sensor_file_cli_" + std::to_string(::getpid())));
    fs::remove_all(*root_);
    fs::create_directories(*root_);
    const fs::path fixture = fs::path(TACTFUNC_SOURCE_DIR) / "tests/data/taxim_ballpress";
    fs::copy(fixture, *root_ / "d");
    fs::copy(fixture, *root_ / "raw");  // the same frames without a description
    std::ofstream(*root_ / "d" / "sensor.json") << Description(16);
    std::ofstream(*root_ / "other.json") << Description(20);

    info_ = new Result(Run("info " + Root("d") + " --json"));
    train_ = new Result(Run("train --data " + Root("d") + " --out " + Root("m.tfm") +
                            " --preset small --latent-dim 8 --width 16 --layers 2 --steps 20"
                            " --batch 8 --threads 2 --seed 3 --json"));
    model_info_ = new Result(Run("info " + Root("m.tfm") + " --json"));
    encode_ = new Result(Run("encode --data " + Root("d") + " --model " + Root("m.tfm") +
                             " --out " + Root("f.tfs") + " --threads 2 --json"));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*root_);
    delete root_;
    delete info_;
    delete train_;
    delete model_info_;
    delete encode_;
  }
  static std::string Root(const std::string& name) { return (*root_ / name).string(); }
  static Result Run(const std::string& args) { return testing_util::RunTactfunc(*root_, args); }

  static fs::path* root_;
  static Result *info_, *train_, *model_info_, *encode_;
};

fs::path* SensorFileCliTest::root_ = nullptr;
Result* SensorFileCliTest::info_ = nullptr;
Result* SensorFileCliTest::train_ = nullptr;
Result* SensorFileCliTest::model_info_ = nullptr;
Result* SensorFileCliTest::encode_ = nullptr;

TEST_F(SensorFileCliTest, InfoPrintsTheDescriptionOfTheDataAndOfTheModel) {
  ASSERT_EQ(info_->exit_code, 0) << info_->err;
  // The frames after the crop.
  EXPECT_THAT(info_->out, HasSubstr("96x128x3 rgb8"));
  EXPECT_THAT(info_->out, HasSubstr("sensor gelsight_taxim: optical, 3 channels, geometry crop x "
                                    "16 y 12 -> 96x128, working size 24x32 (aspect crop), pitch "
                                    "0.1245 mm, scale 0.5, no markers (" +
                                    Root("d/sensor.json") + ")"));
  const nlohmann::json j = info_->LastJson()["sensors"]["gelslim"];
  EXPECT_EQ(j["sensor_description"]["crop"]["x"], 16) << j.dump();
  EXPECT_EQ(j["sensor_description_file"], Root("d/sensor.json"));

  ASSERT_EQ(train_->exit_code, 0) << train_->err;
  EXPECT_THAT(train_->out, HasSubstr("at 24x32"));
  EXPECT_THAT(train_->err, Not(HasSubstr("stretched")));
  ASSERT_EQ(model_info_->exit_code, 0) << model_info_->err;
  EXPECT_THAT(model_info_->out, HasSubstr("sensor gelsight_taxim: optical, 3 channels, geometry "
                                          "crop x 16 y 12 -> 96x128, working size 24x32"));
  EXPECT_THAT(model_info_->out, Not(HasSubstr("the model records none")));
  const nlohmann::json m = model_info_->LastJson()["model"]["trunks"]["gelslim"];
  EXPECT_EQ(m["sensor_description_recorded"], true) << m.dump();
  EXPECT_EQ(m["rows"], 24);
  EXPECT_EQ(m["cols"], 32);
}

TEST_F(SensorFileCliTest, TheModelEncodesReconstructsAndFitsItsOwnSensorsFrames) {
  ASSERT_EQ(encode_->exit_code, 0) << encode_->err;
  EXPECT_EQ(encode_->LastJson()["frames"], 49) << encode_->out;
  const Result recon = Run("recon --data " + Root("d") + " --model " + Root("m.tfm") +
                           " --functaset " + Root("f.tfs") + " --out " + Root("r") +
                           " --examples 2 --json");
  ASSERT_EQ(recon.exit_code, 0) << recon.err;
  EXPECT_EQ(recon.LastJson()["frames"], 49);
  // fit on the raw camera files: --sensor-file crops both before they are compared.
  const Result fit = Run("fit --model " + Root("m.tfm") + " --frame " + Root("raw/press_01.png") +
                         " --reference " + Root("raw/reference.png") + " --sensor-file " +
                         Root("d/sensor.json") + " --strategy meta_sgd:3 --json");
  ASSERT_EQ(fit.exit_code, 0) << fit.err;
  EXPECT_EQ(fit.LastJson()["sensor"], "gelslim");
}

TEST_F(SensorFileCliTest, DataDescribedOtherwiseIsRefusedNamingBoth) {
  ASSERT_EQ(train_->exit_code, 0) << train_->err;
  ASSERT_EQ(encode_->exit_code, 0) << encode_->err;
  const std::string other = " --sensor-file " + Root("other.json");
  const std::string differs = "geometry: crop x 16 y 12 -> 96x128 vs crop x 20 y 12 -> 96x128";
  auto expect_refused = [&](const Result& r, const std::string& data_side) {
    EXPECT_EQ(r.exit_code, 1) << r.err;
    EXPECT_THAT(r.err, HasSubstr("model '" + Root("m.tfm") + "'"));
    EXPECT_THAT(r.err, HasSubstr(data_side));
    EXPECT_THAT(r.err, HasSubstr("--allow-other-frames"));
  };
  // Another crop, by --sensor-file, through each command.
  Result r = Run("encode --data " + Root("d") + other + " --model " + Root("m.tfm") + " --out " +
                 Root("other.tfs") + " --threads 2");
  expect_refused(r, "--data '" + Root("d") + "' (" + Root("other.json") + ")");
  EXPECT_THAT(r.err, HasSubstr(differs));
  EXPECT_FALSE(fs::exists(Root("other.tfs")));
  r = Run("recon --data " + Root("d") + other + " --model " + Root("m.tfm") + " --functaset " +
          Root("f.tfs") + " --out " + Root("r_other"));
  expect_refused(r, Root("other.json"));
  EXPECT_THAT(r.err, HasSubstr(differs));
  r = Run("eval --data " + Root("d") + other + " --model " + Root("m.tfm") + " --functaset " +
          Root("f.tfs") + " --out " + Root("e_other"));
  expect_refused(r, Root("other.json"));
  EXPECT_THAT(r.err, HasSubstr(differs));
  r = Run("fit --model " + Root("m.tfm") + " --frame " + Root("raw/press_01.png") +
          " --reference " + Root("raw/reference.png") + other);
  expect_refused(r, "--sensor-file '" + Root("other.json") + "'");
  EXPECT_THAT(r.err, HasSubstr(differs));
  // pose on raw files applies --sensor-file as fit does, and checks it against the model.
  r = Run("pose --model " + Root("m.tfm") + " --pose-model " + Root("p.tpm") + " --frame " +
          Root("raw/press_01.png") + " --reference " + Root("raw/reference.png") + other);
  expect_refused(r, "--sensor-file '" + Root("other.json") + "'");
  EXPECT_THAT(r.err, HasSubstr(differs));
  // No description at all: the raw 120 x 160 frames are the built-in GelSlim's.
  r = Run("encode --data " + Root("raw") + " --model " + Root("m.tfm") + " --out " +
          Root("raw.tfs") + " --threads 2");
  expect_refused(r, "--data '" + Root("raw") + "' (built-in gelslim description)");
  EXPECT_THAT(r.err, HasSubstr("geometry: crop x 16 y 12 -> 96x128 vs none"));
  // The escape hatch: a warning, and the command runs.
  r = Run("fit --model " + Root("m.tfm") + " --frame " + Root("raw/press_01.png") +
          " --reference " + Root("raw/reference.png") + other +
          " --strategy meta_sgd:3 --allow-other-frames");
  EXPECT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.err, HasSubstr("fit: warning (--allow-other-frames)"));
}

TEST_F(SensorFileCliTest, ABadDescriptionNamesTheFileAndField) {
  std::ofstream(*root_ / "bad.json")
      << R"({"name": "x", "kind": "optical", "pixel_pitch_mm": -1, "normalization_scale": 0.5})";
  const Result r = Run("info " + Root("raw") + " --sensor-file " + Root("bad.json"));
  EXPECT_EQ(r.exit_code, 1) << r.err;
  EXPECT_THAT(r.err, HasSubstr(Root("bad.json") + ": field 'pixel_pitch_mm': expected "));
}

}  // namespace
}  // namespace tactfunc
