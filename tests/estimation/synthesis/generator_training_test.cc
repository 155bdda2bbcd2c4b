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

constexpr int kRows = 8, kCols = 9, kLatent = 5;

PoseGenerator Generator() { return testing_util::MakeTinyGenerator(kLatent, 10, 7); }

// Labelled samples whose latents and frames a fixed generator renders through a tiny trunk.
struct Data {
  SensorTrunk trunk = testing_util::MakeTinyTrunk(kRows, kCols, 12, 2, kLatent, 3);
  std::vector<GeneratorSample> samples;
  Eigen::MatrixXd latents;
  std::vector<TrunkTargets> frames;
  Data() {
    PoseGenerator truth = Generator();
    truth.SetLatentStandardization(Eigen::VectorXd::Zero(kLatent),
                                   Eigen::VectorXd::Constant(kLatent, 0.5));
    const int m = 24;
    latents.resize(m, kLatent);
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
  PoseGenerator straight = Generator();
  GeneratorTrainingOptions o = Options("");
  TrainGeneratorOnLatents(&straight, d.samples, d.latents, o);
  o.standardize_outputs = false;
  TrainGeneratorOnPixels(&straight, d.trunk, d.samples, d.frames, o);

  PoseGenerator resumed = Generator();
  auto stop = [stop_after](int epoch, double) { return epoch + 1 < stop_after; };
  GeneratorTrainingOptions r = Options(dir + "/regression.ckpt");
  GeneratorTrainingSummary s = TrainGeneratorOnLatents(&resumed, d.samples, d.latents, r, stop);
  EXPECT_EQ(s.epochs_completed, stop_after);
  r.resume = true;
  PoseGenerator again = Generator();  // a fresh process: only the checkpoint carries over
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
  PoseGenerator g = Generator();
  GeneratorTrainingSummary s = TrainGeneratorOnLatents(&g, d.samples, d.latents, o);
  EXPECT_EQ(s.epochs_resumed, 0);
  EXPECT_EQ(s.epochs_completed, o.epochs);
  ASSERT_TRUE(fs::exists(o.checkpoint_path));  // written at the end

  // Another trajectory option: refused, naming it.
  GeneratorTrainingOptions other = o;
  other.learning_rate *= 2;
  PoseGenerator h = Generator();
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
