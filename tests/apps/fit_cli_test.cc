// Copyright 2026 The tactfunc Authors.
//
// `tactfunc fit` and `tactfunc bench fit` as a user runs them: a tiny hand-built model
// (tests/support/functa_test_util.h), a tiny dataset, its functaset from `tactfunc
// encode`; exit codes, the --json last line, the files written, the k-NN index kept
// beside the functaset, and bad input that fails with a message naming the file or flag.
#include <sys/wait.h>
#include <unistd.h>

#include <cmath>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <set>
#include <sstream>
#include <string>

#include "estimation/data/image_io.h"
#include "estimation/data/trunk_targets.h"
#include "estimation/evaluation/reconstruction.h"
#include "estimation/knn/knn_index.h"
#include "models/trunk/functa_model.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/apps/cli_test_util.h"
#include "nlohmann/json.hpp"
#include "tests/support/functa_test_util.h"

namespace tactfunc {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;

using Result = testing_util::CliResult;
using testing_util::Slurp;

// One model, dataset and functaset for all tests of the suite (encoding is the slow part).
class FitCliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    Result encode;
    root_ = new fs::path(testing_util::MakeEncodedFixture("tactfunc_fit_cli", &encode));
    ASSERT_EQ(encode.exit_code, 0) << encode.err;
  }
  static void TearDownTestSuite() {
    fs::remove_all(*root_);
    delete root_;
  }
  static std::string Root(const std::string& name) { return (*root_ / name).string(); }

  static Result RunIn(const fs::path& dir, const std::string& args) {
    return testing_util::RunTactfunc(dir, args);
  }
  Result Run(const std::string& args) const { return RunIn(*root_, args); }

  // A fit of bubble test frame 3 against the dataset's reference.
  std::string FitArgs(const std::string& strategy) const {
    return "fit --model " + Root("m.tfm") + " --frame " + Root("d/bubble/000003.png") +
           " --reference " + Root("d/bubble/reference.png") + " --strategy " + strategy;
  }

  static fs::path* root_;
};

fs::path* FitCliTest::root_ = nullptr;

TEST_F(FitCliTest, FitPrintsTheJsonLineAndWritesLatentAndPicture) {
  const std::string out = Root("fit_ceres");
  const Result r = Run(FitArgs("ceres:10") + " --out " + out + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.out, HasSubstr("LatentFitter ceres:10"));  // the Summary's BriefReport
  const nlohmann::json j = r.LastJson();

  // The same frame, model and targets in-process, to judge the figures against.
  const FunctaModel model = FunctaModel::Load(Root("m.tfm"));
  const SensorTrunk& trunk = model.Trunk(SensorKind::kSoftBubble);
  const int d = trunk.siren.latent_dim();
  const TrunkTargets targets =
      MakeTrunkTargets(ReadImage(Root("d/bubble/000003.png"), PixelEncoding::kDepthU16Micrometres),
                       ReadImage(Root("d/bubble/reference.png"), PixelEncoding::kDepthU16Micrometres),
                       SensorKind::kSoftBubble, trunk.format);
  const double psnr_at_zero = Psnr(Reconstruct(trunk, Eigen::VectorXf::Zero(d)), targets);
  ASSERT_TRUE(std::isfinite(psnr_at_zero));

  // Types and values of every field of the --json line.
  ASSERT_TRUE(j["psnr"].is_number()) << j.dump();
  const double psnr = j["psnr"].get<double>();
  EXPECT_TRUE(std::isfinite(psnr));
  EXPECT_GT(psnr, psnr_at_zero + 0.5) << "the fit must improve on the prior mean z = 0";
  ASSERT_TRUE(j["ms"].is_number());
  EXPECT_TRUE(std::isfinite(j["ms"].get<double>()));
  EXPECT_GT(j["ms"].get<double>(), 0.0);
  EXPECT_LT(j["ms"].get<double>(), 60e3);
  EXPECT_EQ(j["strategy"], "ceres:10");  // echoes --strategy
  ASSERT_TRUE(j["termination"].is_string());
  // A Ceres stage ends in one of FitTermination's Ceres outcomes (COMPLETED is for the
  // fixed-step strategies; FAILURE and NO_VALID_PIXELS would be wrong here).
  EXPECT_THAT(j["termination"].get<std::string>(),
              ::testing::AnyOf("CONVERGENCE", "NO_CONVERGENCE"));
  ASSERT_TRUE(j["iterations"].is_number_integer());
  EXPECT_GE(j["iterations"].get<int>(), 1);
  EXPECT_LE(j["iterations"].get<int>(), 10);
  ASSERT_TRUE(j["latent_dim"].is_number_integer());
  EXPECT_EQ(j["latent_dim"].get<int>(), d);
  EXPECT_EQ(j["sensor"], "bubble");  // inferred from the 16-bit frame

  // The files: latent.json holds the latent whose reconstruction has the reported PSNR.
  ASSERT_TRUE(fs::is_regular_file(out + "/fit.png"));
  ASSERT_TRUE(fs::is_regular_file(out + "/latent.json"));
  const nlohmann::json latent = nlohmann::json::parse(Slurp(out + "/latent.json"));
  EXPECT_EQ(latent["sensor"], "bubble");
  EXPECT_EQ(latent["strategy"], "ceres:10");
  EXPECT_EQ(latent["termination"], j["termination"]);
  EXPECT_EQ(latent["iterations"], j["iterations"]);
  EXPECT_EQ(latent["model_checksum"], model.checksum());
  EXPECT_DOUBLE_EQ(latent["psnr"].get<double>(), psnr);
  ASSERT_TRUE(latent["latent"].is_array());
  ASSERT_EQ(latent["latent"].size(), static_cast<std::size_t>(d));
  Eigen::VectorXf z(d);
  for (int k = 0; k < d; ++k) {
    ASSERT_TRUE(latent["latent"][k].is_number()) << k;
    z[k] = latent["latent"][k].get<float>();
    EXPECT_TRUE(std::isfinite(z[k])) << k;
  }
  EXPECT_GT(z.norm(), 0.0f);
  EXPECT_NEAR(Psnr(Reconstruct(trunk, z), targets), psnr, 1e-3);
  const Image picture = ReadImage(out + "/fit.png", PixelEncoding::kRgb8);
  EXPECT_GT(picture.cols, 3 * 100);  // three labelled tiles side by side
}

