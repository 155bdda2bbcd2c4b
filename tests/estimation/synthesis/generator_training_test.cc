// Copyright 2026 The tactfunc Authors.
#include "estimation/synthesis/generator_training.h"

#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <stdexcept>
#include <string>
#include <vector>

#include "models/core/tensor_file.h"
#include "tests/support/sampler_test_util.h"
#include "tests/support/test_dir.h"

namespace tactfunc {
namespace {

namespace fs = std::filesystem;

constexpr int kGenRows = 8, kGenCols = 9, kGenLatent = 5;

PoseGenerator TinyGenerator() { return testing_util::MakeTinyGenerator(kGenLatent, 10, 7); }

// Labelled samples whose latents and frames a fixed generator renders through a tiny trunk.
struct Data {
  SensorTrunk trunk = testing_util::MakeTinyTrunk(kGenRows, kGenCols, 12, 2, kGenLatent, 3);
  std::vector<GeneratorSample> samples;
  Eigen::MatrixXd latents;
  std::vector<TrunkTargets> frames;
  Data() {
    PoseGenerator truth = TinyGenerator();
    truth.SetLatentStandardization(Eigen::VectorXd::Zero(kGenLatent),
                                   Eigen::VectorXd::Constant(kGenLatent, 0.5));
    const int m = 24;
    latents.resize(m, kGenLatent);
    for (int i = 0; i < m; ++i) {
      const GeneratorSample s{i % 2, SE2d::FromXYYaw(1e-3 * (i % 5 - 2), 1e-3 * (i % 3 - 1), 0.4 * i),
                              0.004 + 0.0005 * (i % 7)};
      samples.push_back(s);
      const Eigen::VectorXd z = truth.Generate(s.tool, s.sensor_T_object, s.depth_m);
      latents.row(i) = z.transpose();
      frames.push_back(testing_util::MakeTargets(trunk, z, 0.0, 1));
    }
  }
};

GeneratorTrainingOptions Options(const std::string& checkpoint) {
  GeneratorTrainingOptions o;
  o.epochs = 6;
  o.batch_size = 8;
  o.pixels_per_frame = 20;
  o.seed = 11;
  o.checkpoint_path = checkpoint;
  o.checkpoint_every = 2;
  return o;
}

class GeneratorTrainingCheckpoint : public ::testing::Test {
 protected:
  std::string Path(const std::string& name) const { return dir_ / name; }
  testing_util::TestDir dir_;
};

// Trains (regression, then pixels) straight through, and stopped after `stop_after` epochs
// of each stage then resumed; returns both generators' parameters.
std::pair<Eigen::VectorXd, Eigen::VectorXd> StraightAndResumed(const Data& d,
                                                                const std::string& dir,
                                                                int stop_after) {
  PoseGenerator straight = TinyGenerator();
  GeneratorTrainingOptions o = Options("");
  TrainGeneratorOnLatents(&straight, d.samples, d.latents, o);
  o.standardize_outputs = false;
  TrainGeneratorOnPixels(&straight, d.trunk, d.samples, d.frames, o);

  PoseGenerator resumed = TinyGenerator();
  auto stop = [stop_after](int epoch, double) { return epoch + 1 < stop_after; };
  GeneratorTrainingOptions r = Options(dir + "/regression.ckpt");
  GeneratorTrainingSummary s = TrainGeneratorOnLatents(&resumed, d.samples, d.latents, r, stop);
  EXPECT_EQ(s.epochs_completed, stop_after);
  r.resume = true;
  PoseGenerator again = TinyGenerator();  // a fresh process: only the checkpoint carries over
  s = TrainGeneratorOnLatents(&again, d.samples, d.latents, r);
  EXPECT_EQ(s.epochs_resumed, stop_after);
  EXPECT_EQ(s.epochs_completed, r.epochs);
  EXPECT_EQ(static_cast<int>(s.loss_history.size()), r.epochs);
  GeneratorTrainingOptions p = Options(dir + "/pixels.ckpt");
  p.standardize_outputs = false;
  s = TrainGeneratorOnPixels(&again, d.trunk, d.samples, d.frames, p, stop);
  EXPECT_EQ(s.epochs_completed, stop_after);
  p.resume = true;
  const Eigen::VectorXd stopped_params = again.parameters();
  PoseGenerator last = again;  // the regressed generator, as the command reloads it
  s = TrainGeneratorOnPixels(&last, d.trunk, d.samples, d.frames, p);
  EXPECT_EQ(s.epochs_resumed, stop_after);
  EXPECT_NE(stopped_params, last.parameters());
  return {straight.parameters(), last.parameters()};
}

TEST_F(GeneratorTrainingCheckpoint, AStoppedAndResumedRunEqualsOneNeverStopped) {
  const Data d;
  for (int stop_after : {1, 3}) {  // between and on a periodic checkpoint
    const auto [straight, resumed] = StraightAndResumed(d, dir_.path(), stop_after);
    EXPECT_EQ(straight, resumed) << "stopped after " << stop_after;
    fs::remove(Path("regression.ckpt"));
    fs::remove(Path("pixels.ckpt"));
  }
}

TEST_F(GeneratorTrainingCheckpoint, ResumeWithoutACheckpointStartsAnewAndOthersAreRefused) {
  const Data d;
  GeneratorTrainingOptions o = Options(Path("regression.ckpt"));
  o.resume = true;  // no file yet: starts at epoch 0
  PoseGenerator g = TinyGenerator();
  GeneratorTrainingSummary s = TrainGeneratorOnLatents(&g, d.samples, d.latents, o);
  EXPECT_EQ(s.epochs_resumed, 0);
  EXPECT_EQ(s.epochs_completed, o.epochs);
  ASSERT_TRUE(fs::exists(o.checkpoint_path));  // written at the end

  // Another trajectory option: refused, naming it.
  GeneratorTrainingOptions other = o;
  other.learning_rate *= 2;
  PoseGenerator h = TinyGenerator();
  try {
    TrainGeneratorOnLatents(&h, d.samples, d.latents, other);
    FAIL() << "expected a refusal";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("learning_rate"), std::string::npos) << e.what();
  }
  // Other samples: refused, naming the frames.
  Data changed;
  changed.latents(0, 0) += 1;
  try {
    TrainGeneratorOnLatents(&h, changed.samples, changed.latents, o);
    FAIL() << "expected a refusal";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("training frames differ"), std::string::npos) << e.what();
  }
  // The other stage's checkpoint: refused (its stage differs).
  GeneratorTrainingOptions p = o;
  p.standardize_outputs = false;
  EXPECT_THROW(TrainGeneratorOnPixels(&h, d.trunk, d.samples, d.frames, p), std::runtime_error);
  // A corrupt file: a TensorFileError naming it.
  { std::ofstream(o.checkpoint_path, std::ios::trunc) << "not a checkpoint"; }
  EXPECT_THROW(TrainGeneratorOnLatents(&h, d.samples, d.latents, o), TensorFileError);
}

