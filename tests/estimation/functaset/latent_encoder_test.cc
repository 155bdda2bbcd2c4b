// Copyright 2026 The tactfunc Authors.
#include <Eigen/Eigenvalues>

#include "estimation/functaset/latent_encoder.h"

#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <memory>
#include <iterator>
#include <limits>
#include <random>
#include <string>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "estimation/training/photometric_warm_start.h"
#include "models/trunk/meta_sgd.h"
#include "tests/support/functa_test_util.h"
#include "tests/support/photometric_test_util.h"
#include "tests/support/test_dir.h"

namespace tactfunc {
namespace {

using ::testing::HasSubstr;
using testing_util::FrameId;
using testing_util::kBubbleCols;
using testing_util::kBubbleRows;
using testing_util::kBubbleScale;
using testing_util::kReferenceDepth;
using testing_util::MakeModel;
using testing_util::MakeTrunk;
using testing_util::TestDir;
using testing_util::WriteTinyDataset;

constexpr int kFrames = 12;

// A latent of norm ~`scale`, deterministic in `seed`.
Eigen::VectorXf RandomLatent(int d, double scale, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> normal(0.0f, static_cast<float>(scale / std::sqrt(d)));
  Eigen::VectorXf z(d);
  for (int k = 0; k < d; ++k) z[k] = normal(rng);
  return z;
}

// The step size that makes plain gradient descent on the latent converge: 1 / the
// largest eigenvalue of the Gauss-Newton Hessian 2 J^T J / N at z = 0 (exact for the
// linearised model; the test keeps z small so that it is close).
double SafeRate(const LatentModulatedSiren& siren, const Eigen::MatrixXf& grid) {
  Eigen::MatrixXf J;
  siren.ForwardAndLatentJacobian<float>(grid, Eigen::VectorXf::Zero(siren.latent_dim()), nullptr,
                                        &J);
  const Eigen::MatrixXd H = 2.0 * (J.transpose() * J).cast<double>() / J.rows();
  return 1.0 / Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd>(H).eigenvalues().maxCoeff();
}

// A bubble-only model whose trunk fits its own outputs well: many inner steps at the
// safe rate.
FunctaModel SelfFittingModel(int inner_steps) {
  SensorTrunk trunk = MakeTrunk(SensorKind::kSoftBubble, kBubbleRows, kBubbleCols, kBubbleScale,
                                false, 24, 2, 8, 0.0, inner_steps, 11);
  const Eigen::MatrixXf grid = trunk.siren.Grid<float>(kBubbleRows, kBubbleCols);
  trunk.alpha.setConstant(SafeRate(trunk.siren, grid));
  FunctaModel model;
  model.SetTrunk(std::move(trunk));
  return model;
}

TrunkTargets TargetsFrom(const Eigen::MatrixXf& values) {
  TrunkTargets t;
  t.values = values;
  t.weights = Eigen::VectorXf::Ones(values.rows());
  t.rows = kBubbleRows;
  t.cols = kBubbleCols;
  return t;
}

void ExpectSameFunctaset(const Functaset& a, const Functaset& b) {
  ASSERT_EQ(a.sensors(), b.sensors());
  EXPECT_EQ(a.complete(), b.complete());
  EXPECT_EQ(a.model_checksum(), b.model_checksum());
  for (SensorKind sensor : a.sensors()) {
    ASSERT_EQ(a.entries(sensor).size(), b.entries(sensor).size());
    for (std::size_t i = 0; i < a.entries(sensor).size(); ++i) {
      const FunctasetEntry& x = a.entries(sensor)[i];
      const FunctasetEntry& y = b.entries(sensor)[i];
      EXPECT_EQ(x.id, y.id);
      EXPECT_EQ(x.split, y.split);
      EXPECT_EQ(x.label.has_value(), y.label.has_value());
      // Bit-identical, not merely close: encoding is deterministic.
      EXPECT_TRUE((x.latent.array() == y.latent.array()).all()) << ToString(sensor) << " " << x.id;
      EXPECT_EQ(x.psnr, y.psnr) << x.id;
    }
  }
}

TEST(LatentEncoder, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(LatentEncoder::Options().IsValid(&error)) << error;
}

TEST(LatentEncoder, BadOptionsNameTheField) {
  std::string error;
  LatentEncoder::Options options;
  options.threads = 0;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("threads"));
  options = LatentEncoder::Options();
  options.checkpoint_every = -1;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("checkpoint_every"));
  options = LatentEncoder::Options();
  options.resume = true;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("resume"));
  options = LatentEncoder::Options();
  options.latent_precision = Functaset::LatentPrecision::kAllocated;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("latent_bytes"));
  options = LatentEncoder::Options();
  options.sensors = {SensorKind::kGelSlim, SensorKind::kGelSlim};
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("sensors"));
  const FunctaModel model = MakeModel();
  EXPECT_THROW(LatentEncoder(model, options), std::invalid_argument);
}

TEST(LatentEncoder, TerminationTypesHaveNames) {
  EXPECT_STREQ(ToString(EncodeTermination::kComplete), "complete");
  EXPECT_STREQ(ToString(EncodeTermination::kInterrupted), "interrupted");
}

TEST(LatentEncoder, EncodingAFrameTheModelGeneratedRecoversIt) {
  const FunctaModel model = SelfFittingModel(/*inner_steps=*/300);
  const SensorTrunk& trunk = model.Trunk(SensorKind::kSoftBubble);
  const Eigen::MatrixXf grid = trunk.siren.Grid<float>(kBubbleRows, kBubbleCols);
  const LatentEncoder encoder(model, LatentEncoder::Options());
  for (std::uint64_t seed : {1, 2, 3}) {
    const Eigen::VectorXf z_true = RandomLatent(8, 0.5, seed);
    const TrunkTargets targets = TargetsFrom(trunk.siren.Forward<float>(grid, z_true));
    const LatentEncoder::EncodedFrame fit = encoder.EncodeTargets(SensorKind::kSoftBubble, targets);
    // The starting point z = 0 is far from the frame; the fit is close to it.
    const double psnr_zero =
        Psnr(trunk.siren.Forward<float>(grid, Eigen::VectorXf::Zero(8)), targets);
    EXPECT_GT(fit.psnr, 45.0) << "seed " << seed << ", z = 0 gives " << psnr_zero << " dB";
    EXPECT_GT(fit.psnr, psnr_zero + 15.0);
    // The reported PSNR is the PSNR of the returned latent.
    EXPECT_DOUBLE_EQ(fit.psnr, Psnr(trunk.siren.Forward<float>(grid, fit.latent), targets));
  }
}

