// Copyright 2026 The tactfunc Authors.
#include "estimation/functaset/latent_encoder.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <condition_variable>
#include <exception>
#include <limits>
#include <map>
#include <filesystem>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <thread>
#include <tuple>
#include <utility>

#include "estimation/data/photometric_markers.h"
#include "estimation/fitting/photometric_ceres_fit.h"
#include "estimation/functaset/latent_codes.h"
#include "estimation/training/photometric_trainer.h"
#include "models/trunk/product_precision.h"

namespace tactfunc {
namespace {

// The default fit of a photometric trunk without a warm-start table, adam:N with
// PhotometricFitOptions' default steps
// (docs/REPRESENTATION.md, "How long to fit a photometric latent"), and the fixed seed of
// its pixel subsets.
const int kPhotometricFitSteps = PhotometricFitOptions().steps;
constexpr std::uint64_t kPhotometricFitSeed = 0x70686f746f;
// knn+adam:N: the neighbours scored per frame, the fit's first step size from the start,
// its pixels per step, the share of them drawn towards the contact, and the default N
// for a trunk with a warm-start table per 64 latent values: at d = 64 the most steps
// whose rounds keep encoding above 100 frames/s on 2 threads on this shared machine kind
// (140: 107.1-109.5 frames/s at the medians of three runs of three rounds, 104.2-110.3
// over the rounds; 160: 98.5; docs/REPRESENTATION.md, "Cheaper draws, 140 steps"); a
// longer latent starts further from its neighbour and has more values to move, and
// d = 128 needed twice the steps for the same margin over same-bits PCA
// (docs/REPRESENTATION.md, "Pixels drawn towards the contact").
constexpr int kWarmStartCandidates = 4;
constexpr double kWarmStartRate = 1e-2;
constexpr int kWarmStartBatchPixels = 64;
constexpr double kWarmStartContactShare = 0.5;
constexpr int kWarmStartFitStepsPer64Values = 140;

}  // namespace

const char* ToString(EncodeTermination termination) {
  switch (termination) {
    case EncodeTermination::kComplete:
      return "complete";
    case EncodeTermination::kInterrupted:
      return "interrupted";
  }
  return "unknown";
}

bool LatentEncoder::Options::IsValid(std::string* error) const {
  std::ostringstream message;
  std::string why;
  if (threads < 1) {
    message << "threads must be >= 1, found " << threads;
  } else if (checkpoint_every < 0) {
    message << "checkpoint_every must be >= 0, found " << checkpoint_every;
  } else if (resume && checkpoint_path.empty()) {
    message << "resume needs a checkpoint_path, found \"\"";
  } else if (latent_precision == Functaset::LatentPrecision::kAllocated && latent_bytes < 1) {
    message << "allocated latents need latent_bytes >= 1, found " << latent_bytes;
  } else if (FitStrategy parsed; !strategy.empty() && !FitStrategy::Parse(strategy, &parsed, &why)) {
    message << "strategy: " << why;
  } else if (!strategy.empty() && parsed.knn &&
             parsed.refinement == FitStrategy::Refinement::kMetaSgd) {
    message << "strategy '" << strategy
            << "': the k-NN strategies need a functaset to search; use meta_sgd:K or ceres:N "
               "(a photometric trunk's knn, knn+adam:N and knn+ceres:N search its own "
               "warm-start table)";
  } else if (!problem.IsValid(&why)) {
    message << "problem: " << why;
  } else if (share_rest_latent && !contact.IsValid(&why)) {
    message << "contact: " << why;
  } else {
    std::vector<SensorKind> sorted = sensors;
    std::sort(sorted.begin(), sorted.end());
    if (std::adjacent_find(sorted.begin(), sorted.end()) != sorted.end()) {
      message << "sensors lists '" << ToString(*std::adjacent_find(sorted.begin(), sorted.end()))
              << "' twice";
    } else {
      return true;
    }
  }
  if (error != nullptr) *error = "LatentEncoder::Options::" + message.str();
  return false;
}

std::string LatentEncoder::Summary::BriefReport() const {
  std::ostringstream out;
  out << "encode: " << ToString(termination) << ", " << (frames_encoded + frames_resumed) << "/"
      << frames_total << " frames (" << frames_encoded << " encoded";
  if (frames_resumed > 0) out << ", " << frames_resumed << " resumed";
  out << ") in " << seconds << " s (" << frames_per_second << " frames/s)";
  for (const auto& [sensor, psnr] : mean_psnr) {
    out << ", " << ToString(sensor) << " " << psnr << " dB";
  }
  return out.str();
}

std::string LatentEncoder::Summary::FullReport() const {
  std::ostringstream out;
  out << "LatentEncoder summary\n"
      << "  termination          " << ToString(termination) << "\n"
      << "  message              " << message << "\n"
      << "  frames selected      " << frames_total << "\n"
      << "  frames encoded       " << frames_encoded << "\n"
      << "  frames resumed       " << frames_resumed << "\n"
      << "  checkpoints written  " << checkpoints_written << "\n"
      << "  non-finite latents   " << non_finite_latents << "\n"
      << "  seconds              " << seconds << "\n"
      << "  frames/s             " << frames_per_second << "\n";
  for (const auto& [sensor, count] : frames) {
    const auto it = mean_psnr.find(sensor);
    out << "  " << ToString(sensor) << ": " << count << " frames, mean PSNR "
        << (it == mean_psnr.end() ? std::string("n/a") : std::to_string(it->second) + " dB")
        << "\n";
  }
  return out.str();
}

std::string LatentEncoder::DefaultPhotometricStrategy(bool warm_start_table, int latent_dim) {
  const int steps = std::max(kWarmStartFitStepsPer64Values,
                             (kWarmStartFitStepsPer64Values * latent_dim + 32) / 64);
  return warm_start_table ? "knn+adam:" + std::to_string(steps)
                          : "adam:" + std::to_string(kPhotometricFitSteps);
}

std::string LatentEncoder::StrategyRefusal(const FitStrategy& strategy, bool photometric,
                                           bool warm_start_table) {
  const bool adam = strategy.refinement == FitStrategy::Refinement::kAdam;
  const bool knn_alone = strategy.knn && strategy.refinement == FitStrategy::Refinement::kNone;
  const bool ceres = strategy.refinement == FitStrategy::Refinement::kCeres;
  if (photometric ? !(adam || knn_alone || (ceres && strategy.knn)) : (adam || strategy.knn)) {
    return std::string("is ") +
           (photometric ? "photometric: its latents are fitted with adam:N, knn+adam:N, "
                          "knn+ceres:N or knn, not "
                        : "direct: its latents are fitted with meta_sgd:K or ceres:N (the k-NN "
                          "strategies need a functaset to search), not ") +
           strategy.ToString();
  }
  if (photometric && strategy.knn && !warm_start_table) {
    return "has no warm-start table for " + strategy.ToString() +
           " (it was trained before train --head photometric stored one, or with "
           "--no-warm-start); use adam:N or retrain";
  }
  return "";
}

LatentEncoder::LatentEncoder(const FunctaModel& model, const Options& options)
    : model_(model), options_(options) {
  std::string error;
  if (!options_.IsValid(&error)) throw std::invalid_argument(error);
  for (SensorKind sensor : model.sensors()) {
    const SensorTrunk& trunk = model.Trunk(sensor);
    SensorState state;
    state.sensor = sensor;
    state.trunk = &trunk;
    // One grid per sensor for the whole run: every frame of a sensor has the same
    // working resolution.
    state.grid = trunk.siren.Grid<float>(trunk.format.rows, trunk.format.cols);
    state.alpha = trunk.alpha.cast<float>();
    state.meta_sgd = MetaSgd(trunk.meta_sgd);
    const bool photometric = trunk.photometric != nullptr;
    // The trunk's recorded default, checked here as an asked-for fit is (the model layer
    // only knows it as a name).
    const bool recorded = options_.strategy.empty() && !trunk.default_fit.empty();
    const std::string whose =
        recorded ? " (the fit the model records as its default, train --default-fit)" : "";
    std::string chosen = options_.strategy;
    if (chosen.empty()) {
      chosen = recorded       ? trunk.default_fit
               : photometric ? DefaultPhotometricStrategy(trunk.warm_start != nullptr,
                                                          trunk.photometric->latent_dim())
                             : "meta_sgd:" + std::to_string(trunk.meta_sgd.inner_steps);
    }
    std::string error;
    if (!FitStrategy::Parse(chosen, &state.strategy, &error)) {
      throw std::invalid_argument(std::string("LatentEncoder: the ") + ToString(sensor) +
                                  " trunk's fit" + whose + ": " + error);
    }
    const bool ceres = state.strategy.refinement == FitStrategy::Refinement::kCeres;
    const std::string refusal =
        StrategyRefusal(state.strategy, photometric, trunk.warm_start != nullptr);
    if (!refusal.empty()) {
      throw std::invalid_argument(std::string("LatentEncoder: the ") + ToString(sensor) +
                                  " trunk " + refusal + whose);
    }
    if (photometric && state.strategy.knn) {
      state.warm_start =
          std::make_shared<const PhotometricWarmStart>(*trunk.photometric, trunk.warm_start);
    }
    if (ceres && !photometric) {
      LatentFitter::Options fit;
      fit.strategy = state.strategy;
      state.fitter.emplace(trunk, fit);
    }
    states_.push_back(std::move(state));
  }
  if (options_.share_rest_latent) {
    for (SensorState& state : states_) {
      // The frame with no change: zero targets on every pixel.
      TrunkTargets rest;
      rest.rows = state.trunk->format.rows;
      rest.cols = state.trunk->format.cols;
      rest.values = Eigen::MatrixXf::Zero(state.grid.rows(), TrunkOutputChannels(*state.trunk));
      rest.weights = Eigen::VectorXf::Ones(state.grid.rows());
      state.rest_latent = EncodeTargetsImpl(state.sensor, rest, nullptr, true).latent;
    }
  }
}

const LatentEncoder::SensorState& LatentEncoder::State(SensorKind sensor) const {
  for (const SensorState& state : states_) {
    if (state.sensor == sensor) return state;
  }
  throw std::invalid_argument(std::string("LatentEncoder: the model has no trunk for sensor '") +
                              ToString(sensor) + "'");
}

LatentEncoder::EncodedFrame LatentEncoder::EncodeTargets(
    SensorKind sensor, const TrunkTargets& targets,
    const PhotometricTrunk::Markers* markers) const {
  return EncodeTargetsImpl(sensor, targets, markers, options_.score_targets);
}

LatentEncoder::EncodedFrame LatentEncoder::EncodeTargetsImpl(
    SensorKind sensor, const TrunkTargets& targets, const PhotometricTrunk::Markers* markers,
    bool score) const {
  const SensorState& state = State(sensor);
  const LatentModulatedSiren& siren = state.trunk->siren;
  const int channels = TrunkOutputChannels(*state.trunk);
  if (targets.values.rows() != state.grid.rows() || targets.values.cols() != channels ||
      targets.weights.size() != targets.values.rows()) {
    throw std::invalid_argument(
        std::string("LatentEncoder: the ") + ToString(sensor) + " trunk expects " +
        std::to_string(state.trunk->format.rows) + "x" + std::to_string(state.trunk->format.cols) +
        " pixels x " + std::to_string(channels) + " channel(s) (" +
        std::to_string(state.grid.rows()) + " x " + std::to_string(channels) +
        " targets), found " + std::to_string(targets.values.rows()) + " x " +
        std::to_string(targets.values.cols()) + " targets and " +
        std::to_string(targets.weights.size()) + " weights");
  }
  EncodedFrame out;
  if (state.trunk->photometric != nullptr) {
    // The photometric fit (moment start and its flip); its pixel subsets come from one
    // fixed seed, so a frame's latent depends on the frame alone.
    PhotometricFitOptions fit;
    fit.steps = state.strategy.steps;
    fit.markers = markers;
    if (state.strategy.refinement == FitStrategy::Refinement::kCeres) {
      // knn+ceres:N: Levenberg-Marquardt on every valid pixel from the best neighbour
      // (estimation/fitting/photometric_ceres_fit.h).
      PhotometricCeresOptions ceres;
      ceres.iterations = state.strategy.steps;
      ceres.pixels = 0;
      ceres.markers = markers;
      out.latent = FitPhotometricLatentCeres(
                       *state.trunk->photometric, targets,
                       state.warm_start->BestStart(targets, kWarmStartCandidates,
                                                   PhotometricWarmStart::kScoredPixels, markers),
                       ceres)
                       .latent.cast<float>();
    } else if (state.warm_start != nullptr) {
      // One start, the best of the table's nearest neighbours, refined by a short fit
      // (docs/REPRESENTATION.md, "A warm start from the training latents"); knn alone
      // has 0 steps and keeps that start.
      fit.learning_rate = kWarmStartRate;
      fit.batch_pixels = kWarmStartBatchPixels;
      fit.contact_share = kWarmStartContactShare;
      out.latent = state.warm_start->Fit(targets, kWarmStartCandidates, fit, kPhotometricFitSeed)
                       .latent.cast<float>();
    } else {
      out.latent = FitPhotometricLatent(*state.trunk->photometric, targets, fit,
                                        kPhotometricFitSeed)
                       .latent.cast<float>();
    }
    out.psnr = score ? Psnr(TrunkDecode(*state.trunk, out.latent, markers), targets)
                     : std::numeric_limits<double>::quiet_NaN();
    return out;
  }
  if (state.fitter) {
    const LatentProblem problem(*state.trunk, targets, options_.problem);
    Eigen::VectorXd latent;
    out.psnr = state.fitter->Fit(problem, &latent).psnr;
    out.latent = latent.cast<float>();
    return out;
  }
  // meta_sgd:K over every pixel (invalid ones weigh 0) from the trunk's StartLatent
  // (zero, or the readout branch's projection), as in training.
  out.latent = state.meta_sgd.InnerLoop<float>(
      siren, state.grid, targets.values, targets.weights, state.alpha,
      siren.StartLatent<float>(state.grid, targets.values, targets.weights), state.strategy.steps);
  out.psnr = Psnr(siren.Forward<float>(state.grid, out.latent), targets);
  return out;
}

namespace {

struct Job {
  std::size_t frame = 0;  // index into Dataset::frames()
  SensorKind sensor = SensorKind::kSoftBubble;
  bool done = false;
  FunctasetEntry entry;
};

double MeanFinite(const std::vector<double>& values) {
  double sum = 0;
  std::int64_t count = 0;
  for (double v : values) {
    if (std::isfinite(v)) {
      sum += v;
      ++count;
    }
  }
  return count > 0 ? sum / count : 0.0;
}

// Appends the count and, per job index of `indices`, the index, the PSNR and the latent.
void PackJobs(const std::vector<Job>& jobs, const std::vector<std::size_t>& indices,
              ByteWriter* out) {
  out->Put<std::uint64_t>(indices.size());
  for (std::size_t j : indices) {
    out->Put<std::uint64_t>(j);
    out->Put<float>(jobs[j].entry.psnr);
    out->Put<std::uint8_t>(jobs[j].entry.at_rest ? 1 : 0);
    out->PutFloats(jobs[j].entry.latent.data(), jobs[j].entry.latent.size());
  }
}

// Reads what PackJobs wrote into `jobs` (which must list the same frames) and returns
// the job indices read. Their `done` flags are left to the caller.
std::vector<std::size_t> UnpackJobs(ByteReader& in, std::vector<Job>* jobs) {
  std::vector<std::size_t> indices(static_cast<std::size_t>(in.Get<std::uint64_t>()));
  for (std::size_t& j : indices) {
    j = static_cast<std::size_t>(in.Get<std::uint64_t>());
    if (j >= jobs->size()) {
      throw std::runtime_error("LatentEncoder: another process sent frame " + std::to_string(j) +
                               " of " + std::to_string(jobs->size()) +
                               " (do all processes read the same data and options?)");
    }
    FunctasetEntry& entry = (*jobs)[j].entry;
    entry.psnr = in.Get<float>();
    entry.at_rest = in.Get<std::uint8_t>() != 0;
    entry.latent.resize(static_cast<Eigen::Index>(in.FloatCount()));
    in.GetFloats(entry.latent.data(), static_cast<std::size_t>(entry.latent.size()));
  }
  return indices;
}

std::string ExceptionText(const std::exception_ptr& error) {
  try {
    std::rethrow_exception(error);
  } catch (const std::exception& e) {
    return e.what();
  } catch (...) {
    return "unknown error";
  }
}

}  // namespace

Functaset LatentEncoder::Encode(const Dataset& dataset, Summary* summary,
                                const ProgressCallback& progress,
                                const std::atomic<bool>* interrupt) const {
  const auto start = std::chrono::steady_clock::now();
  Summary local_summary;
  Summary& s = summary != nullptr ? *summary : local_summary;
  s = Summary();

  // ---- Which sensors, and do their frames fit the trunks? -----------------------------
  std::vector<SensorKind> sensors = options_.sensors;
  if (sensors.empty()) {
    for (SensorKind sensor : dataset.sensors()) {
      if (model_.HasSensor(sensor)) sensors.push_back(sensor);
    }
    if (sensors.empty()) {
      throw std::invalid_argument("LatentEncoder: the model and the dataset " + dataset.root() +
                                  " have no sensor in common");
    }
  }
  std::sort(sensors.begin(), sensors.end());
  for (SensorKind sensor : sensors) {
    if (!dataset.has_sensor(sensor)) {
      throw std::invalid_argument(std::string("LatentEncoder: sensor '") + ToString(sensor) +
                                  "' was requested but the dataset " + dataset.root() +
                                  " has no frames of it");
    }
    const SensorTrunk& trunk = *State(sensor).trunk;
    const SensorInfo& info = dataset.sensor_info(sensor);
    const int channels = trunk.format.grayscale ? 1 : info.channels;
    if (channels != TrunkOutputChannels(trunk)) {
      throw std::invalid_argument(
          std::string("LatentEncoder: the model's ") + ToString(sensor) + " trunk outputs " +
          std::to_string(TrunkOutputChannels(trunk)) + " channel(s), but the dataset's " +
          std::to_string(info.channels) + "-channel frames give " + std::to_string(channels) +
          (trunk.format.grayscale ? " (grayscale)" : ""));
    }
    // Allocated codes hold at most 16 bits per value: refused now, not after the frames.
    const int d = TrunkLatentDim(trunk);
    if (options_.latent_precision == Functaset::LatentPrecision::kAllocated &&
        options_.latent_bytes > MaxCodeBytes(d)) {
      throw std::invalid_argument("LatentEncoder: " + std::to_string(options_.latent_bytes) +
                                  " bytes per frame for " + ToString(sensor) + " latents of " +
                                  std::to_string(d) + " values, expected at most " +
                                  std::to_string(MaxCodeBytes(d)) + " (" +
                                  std::to_string(kMaxCodeBits) + " bits per value)");
    }
  }

  // ---- The work list, in output order ------------------------------------------------
  std::vector<Job> jobs;
  for (SensorKind sensor : sensors) {
    for (std::size_t index : dataset.FrameIndices(sensor, options_.split)) {
      Job job;
      job.frame = index;
      job.sensor = sensor;
      const FrameRecord& record = dataset.frames()[index];
      job.entry.id = record.id;
      job.entry.split = record.split;
      job.entry.label = record.label;
      jobs.push_back(std::move(job));
    }
  }
  s.frames_total = static_cast<std::int64_t>(jobs.size());

  const ProcessGroup& group = options_.processes != nullptr ? *options_.processes : SingleProcess();
  if (options_.resume && group.rank() == 0 && std::filesystem::exists(options_.checkpoint_path)) {
    const Functaset checkpoint = Functaset::Load(options_.checkpoint_path);
    checkpoint.CheckModel(model_, "in use", options_.checkpoint_path);
    for (SensorKind sensor : checkpoint.sensors()) {
      const SensorState& state = State(sensor);
      const std::string ours = state.strategy.ToString();
      // A file without the field was written by an encoder that always ran the trunk's
      // own meta-SGD steps.
      const std::string theirs =
          checkpoint.fit_strategy(sensor).empty()
              ? "meta_sgd:" + std::to_string(state.trunk->meta_sgd.inner_steps)
              : checkpoint.fit_strategy(sensor);
      if (theirs != ours) {
        throw std::invalid_argument(
            "LatentEncoder: the checkpoint " + options_.checkpoint_path + " fitted its " +
            ToString(sensor) + " latents with strategy '" + theirs + "', this run with '" + ours +
            "'; resume with the strategy of the interrupted run (or another output)");
      }
      const std::string products = ProductPrecisionName(GetProductPrecision());
      if (checkpoint.products(sensor) != products) {
        throw std::invalid_argument(
            "LatentEncoder: the checkpoint " + options_.checkpoint_path + " fitted its " +
            ToString(sensor) + " latents with " + checkpoint.products(sensor) +
            " products, this run with " + products +
            "; resume with the --products of the interrupted run (or another output)");
      }
      if ((checkpoint.rest_latent(sensor) != nullptr) != options_.share_rest_latent) {
        throw std::invalid_argument(
            "LatentEncoder: the checkpoint " + options_.checkpoint_path + " was written " +
            (options_.share_rest_latent ? "without" : "with") + " a shared rest latent for " +
            ToString(sensor) + ", this run " + (options_.share_rest_latent ? "with" : "without") +
            " one; resume with the choice of the interrupted run (or another output)");
      }
    }
    std::size_t matched = 0;
    for (Job& job : jobs) {
      const auto found = checkpoint.Find(job.sensor, job.entry.id);
      if (!found) continue;
      ++matched;
      const FunctasetEntry& stored = checkpoint.entries(job.sensor)[*found];
      job.entry.latent = stored.latent;
      job.entry.psnr = stored.psnr;
      job.entry.at_rest = stored.at_rest;
      job.done = true;
      ++s.frames_resumed;
    }
    // Resuming with another selection would drop finished work from the file.
    if (matched != checkpoint.size()) {
      std::string example;
      for (SensorKind sensor : checkpoint.sensors()) {
        for (const FunctasetEntry& e : checkpoint.entries(sensor)) {
          const bool selected = std::any_of(jobs.begin(), jobs.end(), [&](const Job& job) {
            return job.sensor == sensor && job.entry.id == e.id;
          });
          if (!selected && example.empty()) example = e.id + " (" + ToString(sensor) + ")";
        }
      }
      throw std::invalid_argument(
          "LatentEncoder: the checkpoint " + options_.checkpoint_path + " holds " +
          std::to_string(checkpoint.size() - matched) +
          " frame(s) that are not among the frames selected from " + dataset.root() + ", e.g. " +
          example +
          "; resume with the sensors and split of the interrupted run (or another output)");
    }
  }

  if (options_.resume && group.size() > 1) {
    // Rank 0 read the checkpoint; the other processes take its finished frames from it.
    ByteWriter finished;
    if (group.rank() == 0) {
      std::vector<std::size_t> indices;
      for (std::size_t j = 0; j < jobs.size(); ++j) {
        if (jobs[j].done) indices.push_back(j);
      }
      PackJobs(jobs, indices, &finished);
    }
    group.Broadcast(&finished.bytes());
    if (group.rank() != 0) {
      ByteReader reader(finished.bytes());
      for (std::size_t j : UnpackJobs(reader, &jobs)) {
        jobs[j].done = true;
        ++s.frames_resumed;
      }
    }
  }

  std::vector<std::size_t> pending;
  for (std::size_t j = 0; j < jobs.size(); ++j) {
    if (!jobs[j].done) pending.push_back(j);
  }
  if (group.size() > 1) {
    // The rounds below are collectives: every process must list the same frames and the
    // same pending ones, or one would wait for the others forever.
    ByteWriter work;
    work.Put<std::uint64_t>(jobs.size());
    work.Put<std::uint64_t>(pending.size());
    std::uint64_t fingerprint = 1469598103934665603ull;  // FNV-1a of the ids and sensors
    for (const Job& job : jobs) {
      for (char ch : job.entry.id + ToString(job.sensor) + "\n") {
        fingerprint = (fingerprint ^ static_cast<unsigned char>(ch)) * 1099511628211ull;
      }
    }
    work.Put(fingerprint);
    const std::vector<Bytes> all = group.AllGather(work.bytes());
    for (int rank = 1; rank < group.size(); ++rank) {
      if (all[rank] == all[0]) continue;
      ByteReader theirs(all[rank]), first(all[0]);
      const auto frames = theirs.Get<std::uint64_t>(), pending_there = theirs.Get<std::uint64_t>();
      const auto frames_0 = first.Get<std::uint64_t>(), pending_0 = first.Get<std::uint64_t>();
      throw std::runtime_error(
          "LatentEncoder: process " + std::to_string(rank) + " selected " +
          std::to_string(frames) + " frames (" + std::to_string(pending_there) +
          " to encode), process 0 " + std::to_string(frames_0) + " (" +
          std::to_string(pending_0) + ")" + (frames == frames_0 ? " with other ids" : "") +
          ": every process must read the same dataset " + dataset.root() + " and options");
    }
  }

  // Builds the functaset of the finished jobs (called with every worker joined).
  auto collect = [&](bool complete) {
    Functaset out(model_.checksum(), dataset.root());
    out.set_complete(complete);
    out.set_tool_symmetries(dataset.tool_symmetries());
    // A partial file keeps b-bit latents as float32: resuming re-quantises nothing (the
    // grid depends on all of the sensor's entries).
    out.set_latent_precision(!complete && IsQuantised(options_.latent_precision)
                                 ? Functaset::LatentPrecision::kFloat32
                                 : options_.latent_precision);
    out.set_latent_bytes(options_.latent_bytes);
    for (SensorKind sensor : sensors) {
      out.AddSensor(sensor, TrunkLatentDim(model_.Trunk(sensor)));
      out.set_fit_strategy(sensor, State(sensor).strategy.ToString());
      out.set_products(sensor, ProductPrecisionName(GetProductPrecision()));
      if (options_.share_rest_latent) out.set_rest_latent(sensor, State(sensor).rest_latent);
    }
    for (const Job& job : jobs) {
      if (job.done) out.Add(job.sensor, job.entry);
    }
    return out;
  };
  auto write_checkpoint = [&](const Functaset& functaset) {
    if (options_.checkpoint_path.empty()) return;
    functaset.Save(options_.checkpoint_path);
    ++s.checkpoints_written;
  };

  // ---- Rounds of workers ---------------------------------------------------------------
  // The pending frames are encoded in rounds of checkpoint_every frames (one round
  // without checkpoints). In a round, process r of n encodes every n-th frame from the
  // r-th on `threads` workers; at its end the processes exchange what they encoded and
  // whether one was interrupted or failed, so every process holds the same entries, and
  // rank 0 writes the checkpoint.
  const bool periodic = options_.checkpoint_every > 0 && !options_.checkpoint_path.empty();
  const std::size_t round_size =
      periodic ? static_cast<std::size_t>(options_.checkpoint_every) : pending.size();
  std::mutex mutex;
  std::condition_variable wake;
  std::exception_ptr failure;
  std::string remote_failure;  // another process's error
  std::int64_t done = s.frames_resumed;
  std::int64_t encoded = 0;
  double psnr_sum = 0;
  std::int64_t psnr_count = 0;
  // Counts a finished job (callers hold `mutex` or have joined the workers).
  auto finish = [&](Job& job) {
    job.done = true;
    ++done;
    ++encoded;
    if (std::isfinite(job.entry.psnr)) {
      psnr_sum += job.entry.psnr;
      ++psnr_count;
    }
  };
  for (const Job& job : jobs) {
    if (job.done && std::isfinite(job.entry.psnr)) {
      psnr_sum += job.entry.psnr;
      ++psnr_count;
    }
  }
  // A photometric trunk draws each frame against its own reference (its clip's).
  std::map<SensorKind, DatasetMarkers> frame_markers;
  for (const SensorState& state : states_) {
    if (state.trunk->photometric != nullptr) {
      frame_markers.emplace(std::piecewise_construct, std::forward_as_tuple(state.sensor),
                            std::forward_as_tuple(dataset, *state.trunk));
    }
  }
  auto markers_of = [&](const Job& job) -> const PhotometricTrunk::Markers* {
    const auto own = frame_markers.find(job.sensor);
    return own == frame_markers.end() ? nullptr : own->second.Of(job.frame);
  };
  auto interrupted = [&]() { return interrupt != nullptr && interrupt->load(); };
  auto last_report = std::chrono::steady_clock::now() - std::chrono::seconds(1);

  for (std::size_t round_begin = 0; round_begin < pending.size(); round_begin += round_size) {
    const std::size_t round_end = std::min(pending.size(), round_begin + round_size);
    std::vector<std::size_t> mine;  // job indices
    for (std::size_t p = round_begin + group.rank(); p < round_end; p += group.size()) {
      mine.push_back(pending[p]);
    }
    const std::int64_t done_before = done;
    std::int64_t mine_done = 0;
    std::atomic<std::size_t> next{0};
    std::atomic<bool> stop{false};
    int running = 0;
    auto work = [&]() {
      for (;;) {
        if (stop.load() || interrupted()) break;
        const std::size_t p = next.fetch_add(1);
        if (p >= mine.size()) break;
        Job& job = jobs[mine[p]];
        try {
          // With share_rest_latent the raw frame is also tested for contact: decoded once.
          const Image frame = dataset.LoadFrame(job.frame);
          const TrunkTargets targets =
              DatasetFrameTargets(dataset, job.frame, frame, model_.Trunk(job.sensor).format);
          if (options_.share_rest_latent &&
              !DetectFrameContact(dataset, job.frame, frame, options_.contact).contact) {
            const SensorState& state = State(job.sensor);
            job.entry.at_rest = true;
            job.entry.latent = state.rest_latent;
            job.entry.psnr = static_cast<float>(
                Psnr(TrunkDecode(*state.trunk, state.rest_latent, markers_of(job)), targets));
          } else {
            EncodedFrame frame = EncodeTargetsImpl(job.sensor, targets, markers_of(job), true);
            job.entry.latent = std::move(frame.latent);
            job.entry.psnr = static_cast<float>(frame.psnr);
          }
        } catch (...) {
          std::lock_guard<std::mutex> lock(mutex);
          if (!failure) failure = std::current_exception();
          stop = true;
          break;
        }
        std::lock_guard<std::mutex> lock(mutex);
        finish(job);
        ++mine_done;
        wake.notify_one();
      }
      std::lock_guard<std::mutex> lock(mutex);
      --running;
      wake.notify_one();
    };

    const int num_threads = static_cast<int>(
        std::min<std::size_t>(options_.threads, std::max<std::size_t>(mine.size(), 1)));
    std::vector<std::thread> workers;
    running = num_threads;
    for (int t = 0; t < num_threads; ++t) workers.emplace_back(work);
    {
      std::unique_lock<std::mutex> lock(mutex);
      while (running > 0) {
        wake.wait_for(lock, std::chrono::milliseconds(100));
        const auto now = std::chrono::steady_clock::now();
        if (progress && now - last_report >= std::chrono::milliseconds(100)) {
          // The other processes' frames of this round are known only at its end; until
          // then they are taken to go as fast as this process's.
          const std::int64_t estimate =
              done_before + std::min<std::int64_t>(mine_done * group.size(),
                                                   static_cast<std::int64_t>(round_end - round_begin));
          const EncodeProgress report{estimate, s.frames_total,
                                      psnr_count > 0 ? psnr_sum / psnr_count : 0.0};
          lock.unlock();
          progress(report);
          lock.lock();
          last_report = now;
        }
      }
    }
    for (std::thread& worker : workers) worker.join();

    bool stopped = interrupted();
    if (group.size() > 1) {
      ByteWriter message;
      message.Put<std::uint8_t>(stopped ? 1 : 0);
      message.PutString(failure ? ExceptionText(failure) : std::string());
      std::vector<std::size_t> finished;
      for (std::size_t j : mine) {
        if (jobs[j].done) finished.push_back(j);
      }
      PackJobs(jobs, finished, &message);
      const std::vector<Bytes> all = group.AllGather(message.bytes());
      for (int rank = 0; rank < group.size(); ++rank) {
        if (rank == group.rank()) continue;
        ByteReader reader(all[rank]);
        stopped = reader.Get<std::uint8_t>() != 0 || stopped;
        const std::string error = reader.GetString();
        if (!error.empty() && !failure && remote_failure.empty()) {
          remote_failure = error + " (in process " + std::to_string(rank) + " of " +
                           std::to_string(group.size()) + ")";
        }
        for (std::size_t j : UnpackJobs(reader, &jobs)) finish(jobs[j]);
      }
    }
    if (failure || !remote_failure.empty() || stopped) break;
    if (periodic && round_end < pending.size()) write_checkpoint(collect(false));
  }

  const bool complete = done == s.frames_total;
  Functaset result = collect(complete);
  if (failure || !remote_failure.empty()) {
    if (encoded > 0) write_checkpoint(result);
    if (failure) std::rethrow_exception(failure);
    throw std::runtime_error(remote_failure);
  }
  write_checkpoint(result);

  s.frames_encoded = encoded;
  s.termination = complete ? EncodeTermination::kComplete : EncodeTermination::kInterrupted;
  s.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  s.frames_per_second = s.seconds > 0 ? encoded / s.seconds : 0.0;
  for (SensorKind sensor : sensors) {
    std::vector<double> psnr;
    for (const FunctasetEntry& e : result.entries(sensor)) {
      psnr.push_back(e.psnr);
      if (!e.latent.allFinite()) ++s.non_finite_latents;
    }
    s.frames[sensor] = static_cast<std::int64_t>(psnr.size());
    if (!psnr.empty()) s.mean_psnr[sensor] = MeanFinite(psnr);
  }
  std::ostringstream message;
  if (complete) {
    message << "encoded " << s.frames_total << " frames";
  } else {
    message << "interrupted after " << done << " of " << s.frames_total << " frames";
    if (!options_.checkpoint_path.empty()) {
      message << "; the partial functaset is in " << options_.checkpoint_path
              << " (resume continues it)";
    }
  }
  if (s.non_finite_latents > 0) {
    message << "; " << s.non_finite_latents
            << " latent(s) are not finite (are the meta-SGD rates alpha too large?)";
  }
  s.message = message.str();
  if (progress)
    progress(EncodeProgress{done, s.frames_total, psnr_count > 0 ? psnr_sum / psnr_count : 0.0});
  return result;
}

}  // namespace tactfunc
