// Copyright 2026 The tactfunc Authors.
//
// PhotometricTrainer and FitPhotometricLatent: training lowers the loss on frames drawn
// by a teacher trunk and is bit-identical for any thread count; a fit of a frame the
// trunk drew from a known latent comes close to it; the moment pose finds a contact's
// centre and axis; a run stopped and resumed from its checkpoint is bit-identical to one
// that never stopped, and a checkpoint of other options or frames is refused by name;
// noise on the training latents teaches the trunk to draw from near them; bad options
// and frames are refused by name.
#include "estimation/training/photometric_trainer.h"

#include <cmath>
#include <filesystem>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "Eigen/QR"
#include "gtest/gtest.h"
#include "models/core/internal/checks.h"
#include "tests/support/photometric_test_util.h"

namespace tactfunc {
namespace {

using internal::kPi;

PhotometricTrunk::Options SmallTrunk() { return testing_util::SmallPhotometricOptions(12, 16); }

using testing_util::MarkerReference;
using testing_util::WholeFrameTargets;

// Frames drawn by a teacher trunk (its markers moving) from latents with varied poses.
struct Teacher {
  PhotometricTrunk trunk;
  std::vector<Eigen::VectorXd> latents;
  std::vector<TrunkTargets> frames;
};

Teacher MakeTeacher(int count) {
  const PhotometricTrunk::Options o = SmallTrunk();
  Teacher t{PhotometricTrunk(o, MarkerReference(2 * o.rows, 2 * o.cols), 42), {}, {}};
  Eigen::VectorXd head = t.trunk.head_parameters();
  head[head.size() - 1] = 0.8;
  t.trunk.SetHeadParameters(head);
  unsigned state = 3;
  auto uniform = [&state] {
    state = state * 1664525u + 1013904223u;
    return 2.0 * (state >> 8) / double(1u << 24) - 1.0;
  };
  for (int i = 0; i < count; ++i) {
    Eigen::VectorXd z(o.latent_dim);
    for (int k = 0; k < z.size(); ++k) z[k] = 0.5 * uniform();
    z[2] = kPi * uniform();
    t.latents.push_back(z);
    t.frames.push_back(WholeFrameTargets(
        t.trunk.Forward<float>(t.trunk.AllPixels(), z.cast<float>()), o.rows, o.cols));
  }
  return t;
}

PhotometricTrainer::Options QuickOptions(int threads) {
  PhotometricTrainer::Options o;
  o.trunk = SmallTrunk();
  o.steps = 150;
  o.batch_frames = 6;
  o.batch_pixels = 64;
  o.trunk_learning_rate = 2e-3;
  o.marker_warmup_steps = 20;
  o.threads = threads;
  return o;
}

TEST(PhotometricTrainerTest, TrainingLowersTheLossAndIsTheSameForAnyThreadCount) {
  const Teacher teacher = MakeTeacher(12);
  const Image reference = teacher.trunk.reference();
  const PhotometricTrainer::Result one =
      PhotometricTrainer(QuickOptions(1)).Train(teacher.frames, reference);
  const PhotometricTrainer::Result two =
      PhotometricTrainer(QuickOptions(2)).Train(teacher.frames, reference);
  ASSERT_EQ(one.summary.steps, 150);
  ASSERT_EQ(one.summary.loss.size(), 150u);
  double first = 0, last = 0;
  for (int k = 0; k < 10; ++k) {
    first += one.summary.loss[k];
    last += one.summary.loss[140 + k];
  }
  EXPECT_LT(last, 0.7 * first) << "first 10 steps " << first / 10 << ", last " << last / 10;
  EXPECT_EQ(one.summary.loss, two.summary.loss);
  EXPECT_EQ(one.trunk.siren().parameters(), two.trunk.siren().parameters());
  EXPECT_EQ(one.trunk.head_parameters(), two.trunk.head_parameters());
  EXPECT_EQ(one.latents, two.latents);
  EXPECT_EQ(one.latents.rows(), 12);
  // The trained trunk samples its markers at the sensor's resolution.
  EXPECT_EQ(one.trunk.marker_sampling(), PhotometricTrunk::MarkerSampling::kSensorResolution);
}

TEST(PhotometricTrainerTest, EachFrameIsDrawnAgainstItsOwnClipsReference) {
  // Frames of two clips: training with a reference per frame is, bit for bit, training
  // on the reference the frames are drawn against; a frame's reference changes the run.
  const Teacher teacher = MakeTeacher(6);
  const Image a = teacher.trunk.reference();
  Image b(a.rows, a.cols, 1);
  for (int r = 0; r < a.rows; ++r) {
    for (int c = 0; c < a.cols; ++c) b.at(r, c) = a.at((r + 1) % a.rows, (c + 2) % a.cols);
  }
  PhotometricTrainer::Options options = QuickOptions(1);
  options.steps = 40;
  const PhotometricTrainer trainer(options);
  const PhotometricTrainer::Result all_b =
      trainer.Train(teacher.frames, std::vector<Image>{a, b}, std::vector<int>(6, 1));
  const PhotometricTrainer::Result on_b = trainer.Train(teacher.frames, b);
  EXPECT_EQ(all_b.summary.loss, on_b.summary.loss);
  EXPECT_EQ(all_b.trunk.head_parameters(), on_b.trunk.head_parameters());
  EXPECT_EQ(all_b.latents, on_b.latents);
  // The trunk keeps the first reference as its own.
  EXPECT_EQ(all_b.trunk.reference().data, a.data);
  const PhotometricTrainer::Result mixed =
      trainer.Train(teacher.frames, std::vector<Image>{a, b}, std::vector<int>{0, 1, 0, 1, 0, 1});
  const PhotometricTrainer::Result on_a = trainer.Train(teacher.frames, a);
  EXPECT_NE(mixed.summary.loss, on_a.summary.loss);
  EXPECT_NE(mixed.summary.loss, on_b.summary.loss);
  // Bad references and indices are refused by name.
  EXPECT_THROW(trainer.Train(teacher.frames, std::vector<Image>{}, std::vector<int>(6, 0)),
               std::invalid_argument);
  EXPECT_THROW(trainer.Train(teacher.frames, std::vector<Image>{a}, std::vector<int>(5, 0)),
               std::invalid_argument);
  try {
    trainer.Train(teacher.frames, std::vector<Image>{a, b}, std::vector<int>{0, 1, 2, 0, 0, 0});
    FAIL() << "accepted a reference index outside the references";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("frame 2"), std::string::npos) << e.what();
  }
}

// Frames the teacher drew plus a pattern every frame shares: the mean residual at the
// teacher's latents is that pattern (a pixel no frame weighs is left 0), whatever the
// thread count; with it as the background the frames are drawn exactly, and a second
// step finds nothing left. Frames of a clip are drawn against their own markers.
// A run of *o checkpointed to `path` (every 100 steps, resumed), stopped by its callback
// at step 130, then resumed to its end: the resumed run's result. *o keeps the
// checkpoint settings for the caller's further runs.
PhotometricTrainer::Result StoppedAndResumed(PhotometricTrainer::Options* o,
                                             const std::vector<TrunkTargets>& frames,
                                             const Image& reference, const std::string& path) {
  std::filesystem::remove(path);
  o->checkpoint_path = path;
  o->checkpoint_every = 100;
  o->resume = true;
  EXPECT_TRUE(PhotometricTrainer(*o)
                  .Train(frames, reference, [](int step, double) { return step < 130; })
                  .summary.stopped);
  return PhotometricTrainer(*o).Train(frames, reference);
}

// The loss of every training frame at its training latent, whole frames, summed.
double SummedLoss(const PhotometricTrainer::Result& r, const std::vector<TrunkTargets>& frames) {
  double sum = 0;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    sum += r.trunk.LossAndGradient<float>(r.trunk.AllPixels(),
                                          r.latents.row(i).transpose().cast<float>(),
                                          frames[i].values, frames[i].weights, nullptr, nullptr,
                                          nullptr);
  }
  return sum;
}

