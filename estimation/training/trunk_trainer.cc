// Copyright 2026 The tactfunc Authors.
#include "estimation/training/trunk_trainer.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iomanip>
#include <limits>
#include <numeric>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "boost/random/mersenne_twister.hpp"
#include "boost/random/uniform_int_distribution.hpp"
#include "boost/random/uniform_real_distribution.hpp"
#include "estimation/data/dataset.h"
#include "estimation/training/internal/checkpoint.h"
#include "models/core/parallel_for.h"
#include "models/core/seed.h"
#include "models/core/tensor_file.h"
#include "models/trunk/product_precision.h"
#include "Eigen/Eigenvalues"
#include "nlohmann/json.hpp"

namespace tactfunc {
namespace {

using Clock = std::chrono::steady_clock;
using Json = nlohmann::json;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

// Independent random streams of one run: DeriveSeed(DeriveSeed(seed, stream), index).
enum Stream : std::uint64_t {
  kThetaStream = 1,
  kAlphaStream = 2,
  kEpochStream = 3,
  kPixelStream = 4,
  kMonitorStream = 5,
  kResidualStream = 6,
};
std::uint64_t StreamSeed(std::uint64_t seed, Stream stream) { return DeriveSeed(seed, stream); }

// A seeded permutation of [0, n) (Fisher-Yates with Boost's portable distributions).
std::vector<int> Permutation(int n, std::uint64_t seed) {
  std::vector<int> perm(n);
  std::iota(perm.begin(), perm.end(), 0);
  boost::random::mt19937_64 rng(seed);
  for (int i = n - 1; i > 0; --i) {
    boost::random::uniform_int_distribution<int> pick(0, i);
    std::swap(perm[i], perm[pick(rng)]);
  }
  return perm;
}

// The first k entries of a seeded permutation of [0, n) (partial Fisher-Yates).
std::vector<int> Sample(int n, int k, std::uint64_t seed) {
  std::vector<int> items(n);
  std::iota(items.begin(), items.end(), 0);
  boost::random::mt19937_64 rng(seed);
  k = std::min(k, n);
  for (int i = 0; i < k; ++i) {
    boost::random::uniform_int_distribution<int> pick(i, n - 1);
    std::swap(items[i], items[pick(rng)]);
  }
  items.resize(k);
  return items;
}

// Mean of the finite values (PSNR is +inf for a perfect fit, NaN with no valid pixel).
double MeanFinite(const std::vector<double>& values) {
  double sum = 0;
  int count = 0;
  for (double v : values) {
    if (std::isfinite(v)) {
      sum += v;
      ++count;
    }
  }
  return count > 0 ? sum / count : std::numeric_limits<double>::quiet_NaN();
}

std::string FormatDouble(double value, int precision = 4) {
  std::ostringstream out;
  out << std::setprecision(precision) << value;
  return out.str();
}

// Completes `results` (one per batch slot) in every process of `group`: each process
// computed the slots of its Share, the others' are copied in bit for bit.
void GatherSlots(const ProcessGroup& group, int num_parameters, int latent_dim,
                 std::vector<MetaSgd::Result<float>>* results) {
  const auto batch = static_cast<std::int64_t>(results->size());
  std::int64_t begin, end;
  group.Share(batch, group.rank(), &begin, &end);
  ByteWriter writer;
  for (std::int64_t b = begin; b < end; ++b) {
    const MetaSgd::Result<float>& r = (*results)[b];
    writer.Put(r.loss);
    writer.Put(r.loss_at_zero);
    writer.PutFloats(r.dL_dtheta.data(), r.dL_dtheta.size());
    writer.PutFloats(r.dL_dalpha.data(), r.dL_dalpha.size());
  }
  const std::vector<Bytes> all = group.AllGather(writer.bytes());
  auto read = [](ByteReader& reader, int expected, Eigen::VectorXf* v) {
    const std::size_t count = reader.FloatCount();
    if (count != static_cast<std::size_t>(expected)) {
      throw std::runtime_error("TrunkTrainer: another process sent a gradient of " +
                               std::to_string(count) + " values, expected " +
                               std::to_string(expected) + " (do all run the same options?)");
    }
    v->resize(expected);
    reader.GetFloats(v->data(), count);
  };
  for (int rank = 0; rank < group.size(); ++rank) {
    if (rank == group.rank()) continue;
    group.Share(batch, rank, &begin, &end);
    ByteReader reader(all[rank]);
    for (std::int64_t b = begin; b < end; ++b) {
      MetaSgd::Result<float>& r = (*results)[b];
      r.loss = reader.Get<float>();
      r.loss_at_zero = reader.Get<float>();
      read(reader, num_parameters, &r.dL_dtheta);
      read(reader, latent_dim, &r.dL_dalpha);
    }
  }
}

// Everything the optimiser carries from step to step.
struct TrainingState {
  int step = 0;
  Eigen::VectorXd theta, alpha;
  Eigen::VectorXd m_theta, v_theta, m_alpha, v_alpha;  // Adam moments
  std::vector<TrunkTrainer::HistoryPoint> history;
  double loss_sum = 0;  // outer losses since the last history point
  int loss_count = 0;
  double train_seconds = 0;  // training-loop seconds of earlier runs
};

const char* kCheckpointFormat = "tactfunc-checkpoint";
constexpr int kCheckpointVersion = 1;
constexpr int kHistoryColumns = 5;

internal::CheckpointRun CheckpointRunOf(SensorKind sensor, const std::string& options_json,
                                        std::uint64_t fingerprint, int num_frames) {
  return {kCheckpointFormat, kCheckpointVersion, ToString(sensor), options_json, fingerprint,
          num_frames};
}

void WriteCheckpoint(const std::string& path, const TrainingState& state, SensorKind sensor,
                     const std::string& options_json, std::uint64_t fingerprint, int num_frames) {
  using internal::ToStdVector;
  TensorFile file =
      internal::NewCheckpoint(CheckpointRunOf(sensor, options_json, fingerprint, num_frames),
                              state.step, state.train_seconds);
  using D = TensorFile::DType;
  const auto n = static_cast<std::int64_t>(state.theta.size());
  const auto d = static_cast<std::int64_t>(state.alpha.size());
  file.Add("theta", D::kFloat64, {n}, ToStdVector(state.theta));
  file.Add("alpha", D::kFloat64, {d}, ToStdVector(state.alpha));
  file.Add("adam/theta_m", D::kFloat64, {n}, ToStdVector(state.m_theta));
  file.Add("adam/theta_v", D::kFloat64, {n}, ToStdVector(state.v_theta));
  file.Add("adam/alpha_m", D::kFloat64, {d}, ToStdVector(state.m_alpha));
  file.Add("adam/alpha_v", D::kFloat64, {d}, ToStdVector(state.v_alpha));
  std::vector<double> history;
  for (const TrunkTrainer::HistoryPoint& p : state.history) {
    history.insert(history.end(),
                   {static_cast<double>(p.step), p.loss, p.psnr, p.psnr_at_zero, p.seconds});
  }
  file.Add("history", D::kFloat64,
           {static_cast<std::int64_t>(state.history.size()), kHistoryColumns}, std::move(history));
  file.Add("loss_accumulator", D::kFloat64, {2},
           {state.loss_sum, static_cast<double>(state.loss_count)});
  file.Write(path);
}

// Reads a checkpoint into *state after checking that it belongs to this run.
void ReadCheckpoint(const std::string& path, SensorKind sensor, const std::string& options_json,
                    std::uint64_t fingerprint, int num_frames, int num_parameters, int latent_dim,
                    TrainingState* state) {
  Json meta;
  const TensorFile file = internal::ReadCheckpoint(
      path, CheckpointRunOf(sensor, options_json, fingerprint, num_frames), &meta);
  const std::string where = "checkpoint " + path + ": ";
  auto vec = [&](const std::string& name, int size) {
    return internal::CheckpointVector(file, name, size);
  };
  state->step = meta.at("step").get<int>();
  state->train_seconds = meta.at("train_seconds").get<double>();
  state->theta = vec("theta", num_parameters);
  state->alpha = vec("alpha", latent_dim);
  state->m_theta = vec("adam/theta_m", num_parameters);
  state->v_theta = vec("adam/theta_v", num_parameters);
  state->m_alpha = vec("adam/alpha_m", latent_dim);
  state->v_alpha = vec("adam/alpha_v", latent_dim);
  const TensorFile::Tensor& history = file.Get("history");
  if (history.shape.size() != 2 || history.shape[1] != kHistoryColumns) {
    throw TensorFileError(where + "tensor 'history' must be H x 5");
  }
  state->history.clear();
  for (std::int64_t i = 0; i < history.shape[0]; ++i) {
    const double* row = history.values.data() + i * kHistoryColumns;
    TrunkTrainer::HistoryPoint p;
    p.step = static_cast<int>(row[0]);
    p.loss = row[1];
    p.psnr = row[2];
    p.psnr_at_zero = row[3];
    p.seconds = row[4];
    state->history.push_back(p);
  }
  const TensorFile::Tensor& accumulator = file.Get("loss_accumulator", {2});
  state->loss_sum = accumulator.values[0];
  state->loss_count = static_cast<int>(accumulator.values[1]);
}

// The default working resolution of each sensor (see Options::rows).
void DefaultResolution(SensorKind sensor, int* rows, int* cols) {
  if (sensor == SensorKind::kSoftBubble) {
    *rows = 70;
    *cols = 88;
  } else {
    *rows = 80;
    *cols = 107;
  }
}

// "" if the newest point of `history` is within `drop_db` of the best finite point
// before it (or the check is off, drop_db = 0); else the divergence message. A newest
// point whose PSNR is NaN counts as diverged once an earlier point was finite. The best
// is taken over the whole history, earlier runs included: a resumed run sees the
// points of the runs before it.
std::string DivergenceMessage(const std::vector<TrunkTrainer::HistoryPoint>& history,
                              double drop_db) {
  if (!(drop_db > 0) || history.size() < 2) return "";
  const TrunkTrainer::HistoryPoint& latest = history.back();
  const TrunkTrainer::HistoryPoint* best = nullptr;
  for (const TrunkTrainer::HistoryPoint& p : history) {
    if (std::isfinite(p.psnr) && (best == nullptr || p.psnr > best->psnr)) best = &p;
  }
  if (best == nullptr || latest.psnr >= best->psnr - drop_db) return "";
  return "diverged: the monitor PSNR fell from " + FormatDouble(best->psnr, 4) + " dB at step " +
         std::to_string(best->step) + " to " + FormatDouble(latest.psnr, 4) + " dB at step " +
         std::to_string(latest.step) + ", more than divergence_drop_db = " +
         FormatDouble(drop_db, 3) + "; start again (without resume) with a smaller learning_rate";
}

}  // namespace

// ---- Options ---------------------------------------------------------------------

LatentModulatedSiren::Options TrunkTrainer::Options::DefaultSirenOptions() {
  LatentModulatedSiren::Options siren;
  siren.width = 64;
  siren.num_hidden_layers = 3;
  siren.latent_dim = 128;
  siren.omega_0 = 30.0;
  return siren;
}

MetaSgd::Options TrunkTrainer::Options::DefaultMetaSgdOptions() {
  MetaSgd::Options meta;
  meta.inner_steps = 3;
  meta.latent_l2_weight = 1e-5;
  meta.first_order = false;
  return meta;
}

bool TrunkTrainer::Options::IsValid(std::string* error) const {
  std::ostringstream message;
  std::string inner;
  auto finite_positive = [](double v) { return std::isfinite(v) && v > 0; };
  LatentModulatedSiren::Options siren_check = siren;
  siren_check.output_channels = 1;  // set from the format, not by the caller
  if (!siren_check.IsValid(&inner)) {
    message << "siren: " << inner;
  } else if (rows < 0 || cols < 0 || (rows == 0) != (cols == 0)) {
    message << "rows and cols must both be 0 (the sensor's default) or both > 0, found " << rows
            << " x " << cols;
  } else if (skip_frames_at_rest && !contact.IsValid(&inner)) {
    message << "contact: " << inner;
  } else if (!(normalization_scale >= 0) || !std::isfinite(normalization_scale)) {
    message << "normalization_scale must be finite and >= 0, found " << normalization_scale;
  } else if (!meta_sgd.IsValid(&inner)) {
    message << "meta_sgd: " << inner;
  } else if (!finite_positive(learning_rate)) {
    message << "learning_rate must be finite and > 0, found " << learning_rate;
  } else if (!(learning_rate_final_fraction > 0 && learning_rate_final_fraction <= 1)) {
    message << "learning_rate_final_fraction must be in (0, 1], found "
            << learning_rate_final_fraction;
  } else if (!finite_positive(alpha_learning_rate)) {
    message << "alpha_learning_rate must be finite and > 0, found " << alpha_learning_rate;
  } else if (!(adam_beta1 >= 0 && adam_beta1 < 1)) {
    message << "adam_beta1 must be in [0, 1), found " << adam_beta1;
  } else if (!(adam_beta2 >= 0 && adam_beta2 < 1)) {
    message << "adam_beta2 must be in [0, 1), found " << adam_beta2;
  } else if (!finite_positive(adam_epsilon)) {
    message << "adam_epsilon must be finite and > 0, found " << adam_epsilon;
  } else if (!finite_positive(alpha_max)) {
    message << "alpha_max must be finite and > 0, found " << alpha_max;
  } else if (!(alpha_init_min >= 0 && alpha_init_min <= alpha_init_max &&
               alpha_init_max <= alpha_max)) {
    message << "alpha_init_min and alpha_init_max must satisfy 0 <= min <= max <= alpha_max ("
            << alpha_max << "), found " << alpha_init_min << " and " << alpha_init_max;
  } else if (!(readout_learning_rate_scale >= 0 && readout_learning_rate_scale <= 1)) {
    message << "readout_learning_rate_scale must be in [0, 1], found "
            << readout_learning_rate_scale;
  } else if (readout_pca_frames < 1) {
    message << "readout_pca_frames must be >= 1, found " << readout_pca_frames;
  } else if (batch_size < 1) {
    message << "batch_size must be >= 1, found " << batch_size;
  } else if (pixels_per_frame < 0) {
    message << "pixels_per_frame must be >= 0 (0 = all), found " << pixels_per_frame;
  } else if (steps < 0) {
    message << "steps must be >= 0, found " << steps;
  } else if (threads < 1 || threads > 256) {
    message << "threads must be in [1, 256], found " << threads;
  } else if (checkpoint_every < 0) {
    message << "checkpoint_every must be >= 0 (0 = only at the end), found " << checkpoint_every;
  } else if (resume && checkpoint_path.empty()) {
    message << "resume requires a checkpoint_path";
  } else if (monitor_every < 1) {
    message << "monitor_every must be >= 1, found " << monitor_every;
  } else if (monitor_frames < 1) {
    message << "monitor_frames must be >= 1, found " << monitor_frames;
  } else if (residual_frames < 1) {
    message << "residual_frames must be >= 1, found " << residual_frames;
  } else if (!(std::isfinite(divergence_drop_db) && divergence_drop_db >= 0)) {
    message << "divergence_drop_db must be finite and >= 0 (0 = never), found "
            << divergence_drop_db;
  } else {
    return true;
  }
  if (error != nullptr) *error = "TrunkTrainer::Options::" + message.str();
  return false;
}

std::vector<std::string> TrunkTrainer::PresetNames() {
  return {"tiny", "small", "default", "storage"};
}

TrunkTrainer::Options TrunkTrainer::Preset(const std::string& name, SensorKind sensor) {
  Options options;
  if (name == "tiny") {
    options.siren.width = 32;
    options.siren.num_hidden_layers = 2;
    options.siren.latent_dim = 16;
    options.rows = 16;
    options.cols = 20;
    options.batch_size = 4;
    options.pixels_per_frame = 0;
    options.learning_rate = 1e-3;
    options.alpha_learning_rate = 1e-2;
    options.steps = 300;
    options.learning_rate_final_fraction = 1.0;
    options.monitor_every = 50;
    options.monitor_frames = 8;
    options.checkpoint_every = 100;
  } else if (name == "small") {
    options.siren.width = 64;
    options.siren.num_hidden_layers = 3;
    options.siren.latent_dim = 64;
    options.batch_size = 32;
    options.pixels_per_frame = 512;
    options.steps = 4000;
    options.learning_rate_final_fraction = 1.0;  // the committed trunk's constant rate
    options.monitor_every = 100;
  } else if (name == "default") {
    // Options() as constructed, with the GelSlim's shorter latent.
    if (sensor == SensorKind::kGelSlim) options.siren.latent_dim = 32;
  } else if (name == "storage") {
    options = Preset("small", sensor);
    options.siren.latent_dim = 256;
    options.batch_size = 8;
    options.pixels_per_frame = 0;
    options.steps = 1000;
    options.readout = true;
    options.readout_pca_frames = 20000;
    options.meta_sgd.inner_steps = 0;
    options.outer_loss_on_clean = true;
  } else {
    std::string names;
    for (const std::string& n : PresetNames()) names += (names.empty() ? "" : ", ") + n;
    throw std::invalid_argument("TrunkTrainer: unknown preset '" + name + "', expected one of " +
                                names);
  }
  return options;
}

const char* ToString(TrunkTrainer::TerminationType type) {
  switch (type) {
    case TrunkTrainer::TerminationType::kCompleted:
      return "completed";
    case TrunkTrainer::TerminationType::kUserStopped:
      return "user_stopped";
    case TrunkTrainer::TerminationType::kNonFinite:
      return "non_finite";
    case TrunkTrainer::TerminationType::kDiverged:
      return "diverged";
  }
  return "unknown";
}

// ---- Summary ---------------------------------------------------------------------

std::string TrunkTrainer::Summary::BriefReport() const {
  std::ostringstream out;
  out << "TrunkTrainer (" << ToString(sensor) << "): " << ToString(termination_type) << ", step "
      << steps_done << ", loss " << FormatDouble(final_loss) << ", train PSNR "
      << FormatDouble(train_psnr_at_zero, 3) << " -> " << FormatDouble(train_psnr, 3)
      << " dB (z = 0 -> K steps), " << FormatDouble(wall_seconds, 3) << " s ("
      << FormatDouble(seconds_per_step * 1e3, 3) << " ms/step)";
  return out.str();
}

std::string TrunkTrainer::Summary::FullReport() const {
  std::ostringstream out;
  out << "TrunkTrainer summary (" << ToString(sensor) << ")\n"
      << "  frames           " << num_train_frames << " train, " << format.rows << " x "
      << format.cols << " px" << (format.grayscale ? ", grayscale" : "") << ", scale "
      << format.scale << "\n"
      << "  parameters       " << num_parameters << "\n"
      << "  steps            " << start_step << " -> " << steps_done
      << (start_step > 0 ? " (resumed)" : "") << "\n"
      << "  time             load " << FormatDouble(load_seconds, 3) << " s, train "
      << FormatDouble(wall_seconds, 3) << " s (" << FormatDouble(seconds_per_step * 1e3, 3)
      << " ms/step), all runs " << FormatDouble(total_train_seconds, 3) << " s\n"
      << "  history          step      loss   PSNR(K)  PSNR(z=0)  seconds\n";
  for (const HistoryPoint& p : history) {
    char line[160];
    std::snprintf(line, sizeof(line), "                   %6d %9.3e %8.2f %10.2f %8.1f\n", p.step,
                  p.loss, p.psnr, p.psnr_at_zero, p.seconds);
    out << line;
  }
  out << "  residual sigma   " << FormatDouble(residual_sigma) << "\n"
      << "  termination      " << ToString(termination_type) << ": " << message << "\n";
  return out.str();
}

// ---- Trainer ---------------------------------------------------------------------

TrunkTrainer::TrunkTrainer(const Options& options) : options_(options) {
  std::string error;
  if (!options_.IsValid(&error)) throw std::invalid_argument(error);
}

FrameFormat TrunkTrainer::ResolveFormat(SensorKind sensor, double sensor_scale) const {
  FrameFormat format;
  if (options_.rows > 0) {
    format.rows = options_.rows;
    format.cols = options_.cols;
  } else {
    DefaultResolution(sensor, &format.rows, &format.cols);
  }
  format.grayscale = options_.grayscale;
  format.per_image_min_max = false;
  format.scale = options_.normalization_scale > 0 ? options_.normalization_scale : sensor_scale;
  return format;
}

void TrunkTrainer::StartReadoutFromPca(const std::vector<TrunkTargets>& frames, int max_frames,
                                       LatentModulatedSiren* siren,
                                       const std::vector<TrunkTargets>* noisy_frames) {
  const LatentModulatedSiren::Options& so = siren->options();
  const long channels = so.output_channels;
  const long nodes = static_cast<long>(so.readout_rows) * so.readout_cols;
  if (!so.has_readout() || frames.empty() || frames[0].values.rows() != nodes ||
      frames[0].values.cols() != channels) {
    throw std::invalid_argument(
        "TrunkTrainer::StartReadoutFromPca: the trunk's readout grid (" +
        std::to_string(so.readout_rows) + " x " + std::to_string(so.readout_cols) + " x " +
        std::to_string(channels) + ") must match the frames' pixels and channels");
  }
  if (noisy_frames != nullptr && noisy_frames->size() != frames.size()) {
    throw std::invalid_argument("TrunkTrainer::StartReadoutFromPca: " +
                                std::to_string(noisy_frames->size()) + " noisy frames for " +
                                std::to_string(frames.size()) + " noise-free copies");
  }
  const long p = nodes * channels;
  const int total = static_cast<int>(frames.size());
  const int m = std::max(1, std::min(total, max_frames));
  // Frames M x P, pixel-major rows (entry j C + c = values(j, c), invalid pixels 0), centred.
  auto stack = [&](const std::vector<TrunkTargets>& source) {
    Eigen::MatrixXd out(m, p);
    for (int i = 0; i < m; ++i) {
      const TrunkTargets& t = source[static_cast<std::size_t>(
          (static_cast<long long>(i) * total) / m)];
      for (long j = 0; j < nodes; ++j) {
        const bool valid = t.weights.size() == 0 || t.weights[j] > 0;
        for (long c = 0; c < channels; ++c) {
          out(i, j * channels + c) = valid ? static_cast<double>(t.values(j, c)) : 0.0;
        }
      }
    }
    return out;
  };
  Eigen::MatrixXd X = stack(frames);
  // With noisy copies: the noise of each stacked frame, for the Wiener gains below.
  const Eigen::MatrixXd noise =
      noisy_frames != nullptr ? Eigen::MatrixXd(stack(*noisy_frames) - X) : Eigen::MatrixXd();
  const Eigen::RowVectorXd mean = X.colwise().mean();
  X.rowwise() -= mean;
  // PCA by the smaller of the M x M Gram matrix X X^T and the P x P scatter X^T X: they
  // share their nonzero eigenvalues lambda_k; the scatter's unit eigenvectors are the
  // principal directions u_k, the Gram matrix's v_k give them as X^T v_k / sqrt(lambda_k).
  // (The eigensolver costs the cube of its size: 16,200 frames of 6,160 pixels take
  // minutes through the scatter and far longer through the Gram matrix.)
  const bool by_gram = m <= p;
  const Eigen::MatrixXd product =
      by_gram ? Eigen::MatrixXd(X * X.transpose()) : Eigen::MatrixXd(X.transpose() * X);
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(product);
  const long n = product.rows();
  const int d = so.latent_dim;
  // Scale sqrt(P / 2): the weighted MSE's latent Hessian of the branch is then
  // (2 / P) R R^T = I over a full frame (header comment of Options::readout).
  const double scale = std::sqrt(static_cast<double>(p) / 2.0);
  Eigen::VectorXd theta = siren->parameters();
  auto R = LatentModulatedSiren::View(&theta, siren->Block(ParameterGroup::kReadoutBasis));
  auto mean_block = LatentModulatedSiren::View(&theta, siren->Block(ParameterGroup::kReadoutMean));
  R.setZero();
  mean_block = mean.transpose();
  const double largest = std::max(eigen.eigenvalues()[n - 1], 0.0);
  // Wiener gains (with noisy copies; components not kept get 1): the variance of the
  // copies along unit component u_k, lambda_k / M, against the noise's, the mean of
  // (noise_i . u_k)^2 over the same frames.
  Eigen::VectorXd gains = Eigen::VectorXd::Ones(d);
  // Centred frames span at most m - 1 directions; either product squares the condition
  // number, so eigenvalues below 1e-9 of the largest are rounding, not directions.
  for (int k = 0; k < d && k < m - 1; ++k) {
    const double lambda = eigen.eigenvalues()[n - 1 - k];  // ascending order
    if (!(lambda > 1e-9 * largest)) break;  // no more directions
    const Eigen::VectorXd unit =
        by_gram ? Eigen::VectorXd(X.transpose() * eigen.eigenvectors().col(n - 1 - k) /
                                  std::sqrt(lambda))
                : Eigen::VectorXd(eigen.eigenvectors().col(n - 1 - k));
    R.row(k) = scale * unit.transpose();
    if (noisy_frames != nullptr) {
      const double signal = lambda / m;
      const double noise_variance = (noise * unit).squaredNorm() / m;
      gains[k] = signal / (signal + noise_variance);
    }
  }
  siren->set_start_gains(noisy_frames != nullptr ? gains : Eigen::VectorXd());
  LatentModulatedSiren::View(&theta, siren->Block(ParameterGroup::kOutputWeight)).setZero();
  LatentModulatedSiren::View(&theta, siren->Block(ParameterGroup::kOutputBias)).setZero();
  siren->SetParameters(theta);
}

std::string TrunkTrainer::TrajectoryOptionsJson(SensorKind sensor,
                                                const FrameFormat& format) const {
  const Options& o = options_;
  Json json;
  json["sensor"] = ToString(sensor);
  json["siren.width"] = o.siren.width;
  json["siren.num_hidden_layers"] = o.siren.num_hidden_layers;
  json["siren.latent_dim"] = o.siren.latent_dim;
  json["siren.omega_0"] = o.siren.omega_0;
  json["siren.coordinates"] = ToString(o.siren.coordinates);
  if (o.siren.has_spatial()) {  // absent = one global latent (older files)
    json["siren.spatial_rows"] = o.siren.spatial_rows;
    json["siren.spatial_cols"] = o.siren.spatial_cols;
    json["siren.spatial_channels"] = o.siren.spatial_channels;
  }
  if (o.readout) {  // absent = no readout branch (older files)
    json["readout"] = true;
    json["readout_pca_frames"] = o.readout_pca_frames;
    json["readout_learning_rate_scale"] = o.readout_learning_rate_scale;
  }
  if (o.outer_loss_on_clean) {  // absent = the outer loss on the noisy frames
    json["outer_loss_on_clean"] = true;
  }
  if (o.skip_frames_at_rest) {  // absent = every train-split frame (older files)
    json["skip_frames_at_rest"] = true;
    json["contact.threshold"] = o.contact.threshold;
    json["contact.window"] = o.contact.window;
  }
  json["format.rows"] = format.rows;
  json["format.cols"] = format.cols;
  json["format.grayscale"] = format.grayscale;
  json["format.scale"] = format.scale;
  // The products' precision shapes the trajectory too (absent = float, older files):
  // a run resumed in the other precision is refused like any other changed option.
  if (GetProductPrecision() != ProductPrecision::kFloat) {
    json["products"] = ProductPrecisionName(GetProductPrecision());
  }
  json["meta_sgd.inner_steps"] = o.meta_sgd.inner_steps;
  json["meta_sgd.latent_l2_weight"] = o.meta_sgd.latent_l2_weight;
  json["meta_sgd.first_order"] = o.meta_sgd.first_order;
  json["learning_rate"] = o.learning_rate;
  json["alpha_learning_rate"] = o.alpha_learning_rate;
  if (o.learning_rate_final_fraction != 1.0) {  // absent = constant (older files)
    json["learning_rate_final_fraction"] = o.learning_rate_final_fraction;
    json["learning_rate_schedule_steps"] = o.steps;
  }
  json["adam_beta1"] = o.adam_beta1;
  json["adam_beta2"] = o.adam_beta2;
  json["adam_epsilon"] = o.adam_epsilon;
  json["alpha_init_min"] = o.alpha_init_min;
  json["alpha_init_max"] = o.alpha_init_max;
  if (o.alpha_max != 1.0) json["alpha_max"] = o.alpha_max;  // absent = 1 (older files)
  json["batch_size"] = o.batch_size;
  json["pixels_per_frame"] = o.pixels_per_frame;
  json["seed"] = o.seed;
  json["precision"] = "float32 gradients, float64 master";
  return json.dump();
}

double TrunkTrainer::LearningRateAt(const Options& options, int step) {
  const double f = options.learning_rate_final_fraction;
  if (f == 1.0 || options.steps <= 0) return options.learning_rate;
  const double progress =
      std::min(1.0, std::max(0.0, static_cast<double>(step - 1) / options.steps));
  return options.learning_rate * (f + (1.0 - f) * 0.5 * (1.0 + std::cos(M_PI * progress)));
}

TrunkTrainer::Summary TrunkTrainer::Train(const Dataset& dataset, SensorKind sensor,
                                          SensorTrunk* trunk, const StepCallback& callback) const {
  const Clock::time_point start = Clock::now();
  const SensorInfo& info = dataset.sensor_info(sensor);
  const double sensor_scale =
      info.normalization_scale > 0 ? info.normalization_scale : DefaultNormalizationScale(sensor);
  const FrameFormat format = ResolveFormat(sensor, sensor_scale);
  std::vector<std::size_t> indices = dataset.FrameIndices(sensor, Split::kTrain);
  if (indices.empty()) {
    throw std::runtime_error("TrunkTrainer: dataset " + dataset.root() +
                             " has no train-split frames of sensor '" + ToString(sensor) + "'");
  }
  // Each frame decoded once: its targets and, with skip_frames_at_rest, its contact test.
  std::vector<TrunkTargets> frames(indices.size());
  std::vector<TrunkTargets> clean_frames(options_.outer_loss_on_clean ? indices.size() : 0);
  if (options_.outer_loss_on_clean) {
    for (std::size_t index : indices) {
      if (dataset.frames()[index].clean_path.empty()) {
        throw std::runtime_error("TrunkTrainer: the outer loss on noise-free frames needs "
                                 "every train-split frame's clean copy; frame '" +
                                 dataset.frames()[index].id + "' of " + dataset.root() +
                                 " has none (synth --clean writes them)");
      }
    }
  }
  std::vector<char> contact(indices.size(), 1);
  internal::ParallelFor(static_cast<int>(indices.size()), options_.threads, [&](int i) {
    const Image frame = dataset.LoadFrame(indices[i]);
    frames[i] = DatasetFrameTargets(dataset, indices[i], frame, format);
    if (options_.outer_loss_on_clean) {
      clean_frames[i] =
          DatasetFrameTargets(dataset, indices[i], dataset.LoadCleanFrame(indices[i]), format);
    }
    if (options_.skip_frames_at_rest) {
      contact[i] = DetectFrameContact(dataset, indices[i], frame, options_.contact).contact;
    }
  });
  int skipped = 0;
  if (options_.skip_frames_at_rest) {
    std::vector<std::size_t> kept;
    std::vector<TrunkTargets> kept_frames, kept_clean;
    for (std::size_t i = 0; i < indices.size(); ++i) {
      if (!contact[i]) continue;
      kept.push_back(indices[i]);
      kept_frames.push_back(std::move(frames[i]));
      if (options_.outer_loss_on_clean) kept_clean.push_back(std::move(clean_frames[i]));
    }
    skipped = static_cast<int>(indices.size() - kept.size());
    if (kept.empty()) {
      throw std::runtime_error("TrunkTrainer: every one of the " + std::to_string(indices.size()) +
                               " train-split " + ToString(sensor) + " frames of " +
                               dataset.root() +
                               " is at rest (no contact above the noise); nothing to train on");
    }
    indices = std::move(kept);
    frames = std::move(kept_frames);
    clean_frames = std::move(kept_clean);
  }
  // FNV-1a over the frame ids: resuming on another training set is refused.
  std::uint64_t fingerprint = internal::Fnv1a(nullptr, 0);
  for (std::size_t index : indices) {
    const std::string line = dataset.frames()[index].id + "\n";
    fingerprint = internal::Fnv1a(line.data(), line.size(), fingerprint);
  }
  const double load_seconds = SecondsSince(start);
  Summary summary = Train(frames, sensor, format, fingerprint, trunk, callback,
                          options_.outer_loss_on_clean ? &clean_frames : nullptr);
  summary.load_seconds = load_seconds;
  summary.num_frames_at_rest_skipped = skipped;
  return summary;
}

TrunkTrainer::Summary TrunkTrainer::Train(const std::vector<TrunkTargets>& frames,
                                          SensorKind sensor, const FrameFormat& format,
                                          std::uint64_t fingerprint, SensorTrunk* trunk,
                                          const StepCallback& callback,
                                          const std::vector<TrunkTargets>* clean_frames) const {
  const Options& o = options_;
  std::string error;
  if (!format.IsValid(&error)) throw std::invalid_argument("TrunkTrainer: " + error);
  if (frames.empty()) throw std::runtime_error("TrunkTrainer: no training frames");
  if (o.outer_loss_on_clean &&
      (clean_frames == nullptr || clean_frames->size() != frames.size())) {
    throw std::invalid_argument("TrunkTrainer: the outer loss on noise-free frames needs one "
                                "clean copy per training frame");
  }
  const int num_pixels = format.rows * format.cols;
  const int channels = static_cast<int>(frames[0].values.cols());
  for (std::size_t i = 0; i < frames.size(); ++i) {
    if (frames[i].values.rows() != num_pixels || frames[i].values.cols() != channels ||
        frames[i].weights.size() != num_pixels) {
      throw std::invalid_argument("TrunkTrainer: training frame " + std::to_string(i) + " is " +
                                  std::to_string(frames[i].values.rows()) + " x " +
                                  std::to_string(frames[i].values.cols()) + " values, expected " +
                                  std::to_string(num_pixels) + " x " + std::to_string(channels) +
                                  " (" + std::to_string(format.rows) + " x " +
                                  std::to_string(format.cols) + " pixels)");
    }
    if (o.outer_loss_on_clean && ((*clean_frames)[i].values.rows() != num_pixels ||
                                  (*clean_frames)[i].values.cols() != channels)) {
      throw std::invalid_argument("TrunkTrainer: clean copy " + std::to_string(i) +
                                  " differs in size from its training frame");
    }
  }
  const int num_frames = static_cast<int>(frames.size());
  const Clock::time_point run_start = Clock::now();

  LatentModulatedSiren::Options siren_options = o.siren;
  siren_options.output_channels = channels;
  siren_options.readout_rows = o.readout ? format.rows : 0;
  siren_options.readout_cols = o.readout ? format.cols : 0;
  LatentModulatedSiren siren(siren_options, StreamSeed(o.seed, kThetaStream));
  // With the outer loss on the noise-free copies the branch starts as their PCA (the
  // basis of what the outer loss asks for, not of the sensor's noise) and its
  // projections are shrunk by their Wiener gains.
  if (o.readout) {
    if (o.outer_loss_on_clean) {
      StartReadoutFromPca(*clean_frames, o.readout_pca_frames, &siren, &frames);
    } else {
      StartReadoutFromPca(frames, o.readout_pca_frames, &siren);
    }
  }
  siren.set_readout_frozen(o.readout && o.readout_learning_rate_scale == 0);
  const MetaSgd meta(o.meta_sgd);
  const int d = siren.latent_dim();
  const int num_parameters = siren.NumParameters();
  const Eigen::MatrixXf grid = siren.Grid<float>(format.rows, format.cols);
  const std::string options_json = TrajectoryOptionsJson(sensor, format);

  TrainingState state;
  state.theta = siren.parameters();
  state.alpha.resize(d);
  {
    boost::random::mt19937_64 rng(StreamSeed(o.seed, kAlphaStream));
    boost::random::uniform_real_distribution<double> uniform(o.alpha_init_min, o.alpha_init_max);
    for (int k = 0; k < d; ++k) {
      state.alpha[k] = o.alpha_init_min == o.alpha_init_max ? o.alpha_init_min : uniform(rng);
    }
  }
  state.m_theta = state.v_theta = Eigen::VectorXd::Zero(num_parameters);
  state.m_alpha = state.v_alpha = Eigen::VectorXd::Zero(d);
  if (o.resume && std::filesystem::exists(o.checkpoint_path)) {
    ReadCheckpoint(o.checkpoint_path, sensor, options_json, fingerprint, num_frames, num_parameters,
                   d, &state);
    siren.SetParameters(state.theta);
  }

  Summary summary;
  summary.sensor = sensor;
  summary.format = format;
  summary.num_train_frames = num_frames;
  summary.num_parameters = num_parameters;
  summary.start_step = state.step;

  // Fixed evaluation subsets.
  const std::vector<int> monitor_set =
      Sample(num_frames, o.monitor_frames, StreamSeed(o.seed, kMonitorStream));
  const Eigen::VectorXf zero_latent = Eigen::VectorXf::Zero(d);
  // Mean PSNR after K steps and at z = 0 and mean loss after K steps on the subset.
  auto monitor = [&](double* psnr, double* psnr_at_zero, double* loss) {
    const int n = static_cast<int>(monitor_set.size());
    std::vector<double> psnrs(n), psnrs_zero(n), losses(n);
    const Eigen::VectorXf alpha = state.alpha.cast<float>();
    internal::ParallelFor(n, o.threads, [&](int i) {
      const TrunkTargets& t = frames[monitor_set[i]];
      float fit_loss = 0;
      const Eigen::VectorXf z =
          meta.FitLatent<float>(siren, grid, t.values, t.weights, alpha, &fit_loss);
      psnrs[i] = Psnr(siren.Forward<float>(grid, z), t);
      psnrs_zero[i] = Psnr(siren.Forward<float>(grid, zero_latent), t);
      losses[i] = fit_loss;
    });
    *psnr = MeanFinite(psnrs);
    *psnr_at_zero = MeanFinite(psnrs_zero);
    *loss = std::accumulate(losses.begin(), losses.end(), 0.0) / n;
  };
  auto add_history_point = [&](double seconds_so_far) {
    HistoryPoint p;
    p.step = state.step;
    double monitor_loss = 0;
    monitor(&p.psnr, &p.psnr_at_zero, &monitor_loss);
    p.loss = state.loss_count > 0 ? state.loss_sum / state.loss_count : monitor_loss;
    p.seconds = seconds_so_far;
    state.history.push_back(p);
    return p;
  };
  const ProcessGroup& group = o.processes != nullptr ? *o.processes : SingleProcess();
  auto checkpoint = [&]() {
    if (o.checkpoint_path.empty() || group.rank() != 0) return;
    WriteCheckpoint(o.checkpoint_path, state, sensor, options_json, fingerprint, num_frames);
  };

  if (state.history.empty()) add_history_point(state.train_seconds);

  // Batch slots: frame choice by epoch permutations, pixel subsets per (step, slot).
  std::vector<int> epoch_perm;
  std::int64_t epoch_cached = -1;
  auto frame_at = [&](std::int64_t position) {
    const std::int64_t epoch = position / num_frames;
    if (epoch != epoch_cached) {
      epoch_perm = Permutation(num_frames, DeriveSeed(StreamSeed(o.seed, kEpochStream),
                                                      static_cast<std::uint64_t>(epoch)));
      epoch_cached = epoch;
    }
    return epoch_perm[position % num_frames];
  };
  const int batch = o.batch_size;
  const bool subset = o.pixels_per_frame > 0 && o.pixels_per_frame < num_pixels;
  std::vector<MetaSgd::Result<float>> results(batch);
  std::vector<int> batch_frames(batch);

  TerminationType termination = TerminationType::kCompleted;
  std::string message;
  double step_seconds = 0;
  int steps_this_run = 0;
  double last_loss = 0;
  while (state.step < o.steps) {
    const Clock::time_point step_start = Clock::now();
    for (int b = 0; b < batch; ++b) {
      batch_frames[b] = frame_at(static_cast<std::int64_t>(state.step) * batch + b);
    }
    const std::uint64_t pixel_seed =
        DeriveSeed(StreamSeed(o.seed, kPixelStream), static_cast<std::uint64_t>(state.step));
    const Eigen::VectorXf alpha = state.alpha.cast<float>();
    // This process's slots; the other processes' are gathered after.
    std::int64_t first_slot, end_slot;
    group.Share(batch, group.rank(), &first_slot, &end_slot);
    internal::ParallelFor(static_cast<int>(end_slot - first_slot), o.threads, [&](int i) {
      const int b = static_cast<int>(first_slot) + i;
      const TrunkTargets& t = frames[batch_frames[b]];
      const Eigen::MatrixXf* clean =
          o.outer_loss_on_clean ? &(*clean_frames)[batch_frames[b]].values : nullptr;
      if (!subset) {
        results[b] =
            meta.OuterLossAndGradient<float>(siren, grid, t.values, t.weights, alpha, clean);
        return;
      }
      const std::vector<int> pixels =
          Sample(num_pixels, o.pixels_per_frame, DeriveSeed(pixel_seed, b));
      const int n = static_cast<int>(pixels.size());
      Eigen::MatrixXf coords(n, 2), targets(n, channels), outer(clean ? n : 0, channels);
      Eigen::VectorXf weights(n);
      for (int i = 0; i < n; ++i) {
        coords.row(i) = grid.row(pixels[i]);
        targets.row(i) = t.values.row(pixels[i]);
        weights[i] = t.weights[pixels[i]];
        if (clean) outer.row(i) = clean->row(pixels[i]);
      }
      results[b] = meta.OuterLossAndGradient<float>(siren, coords, targets, weights, alpha,
                                                    clean ? &outer : nullptr);
    });
    if (group.size() > 1) GatherSlots(group, num_parameters, d, &results);
    // Reduce in slot order (thread- and process-count independent), in double.
    Eigen::VectorXd g_theta = Eigen::VectorXd::Zero(num_parameters);
    Eigen::VectorXd g_alpha = Eigen::VectorXd::Zero(d);
    double loss = 0, loss_at_zero = 0;
    for (int b = 0; b < batch; ++b) {
      const MetaSgd::Result<float>& r = results[b];
      loss += r.loss;
      loss_at_zero += r.loss_at_zero;
      g_theta += r.dL_dtheta.cast<double>();
      g_alpha += r.dL_dalpha.cast<double>();
    }
    // One check on the double sums stands for one per frame: a sum of floats in double
    // cannot overflow, so it is finite exactly when every term is (an infinity meeting its
    // negative gives NaN, still caught). One pass over the gradients instead of two.
    if (!(std::isfinite(loss) && g_theta.allFinite() && g_alpha.allFinite())) {
      termination = TerminationType::kNonFinite;
      message = "non-finite loss or gradient at step " + std::to_string(state.step + 1) +
                "; kept the parameters of step " + std::to_string(state.step) +
                " (try a smaller learning_rate)";
      break;
    }
    const double inv = 1.0 / batch;
    loss *= inv;
    loss_at_zero *= inv;
    g_theta *= inv;
    g_alpha *= inv;

    // Adam (Kingma & Ba 2015, Algorithm 1) on theta and alpha, then alpha clipped to
    // [0, alpha_max].
    const int t = state.step + 1;
    const double b1 = o.adam_beta1, b2 = o.adam_beta2;
    const double correction1 = 1.0 - std::pow(b1, t), correction2 = 1.0 - std::pow(b2, t);
    auto adam = [&](Eigen::VectorXd* x, Eigen::VectorXd* m, Eigen::VectorXd* v,
                    const Eigen::VectorXd& g, double rate) {
      *m = b1 * *m + (1.0 - b1) * g;
      *v = b2 * *v + (1.0 - b2) * g.cwiseAbs2();
      const double step_size = rate / correction1;
      const double sqrt_c2 = std::sqrt(correction2);
      x->array() -= step_size * m->array() / (v->array().sqrt() / sqrt_c2 + o.adam_epsilon);
    };
    // The readout branch moves by readout_learning_rate_scale of Adam's step (the step
    // is linear in the rate), 0 = kept at its PCA start.
    Eigen::VectorXd readout_before;
    long readout_offset = 0;
    if (o.readout) {
      readout_offset = siren.Block(ParameterGroup::kReadoutBasis).offset;
      readout_before = state.theta.tail(num_parameters - readout_offset);
    }
    adam(&state.theta, &state.m_theta, &state.v_theta, g_theta, LearningRateAt(o, t));
    if (o.readout) {
      auto readout = state.theta.tail(num_parameters - readout_offset);
      readout = readout_before + o.readout_learning_rate_scale * (readout - readout_before);
    }
    adam(&state.alpha, &state.m_alpha, &state.v_alpha, g_alpha, o.alpha_learning_rate);
    state.alpha = state.alpha.cwiseMax(0.0).cwiseMin(o.alpha_max);
    siren.SetParameters(state.theta);
    state.step = t;
    state.loss_sum += loss;
    ++state.loss_count;
    last_loss = loss;
    const double this_step = SecondsSince(step_start);
    step_seconds += this_step;
    ++steps_this_run;

    StepReport report;
    report.step = state.step;
    report.total_steps = o.steps;
    report.loss = loss;
    report.loss_at_zero = loss_at_zero;
    const double seconds_so_far = state.train_seconds + SecondsSince(run_start);
    if (state.step % o.monitor_every == 0) {
      report.latest = add_history_point(seconds_so_far);
      report.monitored = true;
      state.loss_sum = 0;
      state.loss_count = 0;
    } else {
      report.latest = state.history.back();
    }
    const bool keep_going = callback ? callback(report) : true;
    if (report.monitored) {
      message = DivergenceMessage(state.history, o.divergence_drop_db);
      if (!message.empty()) {
        termination = TerminationType::kDiverged;
        break;
      }
    }
    if (!keep_going) {
      termination = TerminationType::kUserStopped;
      message = "stopped by the step callback after step " + std::to_string(state.step);
      break;
    }
    if (o.checkpoint_every > 0 && state.step % o.checkpoint_every == 0 && state.step < o.steps) {
      const double run_seconds = SecondsSince(run_start);
      state.train_seconds += run_seconds;
      checkpoint();
      state.train_seconds -= run_seconds;
    }
  }
  (void)last_loss;

  const double run_seconds = SecondsSince(run_start);
  state.train_seconds += run_seconds;
  if (termination != TerminationType::kNonFinite && termination != TerminationType::kDiverged) {
    // The final point, unless the last step already made one. Its loss accumulator is
    // not reset, so a later resume continues the regular history unchanged.
    if (state.history.back().step != state.step) {
      const double sum = state.loss_sum;
      const int count = state.loss_count;
      add_history_point(state.train_seconds);
      state.loss_sum = sum;
      state.loss_count = count;
      // A run that falls apart after its last regular monitor point is diverged too.
      if (termination == TerminationType::kCompleted) {
        message = DivergenceMessage(state.history, o.divergence_drop_db);
        if (!message.empty()) termination = TerminationType::kDiverged;
      }
    }
    if (termination != TerminationType::kDiverged) checkpoint();
  }
  if (termination == TerminationType::kCompleted) {
    message = "reached " + std::to_string(o.steps) + " steps";
  }

  // residual_sigma: RMS per-pixel residual of the K-step fits on a fixed subset.
  double residual_sigma = 0;
  if (termination == TerminationType::kCompleted) {
    const std::vector<int> residual_set =
        Sample(num_frames, o.residual_frames, StreamSeed(o.seed, kResidualStream));
    const int n = static_cast<int>(residual_set.size());
    std::vector<double> sse(n), count(n);
    const Eigen::VectorXf alpha = state.alpha.cast<float>();
    internal::ParallelFor(n, o.threads, [&](int i) {
      const TrunkTargets& t = frames[residual_set[i]];
      const Eigen::VectorXf z = meta.FitLatent<float>(siren, grid, t.values, t.weights, alpha);
      const Eigen::MatrixXf residual = siren.Forward<float>(grid, z) - t.values;
      double s = 0, c = 0;
      for (int j = 0; j < num_pixels; ++j) {
        if (!(t.weights[j] > 0)) continue;
        s += residual.row(j).cast<double>().squaredNorm();
        c += channels;
      }
      sse[i] = s;
      count[i] = c;
    });
    const double total = std::accumulate(count.begin(), count.end(), 0.0);
    if (total > 0) residual_sigma = std::sqrt(std::accumulate(sse.begin(), sse.end(), 0.0) / total);
  }

  if (trunk != nullptr) {
    trunk->sensor = sensor;
    trunk->format = format;
    trunk->siren = siren;
    trunk->siren.set_readout_frozen(false);  // a training choice, not part of the model
    trunk->alpha = state.alpha;
    trunk->meta_sgd = o.meta_sgd;
    trunk->residual_sigma = residual_sigma;
  }

  summary.termination_type = termination;
  summary.message = message;
  summary.steps_done = state.step;
  summary.wall_seconds = run_seconds;
  summary.total_train_seconds = state.train_seconds;
  summary.seconds_per_step = steps_this_run > 0 ? step_seconds / steps_this_run : 0;
  summary.history = state.history;
  summary.final_loss = state.history.back().loss;
  summary.train_psnr = state.history.back().psnr;
  summary.train_psnr_at_zero = state.history.back().psnr_at_zero;
  summary.residual_sigma = residual_sigma;
  return summary;
}

}  // namespace tactfunc
