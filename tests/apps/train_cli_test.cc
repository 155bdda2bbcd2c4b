// Copyright 2026 The tactfunc Authors.
//
// `tactfunc train` as a user runs it: a short tiny-preset run on simulated contacts
// writes a model whose trunk carries the inner-loop knobs given on the command line
// (K, the rates' clip bound and start), `encode` uses that model, and bad knobs fail
// before any data is read with a message naming the flag or field.
#include <filesystem>
#include <string>

#include <unistd.h>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "models/functa_model.h"
#include "tests/apps/cli_test_util.h"

namespace tactfunc {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
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

  static fs::path* root_;
};

fs::path* TrainCliTest::root_ = nullptr;

TEST_F(TrainCliTest, TheInnerLoopKnobsReachTheModelAndEncodeUsesIt) {
  const Result train = Run("train --data " + Root("d") + " --out " + Root("m.tfm") +
                           " --preset tiny --steps 4 --inner-steps 2 --alpha-max 2" +
                           " --alpha-init 1.5 --seed 1 --json");
  ASSERT_EQ(train.exit_code, 0) << train.err;
  EXPECT_EQ(train.LastJson()["sensors"]["bubble"]["steps"].get<int>(), 4);

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
