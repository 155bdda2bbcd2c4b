// Copyright 2026 The tactfunc Authors.
#include "estimation/functaset/latent_refit.h"

#include <algorithm>
#include <chrono>
#include <filesystem>
#include <stdexcept>
#include <vector>

#include "estimation/data/image_io.h"
#include "estimation/data/trunk_targets.h"
#include "estimation/training/internal/checkpoint.h"
#include "models/core/parallel_for.h"
#include "models/core/tensor_file.h"
#include "nlohmann/json.hpp"

namespace tactfunc {
namespace {

// Entries fitted between two looks at `progress`: enough to keep every thread busy, few
// enough that a stop comes within seconds.
constexpr int kBlockPerThread = 16;

// The functaset entries the run starts from: ids, labels and latents.
std::uint64_t EntriesFingerprint(const std::vector<FunctasetEntry>& entries) {
  std::uint64_t hash = internal::Fnv1a(nullptr, 0);
  for (const FunctasetEntry& e : entries) {
    hash = internal::Fnv1a(e.id.data(), e.id.size(), hash);
    const char labelled = e.label.has_value() ? 1 : 0;
    hash = internal::Fnv1a(&labelled, 1, hash);
    if (e.label.has_value()) {
      const double pose[4] = {e.label->sensor_T_object.x(), e.label->sensor_T_object.y(),
                              e.label->sensor_T_object.yaw(), e.label->depth_m};
      hash = internal::Fnv1a(pose, sizeof(pose), hash);
      hash = internal::Fnv1a(e.label->tool.data(), e.label->tool.size(), hash);
    }
    hash = internal::Fnv1a(e.latent.data(), sizeof(float) * e.latent.size(), hash);
  }
  return hash;
}

}  // namespace

bool RefitOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& message) {
    if (error != nullptr) *error = message;
    return false;
  };
  std::string why;
  if (!fit.IsValid(&why)) return fail("RefitOptions::fit: " + why);
  if (fit.strategy.knn) {
    return fail("RefitOptions::fit.strategy: expected meta_sgd:K or ceres:N, got " +
                fit.strategy.ToString());
  }
  if (!problem.IsValid(&why)) return fail("RefitOptions::problem: " + why);
  if (threads < 1) {
    return fail("RefitOptions::threads: expected >= 1, got " + std::to_string(threads));
  }
  if (checkpoint_every < 1) {
    return fail("RefitOptions::checkpoint_every: expected >= 1, got " +
                std::to_string(checkpoint_every));
  }
  if (resume && checkpoint_path.empty()) {
    return fail("RefitOptions::resume: needs a checkpoint_path");
  }
  return true;
}

