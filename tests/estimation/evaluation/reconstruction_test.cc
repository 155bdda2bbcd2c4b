// Copyright 2026 The tactfunc Authors.
#include "estimation/evaluation/reconstruction.h"

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "estimation/functaset/latent_encoder.h"
#include "estimation/data/trunk_targets.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/support/functa_test_util.h"
#include "tests/support/test_dir.h"

namespace tactfunc {
namespace {

using ::testing::HasSubstr;
using testing_util::MakeModel;
using testing_util::TestDir;
using testing_util::WriteTinyDataset;

constexpr double kNaN = std::numeric_limits<double>::quiet_NaN();
constexpr double kInf = std::numeric_limits<double>::infinity();

TEST(ReconstructionEvaluator, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(ReconstructionEvaluator::Options().IsValid(&error)) << error;
}

TEST(ReconstructionEvaluator, BadOptionsNameTheField) {
  ReconstructionEvaluator::Options options;
  options.threads = 0;
  std::string error;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("threads"));
  EXPECT_THROW(ReconstructionEvaluator{options}, std::invalid_argument);
}

// ---- Statistics on known values ---------------------------------------------------------

TEST(PsnrStats, MeanMedianAndFifthPercentileOfKnownValues) {
  std::vector<double> values;
  for (int i = 20; i >= 1; --i) values.push_back(i);  // unsorted on purpose
  const PsnrStats s = ComputePsnrStats(values);
  EXPECT_EQ(s.count, 20);
  EXPECT_EQ(s.excluded, 0);
  EXPECT_DOUBLE_EQ(s.mean, 10.5);
  EXPECT_DOUBLE_EQ(s.median, 10.5);
  EXPECT_DOUBLE_EQ(s.p5, 1.95);  // numpy: np.percentile(np.arange(1, 21), 5) == 1.95
}

TEST(PsnrStats, OddCountMedianIsTheMiddleValue) {
  const PsnrStats s = ComputePsnrStats({30.0, 10.0, 20.0});
  EXPECT_DOUBLE_EQ(s.median, 20.0);
  EXPECT_DOUBLE_EQ(s.mean, 20.0);
  EXPECT_DOUBLE_EQ(s.p5, 11.0);  // rank 0.05 * 2 = 0.1 between 10 and 20
}

TEST(PsnrStats, NonFiniteValuesAreCountedButLeftOut) {
  const PsnrStats s = ComputePsnrStats({25.0, kNaN, 35.0, kInf});
  EXPECT_EQ(s.count, 2);
  EXPECT_EQ(s.excluded, 2);
  EXPECT_DOUBLE_EQ(s.mean, 30.0);
  EXPECT_DOUBLE_EQ(s.median, 30.0);
}

TEST(PsnrStats, NoFiniteValueGivesNan) {
  for (const std::vector<double>& values : {std::vector<double>{}, std::vector<double>{kNaN}}) {
    const PsnrStats s = ComputePsnrStats(values);
    EXPECT_EQ(s.count, 0);
    EXPECT_TRUE(std::isnan(s.mean));
    EXPECT_TRUE(std::isnan(s.median));
    EXPECT_TRUE(std::isnan(s.p5));
  }
  const PsnrStats one = ComputePsnrStats({12.5});
  EXPECT_DOUBLE_EQ(one.p5, 12.5);
  EXPECT_DOUBLE_EQ(one.median, 12.5);
}

// ---- Representation size ----------------------------------------------------------------

TEST(RepresentationSize, RawFrameBytesUseTheSensorsSampleSize) {
  SensorInfo bubble;
  bubble.kind = SensorKind::kSoftBubble;
  bubble.rows = 140;
  bubble.cols = 175;
  bubble.channels = 1;
  bubble.encoding = PixelEncoding::kDepthU16Micrometres;
  EXPECT_EQ(RawFrameBytes(bubble), 140u * 175u * 2u);
  SensorInfo gel;
  gel.kind = SensorKind::kGelSlim;
  gel.rows = 320;
  gel.cols = 427;
  gel.channels = 3;
  gel.encoding = PixelEncoding::kRgb8;
  EXPECT_EQ(RawFrameBytes(gel), 320u * 427u * 3u);
}

TEST(RepresentationSize, CompressionRatioArithmetic) {
  const FunctaModel model = MakeModel();
  const SensorTrunk& b = model.Trunk(SensorKind::kSoftBubble);
  const SensorTrunk& g = model.Trunk(SensorKind::kGelSlim);
  Functaset f(model.checksum(), "d");
  f.AddSensor(SensorKind::kSoftBubble, b.siren.latent_dim());
  f.AddSensor(SensorKind::kGelSlim, g.siren.latent_dim());
  for (int i = 0; i < 5; ++i) {
    f.Add(SensorKind::kSoftBubble,
          FunctasetEntry{"b" + std::to_string(i), Split::kTrain, std::nullopt,
                         Eigen::VectorXf::Zero(b.siren.latent_dim()), 0});
  }
  for (int i = 0; i < 3; ++i) {
    f.Add(SensorKind::kGelSlim, FunctasetEntry{"g" + std::to_string(i), Split::kTest, std::nullopt,
                                               Eigen::VectorXf::Zero(g.siren.latent_dim()), 0});
  }
  const std::vector<SensorInfo> infos = {testing_util::BubbleInfo(), testing_util::GelInfo()};
  const RepresentationSize size = ComputeRepresentationSize(model, f, infos);
  // Model: theta + alpha of both trunks, 4 bytes each -- the whole model here.
  const std::uint64_t model_bytes =
      4ull * (b.siren.NumParameters() + 8 + g.siren.NumParameters() + 6);
  EXPECT_EQ(size.model_bytes, model_bytes);
  EXPECT_EQ(size.model_bytes, model.ParameterBytes());
  EXPECT_EQ(size.latent_bytes, 4u * (5 * 8 + 3 * 6));
  EXPECT_EQ(size.representation_bytes, model_bytes + 4u * (5 * 8 + 3 * 6));
  const std::uint64_t raw = 5u * 12 * 14 * 2 + 3u * 10 * 16 * 3;
  EXPECT_EQ(size.raw_bytes, raw);
  EXPECT_EQ(size.frames, 8);
  EXPECT_DOUBLE_EQ(size.compression_ratio, static_cast<double>(raw) / (model_bytes + 4 * 58));
  // Only the trunks the functaset uses count.
  Functaset bubble_only(model.checksum(), "d");
  bubble_only.AddSensor(SensorKind::kSoftBubble, 8);
  EXPECT_EQ(ComputeRepresentationSize(model, bubble_only, infos).model_bytes,
            4ull * (b.siren.NumParameters() + 8));
  EXPECT_THROW(ComputeRepresentationSize(model, f, {testing_util::BubbleInfo()}),
               std::invalid_argument);
}

// ---- Evaluation on a dataset ------------------------------------------------------------

struct Encoded {
  FunctaModel model;
  Functaset functaset;
};

Encoded EncodeTinyDataset(const Dataset& dataset) {
  Encoded out{MakeModel(), {}};
  out.functaset = LatentEncoder(out.model, LatentEncoder::Options()).Encode(dataset, nullptr);
  return out;
}

TEST(ReconstructionEvaluator, PerFramePsnrsFollowTheOneDefinition) {
  TestDir dir;
  WriteTinyDataset(dir / "data", 8, /*clean=*/true);
  const Dataset dataset = Dataset::Open(dir / "data");
  const Encoded e = EncodeTinyDataset(dataset);
  ReconstructionEvaluator::Options options;
  options.threads = 2;
  const ReconstructionEvaluator::Summary s =
      ReconstructionEvaluator(options).Evaluate(e.model, e.functaset, dataset);
  ASSERT_EQ(s.frames.size(), e.functaset.size());
  EXPECT_TRUE(s.has_clean);
  for (const ReconstructionEvaluator::FrameResult& r : s.frames) {
    SCOPED_TRACE(r.id);
    const SensorTrunk& trunk = e.model.Trunk(r.sensor);
    const FunctasetEntry& entry = e.functaset.entries(r.sensor)[*e.functaset.Find(r.sensor, r.id)];
    const Eigen::MatrixXf prediction = Reconstruct(trunk, entry.latent);
    const TrunkTargets noisy = LoadTrunkTargets(dataset, r.dataset_index, trunk.format);
    const TrunkTargets clean = LoadTrunkTargets(dataset, r.dataset_index, trunk.format, true);
    EXPECT_DOUBLE_EQ(r.psnr, Psnr(prediction, noisy));
    EXPECT_DOUBLE_EQ(r.psnr_clean, Psnr(prediction, clean));
    EXPECT_DOUBLE_EQ(r.psnr_source_peak, PsnrSourcePeak(prediction, noisy));
    EXPECT_DOUBLE_EQ(r.target_range, TargetRange(noisy));
    EXPECT_DOUBLE_EQ(r.source_range, noisy.source_range);
    EXPECT_DOUBLE_EQ(r.rmse, Rmse(prediction, noisy));
    // The source frame's range is at least the resized one's: never a lower PSNR.
    EXPECT_GE(r.psnr_source_peak, r.psnr - 1e-4);  // (float rounding of the values)
    EXPECT_DOUBLE_EQ(r.psnr_zero,
                     Psnr(Reconstruct(trunk, Eigen::VectorXf::Zero(entry.latent.size())), noisy));
    // The encoder's stored PSNR is the same figure (stored as float32).
    EXPECT_FLOAT_EQ(static_cast<float>(r.psnr), entry.psnr);
    EXPECT_EQ(r.split, entry.split);
  }
}

TEST(ReconstructionEvaluator, GroupsSummariseTheirFrames) {
  TestDir dir;
  WriteTinyDataset(dir / "data", 8, /*clean=*/true);
  const Dataset dataset = Dataset::Open(dir / "data");
  const Encoded e = EncodeTinyDataset(dataset);
  const ReconstructionEvaluator::Summary s =
      ReconstructionEvaluator().Evaluate(e.model, e.functaset, dataset);
  ASSERT_EQ(s.groups.size(), 4u);  // 2 sensors x 2 splits
  for (const ReconstructionEvaluator::GroupSummary& g : s.groups) {
    std::vector<double> noisy, clean, zero, source_peak;
    for (const auto& r : s.frames) {
      if (r.sensor != g.sensor || r.split != g.split) continue;
      noisy.push_back(r.psnr);
      source_peak.push_back(r.psnr_source_peak);
      clean.push_back(r.psnr_clean);
      zero.push_back(r.psnr_zero);
    }
    EXPECT_EQ(g.noisy.count, static_cast<std::int64_t>(noisy.size()));
    EXPECT_DOUBLE_EQ(g.noisy.mean, ComputePsnrStats(noisy).mean);
    EXPECT_DOUBLE_EQ(g.noisy.p5, ComputePsnrStats(noisy).p5);
    EXPECT_DOUBLE_EQ(g.clean.median, ComputePsnrStats(clean).median);
    EXPECT_DOUBLE_EQ(g.zero.mean, ComputePsnrStats(zero).mean);
    EXPECT_DOUBLE_EQ(g.source_peak.mean, ComputePsnrStats(source_peak).mean);
  }
  const auto* test = s.Find(SensorKind::kGelSlim, Split::kTest);
  ASSERT_NE(test, nullptr);
  EXPECT_EQ(test->noisy.count, 2);  // frames 3 and 7
  EXPECT_EQ(s.size.frames, 16);
  EXPECT_GT(s.size.compression_ratio, 0.0);
  EXPECT_THAT(s.BriefReport(), HasSubstr("compression"));
  EXPECT_THAT(s.FullReport(), HasSubstr("gelslim"));
}

TEST(ReconstructionEvaluator, WithoutCleanFramesTheCleanPsnrIsAbsent) {
  TestDir dir;
  WriteTinyDataset(dir / "data", 4);
  const Dataset dataset = Dataset::Open(dir / "data");
  const Encoded e = EncodeTinyDataset(dataset);
  const ReconstructionEvaluator::Summary s =
      ReconstructionEvaluator().Evaluate(e.model, e.functaset, dataset);
  EXPECT_FALSE(s.has_clean);
  for (const auto& r : s.frames) EXPECT_TRUE(std::isnan(r.psnr_clean));
  for (const auto& g : s.groups) EXPECT_EQ(g.clean.count, 0);
}

TEST(ReconstructionEvaluator, ResultsDoNotDependOnTheThreadCount) {
  TestDir dir;
  WriteTinyDataset(dir / "data", 8, /*clean=*/true);
  const Dataset dataset = Dataset::Open(dir / "data");
  const Encoded e = EncodeTinyDataset(dataset);
  const auto one = ReconstructionEvaluator().Evaluate(e.model, e.functaset, dataset);
  ReconstructionEvaluator::Options options;
  options.threads = 3;
  const auto three = ReconstructionEvaluator(options).Evaluate(e.model, e.functaset, dataset);
  ASSERT_EQ(one.frames.size(), three.frames.size());
  for (std::size_t i = 0; i < one.frames.size(); ++i) {
    EXPECT_EQ(one.frames[i].id, three.frames[i].id);
    EXPECT_EQ(one.frames[i].psnr, three.frames[i].psnr);
    EXPECT_EQ(one.frames[i].psnr_clean, three.frames[i].psnr_clean);
  }
}

TEST(ReconstructionEvaluator, RefusesAFunctasetOfAnotherModel) {
  TestDir dir;
  WriteTinyDataset(dir / "data", 2);
  const Dataset dataset = Dataset::Open(dir / "data");
  Encoded e = EncodeTinyDataset(dataset);
  e.functaset.set_model_checksum(0x1234);
  EXPECT_THROW(ReconstructionEvaluator().Evaluate(e.model, e.functaset, dataset),
               FunctasetModelMismatch);
}

TEST(ReconstructionEvaluator, RefusesAFrameTheDatasetDoesNotHave) {
  TestDir dir;
  WriteTinyDataset(dir / "data", 2);
  const Dataset dataset = Dataset::Open(dir / "data");
  Encoded e = EncodeTinyDataset(dataset);
  e.functaset.Add(SensorKind::kSoftBubble, FunctasetEntry{"ghost", Split::kTrain, std::nullopt,
                                                          Eigen::VectorXf::Zero(8), 0});
  try {
    ReconstructionEvaluator().Evaluate(e.model, e.functaset, dataset);
    ADD_FAILURE() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& error) {
    EXPECT_THAT(error.what(), HasSubstr("'ghost'"));
  }
}

TEST(Reconstruct, IsTheTrunkOnItsWorkingGrid) {
  const FunctaModel model = MakeModel();
  const SensorTrunk& trunk = model.Trunk(SensorKind::kGelSlim);
  const Eigen::VectorXf z = Eigen::VectorXf::LinSpaced(6, -0.5f, 0.5f);
  const Eigen::MatrixXf y = Reconstruct(trunk, z);
  EXPECT_EQ(y.rows(), 8 * 10);
  EXPECT_TRUE(y.isApprox(trunk.siren.Forward<float>(trunk.siren.Grid<float>(8, 10), z)));
  EXPECT_THROW(Reconstruct(trunk, Eigen::VectorXf::Zero(3)), std::invalid_argument);
}

}  // namespace
}  // namespace tactfunc
