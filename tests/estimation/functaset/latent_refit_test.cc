// Copyright 2026 The tactfunc Authors.
#include "estimation/functaset/latent_refit.h"

#include <filesystem>
#include <stdexcept>
#include <string>

#include "estimation/functaset/latent_encoder.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "models/core/tensor_file.h"
#include "tests/support/functa_test_util.h"
#include "tests/support/test_dir.h"

namespace tactfunc {
namespace {

using ::testing::HasSubstr;
using testing_util::MakeModel;
using testing_util::TestDir;
using testing_util::WriteTinyDataset;

class LatentRefitTest : public ::testing::Test {
 protected:
  LatentRefitTest()
      : model_(MakeModel()),
        dataset_((WriteTinyDataset(dir_ / "data", 40), Dataset::Open(dir_ / "data"))) {
    LatentEncoder::Options encode;
    encode.sensors = {SensorKind::kSoftBubble};
    functaset_ = LatentEncoder(model_, encode).Encode(dataset_, nullptr);
    options_.fit.strategy = FitStrategy::FromString("ceres:3");
    options_.model_checksum = 1234;
    options_.threads = 2;
  }
  const SensorTrunk& trunk() const { return model_.Trunk(SensorKind::kSoftBubble); }
  Functaset Refit(const RefitOptions& options, RefitSummary* summary,
                  const RefitProgress& progress = nullptr) const {
    return RefitLatents(functaset_, SensorKind::kSoftBubble, dataset_, trunk(), options, summary,
                        progress);
  }

