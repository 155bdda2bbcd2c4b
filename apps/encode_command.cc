// Copyright 2026 The tactfunc Authors.
//
// tactfunc encode: a dataset -> its functaset under a trained model (one latent per
// frame, estimation/functaset/latent_encoder.h; file format in docs/FUNCTASET.md).
//
// The --out file doubles as the checkpoint: every --checkpoint-every frames a partial
// functaset ("complete": false) is written there atomically. Ctrl-C (SIGINT) lets the
// workers finish the frames in hand, writes the partial file and says how to resume;
// a second Ctrl-C kills the program at once (the last checkpoint stays intact).

#include <algorithm>
#include <csignal>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <sstream>
#include <thread>

#include "CLI/CLI.hpp"
#include "apps/command.h"
#include "apps/dataset_flags.h"
#include "apps/distributed.h"
#include "apps/interrupt.h"
#include "apps/output_paths.h"
#include "apps/model_inputs.h"
#include "apps/progress_bar.h"
#include "estimation/data/dataset.h"
#include "estimation/functaset/functaset.h"
#include "estimation/functaset/latent_codes.h"
#include "estimation/functaset/latent_encoder.h"
#include "models/trunk/functa_model.h"
#include "models/core/atomic_file.h"
#include "models/core/tensor_file.h"