TEST(PhotometricTrainerTest, TheMeanResidualIsWhatEveryFrameSharesBesidesItsContact) {
  Teacher teacher = MakeTeacher(5);
  const PhotometricTrunk::Options o = SmallTrunk();
  Image pattern(o.rows, o.cols, 1);
  for (int r = 0; r < o.rows; ++r) {
    for (int c = 0; c < o.cols; ++c) {
      pattern.at(r, c) = 0.01f * static_cast<float>((r * 7 + c * 3) % 5 - 2);
    }
  }
  const int unweighed = 17;
  Eigen::MatrixXd latents(5, o.latent_dim);
  for (int i = 0; i < 5; ++i) {
    latents.row(i) = teacher.latents[i].transpose();
    TrunkTargets& t = teacher.frames[i];
    for (int j = 0; j < o.rows * o.cols; ++j) t.values(j, 0) += pattern.data[j];
    t.weights[unweighed] = 0;
  }
  const std::vector<const PhotometricTrunk::Markers*> own = {nullptr};
  const std::vector<int> first(5, 0);
  const Image mean =
      PhotometricTrainer::MeanResidual(teacher.trunk, teacher.frames, latents, own, first, 100, 1);
  const Image mean2 =
      PhotometricTrainer::MeanResidual(teacher.trunk, teacher.frames, latents, own, first, 100, 2);
  EXPECT_EQ(mean.data, mean2.data);
  ASSERT_TRUE(mean.SameShape(pattern));
  for (int j = 0; j < o.rows * o.cols; ++j) {
    ASSERT_NEAR(mean.data[j], j == unweighed ? 0.0f : pattern.data[j], 1e-6) << j;
  }
  PhotometricTrunk with = teacher.trunk;
  with.SetBackground(mean);
  const Image rest =
      PhotometricTrainer::MeanResidual(with, teacher.frames, latents, own, first, 100, 2);
  for (float v : rest.data) ASSERT_LT(std::abs(v), 1e-6);
  // max_frames takes evenly spaced frames: with 0.1 more in the last frame's pixel 0,
  // five frames average it in, the first alone does not.
  std::vector<TrunkTargets> moved = teacher.frames;
  moved[4].values(0, 0) += 0.1f;
  EXPECT_NEAR(PhotometricTrainer::MeanResidual(teacher.trunk, moved, latents, own, first, 5, 1)
                  .data[0],
              pattern.data[0] + 0.02f, 1e-6);
  EXPECT_NEAR(PhotometricTrainer::MeanResidual(teacher.trunk, moved, latents, own, first, 1, 1)
                  .data[0],
              pattern.data[0], 1e-6);
  // A frame against another clip's markers: its residual is taken against those.
  const auto other = teacher.trunk.MakeMarkers(Image(teacher.trunk.reference().rows,
                                                     teacher.trunk.reference().cols, 1, 0.3f));
  const Image against_other = PhotometricTrainer::MeanResidual(
      teacher.trunk, teacher.frames, latents, {nullptr, other.get()}, {0, 0, 1, 0, 0}, 100, 1);
  EXPECT_NE(against_other.data, mean.data);
  // Sizes that do not match are refused.
  EXPECT_THROW(PhotometricTrainer::MeanResidual(teacher.trunk, teacher.frames,
                                                latents.topRows(4), own, first, 100, 1),
               std::invalid_argument);
  EXPECT_THROW(PhotometricTrainer::MeanResidual(teacher.trunk, teacher.frames, latents, own,
                                                {0, 0, 1, 0, 0}, 100, 1),
               std::invalid_argument);
}

