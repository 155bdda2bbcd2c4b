// Copyright 2026 The tactfunc Authors.
//
// `tactfunc export` as a user runs it on a tiny hand-built model and dataset
// (tests/apps/cli_test_util.h): the .npy files' headers, their values against
// LoadTrunkTargets frame by frame, the noise-free and reference arrays, a functaset's
// reconstructions against Reconstruct, export.json, and bad input that fails naming the
// flag with nothing written.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "estimation/data/dataset.h"
#include "estimation/data/preprocess.h"
#include "estimation/data/trunk_targets.h"
#include "estimation/evaluation/reconstruction.h"
#include "estimation/functaset/functaset.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "models/trunk/functa_model.h"
#include "nlohmann/json.hpp"
#include "tests/apps/cli_test_util.h"
#include "tests/support/test_dir.h"

namespace tactfunc {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using Result = testing_util::CliResult;

// A .npy file as read back: the header's fields and the float32 values.
struct Npy {
  std::string error;  // "" if the file parsed
  std::string magic;
  int major = -1, minor = -1;
  std::size_t header_bytes = 0;  // preamble + header text
  std::string descr;
  std::string fortran_order;
  std::vector<std::int64_t> shape;
  std::vector<float> values;
};

// The value of 'key' in the header dict text: what follows "'key': " up to the next
// ", '" or ", }" (a shape's inner ", " is inside its parentheses).
std::string DictField(const std::string& dict, const std::string& key) {
  const std::string start = "'" + key + "': ";
  const std::size_t at = dict.find(start);
  if (at == std::string::npos) return "";
  const std::size_t from = at + start.size();
  if (dict[from] == '(') return dict.substr(from, dict.find(')', from) - from + 1);
  return dict.substr(from, dict.find(',', from) - from);
}

Npy ReadNpy(const std::string& path) {
  Npy npy;
  const std::string bytes = testing_util::Slurp(path);
  if (bytes.size() < 10) {
    npy.error = path + ": " + std::to_string(bytes.size()) + " bytes";
    return npy;
  }
  npy.magic = bytes.substr(0, 6);
  npy.major = static_cast<unsigned char>(bytes[6]);
  npy.minor = static_cast<unsigned char>(bytes[7]);
  const std::size_t text = static_cast<unsigned char>(bytes[8]) |
                           (static_cast<std::size_t>(static_cast<unsigned char>(bytes[9])) << 8);
  npy.header_bytes = 10 + text;
  if (bytes.size() < npy.header_bytes) {
    npy.error = path + ": header of " + std::to_string(text) + " bytes past the end";
    return npy;
  }
  const std::string dict = bytes.substr(10, text);
  if (dict.empty() || dict.back() != '\n') npy.error = path + ": header does not end in '\\n'";
  npy.descr = DictField(dict, "descr");
  npy.fortran_order = DictField(dict, "fortran_order");
  std::string shape = DictField(dict, "shape");
  std::size_t expected = 1;
  if (shape.size() >= 2) {
    std::string inner = shape.substr(1, shape.size() - 2);
    std::size_t at = 0;
    while (at < inner.size()) {
      const std::size_t comma = inner.find(',', at);
      const std::string item = inner.substr(at, comma == std::string::npos ? comma : comma - at);
      if (item.find_first_not_of(' ') != std::string::npos) {
        npy.shape.push_back(std::stoll(item));
        expected *= static_cast<std::size_t>(npy.shape.back());
      }
      if (comma == std::string::npos) break;
      at = comma + 1;
    }
  }
  if (bytes.size() - npy.header_bytes != expected * 4) {
    npy.error = path + ": " + std::to_string(bytes.size() - npy.header_bytes) +
                " bytes of data for " + std::to_string(expected) + " float32 values";
    return npy;
  }
  npy.values.resize(expected);
  for (std::size_t i = 0; i < expected; ++i) {
    std::uint32_t bits = 0;
    for (int b = 0; b < 4; ++b) {
      bits |= static_cast<std::uint32_t>(
                  static_cast<unsigned char>(bytes[npy.header_bytes + 4 * i + b]))
              << (8 * b);
    }
    std::memcpy(&npy.values[i], &bits, 4);
  }
  return npy;
}

class ExportCliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = new fs::path(fs::path(::testing::TempDir()) /
                         ("tactfunc_export_cli_" + std::to_string(::getpid())));
    fs::remove_all(*root_);
    fs::create_directories(*root_);
    testing_util::MakeModel().Save(Root("m.tfm"));
    testing_util::WriteTinyDataset(Root("d"), 12, /*clean=*/true);
    testing_util::WriteTinyDataset(Root("plain"), 8, /*clean=*/false);
    export_ = new Result(Run(Args("d", "ex") + " --clean --json"));
  }
  static void TearDownTestSuite() {
    fs::remove_all(*root_);
    delete root_;
    delete export_;
  }
  static std::string Root(const std::string& name) { return (*root_ / name).string(); }
  static Result Run(const std::string& args) { return testing_util::RunTactfunc(*root_, args); }
  static std::string Args(const std::string& data, const std::string& out) {
    return "export --data " + Root(data) + " --model " + Root("m.tfm") + " --out " + Root(out);
  }
  static nlohmann::json Description(const std::string& out) {
    return nlohmann::json::parse(testing_util::Slurp(Root(out + "/export.json")));
  }

  static fs::path* root_;
  static Result* export_;
};

