// Copyright 2026 The tactfunc Authors.
//
// TrunkTrainer: options are validated by name; a tiny meta-learning run on a tiny
// synthetic dataset lowers the outer loss and raises the PSNR after K steps; runs are
// bit-identical for a seed whatever the thread count, and stopping + resuming from a
// checkpoint gives bit-identically the parameters of an uninterrupted run; mismatched
// or corrupt checkpoints are refused with messages naming the field or the file.
#include "estimation/training/trunk_trainer.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <memory>
#include <random>
#include <stdexcept>
#include <string>

#include "Eigen/SVD"
#include "estimation/data/dataset.h"
#include "estimation/data/synthetic_dataset.h"
#include "estimation/data/trunk_targets.h"
#include "estimation/evaluation/baselines.h"
#include "models/trunk/meta_sgd.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "models/core/tensor_file.h"
#include "tests/support/test_dir.h"

namespace tactfunc {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;
using testing_util::TestDir;

// 2 tools x 6 bubble contacts (all in the train split), written once per suite.
class TrunkTrainerTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    data_dir_ = new TestDir();
    SynthesisPlan plan;
    plan.out = data_dir_->path() + "/data";
    plan.tools = {"hemisphere", "l_shape"};
    plan.sensors = {SensorKind::kSoftBubble};
    plan.frames_per_tool = 6;
    plan.seed = 7;
    plan.test_fraction = 0.0;
    plan.write_clean = true;  // noise-free copies, for the outer loss on them
    Synthesize(plan, ContactSimulator::Options());
    dataset_ = new Dataset(Dataset::Open(plan.out));
  }
  static void TearDownTestSuite() {
    delete dataset_;
    delete data_dir_;
    dataset_ = nullptr;
    data_dir_ = nullptr;
  }

  // The tiny preset, shortened, on a subset of pixels, with batches that straddle
  // epochs (3 frames a step out of 12 would not; 5 does) and off-grid monitor points,
  // so that resuming has to restore every piece of state.
  static TrunkTrainer::Options ShortOptions() {
    TrunkTrainer::Options options = TrunkTrainer::Preset("tiny");
    options.steps = 24;
    options.batch_size = 5;
    options.pixels_per_frame = 100;
    options.monitor_every = 7;
    options.monitor_frames = 4;
    options.checkpoint_every = 5;
    options.residual_frames = 4;
    options.threads = 2;
    return options;
  }

  static TrunkTrainer::Summary Train(const TrunkTrainer::Options& options, SensorTrunk* trunk,
                                     const TrunkTrainer::StepCallback& callback = nullptr) {
    return TrunkTrainer(options).Train(*dataset_, SensorKind::kSoftBubble, trunk, callback);
  }

  static bool SameParameters(const SensorTrunk& a, const SensorTrunk& b) {
    return a.siren.parameters().size() == b.siren.parameters().size() &&
           (a.siren.parameters().array() == b.siren.parameters().array()).all() &&
           a.alpha.size() == b.alpha.size() && (a.alpha.array() == b.alpha.array()).all();
  }

  static TestDir* data_dir_;
  static Dataset* dataset_;
  TestDir dir_;
};
TestDir* TrunkTrainerTest::data_dir_ = nullptr;
Dataset* TrunkTrainerTest::dataset_ = nullptr;

TEST(TrunkTrainerOptions, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(TrunkTrainer::Options().IsValid(&error)) << error;
}

TEST(TrunkTrainerOptions, EveryPresetIsValid) {
  for (const std::string& name : TrunkTrainer::PresetNames()) {
    std::string error;
    EXPECT_TRUE(TrunkTrainer::Preset(name).IsValid(&error)) << name << ": " << error;
  }
}

TEST(TrunkTrainerOptions, TheStoragePresetIsTheSmallSirenWithTheNoiseFreeReadoutRecipe) {
  const TrunkTrainer::Options small = TrunkTrainer::Preset("small");
  const TrunkTrainer::Options o = TrunkTrainer::Preset("storage");
  EXPECT_EQ(o.siren.width, small.siren.width);
  EXPECT_EQ(o.siren.num_hidden_layers, small.siren.num_hidden_layers);
  EXPECT_EQ(o.learning_rate, small.learning_rate);
  EXPECT_EQ(o.learning_rate_final_fraction, small.learning_rate_final_fraction);
  EXPECT_EQ(o.siren.latent_dim, 256);
  EXPECT_EQ(o.batch_size, 8);
  EXPECT_EQ(o.pixels_per_frame, 0);
  EXPECT_EQ(o.steps, 1000);
  EXPECT_TRUE(o.readout);
  EXPECT_EQ(o.readout_pca_frames, 20000);
  EXPECT_EQ(o.meta_sgd.inner_steps, 0);
  EXPECT_TRUE(o.outer_loss_on_clean);
}

TEST(TrunkTrainerOptions, DefaultPresetIsTheDefaultOptions) {
  const FrameFormat format{70, 88, false, false, 0.01};
  EXPECT_EQ(TrunkTrainer(TrunkTrainer::Preset("default"))
                .TrajectoryOptionsJson(SensorKind::kSoftBubble, format),
            TrunkTrainer(TrunkTrainer::Options())
                .TrajectoryOptionsJson(SensorKind::kSoftBubble, format));
  EXPECT_EQ(TrunkTrainer::Preset("default").steps, TrunkTrainer::Options().steps);
}