// Frames that share a pattern the contact does not draw: a background learned along finds
// it (its shape, and about its size) and the frames are drawn closer than without one;
// the same for any thread count, and a run stopped and resumed is bit-identical.
TEST(PhotometricTrainerTest, ALearnedBackgroundDrawsWhatTheFramesShare) {
  Teacher teacher = MakeTeacher(12);
  const PhotometricTrunk::Options t = SmallTrunk();
  const int n = t.rows * t.cols;
  Eigen::VectorXd pattern(n);
  for (int j = 0; j < n; ++j) pattern[j] = 0.05 * std::sin(0.7 * j) + (j % t.cols < 4 ? 0.04 : 0);
  for (TrunkTargets& frame : teacher.frames) {
    frame.values.col(0) += pattern.cast<float>();
  }
  const Image reference = teacher.trunk.reference();
  PhotometricTrainer::Options o = QuickOptions(1);
  o.steps = 300;
  const PhotometricTrainer::Result without = PhotometricTrainer(o).Train(teacher.frames, reference);
  EXPECT_TRUE(without.trunk.background().empty());
  o.learn_background = true;
  const PhotometricTrainer::Result with = PhotometricTrainer(o).Train(teacher.frames, reference);
  const Image& b = with.trunk.background();
  ASSERT_EQ(static_cast<int>(b.size()), n);
  const Eigen::VectorXd learned =
      Eigen::Map<const Eigen::VectorXf>(b.data.data(), n).cast<double>();
  const double cosine = learned.dot(pattern) / (learned.norm() * pattern.norm());
  EXPECT_GT(cosine, 0.8) << "learned RMS " << learned.norm() / std::sqrt(n);
  EXPECT_GT(learned.norm(), 0.5 * pattern.norm());
  EXPECT_LT(SummedLoss(with, teacher.frames), 0.85 * SummedLoss(without, teacher.frames));
  o.threads = 2;
  EXPECT_EQ(PhotometricTrainer(o).Train(teacher.frames, reference).trunk.background().data,
            b.data);
  // Stopped at step 130 and resumed: the background and its Adam moments carry over.
  const std::string path = ::testing::TempDir() + "/photometric_background.ckpt";
  const PhotometricTrainer::Result rest = StoppedAndResumed(&o, teacher.frames, reference, path);
  EXPECT_EQ(rest.trunk.background().data, b.data);
  EXPECT_EQ(rest.latents, with.latents);
  // A checkpoint without a background is another run.
  o.learn_background = false;
  EXPECT_THROW(PhotometricTrainer(o).Train(teacher.frames, reference), std::runtime_error);
  std::filesystem::remove(path);
}