TEST_F(FitCliTest, GelSlimFramesAreInferredFromTheirEncoding) {
  const Result r =
      Run("fit --model " + Root("m.tfm") + " --frame " + Root("d/gelslim/000003.png") +
          " --reference " + Root("d/gelslim/reference.png") + " --strategy meta_sgd:3 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.LastJson()["sensor"], "gelslim");
  EXPECT_EQ(r.LastJson()["latent_dim"], 6);
  EXPECT_EQ(r.LastJson()["termination"], "COMPLETED");
}

TEST_F(FitCliTest, KnnBuildsTheIndexBesideTheFunctasetOnceAndRebuildsItWhenStale) {
  const std::string index = Root("f.tfs.bubble.knn");
  fs::remove(index);
  Result r = Run(FitArgs("knn+ceres:5") + " --functaset " + Root("f.tfs") + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.LastJson()["strategy"], "knn+ceres:5");
  ASSERT_TRUE(fs::exists(index));
  EXPECT_THAT(r.err, HasSubstr("built the k-NN index"));
  EXPECT_EQ(KnnIndex::Load(index)->size(), 12);  // every bubble latent of the functaset

  // Current: reused, not rebuilt.
  r = Run(FitArgs("knn") + " --functaset " + Root("f.tfs") + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.err, ::testing::Not(HasSubstr("built the k-NN index")));
  EXPECT_EQ(r.LastJson()["termination"], "COMPLETED");

  // Stale (other vectors) and corrupt files are rebuilt.
  BruteForceKnnIndex other(8);
  const std::vector<float> zeros(8 * 3, 0.0f);
  other.Add(zeros.data(), 3);
  other.Save(index);
  r = Run(FitArgs("knn") + " --functaset " + Root("f.tfs"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.err, HasSubstr("built the k-NN index"));
  EXPECT_EQ(KnnIndex::Load(index)->size(), 12);
  std::ofstream(index, std::ios::trunc) << "not an index";
  r = Run(FitArgs("knn") + " --functaset " + Root("f.tfs"));
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_THAT(r.err, HasSubstr("cannot be read"));
  EXPECT_EQ(KnnIndex::Load(index)->size(), 12);
}

TEST_F(FitCliTest, BadInputFailsWithAMessageNamingTheFileOrFlag) {
  Result r = Run("fit --model " + Root("m.tfm") + " --frame " + Root("d/bubble/missing.png") +
                 " --reference " + Root("d/bubble/reference.png"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("missing.png"));

  // A reference of another size than the frame.
  Image small(5, 6, 1, 0.05f);
  WritePngAtomically(Root("small_reference.png"), small, PixelEncoding::kDepthU16Micrometres);
  r = Run("fit --model " + Root("m.tfm") + " --frame " + Root("d/bubble/000003.png") +
          " --reference " + Root("small_reference.png"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("small_reference.png"));
  EXPECT_THAT(r.err, HasSubstr("5x6x1"));

  r = Run(FitArgs("lbfgs:3"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--strategy"));
  EXPECT_THAT(r.err, HasSubstr("lbfgs"));

  r = Run(FitArgs("knn+ceres:5"));
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("--functaset"));

  r = Run("fit --model " + Root("no_model.tfm") + " --frame " + Root("d/bubble/000003.png") +
          " --reference " + Root("d/bubble/reference.png"));
  EXPECT_NE(r.exit_code, 0);
  EXPECT_THAT(r.err, HasSubstr("no_model.tfm"));

  r = Run(FitArgs("ceres:5") + " --sensor digit");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("digit"));
}

TEST_F(FitCliTest, BenchFitRunsOnTinyDataAndReportsEveryStrategy) {
  const Result r =
      Run("bench fit --model " + Root("m.tfm") + " --functaset " + Root("f.tfs") + " --data " +
          Root("d") + " --frames 2 --autodiff-frames 1 --threads 2 --plot " + Root("pareto.png") +
          " --table " + Root("table.md") + " --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = r.LastJson();
  for (const char* key : {"strategies", "converged_psnr", "autodiff_over_analytic", "machine"}) {
    EXPECT_TRUE(j.contains(key)) << key;
  }
  ASSERT_FALSE(j["strategies"].empty());
  std::set<std::string> names;
  for (const nlohmann::json& s : j["strategies"]) {
    for (const char* key : {"name", "sensor", "ms_median", "ms_p90", "psnr_mean"}) {
      EXPECT_TRUE(s.contains(key)) << key;
    }
    names.insert(s["name"].get<std::string>());
  }
  for (const char* name :
       {"meta_sgd:1", "meta_sgd:3", "meta_sgd:10", "ceres:2", "ceres:5", "ceres:10", "ceres:20",
        "knn", "knn+meta_sgd:3", "knn+ceres:2", "knn+ceres:5"}) {
    EXPECT_EQ(names.count(name), 1u) << name;
  }
  EXPECT_TRUE(j["converged_psnr"].contains("bubble"));
  EXPECT_TRUE(j["converged_psnr"].contains("gelslim"));
  EXPECT_GT(j["autodiff_over_analytic"].get<double>(), 0.0);
  // The fixed costs are timed against the steps as the fit runs them: meta_sgd:1's one
  // step from the pass at z = 0 is a matrix-vector product, far below the fit around it
  // (building the problem, the closing pass), whose share is then well above 0 (timed
  // against a full pass instead, it read below 0).
  for (const nlohmann::json& s : j["strategies"]) {
    if (s["name"] != "meta_sgd:1") continue;
    ASSERT_TRUE(s["fixed_cost_share"].is_number()) << s.dump();
    EXPECT_LT(s["steps_ms_median"].get<double>(), s["ms_median"].get<double>());
    EXPECT_GT(s["fixed_cost_share"].get<double>(), 0.5);
  }
  EXPECT_TRUE(fs::exists(Root("pareto.png")));
  EXPECT_THAT(Slurp(Root("table.md")), HasSubstr("| bubble | `knn+ceres:5` |"));
}

TEST_F(FitCliTest, BenchKnnReportsRecallAgainstBruteForce) {
  const Result r = Run("bench knn --synthetic 400 --queries 20 --json");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const nlohmann::json j = r.LastJson();
  ASSERT_FALSE(j["rows"].empty());
  EXPECT_EQ(j["rows"][0]["index"], "brute_force");
  EXPECT_EQ(j["rows"][0]["recall_at_8"], 1.0);
  for (const nlohmann::json& row : j["rows"]) {
    EXPECT_GE(row["recall_at_8"].get<double>(), 0.0);
    EXPECT_LE(row["recall_at_8"].get<double>(), 1.0);
  }
  EXPECT_EQ(j["queries"], 20);
  // target_met says whether some approximate row reaches recall@8 >= 0.95 at >= 10x the
  // brute-force speed; it must agree with the rows printed beside it.
  ASSERT_TRUE(j["target_met"].is_boolean());
  bool some_row_meets_it = false;
  for (const nlohmann::json& row : j["rows"]) {
    ASSERT_TRUE(row["speedup"].is_number());
    some_row_meets_it = some_row_meets_it ||
                        (row["checks"].get<int>() > 0 && row["recall_at_8"].get<double>() >= 0.95 &&
                         row["speedup"].get<double>() >= 10);
  }
  EXPECT_EQ(j["target_met"].get<bool>(), some_row_meets_it);
}

}  // namespace
}  // namespace tactfunc