Functaset RefitLatents(const Functaset& functaset, SensorKind sensor, const Dataset& dataset,
                       const SensorTrunk& trunk, const RefitOptions& options, RefitSummary* summary,
                       const RefitProgress& progress) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument("RefitLatents: " + error);
  if (!functaset.has_sensor(sensor)) {
    throw std::invalid_argument(std::string("RefitLatents: the functaset has no ") +
                                ToString(sensor) + " latents");
  }
  if (trunk.photometric != nullptr) {
    throw std::invalid_argument(std::string("RefitLatents: the ") + ToString(sensor) +
                                " trunk is photometric; its latents are encode's fits");
  }
  const auto start = std::chrono::steady_clock::now();
  const std::vector<FunctasetEntry>& entries = functaset.entries(sensor);
  const int n = static_cast<int>(entries.size());
  const int d = functaset.latent_dim(sensor);
  std::vector<std::size_t> frame_of(entries.size(), 0);
  for (int i = 0; i < n; ++i) {
    if (!entries[i].label.has_value()) continue;
    const std::optional<std::size_t> index = dataset.FindFrame(entries[i].id, sensor);
    if (!index) {
      throw DatasetError("the dataset has no " + std::string(ToString(sensor)) + " frame '" +
                         entries[i].id + "' of the functaset");
    }
    frame_of[i] = *index;
  }

  internal::CheckpointRun run;
  run.format = "tactfunc-refit-checkpoint";
  run.version = 1;
  run.sensor = ToString(sensor);
  // What shapes a latent: the fit's strategy, the problem's options and the trunk.
  const LatentProblem::Options& p = options.problem;
  run.options_json =
      nlohmann::json{{"strategy", options.fit.strategy.ToString()},
                     {"sigma", p.sigma},
                     {"sigma_z", p.sigma_z},
                     {"robust_loss", static_cast<int>(p.robust_loss)},
                     {"robust_loss_scale", p.robust_loss_scale},
                     {"pixel_stride", p.pixel_stride},
                     {"max_pixels", p.max_pixels},
                     {"contact_share", p.contact_share},
                     {"precision", p.precision == LatentProblem::Precision::kFloat ? "float"
                                                                                   : "double"},
                     {"model_checksum", options.model_checksum}}
          .dump();
  run.fingerprint = EntriesFingerprint(entries);
  run.num_frames = n;

  std::vector<Eigen::VectorXf> latents(entries.size());
  RefitSummary s;
  s.entries = n;
  double seconds_before = 0;
  const std::string& path = options.checkpoint_path;
  if (options.resume && std::filesystem::exists(path)) {
    nlohmann::json meta;
    const TensorFile file = internal::ReadCheckpoint(path, run, &meta);
    const int held = meta.at("step").get<int>();
    if (held < 0 || held > n) {
      throw std::runtime_error("checkpoint " + path + ": meta.step " + std::to_string(held) +
                               " is outside [0, " + std::to_string(n) + "] entries");
    }
    const Eigen::VectorXd values =
        internal::CheckpointVector(file, "latents", static_cast<std::int64_t>(held) * d);
    for (int i = 0; i < held; ++i) {
      if (entries[i].label.has_value()) latents[i] = values.segment(i * d, d).cast<float>();
    }
    seconds_before = meta.at("train_seconds").get<double>();
    s.resumed = s.done = held;
    // Report the entries taken; a stop asked for now comes after the next block.
    if (progress) progress(s.done, n);
  }
  auto elapsed = [&] {
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  };
  auto write_checkpoint = [&](int done) {
    if (path.empty()) return;
    TensorFile file = internal::NewCheckpoint(run, done, seconds_before + elapsed());
    std::vector<double> values(static_cast<std::size_t>(done) * d, 0.0);
    for (int i = 0; i < done; ++i) {
      if (!entries[i].label.has_value()) continue;
      for (int k = 0; k < d; ++k) values[static_cast<std::size_t>(i) * d + k] = latents[i][k];
    }
    file.Add("latents", TensorFile::DType::kFloat64, {static_cast<std::int64_t>(values.size())},
             values);
    file.Write(path);
  };

  const LatentFitter fitter(trunk, options.fit);
  const int block = kBlockPerThread * options.threads;
  int since_checkpoint = 0;
  while (s.done < n) {
    const int begin = s.done;
    const int end = std::min(n, begin + block);
    // Fits are independent and LatentFitter::Fit is const.
    internal::ParallelFor(end - begin, options.threads, [&](int k) {
      const int i = begin + k;
      if (!entries[i].label.has_value()) return;
      const TrunkTargets targets = LoadTrunkTargets(dataset, frame_of[i], trunk.format);
      Eigen::VectorXd latent;
      fitter.Fit(LatentProblem(trunk, targets, options.problem), &latent);
      latents[i] = latent.cast<float>();
    });
    for (int i = begin; i < end; ++i) s.fitted += entries[i].label.has_value() ? 1 : 0;
    s.done = end;
    since_checkpoint += end - begin;
    const bool go_on = !progress || progress(s.done, n);
    if (!go_on && s.done < n) {
      write_checkpoint(s.done);
      s.stopped = true;
      break;
    }
    if (since_checkpoint >= options.checkpoint_every && s.done < n) {
      write_checkpoint(s.done);
      since_checkpoint = 0;
    }
  }
  // Complete: kept (until the caller removes it) so that a later stage stopped by the
  // user resumes without fitting again.
  if (!s.stopped && s.done > s.resumed) write_checkpoint(n);

  Functaset refitted(functaset.model_checksum(), functaset.dataset());
  refitted.AddSensor(sensor, d);
  for (int i = 0; i < s.done; ++i) {
    FunctasetEntry entry = entries[i];
    if (entry.label.has_value()) entry.latent = latents[i];
    refitted.Add(sensor, std::move(entry));
  }
  s.seconds = elapsed();
  if (summary != nullptr) *summary = s;
  return refitted;
}

}  // namespace tactfunc