// Frames of a trunk with lighting_components 2 and its images at zero, plus a shared
// pattern and each frame's own weighing (its latent's last two values) of two images.
struct LitFrames {
  PhotometricTrunk trunk;
  Eigen::MatrixXd latents;  // one row per frame
  std::vector<TrunkTargets> frames;
  Eigen::VectorXd pattern;  // the background drawn in
  Eigen::MatrixXd images;   // rows cols x 2, the lighting drawn in
};

LitFrames MakeLitFrames(int count, int components, bool contact = true) {
  PhotometricTrunk::Options o = SmallTrunk();
  o.lighting_components = components;
  LitFrames f{PhotometricTrunk(o, MarkerReference(2 * o.rows, 2 * o.cols), 42), {}, {}, {}, {}};
  const int n = o.rows * o.cols;
  f.pattern.resize(n);
  f.images.resize(n, components);
  for (int j = 0; j < n; ++j) {
    f.pattern[j] = 0.03 * std::sin(0.7 * j);
    for (int k = 0; k < components; ++k) {
      // Smooth over the grid, as a gel's lighting: gradients along the two axes.
      f.images(j, k) = 0.2 * (k == 0 ? (j % o.cols) / double(o.cols) - 0.5
                                      : (j / o.cols) / double(o.rows) - 0.5);
    }
  }
  unsigned state = 11;
  auto uniform = [&state] {
    state = state * 1664525u + 1013904223u;
    return 2.0 * (state >> 8) / double(1u << 24) - 1.0;
  };
  f.latents.resize(count, o.latent_dim);
  for (int i = 0; i < count; ++i) {
    Eigen::VectorXd z(o.latent_dim);
    for (int k = 0; k < z.size(); ++k) z[k] = 0.5 * uniform();
    z.tail(components) *= 4.0;  // lighting values within +-2
    f.latents.row(i) = z.transpose();
    Eigen::MatrixXf y = contact ? f.trunk.Forward<float>(f.trunk.AllPixels(), z.cast<float>())
                                : Eigen::MatrixXf::Zero(n, 1);
    y.col(0) += (f.pattern + f.images * z.tail(components)).cast<float>();
    f.frames.push_back(WholeFrameTargets(y, o.rows, o.cols));
  }
  return f;
}

TEST(PhotometricTrainerTest, TheTableCorrectionRecoversTheBackgroundAndTheLightingImages) {
  const LitFrames f = MakeLitFrames(6, 2);
  const std::vector<const PhotometricTrunk::Markers*> own = {nullptr};
  const std::vector<int> first(6, 0);
  const PhotometricTrainer::Tables tables = PhotometricTrainer::TableCorrection(
      f.trunk, f.frames, f.latents, own, first, 100, 1, /*lighting=*/true);
  const int n = static_cast<int>(f.pattern.size());
  ASSERT_EQ(tables.lighting.rows(), n);
  ASSERT_EQ(tables.lighting.cols(), 2);
  for (int j = 0; j < n; ++j) {
    ASSERT_NEAR(tables.background.data[j], f.pattern[j], 2e-5) << j;
    ASSERT_NEAR(tables.lighting(j, 0), f.images(j, 0), 2e-5) << j;
    ASSERT_NEAR(tables.lighting(j, 1), f.images(j, 1), 2e-5) << j;
  }
  // The same with two threads, and without lighting the background alone (MeanResidual).
  const PhotometricTrainer::Tables two = PhotometricTrainer::TableCorrection(
      f.trunk, f.frames, f.latents, own, first, 100, 2, /*lighting=*/true);
  EXPECT_EQ(two.background.data, tables.background.data);
  EXPECT_EQ(two.lighting, tables.lighting);
  const PhotometricTrainer::Tables alone = PhotometricTrainer::TableCorrection(
      f.trunk, f.frames, f.latents, own, first, 100, 1, /*lighting=*/false);
  EXPECT_EQ(alone.lighting.cols(), 0);
  EXPECT_EQ(alone.background.data,
            PhotometricTrainer::MeanResidual(f.trunk, f.frames, f.latents, own, first, 100, 1)
                .data);
  // Set in the trunk, the frames are drawn exactly.
  PhotometricTrunk lit = f.trunk;
  lit.SetBackground(tables.background);
  lit.SetLighting(tables.lighting);
  for (int i = 0; i < 6; ++i) {
    const Eigen::MatrixXf y =
        lit.Forward<float>(lit.AllPixels(), f.latents.row(i).transpose().cast<float>());
    EXPECT_LT((y - f.frames[i].values).cwiseAbs().maxCoeff(), 1e-4) << i;
  }
}