fs::path* ExportCliTest::root_ = nullptr;
Result* ExportCliTest::export_ = nullptr;

TEST_F(ExportCliTest, WritesNpyFilesWithNumpyHeadersAlignedTo64Bytes) {
  ASSERT_EQ(export_->exit_code, 0) << export_->err << export_->out;
  const FunctaModel model = FunctaModel::Load(Root("m.tfm"));
  const Dataset dataset = Dataset::Open(Root("d"));
  for (SensorKind sensor : {SensorKind::kSoftBubble, SensorKind::kGelSlim}) {
    const std::string name = ToString(sensor);
    const FrameFormat& format = model.Trunk(sensor).format;
    const std::int64_t n = static_cast<std::int64_t>(dataset.FrameIndices(sensor).size());
    const std::int64_t c = 1;  // bubble depth; gelslim grayscale
    const std::vector<std::pair<std::string, std::vector<std::int64_t>>> files = {
        {name + "_all.npy", {n, format.rows, format.cols, c}},
        {name + "_all_weights.npy", {n, format.rows, format.cols}},
        {name + "_all_clean.npy", {n, format.rows, format.cols, c}},
        {name + "_reference.npy", {format.rows, format.cols, c}}};
    for (const auto& [file, shape] : files) {
      const Npy npy = ReadNpy(Root("ex/" + file));
      ASSERT_EQ(npy.error, "") << file;
      EXPECT_EQ(npy.magic, "\x93NUMPY") << file;
      EXPECT_EQ(npy.major, 1) << file;
      EXPECT_EQ(npy.minor, 0) << file;
      EXPECT_EQ(npy.header_bytes % 64, 0u) << file;
      EXPECT_EQ(npy.descr, "'<f4'") << file;
      EXPECT_EQ(npy.fortran_order, "False") << file;
      EXPECT_EQ(npy.shape, shape) << file;
    }
  }
  EXPECT_TRUE(fs::exists(Root("ex/export.json")));
  const nlohmann::json j = export_->LastJson();
  EXPECT_EQ(j["files"].size(), 9u) << j.dump();
  EXPECT_EQ(j["sensors"]["bubble"]["frames"], 12);
  // Progress lines on stderr (not a terminal), the last one at 100 %.
  EXPECT_THAT(export_->err, HasSubstr("export: 24/24 frames (100%)"));
}