// Frames another trunk drew: a frozen trunk cannot render them however the generator
// moves, a trunk trained along can come closer.
TEST(GeneratorTrainingTunedTrunk, TrainingTheTrunkAlongFitsFramesTheFrozenOneCannot) {
  const Data d;
  const SensorTrunk other = testing_util::MakeTinyTrunk(kGenRows, kGenCols, 12, 2, kGenLatent, 4);
  GeneratorTrainingOptions o = Options("");
  o.epochs = 40;
  o.standardize_outputs = false;
  PoseGenerator frozen = TinyGenerator();
  const GeneratorTrainingSummary f = TrainGeneratorOnPixels(&frozen, other, d.samples, d.frames, o);
  LatentModulatedSiren untouched = other.siren;  // fraction 0: the argument is not written
  PoseGenerator frozen_again = TinyGenerator();
  TrainGeneratorOnPixels(&frozen_again, other, d.samples, d.frames, o, {}, &untouched);
  EXPECT_EQ(untouched.parameters(), other.siren.parameters());
  EXPECT_EQ(frozen_again.parameters(), frozen.parameters());

  o.trunk_step_fraction = 1;
  PoseGenerator joint = TinyGenerator();
  LatentModulatedSiren tuned = other.siren;
  const SensorTrunk before = other;
  const GeneratorTrainingSummary j =
      TrainGeneratorOnPixels(&joint, other, d.samples, d.frames, o, {}, &tuned);
  EXPECT_EQ(other.siren.parameters(), before.siren.parameters());  // the input stays
  EXPECT_NE(tuned.parameters(), other.siren.parameters());
  EXPECT_LT(j.final_loss, 0.5 * f.final_loss) << "frozen " << f.final_loss;
  // Rendered through the tuned trunk the generator draws the frames better than through
  // the frozen one (a trunk with the tuned SIREN).
  SensorTrunk tuned_trunk = other;
  tuned_trunk.siren = tuned;
  EXPECT_GT(MeanGeneratorPsnr(joint, tuned_trunk, d.samples, d.frames),
            MeanGeneratorPsnr(frozen, other, d.samples, d.frames) + 1);
}

