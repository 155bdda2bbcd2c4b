// Copyright 2026 The tactfunc Authors.
#include "estimation/synthesis/generator_training.h"

#include <algorithm>
#include <boost/random/mersenne_twister.hpp>
#include <boost/random/uniform_int_distribution.hpp>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <numeric>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include "estimation/training/internal/checkpoint.h"
#include "models/core/internal/checks.h"
#include "models/core/seed.h"
#include "models/core/sensor.h"
#include "models/core/tensor_file.h"
#include "nlohmann/json.hpp"

namespace tactfunc {
namespace {

using internal::Check;

// Adam over one flat vector.
class Adam {
 public:
  Adam(const GeneratorTrainingOptions& o, Eigen::Index size)
      : o_(o), m_(Eigen::VectorXd::Zero(size)), v_(Eigen::VectorXd::Zero(size)) {}
  // scale: each coordinate's step as a fraction of lr (empty: 1 for all).
  void Step(double lr, const Eigen::VectorXd& g, const Eigen::VectorXd& scale,
            Eigen::VectorXd* x) {
    ++t_;
    m_ = o_.beta1 * m_ + (1 - o_.beta1) * g;
    v_ = o_.beta2 * v_ + (1 - o_.beta2) * g.cwiseAbs2();
    const double c1 = 1 - std::pow(o_.beta1, t_), c2 = 1 - std::pow(o_.beta2, t_);
    const Eigen::ArrayXd step = m_.array() / ((v_.array() / c2).sqrt() + o_.epsilon);
    if (scale.size() == 0) {
      *x -= (lr / c1) * step.matrix();
    } else {
      *x -= (lr / c1) * (step * scale.array()).matrix();
    }
  }
  const Eigen::VectorXd& m() const { return m_; }
  const Eigen::VectorXd& v() const { return v_; }
  int t() const { return t_; }
  void Restore(Eigen::VectorXd m, Eigen::VectorXd v, int t) {
    m_ = std::move(m);
    v_ = std::move(v);
    t_ = t;
  }