// Encodes a frame the Soft Bubble trunk of `model` generates and checks that the default
// encoding is exactly the meta-SGD fit training runs (MetaSgd::FitLatent).
void ExpectEncodingIsTheTrainingFit(const FunctaModel& model) {
  const SensorTrunk& trunk = model.Trunk(SensorKind::kSoftBubble);
  const Eigen::MatrixXf grid = trunk.siren.Grid<float>(kBubbleRows, kBubbleCols);
  const TrunkTargets targets =
      TargetsFrom(trunk.siren.Forward<float>(grid, RandomLatent(8, 1.0, 4)));
  const Eigen::VectorXf expected =
      MetaSgd(trunk.meta_sgd)
          .FitLatent<float>(trunk.siren, grid, targets.values, targets.weights,
                            trunk.alpha.cast<float>());
  const LatentEncoder encoder(model, LatentEncoder::Options());
  EXPECT_TRUE(
      (encoder.EncodeTargets(SensorKind::kSoftBubble, targets).latent.array() == expected.array())
          .all());
}

TEST(LatentEncoder, EncodeTargetsRunsExactlyTheMetaSgdInnerLoop) {
  ExpectEncodingIsTheTrainingFit(MakeModel(/*inner_steps=*/3, /*alpha=*/0.7));
}

// With the readout branch the inner loop starts from the branch's projection of the
// frame (LatentModulatedSiren::StartLatent), in encoding as in training (MetaSgd::FitLatent).
TEST(LatentEncoder, MetaSgdStartsFromTheReadoutProjectionAsInTraining) {
  FunctaModel model = MakeModel(/*inner_steps=*/2, /*alpha=*/0.3);
  SensorTrunk& trunk = model.MutableTrunk(SensorKind::kSoftBubble);
  LatentModulatedSiren::Options options = trunk.siren.options();
  options.readout_rows = 5;
  options.readout_cols = 6;
  trunk.siren = LatentModulatedSiren(options, 11);
  Eigen::VectorXd theta = trunk.siren.parameters();
  for (ParameterGroup group : {ParameterGroup::kReadoutBasis, ParameterGroup::kReadoutMean}) {
    const ParameterBlock& block = trunk.siren.Block(group);
    theta.segment(block.offset, block.size()) = 0.3 * RandomLatent(block.size(), 1.0, 9).cast<double>();
  }
  trunk.siren.SetParameters(theta);
  const Eigen::MatrixXf grid = trunk.siren.Grid<float>(kBubbleRows, kBubbleCols);
  const TrunkTargets targets =
      TargetsFrom(trunk.siren.Forward<float>(grid, RandomLatent(8, 1.0, 4)));
  // A start other than zero, or the check below shows nothing.
  ASSERT_GT(trunk.siren.StartLatent<float>(grid, targets.values, targets.weights).norm(), 0.0f);
  ExpectEncodingIsTheTrainingFit(model);
}

TEST(LatentEncoder, StrategiesAreValidatedByName) {
  std::string error;
  LatentEncoder::Options options;
  options.strategy = "lbfgs:3";
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("strategy"));
  options.strategy = "knn+meta_sgd:5";
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("k-NN"));
  options.strategy = "knn+ceres:5";  // a photometric trunk's; a direct trunk refuses it
  EXPECT_TRUE(options.IsValid(&error)) << error;
  options.strategy = "ceres:5";
  options.problem.sigma_z = 0;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("sigma_z"));
  options.problem.sigma_z = 1;
  EXPECT_TRUE(options.IsValid(&error)) << error;
}

TEST(LatentEncoder, APhotometricTrunksDefaultStepsGrowWithItsLatent) {
  // 140 Adam steps per 64 latent values from the warm-start table, never fewer than
  // 140; without a table the cold fit's 200.
  EXPECT_EQ(LatentEncoder::DefaultPhotometricStrategy(true, 64), "knn+adam:140");
  EXPECT_EQ(LatentEncoder::DefaultPhotometricStrategy(true, 128), "knn+adam:280");
  EXPECT_EQ(LatentEncoder::DefaultPhotometricStrategy(true, 96), "knn+adam:210");
  EXPECT_EQ(LatentEncoder::DefaultPhotometricStrategy(true, 16), "knn+adam:140");
  EXPECT_EQ(LatentEncoder::DefaultPhotometricStrategy(false, 128), "adam:200");
}

TEST(LatentEncoder, CeresStrategyIsTheLatentFittersFitAndBeatsTheInnerLoop) {
  const FunctaModel model = MakeModel(/*inner_steps=*/3, /*alpha=*/0.7);
  const SensorTrunk& trunk = model.Trunk(SensorKind::kSoftBubble);
  const Eigen::MatrixXf grid = trunk.siren.Grid<float>(kBubbleRows, kBubbleCols);
  const TrunkTargets targets =
      TargetsFrom(trunk.siren.Forward<float>(grid, RandomLatent(8, 1.0, 4)));
  LatentEncoder::Options options;
  options.strategy = "ceres:30";
  const LatentEncoder::EncodedFrame ceres =
      LatentEncoder(model, options).EncodeTargets(SensorKind::kSoftBubble, targets);
  const LatentEncoder::EncodedFrame inner =
      LatentEncoder(model, LatentEncoder::Options()).EncodeTargets(SensorKind::kSoftBubble, targets);
  LatentFitter::Options fit;
  fit.strategy = FitStrategy::FromString("ceres:30");
  Eigen::VectorXd expected;
  const double psnr = LatentFitter(trunk, fit).Fit(LatentProblem(trunk, targets, {}), &expected).psnr;
  EXPECT_TRUE((ceres.latent.array() == expected.cast<float>().array()).all());
  EXPECT_EQ(ceres.psnr, psnr);
  EXPECT_GT(ceres.psnr, inner.psnr + 3.0) << "3 meta-SGD steps: " << inner.psnr << " dB";
  // meta_sgd:K with the trunk's own K is the default, bit for bit.
  options.strategy = "meta_sgd:3";
  const LatentEncoder::EncodedFrame explicit_inner =
      LatentEncoder(model, options).EncodeTargets(SensorKind::kSoftBubble, targets);
  EXPECT_TRUE((explicit_inner.latent.array() == inner.latent.array()).all());
}