TEST_F(GeneratorTrainingCheckpoint, ATunedTrunkResumesBitForBit) {
  const Data d;
  GeneratorTrainingOptions o = Options("");
  o.standardize_outputs = false;
  o.trunk_step_fraction = 0.5;
  PoseGenerator straight = TinyGenerator();
  LatentModulatedSiren straight_siren = d.trunk.siren;
  TrainGeneratorOnPixels(&straight, d.trunk, d.samples, d.frames, o, {}, &straight_siren);

  o.checkpoint_path = Path("pixels.ckpt");
  PoseGenerator stopped = TinyGenerator();
  LatentModulatedSiren siren = d.trunk.siren;
  auto stop = [](int epoch, double) { return epoch + 1 < 3; };
  EXPECT_EQ(TrainGeneratorOnPixels(&stopped, d.trunk, d.samples, d.frames, o, stop, &siren)
                .epochs_completed,
            3);
  o.resume = true;
  PoseGenerator resumed = TinyGenerator();  // a fresh process: only the checkpoint carries over
  LatentModulatedSiren resumed_siren = d.trunk.siren;
  EXPECT_EQ(TrainGeneratorOnPixels(&resumed, d.trunk, d.samples, d.frames, o, {}, &resumed_siren)
                .epochs_resumed,
            3);
  EXPECT_EQ(resumed.parameters(), straight.parameters());
  EXPECT_EQ(resumed_siren.parameters(), straight_siren.parameters());
  // The tuned run's checkpoint is another run than a frozen trunk's: refused.
  o.trunk_step_fraction = 0;
  PoseGenerator g = TinyGenerator();
  try {
    TrainGeneratorOnPixels(&g, d.trunk, d.samples, d.frames, o);
    FAIL() << "expected a refusal";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("differs"), std::string::npos) << e.what();
  }
}

TEST(GeneratorTrainingTunedTrunk, MisuseIsRefused) {
  const Data d;
  GeneratorTrainingOptions o = Options("");
  o.trunk_step_fraction = 0.1;
  PoseGenerator g = TinyGenerator();
  // Nowhere to write the tuned trunk.
  EXPECT_THROW(TrainGeneratorOnPixels(&g, d.trunk, d.samples, d.frames, o), std::invalid_argument);
  // Regression has no trunk to tune.
  EXPECT_THROW(TrainGeneratorOnLatents(&g, d.samples, d.latents, o), std::invalid_argument);
  o.trunk_step_fraction = -0.1;
  std::string error;
  EXPECT_FALSE(o.IsValid(&error));
  EXPECT_NE(error.find("trunk_step_fraction"), std::string::npos) << error;
}

TEST(GeneratorTrainingOptions, CheckpointFieldsAreValidated) {
  GeneratorTrainingOptions o;
  std::string error;
  o.checkpoint_every = 0;
  EXPECT_FALSE(o.IsValid(&error));
  EXPECT_NE(error.find("checkpoint_every"), std::string::npos) << error;
  o = GeneratorTrainingOptions();
  o.resume = true;
  EXPECT_FALSE(o.IsValid(&error));
  EXPECT_NE(error.find("resume"), std::string::npos) << error;
}

}  // namespace
}  // namespace tactfunc