 private:
  GeneratorTrainingOptions o_;
  Eigen::VectorXd m_, v_;
  int t_ = 0;
};

double LearningRate(const GeneratorTrainingOptions& o, int epoch) {
  const double t = o.epochs > 1 ? static_cast<double>(epoch) / (o.epochs - 1) : 1.0;
  const double f = o.final_lr_fraction + (1 - o.final_lr_fraction) * 0.5 * (1 + std::cos(M_PI * t));
  return o.learning_rate * f;
}

Eigen::MatrixXd FeatureMatrix(const PoseGenerator& g, const std::vector<GeneratorSample>& s) {
  Eigen::MatrixXd f(s.size(), g.feature_dim());
  for (std::size_t i = 0; i < s.size(); ++i) {
    Check(s[i].tool >= 0 && s[i].tool < g.num_tools(),
          "generator training: sample " + std::to_string(i) + " has tool index " +
              std::to_string(s[i].tool) + ", expected [0, " + std::to_string(g.num_tools()) + ")");
    f.row(i) = g.Features(s[i].tool, s[i].sensor_T_object, s[i].depth_m).transpose();
  }
  return f;
}

std::vector<int> Shuffled(int m, std::uint64_t seed) {
  std::vector<int> order(m);
  std::iota(order.begin(), order.end(), 0);
  boost::random::mt19937_64 rng(seed);
  for (int i = m - 1; i > 0; --i) {
    boost::random::uniform_int_distribution<int> u(0, i);
    std::swap(order[i], order[u(rng)]);
  }
  return order;
}

// FNV-1a of the samples' tools and poses, continued from `hash`.
std::uint64_t SamplesFingerprint(const std::vector<GeneratorSample>& samples,
                                 std::uint64_t hash = 1469598103934665603ull) {
  for (const GeneratorSample& s : samples) {
    const double pose[4] = {s.sensor_T_object.x(), s.sensor_T_object.y(),
                            s.sensor_T_object.yaw(), s.depth_m};
    hash = internal::Fnv1a(&s.tool, sizeof(s.tool), hash);
    hash = internal::Fnv1a(pose, sizeof(pose), hash);
  }
  return hash;
}

// The checkpoint's identity (header comment): the stage, the options that shape the
// trajectory and the generator's size; the frames are the samples (and their targets).
internal::CheckpointRun GeneratorCheckpointRun(const GeneratorTrainingOptions& o,
                                               const std::string& stage,
                                               const PoseGenerator& generator,
                                               Eigen::Index num_parameters, int m,
                                               std::uint64_t fingerprint) {
  const nlohmann::json options = {{"stage", stage},
                                  {"epochs", o.epochs},
                                  {"batch_size", o.batch_size},
                                  {"learning_rate", o.learning_rate},
                                  {"beta1", o.beta1},
                                  {"beta2", o.beta2},
                                  {"epsilon", o.epsilon},
                                  {"final_lr_fraction", o.final_lr_fraction},
                                  {"pixels_per_frame", o.pixels_per_frame},
                                  {"standardize_outputs", o.standardize_outputs},
                                  {"seed", std::to_string(o.seed)},
                                  {"hidden_sizes", generator.options().hidden_sizes},
                                  {"yaw_harmonics", generator.options().yaw_harmonics},
                                  {"tools", generator.options().tools},
                                  {"trunk_step_fraction", o.trunk_step_fraction},
                                  {"num_parameters", num_parameters}};
  internal::CheckpointRun run;
  run.format = "tactfunc-generator-checkpoint";
  run.version = 1;
  run.sensor = ToString(SensorKind::kSoftBubble);  // the generator path's sensor
  run.options_json = options.dump();
  run.fingerprint = fingerprint;
  run.num_frames = m;
  return run;
}

// Adam over theta (initially `theta`, each coordinate's step scaled by step_scale, empty:
// all 1); `apply` hands the parameters to the model after each epoch and on resuming.
template <typename BatchLoss>
GeneratorTrainingSummary RunAdam(const PoseGenerator& generator, Eigen::VectorXd theta,
                                 const Eigen::VectorXd& step_scale,
                                 const std::function<void(const Eigen::VectorXd&)>& apply, int m,
                                 const GeneratorTrainingOptions& options,
                                 const GeneratorProgressCallback& progress, const std::string& stage,
                                 std::uint64_t fingerprint, const BatchLoss& batch_loss) {
  const auto start = std::chrono::steady_clock::now();
  GeneratorTrainingSummary summary;
  const Eigen::Index n = theta.size();
  Adam adam(options, n);
  const std::string& path = options.checkpoint_path;
  const internal::CheckpointRun run =
      GeneratorCheckpointRun(options, stage, generator, n, m, fingerprint);
  int first_epoch = 0;
  double seconds_before = 0;
  if (!path.empty() && options.resume && std::filesystem::exists(path)) {
    nlohmann::json meta;
    const TensorFile file = internal::ReadCheckpoint(path, run, &meta);
    first_epoch = meta.at("step").get<int>();
    seconds_before = meta.at("train_seconds").get<double>();
    if (first_epoch < 1 || first_epoch > options.epochs) {
      throw std::runtime_error("checkpoint " + path + ": meta.step " + std::to_string(first_epoch) +
                               " is outside [1, " + std::to_string(options.epochs) + "] epochs");
    }
    theta = internal::CheckpointVector(file, "parameters", n);
    adam.Restore(internal::CheckpointVector(file, "adam_m", n),
                 internal::CheckpointVector(file, "adam_v", n),
                 static_cast<int>(internal::CheckpointVector(file, "adam_t", 1)[0]));
    const Eigen::VectorXd history = internal::CheckpointVector(file, "loss_history", first_epoch);
    summary.loss_history.assign(history.data(), history.data() + history.size());
    apply(theta);
    summary.epochs_resumed = summary.epochs_completed = first_epoch;
  }
  auto write_checkpoint = [&](int epochs_done) {
    const double seconds =
        seconds_before +
        std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    TensorFile file = internal::NewCheckpoint(run, epochs_done, seconds);
    const auto f64 = TensorFile::DType::kFloat64;
    file.Add("parameters", f64, {n}, internal::ToStdVector(theta));
    file.Add("adam_m", f64, {n}, internal::ToStdVector(adam.m()));
    file.Add("adam_v", f64, {n}, internal::ToStdVector(adam.v()));
    file.Add("adam_t", f64, {1}, {static_cast<double>(adam.t())});
    file.Add("loss_history", f64, {static_cast<std::int64_t>(summary.loss_history.size())},
             summary.loss_history);
    file.Write(path);
  };
  for (int epoch = first_epoch; epoch < options.epochs; ++epoch) {
    const std::vector<int> order = Shuffled(m, DeriveSeed(options.seed, epoch));
    const double lr = LearningRate(options, epoch);
    double sum = 0;
    int batches = 0;
    for (int b = 0; b < m; b += options.batch_size) {
      const std::vector<int> rows(order.begin() + b,
                                  order.begin() + std::min(m, b + options.batch_size));
      Eigen::VectorXd gradient;
      sum += batch_loss(theta, rows, epoch, &gradient);
      ++batches;
      adam.Step(lr, gradient, step_scale, &theta);
    }
    const double loss = sum / std::max(1, batches);
    if (!std::isfinite(loss)) break;
    apply(theta);
    summary.loss_history.push_back(loss);
    summary.epochs_completed = epoch + 1;
    const bool stop = progress && !progress(epoch, loss);
    if (!path.empty() &&
        (stop || (epoch + 1) % options.checkpoint_every == 0 || epoch + 1 == options.epochs)) {
      write_checkpoint(epoch + 1);
    }
    if (stop) break;
  }
  if (!summary.loss_history.empty()) {
    summary.initial_loss = summary.loss_history.front();
    summary.final_loss = summary.loss_history.back();
  }
  summary.total_time_in_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

}  // namespace

bool GeneratorTrainingOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& m) {
    if (error != nullptr) *error = "GeneratorTrainingOptions: " + m;
    return false;
  };
  if (epochs < 1) return fail("epochs must be >= 1");
  if (batch_size < 1) return fail("batch_size must be >= 1");
  if (!(learning_rate > 0)) return fail("learning_rate must be > 0");
  if (!(beta1 >= 0 && beta1 < 1 && beta2 >= 0 && beta2 < 1)) return fail("betas must be in [0, 1)");
  if (!(epsilon > 0)) return fail("epsilon must be > 0");
  if (!(final_lr_fraction >= 0 && final_lr_fraction <= 1)) {
    return fail("final_lr_fraction must be in [0, 1]");
  }
  if (pixels_per_frame < 1) return fail("pixels_per_frame must be >= 1");
  if (checkpoint_every < 1) return fail("checkpoint_every must be >= 1");
  if (resume && checkpoint_path.empty()) return fail("resume requires a checkpoint_path");
  if (!(trunk_step_fraction >= 0)) return fail("trunk_step_fraction must be >= 0");
  return true;
}