TEST(TrunkTrainerOptions, TheDefaultPresetGivesTheGelSlimAShorterLatentThanTheBubble) {
  const TrunkTrainer::Options bubble = TrunkTrainer::Preset("default", SensorKind::kSoftBubble);
  const TrunkTrainer::Options gel = TrunkTrainer::Preset("default", SensorKind::kGelSlim);
  EXPECT_EQ(bubble.siren.latent_dim, 128);
  EXPECT_EQ(gel.siren.latent_dim, 32);
  // Everything else is shared.
  EXPECT_EQ(gel.siren.width, bubble.siren.width);
  EXPECT_EQ(gel.siren.num_hidden_layers, bubble.siren.num_hidden_layers);
  EXPECT_EQ(gel.steps, bubble.steps);
  EXPECT_EQ(gel.batch_size, bubble.batch_size);
  EXPECT_EQ(gel.pixels_per_frame, bubble.pixels_per_frame);
  EXPECT_EQ(gel.learning_rate_final_fraction, 0.1);
  EXPECT_EQ(bubble.learning_rate_final_fraction, 0.1);
  // The other presets keep the paper's constant rate and are the same for both sensors.
  EXPECT_EQ(TrunkTrainer::Preset("small").learning_rate_final_fraction, 1.0);
  EXPECT_EQ(TrunkTrainer::Preset("tiny").learning_rate_final_fraction, 1.0);
  for (const char* name : {"tiny", "small"}) {
    EXPECT_EQ(TrunkTrainer::Preset(name, SensorKind::kGelSlim).siren.latent_dim,
              TrunkTrainer::Preset(name, SensorKind::kSoftBubble).siren.latent_dim)
        << name;
  }
}

TEST(TrunkTrainerOptions, TheLearningRateIsConstantUnlessACosineDecayIsAsked) {
  TrunkTrainer::Options o = TrunkTrainer::Preset("tiny");
  o.steps = 100;
  for (int t : {1, 50, 100}) EXPECT_EQ(TrunkTrainer::LearningRateAt(o, t), o.learning_rate);
  o.learning_rate_final_fraction = 0.1;
  EXPECT_DOUBLE_EQ(TrunkTrainer::LearningRateAt(o, 1), o.learning_rate);
  EXPECT_NEAR(TrunkTrainer::LearningRateAt(o, 51), 0.55 * o.learning_rate, 1e-15);
  EXPECT_NEAR(TrunkTrainer::LearningRateAt(o, 101), 0.1 * o.learning_rate, 1e-15);
  for (int t = 2; t <= 100; ++t) {
    EXPECT_LT(TrunkTrainer::LearningRateAt(o, t), TrunkTrainer::LearningRateAt(o, t - 1)) << t;
  }
  std::string error;
  o.learning_rate_final_fraction = 0;
  EXPECT_FALSE(o.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("learning_rate_final_fraction"));
  o.learning_rate_final_fraction = 1.5;
  EXPECT_FALSE(o.IsValid(&error));
}

TEST(TrunkTrainerOptions, WithADecayTheStepCountBelongsToTheTrajectory) {
  const FrameFormat format{16, 20, false, false, 0.01};
  TrunkTrainer::Options a = TrunkTrainer::Preset("tiny");
  TrunkTrainer::Options b = a;
  b.steps = a.steps + 100;
  // Constant rate: running longer continues the same trajectory.
  EXPECT_EQ(TrunkTrainer(a).TrajectoryOptionsJson(SensorKind::kSoftBubble, format),
            TrunkTrainer(b).TrajectoryOptionsJson(SensorKind::kSoftBubble, format));
  // Decay: the schedule depends on the step count, so a resume must keep it.
  a.learning_rate_final_fraction = b.learning_rate_final_fraction = 0.1;
  EXPECT_NE(TrunkTrainer(a).TrajectoryOptionsJson(SensorKind::kSoftBubble, format),
            TrunkTrainer(b).TrajectoryOptionsJson(SensorKind::kSoftBubble, format));
}

TEST(TrunkTrainerOptions, UnknownPresetIsRejectedListingTheNames) {
  try {
    TrunkTrainer::Preset("huge");
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("huge"));
    EXPECT_THAT(e.what(), HasSubstr("tiny, small, default, storage"));
  }
}

TEST(TrunkTrainerOptions, BadOptionsNameTheField) {
  struct Case {
    const char* field;
    void (*mutate)(TrunkTrainer::Options*);
  };
  const Case cases[] = {
      {"siren", [](TrunkTrainer::Options* o) { o->siren.width = 0; }},
      {"rows", [](TrunkTrainer::Options* o) { o->rows = 10; }},
      {"normalization_scale", [](TrunkTrainer::Options* o) { o->normalization_scale = -1; }},
      {"meta_sgd", [](TrunkTrainer::Options* o) { o->meta_sgd.inner_steps = -1; }},
      {"learning_rate", [](TrunkTrainer::Options* o) { o->learning_rate = 0; }},
      {"alpha_learning_rate", [](TrunkTrainer::Options* o) { o->alpha_learning_rate = -1; }},
      {"adam_beta1", [](TrunkTrainer::Options* o) { o->adam_beta1 = 1; }},
      {"adam_beta2", [](TrunkTrainer::Options* o) { o->adam_beta2 = -0.1; }},
      {"adam_epsilon", [](TrunkTrainer::Options* o) { o->adam_epsilon = 0; }},
      {"alpha_init_min", [](TrunkTrainer::Options* o) { o->alpha_init_max = 1.5; }},
      {"alpha_max", [](TrunkTrainer::Options* o) { o->alpha_max = 0; }},
      {"alpha_init_min", [](TrunkTrainer::Options* o) { o->alpha_max = 0.5; }},  // init 1 > 0.5
      {"batch_size", [](TrunkTrainer::Options* o) { o->batch_size = 0; }},
      {"pixels_per_frame", [](TrunkTrainer::Options* o) { o->pixels_per_frame = -1; }},
      {"steps", [](TrunkTrainer::Options* o) { o->steps = -1; }},
      {"threads", [](TrunkTrainer::Options* o) { o->threads = 0; }},
      {"checkpoint_every", [](TrunkTrainer::Options* o) { o->checkpoint_every = -1; }},
      {"resume", [](TrunkTrainer::Options* o) { o->resume = true; }},
      {"monitor_every", [](TrunkTrainer::Options* o) { o->monitor_every = 0; }},
      {"monitor_frames", [](TrunkTrainer::Options* o) { o->monitor_frames = 0; }},
      {"residual_frames", [](TrunkTrainer::Options* o) { o->residual_frames = 0; }},
      {"divergence_drop_db", [](TrunkTrainer::Options* o) { o->divergence_drop_db = -1; }},
      {"divergence_drop_db", [](TrunkTrainer::Options* o) { o->divergence_drop_db = NAN; }},
  };
  for (const Case& c : cases) {
    TrunkTrainer::Options options;
    c.mutate(&options);
    std::string error;
    EXPECT_FALSE(options.IsValid(&error)) << c.field;
    EXPECT_THAT(error, HasSubstr(c.field));
    EXPECT_THROW(TrunkTrainer trainer(options), std::invalid_argument) << c.field;
  }
}