// Frames without a contact whose lighting over the whole grid varies from frame to
// frame: a trunk with two lighting images draws them closer than one with the
// background alone (whose SIREN must draw it in a contact's frame), its images span the
// lighting drawn in, and the run is the same for any thread count and when resumed.
TEST(PhotometricTrainerTest, LearnedLightingImagesDrawWhatVariesOverTheWholeGrid) {
  const LitFrames f = MakeLitFrames(12, 2, /*contact=*/false);
  const Image reference = f.trunk.reference();
  PhotometricTrainer::Options o = QuickOptions(1);
  o.steps = 300;
  o.learn_background = true;
  o.trunk.latent_dim = 10;  // the same code (5 values) with and without the two images
  const PhotometricTrainer::Result without = PhotometricTrainer(o).Train(f.frames, reference);
  o.trunk.lighting_components = 2;
  const PhotometricTrainer::Result with = PhotometricTrainer(o).Train(f.frames, reference);
  ASSERT_EQ(with.trunk.lighting().cols(), 2);
  EXPECT_LT(SummedLoss(with, f.frames), 0.2 * SummedLoss(without, f.frames));
  // The images drawn in lie near the span of the learned ones (within a quarter of their
  // norm: the SIREN draws a part of the lighting too).
  const Eigen::MatrixXd learned = with.trunk.lighting().cast<double>();
  const Eigen::MatrixXd projected =
      learned * learned.colPivHouseholderQr().solve(f.images);
  EXPECT_LT((projected - f.images).norm(), 0.25 * f.images.norm());
  o.threads = 2;
  EXPECT_EQ(PhotometricTrainer(o).Train(f.frames, reference).trunk.lighting(),
            with.trunk.lighting());
  // Stopped at step 130 and resumed: the images and their Adam moments carry over.
  const std::string path = ::testing::TempDir() + "/photometric_lighting.ckpt";
  const PhotometricTrainer::Result rest = StoppedAndResumed(&o, f.frames, reference, path);
  EXPECT_EQ(rest.trunk.lighting(), with.trunk.lighting());
  EXPECT_EQ(rest.latents, with.latents);
  // A checkpoint of another count is another run; lighting needs a background.
  o.trunk.lighting_components = 1;
  EXPECT_THROW(PhotometricTrainer(o).Train(f.frames, reference), std::runtime_error);
  std::filesystem::remove(path);
  o.learn_background = false;
  EXPECT_THROW(PhotometricTrainer{o}, std::invalid_argument);
}

// The summed loss of the training frames with each latent's code values moved by a
// fixed draw of the given size (its rigid motion and lighting values kept).
double SummedLossNearTheLatents(const PhotometricTrainer::Result& r,
                                const std::vector<TrunkTargets>& frames, double size) {
  PhotometricTrainer::Result moved = r;
  unsigned state = 11;
  for (Eigen::Index i = 0; i < moved.latents.rows(); ++i) {
    for (double& value :
         moved.latents.row(i).segment(PhotometricTrunk::kPoseValues, r.trunk.CodeValues())) {
      state = state * 1664525u + 1013904223u;
      value += ((state >> 31) ? size : -size);
    }
  }
  return SummedLoss(moved, frames);
}