std::string GeneratorTrainingSummary::BriefReport() const {
  char buffer[160];
  std::snprintf(buffer, sizeof(buffer), "%d epochs, loss %.6g -> %.6g (%.1f s)", epochs_completed,
                initial_loss, final_loss, total_time_in_seconds);
  return buffer;
}

GeneratorTrainingSummary TrainGeneratorOnLatents(PoseGenerator* generator,
                                                 const std::vector<GeneratorSample>& samples,
                                                 const Eigen::MatrixXd& latents,
                                                 const GeneratorTrainingOptions& options,
                                                 const GeneratorProgressCallback& progress) {
  std::string error;
  Check(options.IsValid(&error), error);
  Check(generator != nullptr, "TrainGeneratorOnLatents: null generator");
  Check(options.trunk_step_fraction == 0,
        "TrainGeneratorOnLatents: trunk_step_fraction applies to training on pixels only");
  const int m = static_cast<int>(samples.size());
  Check(m > 0 && latents.rows() == m && latents.cols() == generator->latent_dim(),
        "TrainGeneratorOnLatents: expected " + std::to_string(m) + " x " +
            std::to_string(generator->latent_dim()) + " latents (one per sample, M > 0), got " +
            std::to_string(latents.rows()) + " x " + std::to_string(latents.cols()));
  Check(latents.allFinite(), "TrainGeneratorOnLatents: the latents hold non-finite values");
  if (options.standardize_outputs) {
    const Eigen::VectorXd mean = latents.colwise().mean().transpose();
    Eigen::VectorXd stddev =
        ((latents.rowwise() - mean.transpose()).cwiseAbs2().colwise().mean()).cwiseSqrt().transpose();
    for (Eigen::Index k = 0; k < stddev.size(); ++k) {
      if (!(stddev[k] > 1e-6)) stddev[k] = 1;
    }
    generator->SetLatentStandardization(mean, stddev);
  }
  const Eigen::MatrixXd features = FeatureMatrix(*generator, samples);
  const Eigen::VectorXd inv_var = generator->latent_stddev().cwiseAbs2().cwiseInverse();
  const double d = generator->latent_dim();
  const std::uint64_t fingerprint = internal::Fnv1a(
      latents.data(), sizeof(double) * static_cast<std::size_t>(latents.size()),
      SamplesFingerprint(samples));
  return RunAdam(*generator, generator->parameters(), Eigen::VectorXd(),
                 [generator](const Eigen::VectorXd& p) { generator->SetParameters(p); }, m,
                 options, progress, "latents", fingerprint,
                 [&](const Eigen::VectorXd& theta, const std::vector<int>& rows, int,
                     Eigen::VectorXd* gradient) {
                   const int b = static_cast<int>(rows.size());
                   Eigen::MatrixXd f(b, features.cols()), z(b, latents.cols());
                   for (int i = 0; i < b; ++i) {
                     f.row(i) = features.row(rows[i]);
                     z.row(i) = latents.row(rows[i]);
                   }
                   const Eigen::MatrixXd diff = generator->Forward(theta, f) - z;
                   const Eigen::MatrixXd weighted = diff.array().rowwise() * inv_var.transpose().array();
                   const double loss = (weighted.array() * diff.array()).sum() / (b * d);
                   generator->Backward(theta, f, (2.0 / (b * d)) * weighted, gradient, nullptr);
                   return loss;
                 });
}