TEST(LatentEncoder, TheFunctasetRecordsTheStrategyAndResumeInsistsOnIt) {
  TestDir dir;
  WriteTinyDataset(dir / "data", kFrames);
  const Dataset dataset = Dataset::Open(dir / "data");
  const FunctaModel model = MakeModel(/*inner_steps=*/3);
  LatentEncoder::Options options;
  options.checkpoint_path = dir / "set.tfs";
  const Functaset by_default = LatentEncoder(model, options).Encode(dataset, nullptr);
  for (SensorKind sensor : by_default.sensors()) {
    EXPECT_EQ(by_default.fit_strategy(sensor), "meta_sgd:3");
    EXPECT_EQ(Functaset::Load(dir / "set.tfs").fit_strategy(sensor), "meta_sgd:3");
  }
  options.resume = true;
  options.strategy = "ceres:2";
  try {
    LatentEncoder(model, options).Encode(dataset, nullptr);
    FAIL() << "resumed a meta_sgd:3 checkpoint with ceres:2";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("'meta_sgd:3'"));
    EXPECT_THAT(e.what(), HasSubstr("'ceres:2'"));
  }
  options.resume = false;
  options.checkpoint_path = dir / "ceres.tfs";
  const Functaset by_ceres = LatentEncoder(model, options).Encode(dataset, nullptr);
  for (SensorKind sensor : by_ceres.sensors()) {
    EXPECT_EQ(Functaset::Load(dir / "ceres.tfs").fit_strategy(sensor), "ceres:2");
  }
}

// share_rest_latent: frames at rest take the fit of a frame with no change, frames in
// contact are fitted as without it, and a resume must make the same choice.
TEST(LatentEncoder, FramesAtRestShareTheFitOfNoChangeAndResumeInsistsOnTheChoice) {
  TestDir dir;
  WriteTinyDataset(dir / "data", kFrames);
  std::ofstream(std::string(dir / "data") + "/tools.csv") << "tool,symmetry_order\nedge,4\n";
  const Dataset dataset = Dataset::Open(dir / "data");
  const FunctaModel model = MakeModel(/*inner_steps=*/3);
  LatentEncoder::Options options;
  const Functaset plain = LatentEncoder(model, options).Encode(dataset, nullptr);
  options.share_rest_latent = true;
  // Every simulated frame is a press: none is at rest at the default threshold ...
  const Functaset shared = LatentEncoder(model, options).Encode(dataset, nullptr);
  for (SensorKind sensor : plain.sensors()) {
    ASSERT_NE(shared.rest_latent(sensor), nullptr);
    EXPECT_EQ(shared.NumStoredLatents(sensor),
              static_cast<std::int64_t>(plain.entries(sensor).size()));
    for (std::size_t i = 0; i < plain.entries(sensor).size(); ++i) {
      EXPECT_EQ(shared.entries(sensor)[i].latent, plain.entries(sensor)[i].latent);
    }
  }
  // The functaset carries the dataset's declared tool symmetries.
  EXPECT_EQ(shared.tool_symmetries(), (std::map<std::string, int>{{"edge", 4}}));
  // ... and every frame is at rest at an unreachable one: each carries the rest latent,
  // the fit of all-zero targets.
  options.contact.threshold = 1e12;
  options.checkpoint_path = dir / "rest.tfs";
  const Functaset resting = LatentEncoder(model, options).Encode(dataset, nullptr);
  for (SensorKind sensor : resting.sensors()) {
    const SensorTrunk& trunk = model.Trunk(sensor);
    TrunkTargets zero;
    zero.rows = trunk.format.rows;
    zero.cols = trunk.format.cols;
    zero.values = Eigen::MatrixXf::Zero(zero.rows * zero.cols, trunk.siren.output_channels());
    zero.weights = Eigen::VectorXf::Ones(zero.rows * zero.cols);
    const Eigen::VectorXf expected =
        LatentEncoder(model, LatentEncoder::Options()).EncodeTargets(sensor, zero).latent;
    EXPECT_EQ(*resting.rest_latent(sensor), expected);
    EXPECT_EQ(resting.NumStoredLatents(sensor), 0);
    for (const FunctasetEntry& e : resting.entries(sensor)) {
      EXPECT_TRUE(e.at_rest);
      EXPECT_EQ(e.latent, expected);
    }
  }
  options.resume = true;
  options.share_rest_latent = false;
  try {
    LatentEncoder(model, options).Encode(dataset, nullptr);
    FAIL() << "resumed a shared-rest checkpoint without sharing";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("rest latent"));
  }
}

TEST(LatentEncoder, FramesTheModelGeneratedAreRecoveredThroughTheDataset) {
  // Frames written as depth PNGs: reference - scale * f(grid; z_i), at the trunk's
  // working resolution, so only the 1 um depth quantisation separates them from the
  // model's own output.
  TestDir dir;
  const FunctaModel model = SelfFittingModel(/*inner_steps=*/300);
  const SensorTrunk& trunk = model.Trunk(SensorKind::kSoftBubble);
  const Eigen::MatrixXf grid = trunk.siren.Grid<float>(kBubbleRows, kBubbleCols);
  {
    DatasetWriter writer(dir / "data", DatasetWriter::Options());
    writer.AddSensor(testing_util::BubbleInfo(),
                     Image(kBubbleRows, kBubbleCols, 1, static_cast<float>(kReferenceDepth)));
    for (int i = 0; i < 4; ++i) {
      const Eigen::MatrixXf y = trunk.siren.Forward<float>(grid, RandomLatent(8, 0.5, 20 + i));
      Image frame(kBubbleRows, kBubbleCols, 1);
      for (int j = 0; j < kBubbleRows * kBubbleCols; ++j) {
        frame.data[j] = static_cast<float>(kReferenceDepth - kBubbleScale * y(j, 0));
      }
      writer.AddFrame(FrameId(i), SensorKind::kSoftBubble, frame, nullptr, std::nullopt,
                      Split::kTrain);
    }
    writer.Finish();
  }
  const Dataset dataset = Dataset::Open(dir / "data");
  LatentEncoder::Summary summary;
  const Functaset functaset =
      LatentEncoder(model, LatentEncoder::Options()).Encode(dataset, &summary);
  ASSERT_EQ(functaset.entries(SensorKind::kSoftBubble).size(), 4u);
  for (const FunctasetEntry& e : functaset.entries(SensorKind::kSoftBubble)) {
    EXPECT_GT(e.psnr, 40.0) << e.id;
  }
  EXPECT_EQ(summary.termination, EncodeTermination::kComplete);
  EXPECT_GT(summary.mean_psnr.at(SensorKind::kSoftBubble), 40.0);
}