namespace tactfunc::apps {
namespace {

struct EncodeFlags {
  std::string model;
  std::string data;
  std::string out;
  int threads = 0;
  std::string products = "float";
  int checkpoint_every = 500;
  bool resume = false;
  std::string sensors;
  std::string split;
  std::string latent_precision = "float16";
  int latent_bytes = 0;  // > 0: allocated codes of this many bytes per frame
  std::string strategy;  // "" = each trunk's meta_sgd:K
  bool json = false;
  bool allow_other_frames = false;
  bool share_rest = false;
  DatasetFlags dataset;
};

// The command line that continues an interrupted run: the flags that select frames and
// shape the run, plus --resume.
std::string ResumeCommand(const EncodeFlags& flags) {
  std::string command =
      "tactfunc encode --model " + flags.model + " --data " + flags.data + " --out " + flags.out;
  if (!flags.sensors.empty()) command += " --sensors " + flags.sensors;
  if (!flags.split.empty()) command += " --split " + flags.split;
  if (!flags.strategy.empty()) command += " --strategy " + flags.strategy;
  if (flags.threads > 0) command += " --threads " + std::to_string(flags.threads);
  if (flags.products != "float") command += " --products " + flags.products;
  if (flags.allow_other_frames) command += " --allow-other-frames";
  if (flags.share_rest) command += " --share-rest";
  if (flags.latent_bytes > 0) {
    command += " --latent-bytes " + std::to_string(flags.latent_bytes);
  } else if (flags.latent_precision != "float16") {
    command += " --latent-precision " + flags.latent_precision;
  }
  if (!flags.dataset.sensor.empty()) command += " --sensor " + flags.dataset.sensor;
  if (!flags.dataset.reference.empty()) command += " --reference " + flags.dataset.reference;
  if (!flags.dataset.labels.empty()) command += " --labels " + flags.dataset.labels;
  if (!flags.dataset.tools.empty()) command += " --tool-symmetry " + flags.dataset.tools;
  if (flags.dataset.reference_index != 0) {
    command += " --reference-index " + std::to_string(flags.dataset.reference_index);
  }
  if (flags.dataset.pixel_pitch_mm != 0) {
    std::ostringstream pitch;
    pitch << flags.dataset.pixel_pitch_mm;
    command += " --pixel-pitch-mm " + pitch.str();
  }
  return command + " --resume";
}

// After a failed encode: tells on stderr whether --out holds a partial functaset (this
// run's checkpoint, or an earlier one) and how to continue or discard it.
void PartialOutputNote(const EncodeFlags& flags, bool existed_before) {
  std::error_code ec;
  if (!std::filesystem::exists(flags.out, ec)) {
    std::cerr << "encode: nothing was written to " << flags.out << "\n";
    return;
  }
  try {
    const Functaset partial = Functaset::Load(flags.out);
    if (partial.complete()) {
      std::cerr << "encode: " << flags.out << " is unchanged (a complete functaset from "
                << "an earlier run)\n";
      return;
    }
    std::cerr << "encode: " << flags.out << " holds a PARTIAL functaset of " << partial.size()
              << " frames" << (existed_before ? "" : " written by this run")
              << "; after fixing the cause, continue it with:\n  " << ResumeCommand(flags)
              << "\nor delete it to start over\n";
  } catch (const std::exception&) {
    if (!existed_before) {
      std::cerr << "encode: " << flags.out << " exists but is not a readable functaset\n";
    }
  }
}

void RunEncode(const EncodeFlags& flags) {
  // --out doubles as the checkpoint: it must not be the model or any dataset file.
  const std::vector<NamedPath> outputs = {{"--out", flags.out}};
  std::vector<NamedPath> inputs = DatasetPathInputs("--data", flags.data, flags.dataset);
  inputs.push_back({"--model", flags.model});
  RefuseOutputsThatAreInputs(outputs, inputs);
  const ProcessGroup& processes = Processes();
  // Left by an earlier run killed mid-write; rank 0 is the one process that writes.
  if (processes.rank() == 0) RemoveStaleTemporaries(flags.out);
  ApplyProductPrecision(flags.products);
  const FunctaModel model = FunctaModel::Load(flags.model);
  const Dataset dataset = OpenDataset(flags.data, flags.dataset);
  RefuseOutputsThatAreInputs(outputs, DatasetFileInputs("--data", dataset));

  LatentEncoder::Options options;
  options.threads = ResolveThreads(flags.threads);
  options.checkpoint_path = flags.out;
  options.checkpoint_every = flags.checkpoint_every;
  options.resume = flags.resume;
  options.processes = &processes;
  options.sensors = ParseSensorsFlag(flags.sensors);
  if (!flags.split.empty()) {
    Split split;
    if (!SplitFromString(flags.split, &split)) {
      throw UsageError("--split: expected train or test, got '" + flags.split + "'");
    }
    options.split = split;
  }
  if (!LatentPrecisionFromString(flags.latent_precision, &options.latent_precision)) {
    throw UsageError("--latent-precision: expected float32, float16, uint8, uint6 or uint4, got '" +
                     flags.latent_precision + "'");
  }
  if (flags.latent_bytes > 0) {
    options.latent_precision = Functaset::LatentPrecision::kAllocated;
    options.latent_bytes = flags.latent_bytes;
  }
  options.strategy = flags.strategy;
  options.share_rest_latent = flags.share_rest;
  if (std::string error; !options.IsValid(&error)) throw UsageError("--strategy: " + error);

  // Never silently throw away a partial run.
  const bool out_exists = std::filesystem::exists(flags.out);
  if (out_exists && !flags.resume) {
    bool partial = false;
    std::size_t frames = 0;
    try {
      const Functaset existing = Functaset::Load(flags.out);
      partial = !existing.complete();
      frames = existing.size();
    } catch (const std::exception&) {
      // Not a readable functaset: it is replaced like any other output file.
    }
    if (partial) {
      throw UsageError(flags.out + " holds a partial functaset (" + std::to_string(frames) +
                       " frames): pass --resume to continue it, or delete it to start over");
    }
  }
  if (flags.resume && !out_exists) {
    std::cerr << "encode: " << flags.out << " does not exist yet; starting from the first frame\n";
  }
  const std::filesystem::path parent = std::filesystem::path(flags.out).parent_path();
  if (!parent.empty()) std::filesystem::create_directories(parent);

  // The model against the data: frames of another sensor description, size or channel
  // count than the trunk was trained on are refused (--allow-other-frames: a warning); a
  // stretch to the working resolution is said.
  for (SensorKind sensor : options.sensors.empty() ? dataset.sensors() : options.sensors) {
    if (!model.HasSensor(sensor) || !dataset.has_sensor(sensor)) continue;
    CheckModelMatchesData(model, flags.model, dataset, flags.data, sensor, "encode",
                          "--allow-other-frames", flags.allow_other_frames);
    const int d = TrunkLatentDim(model.Trunk(sensor));
    if (flags.latent_bytes > MaxCodeBytes(d)) {
      throw UsageError("--latent-bytes: " + std::to_string(flags.latent_bytes) + " bytes for " +
                       ToString(sensor) + " latents of " + std::to_string(d) + " values in " +
                       flags.model + ", expected at most " + std::to_string(MaxCodeBytes(d)) +
                       " (" + std::to_string(kMaxCodeBits) + " bits per value)");
    }
    const FrameFormat& format = model.Trunk(sensor).format;
    WarnIfStretched(dataset, flags.data, sensor, format.rows, format.cols, "encode");
  }

  const LatentEncoder encoder(model, options);
  std::int64_t total = 0;
  for (SensorKind sensor : options.sensors.empty() ? dataset.sensors() : options.sensors) {
    if (model.HasSensor(sensor) && dataset.has_sensor(sensor)) {
      total += static_cast<std::int64_t>(dataset.FrameIndices(sensor, options.split).size());
    }
  }
  ProgressBar bar("encode", total, "frames", ProgressBar::Lines::kWhenNotDrawn);
  std::int64_t shown = 0;
  auto progress = [&](const EncodeProgress& p) {
    if (p.done > shown) {
      bar.Tick(p.done - shown);
      shown = p.done;
    }
    if (p.done > 0) bar.SetStatus("psnr " + FormatFixed(p.mean_psnr, 2) + " dB");
  };

  LatentEncoder::Summary summary;
  Functaset functaset;
  try {
    InterruptScope scope;
    functaset = encoder.Encode(dataset, &summary, progress, &InterruptScope::Flag());
  } catch (const std::exception&) {
    bar.Finish();
    // Never leave a partial output unannounced: say what --out holds now.
    PartialOutputNote(flags, out_exists);
    throw;
  }
  bar.Finish();

  std::cout << "encode: " << (functaset.complete() ? "wrote " : "wrote a PARTIAL functaset of ")
            << functaset.size() << " frames to " << flags.out << " (" << summary.frames_encoded
            << " encoded in " << FormatFixed(summary.seconds, 2) << " s, "
            << FormatFixed(summary.frames_per_second, 1) << " frames/s on "
            << (processes.size() > 1 ? std::to_string(processes.size()) + " processes x " : "")
            << options.threads << " thread(s)";
  if (summary.frames_resumed > 0) std::cout << ", " << summary.frames_resumed << " resumed";
  std::cout << ")\n";
  nlohmann::json at_rest = nlohmann::json::object();
  for (SensorKind sensor : functaset.sensors()) {
    const std::int64_t rest = static_cast<std::int64_t>(functaset.entries(sensor).size()) -
                              functaset.NumStoredLatents(sensor);
    at_rest[ToString(sensor)] = rest;
  }
  for (const auto& [sensor, psnr] : summary.mean_psnr) {
    std::cout << "  " << ToString(sensor) << ": " << summary.frames.at(sensor)
              << " frames, mean PSNR " << FormatFixed(psnr, 2)
              << " dB (against the noisy frames), fit " << functaset.fit_strategy(sensor);
    if (flags.share_rest) {
      std::cout << "; " << at_rest[ToString(sensor)].get<std::int64_t>()
                << " at rest share one latent";
    }
    std::cout << "\n";
  }
  if (summary.non_finite_latents > 0) std::cout << "  warning: " << summary.message << "\n";

  if (flags.json) {
    nlohmann::json psnr = nlohmann::json::object(), strategy = nlohmann::json::object();
    for (const auto& [sensor, value] : summary.mean_psnr) psnr[ToString(sensor)] = value;
    for (SensorKind sensor : functaset.sensors()) {
      strategy[ToString(sensor)] = functaset.fit_strategy(sensor);
    }
    EmitJson({{"frames", functaset.size()},
              {"frames_encoded", summary.frames_encoded},
              {"frames_resumed", summary.frames_resumed},
              {"complete", functaset.complete()},
              {"seconds", summary.seconds},
              {"frames_per_s", summary.frames_per_second},
              {"threads", options.threads},
              {"processes", processes.size()},
              {"psnr_mean", psnr},
              {"fit_strategy", strategy},
              {"frames_at_rest", at_rest},
              {"model_checksum", model.checksum()},
              {"out", flags.out}});
  }
  if (summary.termination == EncodeTermination::kInterrupted) {
    std::cerr << "encode: interrupted after " << functaset.size() << " of " << summary.frames_total
              << " frames; the partial functaset is in " << flags.out
              << ".\nencode: to continue, run the same command with --resume:\n  "
              << ResumeCommand(flags) << "\n";
    ExitInterrupted();
  }
}

}  // namespace

void RegisterEncode(CLI::App& app, CommandBody* selected) {
  auto flags = std::make_shared<EncodeFlags>();
  CLI::App* sub = app.add_subcommand(
      "encode",
      "Encode every frame of a dataset as one latent under a trained model: the "
      "functaset (docs/FUNCTASET.md). Ctrl-C stops cleanly; --resume continues.");
  sub->add_option("--model", flags->model, "Model file (.tfm) from `tactfunc train`")->required();
  sub->add_option("--data", flags->data, "Dataset folder or video")->required();
  sub->add_option("--out", flags->out,
                  "Functaset file to write (.tfs); also the checkpoint of a partial run")
      ->required();
  AddProductPrecisionFlag(sub, &flags->products);
  sub->add_option("--threads", flags->threads, "Worker threads (default: all cores)")
      ->check(CLI::Range(0, 256));
  sub->add_option("--checkpoint-every", flags->checkpoint_every,
                  "Write the partial functaset to --out every N frames (0 = only at the end "
                  "or on Ctrl-C)")
      ->check(CLI::Range(0, 100000000));
  sub->add_flag("--resume", flags->resume,
                "Continue the partial functaset in --out (same model required)");
  sub->add_option("--sensors", flags->sensors,
                  "Comma-separated sensors to encode (default: every sensor of the dataset "
                  "that the model has a trunk for)");
  sub->add_option("--split", flags->split, "Only frames of this split: train or test");
  sub->add_option("--latent-precision", flags->latent_precision,
                  "Storage of the latents: float16 (default: half the bytes, no measurable PSNR "
                  "cost, docs/RESULTS_RECONSTRUCTION.md), float32, or uint8 / uint6 / uint4: "
                  "8-, 6- or 4-bit codes on a uniform grid per sensor and latent dimension "
                  "between its min and max over the frames (ceil(d b / 8) bytes per frame plus "
                  "2 x d float32 per sensor; docs/FUNCTASET.md, \"Latent precision\")")
      ->check(CLI::IsMember({"float32", "float16", "uint8", "uint6", "uint4"}));
  sub->add_option("--latent-bytes", flags->latent_bytes,
                  "Store each frame's latent in exactly N bytes: the N x 8 bits go one at a time "
                  "to the latent dimension whose squared error over the frames drops most, each "
                  "dimension on its least-squares grid (0-16 bits; per sensor d bytes of bits "
                  "and 2 x d float32; docs/FUNCTASET.md, \"Allocated codes\"). Instead of "
                  "--latent-precision")
      ->check(CLI::Range(1, 1 << 20))
      ->excludes("--latent-precision");
  sub->add_option("--strategy", flags->strategy,
                  "How each frame's latent is fitted: meta_sgd:K or ceres:N (default: the "
                  "trunk's own meta_sgd:K, what it was trained for; ceres:N fits the latent "
                  "problem to convergence, docs/FITTING.md); a photometric trunk (train "
                  "--head photometric): knn+adam:N, N Adam steps from the best of the "
                  "model's training latents, 64 pixels a step, half of them drawn towards "
                  "the contact (default " +
                      LatentEncoder::DefaultPhotometricStrategy(true, 64) +
                      " for a latent of 64 values, in proportion for longer ones, where the "
                      "model holds that table), knn+ceres:N, at most N "
                      "Levenberg-Marquardt iterations in Ceres on every valid pixel from that "
                      "latent (slower, closer to convergence), knn (that latent as it is), or "
                      "adam:N, N steps from the contact's moment pose and its turn by pi "
                      "(default " +
                      LatentEncoder::DefaultPhotometricStrategy(false, 64) + " without a table)");
  sub->add_flag("--allow-other-frames", flags->allow_other_frames,
                "Encode even when the data's frames (size, channels, sensor description) are "
                "not those the model's trunk was trained on (a warning instead of an error)");
  sub->add_flag("--share-rest", flags->share_rest,
                "Frames at rest (no contact above the sensor's noise; docs/REAL_DATA.md) are "
                "not fitted: they share one latent per sensor, stored once, and cost no latent "
                "bytes");
  sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
  AddDatasetFlags(sub, &flags->dataset);
  sub->callback([flags, selected]() { *selected = [flags]() { RunEncode(*flags); }; });
}

}  // namespace tactfunc::apps