TEST_F(ExportCliTest, EveryFrameEqualsLoadTrunkTargetsExactly) {
  ASSERT_EQ(export_->exit_code, 0) << export_->err;
  const FunctaModel model = FunctaModel::Load(Root("m.tfm"));
  const Dataset dataset = Dataset::Open(Root("d"));
  const nlohmann::json description = Description("ex");
  for (SensorKind sensor : {SensorKind::kSoftBubble, SensorKind::kGelSlim}) {
    const std::string name = ToString(sensor);
    const FrameFormat& format = model.Trunk(sensor).format;
    const Npy values = ReadNpy(Root("ex/" + name + "_all.npy"));
    const Npy weights = ReadNpy(Root("ex/" + name + "_all_weights.npy"));
    ASSERT_EQ(values.error, "");
    ASSERT_EQ(weights.error, "");
    const std::vector<std::size_t> indices = dataset.FrameIndices(sensor);
    const nlohmann::json& frames = description["sensors"][name]["frames"];
    ASSERT_EQ(frames.size(), indices.size());
    const std::size_t pixels = static_cast<std::size_t>(format.rows) * format.cols;
    for (std::size_t k = 0; k < indices.size(); ++k) {
      const TrunkTargets t = LoadTrunkTargets(dataset, indices[k], format, /*clean=*/false);
      ASSERT_EQ(t.values.rows(), static_cast<Eigen::Index>(pixels));
      ASSERT_EQ(t.values.cols(), 1);
      for (std::size_t j = 0; j < pixels; ++j) {
        // Pixel j = row * cols + col: the file's (k, row, col, 0).
        ASSERT_EQ(values.values[k * pixels + j], t.values(static_cast<Eigen::Index>(j), 0))
            << name << " frame " << k << " pixel " << j;
        ASSERT_EQ(weights.values[k * pixels + j], t.weights[static_cast<Eigen::Index>(j)])
            << name << " frame " << k << " pixel " << j;
      }
      const nlohmann::json& f = frames[k];
      const FrameRecord& record = dataset.frames()[indices[k]];
      EXPECT_EQ(f["index"], indices[k]);
      EXPECT_EQ(f["id"], record.id);
      EXPECT_EQ(f["split"], ToString(record.split));
      EXPECT_EQ(f["scale"].get<double>(), t.scale);
      EXPECT_EQ(f["offset"].get<double>(), t.offset);
      if (record.label) {
        EXPECT_EQ(f["label"]["tool"], record.label->tool);
        EXPECT_EQ(f["label"]["x_m"].get<double>(), record.label->sensor_T_object.x());
        EXPECT_EQ(f["label"]["yaw_rad"].get<double>(), record.label->sensor_T_object.yaw());
        EXPECT_EQ(f["label"]["depth_m"].get<double>(), record.label->depth_m);
      } else {
        EXPECT_TRUE(f["label"].is_null()) << f.dump();
      }
    }
    const nlohmann::json& s = description["sensors"][name];
    EXPECT_EQ(s["rows"], format.rows);
    EXPECT_EQ(s["cols"], format.cols);
    EXPECT_EQ(s["channels"], 1);
    EXPECT_EQ(s["scale"].get<double>(), format.scale);
    EXPECT_EQ(s["normalization"], "fixed_scale");
    EXPECT_EQ(s["files"]["values"], name + "_all.npy");
  }
  EXPECT_EQ(description["inputs"]["split"], "all");
  EXPECT_EQ(description["inputs"]["clean"], true);
}

TEST_F(ExportCliTest, CleanFileHoldsTheNoiseFreeTargetsAndDiffersFromTheNoisyOnes) {
  ASSERT_EQ(export_->exit_code, 0) << export_->err;
  const FunctaModel model = FunctaModel::Load(Root("m.tfm"));
  const Dataset dataset = Dataset::Open(Root("d"));
  for (SensorKind sensor : {SensorKind::kSoftBubble, SensorKind::kGelSlim}) {
    const std::string name = ToString(sensor);
    const FrameFormat& format = model.Trunk(sensor).format;
    const Npy noisy = ReadNpy(Root("ex/" + name + "_all.npy"));
    const Npy clean = ReadNpy(Root("ex/" + name + "_all_clean.npy"));
    ASSERT_EQ(clean.error, "");
    ASSERT_EQ(clean.values.size(), noisy.values.size());
    EXPECT_NE(clean.values, noisy.values) << name;
    const std::vector<std::size_t> indices = dataset.FrameIndices(sensor);
    const std::size_t pixels = static_cast<std::size_t>(format.rows) * format.cols;
    const std::size_t k = 5;
    const TrunkTargets t = LoadTrunkTargets(dataset, indices[k], format, /*clean=*/true);
    for (std::size_t j = 0; j < pixels; ++j) {
      ASSERT_EQ(clean.values[k * pixels + j], t.values(static_cast<Eigen::Index>(j), 0))
          << name << " pixel " << j;
    }
  }
}