TEST(LatentEncoder, EncodesEveryFrameOfEverySensorInDatasetOrder) {
  TestDir dir;
  WriteTinyDataset(dir / "data", kFrames);
  const Dataset dataset = Dataset::Open(dir / "data");
  const FunctaModel model = MakeModel();
  LatentEncoder::Summary summary;
  const Functaset f = LatentEncoder(model, LatentEncoder::Options()).Encode(dataset, &summary);
  EXPECT_TRUE(f.complete());
  EXPECT_EQ(f.model_checksum(), model.checksum());
  EXPECT_EQ(f.dataset(), dataset.root());
  EXPECT_EQ(summary.frames_total, 2 * kFrames);
  EXPECT_EQ(summary.frames_encoded, 2 * kFrames);
  EXPECT_EQ(summary.frames_resumed, 0);
  EXPECT_EQ(summary.non_finite_latents, 0);
  EXPECT_GT(summary.frames_per_second, 0.0);
  for (SensorKind sensor : {SensorKind::kSoftBubble, SensorKind::kGelSlim}) {
    const std::vector<std::size_t> indices = dataset.FrameIndices(sensor);
    ASSERT_EQ(f.entries(sensor).size(), indices.size());
    EXPECT_EQ(f.latent_dim(sensor), model.Trunk(sensor).siren.latent_dim());
    for (std::size_t i = 0; i < indices.size(); ++i) {
      const FrameRecord& record = dataset.frames()[indices[i]];
      const FunctasetEntry& e = f.entries(sensor)[i];
      EXPECT_EQ(e.id, record.id);
      EXPECT_EQ(e.split, record.split);
      EXPECT_EQ(e.label.has_value(), record.label.has_value());
      EXPECT_TRUE(e.latent.allFinite());
      // The stored PSNR is that of the frame's targets under its latent.
      const TrunkTargets targets =
          LoadTrunkTargets(dataset, indices[i], model.Trunk(sensor).format);
      const Eigen::MatrixXf grid =
          model.Trunk(sensor).siren.Grid<float>(targets.rows, targets.cols);
      EXPECT_FLOAT_EQ(e.psnr,
                      Psnr(model.Trunk(sensor).siren.Forward<float>(grid, e.latent), targets));
    }
  }
  EXPECT_THAT(summary.BriefReport(), HasSubstr("complete"));
  EXPECT_THAT(summary.FullReport(), HasSubstr("bubble"));
}

TEST(LatentEncoder, SelectsSensorsAndSplit) {
  TestDir dir;
  WriteTinyDataset(dir / "data", kFrames);
  const Dataset dataset = Dataset::Open(dir / "data");
  const FunctaModel model = MakeModel();
  LatentEncoder::Options options;
  options.sensors = {SensorKind::kGelSlim};
  options.split = Split::kTest;
  const Functaset f = LatentEncoder(model, options).Encode(dataset, nullptr);
  EXPECT_EQ(f.sensors(), std::vector<SensorKind>{SensorKind::kGelSlim});
  EXPECT_EQ(f.entries(SensorKind::kGelSlim).size(),
            dataset.FrameIndices(SensorKind::kGelSlim, Split::kTest).size());
  for (const FunctasetEntry& e : f.entries(SensorKind::kGelSlim)) EXPECT_EQ(e.split, Split::kTest);
}

TEST(LatentEncoder, ASensorWithoutATrunkIsRejectedByName) {
  TestDir dir;
  WriteTinyDataset(dir / "data", 2);
  const Dataset dataset = Dataset::Open(dir / "data");
  FunctaModel model;
  model.SetTrunk(MakeModel().Trunk(SensorKind::kSoftBubble));
  LatentEncoder::Options options;
  options.sensors = {SensorKind::kGelSlim};
  try {
    LatentEncoder(model, options).Encode(dataset, nullptr);
    ADD_FAILURE() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("gelslim"));
  }
  // Without a selection only the sensors the model has are encoded.
  const Functaset f = LatentEncoder(model, LatentEncoder::Options()).Encode(dataset, nullptr);
  EXPECT_EQ(f.sensors(), std::vector<SensorKind>{SensorKind::kSoftBubble});
}

TEST(LatentEncoder, FramesWithTheWrongChannelCountAreRejected) {
  TestDir dir;
  WriteTinyDataset(dir / "data", 2);
  const Dataset dataset = Dataset::Open(dir / "data");
  FunctaModel model = MakeModel();
  model.MutableTrunk(SensorKind::kGelSlim).format.grayscale = false;  // 3 channels vs 1 output
  try {
    LatentEncoder(model, LatentEncoder::Options()).Encode(dataset, nullptr);
    ADD_FAILURE() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("gelslim trunk outputs 1 channel"));
  }
  const LatentEncoder encoder(model, LatentEncoder::Options());
  EXPECT_THROW(encoder.EncodeTargets(SensorKind::kSoftBubble, TargetsFrom(Eigen::MatrixXf(5, 1))),
               std::invalid_argument);
}