TEST(PhotometricTrainerTest, NoiseOnTheLatentsTeachesTheTrunkToDrawFromNearThem) {
  // Trained with noise on the code values, the trunk draws its frames from latents moved
  // by that much far closer than a trunk trained without; the run is still the same for
  // any thread count and when stopped and resumed, and noise changes it.
  const Teacher teacher = MakeTeacher(12);
  const Image reference = teacher.trunk.reference();
  PhotometricTrainer::Options o = QuickOptions(1);
  o.steps = 300;
  const PhotometricTrainer::Result plain = PhotometricTrainer(o).Train(teacher.frames, reference);
  o.latent_noise = 0.3;
  const PhotometricTrainer::Result noisy = PhotometricTrainer(o).Train(teacher.frames, reference);
  const double plain_near = SummedLossNearTheLatents(plain, teacher.frames, 0.3);
  const double noisy_near = SummedLossNearTheLatents(noisy, teacher.frames, 0.3);
  EXPECT_LT(noisy_near, 0.5 * plain_near) << "at the latents: without noise "
                                          << SummedLoss(plain, teacher.frames) << ", with "
                                          << SummedLoss(noisy, teacher.frames);
  EXPECT_NE(noisy.latents, plain.latents);
  o.threads = 2;
  EXPECT_EQ(PhotometricTrainer(o).Train(teacher.frames, reference).latents, noisy.latents);
  const std::string path = ::testing::TempDir() + "/photometric_noise.ckpt";
  const PhotometricTrainer::Result rest = StoppedAndResumed(&o, teacher.frames, reference, path);
  EXPECT_EQ(rest.latents, noisy.latents);
  EXPECT_EQ(rest.trunk.siren().parameters(), noisy.trunk.siren().parameters());
  // A checkpoint of another noise is another run.
  o.latent_noise = 0.2;
  try {
    PhotometricTrainer(o).Train(teacher.frames, reference);
    FAIL() << "a checkpoint of another latent_noise resumed";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("latent_noise"), std::string::npos) << e.what();
  }
  std::filesystem::remove(path);
}

TEST(PhotometricTrainerTest, TheCallbackStopsTraining) {
  const Teacher teacher = MakeTeacher(4);
  const PhotometricTrainer::Result result = PhotometricTrainer(QuickOptions(1)).Train(
      teacher.frames, teacher.trunk.reference(), [](int step, double) { return step < 5; });
  EXPECT_TRUE(result.summary.stopped);
  EXPECT_EQ(result.summary.steps, 5);
}

TEST(PhotometricTrainerTest, AStoppedAndResumedRunIsBitIdenticalToOneThatNeverStopped) {
  const Teacher teacher = MakeTeacher(6);
  const Image reference = teacher.trunk.reference();
  const PhotometricTrainer::Result whole =
      PhotometricTrainer(QuickOptions(1)).Train(teacher.frames, reference);
  const std::string path = ::testing::TempDir() + "/photometric_resume.ckpt";
  std::filesystem::remove(path);
  PhotometricTrainer::Options o = QuickOptions(1);
  o.checkpoint_path = path;
  o.checkpoint_every = 40;
  o.resume = true;  // no checkpoint yet: starts at step 0
  // Stopped at step 57 (between periodic checkpoints: the stop writes its own).
  const PhotometricTrainer::Result first = PhotometricTrainer(o).Train(
      teacher.frames, reference, [](int step, double) { return step < 57; });
  ASSERT_TRUE(first.summary.stopped);
  ASSERT_TRUE(std::filesystem::exists(path));
  o.threads = 2;  // threads do not change the result
  const PhotometricTrainer::Result rest = PhotometricTrainer(o).Train(teacher.frames, reference);
  EXPECT_FALSE(rest.summary.stopped);
  EXPECT_EQ(rest.summary.steps, 150);
  EXPECT_EQ(rest.summary.loss, whole.summary.loss);
  EXPECT_EQ(rest.trunk.siren().parameters(), whole.trunk.siren().parameters());
  EXPECT_EQ(rest.trunk.head_parameters(), whole.trunk.head_parameters());
  EXPECT_EQ(rest.latents, whole.latents);
  // Resuming a finished run returns its trunk without another step.
  const PhotometricTrainer::Result again = PhotometricTrainer(o).Train(teacher.frames, reference);
  EXPECT_EQ(again.trunk.head_parameters(), whole.trunk.head_parameters());
  EXPECT_EQ(again.summary.loss, whole.summary.loss);

  // Another trajectory option is refused by name, and so are other frames.
  PhotometricTrainer::Options other = o;
  other.latent_learning_rate = 1e-2;
  try {
    PhotometricTrainer(other).Train(teacher.frames, reference);
    FAIL() << "a checkpoint of another latent_learning_rate resumed";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("option 'latent_learning_rate' differs"),
              std::string::npos)
        << e.what();
  }
  std::vector<TrunkTargets> frames = teacher.frames;
  frames[3].values(5, 0) += 1e-3f;
  try {
    PhotometricTrainer(o).Train(frames, reference);
    FAIL() << "a checkpoint of other frames resumed";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("training frames differ"), std::string::npos)
        << e.what();
  }
  std::filesystem::remove(path);
  PhotometricTrainer::Options no_path = QuickOptions(1);
  no_path.resume = true;
  EXPECT_THROW(PhotometricTrainer{no_path}, std::invalid_argument);
}