TEST(TrunkTrainerOptions, TerminationTypesHaveNames) {
  EXPECT_STREQ(ToString(TrunkTrainer::TerminationType::kCompleted), "completed");
  EXPECT_STREQ(ToString(TrunkTrainer::TerminationType::kUserStopped), "user_stopped");
  EXPECT_STREQ(ToString(TrunkTrainer::TerminationType::kNonFinite), "non_finite");
  EXPECT_STREQ(ToString(TrunkTrainer::TerminationType::kDiverged), "diverged");
}

TEST_F(TrunkTrainerTest, AFarTooLargeLearningRateStopsAsDivergedAtTheFirstMonitorPointThatShowsIt) {
  TrunkTrainer::Options options = TrunkTrainer::Preset("tiny");
  options.learning_rate = 0.03;  // 30x the preset's: the trunk blows up within 50 steps
  options.steps = 100;
  options.monitor_every = 10;
  options.monitor_frames = 4;
  options.checkpoint_path = dir_ / "diverged.ckpt";
  options.checkpoint_every = 0;
  options.threads = 2;
  SensorTrunk trunk;
  const TrunkTrainer::Summary summary = Train(options, &trunk);
  ASSERT_EQ(summary.termination_type, TrunkTrainer::TerminationType::kDiverged)
      << summary.FullReport();
  EXPECT_LT(summary.steps_done, options.steps);
  EXPECT_EQ(summary.steps_done % options.monitor_every, 0);
  // The last point is the first one more than 6 dB below the best before it.
  double best = summary.history.front().psnr;
  for (std::size_t i = 0; i + 1 < summary.history.size(); ++i) {
    best = std::max(best, summary.history[i].psnr);
    EXPECT_LE(best - summary.history[i].psnr, options.divergence_drop_db) << i;
  }
  EXPECT_GT(best - summary.history.back().psnr, options.divergence_drop_db);
  EXPECT_EQ(summary.history.back().step, summary.steps_done);
  EXPECT_THAT(summary.message, HasSubstr("diverged"));
  EXPECT_THAT(summary.message, HasSubstr("learning_rate"));
  // Nothing to resume from: a diverged state is not checkpointed.
  EXPECT_FALSE(std::filesystem::exists(options.checkpoint_path));

  // A fall after the last regular monitor point is caught at the final point.
  TrunkTrainer::Options late = options;
  late.monitor_every = 1000;  // only step 0 and the final point
  late.steps = 60;
  const TrunkTrainer::Summary at_end = Train(late, &trunk);
  EXPECT_EQ(at_end.termination_type, TrunkTrainer::TerminationType::kDiverged)
      << at_end.FullReport();
  EXPECT_EQ(at_end.steps_done, 60);
  ASSERT_EQ(at_end.history.size(), 2u);

  // With the check off the same run goes on to the end, far below where it started.
  const double drop = options.divergence_drop_db;
  options.divergence_drop_db = 0;
  const TrunkTrainer::Summary unchecked = Train(options, &trunk);
  ASSERT_EQ(unchecked.termination_type, TrunkTrainer::TerminationType::kCompleted)
      << unchecked.message;
  EXPECT_EQ(unchecked.steps_done, options.steps);
  EXPECT_LT(unchecked.train_psnr, summary.history.front().psnr - drop);
}

TEST_F(TrunkTrainerTest, ANonFiniteGradientStopsTheRunKeepingTheLastFiniteParameters) {
  TrunkTrainer::Options options = ShortOptions();
  options.checkpoint_every = 0;
  options.monitor_every = 1000;  // no monitor point before the gradient breaks
  options.learning_rate = 1e30;  // Adam moves theta by about this much: the trunk overflows
  SensorTrunk trunk;
  const TrunkTrainer::Summary summary = Train(options, &trunk);
  ASSERT_EQ(summary.termination_type, TrunkTrainer::TerminationType::kNonFinite)
      << summary.FullReport();
  EXPECT_GE(summary.steps_done, 1);
  EXPECT_LT(summary.steps_done, options.steps);
  EXPECT_THAT(summary.message, HasSubstr("non-finite"));
  EXPECT_THAT(summary.message, HasSubstr("learning_rate"));
  EXPECT_THAT(summary.message,
              HasSubstr("kept the parameters of step " + std::to_string(summary.steps_done)));
  EXPECT_TRUE(trunk.siren.parameters().allFinite());
  EXPECT_TRUE(trunk.alpha.allFinite());
}