TEST(LatentEncoder, OutputIsDeterministicAndIndependentOfTheThreadCount) {
  TestDir dir;
  WriteTinyDataset(dir / "data", kFrames);
  const Dataset dataset = Dataset::Open(dir / "data");
  const FunctaModel model = MakeModel();
  LatentEncoder::Options options;
  const Functaset one = LatentEncoder(model, options).Encode(dataset, nullptr);
  ExpectSameFunctaset(one, LatentEncoder(model, options).Encode(dataset, nullptr));
  for (int threads : {2, 3, 7}) {
    SCOPED_TRACE(threads);
    options.threads = threads;
    ExpectSameFunctaset(one, LatentEncoder(model, options).Encode(dataset, nullptr));
  }
}

TEST(LatentEncoder, CheckpointFileHoldsTheFinalFunctaset) {
  TestDir dir;
  WriteTinyDataset(dir / "data", kFrames);
  const Dataset dataset = Dataset::Open(dir / "data");
  const FunctaModel model = MakeModel();
  LatentEncoder::Options options;
  options.threads = 2;
  options.checkpoint_path = dir / "set.tfs";
  options.checkpoint_every = 2;
  LatentEncoder::Summary summary;
  const Functaset f = LatentEncoder(model, options).Encode(dataset, &summary);
  EXPECT_GE(summary.checkpoints_written, 1);
  const Functaset saved = Functaset::Load(dir / "set.tfs");
  EXPECT_TRUE(saved.complete());
  ExpectSameFunctaset(f, saved);
}

TEST(LatentEncoder, ResumingAPartialFileGivesTheUninterruptedFunctaset) {
  TestDir dir;
  WriteTinyDataset(dir / "data", kFrames);
  const Dataset dataset = Dataset::Open(dir / "data");
  const FunctaModel model = MakeModel();
  const Functaset full = LatentEncoder(model, LatentEncoder::Options()).Encode(dataset, nullptr);

  // A checkpoint holding every third frame, as an interrupted run might leave.
  Functaset partial(full.model_checksum(), full.dataset());
  partial.set_complete(false);
  int kept = 0;
  for (SensorKind sensor : full.sensors()) {
    partial.AddSensor(sensor, full.latent_dim(sensor));
    for (std::size_t i = 0; i < full.entries(sensor).size(); i += 3, ++kept) {
      partial.Add(sensor, full.entries(sensor)[i]);
    }
  }
  partial.Save(dir / "set.tfs");

  LatentEncoder::Options options;
  options.threads = 2;
  options.checkpoint_path = dir / "set.tfs";
  options.resume = true;
  LatentEncoder::Summary summary;
  const Functaset resumed = LatentEncoder(model, options).Encode(dataset, &summary);
  EXPECT_EQ(summary.frames_resumed, kept);
  EXPECT_EQ(summary.frames_encoded, 2 * kFrames - kept);
  ExpectSameFunctaset(full, resumed);
  ExpectSameFunctaset(full, Functaset::Load(dir / "set.tfs"));
}

TEST(LatentEncoder, InterruptedRunWritesAPartialFileThatResumesToTheFullFunctaset) {
  TestDir dir;
  WriteTinyDataset(dir / "data", kFrames);
  const Dataset dataset = Dataset::Open(dir / "data");
  const FunctaModel model = MakeModel();
  const Functaset full = LatentEncoder(model, LatentEncoder::Options()).Encode(dataset, nullptr);

  LatentEncoder::Options options;
  options.checkpoint_path = dir / "set.tfs";
  // Interrupted before the first frame: nothing encoded, an empty partial file.
  std::atomic<bool> interrupt{true};
  LatentEncoder::Summary summary;
  const Functaset none =
      LatentEncoder(model, options).Encode(dataset, &summary, nullptr, &interrupt);
  EXPECT_EQ(summary.termination, EncodeTermination::kInterrupted);
  EXPECT_THAT(summary.message, HasSubstr("interrupted after 0 of 24 frames"));
  EXPECT_FALSE(none.complete());
  EXPECT_EQ(none.size(), 0u);
  EXPECT_FALSE(Functaset::Load(dir / "set.tfs").complete());

  // Interrupted by the first progress report: however many frames were done by then
  // (that depends on timing), resuming completes the same functaset.
  interrupt = false;
  options.threads = 2;
  options.resume = true;
  LatentEncoder(model, options)
      .Encode(
          dataset, &summary, [&](const EncodeProgress&) { interrupt = true; }, &interrupt);
  const Functaset checkpoint = Functaset::Load(dir / "set.tfs");
  EXPECT_EQ(checkpoint.complete(), summary.termination == EncodeTermination::kComplete);
  interrupt = false;
  const Functaset resumed =
      LatentEncoder(model, options).Encode(dataset, &summary, nullptr, &interrupt);
  EXPECT_EQ(summary.termination, EncodeTermination::kComplete);
  EXPECT_EQ(summary.frames_resumed, static_cast<std::int64_t>(checkpoint.size()));
  ExpectSameFunctaset(full, resumed);
}