TEST_F(ExportCliTest, ReferenceIsTheReferenceItselfInTheTargetsUnits) {
  ASSERT_EQ(export_->exit_code, 0) << export_->err;
  const FunctaModel model = FunctaModel::Load(Root("m.tfm"));
  const Dataset dataset = Dataset::Open(Root("d"));
  for (SensorKind sensor : {SensorKind::kSoftBubble, SensorKind::kGelSlim}) {
    const FrameFormat& format = model.Trunk(sensor).format;
    const Npy reference = ReadNpy(Root("ex/" + std::string(ToString(sensor)) + "_reference.npy"));
    ASSERT_EQ(reference.error, "");
    const PreprocessedFrame expected =
        PreprocessImage(dataset.Reference(sensor), ToPreprocessOptions(format), format.scale);
    EXPECT_EQ(reference.values, expected.values.data);
    // The tiny dataset's references are flat: bubble 0.05 m of depth over a 0.01 m
    // scale; gelslim 0.4 grey in every channel (luma 0.4) over 0.5.
    const float flat = sensor == SensorKind::kSoftBubble ? 5.0f : 0.8f;
    for (float v : reference.values) ASSERT_NEAR(v, flat, 1e-5) << ToString(sensor);
  }
}

TEST_F(ExportCliTest, SplitAndSensorsSelectTheFramesAndNameTheFiles) {
  const Result r = Run(Args("d", "test_only") + " --split test --sensors bubble");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(testing_util::ListDir(Root("test_only")),
            (std::vector<std::string>{"bubble_reference.npy", "bubble_test.npy",
                                      "bubble_test_weights.npy", "export.json"}));
  const Npy values = ReadNpy(Root("test_only/bubble_test.npy"));
  ASSERT_EQ(values.error, "");
  ASSERT_FALSE(values.shape.empty());
  EXPECT_EQ(values.shape[0], 3);  // frames 3, 7 and 11 are the test split
  const nlohmann::json description = Description("test_only");
  EXPECT_FALSE(description["sensors"].contains("gelslim"));
  for (const nlohmann::json& f : description["sensors"]["bubble"]["frames"]) {
    EXPECT_EQ(f["split"], "test");
  }
}

TEST_F(ExportCliTest, UnknownSensorFailsNamingTheFlagAndWritesNothing) {
  const Result r = Run(Args("d", "bad_sensor") + " --sensors bubble,fingertip");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("--sensors"));
  EXPECT_THAT(r.err, HasSubstr("'fingertip'"));
  EXPECT_THAT(r.err, HasSubstr("expected bubble or gelslim"));
  EXPECT_FALSE(fs::exists(Root("bad_sensor")));
}

TEST_F(ExportCliTest, CleanOnADatasetWithoutNoiseFreeFramesFailsNamingTheFlag) {
  const Result r = Run(Args("plain", "no_clean") + " --clean");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("--clean"));
  EXPECT_THAT(r.err, HasSubstr("no noise-free frames"));
  EXPECT_FALSE(fs::exists(Root("no_clean")));
  // Without --clean the same dataset exports.
  const Result ok = Run(Args("plain", "no_clean"));
  EXPECT_EQ(ok.exit_code, 0) << ok.err;
}

TEST_F(ExportCliTest, ExistingFilesAreReplacedOnlyWithOverwrite) {
  const Result first = Run(Args("d", "again") + " --sensors gelslim");
  ASSERT_EQ(first.exit_code, 0) << first.err;
  const std::string before = testing_util::Slurp(Root("again/gelslim_all.npy"));
  const Result refused = Run(Args("d", "again") + " --sensors gelslim");
  EXPECT_NE(refused.exit_code, 0);
  EXPECT_THAT(refused.err, HasSubstr("gelslim_all.npy"));
  EXPECT_THAT(refused.err, HasSubstr("--overwrite"));
  EXPECT_EQ(testing_util::Slurp(Root("again/gelslim_all.npy")), before);
  const Result replaced = Run(Args("d", "again") + " --sensors gelslim --overwrite");
  EXPECT_EQ(replaced.exit_code, 0) << replaced.err;
  EXPECT_EQ(testing_util::Slurp(Root("again/gelslim_all.npy")), before);  // same inputs
  EXPECT_TRUE(fs::exists(Root("again/export.json")));
}