TEST_F(TrunkTrainerTest, TheReadoutBranchStartsAsThePcaOfTheTrainingFrames) {
  // Zero steps: the trunk is its start. One full-frame meta-SGD step at alpha = 1 from
  // z = 0 must then reconstruct every training frame as PCA with d components does.
  TrunkTrainer::Options options = TrunkTrainer::Preset("tiny");
  options.readout = true;
  options.steps = 0;
  options.threads = 2;
  options.siren.latent_dim = 4;  // fewer components than the 12 frames span
  SensorTrunk trunk;
  const TrunkTrainer::Summary summary = Train(options, &trunk);
  ASSERT_EQ(summary.termination_type, TrunkTrainer::TerminationType::kCompleted) << summary.message;
  ASSERT_TRUE(trunk.siren.has_readout());
  EXPECT_FALSE(trunk.siren.readout_frozen());
  EXPECT_EQ(trunk.siren.options().readout_rows, trunk.format.rows);
  EXPECT_EQ(trunk.siren.options().readout_cols, trunk.format.cols);
  std::vector<TrunkTargets> frames;
  std::vector<const TrunkTargets*> pointers;
  for (std::size_t i = 0; i < dataset_->frames().size(); ++i) {
    frames.push_back(LoadTrunkTargets(*dataset_, i, trunk.format));
  }
  for (const TrunkTargets& t : frames) pointers.push_back(&t);
  const int d = trunk.siren.latent_dim();
  PcaCodec::Options pca_options;
  pca_options.components = d;
  const Eigen::MatrixXf stacked = StackFrames(pointers);
  const PcaCodec pca = PcaCodec::Fit(stacked, pca_options);
  const Eigen::MatrixXf pca_frames = pca.Decode(pca.Encode(stacked));
  MetaSgd::Options one_step;
  one_step.inner_steps = 1;
  const MetaSgd meta(one_step);
  const Eigen::MatrixXf grid = trunk.siren.Grid<float>(trunk.format.rows, trunk.format.cols);
  const Eigen::VectorXf alpha = Eigen::VectorXf::Ones(d);
  const Eigen::VectorXf all_pixels;  // every pixel weighs 1, as the PCA sees them
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const Eigen::VectorXf z = meta.FitLatent<float>(trunk.siren, grid, frames[i].values,
                                                    all_pixels, alpha);
    const Eigen::MatrixXf y = trunk.siren.Forward<float>(grid, z);
    const Eigen::MatrixXf expected = UnflattenFrame(pca_frames.row(i), 1);
    const float scale = std::max(1e-3f, expected.cwiseAbs().maxCoeff());
    EXPECT_LE((y - expected).cwiseAbs().maxCoeff(), 1e-3f * scale)
        << "frame " << i << ": PCA misses the frame by "
        << (expected - frames[i].values).cwiseAbs().maxCoeff();
  }
  // The model file records the branch and reads back the same trunk.
  FunctaModel model;
  model.SetTrunk(trunk);
  const FunctaModel read = FunctaModel::Parse(model.Serialize(), "readout.tfm");
  const SensorTrunk& back = read.Trunk(SensorKind::kSoftBubble);
  EXPECT_EQ(back.siren.options().readout_rows, trunk.format.rows);
  EXPECT_EQ(back.siren.NumParameters(), trunk.siren.NumParameters());
  // Every parameter as float32, the basis as float16 (11 significant bits).
  const ParameterBlock& basis = trunk.siren.Block(ParameterGroup::kReadoutBasis);
  const Eigen::VectorXd& a = trunk.siren.parameters();
  const Eigen::VectorXd& b = back.siren.parameters();
  for (Eigen::Index i = 0; i < a.size(); ++i) {
    const bool in_basis = i >= basis.offset && i < basis.offset + basis.size();
    // float16: half a unit in the last of 11 bits, and 2^-25 among its subnormals.
    const double bound = in_basis ? std::pow(2.0, -11) * std::abs(a[i]) + std::pow(2.0, -25)
                                  : 1e-7 * std::abs(a[i]) + 1e-12;
    EXPECT_LE(std::abs(b[i] - a[i]), bound)
        << "parameter " << i << (in_basis ? " (basis)" : "");
  }
}

TEST_F(TrunkTrainerTest, WithTheOuterLossOnNoiseFreeCopiesTheReadoutStartsAsTheirShrunkPca) {
  TrunkTrainer::Options options = TrunkTrainer::Preset("tiny");
  options.readout = true;
  options.steps = 0;
  options.threads = 2;
  options.siren.latent_dim = 10;  // up to the weakest of the 11 directions 12 frames span
  options.outer_loss_on_clean = true;
  SensorTrunk trunk;
  Train(options, &trunk);
  // The branch's mean is the mean of the clean copies, not of the noisy frames.
  const std::vector<std::size_t> indices =
      dataset_->FrameIndices(SensorKind::kSoftBubble, Split::kTrain);
  const std::vector<TrunkTargets> clean =
      LoadTrunkTargets(*dataset_, indices, trunk.format, /*clean=*/true, 2);
  const std::vector<TrunkTargets> noisy =
      LoadTrunkTargets(*dataset_, indices, trunk.format, /*clean=*/false, 2);
  Eigen::MatrixXf clean_mean = Eigen::MatrixXf::Zero(trunk.format.rows * trunk.format.cols, 1);
  Eigen::MatrixXf noisy_mean = clean_mean;
  const std::size_t n = indices.size();
  for (std::size_t i = 0; i < n; ++i) {
    clean_mean += clean[i].values / n;
    noisy_mean += noisy[i].values / n;
  }
  const Eigen::VectorXd theta = trunk.siren.parameters();
  const ParameterBlock mean_block = trunk.siren.Block(ParameterGroup::kReadoutMean);
  const Eigen::VectorXf branch_mean =
      theta.segment(mean_block.offset, mean_block.size()).cast<float>();
  const float scale = clean_mean.cwiseAbs().maxCoeff();
  EXPECT_LE((branch_mean - clean_mean.col(0)).cwiseAbs().maxCoeff(), 1e-5f * scale);
  EXPECT_GT((branch_mean - noisy_mean.col(0)).cwiseAbs().maxCoeff(), 1e-3f * scale);
  // Its projections are shrunk by Wiener gains in (0, 1], the noisier components more;
  // noisy frames equal to their copies (no noise) leave every gain at 1.
  const Eigen::VectorXd& gains = trunk.siren.start_gains();
  ASSERT_EQ(gains.size(), 10);
  EXPECT_GT(gains.minCoeff(), 0.0);
  EXPECT_LE(gains.maxCoeff(), 1.0);
  EXPECT_LT(gains.minCoeff(), 0.99);
  // Each is lambda_k / (lambda_k + sigma_k^2) along the branch's unit component u_k:
  // the copies' variance about their mean and the noise's mean square, over the frames.
  const ParameterBlock basis_block = trunk.siren.Block(ParameterGroup::kReadoutBasis);
  const Eigen::MatrixXd basis =
      LatentModulatedSiren::View(theta, basis_block);  // d x pixels, rows scale u_k
  for (int k = 0; k < 10; ++k) {
    const Eigen::VectorXd unit = basis.row(k).transpose().normalized();
    double lambda = 0, sigma2 = 0;
    for (std::size_t i = 0; i < n; ++i) {
      const Eigen::VectorXd copy = clean[i].values.col(0).cast<double>();
      lambda += std::pow((copy - clean_mean.col(0).cast<double>()).dot(unit), 2) / n;
      sigma2 += std::pow((noisy[i].values.col(0).cast<double>() - copy).dot(unit), 2) / n;
    }
    EXPECT_NEAR(gains[k], lambda / (lambda + sigma2), 1e-4) << "component " << k;
  }
  LatentModulatedSiren no_noise = trunk.siren;
  TrunkTrainer::StartReadoutFromPca(clean, 1500, &no_noise, &clean);
  EXPECT_EQ(no_noise.start_gains(), Eigen::VectorXd::Ones(10));
  // Without noisy frames the trunk has none; a wrong count is refused.
  TrunkTrainer::StartReadoutFromPca(clean, 1500, &no_noise);
  EXPECT_EQ(no_noise.start_gains().size(), 0);
  const std::vector<TrunkTargets> fewer(clean.begin(), clean.end() - 1);
  EXPECT_THROW(TrunkTrainer::StartReadoutFromPca(clean, 1500, &no_noise, &fewer),
               std::invalid_argument);
}