TEST(LatentEncoder, CodeRunsCheckpointFloatLatentsAndResumeToTheUninterruptedFile) {
  for (const Functaset::LatentPrecision precision :
       {Functaset::LatentPrecision::kUint6, Functaset::LatentPrecision::kAllocated}) {
    SCOPED_TRACE(ToString(precision));
    TestDir dir;
    WriteTinyDataset(dir / "data", kFrames);
    const Dataset dataset = Dataset::Open(dir / "data");
    const FunctaModel model = MakeModel();
    LatentEncoder::Options options;
    options.latent_precision = precision;
    options.latent_bytes = 3;
    options.checkpoint_path = dir / "full.tfs";
    LatentEncoder(model, options).Encode(dataset, nullptr);
    EXPECT_EQ(Functaset::Load(dir / "full.tfs").latent_precision(), precision);

    // A run interrupted before its first frame leaves a partial file of float32 latents
    // (the codes' grid spans all of a sensor's entries, so only a complete file has codes).
    options.checkpoint_path = dir / "set.tfs";
    std::atomic<bool> interrupt{true};
    LatentEncoder::Summary summary;
    LatentEncoder(model, options).Encode(dataset, &summary, nullptr, &interrupt);
    EXPECT_EQ(summary.termination, EncodeTermination::kInterrupted);
    EXPECT_FALSE(Functaset::Load(dir / "set.tfs").complete());
    EXPECT_EQ(Functaset::Load(dir / "set.tfs").latent_precision(),
              Functaset::LatentPrecision::kFloat32);
    // A partial file holding every third frame's float32 latent, as an interrupted run
    // leaves one (built here so that the test does not depend on thread timing): resuming
    // it writes the uninterrupted run's bytes.
    LatentEncoder::Options float_options;
    float_options.checkpoint_path = dir / "float.tfs";
    const Functaset full = LatentEncoder(model, float_options).Encode(dataset, nullptr);
    Functaset partial(full.model_checksum(), full.dataset());
    partial.set_complete(false);
    for (SensorKind sensor : full.sensors()) {
      partial.AddSensor(sensor, full.latent_dim(sensor));
      partial.set_fit_strategy(sensor, full.fit_strategy(sensor));
      for (std::size_t i = 0; i < full.entries(sensor).size(); i += 3) {
        partial.Add(sensor, full.entries(sensor)[i]);
      }
    }
    partial.Save(dir / "set.tfs");
    interrupt = false;
    options.resume = true;
    LatentEncoder(model, options).Encode(dataset, &summary, nullptr, &interrupt);
    EXPECT_EQ(summary.termination, EncodeTermination::kComplete);
    EXPECT_EQ(summary.frames_resumed, static_cast<std::int64_t>(partial.size()));
    auto bytes = [](const std::string& path) {
      std::ifstream in(path, std::ios::binary);
      return std::string(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
    };
    EXPECT_EQ(bytes(dir / "set.tfs"), bytes(dir / "full.tfs"));
  }
}

TEST(LatentEncoder, AllocatedCodesBeyondSixteenBitsPerValueAreRefusedBeforeEncoding) {
  TestDir dir;
  WriteTinyDataset(dir / "data", kFrames);
  const Dataset dataset = Dataset::Open(dir / "data");
  const FunctaModel model = MakeModel();
  LatentEncoder::Options options;
  options.latent_precision = Functaset::LatentPrecision::kAllocated;
  options.latent_bytes = 1000;
  options.checkpoint_path = dir / "set.tfs";
  try {
    LatentEncoder(model, options).Encode(dataset, nullptr);
    ADD_FAILURE() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("16 bits per value"));
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "set.tfs"));
}

TEST(LatentEncoder, ResumeRefusesACheckpointOfAnotherModel) {
  TestDir dir;
  WriteTinyDataset(dir / "data", 2);
  const Dataset dataset = Dataset::Open(dir / "data");
  const FunctaModel model = MakeModel();  // checksum 0 (never saved)
  Functaset other(12345, "elsewhere");
  other.set_complete(false);
  other.Save(dir / "set.tfs");
  LatentEncoder::Options options;
  options.checkpoint_path = dir / "set.tfs";
  options.resume = true;
  EXPECT_THROW(LatentEncoder(model, options).Encode(dataset, nullptr), FunctasetModelMismatch);
}

TEST(LatentEncoder, ResumeRefusesACheckpointHoldingFramesOutsideTheSelection) {
  // Resuming with a narrower selection would silently drop finished frames.
  TestDir dir;
  WriteTinyDataset(dir / "data", 4);
  const Dataset dataset = Dataset::Open(dir / "data");
  const FunctaModel model = MakeModel();
  LatentEncoder::Options options;
  options.checkpoint_path = dir / "set.tfs";
  LatentEncoder(model, options).Encode(dataset, nullptr);
  options.resume = true;
  options.sensors = {SensorKind::kSoftBubble};
  try {
    LatentEncoder(model, options).Encode(dataset, nullptr);
    ADD_FAILURE() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("4 frame(s) that are not among the frames selected"));
    EXPECT_THAT(e.what(), HasSubstr("(gelslim)"));
  }
  EXPECT_EQ(Functaset::Load(dir / "set.tfs").size(), 8u);  // untouched
}

TEST(LatentEncoder, AFrameThatFailsToLoadIsReportedAfterCheckpointing) {
  TestDir dir;
  WriteTinyDataset(dir / "data", 4);
  std::filesystem::resize_file(dir / "data/gelslim/000003.png", 20);  // truncated PNG
  const Dataset dataset = Dataset::Open(dir / "data");
  LatentEncoder::Options options;
  options.checkpoint_path = dir / "set.tfs";
  const FunctaModel model = MakeModel();
  try {
    LatentEncoder(model, options).Encode(dataset, nullptr);
    ADD_FAILURE() << "expected DatasetError";
  } catch (const DatasetError& e) {
    EXPECT_THAT(e.what(), HasSubstr("000003"));
  }
  const Functaset partial = Functaset::Load(dir / "set.tfs");
  EXPECT_FALSE(partial.complete());
  EXPECT_GE(partial.entries(SensorKind::kSoftBubble).size(), 4u);  // bubble frames come first
}

// ---- Extremes --------------------------------------------------------------------------

TEST(LatentEncoder, BlankFrameEncodesToAFiniteLatentAndFinitePsnr) {
  const FunctaModel model = MakeModel();
  const LatentEncoder encoder(model, LatentEncoder::Options());
  const TrunkTargets blank = TargetsFrom(Eigen::MatrixXf::Zero(kBubbleRows * kBubbleCols, 1));
  const LatentEncoder::EncodedFrame fit = encoder.EncodeTargets(SensorKind::kSoftBubble, blank);
  EXPECT_TRUE(fit.latent.allFinite());
  EXPECT_TRUE(std::isfinite(fit.psnr));  // a blank target's range counts as 1
}

TEST(LatentEncoder, MaskedPixelsAreIgnoredWhateverTheyHold) {
  const FunctaModel model = MakeModel();
  const LatentEncoder encoder(model, LatentEncoder::Options());
  TrunkTargets targets = TargetsFrom(Eigen::MatrixXf::Constant(kBubbleRows * kBubbleCols, 1, 0.3f));
  for (int j = 0; j < targets.values.rows(); j += 3) targets.weights[j] = 0.0f;
  const LatentEncoder::EncodedFrame reference =
      encoder.EncodeTargets(SensorKind::kSoftBubble, targets);
  for (int j = 0; j < targets.values.rows(); j += 3) {
    targets.values(j, 0) = std::numeric_limits<float>::quiet_NaN();
  }
  const LatentEncoder::EncodedFrame fit = encoder.EncodeTargets(SensorKind::kSoftBubble, targets);
  EXPECT_TRUE(fit.latent.allFinite());
  EXPECT_TRUE((fit.latent.array() == reference.latent.array()).all());
  EXPECT_EQ(fit.psnr, reference.psnr);
}