TEST(PhotometricTrainerTest, AFitOfAFrameTheTrunkDrewLowersItsLossTenfold) {
  const Teacher teacher = MakeTeacher(3);
  PhotometricFitOptions options;
  options.steps = 300;
  options.batch_pixels = 192;
  // Independent pixels, 12 blocks of 4 x 4 a step (PhotometricFitOptions::pixel_block),
  // and independent pixels half drawn towards the contact (contact_share).
  for (const auto& [block, share] : {std::pair{1, 0.0}, std::pair{4, 0.0}, std::pair{1, 0.5}}) {
    options.pixel_block = block;
    options.contact_share = share;
    for (int i = 0; i < 3; ++i) {
      const TrunkTargets& frame = teacher.frames[i];
      // From the true pose and a zero code (a random teacher's frames are no contacts:
      // their moment pose says little about the pose that drew them).
      Eigen::VectorXd start = Eigen::VectorXd::Zero(8);
      start.head<3>() = teacher.latents[i].head<3>();
      const double start_loss = teacher.trunk.LossAndGradient<float>(
          teacher.trunk.AllPixels(), start.cast<float>(), frame.values, frame.weights, nullptr,
          nullptr, nullptr);
      const PhotometricFit fit = FitPhotometricLatent(teacher.trunk, frame, options, 11 + i,
                                                      &start);
      EXPECT_LT(fit.loss, 0.1 * start_loss)
          << "frame " << i << ", block " << block << ", contact share " << share;
      EXPECT_EQ(fit.latent.size(), 8);
      // The pixels come from the seed: the same seed, the same latent.
      EXPECT_EQ(FitPhotometricLatent(teacher.trunk, frame, options, 11 + i, &start).latent,
                fit.latent);
    }
  }
}

TEST(PhotometricTrainerTest, AProbeKeepsTheStartAheadAndOtherwiseChangesNothing) {
  const Teacher teacher = MakeTeacher(3);
  PhotometricFitOptions both;
  both.steps = 120;
  both.batch_pixels = 96;
  PhotometricFitOptions probed = both;
  probed.probe_steps = 30;
  int checked = 0;
  for (int i = 0; i < 3; ++i) {
    const TrunkTargets& frame = teacher.frames[i];
    // Starts a quarter turn from the truth each way (a random teacher's moment pose says
    // little), so that either may be ahead.
    Eigen::VectorXd start = Eigen::VectorXd::Zero(8);
    start.head<3>() = teacher.latents[i].head<3>();
    start[2] += 0.5 * (i - 1);
    const PhotometricFit full = FitPhotometricLatent(teacher.trunk, frame, both, 5 + i, &start);
    const PhotometricFit fast = FitPhotometricLatent(teacher.trunk, frame, probed, 5 + i, &start);
    // The kept start follows the same trajectory as in the full fit: when the probe keeps
    // the full fit's winner, the latents are the same to the bit.
    if (fast.flipped == full.flipped) {
      EXPECT_EQ(fast.latent, full.latent) << "frame " << i;
      EXPECT_EQ(fast.loss, full.loss) << "frame " << i;
      ++checked;
    } else {
      EXPECT_GE(fast.loss, full.loss) << "frame " << i;
    }
  }
  EXPECT_GE(checked, 2);
  // The probe decides by the loss: starting on the truth, the turned start never wins.
  Eigen::VectorXd truth = teacher.latents[0];
  const PhotometricFit on_truth =
      FitPhotometricLatent(teacher.trunk, teacher.frames[0], probed, 3, &truth);
  EXPECT_FALSE(on_truth.flipped);
  PhotometricFitOptions bad = both;
  bad.probe_steps = both.steps + 1;
  EXPECT_THROW(FitPhotometricLatent(teacher.trunk, teacher.frames[0], bad, 1),
               std::invalid_argument);
}

TEST(PhotometricTrainerTest, AFitRefusesPixelBlocksLargerThanTheFrameOrBelowOne) {
  const Teacher teacher = MakeTeacher(1);
  PhotometricFitOptions options;
  options.steps = 3;
  PhotometricFitOptions wide = options;
  wide.pixel_block = teacher.frames[0].rows + 1;
  try {
    FitPhotometricLatent(teacher.trunk, teacher.frames[0], wide, 1);
    FAIL() << "a block larger than the frame accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("pixel_block"), std::string::npos) << e.what();
  }
  wide.pixel_block = 0;
  EXPECT_THROW(FitPhotometricLatent(teacher.trunk, teacher.frames[0], wide, 1),
               std::invalid_argument);
}