// The branch's PCA takes the Gram matrix when the frames are fewer than their values and
// the scatter matrix when they are more; either way its rows are the principal directions
// of the centred frames (their right singular vectors, up to sign) scaled by sqrt(P / 2),
// and the Wiener gains read the noise along them.
TEST(TrunkTrainerReadoutPca, FewerAndMoreFramesThanPixelsGiveTheSameDirectionsAsAnSvd) {
  LatentModulatedSiren::Options so;
  so.width = 8;
  so.num_hidden_layers = 1;
  so.latent_dim = 4;
  so.readout_rows = 3;
  so.readout_cols = 4;  // P = 12 values a frame
  const long p = 12;
  std::mt19937 random(7);
  std::normal_distribution<double> normal(0.0, 1.0);
  // Frames along 4 fixed directions with distinct spreads, and noisy copies of them.
  Eigen::MatrixXd directions(4, p);
  for (long i = 0; i < directions.size(); ++i) directions.data()[i] = normal(random);
  for (int frames : {8, 60}) {
    SCOPED_TRACE(std::to_string(frames) + " frames");
    std::vector<TrunkTargets> clean(frames), noisy(frames);
    for (int i = 0; i < frames; ++i) {
      Eigen::VectorXd x = Eigen::VectorXd::Constant(p, 0.5);
      for (int k = 0; k < 4; ++k) x += (4.0 - k) * normal(random) * directions.row(k).transpose();
      clean[i].values = x.cast<float>();
      clean[i].weights = Eigen::VectorXf::Ones(p);
      noisy[i] = clean[i];
      for (long j = 0; j < p; ++j) noisy[i].values(j, 0) += 0.1f * normal(random);
    }
    LatentModulatedSiren siren(so, 1);
    TrunkTrainer::StartReadoutFromPca(clean, 1000, &siren, &noisy);
    Eigen::MatrixXd X(frames, p);
    for (int i = 0; i < frames; ++i) X.row(i) = clean[i].values.col(0).cast<double>().transpose();
    X.rowwise() -= X.colwise().mean();
    const Eigen::JacobiSVD<Eigen::MatrixXd> svd(X, Eigen::ComputeThinV);
    const Eigen::MatrixXd basis = LatentModulatedSiren::View(
        siren.parameters(), siren.Block(ParameterGroup::kReadoutBasis));
    const Eigen::VectorXd& gains = siren.start_gains();
    ASSERT_EQ(gains.size(), 4);
    for (int k = 0; k < 4; ++k) {
      const Eigen::VectorXd unit = svd.matrixV().col(k);
      const Eigen::VectorXd row = basis.row(k).transpose() / std::sqrt(p / 2.0);
      EXPECT_NEAR(std::abs(row.dot(unit)), 1.0, 1e-9) << "component " << k;
      EXPECT_NEAR(row.norm(), 1.0, 1e-9) << "component " << k;
      double noise = 0;
      for (int i = 0; i < frames; ++i) {
        noise += std::pow((noisy[i].values - clean[i].values).col(0).cast<double>().dot(unit), 2);
      }
      const double signal = std::pow(svd.singularValues()[k], 2);
      EXPECT_NEAR(gains[k], signal / (signal + noise), 1e-9) << "component " << k;
    }
  }
}

TEST_F(TrunkTrainerTest, ResumingAReadoutRunIsBitIdentical) {
  TrunkTrainer::Options options = ShortOptions();
  options.readout = true;
  options.checkpoint_path = dir_.path() + "/readout.ckpt";
  SensorTrunk whole;
  TrunkTrainer::Options uninterrupted = options;
  uninterrupted.checkpoint_path.clear();
  Train(uninterrupted, &whole);
  SensorTrunk first, resumed;
  Train(options, &first, [](const TrunkTrainer::StepReport& r) { return r.step < 11; });
  options.resume = true;
  Train(options, &resumed);
  EXPECT_TRUE(SameParameters(whole, resumed));
  // A checkpoint of a run without the branch is refused, naming the field.
  TrunkTrainer::Options plain = options;
  plain.readout = false;
  SensorTrunk refused;
  EXPECT_THAT([&] { Train(plain, &refused); },
              ::testing::ThrowsMessage<std::runtime_error>(HasSubstr("readout")));
}

