// Copyright 2026 The tactfunc Authors.
#include "estimation/training/photometric_trainer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <limits>
#include <memory>
#include <numeric>
#include <sstream>
#include <stdexcept>

#include "Eigen/Cholesky"
#include "boost/random/mersenne_twister.hpp"
#include "boost/random/normal_distribution.hpp"
#include "boost/random/uniform_int_distribution.hpp"
#include "boost/random/uniform_real_distribution.hpp"
#include "estimation/training/internal/checkpoint.h"
#include "models/core/internal/checks.h"
#include "models/core/parallel_for.h"
#include "models/core/seed.h"
#include "models/trunk/product_precision.h"
#include "nlohmann/json.hpp"

namespace tactfunc {
namespace {

using internal::kPi;
const char* kCheckpointFormat = "tactfunc-photometric-checkpoint";
constexpr int kCheckpointVersion = 1;

// Frames the finished background's last correction averages over (evenly spaced).
constexpr int kBackgroundFrames = 8192;
// The lighting images' starting values are drawn within +-kLightingStart, a tenth of the
// background's RMS on real and simulated frames (docs/REAL_DATA.md): small beside the
// lighting they learn to draw, large enough for the frames' lighting values to get a
// gradient.
constexpr double kLightingStart = 1e-3;

// Adam with bias correction on one flat vector (double moments).
struct Adam {
  Eigen::VectorXd m, v;
  explicit Adam(Eigen::Index size) : m(Eigen::VectorXd::Zero(size)), v(Eigen::VectorXd::Zero(size)) {}
  // last_scale multiplies the rate of the last value (the head's marker scale).
  void Step(int t, double rate, const Eigen::VectorXd& gradient, double* values,
            double last_scale = 1.0) {
    constexpr double b1 = 0.9, b2 = 0.999, eps = 1e-8;
    m = b1 * m + (1 - b1) * gradient;
    v = b2 * v + (1 - b2) * gradient.cwiseAbs2();
    const double c1 = 1 - std::pow(b1, t), c2 = 1 - std::pow(b2, t);
    for (Eigen::Index i = 0; i < m.size(); ++i) {
      const double r = i + 1 == m.size() ? rate * last_scale : rate;
      values[i] -= r * (m[i] / c1) / (std::sqrt(v[i] / c2) + eps);
    }
  }
};

// Draws `count` pixels (with replacement) among the frame's pixels and gathers their
// targets and weights.
void DrawPixels(const TrunkTargets& frame, int count, boost::random::mt19937_64* rng,
                std::vector<int>* pixels, Eigen::MatrixXf* targets, Eigen::VectorXf* weights) {
  const int n = static_cast<int>(frame.values.rows());
  boost::random::uniform_int_distribution<int> pick(0, n - 1);
  pixels->resize(count);
  targets->resize(count, frame.values.cols());
  weights->resize(count);
  for (int i = 0; i < count; ++i) {
    const int j = pick(*rng);
    (*pixels)[i] = j;
    targets->row(i) = frame.values.row(j);
    (*weights)[i] = frame.weights.size() == 0 ? 1.0f : frame.weights[j];
  }
}

// DrawPixels by the distribution `draw`: pixel j weighs w_j / (N p_j).
void DrawPixelsBy(const TrunkTargets& frame, const ContactDraw& draw, int count,
                  boost::random::mt19937_64* rng, std::vector<int>* pixels,
                  Eigen::MatrixXf* targets, Eigen::VectorXf* weights) {
  const std::vector<double>& cdf = draw.cdf;
  const int n = static_cast<int>(cdf.size());
  boost::random::uniform_real_distribution<double> uniform(0.0, 1.0);
  pixels->resize(count);
  targets->resize(count, frame.values.cols());
  weights->resize(count);
  for (int i = 0; i < count; ++i) {
    const int j = draw.Pixel(uniform(*rng));
    const double p = cdf[j] - (j > 0 ? cdf[j - 1] : 0.0);
    (*pixels)[i] = j;
    targets->row(i) = frame.values.row(j);
    const double w = frame.weights.size() == 0 ? 1.0 : frame.weights[j];
    (*weights)[i] = static_cast<float>(w / (n * p));
  }
}

// DrawPixels in square blocks of side `block` (PhotometricFitOptions::pixel_block):
// count / block^2 blocks (at least one), each block's rows in order.
void DrawPixelBlocks(const TrunkTargets& frame, int count, int block,
                     boost::random::mt19937_64* rng, std::vector<int>* pixels,
                     Eigen::MatrixXf* targets, Eigen::VectorXf* weights) {
  if (block == 1) {
    DrawPixels(frame, count, rng, pixels, targets, weights);
    return;
  }
  const int blocks = std::max(1, count / (block * block));
  const int size = blocks * block * block;
  boost::random::uniform_int_distribution<int> pick_row(0, frame.rows - block);
  boost::random::uniform_int_distribution<int> pick_col(0, frame.cols - block);
  pixels->resize(size);
  targets->resize(size, frame.values.cols());
  weights->resize(size);
  int i = 0;
  for (int b = 0; b < blocks; ++b) {
    const int r0 = pick_row(*rng);
    const int c0 = pick_col(*rng);
    for (int r = r0; r < r0 + block; ++r) {
      for (int c = c0; c < c0 + block; ++c, ++i) {
        const int j = r * frame.cols + c;
        (*pixels)[i] = j;
        targets->row(i) = frame.values.row(j);
        (*weights)[i] = frame.weights.size() == 0 ? 1.0f : frame.weights[j];
      }
    }
  }
}

void CheckFrame(const PhotometricTrunk& trunk, const TrunkTargets& frame) {
  const auto& o = trunk.options();
  CheckTargetsShape(frame, o.rows, o.cols, o.channels, "photometric trunk");
}

}  // namespace

bool PhotometricTrainer::Options::IsValid(std::string* error) const {
  std::ostringstream message;
  if (steps < 1) {
    message << "steps must be >= 1, found " << steps;
  } else if (batch_frames < 1 || batch_pixels < 1) {
    message << "batch_frames and batch_pixels must be >= 1, found " << batch_frames << " and "
            << batch_pixels;
  } else if (!(trunk_learning_rate > 0 && std::isfinite(trunk_learning_rate))) {
    message << "trunk_learning_rate must be finite and > 0, found " << trunk_learning_rate;
  } else if (!(latent_learning_rate > 0 && std::isfinite(latent_learning_rate))) {
    message << "latent_learning_rate must be finite and > 0, found " << latent_learning_rate;
  } else if (!(marker_learning_rate >= 0 && std::isfinite(marker_learning_rate))) {
    message << "marker_learning_rate must be finite and >= 0, found " << marker_learning_rate;
  } else if (!(contact_share >= 0 && contact_share < 1)) {
    message << "contact_share must be in [0, 1), found " << contact_share;
  } else if (marker_warmup_steps < 0) {
    message << "marker_warmup_steps must be >= 0, found " << marker_warmup_steps;
  } else if (trunk.lighting_components > 0 && !learn_background) {
    message << "trunk.lighting_components (" << trunk.lighting_components
            << ") needs learn_background: the lighting images vary about the background";
  } else if (!(latent_noise >= 0 && std::isfinite(latent_noise))) {
    message << "latent_noise must be finite and >= 0, found " << latent_noise;
  } else if (threads < 1) {
    message << "threads must be >= 1, found " << threads;
  } else if (checkpoint_every < 0) {
    message << "checkpoint_every must be >= 0 (0 = only at the end), found " << checkpoint_every;
  } else if (resume && checkpoint_path.empty()) {
    message << "resume requires a checkpoint_path";
  }
  const std::string text = message.str();
  if (error != nullptr) *error = text;
  return text.empty();
}

std::string PhotometricTrainer::Options::TrajectoryOptionsJson() const {
  nlohmann::json json;
  json["trunk.width"] = trunk.width;
  json["trunk.num_hidden_layers"] = trunk.num_hidden_layers;
  json["trunk.omega_0"] = trunk.omega_0;
  json["trunk.latent_dim"] = trunk.latent_dim;
  json["trunk.shading_width"] = trunk.shading_width;
  json["trunk.supersample"] = trunk.supersample;
  json["trunk.wide_biases"] = trunk.wide_biases;
  // Absent without lighting images, so that older runs resume.
  if (trunk.lighting_components > 0) json["trunk.lighting_components"] = trunk.lighting_components;
  // As TrunkTrainer's: absent = float products (older files).
  if (GetProductPrecision() != ProductPrecision::kFloat) {
    json["products"] = ProductPrecisionName(GetProductPrecision());
  }
  json["steps"] = steps;
  json["batch_frames"] = batch_frames;
  json["batch_pixels"] = batch_pixels;
  json["trunk_learning_rate"] = trunk_learning_rate;
  json["latent_learning_rate"] = latent_learning_rate;
  json["marker_learning_rate"] = marker_learning_rate;
  json["cosine_schedule"] = cosine_schedule;
  json["marker_warmup_steps"] = marker_warmup_steps;
  json["seed"] = seed;
  // Only where it draws towards the contact, so that the checkpoints of runs that drew
  // every pixel alike still resume.
  if (contact_share > 0) json["contact_share"] = contact_share;
  if (learn_background) json["learn_background"] = true;  // absent: older runs resume
  if (latent_noise > 0) json["latent_noise"] = latent_noise;  // likewise
  return json.dump();
}

bool PhotometricFitOptions::IsValid(std::string* error) const {
  std::ostringstream message;
  if (steps < 1 || batch_pixels < 1) {
    message << "steps and batch_pixels must be >= 1, found " << steps << " and "
            << batch_pixels;
  } else if (pixel_block < 1 || pixel_block > 16) {
    message << "pixel_block must be in [1, 16], found " << pixel_block;
  } else if (!(contact_share >= 0 && contact_share < 1)) {
    message << "contact_share must be in [0, 1), found " << contact_share;
  } else if (contact_share > 0 && pixel_block != 1) {
    message << "contact_share needs pixel_block 1, found " << pixel_block;
  } else if (probe_steps < 0 || probe_steps > steps) {
    message << "probe_steps must be in [0, steps = " << steps << "], found " << probe_steps;
  } else if (!(learning_rate > 0 && std::isfinite(learning_rate)) ||
             !(final_learning_rate >= 0 && final_learning_rate <= learning_rate)) {
    message << "learning_rate must be finite and > 0 and final_learning_rate in [0, "
               "learning_rate], found "
            << learning_rate << " and " << final_learning_rate;
  }
  const std::string text = message.str();
  if (error != nullptr) *error = text;
  return text.empty();
}

PhotometricTrainer::PhotometricTrainer(const Options& options) : options_(options) {
  std::string error;
  if (!options.IsValid(&error)) {
    throw std::invalid_argument("PhotometricTrainer::Options: " + error);
  }
}

Eigen::Vector3d MomentPose(const PhotometricTrunk& trunk, const TrunkTargets& frame) {
  CheckFrame(trunk, frame);
  const Eigen::Index n = frame.values.rows();
  double total = 0, s0 = 0, s1 = 0;
  Eigen::VectorXd energy(n);
  for (Eigen::Index j = 0; j < n; ++j) {
    const double w = frame.weights.size() == 0 ? 1.0 : frame.weights[j];
    energy[j] = w * frame.values.row(j).cast<double>().squaredNorm();
    const Eigen::Vector2d x = trunk.PixelCoordinate(static_cast<int>(j));
    total += energy[j];
    s0 += energy[j] * x[0];
    s1 += energy[j] * x[1];
  }
  if (!(total > 0)) return Eigen::Vector3d::Zero();
  const Eigen::Vector2d t(s0 / total, s1 / total);
  double c00 = 0, c01 = 0, c11 = 0;
  for (Eigen::Index j = 0; j < n; ++j) {
    const Eigen::Vector2d d = trunk.PixelCoordinate(static_cast<int>(j)) - t;
    c00 += energy[j] * d[0] * d[0];
    c01 += energy[j] * d[0] * d[1];
    c11 += energy[j] * d[1] * d[1];
  }
  return {t[0], t[1], 0.5 * std::atan2(2 * c01, c00 - c11)};
}

PhotometricTrainer::Result PhotometricTrainer::Train(const std::vector<TrunkTargets>& frames,
                                                     const Image& reference,
                                                     const Callback& callback) const {
  return Train(frames, std::vector<Image>{reference}, std::vector<int>(frames.size(), 0),
               callback);
}

PhotometricTrainer::Result PhotometricTrainer::Train(const std::vector<TrunkTargets>& frames,
                                                     const std::vector<Image>& references,
                                                     const std::vector<int>& frame_reference,
                                                     const Callback& callback) const {
  if (frames.empty()) throw std::invalid_argument("PhotometricTrainer: no training frames");
  if (references.empty()) throw std::invalid_argument("PhotometricTrainer: no reference");
  if (frame_reference.size() != frames.size()) {
    throw std::invalid_argument("PhotometricTrainer: " + std::to_string(frames.size()) +
                                " frames but " + std::to_string(frame_reference.size()) +
                                " reference indices");
  }
  for (std::size_t i = 0; i < frames.size(); ++i) {
    if (frame_reference[i] < 0 || frame_reference[i] >= static_cast<int>(references.size())) {
      throw std::invalid_argument("PhotometricTrainer: frame " + std::to_string(i) +
                                  ": reference index " + std::to_string(frame_reference[i]) +
                                  " outside the " + std::to_string(references.size()) +
                                  " references");
    }
  }
  const Image& reference = references[0];
  const auto start = std::chrono::steady_clock::now();
  const Options& o = options_;
  PhotometricTrunk::Options trunk_options = o.trunk;
  trunk_options.rows = frames[0].rows;
  trunk_options.cols = frames[0].cols;
  trunk_options.channels = static_cast<int>(frames[0].values.cols());
  PhotometricTrunk trunk(trunk_options, reference, o.seed);
  for (const TrunkTargets& frame : frames) CheckFrame(trunk, frame);
  // Each reference's markers (the trunk's own for the first).
  std::vector<std::shared_ptr<const PhotometricTrunk::Markers>> markers(references.size());
  for (std::size_t k = 1; k < references.size(); ++k) {
    markers[k] = trunk.MakeMarkers(references[k]);
  }
  const int num_frames = static_cast<int>(frames.size());
  const int d = trunk.latent_dim();
  Eigen::MatrixXd latents = Eigen::MatrixXd::Zero(d, num_frames);  // one column per frame
  for (int i = 0; i < num_frames; ++i) {
    latents.col(i).head<PhotometricTrunk::kPoseValues>() = MomentPose(trunk, frames[i]);
  }
  Eigen::VectorXd siren_theta = trunk.siren().parameters();
  Eigen::VectorXd head = trunk.head_parameters();
  Adam adam_siren(siren_theta.size()), adam_head(head.size()), adam_latents(latents.size());
  // The background's values, pixel-major with channels interleaved (Image's layout).
  const int grid_values = trunk_options.rows * trunk_options.cols * trunk_options.channels;
  Eigen::VectorXd background = Eigen::VectorXd::Zero(o.learn_background ? grid_values : 0);
  Adam adam_background(background.size());
  const auto set_background = [&]() {
    if (!o.learn_background) return;
    Image b(trunk_options.rows, trunk_options.cols, trunk_options.channels);
    for (int i = 0; i < grid_values; ++i) b.data[i] = static_cast<float>(background[i]);
    trunk.SetBackground(b);
  };
  // The lighting images, (grid values) x K column-major. They start at small random
  // values (Boost.Random from the seed) and the frames' lighting values at zero: with
  // both at zero neither would get a gradient.
  const int k_light = trunk_options.lighting_components;
  const bool learn_lighting = k_light > 0;
  Eigen::MatrixXd lighting = Eigen::MatrixXd::Zero(grid_values, k_light);
  {
    boost::random::mt19937_64 rng(DeriveSeed(o.seed, 7));
    boost::random::uniform_real_distribution<double> uniform(-kLightingStart, kLightingStart);
    for (Eigen::Index i = 0; i < lighting.size(); ++i) lighting.data()[i] = uniform(rng);
  }
  Adam adam_lighting(lighting.size());
  const auto set_lighting = [&]() {
    if (learn_lighting) trunk.SetLighting(lighting.cast<float>());
  };
  set_lighting();
  Summary summary;
  summary.loss.reserve(o.steps);

  // Checkpoints: the run they belong to (options, frames and reference), then resume.
  internal::CheckpointRun run;
  double earlier_seconds = 0;  // training seconds of the runs resumed from
  if (!o.checkpoint_path.empty()) {
    run.format = kCheckpointFormat;
    run.version = kCheckpointVersion;
    run.sensor = "optical";
    run.options_json = o.TrajectoryOptionsJson();
    run.num_frames = num_frames;
    std::uint64_t hash = internal::Fnv1a(nullptr, 0);
    for (const TrunkTargets& frame : frames) {
      hash = internal::Fnv1a(frame.values.data(), sizeof(float) * frame.values.size(), hash);
      hash = internal::Fnv1a(frame.weights.data(), sizeof(float) * frame.weights.size(), hash);
    }
    // One reference hashes as before several could be given, so its checkpoints resume.
    for (const Image& r : references) {
      hash = internal::Fnv1a(r.data.data(), sizeof(float) * r.data.size(), hash);
    }
    if (references.size() > 1) {
      hash = internal::Fnv1a(frame_reference.data(), sizeof(int) * frame_reference.size(), hash);
    }
    run.fingerprint = hash;
  }
  int first_step = 1;
  if (o.resume && std::filesystem::exists(o.checkpoint_path)) {
    nlohmann::json meta;
    const TensorFile file = internal::ReadCheckpoint(o.checkpoint_path, run, &meta);
    const int done = meta.at("step").get<int>();
    if (done < 0 || done > o.steps) {
      throw TensorFileError("checkpoint " + o.checkpoint_path + ": meta.step: expected 0.." +
                            std::to_string(o.steps) + ", found " + std::to_string(done));
    }
    earlier_seconds = meta.at("train_seconds").get<double>();
    const auto n = static_cast<std::int64_t>(siren_theta.size());
    const auto h = static_cast<std::int64_t>(head.size());
    const auto l = static_cast<std::int64_t>(latents.size());
    siren_theta = internal::CheckpointVector(file, "siren", n);
    head = internal::CheckpointVector(file, "head", h);
    latents = Eigen::Map<const Eigen::MatrixXd>(
        internal::CheckpointVector(file, "latents", l).data(), d, num_frames);
    adam_siren.m = internal::CheckpointVector(file, "adam/siren_m", n);
    adam_siren.v = internal::CheckpointVector(file, "adam/siren_v", n);
    adam_head.m = internal::CheckpointVector(file, "adam/head_m", h);
    adam_head.v = internal::CheckpointVector(file, "adam/head_v", h);
    adam_latents.m = internal::CheckpointVector(file, "adam/latents_m", l);
    adam_latents.v = internal::CheckpointVector(file, "adam/latents_v", l);
    if (o.learn_background) {
      background = internal::CheckpointVector(file, "background", grid_values);
      adam_background.m = internal::CheckpointVector(file, "adam/background_m", grid_values);
      adam_background.v = internal::CheckpointVector(file, "adam/background_v", grid_values);
      set_background();
    }
    if (learn_lighting) {
      const auto size = static_cast<std::int64_t>(lighting.size());
      lighting = Eigen::Map<const Eigen::MatrixXd>(
          internal::CheckpointVector(file, "lighting", size).data(), grid_values, k_light);
      adam_lighting.m = internal::CheckpointVector(file, "adam/lighting_m", size);
      adam_lighting.v = internal::CheckpointVector(file, "adam/lighting_v", size);
      set_lighting();
    }
    const Eigen::VectorXd loss = internal::CheckpointVector(file, "loss", done);
    summary.loss.assign(loss.data(), loss.data() + loss.size());
    trunk.mutable_siren().SetParameters(siren_theta);
    trunk.SetHeadParameters(head);
    summary.steps = done;
    summary.final_loss = done > 0 ? summary.loss.back() : 0.0;
    first_step = done + 1;
  }
  auto seconds = [&]() {
    return earlier_seconds +
           std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  auto checkpoint = [&]() {
    if (o.checkpoint_path.empty()) return;
    using internal::ToStdVector;
    using D = TensorFile::DType;
    TensorFile file = internal::NewCheckpoint(run, summary.steps, seconds());
    const auto n = static_cast<std::int64_t>(siren_theta.size());
    const auto h = static_cast<std::int64_t>(head.size());
    const auto l = static_cast<std::int64_t>(latents.size());
    file.Add("siren", D::kFloat64, {n}, ToStdVector(siren_theta));
    file.Add("head", D::kFloat64, {h}, ToStdVector(head));
    file.Add("latents", D::kFloat64, {l},
             std::vector<double>(latents.data(), latents.data() + l));
    file.Add("adam/siren_m", D::kFloat64, {n}, ToStdVector(adam_siren.m));
    file.Add("adam/siren_v", D::kFloat64, {n}, ToStdVector(adam_siren.v));
    file.Add("adam/head_m", D::kFloat64, {h}, ToStdVector(adam_head.m));
    file.Add("adam/head_v", D::kFloat64, {h}, ToStdVector(adam_head.v));
    file.Add("adam/latents_m", D::kFloat64, {l}, ToStdVector(adam_latents.m));
    file.Add("adam/latents_v", D::kFloat64, {l}, ToStdVector(adam_latents.v));
    if (o.learn_background) {
      file.Add("background", D::kFloat64, {grid_values}, ToStdVector(background));
      file.Add("adam/background_m", D::kFloat64, {grid_values}, ToStdVector(adam_background.m));
      file.Add("adam/background_v", D::kFloat64, {grid_values}, ToStdVector(adam_background.v));
    }
    if (learn_lighting) {
      const auto size = static_cast<std::int64_t>(lighting.size());
      file.Add("lighting", D::kFloat64, {size},
               std::vector<double>(lighting.data(), lighting.data() + size));
      file.Add("adam/lighting_m", D::kFloat64, {size}, ToStdVector(adam_lighting.m));
      file.Add("adam/lighting_v", D::kFloat64, {size}, ToStdVector(adam_lighting.v));
    }
    file.Add("loss", D::kFloat64, {static_cast<std::int64_t>(summary.loss.size())},
             summary.loss);
    file.Write(o.checkpoint_path);
  };

  struct Slot {
    int frame = 0;
    double loss = 0;
    Eigen::VectorXf dz, dsiren, dhead;
    // With a background or lighting images to learn: the drawn pixels and dL/dY there
    // (the outputs are linear in B and in L).
    std::vector<int> pixels;
    Eigen::MatrixXf dY;
  };
  std::vector<Slot> slots(o.batch_frames);
  const bool learn_tables = o.learn_background || learn_lighting;
  for (int step = first_step; step <= o.steps; ++step) {
    trunk.set_marker_sampling(step <= o.marker_warmup_steps
                                  ? PhotometricTrunk::MarkerSampling::kWorkingResolution
                                  : PhotometricTrunk::MarkerSampling::kSensorResolution);
    const std::uint64_t step_seed = DeriveSeed(o.seed, 1000 + step);
    {
      boost::random::mt19937_64 rng(step_seed);
      boost::random::uniform_int_distribution<int> pick(0, num_frames - 1);
      for (Slot& slot : slots) slot.frame = pick(rng);
    }
    internal::ParallelFor(o.batch_frames, o.threads, [&](int s) {
      Slot& slot = slots[s];
      boost::random::mt19937_64 rng(DeriveSeed(step_seed, s));
      std::vector<int> pixels;
      Eigen::MatrixXf targets;
      Eigen::VectorXf weights;
      if (o.contact_share > 0) {
        // The frame's distribution is made anew each time it is drawn: kept for every
        // training frame it would take 8 bytes per pixel (110 MB at 1620 GelSlim frames)
        // to save about 1.4% of a step (perf of `train --head photometric`, 2026-11-28).
        // No guide: building it costs more than the step's few draws save.
        DrawPixelsBy(frames[slot.frame],
                     ContactDraw(frames[slot.frame], o.contact_share, /*with_guide=*/false),
                     o.batch_pixels, &rng, &pixels, &targets, &weights);
      } else {
        DrawPixels(frames[slot.frame], o.batch_pixels, &rng, &pixels, &targets, &weights);
      }
      Eigen::VectorXf z = latents.col(slot.frame).cast<float>();
      if (o.latent_noise > 0) {
        boost::random::normal_distribution<double> noise(0.0, o.latent_noise);
        for (float& value : z.segment(PhotometricTrunk::kPoseValues, trunk.CodeValues())) {
          value += static_cast<float>(noise(rng));
        }
      }
      // dL/dB at a pixel is dL/dY there, and dL/dL_k is dL/dY times a_k.
      slot.loss = trunk.LossAndGradient<float>(pixels, z, targets, weights, &slot.dz,
                                               &slot.dsiren, &slot.dhead, nullptr,
                                               markers[frame_reference[slot.frame]].get(),
                                               learn_tables ? &slot.dY : nullptr);
      if (learn_tables) slot.pixels = std::move(pixels);
    });
    Eigen::VectorXd g_siren = Eigen::VectorXd::Zero(siren_theta.size());
    Eigen::VectorXd g_head = Eigen::VectorXd::Zero(head.size());
    Eigen::MatrixXd g_latents = Eigen::MatrixXd::Zero(d, num_frames);
    double loss = 0;
    const double scale = 1.0 / o.batch_frames;
    Eigen::VectorXd g_background = Eigen::VectorXd::Zero(background.size());
    Eigen::MatrixXd g_lighting = Eigen::MatrixXd::Zero(grid_values, k_light);
    const int channels = trunk_options.channels;
    for (const Slot& slot : slots) {
      loss += scale * slot.loss;
      g_siren += scale * slot.dsiren.cast<double>();
      g_head += scale * slot.dhead.cast<double>();
      g_latents.col(slot.frame) += scale * slot.dz.cast<double>();
      for (std::size_t i = 0; i < slot.pixels.size(); ++i) {
        for (int ch = 0; ch < channels; ++ch) {
          if (o.learn_background) {
            g_background[slot.pixels[i] * channels + ch] += scale * slot.dY(i, ch);
          }
          if (learn_lighting) {
            // dL/dL_k at a pixel is dL/dY there times the frame's k-th lighting value.
            g_lighting.row(slot.pixels[i] * channels + ch) +=
                (scale * slot.dY(i, ch)) * latents.col(slot.frame).tail(k_light).transpose();
          }
        }
      }
    }
    const double factor =
        o.cosine_schedule ? 0.1 + 0.45 * (1 + std::cos(kPi * (step - 1) / o.steps)) : 1.0;
    adam_siren.Step(step, factor * o.trunk_learning_rate, g_siren, siren_theta.data());
    const double head_rate = factor * o.trunk_learning_rate;
    const double marker_rate =
        factor * (o.marker_learning_rate > 0 ? o.marker_learning_rate : o.trunk_learning_rate);
    adam_head.Step(step, head_rate, g_head, head.data(), marker_rate / head_rate);
    adam_latents.Step(step, factor * o.latent_learning_rate,
                      Eigen::Map<const Eigen::VectorXd>(g_latents.data(), g_latents.size()),
                      latents.data());
    if (o.learn_background) {
      adam_background.Step(step, head_rate, g_background, background.data());
      set_background();
    }
    if (learn_lighting) {
      adam_lighting.Step(step, head_rate,
                         Eigen::Map<const Eigen::VectorXd>(g_lighting.data(), g_lighting.size()),
                         lighting.data());
      set_lighting();
    }
    trunk.mutable_siren().SetParameters(siren_theta);
    trunk.SetHeadParameters(head);
    summary.steps = step;
    summary.final_loss = loss;
    summary.loss.push_back(loss);
    if (!std::isfinite(loss)) break;
    if (callback && !callback(step, loss)) {
      summary.stopped = true;
      break;
    }
    if (o.checkpoint_every > 0 && step % o.checkpoint_every == 0 && step < o.steps) checkpoint();
  }
  // At the end or on a stop; a diverged run keeps its last finite checkpoint.
  if (std::isfinite(summary.final_loss)) checkpoint();
  trunk.set_marker_sampling(PhotometricTrunk::MarkerSampling::kSensorResolution);
  if (o.learn_background && !summary.stopped && std::isfinite(summary.final_loss)) {
    // Adam leaves each value within about its step of where the noisy batches put it:
    // the finished background (and lighting images) are the learned ones plus their
    // exact least-squares correction at the frames' final latents (TableCorrection; the
    // background alone: what the frames still share, MeanResidual). The checkpoint
    // keeps the learned ones, so a finished run resumed ends the same.
    std::vector<const PhotometricTrunk::Markers*> marker_of(markers.size());
    for (std::size_t k = 0; k < markers.size(); ++k) marker_of[k] = markers[k].get();
    if (learn_lighting) {
      // Each lighting value and its image are known only up to a shared scale and an
      // offset the background takes. Adam moves the latents' values about a hundred
      // times faster than the images', so they end large; a fit of a new frame starts
      // its lighting values at zero and moves them by its step size. Each is set to mean
      // zero and unit RMS over the training frames (the correction below then redraws
      // the same frames exactly as before: the regressors 1, a_1..a_K span the same).
      for (int k = 0; k < k_light; ++k) {
        auto values = latents.row(d - k_light + k);
        const double mean = values.mean();
        const double rms = std::sqrt((values.array() - mean).square().mean());
        values.array() -= mean;
        if (rms > 0) values /= rms;
      }
    }
    const Tables rest = TableCorrection(trunk, frames, latents.transpose(), marker_of,
                                        frame_reference, kBackgroundFrames, o.threads,
                                        learn_lighting);
    for (int i = 0; i < grid_values; ++i) background[i] += rest.background.data[i];
    set_background();
    if (learn_lighting) {
      lighting += rest.lighting.cast<double>();
      set_lighting();
    }
  }
  summary.seconds = seconds();
  return Result{std::move(trunk), latents.transpose(), std::move(summary)};
}

PhotometricFit FitPhotometricLatent(const PhotometricTrunk& trunk, const TrunkTargets& frame,
                                    const PhotometricFitOptions& options, std::uint64_t seed,
                                    const Eigen::VectorXd* start_latent) {
  std::string error;
  if (!options.IsValid(&error)) {
    throw std::invalid_argument("PhotometricFitOptions: " + error);
  }
  CheckFrame(trunk, frame);
  if (options.pixel_block > std::min(frame.rows, frame.cols)) {
    throw std::invalid_argument("PhotometricFitOptions: pixel_block " +
                                std::to_string(options.pixel_block) + " exceeds the " +
                                std::to_string(frame.rows) + " x " +
                                std::to_string(frame.cols) + " frame");
  }
  if (start_latent != nullptr && start_latent->size() != trunk.latent_dim()) {
    throw std::invalid_argument("FitPhotometricLatent: expected a start of " +
                                std::to_string(trunk.latent_dim()) + " values, found " +
                                std::to_string(start_latent->size()));
  }
  const std::vector<int> all = trunk.AllPixels();
  // One start's state: it advances alone, from its own pixel-subset stream.
  struct Start {
    Eigen::VectorXd z;
    Adam adam;
    boost::random::mt19937_64 rng;
    int step = 0;
    double loss = 0;
  };
  const int num_starts = options.flipped_start ? 2 : 1;
  std::vector<Start> starts;
  for (int start = 0; start < num_starts; ++start) {
    Eigen::VectorXd z = Eigen::VectorXd::Zero(trunk.latent_dim());
    if (start_latent != nullptr) {
      z = *start_latent;
    } else {
      z.head<PhotometricTrunk::kPoseValues>() = MomentPose(trunk, frame);
    }
    z[2] += kPi * start;
    starts.push_back(
        Start{z, Adam(z.size()), boost::random::mt19937_64(DeriveSeed(seed, start))});
  }
  std::vector<int> pixels;
  Eigen::MatrixXf targets;
  Eigen::VectorXf weights, dz;
  // A fit draws its frame's pixels over many steps: worth the guide.
  const ContactDraw contact = options.contact_share > 0
                                  ? ContactDraw(frame, options.contact_share, /*with_guide=*/true)
                                  : ContactDraw();
  auto advance = [&](Start* s, int last_step) {
    for (int step = s->step + 1; step <= last_step; ++step) {
      if (contact.cdf.empty()) {
        DrawPixelBlocks(frame, options.batch_pixels, options.pixel_block, &s->rng, &pixels,
                        &targets, &weights);
      } else {
        DrawPixelsBy(frame, contact, options.batch_pixels, &s->rng, &pixels, &targets,
                     &weights);
      }
      trunk.LossAndGradient<float>(pixels, s->z.cast<float>(), targets, weights, &dz, nullptr,
                                   nullptr, nullptr, options.markers);
      const double rate =
          options.final_learning_rate + (options.learning_rate - options.final_learning_rate) *
                                            0.5 * (1 + std::cos(kPi * (step - 1) / options.steps));
      s->adam.Step(step, rate, dz.cast<double>(), s->z.data());
    }
    s->step = std::max(s->step, last_step);
    s->loss = num_starts == 1 && !options.score
                  ? std::numeric_limits<double>::quiet_NaN()
                  : trunk.LossAndGradient<float>(all, s->z.cast<float>(), frame.values,
                                                 frame.weights, nullptr, nullptr, nullptr,
                                                 nullptr, options.markers);
  };
  std::vector<int> running(num_starts);
  for (int start = 0; start < num_starts; ++start) running[start] = start;
  if (num_starts == 2 && options.probe_steps > 0 && options.probe_steps < options.steps) {
    for (Start& s : starts) advance(&s, options.probe_steps);
    // The lower loss goes on; a tie keeps the moment start, as the final comparison does.
    running = {starts[1].loss < starts[0].loss ? 1 : 0};
  }
  for (int start : running) advance(&starts[start], options.steps);
  PhotometricFit best;
  for (int i = 0; i < static_cast<int>(running.size()); ++i) {
    const Start& s = starts[running[i]];
    if (i == 0 || s.loss < best.loss) {
      best.latent = s.z;
      best.loss = s.loss;
      best.flipped = running[i] == 1;
    }
  }
  return best;
}

Image PhotometricTrainer::MeanResidual(
    const PhotometricTrunk& trunk, const std::vector<TrunkTargets>& frames,
    const Eigen::MatrixXd& latents, const std::vector<const PhotometricTrunk::Markers*>& markers,
    const std::vector<int>& frame_reference, int max_frames, int threads) {
  return TableCorrection(trunk, frames, latents, markers, frame_reference, max_frames, threads,
                         /*lighting=*/false)
      .background;
}

PhotometricTrainer::Tables PhotometricTrainer::TableCorrection(
    const PhotometricTrunk& trunk, const std::vector<TrunkTargets>& frames,
    const Eigen::MatrixXd& latents, const std::vector<const PhotometricTrunk::Markers*>& markers,
    const std::vector<int>& frame_reference, int max_frames, int threads, bool lighting) {
  const int m = static_cast<int>(frames.size());
  if (m < 1 || latents.rows() != m || latents.cols() != trunk.latent_dim() ||
      static_cast<int>(frame_reference.size()) != m || max_frames < 1) {
    throw std::invalid_argument(
        "PhotometricTrainer::TableCorrection: expected one latent of " +
        std::to_string(trunk.latent_dim()) + " values and one reference index per frame, and "
        "max_frames >= 1; found " + std::to_string(m) + " frames, " +
        std::to_string(latents.rows()) + " x " + std::to_string(latents.cols()) + " latents, " +
        std::to_string(frame_reference.size()) + " indices");
  }
  const int rows = trunk.options().rows, cols = trunk.options().cols, c = trunk.channels();
  const int n = rows * cols;
  const int used = std::min(m, max_frames);
  for (int k = 0; k < used; ++k) {
    const std::size_t i = static_cast<std::size_t>(k) * m / used;
    const int r = frame_reference[i];
    if (frames[i].values.rows() != n || frames[i].values.cols() != c ||
        frames[i].weights.size() != n || r < 0 || r >= static_cast<int>(markers.size())) {
      throw std::invalid_argument("PhotometricTrainer::TableCorrection: frame " +
                                  std::to_string(i) + " is not " + std::to_string(rows) + "x" +
                                  std::to_string(cols) + "x" + std::to_string(c) +
                                  " or names no reference");
    }
  }
  // The regressors of frame i: 1 (the background), then its K lighting values. Per
  // pixel the normal equations' matrix sum_i w_i x_i x_i^T (q x q, one row of q q values
  // of `grams`) and right-hand side sum_i w_i r_i x_i^T (C rows of `sums`).
  const int k_light = lighting ? trunk.lighting_components() : 0;
  const int q = 1 + k_light;
  // Per-thread sums (threads own contiguous ranges of the frames), added in thread order
  // so that the tables do not depend on the scheduling.
  const int parts = std::max(1, std::min(threads, used));
  const auto values = static_cast<Eigen::Index>(n) * c;
  std::vector<Eigen::MatrixXd> sums(parts, Eigen::MatrixXd::Zero(values, q));
  std::vector<Eigen::MatrixXd> grams(parts, Eigen::MatrixXd::Zero(n, q * q));
  const std::vector<int> pixels = trunk.AllPixels();
  internal::ParallelFor(parts, parts, [&](int part) {
    Eigen::VectorXd x(q);
    for (int k = part * used / parts; k < (part + 1) * used / parts; ++k) {
      const std::size_t i = static_cast<std::size_t>(k) * m / used;
      const Eigen::MatrixXf y = trunk.Forward<float>(
          pixels, latents.row(i).transpose().cast<float>(), markers[frame_reference[i]]);
      x[0] = 1.0;
      x.tail(k_light) = latents.row(i).tail(k_light).transpose();
      const Eigen::MatrixXd xx = x * x.transpose();
      for (int j = 0; j < n; ++j) {
        const double w = static_cast<double>(frames[i].weights[j]);
        if (w == 0.0) continue;
        grams[part].row(j) += w * Eigen::Map<const Eigen::RowVectorXd>(xx.data(), q * q);
        for (int ch = 0; ch < c; ++ch) {
          const double r = static_cast<double>(frames[i].values(j, ch) - y(j, ch));
          sums[part].row(static_cast<Eigen::Index>(j) * c + ch) += (w * r) * x.transpose();
        }
      }
    }
  });
  for (int part = 1; part < parts; ++part) {
    sums[0] += sums[part];
    grams[0] += grams[part];
  }
  Tables tables;
  tables.background = Image(rows, cols, c);
  tables.lighting = Eigen::MatrixXf::Zero(static_cast<Eigen::Index>(n) * c, k_light);
  for (int j = 0; j < n; ++j) {
    const double weight = grams[0](j, 0);  // sum_i w_i
    if (!(weight > 0)) continue;  // no frame weighs the pixel
    Eigen::MatrixXd solution(q, c);
    if (q == 1) {
      for (int ch = 0; ch < c; ++ch) {
        solution(0, ch) = sums[0](static_cast<Eigen::Index>(j) * c + ch, 0) / weight;
      }
    } else {
      // A ridge of 1e-9 of the mean diagonal keeps a pixel whose frames' lighting values
      // span fewer than K directions solvable (its tables then the least-norm-like
      // solution).
      const Eigen::RowVectorXd flat = grams[0].row(j);
      Eigen::MatrixXd gram = Eigen::Map<const Eigen::MatrixXd>(flat.data(), q, q);
      gram.diagonal().array() += 1e-9 * gram.diagonal().mean();
      const Eigen::MatrixXd rhs =
          sums[0].middleRows(static_cast<Eigen::Index>(j) * c, c).transpose();  // q x C
      solution = gram.ldlt().solve(rhs);
    }
    for (int ch = 0; ch < c; ++ch) {
      tables.background.data[static_cast<std::size_t>(j) * c + ch] =
          static_cast<float>(solution(0, ch));
      for (int k = 0; k < k_light; ++k) {
        tables.lighting(static_cast<Eigen::Index>(j) * c + ch, k) =
            static_cast<float>(solution(1 + k, ch));
      }
    }
  }
  return tables;
}

}  // namespace tactfunc