TEST(LatentEncoder, FrameWithoutValidPixelsGivesAZeroLatentAndNanPsnr) {
  const FunctaModel model = MakeModel();
  const LatentEncoder encoder(model, LatentEncoder::Options());
  TrunkTargets targets = TargetsFrom(Eigen::MatrixXf::Zero(kBubbleRows * kBubbleCols, 1));
  targets.weights.setZero();
  const LatentEncoder::EncodedFrame fit = encoder.EncodeTargets(SensorKind::kSoftBubble, targets);
  EXPECT_TRUE(fit.latent.isZero());
  EXPECT_TRUE(std::isnan(fit.psnr));
}

TEST(LatentEncoder, DatasetExtremesEncodeWithoutNan) {
  // Blank, saturated and partly-invalid frames read from disk, through the whole path.
  TestDir dir;
  {
    DatasetWriter writer(dir / "data", DatasetWriter::Options());
    const float ref = static_cast<float>(kReferenceDepth);
    writer.AddSensor(testing_util::BubbleInfo(), Image(kBubbleRows, kBubbleCols, 1, ref));
    writer.AddSensor(testing_util::GelInfo(),
                     Image(testing_util::kGelRows, testing_util::kGelCols, 3, 0.4f));
    Image holes = testing_util::BubbleFrame(1);
    for (int c = 0; c < kBubbleCols; ++c) holes.at(3, c) = std::numeric_limits<float>::quiet_NaN();
    Image none(kBubbleRows, kBubbleCols, 1, std::numeric_limits<float>::quiet_NaN());
    writer.AddFrame("blank", SensorKind::kSoftBubble, Image(kBubbleRows, kBubbleCols, 1, ref),
                    nullptr, std::nullopt, Split::kTrain);
    writer.AddFrame("deep", SensorKind::kSoftBubble, Image(kBubbleRows, kBubbleCols, 1, 0.001f),
                    nullptr, std::nullopt, Split::kTrain);  // 49 mm in: 4.9 x the scale
    writer.AddFrame("holes", SensorKind::kSoftBubble, holes, nullptr, std::nullopt, Split::kTrain);
    writer.AddFrame("dropout", SensorKind::kSoftBubble, none, nullptr, std::nullopt, Split::kTrain);
    writer.AddFrame("white", SensorKind::kGelSlim,
                    Image(testing_util::kGelRows, testing_util::kGelCols, 3, 1.0f), nullptr,
                    std::nullopt, Split::kTrain);
    writer.AddFrame("black", SensorKind::kGelSlim,
                    Image(testing_util::kGelRows, testing_util::kGelCols, 3, 0.0f), nullptr,
                    std::nullopt, Split::kTrain);
    writer.Finish();
  }
  const Dataset dataset = Dataset::Open(dir / "data");
  LatentEncoder::Summary summary;
  const FunctaModel model = MakeModel();
  const Functaset f = LatentEncoder(model, LatentEncoder::Options()).Encode(dataset, &summary);
  EXPECT_EQ(summary.non_finite_latents, 0);
  for (SensorKind sensor : f.sensors()) {
    for (const FunctasetEntry& e : f.entries(sensor)) {
      SCOPED_TRACE(e.id);
      EXPECT_TRUE(e.latent.allFinite());
      if (e.id == "dropout") {
        EXPECT_TRUE(std::isnan(e.psnr));  // no valid pixel
      } else {
        EXPECT_TRUE(std::isfinite(e.psnr));
      }
    }
  }
  // The mean skips the frame without a PSNR.
  EXPECT_TRUE(std::isfinite(summary.mean_psnr.at(SensorKind::kSoftBubble)));
  // And the file keeps the NaN PSNR.
  f.Save(dir / "set.tfs");
  EXPECT_TRUE(
      std::isnan(Functaset::Load(dir / "set.tfs")
                     .entries(SensorKind::kSoftBubble)[*f.Find(SensorKind::kSoftBubble, "dropout")]
                     .psnr));
}

// A photometric model whose trunk draws against `reference`, its markers moving
// (m = 0.8), with a warm-start table of frames it drew against `table_reference`.
FunctaModel PhotometricModel(const Image& reference, const Image& table_reference) {
  const PhotometricTrunk::Options o = testing_util::SmallPhotometricOptions(12, 16);
  auto trunk = std::make_shared<PhotometricTrunk>(o, reference, 21);
  Eigen::VectorXd head = trunk->head_parameters();
  head[head.size() - 1] = 0.8;
  trunk->SetHeadParameters(head);
  const auto table_markers = trunk->MakeMarkers(table_reference);
  std::vector<TrunkTargets> frames;
  Eigen::MatrixXd latents(4, o.latent_dim);
  for (int i = 0; i < 4; ++i) {
    for (int k = 0; k < o.latent_dim; ++k) latents(i, k) = 0.3 * std::sin(1.3 * i + 0.7 * k);
    frames.push_back(testing_util::WholeFrameTargets(
        trunk->Forward<float>(trunk->AllPixels(), latents.row(i).transpose().cast<float>(),
                              table_markers.get()),
        o.rows, o.cols));
  }
  SensorTrunk sensor_trunk;
  sensor_trunk.sensor = SensorKind::kGelSlim;
  sensor_trunk.format.rows = o.rows;
  sensor_trunk.format.cols = o.cols;
  sensor_trunk.format.grayscale = true;
  sensor_trunk.format.scale = 1.0;
  sensor_trunk.siren = trunk->siren();
  sensor_trunk.alpha = Eigen::VectorXd::Zero(trunk->siren().latent_dim());
  sensor_trunk.warm_start = std::make_shared<WarmStartTable>(PhotometricWarmStart::BuildTable(
      *trunk, frames, latents, PhotometricWarmStart::Options()));
  sensor_trunk.photometric = trunk;
  FunctaModel model;
  model.SetTrunk(sensor_trunk);
  return model;
}