TEST_F(TrunkTrainerTest, ASpatialLatentRunLearnsResumesBitIdenticallyAndRecordsItsGrid) {
  // A 2 x 2 grid of 3-value latents beside 4 global values (d = 16, the tiny preset's).
  TrunkTrainer::Options options = ShortOptions();
  options.siren.spatial_rows = 2;
  options.siren.spatial_cols = 2;
  options.siren.spatial_channels = 3;
  options.checkpoint_path = dir_.path() + "/spatial.ckpt";
  TrunkTrainer::Options uninterrupted = options;
  uninterrupted.checkpoint_path.clear();
  SensorTrunk whole;
  const TrunkTrainer::Summary summary = Train(uninterrupted, &whole);
  ASSERT_EQ(summary.termination_type, TrunkTrainer::TerminationType::kCompleted)
      << summary.message;
  EXPECT_LT(summary.final_loss, summary.history.front().loss) << summary.FullReport();
  EXPECT_GT(summary.train_psnr, summary.train_psnr_at_zero) << summary.FullReport();
  EXPECT_EQ(whole.siren.options().spatial_rows, 2);
  EXPECT_EQ(whole.siren.options().spatial_channels, 3);
  EXPECT_EQ(whole.siren.options().global_latent_dim(), 4);
  EXPECT_EQ(whole.alpha.size(), 16);
  EXPECT_THAT(TrunkTrainer(options).TrajectoryOptionsJson(SensorKind::kSoftBubble, whole.format),
              HasSubstr("\"siren.spatial_channels\":3"));
  EXPECT_THAT(TrunkTrainer(ShortOptions()).TrajectoryOptionsJson(SensorKind::kSoftBubble,
                                                                  whole.format),
              ::testing::Not(HasSubstr("spatial")));
  SensorTrunk first, resumed;
  Train(options, &first, [](const TrunkTrainer::StepReport& r) { return r.step < 11; });
  options.resume = true;
  Train(options, &resumed);
  EXPECT_TRUE(SameParameters(whole, resumed));
  // A checkpoint of another grid is refused, naming the field.
  TrunkTrainer::Options other = options;
  other.siren.spatial_channels = 2;
  SensorTrunk refused;
  EXPECT_THAT([&] { Train(other, &refused); },
              ::testing::ThrowsMessage<std::runtime_error>(HasSubstr("siren.spatial_channels")));
  // A grid larger than the latent is an invalid option naming latent_dim.
  other.siren.spatial_channels = 5;  // 20 values > d = 16
  std::string error;
  EXPECT_FALSE(other.IsValid(&error));
  EXPECT_THAT(error, HasSubstr("latent_dim"));
}

TEST_F(TrunkTrainerTest, TinyRunLowersTheOuterLossAndRaisesPsnrAfterKSteps) {
  TrunkTrainer::Options options = TrunkTrainer::Preset("tiny");
  options.threads = 2;
  options.monitor_frames = 12;
  SensorTrunk trunk;
  const TrunkTrainer::Summary summary = Train(options, &trunk);
  ASSERT_EQ(summary.termination_type, TrunkTrainer::TerminationType::kCompleted) << summary.message;
  EXPECT_EQ(summary.steps_done, options.steps);
  EXPECT_EQ(summary.num_train_frames, 12);
  ASSERT_GE(summary.history.size(), 2u);
  const TrunkTrainer::HistoryPoint& first = summary.history.front();
  EXPECT_EQ(first.step, 0);
  // The outer loss after K steps falls severalfold from the SIREN initialisation ...
  EXPECT_LT(summary.final_loss, 0.25 * first.loss) << summary.FullReport();
  // ... the PSNR after K steps rises by several dB, and beats the trunk alone (z = 0).
  EXPECT_GT(summary.train_psnr, first.psnr + 5.0) << summary.FullReport();
  EXPECT_GT(summary.train_psnr, summary.train_psnr_at_zero + 3.0) << summary.FullReport();
  // The trunk is filled in: sizes, rates in [0, 1], the residual scale.
  EXPECT_EQ(trunk.sensor, SensorKind::kSoftBubble);
  EXPECT_EQ(trunk.format.rows, 16);
  EXPECT_EQ(trunk.format.cols, 20);
  EXPECT_EQ(trunk.siren.output_channels(), 1);
  EXPECT_EQ(trunk.siren.latent_dim(), 16);
  ASSERT_EQ(trunk.alpha.size(), 16);
  EXPECT_GE(trunk.alpha.minCoeff(), 0.0);
  EXPECT_LE(trunk.alpha.maxCoeff(), 1.0);
  EXPECT_GT(trunk.residual_sigma, 0.0);
  EXPECT_EQ(trunk.residual_sigma, summary.residual_sigma);
  EXPECT_THAT(summary.BriefReport(), HasSubstr("completed"));
  EXPECT_THAT(summary.FullReport(), HasSubstr("residual sigma"));
}

TEST_F(TrunkTrainerTest, TheRatesStayWithinTheirClipBoundAndALargerBoundLetsThemPassOne) {
  TrunkTrainer::Options options = ShortOptions();
  options.checkpoint_every = 0;
  options.alpha_learning_rate = 0.5;  // large, so that 24 steps reach the bounds
  SensorTrunk clipped;
  ASSERT_EQ(Train(options, &clipped).termination_type, TrunkTrainer::TerminationType::kCompleted);
  EXPECT_GE(clipped.alpha.minCoeff(), 0.0);
  EXPECT_LE(clipped.alpha.maxCoeff(), 1.0);

  options.alpha_max = 4.0;
  options.alpha_init_min = options.alpha_init_max = 3.0;
  SensorTrunk lifted;
  ASSERT_EQ(Train(options, &lifted).termination_type, TrunkTrainer::TerminationType::kCompleted);
  EXPECT_GE(lifted.alpha.minCoeff(), 0.0);
  EXPECT_LE(lifted.alpha.maxCoeff(), 4.0);
  EXPECT_GT(lifted.alpha.maxCoeff(), 1.0);
  // The bound belongs to the trajectory: a resume must not change it.
  EXPECT_THAT(TrunkTrainer(options).TrajectoryOptionsJson(SensorKind::kSoftBubble, lifted.format),
              HasSubstr("\"alpha_max\":4"));
  EXPECT_THAT(TrunkTrainer(ShortOptions()).TrajectoryOptionsJson(SensorKind::kSoftBubble,
                                                                  lifted.format),
              ::testing::Not(HasSubstr("alpha_max")));
}

