// Copyright 2026 The tactfunc Authors.
//
// tactfunc recon: how well a functaset reproduces its dataset (PSNR per sensor and
// split against the noisy and, for simulated data, the clean frames; the z = 0
// "initial image"), its size against the raw frames, and a picture per sensor of
// examples: target | z = 0 | reconstruction | error (estimation/evaluation/reconstruction.h).
// Runs as several processes under mpirun (docs/SCALING.md): the frames are shared out,
// rank 0 writes the files, which are those of one process.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <limits>
#include <optional>
#include <thread>

#include <opencv2/imgproc.hpp>

#include "CLI/CLI.hpp"
#include "apps/command.h"
#include "apps/dataset_flags.h"
#include "apps/distributed.h"
#include "apps/model_inputs.h"
#include "apps/output_paths.h"
#include "apps/pictures.h"
#include "estimation/data/dataset.h"
#include "estimation/data/photometric_markers.h"
#include "estimation/functaset/functaset.h"
#include "estimation/evaluation/reconstruction.h"
#include "estimation/data/trunk_targets.h"
#include "models/core/atomic_file.h"
#include "models/trunk/functa_model.h"

namespace tactfunc::apps {
namespace {

struct ReconFlags {
  std::string model;
  std::string functaset;
  std::string data;
  std::string out;
  int examples = 6;
  int threads = 0;
  std::string products;  // "": as the functaset was encoded
  int tile_height = 140;
  bool worst = false;
  bool json = false;
  bool allow_other_frames = false;
  DatasetFlags dataset;
};

cv::Mat TextCell(int height, int width, const std::vector<std::string>& lines) {
  cv::Mat cell(height, width, CV_8UC3, kBackground);
  int y = 18;
  for (const std::string& line : lines) {
    PutLabel(cell, line, {6, y}, 0.42);
    y += 17;
  }
  return cell;
}

std::string Db(double value) {
  if (!std::isfinite(value)) return "n/a";
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.2f", value);
  return buffer;
}

// Up to n entries of one sensor, test split first: each split evenly spread, or, with
// `worst`, its lowest-PSNR frames first (frames without a finite PSNR last).
std::vector<const ReconstructionEvaluator::FrameResult*> PickExamples(
    const ReconstructionEvaluator::Summary& summary, SensorKind sensor, int n, bool worst) {
  std::vector<const ReconstructionEvaluator::FrameResult*> picked;
  for (Split split : {Split::kTest, Split::kTrain}) {
    std::vector<const ReconstructionEvaluator::FrameResult*> pool;
    for (const auto& r : summary.frames) {
      if (r.sensor == sensor && r.split == split) pool.push_back(&r);
    }
    const int want = std::min<int>(n - static_cast<int>(picked.size()), pool.size());
    if (worst) {
      auto key = [](const ReconstructionEvaluator::FrameResult* r) {
        return std::isfinite(r->psnr) ? r->psnr : std::numeric_limits<double>::infinity();
      };
      std::stable_sort(pool.begin(), pool.end(),
                       [&](const auto* a, const auto* b) { return key(a) < key(b); });
      picked.insert(picked.end(), pool.begin(), pool.begin() + want);
    } else {
      for (int k = 0; k < want; ++k) picked.push_back(pool[k * pool.size() / want]);
    }
  }
  return picked;
}

// Writes the picture of one sensor's examples to `path`; returns the frame ids shown,
// top to bottom.
std::vector<std::string> WriteExamples(const ReconFlags& flags, const FunctaModel& model,
                                       const Dataset& dataset,
                                       const ReconstructionEvaluator::Summary& summary,
                                       const Functaset& functaset, SensorKind sensor,
                                       const std::string& path) {
  const SensorTrunk& trunk = model.Trunk(sensor);
  const int rows = trunk.format.rows, cols = trunk.format.cols, h = flags.tile_height;
  const int w = std::max(1, static_cast<int>(std::lround(cols * double(h) / rows)));
  // A photometric trunk draws each frame against its own reference (its clip's).
  std::optional<DatasetMarkers> markers;
  if (trunk.photometric != nullptr) markers.emplace(dataset, trunk);
  struct Example {
    const ReconstructionEvaluator::FrameResult* result;
    TrunkTargets target;
    Eigen::MatrixXf recon;
    Eigen::MatrixXf zero;  // what the trunk draws for a zero latent
  };
  std::vector<Example> examples;
  double error_scale = 0;
  for (const auto* r : PickExamples(summary, sensor, flags.examples, flags.worst)) {
    const PhotometricTrunk::Markers* own = markers ? markers->Of(r->dataset_index) : nullptr;
    Example e{r, LoadTrunkTargets(dataset, r->dataset_index, trunk.format),
              Reconstruct(trunk, functaset.entries(sensor)[*functaset.Find(sensor, r->id)].latent,
                          own),
              Reconstruct(trunk, Eigen::VectorXf::Zero(TrunkLatentDim(trunk)), own)};
    for (int j = 0; j < rows * cols; ++j) {
      if (e.target.weights[j] > 0) {
        error_scale = std::max<double>(error_scale,
                                       std::abs((e.recon.row(j) - e.target.values.row(j)).mean()));
      }
    }
    examples.push_back(std::move(e));
  }
  if (examples.empty()) return {};
  if (!(error_scale > 0)) error_scale = 1.0;

  std::vector<std::vector<cv::Mat>> grid;
  char error_title[64];
  std::snprintf(error_title, sizeof(error_title), "error (+-%.3g)", error_scale);
  grid.push_back({TextCell(
      26, 170,
      {std::string(ToString(sensor)) + " " + std::to_string(rows) + "x" + std::to_string(cols) +
       (flags.worst ? " worst" : "")})});
  for (const char* title : {"target", "z = 0", "reconstruction"}) {
    grid.back().push_back(TextCell(26, w, {title}));
  }
  grid.back().push_back(TextCell(26, w, {error_title}));
  for (const Example& e : examples) {
    // Target, z = 0 and reconstruction share the target's range.
    const auto [lo, hi] = ValidValueRange(e.target);
    const auto& r = *e.result;
    std::vector<cv::Mat> row;
    row.push_back(TextCell(
        h, 170,
        {r.id + " (" + ToString(r.split) + ")", "recon " + Db(r.psnr) + " dB",
         "z=0 " + Db(r.psnr_zero) + " dB",
         std::isfinite(r.psnr_clean) ? "clean " + Db(r.psnr_clean) + " dB" : std::string()}));
    row.push_back(FitHeight(ValueTile(e.target.values, e.target.weights, rows, cols, lo, hi), h));
    row.push_back(FitHeight(ValueTile(e.zero, e.target.weights, rows, cols, lo, hi), h));
    row.push_back(FitHeight(ValueTile(e.recon, e.target.weights, rows, cols, lo, hi), h));
    row.push_back(FitHeight(ErrorTile(e.recon, e.target, error_scale), h));
    grid.push_back(std::move(row));
  }
  WritePicture(path, TileGrid(grid));
  std::vector<std::string> ids;
  for (const Example& e : examples) ids.push_back(e.result->id);
  return ids;
}

// A CSV field: as is, or in double quotes (quotes doubled) if it holds a comma, a
// quote or a line break.
std::string CsvField(const std::string& text) {
  if (text.find_first_of(",\"\r\n") == std::string::npos) return text;
  std::string quoted = "\"";
  for (char c : text) quoted += c == '"' ? std::string("\"\"") : std::string(1, c);
  return quoted + "\"";
}

std::string CsvNumber(double value) {
  if (std::isnan(value)) return "";
  if (std::isinf(value)) return value > 0 ? "inf" : "-inf";
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.9g", value);
  return buffer;
}

// One row per functaset entry, in functaset order (docs/CLI.md, "recon"). Empty fields:
// no label, no clean frame, no valid pixel.
void WritePerFrameCsv(const std::string& path, const ReconstructionEvaluator::Summary& summary,
                      const Dataset& dataset) {
  std::string text =
      "frame,sensor,split,tool,depth_m,target_range,source_range,rmse,psnr,psnr_clean,"
      "psnr_zero,psnr_source_peak,contact,contact_score,contact_row,contact_col,"
      "recon_contact_row,recon_contact_col\n";
  for (const auto& r : summary.frames) {
    const auto& label = dataset.frames()[r.dataset_index].label;
    text += CsvField(r.id) + "," + ToString(r.sensor) + "," + ToString(r.split) + "," +
            (label ? CsvField(label->tool) : std::string()) + "," +
            (label ? CsvNumber(label->depth_m) : std::string()) + "," +
            CsvNumber(r.target_range) + "," + CsvNumber(r.source_range) + "," +
            CsvNumber(r.rmse) + "," + CsvNumber(r.psnr) + "," + CsvNumber(r.psnr_clean) + "," +
            CsvNumber(r.psnr_zero) + "," + CsvNumber(r.psnr_source_peak) + "," +
            (r.contact ? "1" : "0") + "," + CsvNumber(r.contact_score) + "," +
            CsvNumber(r.contact_row) + "," + CsvNumber(r.contact_col) + "," +
            CsvNumber(r.recon_contact_row) + "," + CsvNumber(r.recon_contact_col) + "\n";
  }
  WriteFileAtomically(path, text);
}

void RunRecon(const ReconFlags& flags) {
  std::vector<NamedPath> outputs = FilesIn("--out", flags.out,
                                           {"frames.csv", "recon_bubble.png", "recon_gelslim.png"});
  outputs.push_back({"--out", flags.out});
  std::vector<NamedPath> inputs = DatasetPathInputs("--data", flags.data, flags.dataset);
  inputs.push_back({"--model", flags.model});
  inputs.push_back({"--functaset", flags.functaset});
  RefuseOutputsThatAreInputs(outputs, inputs);
  // The functaset first: its products' precision is set before the model is read, so
  // that the trunks pack their weights for it.
  const Functaset functaset = Functaset::Load(flags.functaset);
  ApplyProductPrecision(ProductPrecisionFor(flags.products, functaset, flags.functaset, "recon"));
  const FunctaModel model = FunctaModel::Load(flags.model);
  functaset.CheckModel(model, flags.model, flags.functaset);
  if (!functaset.complete()) {
    std::cerr << "recon: note: " << flags.functaset << " is a partial functaset; evaluating the "
              << functaset.size() << " frames it holds\n";
  }
  const Dataset dataset = OpenDataset(flags.data, flags.dataset);
  RefuseOutputsThatAreInputs(outputs, DatasetFileInputs("--data", dataset));
  // Frames of another sensor description or size than the trunk was trained on.
  for (SensorKind sensor : functaset.sensors()) {
    CheckModelMatchesData(model, flags.model, dataset, flags.data, sensor, "recon",
                          "--allow-other-frames", flags.allow_other_frames);
  }
  // Under mpirun every process evaluates its share of the frames and receives the
  // others' figures (docs/SCALING.md); rank 0 alone draws the examples (a handful of
  // frames) and writes the files.
  const ProcessGroup& processes = Processes();
  ReconstructionEvaluator::Options options;
  options.threads = ResolveThreads(flags.threads);
  options.processes = &processes;
  const ReconstructionEvaluator::Summary summary =
      ReconstructionEvaluator(options).Evaluate(model, functaset, dataset);
  if (processes.rank() != 0) return;

  std::filesystem::create_directories(flags.out);
  std::vector<std::string> pictures;
  nlohmann::json pictured = nlohmann::json::object();
  for (SensorKind sensor : functaset.sensors()) {
    if (functaset.entries(sensor).empty() || flags.examples <= 0) continue;
    const std::string path =
        (std::filesystem::path(flags.out) / ("recon_" + std::string(ToString(sensor)) + ".png"))
            .string();
    std::vector<std::string> ids =
        WriteExamples(flags, model, dataset, summary, functaset, sensor, path);
    if (ids.empty()) continue;  // nothing to show, no picture written
    pictured[ToString(sensor)] = std::move(ids);
    pictures.push_back(path);
  }

  std::cout << "recon: " << summary.frames.size() << " frames of " << flags.functaset << " against "
            << flags.data << " (PSNR in dB, Psnr() of estimation/data/trunk_targets.h)\n"
            << summary.FullReport();
  nlohmann::json fit_strategies = nlohmann::json::object();
  for (SensorKind sensor : functaset.sensors()) {
    const std::string& strategy = functaset.fit_strategy(sensor);
    std::cout << "recon: " << ToString(sensor) << " latents fitted with "
              << (strategy.empty() ? "the trunk's meta-SGD steps (not recorded)" : strategy)
              << "\n";
    fit_strategies[ToString(sensor)] =
        strategy.empty() ? nlohmann::json(nullptr) : nlohmann::json(strategy);
  }
  for (const std::string& p : pictures) std::cout << "recon: wrote " << p << "\n";
  const std::string per_frame = (std::filesystem::path(flags.out) / "frames.csv").string();
  WritePerFrameCsv(per_frame, summary, dataset);
  std::cout << "recon: wrote " << per_frame << " (one row per frame)\n";

  if (flags.json) {
    nlohmann::json figures;
    auto per_sensor = [&](Split split, PsnrStats ReconstructionEvaluator::GroupSummary::*stats) {
      nlohmann::json out = nlohmann::json::object();
      for (SensorKind sensor : functaset.sensors()) {
        const auto* g = summary.Find(sensor, split);
        const double mean =
            g == nullptr ? std::numeric_limits<double>::quiet_NaN() : (g->*stats).mean;
        out[ToString(sensor)] = NumberOrNull(mean);
      }
      return out;
    };
    using Group = ReconstructionEvaluator::GroupSummary;
    figures["fit_strategy"] = fit_strategies;
    figures["psnr_test"] = per_sensor(Split::kTest, &Group::noisy);
    figures["psnr_train"] = per_sensor(Split::kTrain, &Group::noisy);
    figures["psnr_test_clean"] =
        summary.has_clean ? per_sensor(Split::kTest, &Group::clean) : nlohmann::json(nullptr);
    figures["psnr_train_clean"] =
        summary.has_clean ? per_sensor(Split::kTrain, &Group::clean) : nlohmann::json(nullptr);
    // The paper release's PSNR convention (peak = the source-resolution range).
    figures["psnr_test_source_peak"] = per_sensor(Split::kTest, &Group::source_peak);
    figures["psnr_train_source_peak"] = per_sensor(Split::kTrain, &Group::source_peak);
    // Contact and no-contact frames apart (estimation/data/contact.h).
    figures["psnr_test_contact"] = per_sensor(Split::kTest, &Group::contact);
    figures["psnr_test_no_contact"] = per_sensor(Split::kTest, &Group::no_contact);
    figures["psnr_train_contact"] = per_sensor(Split::kTrain, &Group::contact);
    figures["psnr_train_no_contact"] = per_sensor(Split::kTrain, &Group::no_contact);
    nlohmann::json groups = nlohmann::json::array();
    for (const auto& g : summary.groups) {
      auto stats = [](const PsnrStats& s) {
        return nlohmann::json{{"count", s.count},
                              {"mean", NumberOrNull(s.mean)},
                              {"median", NumberOrNull(s.median)},
                              {"p5", NumberOrNull(s.p5)}};
      };
      groups.push_back({{"sensor", ToString(g.sensor)},
                        {"split", ToString(g.split)},
                        {"noisy", stats(g.noisy)},
                        {"clean", summary.has_clean ? stats(g.clean) : nlohmann::json(nullptr)},
                        {"zero", stats(g.zero)},
                        {"source_peak", stats(g.source_peak)},
                        {"contact", stats(g.contact)},
                        {"no_contact", stats(g.no_contact)}});
    }
    figures["groups"] = groups;
    figures["compression_ratio"] = summary.size.compression_ratio;
    figures["representation_bytes"] = summary.size.representation_bytes;
    figures["model_bytes"] = summary.size.model_bytes;
    figures["latent_bytes"] = summary.size.latent_bytes;
    figures["raw_bytes"] = summary.size.raw_bytes;
    figures["frames"] = summary.frames.size();
    figures["seconds"] = summary.seconds;
    figures["pictures"] = pictures;
    figures["pictured"] = pictured;
    figures["per_frame"] = per_frame;
    EmitJson(figures);
  }
}

}  // namespace

void RegisterRecon(CLI::App& app, CommandBody* selected) {
  auto flags = std::make_shared<ReconFlags>();
  CLI::App* sub = app.add_subcommand(
      "recon",
      "Reconstruction quality (PSNR per sensor and split, z = 0 baseline) and size of a "
      "functaset, with example pictures per sensor.");
  sub->add_option("--model", flags->model, "Model file (.tfm) the functaset was encoded with")
      ->required();
  sub->add_option("--functaset", flags->functaset, "Functaset file (.tfs) from `tactfunc encode`")
      ->required();
  sub->add_option("--data", flags->data, "The dataset folder or video it was encoded from")
      ->required();
  sub->add_option("--out", flags->out,
                  "Folder for recon_<sensor>.png and frames.csv (one row per frame; created)")
      ->required();
  sub->add_option("--examples", flags->examples,
                  "Example rows per picture, test split first (0 = no pictures)")
      ->check(CLI::Range(0, 1000));
  sub->add_flag("--worst", flags->worst,
                "Picture the lowest-PSNR frames (test split first) instead of an even spread");
  sub->add_option("--threads", flags->threads, "Worker threads (default: all cores)")
      ->check(CLI::Range(0, 256));
  sub->add_option("--tile-height", flags->tile_height, "Tile height in pixels")
      ->check(CLI::Range(16, 2000));
  sub->add_flag("--allow-other-frames", flags->allow_other_frames,
                "Run even when the data's frames (size, channels, sensor description) are not "
                "those the model's trunk was trained on (a warning instead of an error)");
  AddProductPrecisionFlag(sub, &flags->products, /*as_functaset=*/true);
  sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
  AddDatasetFlags(sub, &flags->dataset);
  sub->callback([flags, selected]() { *selected = [flags]() { RunRecon(*flags); }; });
}

}  // namespace tactfunc::apps
