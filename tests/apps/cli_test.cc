// Copyright 2026 The tactfunc Authors.
//
// The tactfunc program as a user runs it: exit codes, --help, --json last lines,
// error messages that name the file, and nothing lost on failure.
#include <sys/wait.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include "estimation/data/dataset.h"
#include "estimation/data/image_io.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "models/trunk/product_precision.h"
#include "tests/apps/cli_test_util.h"
#include "tests/support/dataset_test_util.h"
#include "nlohmann/json.hpp"

namespace tactfunc {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

using Result = testing_util::CliResult;
using testing_util::Slurp;

class CliTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::path(testing::TempDir()) /
           ("tactfunc_cli_" + std::string(testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(dir_);
    fs::create_directories(dir_);
  }
  void TearDown() override { fs::remove_all(dir_); }

  Result Run(const std::string& args) const {
    return testing_util::RunTactfunc(dir_, args);
  }
  std::string Path(const std::string& name) const { return (dir_ / name).string(); }

  fs::path dir_;
};

// One entry of a section ("Options:", "Subcommands:", ...) of CLI11's help text.
struct HelpEntry {
  std::string name;         // "--out TEXT REQUIRED", "synth"
  std::string description;  // empty if the entry has none
};

std::string Trim(const std::string& text) {
  const std::size_t begin = text.find_first_not_of(' ');
  if (begin == std::string::npos) return "";
  return text.substr(begin, text.find_last_not_of(' ') - begin + 1);
}

// The entries under the line `title` of a help text, in order. CLI11 (App::Formatter,
// column width 30) writes an entry as "  <name>" padded to column 30 followed by its
// description, or, for a name reaching column 30, the name alone with the description
// on the next line indented to column 30; further description lines are indented
// likewise. The section ends at a blank line.
std::vector<HelpEntry> HelpSection(const std::string& help, const std::string& title) {
  constexpr std::size_t kColumn = 30;
  std::vector<HelpEntry> entries;
  std::istringstream lines(help);
  std::string line;
  bool inside = false;
  while (std::getline(lines, line)) {
    if (!inside) {
      inside = line == title;
      continue;
    }
    if (Trim(line).empty()) break;
    const bool continuation = line.size() > kColumn &&
                              line.find_first_not_of(' ') == kColumn && !entries.empty();
    if (continuation) {
      entries.back().description += Trim(line);
    } else if (line.size() > kColumn && line[kColumn - 1] == ' ') {
      entries.push_back({Trim(line.substr(0, kColumn)), Trim(line.substr(kColumn))});
    } else {
      entries.push_back({Trim(line), ""});
    }
  }
  return entries;
}

TEST(HelpSection, ReadsCli11sLayout) {
  const std::string help =
      "Usage: tactfunc fit [OPTIONS]\n\nOptions:\n"
      "  -h,--help                   Print this help message and exit\n"
      "  --model TEXT REQUIRED       Model file\n"
      "  --a-very-long-option-name TEXT\n"
      "                              Its description, on the next line,\n"
      "                              and continued\n"
      "  --bare                      \n"
      "\nSubcommands:\n  synth                       Render frames\n";
  const std::vector<HelpEntry> options = HelpSection(help, "Options:");
  ASSERT_EQ(options.size(), 4u);
  EXPECT_EQ(options[1].name, "--model TEXT REQUIRED");
  EXPECT_EQ(options[1].description, "Model file");
  EXPECT_EQ(options[2].name, "--a-very-long-option-name TEXT");
  EXPECT_EQ(options[2].description, "Its description, on the next line,and continued");
  EXPECT_EQ(options[3].name, "--bare");
  EXPECT_EQ(options[3].description, "");
  const std::vector<HelpEntry> subcommands = HelpSection(help, "Subcommands:");
  ASSERT_EQ(subcommands.size(), 1u);
  EXPECT_EQ(subcommands[0].name, "synth");
}

// `tactfunc <command> --help` exits 0 and prints its usage line and its options, each
// with a description; a command with subcommands of its own (bench) lists them, each
// with a description, and each is checked the same way.
void ExpectHelpDescribesEveryOption(const fs::path& dir, const std::string& command) {
  SCOPED_TRACE("tactfunc " + command + " --help");
  const Result help = testing_util::RunTactfunc(dir, command + " --help");
  ASSERT_EQ(help.exit_code, 0) << help.err;
  EXPECT_THAT(help.out, HasSubstr("Usage: tactfunc " + command + " "));
  const std::vector<HelpEntry> subcommands = HelpSection(help.out, "Subcommands:");
  std::vector<HelpEntry> options = HelpSection(help.out, "Options:");
  for (const HelpEntry& positional : HelpSection(help.out, "Positionals:")) {
    options.push_back(positional);
  }
  int own_options = 0;
  for (const HelpEntry& option : options) {
    EXPECT_FALSE(option.description.empty()) << "option '" << option.name << "' has no description";
    if (option.name != "-h,--help") ++own_options;
  }
  if (subcommands.empty()) {
    EXPECT_GT(own_options, 0) << "no options besides --help:\n" << help.out;
  }
  for (const HelpEntry& sub : subcommands) {
    EXPECT_FALSE(sub.description.empty()) << "subcommand '" << sub.name << "' has no description";
    ExpectHelpDescribesEveryOption(dir, command + " " + sub.name);
  }
}

TEST_F(CliTest, EverySubcommandHasHelp) {
  // The subcommands are read from the program's own help, so a new one is covered
  // without touching this test.
  const Result top = Run("--help");
  ASSERT_EQ(top.exit_code, 0) << top.err;
  EXPECT_THAT(top.out, HasSubstr("Usage: tactfunc "));
  const std::vector<HelpEntry> subcommands = HelpSection(top.out, "Subcommands:");
  EXPECT_GE(subcommands.size(), 11u) << top.out;
  for (const HelpEntry& sub : subcommands) {
    EXPECT_FALSE(sub.description.empty()) << sub.name;
    ExpectHelpDescribesEveryOption(dir_, sub.name);
  }
}

// `bench trunk` times both workloads at any size without a model or dataset, and its
// GEMM FLOP counts are the trunk's matrix products: per pixel, with first = 2 w,
// hidden = (L - 1) w^2 and out = w C multiply-adds, a latent gradient costs
// first + 2 hidden + 2 out, a gradient w.r.t. theta too 2 first + 3 hidden + 3 out and a
// Hessian-vector product read from the inner step's tape first + 4 hidden + 4 out
// (models/trunk/latent_modulated_siren.cc).
TEST_F(CliTest, BenchTrunkTimesTheFitAndTheMetaStepAndCountsTheirFlops) {
  const Result r = Run("bench trunk --width 8 --layers 2 --latent 4 --rows 6 --cols 7 --steps 2 "
                       "--batch 3 --pixels 10 --repeats 2 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = r.LastJson();
  EXPECT_EQ(j["bench"], "trunk");
  EXPECT_GT(j["gemm_gflops"].get<double>(), 0.0);
  // first 16, hidden 64, out 8: a gradient w.r.t. z 160, w.r.t. theta 248, an HVP 304.
  const nlohmann::json& fit = j["fit"];
  EXPECT_EQ(fit["pixels"], 42);
  EXPECT_NEAR(fit["core_gemm_gflop"].get<double>(), 2.0 * 2 * 42 * 160 / 1e9, 1e-15);
  // The fit runs its first step from the pass at z = 0 (one d x n product: 4 x 42) and
  // the other K - 1 in full; the whole fit adds one forward pass (88) at z_K (the start's
  // cost comes from the pass).
  EXPECT_NEAR(fit["fit_steps_gemm_gflop"].get<double>(), (2.0 * 42 * 160 + 2.0 * 4 * 42) / 1e9,
              1e-15);
  EXPECT_NEAR(fit["full_gemm_gflop"].get<double>(),
              (2.0 * 42 * 160 + 2.0 * 4 * 42 + 2.0 * 42 * 88) / 1e9, 1e-15);
  EXPECT_GT(fit["start_pass_ms"].get<double>(), 0.0);
  EXPECT_EQ(fit["fit_steps_ms"].size(), 2u);
  EXPECT_EQ(fit["core_ms"].size(), 2u);
  EXPECT_EQ(fit["full_ms"].size(), 2u);
  EXPECT_LE(fit["full_ms_min"].get<double>(), fit["full_ms_median"].get<double>());
  EXPECT_GT(fit["psnr"].get<double>(), 0.0);
  const nlohmann::json& step = j["meta_step"];
  EXPECT_EQ(step["pixels"], 10);
  EXPECT_NEAR(step["gemm_gflop"].get<double>(), 2.0 * 3 * 10 * (2 * 160 + 248 + 2 * 304) / 1e9,
              1e-15);
  EXPECT_EQ(step["ms"].size(), 2u);  // repeats + 1 steps, the first untimed

  const Result bad = Run("bench trunk --workloads fit,train");
  EXPECT_NE(bad.exit_code, 0);
  EXPECT_THAT(bad.err, HasSubstr("--workloads"));
}

// --products bf16 runs the same workloads with bfloat16 products where the CPU has
// AVX512_BF16 (and says so in its output), refuses clearly where it lacks it, and any
// other value is a usage error.
TEST_F(CliTest, BenchTrunkRunsItsProductsInBfloat16OnRequest) {
  const std::string base = "bench trunk --width 32 --layers 2 --latent 8 --rows 12 --cols 14 "
                           "--steps 2 --batch 2 --pixels 20 --repeats 1 --workloads fit --json";
  const Result as_float = Run(base);
  ASSERT_EQ(as_float.exit_code, 0) << as_float.err;
  EXPECT_EQ(as_float.LastJson()["products"], "float");
  const Result bf16 = Run(base + " --products bf16");
  if (ProductPrecisionAvailable(ProductPrecision::kBfloat16)) {
    ASSERT_EQ(bf16.exit_code, 0) << bf16.err;
    EXPECT_THAT(bf16.out, HasSubstr("bf16 products"));
    const nlohmann::json j = bf16.LastJson();
    EXPECT_EQ(j["products"], "bf16");
    // The same frame fitted the same way, within bfloat16's error of float's PSNR.
    EXPECT_NEAR(j["fit"]["psnr"].get<double>(), as_float.LastJson()["fit"]["psnr"].get<double>(),
                0.5);
  } else {
    EXPECT_EQ(bf16.exit_code, 2);
    EXPECT_THAT(bf16.err, HasSubstr("AVX512_BF16"));
  }
  const Result bad = Run(base + " --products half");
  EXPECT_EQ(bad.exit_code, 2);
  EXPECT_THAT(bad.err, HasSubstr("--products"));
}

TEST_F(CliTest, BenchPcaOnADatasetScoresThreeBasesAgainstTheNoiseFreeFrames) {
  ASSERT_EQ(Run("synth --out " + Path("d") + " --frames-per-tool 4 --tools rod,square,lines5 "
                "--clean --seed 3 --test-fraction 0.5").exit_code, 0);
  testing_util::MakeModel().Save(Path("m.tfm"));
  const Result r = Run("bench pca --data " + Path("d") + " --model " + Path("m.tfm") +
                       " --sizes 2,4 --smooth 1 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = r.LastJson();
  EXPECT_EQ(j["bench"], "pca");
  // Two sensors x three bases x two sizes.
  ASSERT_EQ(j["rows"].size(), 12u) << j.dump();
  std::map<std::string, int> per_sensor;
  for (const nlohmann::json& row : j["rows"]) {
    ++per_sensor[row["sensor"].get<std::string>()];
    EXPECT_EQ(row["bytes_per_frame"].get<int>(), 2 * row["components"].get<int>());
    EXPECT_TRUE(std::isfinite(row["psnr_clean"].get<double>())) << row.dump();
    EXPECT_GT(row["psnr_clean"].get<double>(), 0.0) << row.dump();
    EXPECT_GT(row["test_frames"].get<int>(), 0);
  }
  EXPECT_EQ(per_sensor["bubble"], 6);
  EXPECT_EQ(per_sensor["gelslim"], 6);
  EXPECT_THAT(r.out, HasSubstr("noise-free frames (bound)"));
  EXPECT_THAT(r.out, HasSubstr("noisy frames, blurred 1 px"));

  // A dataset without noise-free frames is refused naming it; so is a bad size list.
  ASSERT_EQ(Run("synth --out " + Path("n") + " --frames-per-tool 2 --tools rod").exit_code, 0);
  const Result unclean = Run("bench pca --data " + Path("n") + " --model " + Path("m.tfm"));
  EXPECT_NE(unclean.exit_code, 0);
  EXPECT_THAT(unclean.err, HasSubstr("no noise-free frames"));
  EXPECT_THAT(unclean.err, HasSubstr(Path("n")));
  const Result sizes = Run("bench pca --data " + Path("d") + " --model " + Path("m.tfm") +
                           " --sizes 4,x");
  EXPECT_NE(sizes.exit_code, 0);
  EXPECT_THAT(sizes.err, HasSubstr("--sizes"));
}

TEST_F(CliTest, BenchPhotometricTrainsFitsAndScoresAgainstPcaAtTheSameBits) {
  ASSERT_EQ(Run("synth --out " + Path("d") + " --frames-per-tool 6 --tools rod,square "
                "--sensors gelslim --clean --seed 3 --test-fraction 0.25").exit_code, 0);
  const Result r = Run("bench photometric --data " + Path("d") + " --steps 6 --warmup 3 "
                       "--latent-dim 8 --width 8 --layers 1 --fit-steps 3 --max-test-frames 2 "
                       "--picture " + Path("p.png") + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = r.LastJson();
  EXPECT_EQ(j["bench"], "photometric");
  EXPECT_EQ(j["bytes_per_frame"], 16);
  EXPECT_EQ(j["test_frames"], 2);
  ASSERT_EQ(j["rows"].size(), 3u) << j.dump();
  EXPECT_EQ(j["rows"][1]["representation"], "PCA-8 float16 (same bits)");
  for (const nlohmann::json& row : j["rows"]) {
    EXPECT_TRUE(std::isfinite(row["psnr_clean"].get<double>())) << row.dump();
  }
  EXPECT_NEAR(j["margin_vs_pca_same_bits_clean"].get<double>(),
              j["rows"][2]["psnr_clean"].get<double>() - j["rows"][1]["psnr_clean"].get<double>(),
              1e-9);
  EXPECT_TRUE(std::filesystem::exists(Path("p.png")));
  EXPECT_THAT(r.err, HasSubstr("step 6/6"));

  // A trained model's trunk, fitted with every step size and count asked for: the first
  // setting is the bench's row, all of them the fit trade table and picture.
  ASSERT_EQ(Run("train --data " + Path("d") + " --out " + Path("p.tfm") +
                " --head photometric --steps 4 --marker-warmup 2 --latent-dim 8 --width 8 "
                "--layers 1 --threads 1")
                .exit_code, 0);
  const Result trade = Run("bench photometric --data " + Path("d") + " --model " +
                           Path("p.tfm") + " --latent-dim 8 --fit-steps 2,5 --fit-rate "
                           "1e-2,5e-2 --max-test-frames 2 --trade-picture " + Path("t.png") +
                           " --json");
  ASSERT_EQ(trade.exit_code, 0) << trade.err;
  const nlohmann::json t = trade.LastJson();
  EXPECT_EQ(t["model"], Path("p.tfm"));
  EXPECT_EQ(t["train_frames"], 0);
  EXPECT_TRUE(t["steps"].is_null()) << t.dump();
  ASSERT_EQ(t["fits"].size(), 4u) << t.dump();
  EXPECT_EQ(t["fits"][0]["steps"], 2);
  EXPECT_EQ(t["fits"][0]["learning_rate"], 1e-2);
  EXPECT_EQ(t["fits"][3]["steps"], 5);
  EXPECT_EQ(t["fits"][3]["learning_rate"], 5e-2);
  EXPECT_EQ(t["fits"][0]["psnr_clean"], t["rows"][2]["psnr_clean"]);
  EXPECT_THAT(trade.out, HasSubstr("fit trade"));
  EXPECT_THAT(trade.out, HasSubstr("the trunk of " + Path("p.tfm")));
  EXPECT_TRUE(std::filesystem::exists(Path("t.png")));
  // Another d than the model's, and a probe longer than a fit, are refused by name.
  const Result other_d = Run("bench photometric --data " + Path("d") + " --model " +
                             Path("p.tfm") + " --latent-dim 16 --max-test-frames 1");
  EXPECT_NE(other_d.exit_code, 0);
  EXPECT_THAT(other_d.err, HasSubstr("--latent-dim 16"));
  const Result probe = Run("bench photometric --data " + Path("d") + " --model " +
                           Path("p.tfm") + " --latent-dim 8 --fit-steps 3 --fit-probe 4");
  EXPECT_NE(probe.exit_code, 0);
  EXPECT_THAT(probe.err, HasSubstr("--fit-probe 4"));
  // From the model's warm-start table: 0 steps scores the neighbour as it is, and more
  // steps from it fit the same frames (one start: no turned start kept).
  const Result warm = Run("bench photometric --data " + Path("d") + " --model " +
                          Path("p.tfm") + " --latent-dim 8 --fit-knn 2 --fit-steps 0,3 "
                          "--fit-rate 1e-2 --fit-ceres 2 --max-test-frames 2 --json");
  ASSERT_EQ(warm.exit_code, 0) << warm.err;
  const nlohmann::json w = warm.LastJson();
  ASSERT_EQ(w["fits"].size(), 3u) << w.dump();
  // The Ceres row (encode's knn+ceres:2) fits from the same neighbour as the 0-step row.
  EXPECT_EQ(w["fits"][2]["solver"], "ceres");
  EXPECT_EQ(w["fits"][2]["steps"], 2);
  EXPECT_GT(w["fits"][2]["psnr_clean"].get<double>(), w["fits"][0]["psnr_clean"].get<double>())
      << w.dump();
  EXPECT_EQ(w["fit_knn"], 2);
  EXPECT_EQ(w["fits"][0]["steps"], 0);
  EXPECT_TRUE(std::isfinite(w["fits"][0]["psnr_clean"].get<double>())) << w.dump();
  EXPECT_NE(w["fits"][0]["psnr_clean"], w["fits"][1]["psnr_clean"]);
  EXPECT_EQ(w["fits"][1]["flipped_starts_kept"], 0);
  const Result cold_zero = Run("bench photometric --data " + Path("d") + " --model " +
                               Path("p.tfm") + " --latent-dim 8 --fit-steps 0");
  EXPECT_NE(cold_zero.exit_code, 0);
  EXPECT_THAT(cold_zero.err, HasSubstr("--fit-knn"));
  const Result cold_ceres = Run("bench photometric --data " + Path("d") + " --model " +
                                Path("p.tfm") + " --latent-dim 8 --fit-ceres 2");
  EXPECT_NE(cold_ceres.exit_code, 0);
  EXPECT_THAT(cold_ceres.err, HasSubstr("--fit-knn"));

  // Data without noise-free frames is refused naming it.
  ASSERT_EQ(Run("synth --out " + Path("n") + " --frames-per-tool 2 --tools rod --sensors gelslim")
                .exit_code, 0);
  const Result unclean = Run("bench photometric --data " + Path("n"));
  EXPECT_NE(unclean.exit_code, 0);
  EXPECT_THAT(unclean.err, HasSubstr("no noise-free frames"));
  EXPECT_THAT(unclean.err, HasSubstr(Path("n")));
}

TEST_F(CliTest, SynthWritesThePairedFramesItReports) {
  const Result r = Run("synth --out " + Path("d") +
                       " --frames-per-tool 2 --seed 7 --tools rod,square,l_shape --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = r.LastJson();
  EXPECT_EQ(j["frames"], 6);   // 3 tools x 2 paired frames
  EXPECT_EQ(j["images"], 12);  // x 2 sensors
  EXPECT_EQ(j["contacts"], 6);
  EXPECT_EQ(j["tools"], 3);
  EXPECT_EQ(j["sensors"], nlohmann::json({"bubble", "gelslim"}));
  EXPECT_EQ(j["out"], Path("d"));
  const Dataset dataset = Dataset::Open(Path("d"));
  EXPECT_EQ(dataset.frames().size(), 12u);
  const Result info = Run("info " + Path("d") + " --json");
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_EQ(info.LastJson()["sensors"]["gelslim"]["frames"], 6);
  EXPECT_EQ(info.LastJson()["bytes"], dataset.BytesOnDisk());
}

TEST_F(CliTest, SynthRendersOnlyTheSensorsAskedFor) {
  const Result r = Run("synth --out " + Path("d") +
                       " --frames-per-tool 1 --tools rod --sensors gelslim --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.LastJson()["sensors"], nlohmann::json({"gelslim"}));
  EXPECT_EQ(r.LastJson()["images"], 1);
  EXPECT_EQ(Dataset::Open(Path("d")).sensors(), std::vector<SensorKind>{SensorKind::kGelSlim});
}

TEST_F(CliTest, ShowWritesAPictureOfTheDataset) {
  ASSERT_EQ(Run("synth --out " + Path("d") + " --frames-per-tool 1 --tools rod,lines5").exit_code, 0);
  const Result r = Run("show " + Path("d") + " --out " + Path("sheet.png") + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.LastJson()["contacts"], 2);
  const Image sheet = ReadImage(Path("sheet.png"), PixelEncoding::kRgb8);
  EXPECT_EQ(sheet.rows, r.LastJson()["height"].get<int>());
  EXPECT_GT(sheet.cols, 6 * 100);
}

TEST_F(CliTest, BadInputFailsWithAMessageNamingIt) {
  Result r = Run("info " + Path("missing_dataset"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("missing_dataset"));

  r = Run("synth --out " + Path("d") + " --tools rod,teapot");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("teapot"));
  EXPECT_THAT(r.err, HasSubstr("hemisphere"));  // lists the valid names

  r = Run("synth --out " + Path("d") + " --frames-per-tool 0");
  EXPECT_EQ(r.exit_code, 2);
  r = Run("synth --out " + Path("d") + " --sensors bubble,digit");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("digit"));
  r = Run("frobnicate");
  EXPECT_EQ(r.exit_code, 2);
}

TEST_F(CliTest, SynthRefusesToOverwriteADatasetAndLosesNothing) {
  ASSERT_EQ(Run("synth --out " + Path("d") + " --frames-per-tool 1 --tools rod").exit_code, 0);
  const std::string labels = Slurp(Path("d/labels.csv"));
  const Result r = Run("synth --out " + Path("d") + " --frames-per-tool 3 --tools square");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("overwrite"));
  EXPECT_EQ(Slurp(Path("d/labels.csv")), labels);
  EXPECT_EQ(Dataset::Open(Path("d")).frames().size(), 2u);
  ASSERT_EQ(Run("synth --out " + Path("d") + " --frames-per-tool 3 --tools square --overwrite")
                .exit_code,
            0);
  EXPECT_EQ(Dataset::Open(Path("d")).frames().size(), 6u);
}

TEST_F(CliTest, AUsersOwnFolderOfFramesLoadsLikeADataset) {
  // A flat folder of 8-bit RGB frames with a reference, as a GelSight user has it.
  fs::create_directories(Path("mine"));
  Image reference(24, 32, 3, 0.5f);
  WritePngAtomically(Path("mine/reference.png"), reference, PixelEncoding::kRgb8);
  for (int i = 0; i < 3; ++i) {
    Image frame = reference;
    frame.at(10, 10 + i, 0) = 1.0f;
    WritePngAtomically(Path("mine/frame_" + std::to_string(i) + ".png"), frame,
                       PixelEncoding::kRgb8);
  }
  const Result r = Run("info " + Path("mine") + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.LastJson()["sensors"]["gelslim"]["frames"], 3);
  const Result sheet = Run("show " + Path("mine") + " --out " + Path("mine_sheet.png"));
  EXPECT_EQ(sheet.exit_code, 0) << sheet.err;
  const Result wrong = Run("info " + Path("mine") + " --sensor bubble");
  EXPECT_NE(wrong.exit_code, 0);
  EXPECT_THAT(wrong.err, HasSubstr("mine"));
}

TEST_F(CliTest, ASetOfClipsEncodesAndReconstructsUnderClipQualifiedIds) {
  // Two folder clips with references of their own and, where MJPG can be written here,
  // a video clip whose frame 0 is its reference; clip b is a test clip.
  testing_util::MakeModel().Save(Path("m.tfm"));
  for (const std::string clip : {"a", "b"}) {
    fs::create_directories(Path("set/" + clip));
    const Image reference(24, 32, 3, clip == "a" ? 0.4f : 0.6f);
    WritePngAtomically(Path("set/" + clip + "/reference.png"), reference, PixelEncoding::kRgb8);
    for (int i = 0; i < 2; ++i) {
      Image frame = reference;
      frame.at(10, 10 + i, 0) = 1.0f;
      WritePngAtomically(Path("set/" + clip + "/f" + std::to_string(i) + ".png"), frame,
                         PixelEncoding::kRgb8);
    }
  }
  const bool video = testing_util::WriteMjpgVideo(
      Path("set/c.avi"), {testing_util::PatternFrame(0), testing_util::PatternFrame(1),
                          testing_util::PatternFrame(2)});
  std::ofstream(Path("set/clips.csv")) << "clip,split\nb,test\n";
  const Result info = Run("info " + Path("set") + " --json");
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_EQ(info.LastJson()["clips"], video ? 3 : 2);
  EXPECT_EQ(info.LastJson()["sensors"]["gelslim"]["frames"], video ? 6 : 4);
  EXPECT_EQ(info.LastJson()["sensors"]["gelslim"]["test"], 2);
  EXPECT_THAT(info.out, HasSubstr("clips: " + std::string(video ? "3" : "2")));
  const Result encode = Run("encode --model " + Path("m.tfm") + " --data " + Path("set") +
                            " --out " + Path("f.tfs") + " --threads 2");
  ASSERT_EQ(encode.exit_code, 0) << encode.err;
  const Result recon = Run("recon --model " + Path("m.tfm") + " --functaset " + Path("f.tfs") +
                           " --data " + Path("set") + " --out " + Path("r") + " --threads 1");
  ASSERT_EQ(recon.exit_code, 0) << recon.err;
  const std::string frames = Slurp(Path("r/frames.csv"));
  EXPECT_THAT(frames, HasSubstr("\na/f0,gelslim,train,"));
  EXPECT_THAT(frames, HasSubstr("\nb/f1,gelslim,test,"));
  if (video) {
    EXPECT_THAT(frames, HasSubstr("\nc/000002,gelslim,train,"));
  }
  EXPECT_TRUE(fs::exists(Path("r/recon_gelslim.png")));
}

}  // namespace
}  // namespace tactfunc