TEST(LatentEncoder, APhotometricFrameIsFittedAgainstTheMarkersItIsGiven) {
  // The same trunk on two references: encoding with the other reference's markers is,
  // bit for bit, encoding with a trunk built on that reference, for every strategy.
  const Image a = testing_util::MarkerReference(24, 32);
  Image b(24, 32, 1);
  for (int r = 0; r < 24; ++r) {
    for (int c = 0; c < 32; ++c) b.at(r, c) = a.at((r + 2) % 24, (c + 1) % 32);
  }
  const FunctaModel on_a = PhotometricModel(a, a);
  const FunctaModel on_b = PhotometricModel(b, a);  // the same table
  const PhotometricTrunk& trunk_a = *on_a.Trunk(SensorKind::kGelSlim).photometric;
  const PhotometricTrunk& trunk_b = *on_b.Trunk(SensorKind::kGelSlim).photometric;
  ASSERT_EQ(trunk_a.siren().parameters(), trunk_b.siren().parameters());
  const auto markers_b = trunk_a.MakeMarkers(b);
  Eigen::VectorXf z(8);
  for (int k = 0; k < 8; ++k) z[k] = static_cast<float>(0.25 * std::cos(0.9 * k + 0.4));
  const TrunkTargets frame = testing_util::WholeFrameTargets(
      trunk_b.Forward<float>(trunk_b.AllPixels(), z), 12, 16);
  for (const char* strategy : {"adam:20", "knn+adam:10", "knn", "knn+ceres:2"}) {
    LatentEncoder::Options options;
    options.strategy = strategy;
    const LatentEncoder encoder_a(on_a, options), encoder_b(on_b, options);
    const LatentEncoder::EncodedFrame given =
        encoder_a.EncodeTargets(SensorKind::kGelSlim, frame, markers_b.get());
    const LatentEncoder::EncodedFrame built = encoder_b.EncodeTargets(SensorKind::kGelSlim, frame);
    EXPECT_TRUE((given.latent.array() == built.latent.array()).all()) << strategy;
    EXPECT_EQ(given.psnr, built.psnr) << strategy;
    // Against the trunk's own reference the fit is another one.
    const LatentEncoder::EncodedFrame wrong = encoder_a.EncodeTargets(SensorKind::kGelSlim, frame);
    EXPECT_NE(wrong.psnr, given.psnr) << strategy;
    // Unscored (for a posterior): the same latent, no PSNR.
    options.score_targets = false;
    const LatentEncoder::EncodedFrame unscored = LatentEncoder(on_a, options).EncodeTargets(
        SensorKind::kGelSlim, frame, markers_b.get());
    EXPECT_TRUE((unscored.latent.array() == given.latent.array()).all()) << strategy;
    EXPECT_TRUE(std::isnan(unscored.psnr)) << strategy;
  }
}

TEST(LatentEncoder, ATrunksRecordedDefaultFitIsUsedUnlessAnotherIsAskedFor) {
  const Image reference = testing_util::MarkerReference(24, 32);
  FunctaModel model = PhotometricModel(reference, reference);
  EXPECT_EQ(LatentEncoder(model, {}).StrategyOf(SensorKind::kGelSlim).ToString(),
            LatentEncoder::DefaultPhotometricStrategy(true, 8));
  model.MutableTrunk(SensorKind::kGelSlim).default_fit = "knn+adam:7";
  EXPECT_EQ(LatentEncoder(model, {}).StrategyOf(SensorKind::kGelSlim).ToString(), "knn+adam:7");
  LatentEncoder::Options asked;
  asked.strategy = "adam:5";
  EXPECT_EQ(LatentEncoder(model, asked).StrategyOf(SensorKind::kGelSlim).ToString(), "adam:5");
  // The recorded fit encodes as the same fit asked for by name, bit for bit.
  asked.strategy = "knn+adam:7";
  Eigen::VectorXf z(8);
  for (int k = 0; k < 8; ++k) z[k] = static_cast<float>(0.2 * std::sin(0.8 * k + 0.3));
  const PhotometricTrunk& trunk = *model.Trunk(SensorKind::kGelSlim).photometric;
  const TrunkTargets frame =
      testing_util::WholeFrameTargets(trunk.Forward<float>(trunk.AllPixels(), z), 12, 16);
  const LatentEncoder::EncodedFrame recorded =
      LatentEncoder(model, {}).EncodeTargets(SensorKind::kGelSlim, frame);
  const LatentEncoder::EncodedFrame named =
      LatentEncoder(model, asked).EncodeTargets(SensorKind::kGelSlim, frame);
  EXPECT_TRUE((recorded.latent.array() == named.latent.array()).all());
  // A recorded fit the trunk cannot use, or no strategy at all, is refused naming it.
  for (const char* bad : {"meta_sgd:3", "lbfgs:3"}) {
    model.MutableTrunk(SensorKind::kGelSlim).default_fit = bad;
    try {
      LatentEncoder encoder(model, {});
      ADD_FAILURE() << "accepted " << bad;
    } catch (const std::invalid_argument& e) {
      EXPECT_THAT(e.what(), HasSubstr("gelslim trunk")) << e.what();
      EXPECT_THAT(e.what(), HasSubstr("train --default-fit")) << e.what();
    }
  }
  // Without the warm-start table the k-NN fits are refused, recorded or asked for.
  model.MutableTrunk(SensorKind::kGelSlim).default_fit = "knn+adam:7";
  model.MutableTrunk(SensorKind::kGelSlim).warm_start = nullptr;
  EXPECT_THROW(LatentEncoder(model, {}), std::invalid_argument);
  EXPECT_EQ(LatentEncoder::StrategyRefusal(FitStrategy::FromString("knn+adam:7"), true, false)
                .find("has no warm-start table"),
            0u);
  EXPECT_EQ(LatentEncoder::StrategyRefusal(FitStrategy::FromString("ceres:5"), false, false), "");
}

}  // namespace
}  // namespace tactfunc