GeneratorTrainingSummary TrainGeneratorOnPixels(PoseGenerator* generator,
                                                const SensorTrunk& trunk,
                                                const std::vector<GeneratorSample>& samples,
                                                const std::vector<TrunkTargets>& frames,
                                                const GeneratorTrainingOptions& options,
                                                const GeneratorProgressCallback& progress,
                                                LatentModulatedSiren* tuned_siren) {
  std::string error;
  Check(options.IsValid(&error), error);
  Check(generator != nullptr, "TrainGeneratorOnPixels: null generator");
  Check(trunk.photometric == nullptr,
        "TrainGeneratorOnPixels: renders through the direct trunk; the photometric trunk has "
        "no pose generator yet");
  Check(generator->latent_dim() == trunk.siren.latent_dim(),
        "TrainGeneratorOnPixels: the generator's latent_dim " +
            std::to_string(generator->latent_dim()) + " is not the trunk's " +
            std::to_string(trunk.siren.latent_dim()));
  const bool tune = options.trunk_step_fraction > 0;
  Check(!tune || tuned_siren != nullptr,
        "TrainGeneratorOnPixels: trunk_step_fraction > 0 needs a tuned_siren to write");
  // The SIREN the loss passes run through: the trunk's own, or a copy trained along.
  std::optional<LatentModulatedSiren> tuned;
  if (tune) tuned.emplace(trunk.siren);
  const LatentModulatedSiren& siren = tune ? *tuned : trunk.siren;
  const Eigen::Index generator_size = generator->parameters().size();
  const int m = static_cast<int>(samples.size());
  Check(m > 0 && static_cast<int>(frames.size()) == m,
        "TrainGeneratorOnPixels: expected one frame per sample (" + std::to_string(m) +
            "), got " + std::to_string(frames.size()));
  const int channels = siren.output_channels();
  // Valid pixels and the grid of each frame's resolution.
  std::vector<std::vector<int>> valid(m);
  std::vector<Eigen::MatrixXf> grids;
  std::vector<int> grid_of(m);
  std::vector<std::pair<int, int>> sizes;
  for (int i = 0; i < m; ++i) {
    const TrunkTargets& t = frames[i];
    Check(t.values.rows() == t.rows * t.cols && t.values.cols() == channels &&
              t.weights.size() == t.values.rows(),
          "TrainGeneratorOnPixels: frame " + std::to_string(i) + " has the wrong shape");
    for (Eigen::Index j = 0; j < t.weights.size(); ++j) {
      if (t.weights[j] > 0) valid[i].push_back(static_cast<int>(j));
    }
    const std::pair<int, int> size(t.rows, t.cols);
    auto it = std::find(sizes.begin(), sizes.end(), size);
    if (it == sizes.end()) {
      sizes.push_back(size);
      grids.push_back(siren.Grid<float>(t.rows, t.cols));
      grid_of[i] = static_cast<int>(grids.size()) - 1;
    } else {
      grid_of[i] = static_cast<int>(it - sizes.begin());
    }
  }
  const Eigen::MatrixXd features = FeatureMatrix(*generator, samples);
  const int p = options.pixels_per_frame;
  std::uint64_t fingerprint = SamplesFingerprint(samples);
  for (const TrunkTargets& t : frames) {
    fingerprint = internal::Fnv1a(t.values.data(),
                                  sizeof(float) * static_cast<std::size_t>(t.values.size()),
                                  fingerprint);
    fingerprint = internal::Fnv1a(t.weights.data(),
                                  sizeof(float) * static_cast<std::size_t>(t.weights.size()),
                                  fingerprint);
  }
  // theta = the generator's parameters, then (tuning) the SIREN's.
  const Eigen::Index trunk_size = tune ? tuned->NumParameters() : 0;
  Eigen::VectorXd theta0(generator_size + trunk_size), step_scale;
  theta0 << generator->parameters(), (tune ? tuned->parameters() : Eigen::VectorXd());
  if (tune) {
    step_scale = Eigen::VectorXd::Ones(theta0.size());
    step_scale.tail(trunk_size).setConstant(options.trunk_step_fraction);
  }
  const auto apply = [&](const Eigen::VectorXd& theta) {
    generator->SetParameters(theta.head(generator_size));
    if (tune) tuned->SetParameters(theta.tail(trunk_size));
  };
  const GeneratorTrainingSummary summary = RunAdam(
      *generator, theta0, step_scale, apply, m, options, progress, "pixels", fingerprint,
      [&](const Eigen::VectorXd& theta, const std::vector<int>& rows, int epoch,
          Eigen::VectorXd* gradient) {
        const int b = static_cast<int>(rows.size());
        Eigen::MatrixXd f(b, features.cols());
        for (int i = 0; i < b; ++i) f.row(i) = features.row(rows[i]);
        const Eigen::VectorXd generator_theta = theta.head(generator_size);
        if (tune) tuned->SetParameters(theta.tail(trunk_size));
        const Eigen::MatrixXd z = generator->Forward(generator_theta, f);
        Eigen::VectorXd trunk_gradient = Eigen::VectorXd::Zero(trunk_size);
        Eigen::MatrixXd dL_dZ(b, z.cols());
        double loss = 0;
        for (int i = 0; i < b; ++i) {
          const int s = rows[i];
          const std::vector<int>& v = valid[s];
          if (v.empty()) {
            dL_dZ.row(i).setZero();
            continue;
          }
          boost::random::mt19937_64 rng(DeriveSeed(DeriveSeed(options.seed, epoch), s));
          boost::random::uniform_int_distribution<int> u(0, static_cast<int>(v.size()) - 1);
          const int count = std::min<int>(p, static_cast<int>(v.size()));
          Eigen::MatrixXf coords(count, 2), targets(count, channels);
          const Eigen::MatrixXf& grid = grids[grid_of[s]];
          for (int j = 0; j < count; ++j) {
            const int pixel = count == static_cast<int>(v.size()) ? v[j] : v[u(rng)];
            coords.row(j) = grid.row(pixel);
            targets.row(j) = frames[s].values.row(pixel);
          }
          Eigen::VectorXf dz, dtheta;
          const Eigen::VectorXf zf = z.row(i).transpose().cast<float>();
          loss += siren.LossAndGradient<float>(coords, zf, targets, Eigen::VectorXf(), &dz,
                                               tune ? &dtheta : nullptr);
          dL_dZ.row(i) = dz.cast<double>().transpose() / b;
          if (tune) trunk_gradient += dtheta.cast<double>() / b;
        }
        Eigen::VectorXd generator_gradient;
        generator->Backward(generator_theta, f, dL_dZ, &generator_gradient, nullptr);
        gradient->resize(theta.size());
        *gradient << generator_gradient, trunk_gradient;
        return loss / b;
      });
  if (tune) *tuned_siren = *tuned;
  return summary;
}

double MeanGeneratorPsnr(const PoseGenerator& generator, const SensorTrunk& trunk,
                         const std::vector<GeneratorSample>& samples,
                         const std::vector<TrunkTargets>& frames) {
  Check(samples.size() == frames.size(), "MeanGeneratorPsnr: one frame per sample expected");
  double sum = 0;
  int count = 0;
  for (std::size_t i = 0; i < samples.size(); ++i) {
    const Eigen::VectorXf z = generator
                                  .Generate(samples[i].tool, samples[i].sensor_T_object,
                                            samples[i].depth_m)
                                  .cast<float>();
    const Eigen::MatrixXf grid = trunk.siren.Grid<float>(frames[i].rows, frames[i].cols);
    const double psnr = Psnr(trunk.siren.Forward<float>(grid, z), frames[i]);
    if (std::isfinite(psnr)) {
      sum += psnr;
      ++count;
    }
  }
  return count > 0 ? sum / count : 0;
}

}  // namespace tactfunc