TEST_F(TrunkTrainerTest, TheDivergenceCheckDoesNotTouchARunThatDoesNotDiverge) {
  TrunkTrainer::Options options = ShortOptions();
  SensorTrunk checked, unchecked;
  ASSERT_EQ(Train(options, &checked).termination_type, TrunkTrainer::TerminationType::kCompleted);
  options.divergence_drop_db = 0;
  ASSERT_EQ(Train(options, &unchecked).termination_type,
            TrunkTrainer::TerminationType::kCompleted);
  EXPECT_TRUE(SameParameters(checked, unchecked));
  // Nor is it part of the trajectory a resume must match.
  EXPECT_EQ(TrunkTrainer(options).TrajectoryOptionsJson(SensorKind::kSoftBubble, checked.format),
            TrunkTrainer(ShortOptions())
                .TrajectoryOptionsJson(SensorKind::kSoftBubble, checked.format));
}

TEST_F(TrunkTrainerTest, SameSeedGivesTheSameModelWhateverTheThreadCount) {
  TrunkTrainer::Options options = ShortOptions();
  SensorTrunk one, two, three, other_seed;
  options.threads = 1;
  Train(options, &one);
  options.threads = 2;
  Train(options, &two);
  options.threads = 3;
  Train(options, &three);
  EXPECT_TRUE(SameParameters(one, two));
  EXPECT_TRUE(SameParameters(one, three));
  EXPECT_EQ(one.residual_sigma, three.residual_sigma);
  options.seed = 1;
  Train(options, &other_seed);
  EXPECT_FALSE(SameParameters(one, other_seed));
}

TEST_F(TrunkTrainerTest, StoppingAndResumingIsBitIdenticalToAnUninterruptedRun) {
  TrunkTrainer::Options options = ShortOptions();
  SensorTrunk uninterrupted;
  Train(options, &uninterrupted);

  // Stopped by the callback after step 11 (between checkpoints and monitor points).
  options.checkpoint_path = dir_ / "run.ckpt";
  SensorTrunk stopped;
  const TrunkTrainer::Summary first = Train(
      options, &stopped, [](const TrunkTrainer::StepReport& report) { return report.step < 11; });
  EXPECT_EQ(first.termination_type, TrunkTrainer::TerminationType::kUserStopped);
  EXPECT_EQ(first.steps_done, 11);
  EXPECT_FALSE(SameParameters(stopped, uninterrupted));

  options.resume = true;
  options.threads = 1;  // a different thread count on resume changes nothing
  SensorTrunk resumed;
  const TrunkTrainer::Summary second = Train(options, &resumed);
  EXPECT_EQ(second.termination_type, TrunkTrainer::TerminationType::kCompleted);
  EXPECT_EQ(second.start_step, 11);
  EXPECT_EQ(second.steps_done, options.steps);
  EXPECT_TRUE(SameParameters(resumed, uninterrupted));
  EXPECT_EQ(resumed.residual_sigma, uninterrupted.residual_sigma);
}

TEST_F(TrunkTrainerTest, WithACosineDecayResumingIsStillBitIdenticalAndTheDecayChangesTheModel) {
  TrunkTrainer::Options options = ShortOptions();
  SensorTrunk constant;
  Train(options, &constant);
  options.learning_rate_final_fraction = 0.1;
  SensorTrunk uninterrupted;
  Train(options, &uninterrupted);
  EXPECT_FALSE(SameParameters(uninterrupted, constant));

  options.checkpoint_path = dir_ / "decay.ckpt";
  SensorTrunk stopped;
  Train(options, &stopped, [](const TrunkTrainer::StepReport& report) { return report.step < 11; });
  options.resume = true;
  SensorTrunk resumed;
  const TrunkTrainer::Summary second = Train(options, &resumed);
  EXPECT_EQ(second.start_step, 11);
  EXPECT_TRUE(SameParameters(resumed, uninterrupted));
}

TEST_F(TrunkTrainerTest, ExtendingAFinishedRunEqualsTrainingLongerAtOnce) {
  TrunkTrainer::Options options = ShortOptions();
  SensorTrunk at_once;
  Train(options, &at_once);  // 24 steps

  options.checkpoint_path = dir_ / "run.ckpt";
  options.steps = 12;
  SensorTrunk half;
  Train(options, &half);
  options.steps = 24;
  options.resume = true;
  SensorTrunk extended;
  const TrunkTrainer::Summary summary = Train(options, &extended);
  EXPECT_EQ(summary.start_step, 12);
  EXPECT_TRUE(SameParameters(extended, at_once));
}

TEST_F(TrunkTrainerTest, TheOuterLossOnNoiseFreeCopiesIsWiredToTheCleanFrames) {
  TrunkTrainer::Options options = ShortOptions();
  options.checkpoint_every = 0;
  const TrunkTrainer plain_trainer(options);
  options.outer_loss_on_clean = true;
  const TrunkTrainer clean_trainer(options);
  const FrameFormat format = plain_trainer.ResolveFormat(
      SensorKind::kSoftBubble, dataset_->sensor_info(SensorKind::kSoftBubble).normalization_scale);
  const std::vector<std::size_t> indices =
      dataset_->FrameIndices(SensorKind::kSoftBubble, Split::kTrain);
  const std::vector<TrunkTargets> noisy =
      LoadTrunkTargets(*dataset_, indices, format, /*clean=*/false, 2);
  const std::vector<TrunkTargets> clean =
      LoadTrunkTargets(*dataset_, indices, format, /*clean=*/true, 2);

  // Outer targets equal to the inner ones: the plain run, bit for bit.
  SensorTrunk plain, same, on_clean, from_dataset;
  plain_trainer.Train(noisy, SensorKind::kSoftBubble, format, 1, &plain);
  clean_trainer.Train(noisy, SensorKind::kSoftBubble, format, 1, &same, nullptr, &noisy);
  EXPECT_TRUE(SameParameters(plain, same));
  // The noise-free copies change the run; the dataset overload reads them itself.
  clean_trainer.Train(noisy, SensorKind::kSoftBubble, format, 1, &on_clean, nullptr, &clean);
  EXPECT_FALSE(SameParameters(plain, on_clean));
  clean_trainer.Train(*dataset_, SensorKind::kSoftBubble, &from_dataset);
  EXPECT_TRUE(SameParameters(on_clean, from_dataset));
  // Without the copies, or with copies of another size, the run is refused.
  EXPECT_THROW(clean_trainer.Train(noisy, SensorKind::kSoftBubble, format, 1, &same),
               std::invalid_argument);
  std::vector<TrunkTargets> short_copies(clean.begin(), clean.end() - 1);
  EXPECT_THROW(
      clean_trainer.Train(noisy, SensorKind::kSoftBubble, format, 1, &same, nullptr, &short_copies),
      std::invalid_argument);
  // It shapes the trajectory: a checkpoint of the plain run does not resume it.
  EXPECT_THAT(clean_trainer.TrajectoryOptionsJson(SensorKind::kSoftBubble, format),
              HasSubstr("\"outer_loss_on_clean\":true"));
  EXPECT_THAT(plain_trainer.TrajectoryOptionsJson(SensorKind::kSoftBubble, format),
              Not(HasSubstr("outer_loss_on_clean")));
}