TEST_F(ExportCliTest, BadSplitFailsNamingTheFlag) {
  const Result r = Run(Args("d", "bad_split") + " --split validation");
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("--split: expected train, test or all, got 'validation'"));
  EXPECT_FALSE(fs::exists(Root("bad_split")));
}

TEST_F(ExportCliTest, FunctasetReconstructionsAreEachFrameDrawnFromItsStoredLatent) {
  // Latents in allocated codes: the file must hold what the stored codes draw.
  const Result encode = Run("encode --data " + Root("d") + " --model " + Root("m.tfm") +
                            " --out " + Root("f.tfs") + " --latent-bytes 6");
  ASSERT_EQ(encode.exit_code, 0) << encode.err;
  const Result r = Run(Args("d", "with_recon") + " --split test --functaset " + Root("f.tfs"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const FunctaModel model = FunctaModel::Load(Root("m.tfm"));
  const Functaset functaset = Functaset::Load(Root("f.tfs"));
  const Dataset dataset = Dataset::Open(Root("d"));
  const nlohmann::json description = Description("with_recon");
  EXPECT_EQ(description["inputs"]["functaset"], Root("f.tfs"));
  for (SensorKind sensor : {SensorKind::kSoftBubble, SensorKind::kGelSlim}) {
    const std::string name = ToString(sensor);
    EXPECT_EQ(description["sensors"][name]["files"]["recon"], name + "_test_recon.npy");
    const Npy recon = ReadNpy(Root("with_recon/" + name + "_test_recon.npy"));
    ASSERT_EQ(recon.error, "") << name;
    const FrameFormat& format = model.Trunk(sensor).format;
    ASSERT_EQ(recon.shape, (std::vector<std::int64_t>{3, format.rows, format.cols, 1}));
    const std::vector<std::size_t> indices = dataset.FrameIndices(sensor, Split::kTest);
    const std::size_t pixels = static_cast<std::size_t>(format.rows) * format.cols;
    double largest = 0;
    for (std::size_t k = 0; k < indices.size(); ++k) {
      const std::optional<std::size_t> entry =
          functaset.Find(sensor, dataset.frames()[indices[k]].id);
      ASSERT_TRUE(entry.has_value());
      const Eigen::MatrixXf expected =
          Reconstruct(model.Trunk(sensor), functaset.entries(sensor)[*entry].latent);
      for (std::size_t j = 0; j < pixels; ++j) {
        ASSERT_EQ(recon.values[k * pixels + j], expected(static_cast<Eigen::Index>(j), 0))
            << name << " frame " << k << " pixel " << j;
        largest = std::max<double>(largest, std::abs(expected(static_cast<Eigen::Index>(j), 0)));
      }
    }
    EXPECT_GT(largest, 0.0) << name << ": every reconstruction is zero";
  }
}

TEST_F(ExportCliTest, FunctasetWithoutAFramesLatentFailsNamingTheFrameAndWritesNothing) {
  const Result encode = Run("encode --data " + Root("d") + " --model " + Root("m.tfm") +
                            " --out " + Root("bubble_only.tfs") + " --sensors bubble");
  ASSERT_EQ(encode.exit_code, 0) << encode.err;
  const Result r = Run(Args("d", "missing") + " --functaset " + Root("bubble_only.tfs"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("--functaset"));
  EXPECT_THAT(r.err, HasSubstr("no gelslim latent for frame"));
  EXPECT_FALSE(fs::exists(Root("missing")));
  // The sensor it holds exports.
  const Result ok =
      Run(Args("d", "missing") + " --sensors bubble --functaset " + Root("bubble_only.tfs"));
  EXPECT_EQ(ok.exit_code, 0) << ok.err;
  EXPECT_TRUE(fs::exists(Root("missing/bubble_all_recon.npy")));
}

}  // namespace
}  // namespace tactfunc