TEST(PhotometricTrainerTest, AFitRefusesAContactShareOutsideZeroToOneOrWithBlocks) {
  const Teacher teacher = MakeTeacher(1);
  PhotometricFitOptions options;
  options.steps = 3;
  for (const auto& [share, block] :
       {std::pair{1.0, 1}, std::pair{-0.1, 1}, std::pair{std::nan(""), 1}, std::pair{0.5, 4}}) {
    PhotometricFitOptions bad = options;
    bad.contact_share = share;
    bad.pixel_block = block;
    try {
      FitPhotometricLatent(teacher.trunk, teacher.frames[0], bad, 1);
      FAIL() << "contact_share " << share << " with pixel_block " << block << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("contact_share"), std::string::npos) << e.what();
    }
  }
  // A blank frame has no contact to draw towards: it is drawn evenly, and fits.
  TrunkTargets blank = teacher.frames[0];
  blank.values.setZero();
  options.contact_share = 0.5;
  EXPECT_TRUE(FitPhotometricLatent(teacher.trunk, blank, options, 1).latent.allFinite());
}

TEST(PhotometricTrainerTest, MomentPoseFindsTheCentreAndTheAxis) {
  const PhotometricTrunk trunk(SmallTrunk(), MarkerReference(24, 32));
  // A bar along the columns, rows 5-6, columns 4-11: centre between pixels (5, 4) and
  // (6, 11), axis along x_0 (phi = 0); then the same bar along the rows (phi = pi / 2).
  Eigen::MatrixXf values = Eigen::MatrixXf::Zero(12 * 16, 1);
  for (int r = 5; r <= 6; ++r) {
    for (int c = 4; c <= 11; ++c) values(r * 16 + c, 0) = 1.0f;
  }
  const Eigen::Vector3d pose = MomentPose(trunk, WholeFrameTargets(values, 12, 16));
  const Eigen::Vector2d a = trunk.PixelCoordinate(5 * 16 + 4), b = trunk.PixelCoordinate(6 * 16 + 11);
  EXPECT_NEAR(pose[0], (a[0] + b[0]) / 2, 1e-9);
  EXPECT_NEAR(pose[1], (a[1] + b[1]) / 2, 1e-9);
  EXPECT_NEAR(pose[2], 0.0, 1e-9);
  Eigen::MatrixXf column = Eigen::MatrixXf::Zero(12 * 16, 1);
  for (int r = 2; r <= 9; ++r) column(r * 16 + 7, 0) = -1.0f;  // energy: the sign is squared
  EXPECT_NEAR(std::abs(MomentPose(trunk, WholeFrameTargets(column, 12, 16))[2]), kPi / 2, 1e-9);
  EXPECT_EQ(MomentPose(trunk, WholeFrameTargets(Eigen::MatrixXf::Zero(12 * 16, 1), 12, 16)),
            Eigen::Vector3d::Zero());
}

TEST(PhotometricTrainerTest, RefusesBadOptionsAndFrames) {
  PhotometricTrainer::Options o = QuickOptions(1);
  o.batch_pixels = 0;
  try {
    PhotometricTrainer trainer(o);
    FAIL() << "batch_pixels 0 accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("batch_pixels"), std::string::npos) << e.what();
  }
  const PhotometricTrainer trainer(QuickOptions(1));
  EXPECT_THROW(trainer.Train({}, MarkerReference(24, 32)), std::invalid_argument);
  const Teacher teacher = MakeTeacher(2);
  std::vector<TrunkTargets> mixed = teacher.frames;
  mixed.push_back(WholeFrameTargets(Eigen::MatrixXf::Zero(10 * 16, 1), 10, 16));
  try {
    trainer.Train(mixed, teacher.trunk.reference());
    FAIL() << "a frame of another size accepted";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("10 x 16"), std::string::npos) << e.what();
  }
  for (double noise : {-0.1, std::nan("")}) {
    PhotometricTrainer::Options bad = QuickOptions(1);
    bad.latent_noise = noise;
    try {
      PhotometricTrainer refused(bad);
      FAIL() << "latent_noise " << noise << " accepted";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("latent_noise"), std::string::npos) << e.what();
    }
  }
  PhotometricFitOptions fit;
  fit.final_learning_rate = 1.0;  // above learning_rate
  EXPECT_THROW(FitPhotometricLatent(teacher.trunk, teacher.frames[0], fit, 1),
               std::invalid_argument);
}

}  // namespace
}  // namespace tactfunc
