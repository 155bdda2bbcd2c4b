// Copyright 2026 The tactfunc Authors.
//
// tactfunc train: meta-learns one SIREN trunk per sensor on a dataset's train split
// (estimation/training/trunk_trainer.h, docs/TRAINING.md) and writes one model file.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <sstream>
#include <thread>
#include <utility>
#include <vector>

#include <opencv2/imgproc.hpp>

#include "CLI/CLI.hpp"
#include "apps/command.h"
#include "apps/dataset_flags.h"
#include "apps/distributed.h"
#include "apps/interrupt.h"
#include "apps/output_paths.h"
#include "apps/model_inputs.h"
#include "apps/pictures.h"
#include "apps/progress_bar.h"
#include "estimation/data/dataset.h"
#include "estimation/fitting/latent_fitter.h"
#include "estimation/functaset/latent_encoder.h"
#include "estimation/training/photometric_trainer.h"
#include "estimation/training/photometric_warm_start.h"
#include "estimation/training/trunk_trainer.h"
#include "models/core/parallel_for.h"
#include "models/core/atomic_file.h"
#include "models/trunk/functa_model.h"

namespace tactfunc::apps {
namespace {

struct TrainFlags {
  std::string data;
  DatasetFlags data_flags;
  std::string out;
  std::string preset = "default";
  std::string sensors;  // empty = every sensor of the dataset
  int latent_dim = 0, width = 0, layers = 0, steps = 0, batch = 0, pixels = 0;
  int threads = 0;
  std::string products = "float";
  double learning_rate = 0;
  double omega_0 = 0;
  double lr_final_fraction = 1;
  int inner_steps = 0;
  double alpha_init = 0, alpha_max = 0;
  double divergence_drop_db = 0;
  double readout_rate = 0;
  int readout_pca_frames = 0;
  std::uint64_t seed = 0;
  int checkpoint_every = 0;
  bool first_order = false;
  bool readout = false;
  bool skip_rest = false;
  bool outer_clean = false;
  std::string working_size;  // "ROWSxCOLS", empty = the preset's
  std::string spatial_latent;  // "GHxGWxC", empty = one global latent
  bool resume = false;
  bool json = false;
  std::string head = "direct";  // "direct" or "photometric"
  int marker_warmup = 1000;
  double contact_share = PhotometricTrainer::Options().contact_share;
  bool no_warm_start = false;
  bool background = false;  // --head photometric: learn the sensor's background table
  int lighting = 0;  // --head photometric: lighting images weighed by each frame's latent
  double latent_noise = 0;  // --head photometric: noise on the training latents' code values
  std::string default_fit;  // "": the encoder's rule
  // Set after parsing: which overrides were given.
  CLI::Option *latent_dim_option = nullptr, *width_option = nullptr, *layers_option = nullptr,
              *steps_option = nullptr, *batch_option = nullptr, *pixels_option = nullptr,
              *seed_option = nullptr, *checkpoint_every_option = nullptr,
              *learning_rate_option = nullptr, *omega_0_option = nullptr,
              *lr_final_fraction_option = nullptr, *inner_steps_option = nullptr,
              *alpha_init_option = nullptr, *alpha_max_option = nullptr,
              *divergence_drop_db_option = nullptr, *readout_rate_option = nullptr,
              *marker_warmup_option = nullptr, *contact_share_option = nullptr;
};

// SIGINT: the current step finishes, a checkpoint is written, the command exits 1. A
// second SIGINT aborts at once (default action; the last periodic checkpoint remains)
// -- except while the final model is written: then every SIGINT is only noted, the
// write completes (the model is never lost to a Ctrl-C) and the command exits 130.
std::atomic<bool> g_interrupted{false};
std::atomic<bool> g_saving{false};
static_assert(std::atomic<bool>::is_always_lock_free);
extern "C" void HandleSigint(int) {
  if (g_interrupted.exchange(true) && !g_saving.load()) {
    std::signal(SIGINT, SIG_DFL);
    std::raise(SIGINT);
  }
}

std::string CheckpointPath(const std::string& out, SensorKind sensor) {
  return CheckpointBeside(out, ToString(sensor));
}

// M -> M.training.png, beside the checkpoints M.<sensor>.ckpt.
std::string TrainingCurvesPath(const std::string& out) { return out + ".training.png"; }

std::string Status(const TrunkTrainer::StepReport& report) {
  char buffer[160];
  std::snprintf(buffer, sizeof(buffer), "loss %.3e  PSNR %.2f dB (z=0 %.2f)", report.loss,
                report.latest.psnr, report.latest.psnr_at_zero);
  return buffer;
}

// The preset for `sensor` (presets may size the trunk per sensor), then the flags'
// overrides. Throws UsageError for invalid options.
TrunkTrainer::Options OptionsFor(const TrainFlags& flags, SensorKind sensor) {
  TrunkTrainer::Options options = TrunkTrainer::Preset(flags.preset, sensor);
  if (flags.latent_dim_option->count()) options.siren.latent_dim = flags.latent_dim;
  if (flags.width_option->count()) options.siren.width = flags.width;
  if (flags.layers_option->count()) options.siren.num_hidden_layers = flags.layers;
  if (flags.steps_option->count()) options.steps = flags.steps;
  if (flags.batch_option->count()) options.batch_size = flags.batch;
  if (flags.pixels_option->count()) options.pixels_per_frame = flags.pixels;
  if (flags.seed_option->count()) options.seed = flags.seed;
  if (flags.checkpoint_every_option->count()) options.checkpoint_every = flags.checkpoint_every;
  if (flags.first_order) options.meta_sgd.first_order = true;
  // The branch from the flag or the preset (`storage`): the checks below ask the options.
  if (flags.readout) options.readout = true;
  if (flags.readout_rate_option->count()) {
    if (!options.readout) throw UsageError("--readout-rate needs --readout");
    options.readout_learning_rate_scale = flags.readout_rate;
  }
  if (flags.readout_pca_frames > 0) {
    if (!options.readout) throw UsageError("--readout-pca-frames needs --readout");
    options.readout_pca_frames = flags.readout_pca_frames;
  }
  if (flags.learning_rate_option->count()) options.learning_rate = flags.learning_rate;
  if (flags.omega_0_option->count()) options.siren.omega_0 = flags.omega_0;
  if (flags.lr_final_fraction_option->count()) {
    options.learning_rate_final_fraction = flags.lr_final_fraction;
  }
  if (flags.inner_steps_option->count()) {
    if (flags.inner_steps == 0 && !options.readout) {
      throw UsageError("--inner-steps 0 leaves every latent at its start, which is z = 0 "
                       "without --readout (with it, the branch's projection of the frame)");
    }
    options.meta_sgd.inner_steps = flags.inner_steps;
  }
  if (flags.alpha_max_option->count()) options.alpha_max = flags.alpha_max;
  if (flags.alpha_init_option->count()) {
    options.alpha_init_min = options.alpha_init_max = flags.alpha_init;
  }
  if (flags.divergence_drop_db_option->count()) {
    options.divergence_drop_db = flags.divergence_drop_db;
  }
  if (flags.skip_rest) options.skip_frames_at_rest = true;
  if (flags.outer_clean) options.outer_loss_on_clean = true;
  if (!flags.spatial_latent.empty()) {
    int rows = 0, cols = 0, channels = 0;
    char x1 = 0, x2 = 0, extra = 0;
    std::istringstream in(flags.spatial_latent);
    if (!(in >> rows >> x1 >> cols >> x2 >> channels) || (x1 != 'x' && x1 != 'X') ||
        (x2 != 'x' && x2 != 'X') || (in >> extra) || rows < 1 || cols < 1 || channels < 1 ||
        rows > 1024 || cols > 1024 || channels > 1024) {
      throw UsageError("--spatial-latent: expected GHxGWxC (grid rows x grid cols x values "
                       "per node, each in [1, 1024]), got '" +
                       flags.spatial_latent + "'");
    }
    const long grid = static_cast<long>(rows) * cols * channels;
    if (options.siren.latent_dim < grid) {
      throw UsageError("--spatial-latent " + flags.spatial_latent + ": the grid holds " +
                       std::to_string(grid) + " latent values, more than the latent " +
                       "dimension " + std::to_string(options.siren.latent_dim) + " (" +
                       (flags.latent_dim_option->count() ? std::string("--latent-dim")
                                                         : "preset " + flags.preset + ", " +
                                                               ToString(sensor)) +
                       "); --latent-dim counts the grid's values plus the global ones, so "
                       "give --latent-dim >= " + std::to_string(grid));
    }
    options.siren.spatial_rows = rows;
    options.siren.spatial_cols = cols;
    options.siren.spatial_channels = channels;
  }
  if (!flags.working_size.empty()) {
    int rows = 0, cols = 0;
    char x = 0, extra = 0;
    std::istringstream in(flags.working_size);
    if (!(in >> rows >> x >> cols) || (x != 'x' && x != 'X') || (in >> extra) || rows < 1 ||
        cols < 1 || rows > 4096 || cols > 4096) {
      throw UsageError("--working-size: expected ROWSxCOLS with each in [1, 4096], got '" +
                       flags.working_size + "'");
    }
    options.rows = rows;
    options.cols = cols;
  }
  options.threads = ResolveThreads(flags.threads);
  std::string error;
  if (!options.IsValid(&error)) throw UsageError(error);
  return options;
}

// OptionsFor, with the working size of the data's sensor description when it sets one
// (--working-size must then agree: the description's aspect handling was made for it).
TrunkTrainer::Options OptionsForData(const TrainFlags& flags, const Dataset& dataset,
                                     SensorKind sensor) {
  TrunkTrainer::Options options = OptionsFor(flags, sensor);
  const SensorInfo& info = dataset.sensor_info(sensor);
  if (!info.description || info.description->working_rows <= 0) return options;
  const SensorDescription& d = *info.description;
  if (!flags.working_size.empty() && (options.rows != d.working_rows || options.cols != d.working_cols)) {
    throw UsageError("--working-size " + flags.working_size + ": " + info.description_path +
                     " sets working_size " + std::to_string(d.working_rows) + "x" +
                     std::to_string(d.working_cols) + " for the " + ToString(sensor) +
                     " frames; give one of them");
  }
  options.rows = d.working_rows;
  options.cols = d.working_cols;
  return options;
}

// The description a trunk trained on `dataset`'s `sensor` frames records: the data's, at
// the working size it was trained at (aspect "stretch" when the data's description set
// none: the frames were resized to it as they were).
SensorDescription TrainedDescription(const Dataset& dataset, SensorKind sensor,
                                     const FrameFormat& format) {
  SensorDescription d = DataSensorDescription(dataset.sensor_info(sensor));
  if (d.working_rows <= 0) d.aspect = SensorDescription::Aspect::kStretch;
  d.working_rows = format.rows;
  d.working_cols = format.cols;
  return d;
}

// The training curves of every sensor trained: the monitor PSNR after K steps (thick)
// and at z = 0 (thin) at every history point, against step + 1 on a log scale (so the
// start, step 0, is drawn too). Empty if no history point has a finite PSNR.
cv::Mat TrainingCurvesPlot(
    const std::vector<std::pair<SensorKind, std::vector<TrunkTrainer::HistoryPoint>>>& runs,
    const std::string& subtitle) {
  double x_lo = std::numeric_limits<double>::infinity(), x_hi = 0, y_lo = x_lo, y_hi = -x_lo;
  for (const auto& [sensor, history] : runs) {
    for (const TrunkTrainer::HistoryPoint& p : history) {
      for (double y : {p.psnr, p.psnr_at_zero}) {
        if (!std::isfinite(y)) continue;
        x_lo = std::min<double>(x_lo, p.step + 1);
        x_hi = std::max<double>(x_hi, p.step + 1);
        y_lo = std::min(y_lo, y);
        y_hi = std::max(y_hi, y);
      }
    }
  }
  if (!(x_hi > 0)) return cv::Mat();
  if (!(x_hi > x_lo)) x_hi = x_lo * 2;
  if (!(y_hi > y_lo)) y_hi = y_lo + 1;
  LogXPlot::Layout layout;
  layout.height = 620;
  LogXPlot plot(layout, x_lo, x_hi, y_lo, y_hi);
  plot.DrawFrame("outer step + 1 (log scale)", "monitor PSNR, dB", "Training curves", subtitle);
  cv::Mat& canvas = plot.canvas();
  const cv::Scalar colours[] = {cv::Scalar(40, 140, 255), cv::Scalar(230, 120, 40)};
  std::vector<std::pair<std::string, cv::Scalar>> legend;
  for (std::size_t k = 0; k < runs.size(); ++k) {
    const cv::Scalar colour = colours[k % 2];
    std::vector<cv::Point> fitted, zero;
    for (const TrunkTrainer::HistoryPoint& p : runs[k].second) {
      const int x = plot.X(p.step + 1);
      if (std::isfinite(p.psnr)) fitted.push_back({x, plot.Y(p.psnr)});
      if (std::isfinite(p.psnr_at_zero)) zero.push_back({x, plot.Y(p.psnr_at_zero)});
    }
    cv::polylines(canvas, fitted, false, colour, 3, cv::LINE_AA);
    cv::polylines(canvas, zero, false, colour * 0.8, 1, cv::LINE_AA);
    for (const cv::Point& q : fitted) cv::circle(canvas, q, 4, colour, cv::FILLED, cv::LINE_AA);
    for (const cv::Point& q : zero) cv::circle(canvas, q, 2, colour * 0.8, cv::FILLED, cv::LINE_AA);
    legend.push_back({std::string(ToString(runs[k].first)) + ": after K steps", colour});
    legend.push_back({std::string(ToString(runs[k].first)) + ": z = 0", colour * 0.8});
  }
  const int lx = plot.area().x + plot.area().width + 22, ly = plot.area().y + 14;
  for (std::size_t k = 0; k < legend.size(); ++k) {
    const int y = ly + 20 * static_cast<int>(k);
    cv::line(canvas, {lx, y}, {lx + 16, y}, legend[k].second, k % 2 == 0 ? 3 : 1, cv::LINE_AA);
    PlainText(canvas, legend[k].first, {lx + 22, y + 5}, 0.42);
  }
  return canvas;
}

// Steps of `train --head photometric` without --steps: the committed GelSlim trunk's
// (scripts/train_pretrained_gelslim.sh). Eight times the 3000 of earlier releases gained
// 0.9 dB on two fresh sets, so that encode's default fit passes the paper's 37 dB, in
// 33 minutes on 2 cores at 1620 frames (docs/REPRESENTATION.md, "Longer training").
constexpr int kPhotometricDefaultSteps = 24000;

// `train --head photometric`: the optical sensors' photometric trunk
// (models/trunk/photometric_trunk.h), trained jointly with its training latents
// (PhotometricTrainer). Writes the model and its checkpoints (OUT.<sensor>.ckpt, resumed
// with --resume) as the direct path does.
void TrainPhotometric(const TrainFlags& flags, const Dataset& dataset,
                      const std::vector<SensorKind>& sensors) {
  const std::vector<std::pair<bool, const char*>> direct_only = {
      {flags.readout, "--readout"},
      {!flags.spatial_latent.empty(), "--spatial-latent"},
      {flags.first_order, "--first-order"},
      {flags.skip_rest, "--skip-rest"},
      {flags.outer_clean, "--outer-clean"},
      {flags.inner_steps_option->count() > 0, "--inner-steps"},
      {flags.alpha_init_option->count() > 0, "--alpha-init"},
      {flags.alpha_max_option->count() > 0, "--alpha-max"}};
  for (const auto& [given, name] : direct_only) {
    if (given) {
      throw UsageError(std::string(name) + " applies to the direct trunk (meta-SGD); "
                       "--head photometric trains its trunk and latents jointly");
    }
  }
  if (Processes().size() > 1) {
    throw UsageError("--head photometric runs as one process (several threads: --threads)");
  }
  for (SensorKind sensor : sensors) {  // before any sensor's training starts
    if (sensor == SensorKind::kSoftBubble) {
      throw UsageError("--head photometric: the bubble is a depth sensor; the photometric head "
                       "draws optical (gelslim) frames. Pass --sensors gelslim.");
    }
  }
  FunctaModel model;
  nlohmann::json figures = nlohmann::json::object();
  nlohmann::json info_trunks = nlohmann::json::object();
  for (SensorKind sensor : sensors) {
    const char* name = ToString(sensor);
    const TrunkTrainer::Options base = OptionsForData(flags, dataset, sensor);
    const SensorInfo& info = dataset.sensor_info(sensor);
    const double scale =
        info.normalization_scale > 0 ? info.normalization_scale : DefaultNormalizationScale(sensor);
    const FrameFormat format = TrunkTrainer(base).ResolveFormat(sensor, scale);
    const std::vector<std::size_t> indices = dataset.FrameIndices(sensor, Split::kTrain);
    if (indices.empty()) {
      throw DatasetError(flags.data + ": no train-split " + std::string(name) + " frames");
    }
    PhotometricTrainer::Options o;
    o.trunk.width = flags.width_option->count() ? flags.width : 64;
    o.trunk.num_hidden_layers = flags.layers_option->count() ? flags.layers : 3;
    o.trunk.latent_dim = flags.latent_dim_option->count() ? flags.latent_dim : 64;
    o.steps = flags.steps_option->count() ? flags.steps : kPhotometricDefaultSteps;
    o.batch_frames = flags.batch_option->count() ? flags.batch : 64;
    o.batch_pixels = flags.pixels_option->count() && flags.pixels > 0 ? flags.pixels : 512;
    o.trunk_learning_rate = flags.learning_rate_option->count() ? flags.learning_rate : 2e-4;
    o.marker_warmup_steps = flags.marker_warmup;
    o.contact_share = flags.contact_share;
    o.learn_background = flags.background || flags.lighting > 0;  // lighting needs it
    o.trunk.lighting_components = flags.lighting;
    o.latent_noise = flags.latent_noise;
    o.seed = base.seed;
    o.threads = base.threads;
    o.checkpoint_path = CheckpointPath(flags.out, sensor);
    o.checkpoint_every = base.checkpoint_every;
    o.resume = flags.resume;
    if (o.trunk.latent_dim <= PhotometricTrunk::kPoseValues + flags.lighting) {
      throw UsageError("--latent-dim: the photometric trunk's latent holds a rigid motion (3 "
                       "values), " + std::to_string(flags.lighting) +
                       " lighting value(s) (--lighting) and a code: expected at least " +
                       std::to_string(PhotometricTrunk::kPoseValues + flags.lighting + 1) +
                       ", got " + std::to_string(o.trunk.latent_dim));
    }
    const PhotometricTrainer trainer(o);  // bad values fail before the frames are read
    std::cout << "train " << name << ": photometric head, " << o.steps << " steps ("
              << (flags.steps_option->count() ? "--steps" : "default") << ", markers at the "
              << "working resolution for the first " << o.marker_warmup_steps << ") at "
              << format.rows << "x" << format.cols << ", " << o.batch_frames << " frames x "
              << o.batch_pixels << " pixels a step (a share of " << o.contact_share
              << " drawn towards the contact) on " << o.threads << " thread(s), latent "
              << o.trunk.latent_dim;
    if (o.latent_noise > 0) std::cout << ", noise " << o.latent_noise << " on its code values";
    std::cout << std::endl;
    if (flags.resume) {
      std::cout << "train " << name << ": "
                << (std::filesystem::exists(o.checkpoint_path)
                        ? "resuming from " + o.checkpoint_path
                        : std::string("no checkpoint, starting at step 0"))
                << std::endl;
    }
    WarnIfStretched(dataset, flags.data, sensor, format.rows, format.cols, "train");
    const std::vector<TrunkTargets> frames =
        LoadTrunkTargets(dataset, indices, format, /*clean=*/false, o.threads);
    // Each frame is drawn against its own reference: its clip's in a set of clips.
    std::vector<Image> references;
    std::vector<int> frame_reference;
    std::map<int, int> reference_of_clip;
    for (std::size_t i : indices) {
      const auto [it, added] = reference_of_clip.emplace(dataset.frames()[i].clip,
                                                         static_cast<int>(references.size()));
      if (added) references.push_back(PhotometricReference(dataset.FrameReference(i), format));
      frame_reference.push_back(it->second);
    }
    if (references.size() > 1) {
      std::cout << "train " << name << ": " << references.size()
                << " clips, each frame drawn against its own clip's reference" << std::endl;
    }
    auto bar = std::make_unique<ProgressBar>(std::string("train ") + name, o.steps, "steps");
    const bool bar_enabled = ProgressBar::Enabled();
    const int every = std::max(1, o.steps / 20);
    const auto started = std::chrono::steady_clock::now();
    bool first = true;
    const PhotometricTrainer::Result result =
        trainer.Train(frames, references, frame_reference, [&](int step, double loss) {
          bar->Tick(first ? step : 1);  // a resumed run starts with the bar part-way
          first = false;
          bar->SetStatus("loss " + FormatFixed(loss * 1e3, 3) + "e-3");
          if (!bar_enabled && (step % every == 0 || step == o.steps)) {
            const double seconds =
                std::chrono::duration<double>(std::chrono::steady_clock::now() - started).count();
            std::cout << "train " << name << ": step " << step << "/" << o.steps << "  batch loss "
                      << loss << "  " << static_cast<int>(seconds) << " s" << std::endl;
          }
          return !g_interrupted.load();
        });
    bar->Finish();
    if (result.summary.stopped) {
      std::signal(SIGINT, SIG_DFL);
      throw std::runtime_error(std::string("interrupted while training ") + name + " at step " +
                               std::to_string(result.summary.steps) + "; checkpoint written to " +
                               o.checkpoint_path +
                               ". Continue with the same command plus --resume.");
    }
    if (!std::isfinite(result.summary.final_loss)) {
      throw std::runtime_error(std::string("training ") + name + " failed: the loss became " +
                               "non-finite at step " + std::to_string(result.summary.steps) +
                               ". No model was written. This run's --learning-rate was " +
                               std::to_string(o.trunk_learning_rate));
    }
    std::vector<std::shared_ptr<const PhotometricTrunk::Markers>> markers;
    for (const Image& reference : references) {
      markers.push_back(result.trunk.MakeMarkers(reference));
    }
    auto photometric = std::make_shared<PhotometricTrunk>(result.trunk);
    if (o.learn_background) {
      std::cout << "train " << name << ": background learned along, RMS "
                << photometric->BackgroundRms() << std::endl;
    }
    if (flags.lighting > 0) {
      std::cout << "train " << name << ": " << flags.lighting << " lighting images learned, RMS "
                << photometric->LightingRms() << std::endl;
    }
    // The likelihood scale of the samplers: the RMS residual of the training latents over
    // up to 64 evenly spaced training frames, whole frames.
    const int checked = std::min<int>(64, static_cast<int>(frames.size()));
    std::vector<double> mse(checked);
    internal::ParallelFor(checked, o.threads, [&](int k) {
      const std::size_t i = static_cast<std::size_t>(k) * frames.size() / checked;
      mse[k] = photometric->LossAndGradient<float>(
          photometric->AllPixels(), result.latents.row(i).transpose().cast<float>(),
          frames[i].values, frames[i].weights, nullptr, nullptr, nullptr, nullptr,
          markers[frame_reference[i]].get());
    });
    double mse_sum = 0;
    for (double m : mse) mse_sum += m;
    SensorTrunk trunk;
    trunk.sensor = sensor;
    trunk.format = format;
    trunk.siren = result.trunk.siren();
    trunk.alpha = Eigen::VectorXd::Zero(trunk.siren.latent_dim());
    trunk.photometric = photometric;
    // The fits' warm starts (encode --strategy knn+adam:N): the training latents, looked
    // up by each frame's descriptor in its moment frame.
    if (!flags.no_warm_start) {
      trunk.warm_start = std::make_shared<WarmStartTable>(
          PhotometricWarmStart::BuildTable(*trunk.photometric, frames, result.latents,
                                           PhotometricWarmStart::Options(), o.threads));
    }
    trunk.residual_sigma = std::sqrt(mse_sum / checked);
    trunk.description = TrainedDescription(dataset, sensor, format);
    std::cout << "train " << name << ": " << result.summary.steps << " steps in "
              << FormatDuration(result.summary.seconds) << " (h:mm:ss / m:ss), final batch loss "
              << result.summary.final_loss << ", marker scale "
              << FormatFixed(result.trunk.marker_scale(), 3) << " px per unit slope, residual "
              << "sigma " << trunk.residual_sigma << std::endl;
    figures[name] = {{"head", "photometric"},
                     {"steps", result.summary.steps},
                     {"seconds", result.summary.seconds},
                     {"loss", result.summary.final_loss},
                     {"residual_sigma", trunk.residual_sigma},
                     {"train_frames", frames.size()},
                     {"marker_scale", result.trunk.marker_scale()}};
    if (o.learn_background) figures[name]["background_rms"] = photometric->BackgroundRms();
    if (flags.lighting > 0) figures[name]["lighting_rms"] = photometric->LightingRms();
    info_trunks[name] = {{"data_frames", DataFramesJson(info)},
                         {"head", "photometric"},
                         {"options",
                          {{"width", o.trunk.width},
                           {"layers", o.trunk.num_hidden_layers},
                           {"latent_dim", o.trunk.latent_dim},
                           {"steps", o.steps},
                           {"batch_frames", o.batch_frames},
                           {"batch_pixels", o.batch_pixels},
                           {"trunk_learning_rate", o.trunk_learning_rate},
                           {"latent_learning_rate", o.latent_learning_rate},
                           {"marker_warmup_steps", o.marker_warmup_steps},
                           {"contact_share", o.contact_share},
                           {"background", o.learn_background},
                           {"lighting", flags.lighting},
                           {"latent_noise", o.latent_noise},
                           {"seed", o.seed}}},
                         {"steps", result.summary.steps},
                         {"train_frames", frames.size()},
                         {"final_loss", result.summary.final_loss}};
    trunk.default_fit = flags.default_fit;
    model.SetTrunk(std::move(trunk));
  }
  model.set_info_json(nlohmann::json({{"trainer", "tactfunc train --head photometric"},
                                      {"preset", "photometric"},
                                      {"data", flags.data},
                                      {"trunks", info_trunks}})
                          .dump(-1, ' ', false, nlohmann::json::error_handler_t::replace));
  g_saving.store(true);
  model.Save(flags.out);
  g_saving.store(false);
  std::signal(SIGINT, SIG_DFL);
  const std::uint64_t model_bytes = std::filesystem::file_size(flags.out);
  std::cout << "train: wrote " << flags.out << " (" << FormatBytes(model_bytes) << ", "
            << sensors.size() << " photometric trunk(s))" << std::endl;
  if (g_interrupted.load()) ExitInterrupted();
  if (flags.json) {
    EmitJson({{"out", flags.out},
              {"sensors", figures},
              {"processes", 1},
              {"threads", OptionsForData(flags, dataset, sensors.front()).threads},
              {"model_bytes", model_bytes},
              {"curves", nullptr}});
  }
}

void RunTrain(const TrainFlags& flags) {
  for (SensorKind sensor : {SensorKind::kSoftBubble, SensorKind::kGelSlim}) {
    OptionsFor(flags, sensor);  // bad flags fail before the dataset is read
  }
  if (!flags.default_fit.empty()) {  // checked as encode will check it, before training
    // Only the photometric head's: `fit` fits a direct trunk with its own default
    // (ceres:10), not encode's, so a recorded fit would mean two things there.
    if (flags.head != "photometric") {
      throw UsageError("--default-fit applies to --head photometric");
    }
    FitStrategy strategy;
    std::string error;
    if (!FitStrategy::Parse(flags.default_fit, &strategy, &error)) {
      throw UsageError("--default-fit: " + error);
    }
    error = LatentEncoder::StrategyRefusal(strategy, /*photometric=*/true, !flags.no_warm_start);
    if (!error.empty()) throw UsageError("--default-fit: the trained trunk " + error);
  }
  ApplyProductPrecision(flags.products);

  const std::filesystem::path out_path(flags.out);
  const std::filesystem::path out_dir =
      out_path.has_parent_path() ? out_path.parent_path() : std::filesystem::path(".");
  if (!std::filesystem::is_directory(out_dir)) {
    throw UsageError("--out: folder '" + out_dir.string() + "' does not exist");
  }

  // The model, its checkpoints and its curves picture must not be a dataset file.
  const std::vector<NamedPath> outputs = {
      {"--out", flags.out},
      {"--out (checkpoint)", CheckpointPath(flags.out, SensorKind::kSoftBubble)},
      {"--out (checkpoint)", CheckpointPath(flags.out, SensorKind::kGelSlim)},
      {"--out (training curves)", TrainingCurvesPath(flags.out)}};
  RefuseOutputsThatAreInputs(outputs, DatasetPathInputs("--data", flags.data, flags.data_flags));
  // Temporary files of an earlier run killed mid-write (SIGKILL) are removed (by the
  // one process that writes).
  const ProcessGroup& processes = Processes();
  if (processes.rank() == 0) {
    for (const NamedPath& output : outputs) RemoveStaleTemporaries(output.path);
  }
  const Dataset dataset = OpenDataset(flags.data, flags.data_flags);
  RefuseOutputsThatAreInputs(outputs, DatasetFileInputs("--data", dataset));
  std::vector<SensorKind> sensors;
  if (flags.sensors.empty()) {
    sensors = dataset.sensors();
  } else {
    sensors = ParseSensorsFlag(flags.sensors);
    for (SensorKind kind : sensors) {
      if (!dataset.has_sensor(kind)) {
        throw UsageError("--sensors: the dataset " + flags.data + " has no '" +
                         std::string(ToString(kind)) + "' frames");
      }
    }
  }
  if (sensors.empty()) throw UsageError("--sensors: expected at least one sensor");
  if (flags.head == "photometric" && flags.sensors.empty()) {  // the dataset's optical sensors
    sensors.erase(std::remove(sensors.begin(), sensors.end(), SensorKind::kSoftBubble),
                  sensors.end());
    if (sensors.empty()) {
      throw UsageError("--head photometric: the dataset " + flags.data +
                       " has no optical (gelslim) frames");
    }
  }
  if (flags.resume) {
    bool any = false;
    for (SensorKind s : sensors) any = any || std::filesystem::exists(CheckpointPath(flags.out, s));
    if (!any) {
      throw UsageError("--resume: no checkpoint found (looked for " +
                       CheckpointPath(flags.out, sensors[0]) + ")");
    }
  }
  if (flags.head == "photometric") {
    g_interrupted.store(false);
    std::signal(SIGINT, HandleSigint);
    TrainPhotometric(flags, dataset, sensors);
    return;
  }
  if (flags.marker_warmup_option->count()) {
    throw UsageError("--marker-warmup applies to --head photometric");
  }
  if (flags.contact_share_option->count()) {
    throw UsageError("--contact-share applies to --head photometric");
  }
  if (flags.no_warm_start) throw UsageError("--no-warm-start applies to --head photometric");
  if (flags.background) throw UsageError("--background applies to --head photometric");
  if (flags.lighting > 0) throw UsageError("--lighting applies to --head photometric");
  if (flags.latent_noise > 0) {
    throw UsageError("--latent-noise applies to --head photometric");
  }
  if (flags.resume) {
    // Every process reads the checkpoints (rank 0 writes them): they must see the same.
    for (SensorKind s : sensors) RefuseUnsharedFile(processes, CheckpointPath(flags.out, s));
  }

  // What the run will do, before it starts: steps per sensor and the working resolution
  // (a stretch of the frames to it is warned about); a time estimate follows from the
  // first steps.
  for (SensorKind sensor : sensors) {
    const TrunkTrainer::Options o = OptionsForData(flags, dataset, sensor);
    std::string resolution;
    try {
      // Only rows and cols are used here; the scale is the trainer's business.
      const double scale = dataset.sensor_info(sensor).normalization_scale;
      const FrameFormat format = TrunkTrainer(o).ResolveFormat(sensor, scale > 0 ? scale : 1.0);
      resolution = " at " + std::to_string(format.rows) + "x" + std::to_string(format.cols);
      WarnIfStretched(dataset, flags.data, sensor, format.rows, format.cols, "train");
    } catch (const std::exception&) {
      // The trainer reports a format it cannot resolve when it starts.
    }
    std::cout << "train " << ToString(sensor) << ": " << o.steps << " steps (preset "
              << flags.preset << (flags.steps_option->count() ? ", --steps" : "") << ")"
              << resolution << ", batch " << o.batch_size << " on "
              << (processes.size() > 1 ? std::to_string(processes.size()) + " processes x " : "")
              << o.threads << " thread(s)"
              << (o.siren.has_spatial()
                      ? ", spatial latents " + std::to_string(o.siren.spatial_rows) + "x" +
                            std::to_string(o.siren.spatial_cols) + "x" +
                            std::to_string(o.siren.spatial_channels) + " + " +
                            std::to_string(o.siren.global_latent_dim()) + " global"
                      : std::string())
              << (o.readout
                      ? "; first the readout branch's basis, a PCA of up to " +
                            std::to_string(o.readout_pca_frames) + " training frames"
                      : std::string())
              << "; a time estimate follows the first steps" << std::endl;
  }

  g_interrupted.store(false);
  std::signal(SIGINT, HandleSigint);
  const bool bar_enabled = ProgressBar::Enabled();

  FunctaModel model;
  std::vector<std::pair<SensorKind, std::vector<TrunkTrainer::HistoryPoint>>> curves;
  nlohmann::json sensor_figures = nlohmann::json::object();
  nlohmann::json info_trunks = nlohmann::json::object();
  for (SensorKind sensor : sensors) {
    TrunkTrainer::Options sensor_options = OptionsForData(flags, dataset, sensor);
    sensor_options.checkpoint_path = CheckpointPath(flags.out, sensor);
    sensor_options.resume = flags.resume;
    sensor_options.processes = &processes;
    const TrunkTrainer trainer(sensor_options);
    const char* name = ToString(sensor);
    if (flags.resume) {
      std::cout << "train " << name << ": "
                << (std::filesystem::exists(sensor_options.checkpoint_path)
                        ? "resuming from " + sensor_options.checkpoint_path
                        : std::string("no checkpoint, starting at step 0"))
                << "\n";
    }
    auto bar =
        std::make_unique<ProgressBar>(std::string("train ") + name, sensor_options.steps, "steps");
    bool first = true;
    // The estimate: wall time from the first step's report over at least 5 more steps
    // and 2 s (or 10 s), said once.
    bool estimated = false;
    int first_step = 0;
    std::chrono::steady_clock::time_point first_time;
    const auto callback = [&](const TrunkTrainer::StepReport& report) {
      if (first) {  // a resumed run starts with the bar part-way
        bar->Tick(report.step - 1);
        first = false;
        first_step = report.step;
        first_time = std::chrono::steady_clock::now();
      } else if (!estimated && report.step < report.total_steps) {
        const double seconds =
            std::chrono::duration<double>(std::chrono::steady_clock::now() - first_time).count();
        const int steps = report.step - first_step;
        if ((steps >= 5 && seconds >= 2) || seconds >= 10) {
          const double per_step = seconds / steps;
          std::cout << "train " << name << ": " << FormatFixed(per_step, 3)
                    << " s per step over steps " << first_step + 1 << "-" << report.step
                    << ": about " << FormatDuration(per_step * (report.total_steps - report.step))
                    << " (h:mm:ss / m:ss) for the remaining "
                    << report.total_steps - report.step << " steps" << std::endl;
          estimated = true;
        }
      }
      bar->Tick(1);
      bar->SetStatus(Status(report));
      if (report.monitored && !bar_enabled) {
        std::cout << "train " << name << ": step " << report.step << "/" << report.total_steps
                  << "  " << Status(report) << "  " << static_cast<int>(report.latest.seconds)
                  << " s" << std::endl;
      }
      // Every process stops after the same step when any was interrupted.
      return !processes.AnyOf(g_interrupted.load());
    };
    SensorTrunk trunk;
    const TrunkTrainer::Summary summary = trainer.Train(dataset, sensor, &trunk, callback);
    bar->Finish();
    trunk.description = TrainedDescription(dataset, sensor, trunk.format);
    if (sensor_options.skip_frames_at_rest) {
      std::cout << "train " << name << ": left out " << summary.num_frames_at_rest_skipped
                << " train-split frame(s) at rest; trained on " << summary.num_train_frames
                << "\n";
    }
    std::cout << summary.BriefReport() << "\n";
    if (summary.termination_type == TrunkTrainer::TerminationType::kUserStopped) {
      std::signal(SIGINT, SIG_DFL);
      throw std::runtime_error(std::string("interrupted while training ") + name + " at step " +
                               std::to_string(summary.steps_done) + "; checkpoint written to " +
                               sensor_options.checkpoint_path +
                               ". Continue with the same command plus --resume.");
    }
    if (summary.termination_type == TrunkTrainer::TerminationType::kNonFinite ||
        summary.termination_type == TrunkTrainer::TerminationType::kDiverged) {
      std::signal(SIGINT, SIG_DFL);
      std::ostringstream hint;
      hint << ". No model was written. This run's --learning-rate was "
           << sensor_options.learning_rate;
      if (summary.termination_type == TrunkTrainer::TerminationType::kDiverged) {
        hint << "; --divergence-drop-db 0 turns the check off";
      }
      throw std::runtime_error(std::string("training ") + name + " failed: " + summary.message +
                               hint.str());
    }
    model.SetTrunk(std::move(trunk));
    sensor_figures[name] = {{"steps", summary.steps_done},
                            {"seconds", summary.total_train_seconds},
                            {"seconds_per_step", summary.seconds_per_step},
                            {"train_psnr", summary.train_psnr},
                            {"train_psnr_at_zero", summary.train_psnr_at_zero},
                            {"loss", summary.final_loss},
                            {"residual_sigma", summary.residual_sigma},
                            {"train_frames", summary.num_train_frames},
                            {"frames_at_rest_skipped", summary.num_frames_at_rest_skipped},
                            {"parameters", summary.num_parameters}};
    // No wall-clock figures (seconds, threads) in the model file: the same seed gives
    // the same bytes and so the same checksum (docs/TRAINING.md). The timing is in
    // the output above and in --json.
    nlohmann::json history = nlohmann::json::array();
    for (const TrunkTrainer::HistoryPoint& p : summary.history) {
      history.push_back({p.step, p.loss, p.psnr, p.psnr_at_zero});
    }
    curves.push_back({sensor, summary.history});
    info_trunks[name] = {
        {"data_frames", DataFramesJson(dataset.sensor_info(sensor))},
        {"options", nlohmann::json::parse(trainer.TrajectoryOptionsJson(sensor, summary.format))},
        {"steps", summary.steps_done},
        {"train_frames", summary.num_train_frames},
        {"train_psnr", summary.train_psnr},
        {"train_psnr_at_zero", summary.train_psnr_at_zero},
        {"final_loss", summary.final_loss},
        {"history_columns", {"step", "loss", "psnr", "psnr_at_zero"}},
        {"history", history}};
  }
  if (processes.rank() != 0) return;  // rank 0 writes the model and speaks
  nlohmann::json info = {{"trainer", "tactfunc train"},
                         {"preset", flags.preset},
                         {"data", flags.data},
                         {"trunks", info_trunks}};
  // Only where not float, so that a float run's model keeps the bytes (and checksum) it
  // had before the flag existed.
  if (flags.products != "float") info["products"] = flags.products;
  model.set_info_json(info.dump(-1, ' ', false, nlohmann::json::error_handler_t::replace));
  // The handler stays installed through the write (a Ctrl-C now would otherwise kill
  // the process between the temporary file and the rename, losing the model).
  g_saving.store(true);
  model.Save(flags.out);
  g_saving.store(false);
  std::signal(SIGINT, SIG_DFL);
  if (g_interrupted.load()) {
    std::cout << "train: interrupted while writing the model; the model was written "
                 "completely to "
              << flags.out << " (training curves skipped)" << std::endl;
    ExitInterrupted();
  }
  const std::uint64_t model_bytes = std::filesystem::file_size(flags.out);
  std::cout << "train: wrote " << flags.out << " (" << FormatBytes(model_bytes) << ", "
            << sensors.size() << " trunk(s), preset " << flags.preset << "); checkpoints "
            << flags.out << ".<sensor>.ckpt can be deleted\n";
  const std::string curves_path = TrainingCurvesPath(flags.out);
  const cv::Mat picture = TrainingCurvesPlot(
      curves, "preset " + flags.preset + ", data " + flags.data + ", seed " +
                  std::to_string(OptionsFor(flags, sensors.front()).seed));
  bool wrote_curves = false;
  if (!picture.empty()) {
    try {  // the model is written: a picture that cannot be is a warning, not a failure
      WritePicture(curves_path, picture);
      wrote_curves = true;
      std::cout << "train: wrote the training curves to " << curves_path << "\n";
    } catch (const std::exception& e) {
      std::cerr << "train: warning: no training curves: " << e.what() << "\n";
    }
  }
  if (flags.json) {
    EmitJson({{"out", flags.out},
              {"sensors", sensor_figures},
              {"processes", processes.size()},
              {"threads", OptionsFor(flags, sensors.front()).threads},
              {"model_bytes", model_bytes},
              {"curves", wrote_curves ? nlohmann::json(curves_path) : nlohmann::json(nullptr)}});
  }
}

}  // namespace

void RegisterTrain(CLI::App& app, CommandBody* selected) {
  auto flags = std::make_shared<TrainFlags>();
  CLI::App* sub = app.add_subcommand(
      "train",
      "Meta-learn a latent-modulated SIREN trunk per sensor on a dataset's train split "
      "and write a model file (docs/TRAINING.md).");
  sub->add_option("--data", flags->data, "Dataset folder (ours or your own) or video")->required();
  AddDatasetFlags(sub, &flags->data_flags);
  sub->add_option("--out", flags->out, "Model file to write (.tfm)")->required();
  std::string presets;
  for (const std::string& n : TrunkTrainer::PresetNames())
    presets += (presets.empty() ? "" : ", ") + n;
  sub->add_option("--preset", flags->preset,
                  "Starting options: " + presets + " (default: default; docs/TRAINING.md)")
      ->check(CLI::IsMember(TrunkTrainer::PresetNames()));
  sub->add_option("--sensors", flags->sensors,
                  "Comma-separated: bubble,gelslim (default: every sensor of the dataset)");
  flags->latent_dim_option = sub->add_option("--latent-dim", flags->latent_dim,
                                             "Latent dimension d (overrides the preset)")
                                 ->check(CLI::Range(1, 100000));
  flags->width_option = sub->add_option("--width", flags->width, "Units per hidden layer")
                            ->check(CLI::Range(1, 100000));
  flags->layers_option =
      sub->add_option("--layers", flags->layers, "Hidden sine layers")->check(CLI::Range(1, 1000));
  flags->steps_option =
      sub->add_option("--steps", flags->steps,
                      "Outer steps in total (a resumed run counts earlier ones; default: the "
                      "preset's, or " +
                          std::to_string(kPhotometricDefaultSteps) + " with --head photometric)")
          ->check(CLI::Range(0, 100000000));
  flags->batch_option = sub->add_option("--batch", flags->batch, "Frames per outer step")
                            ->check(CLI::Range(1, 100000));
  flags->pixels_option =
      sub->add_option("--pixels", flags->pixels, "Random pixels per frame per step (0 = all)")
          ->check(CLI::Range(0, 100000000));
  flags->learning_rate_option =
      sub->add_option("--learning-rate", flags->learning_rate,
                      "Adam step size of the trunk (default: the preset's, 3e-4)")
          ->check(CLI::PositiveNumber);
  flags->lr_final_fraction_option =
      sub->add_option("--lr-final-fraction", flags->lr_final_fraction,
                      "Cosine decay of the learning rate to this fraction of it by the last "
                      "step, in (0, 1] (default: the preset's; 1 = constant)")
          ->check(CLI::Range(1e-9, 1.0));
  flags->omega_0_option =
      sub->add_option("--omega-0", flags->omega_0,
                      "SIREN frequency omega_0 in rad per unit of coordinate (default 30, "
                      "SIREN's and the paper's; coordinates span [-1, 1])")
          ->check(CLI::PositiveNumber);
  flags->inner_steps_option =
      sub->add_option("--inner-steps", flags->inner_steps,
                      "Meta-SGD steps K from z = 0, in training and in every later encode "
                      "(default 3, the paper's; cost grows linearly in K; 0, with --readout "
                      "only: every fit is the readout branch's projection)")
          ->check(CLI::Range(0, 1000));
  flags->alpha_init_option =
      sub->add_option("--alpha-init", flags->alpha_init,
                      "Initial meta-SGD rate of every latent dimension, in [0, alpha-max] "
                      "(default 1)")
          ->check(CLI::NonNegativeNumber);
  flags->alpha_max_option =
      sub->add_option("--alpha-max", flags->alpha_max,
                      "Upper clip bound of the learned meta-SGD rates (default 1, the "
                      "range of functa's meta-SGD rates, [0, 1]; docs/TRAINING.md)")
          ->check(CLI::PositiveNumber);
  flags->divergence_drop_db_option =
      sub->add_option("--divergence-drop-db", flags->divergence_drop_db,
                      "Stop with an error when the monitor PSNR falls this many dB below its "
                      "best (default 6; 0 = never; docs/TRAINING.md)")
          ->check(CLI::NonNegativeNumber);
  sub->add_flag("--first-order", flags->first_order,
                "First-order meta-gradients (cheaper, biased; default exact)");
  sub->add_flag("--readout", flags->readout,
                "Add the linear readout branch: a per-pixel basis started from the training "
                "frames' PCA, so the trunk contains PCA (docs/REPRESENTATION.md)");
  sub->add_option("--readout-pca-frames", flags->readout_pca_frames,
                  "Training frames (evenly spaced) the readout branch's PCA start is "
                  "computed from (default 1500; the PCA's time grows as the cube of the "
                  "smaller of their count and their values)")
      ->check(CLI::Range(1, 100000));
  flags->readout_rate_option =
      sub->add_option("--readout-rate", flags->readout_rate,
                      "The readout branch's step size as a fraction of the trunk's, in [0, 1] "
                      "(default 0: kept at its PCA start)")
          ->check(CLI::Range(0.0, 1.0));
  sub->add_flag("--outer-clean", flags->outer_clean,
                "Meta-learn against the frames' noise-free copies (a dataset with them: synth "
                "--clean): the inner fit sees the noisy frame, the outer loss the clean one, "
                "so the trunk learns fits that leave the noise out (docs/REPRESENTATION.md)");
  sub->add_flag("--skip-rest", flags->skip_rest,
                "Leave train-split frames at rest (no contact above the sensor's noise; "
                "docs/REAL_DATA.md) out of training");
  sub->add_option("--spatial-latent", flags->spatial_latent,
                  "Spatial latents GHxGWxC: a GH x GW grid of C-value latents, interpolated "
                  "per pixel into the trunk's shifts, beside a global latent of "
                  "latent-dim - GH*GW*C values (0: spatial alone); --latent-dim counts both "
                  "(docs/REPRESENTATION.md)");
  sub->add_option("--working-size", flags->working_size,
                  "Working resolution ROWSxCOLS the frames are resized to (default: the "
                  "preset's; keep your frames' aspect ratio)");
  AddProductPrecisionFlag(sub, &flags->products);
  sub->add_option("--threads", flags->threads, "Worker threads (default: all cores)")
      ->check(CLI::Range(0, 256));
  flags->seed_option =
      sub->add_option("--seed", flags->seed, "Seed; the same seed gives the same model");
  flags->checkpoint_every_option =
      sub->add_option("--checkpoint-every", flags->checkpoint_every,
                      "Write OUT.<sensor>.ckpt every N steps (0 = only at the end or on Ctrl-C)")
          ->check(CLI::Range(0, 100000000));
  sub->add_flag("--resume", flags->resume,
                "Continue from OUT.<sensor>.ckpt (the options must match the checkpoint's)");
  sub->add_option("--head", flags->head,
                  "direct (default: the SIREN draws the frame, meta-SGD fits) or photometric "
                  "(optical sensors: the SIREN draws the contact, a head moves the reference's "
                  "markers and shades it; trained jointly with its latents, docs/REPRESENTATION.md)")
      ->check(CLI::IsMember({"direct", "photometric"}));
  flags->marker_warmup_option =
      sub->add_option("--marker-warmup", flags->marker_warmup,
                      "--head photometric: steps with the markers moved at the working "
                      "resolution before the sensor's (default 1000)")
          ->check(CLI::Range(0, 100000000));
  flags->contact_share_option =
      sub->add_option("--contact-share", flags->contact_share,
                      "--head photometric: share of each frame's pixels a step draws towards "
                      "its contact (weighted so that the loss is still the whole frame's); "
                      "0 draws every pixel alike (default 0.5)")
          ->check(CLI::Range(0.0, 0.999));
  sub->add_flag("--no-warm-start", flags->no_warm_start,
                "--head photometric: leave the training latents' warm-start table out of the "
                "model (a smaller file; encode then fits with adam:N only)");
  sub->add_flag("--background", flags->background,
                "--head photometric: also learn the sensor's background, what every frame "
                "shares that the contact does not draw (a value per pixel, no latent bytes), "
                "which every reconstruction adds: for real gels that drift from their "
                "reference; it costs on simulated frames (docs/REAL_DATA.md)");
  sub->add_option("--lighting", flags->lighting,
                  "--head photometric: K lighting images, each weighed by one of the latent's "
                  "last K values: how a real gel's lighting varies from frame to frame over "
                  "the whole gel, a few of the latent's values instead of the contact's code; "
                  "implies --background (default 0; docs/REAL_DATA.md)")
      ->check(CLI::Range(0, 64));
  sub->add_option("--latent-noise", flags->latent_noise,
                  "--head photometric: standard deviation of the noise added to each training "
                  "frame's code values whenever a step draws it, so that the trunk draws the "
                  "frames from near their latents too: for a few real frames, whose unseen "
                  "frames it then draws closer (default 0, none; docs/REAL_DATA.md)")
      ->check(CLI::Range(0.0, 100.0));
  sub->add_option("--default-fit", flags->default_fit,
                  "--head photometric: the fit encode and fit use for the trained trunk(s) "
                  "when no --strategy is given, recorded in the model (e.g. knn+adam:480; "
                  "default: encode's rule, docs/CLI.md)");
  sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
  sub->callback([flags, selected]() { *selected = [flags]() { RunTrain(*flags); }; });
}

}  // namespace tactfunc::apps