TEST_F(TrunkTrainerTest, TheOuterLossOnNoiseFreeCopiesNamesAFrameWithoutOne) {
  TestDir dir;
  SynthesisPlan plan;
  plan.out = dir.path() + "/noisy_only";
  plan.tools = {"hemisphere"};
  plan.sensors = {SensorKind::kSoftBubble};
  plan.frames_per_tool = 2;
  plan.test_fraction = 0.0;
  Synthesize(plan, ContactSimulator::Options());
  TrunkTrainer::Options options = ShortOptions();
  options.outer_loss_on_clean = true;
  SensorTrunk trunk;
  try {
    TrunkTrainer(options).Train(Dataset::Open(plan.out), SensorKind::kSoftBubble, &trunk);
    FAIL() << "expected std::runtime_error";
  } catch (const std::runtime_error& e) {
    EXPECT_THAT(e.what(), HasSubstr("clean copy"));
    EXPECT_THAT(e.what(), HasSubstr("noisy_only"));
    EXPECT_THAT(e.what(), HasSubstr("synth --clean"));
  }
}

TEST_F(TrunkTrainerTest, ResumeWithoutACheckpointStartsAtStepZero) {
  TrunkTrainer::Options options = ShortOptions();
  options.checkpoint_path = dir_ / "absent.ckpt";
  options.resume = true;
  SensorTrunk trunk;
  const TrunkTrainer::Summary summary = Train(options, &trunk);
  EXPECT_EQ(summary.start_step, 0);
  EXPECT_EQ(summary.steps_done, options.steps);
}

TEST_F(TrunkTrainerTest, ResumeRejectsMismatchedOptionsNamingTheField) {
  TrunkTrainer::Options options = ShortOptions();
  options.steps = 5;
  options.checkpoint_path = dir_ / "run.ckpt";
  SensorTrunk trunk;
  Train(options, &trunk);

  options.resume = true;
  options.steps = 10;
  TrunkTrainer::Options changed = options;
  changed.learning_rate *= 2;
  try {
    Train(changed, &trunk);
    FAIL() << "expected std::runtime_error";
  } catch (const std::runtime_error& e) {
    EXPECT_THAT(e.what(), HasSubstr("learning_rate"));
    EXPECT_THAT(e.what(), HasSubstr("run.ckpt"));
  }
  changed = options;
  changed.siren.latent_dim = 8;
  EXPECT_THROW(
      {
        try {
          Train(changed, &trunk);
        } catch (const std::runtime_error& e) {
          EXPECT_THAT(e.what(), HasSubstr("siren.latent_dim"));
          throw;
        }
      },
      std::runtime_error);
  // Other training frames (here: fewer of them) are refused too.
  const std::vector<std::size_t> indices =
      dataset_->FrameIndices(SensorKind::kSoftBubble, Split::kTrain);
  const TrunkTrainer trainer(options);
  const FrameFormat format = trainer.ResolveFormat(
      SensorKind::kSoftBubble, dataset_->sensor_info(SensorKind::kSoftBubble).normalization_scale);
  std::vector<TrunkTargets> frames;
  for (std::size_t i = 0; i + 1 < indices.size(); ++i) {
    frames.push_back(LoadTrunkTargets(*dataset_, indices[i], format));
  }
  try {
    trainer.Train(frames, SensorKind::kSoftBubble, format, 42, &trunk);
    FAIL() << "expected std::runtime_error";
  } catch (const std::runtime_error& e) {
    EXPECT_THAT(e.what(), HasSubstr("training frames differ"));
  }
  // Options that do not shape the trajectory may change.
  changed = options;
  changed.threads = 1;
  changed.monitor_every = 3;
  changed.checkpoint_every = 0;
  EXPECT_NO_THROW(Train(changed, &trunk));
}

TEST_F(TrunkTrainerTest, CorruptCheckpointGivesAClearError) {
  TrunkTrainer::Options options = ShortOptions();
  options.steps = 5;
  options.checkpoint_path = dir_ / "run.ckpt";
  SensorTrunk trunk;
  Train(options, &trunk);
  std::string bytes;
  {
    std::ifstream in(options.checkpoint_path, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }
  ASSERT_GT(bytes.size(), 100u);
  bytes[bytes.size() - 50] ^= 0x55;  // a payload byte: only the checksum notices
  {
    std::ofstream out(options.checkpoint_path, std::ios::binary | std::ios::trunc);
    out << bytes;
  }
  options.resume = true;
  options.steps = 10;
  try {
    Train(options, &trunk);
    FAIL() << "expected TensorFileError";
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("cannot resume from checkpoint"));
    EXPECT_THAT(e.what(), HasSubstr("run.ckpt"));
  }
  // A file of another kind (a model) is refused as well.
  FunctaModel model;
  model.SetTrunk(trunk);
  model.Save(options.checkpoint_path);
  EXPECT_THROW(Train(options, &trunk), TensorFileError);
}

}  // namespace
}  // namespace tactfunc