  TestDir dir_;
  FunctaModel model_;
  Dataset dataset_;
  Functaset functaset_;
  RefitOptions options_;
};

TEST_F(LatentRefitTest, LabelledEntriesGetTheFittersLatentAndTheRestStayAsTheyWere) {
  RefitSummary summary;
  const Functaset refitted = Refit(options_, &summary);
  const auto& before = functaset_.entries(SensorKind::kSoftBubble);
  const auto& after = refitted.entries(SensorKind::kSoftBubble);
  ASSERT_EQ(after.size(), before.size());
  EXPECT_EQ(summary.entries, 40);
  EXPECT_EQ(summary.done, 40);
  EXPECT_EQ(summary.fitted, 39);  // frame 2 has no label
  EXPECT_FALSE(summary.stopped);
  const LatentFitter fitter(trunk(), options_.fit);
  for (std::size_t i = 0; i < after.size(); ++i) {
    EXPECT_EQ(after[i].id, before[i].id);
    if (!before[i].label.has_value()) {
      EXPECT_EQ(after[i].latent, before[i].latent) << after[i].id;
      continue;
    }
    const TrunkTargets targets = LoadTrunkTargets(
        dataset_, *dataset_.FindFrame(before[i].id, SensorKind::kSoftBubble), trunk().format);
    Eigen::VectorXd latent;
    fitter.Fit(LatentProblem(trunk(), targets, options_.problem), &latent);
    EXPECT_EQ(after[i].latent, latent.cast<float>()) << after[i].id;
  }
  // One thread gives the same latents.
  RefitOptions one = options_;
  one.threads = 1;
  const Functaset serial = Refit(one, nullptr);
  for (std::size_t i = 0; i < after.size(); ++i) {
    EXPECT_EQ(serial.entries(SensorKind::kSoftBubble)[i].latent, after[i].latent);
  }
}

TEST_F(LatentRefitTest, AStoppedRunResumesFromItsCheckpointToTheSameLatents) {
  const Functaset whole = Refit(options_, nullptr);
  RefitOptions options = options_;
  options.checkpoint_path = dir_ / "refit.ckpt";
  RefitSummary first;
  const Functaset partial =
      Refit(options, &first, [](int done, int total) { return done < total / 2; });
  EXPECT_TRUE(first.stopped);
  EXPECT_GE(first.done, 20);
  EXPECT_LT(first.done, 40);
  EXPECT_EQ(partial.entries(SensorKind::kSoftBubble).size(), static_cast<std::size_t>(first.done));
  ASSERT_TRUE(std::filesystem::exists(options.checkpoint_path));

  options.resume = true;
  RefitSummary second;
  int calls = 0;
  const Functaset resumed = Refit(options, &second, [&](int, int) { return ++calls > 0; });
  EXPECT_FALSE(second.stopped);
  EXPECT_EQ(second.resumed, first.done);
  EXPECT_EQ(second.done, 40);
  EXPECT_LT(second.fitted, 39);  // the resumed ones were not fitted again
  const auto& a = resumed.entries(SensorKind::kSoftBubble);
  const auto& b = whole.entries(SensorKind::kSoftBubble);
  ASSERT_EQ(a.size(), b.size());
  for (std::size_t i = 0; i < a.size(); ++i) EXPECT_EQ(a[i].latent, b[i].latent) << a[i].id;

  // The complete run leaves a complete checkpoint: resuming again fits nothing.
  RefitSummary third;
  const Functaset again = Refit(options, &third);
  EXPECT_EQ(third.resumed, 40);
  EXPECT_EQ(third.fitted, 0);
  for (std::size_t i = 0; i < a.size(); ++i) {
    EXPECT_EQ(again.entries(SensorKind::kSoftBubble)[i].latent, b[i].latent);
  }
}

TEST_F(LatentRefitTest, ACheckpointOfAnotherRunIsRefusedNamingWhatDiffers) {
  RefitOptions options = options_;
  options.checkpoint_path = dir_ / "refit.ckpt";
  Refit(options, nullptr, [](int, int) { return false; });
  ASSERT_TRUE(std::filesystem::exists(options.checkpoint_path));
  options.resume = true;

  RefitOptions other_strategy = options;
  other_strategy.fit.strategy = FitStrategy::FromString("ceres:4");
  try {
    Refit(other_strategy, nullptr);
    FAIL() << "expected a refusal";
  } catch (const std::runtime_error& e) {
    EXPECT_THAT(e.what(), HasSubstr("strategy"));
  }
  RefitOptions other_model = options;
  other_model.model_checksum = 99;
  EXPECT_THROW(Refit(other_model, nullptr), std::runtime_error);

  // Other functaset entries: one latent changed.
  Functaset changed(functaset_.model_checksum(), functaset_.dataset());
  changed.AddSensor(SensorKind::kSoftBubble, functaset_.latent_dim(SensorKind::kSoftBubble));
  for (FunctasetEntry e : functaset_.entries(SensorKind::kSoftBubble)) {
    if (e.id == "000005") e.latent[0] += 1.0f;
    changed.Add(SensorKind::kSoftBubble, std::move(e));
  }
  try {
    RefitLatents(changed, SensorKind::kSoftBubble, dataset_, trunk(), options, nullptr);
    FAIL() << "expected a refusal";
  } catch (const std::runtime_error& e) {
    EXPECT_THAT(e.what(), HasSubstr("fingerprint"));
  }
}

TEST_F(LatentRefitTest, BadOptionsAreRefusedByName) {
  auto refused = [&](const RefitOptions& options, const std::string& field) {
    try {
      Refit(options, nullptr);
      ADD_FAILURE() << "expected a refusal naming " << field;
    } catch (const std::invalid_argument& e) {
      EXPECT_THAT(e.what(), HasSubstr(field));
    }
  };
  RefitOptions o = options_;
  o.threads = 0;
  refused(o, "threads");
  o = options_;
  o.checkpoint_every = 0;
  refused(o, "checkpoint_every");
  o = options_;
  o.resume = true;
  refused(o, "resume");
  o = options_;
  o.fit.strategy = FitStrategy::FromString("knn+ceres:2");
  refused(o, "strategy");
  EXPECT_THROW(RefitLatents(functaset_, SensorKind::kGelSlim, dataset_, trunk(), options_, nullptr),
               std::invalid_argument);
}

}  // namespace
}  // namespace tactfunc
