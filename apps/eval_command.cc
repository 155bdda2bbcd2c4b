// Copyright 2026 The tactfunc Authors.
//
// tactfunc eval: the paper's Table I on a dataset -- representation size, reconstruction
// PSNR and pose error of TactFunc against baselines, on train and test, plus a
// rate-distortion picture:
//
//   tactfunc eval --data D --model M --functaset F [--pose-model P] --out DIR [--json]
//       [--sensors LIST] [--threads N] [--extra-functaset F2 --extra-model M2]...
//       [--sensor KIND --reference IMG --reference-index K --pixel-pitch-mm MM --labels CSV]
//
// Without --pose-model (data without pose labels) the table holds the reconstruction
// columns alone: no pose columns, pose targets null in table.json, said once on stderr
// and in table.md.
//
// The evaluation itself (rows, baselines, targets) is TableEvaluation
// (estimation/evaluation/table_evaluation.h); this command checks the flags, loads the
// files, and prints the table, writes table.md and table.json and draws
// rate_distortion.png. Runs as several processes under mpirun (docs/SCALING.md): the
// per-frame work is shared out, rank 0 writes the files, which are those of one process
// (but for the PCA fit's seconds in table.json).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <sstream>

#include <opencv2/imgproc.hpp>

#include "CLI/CLI.hpp"
#include "apps/bench.h"
#include "apps/command.h"
#include "apps/dataset_flags.h"
#include "apps/distributed.h"
#include "apps/model_inputs.h"
#include "apps/output_paths.h"
#include "apps/pictures.h"
#include "apps/progress_bar.h"
#include "estimation/evaluation/table_evaluation.h"
#include "estimation/data/dataset.h"
#include "estimation/data/image_io.h"
#include "estimation/functaset/functaset.h"
#include "estimation/evaluation/reconstruction.h"
#include "estimation/data/trunk_targets.h"
#include "models/core/atomic_file.h"
#include "models/trunk/functa_model.h"
#include "models/pose/pose_mlp.h"
#include "models/pose/pose_model_provenance.h"

namespace tactfunc::apps {
namespace {

namespace fs = std::filesystem;

struct EvalFlags {
  std::string data, model, functaset, pose_model, out, sensors;
  std::vector<std::string> extra_functasets, extra_models;
  int threads = 0;
  std::string products;  // "": as the functaset was encoded
  int raw_downsample = 2;
  int knn_k = 5;
  bool json = false;
  bool allow_other_frames = false;
  DatasetFlags dataset;           // --sensor, --reference, --pixel-pitch-mm, --labels, ...
  std::vector<std::string> argv;  // for the report
};

std::string Sci(double v) {
  if (!std::isfinite(v)) return "-";
  char buffer[48];
  std::snprintf(buffer, sizeof(buffer), "%.3g", v);
  return buffer;
}

using TableRow = TableEvaluation::Row;
using RdPoint = TableEvaluation::RdPoint;
using RdCurves = TableEvaluation::RdCurves;

nlohmann::json RowJson(const TableRow& r) {
  const bool has_pose = r.pose.count > 0;
  return {{"approach", r.approach},
          {"pose_from", r.pose_from.empty() ? nlohmann::json(nullptr) : nlohmann::json(r.pose_from)},
          {"sensor", ToString(r.sensor)},
          {"split", ToString(r.split)},
          {"rep_size_mb", r.rep_bytes / 1e6},
          {"rep_size_bytes", r.rep_bytes},
          {"bytes_per_frame", NumberOrNull(r.bytes_per_frame)},
          {"psnr", r.psnr_applicable ? NumberOrNull(r.psnr) : nlohmann::json(nullptr)},
          {"psnr_applicable", r.psnr_applicable},
          {"psnr_clean", NumberOrNull(r.psnr_clean)},
          {"frames", r.frames},
          {"contact_frames", r.contact_frames},
          {"psnr_contact", NumberOrNull(r.psnr_contact)},
          {"psnr_no_contact", NumberOrNull(r.psnr_no_contact)},
          {"pose_frames", r.pose.count},
          {"pose_mse", has_pose ? NumberOrNull(r.pose.PoseMse()) : nlohmann::json(nullptr)},
          {"rmse_mm", has_pose ? NumberOrNull(r.pose.RmseMm()) : nlohmann::json(nullptr)},
          {"rmse_deg", has_pose ? NumberOrNull(r.pose.RmseDeg()) : nlohmann::json(nullptr)},
          {"note", r.note}};
}

nlohmann::json RdJson(const std::vector<RdPoint>& points) {
  nlohmann::json out = nlohmann::json::array();
  for (const RdPoint& p : points) {
    out.push_back({{"label", p.label},
                   {"bytes_per_frame", p.bytes_per_frame},
                   {"psnr_test", NumberOrNull(p.psnr)},
                   {"psnr_test_clean", NumberOrNull(p.psnr_clean)}});
  }
  return out;
}

// True if some point has a PSNR against noise-free frames.
bool HasCleanPoints(const RdCurves& curves) {
  for (const auto* series : {&curves.tactfunc, &curves.pca, &curves.pca_same_storage}) {
    for (const RdPoint& p : *series) {
      if (std::isfinite(p.psnr_clean)) return true;
    }
  }
  return false;
}

// The rate-distortion picture of one sensor: PSNR (test) vs bytes per frame (log),
// against the frames or (clean) against their noise-free copies.
cv::Mat RateDistortionPlot(SensorKind sensor, const RdCurves& curves, bool clean,
                           const std::string& subtitle) {
  struct Series {
    const std::vector<RdPoint>* points;
    std::string name;
    cv::Scalar colour;
  };
  const std::vector<Series> series = {
      {&curves.tactfunc, "TactFunc (latent sizes)", cv::Scalar(40, 140, 255)},
      {&curves.pca, "PCA (float32 components)", cv::Scalar(230, 160, 40)},
      {&curves.pca_same_storage, "PCA stored as the latents", cv::Scalar(150, 60, 150)},
      {&curves.jpeg, "JPEG (qualities)", cv::Scalar(90, 170, 60)}};
  auto psnr = [clean](const RdPoint& p) { return clean ? p.psnr_clean : p.psnr; };
  double x_lo = std::numeric_limits<double>::infinity(), x_hi = 0, y_lo = x_lo, y_hi = -x_lo;
  for (const Series& s : series) {
    for (const RdPoint& p : *s.points) {
      if (!(p.bytes_per_frame > 0) || !std::isfinite(psnr(p))) continue;
      x_lo = std::min(x_lo, p.bytes_per_frame);
      x_hi = std::max(x_hi, p.bytes_per_frame);
      y_lo = std::min(y_lo, psnr(p));
      y_hi = std::max(y_hi, psnr(p));
    }
  }
  LogXPlot::Layout layout;
  layout.height = 620;
  LogXPlot plot(layout, x_lo, x_hi, y_lo, y_hi);
  plot.DrawFrame("bytes per frame (log scale)",
                 clean ? "mean PSNR vs noise-free frames, dB"
                       : "mean PSNR, test split, dB",
                 std::string("Rate-distortion, ") + ToString(sensor) +
                     (clean ? ", against the noise-free frames" : ""),
                 subtitle);
  cv::Mat& canvas = plot.canvas();
  for (const Series& s : series) {
    std::vector<RdPoint> pts;
    for (const RdPoint& p : *s.points) {
      if (p.bytes_per_frame > 0 && std::isfinite(psnr(p))) pts.push_back(p);
    }
    std::sort(pts.begin(), pts.end(),
              [](const RdPoint& a, const RdPoint& b) { return a.bytes_per_frame < b.bytes_per_frame; });
    std::vector<cv::Point> line;
    for (const RdPoint& p : pts) line.push_back({plot.X(p.bytes_per_frame), plot.Y(psnr(p))});
    if (line.size() > 1) cv::polylines(canvas, line, false, s.colour, 2, cv::LINE_AA);
    for (std::size_t k = 0; k < pts.size(); ++k) {
      cv::circle(canvas, line[k], 5, s.colour, cv::FILLED, cv::LINE_AA);
      PlainText(canvas, pts[k].label, line[k] + cv::Point(7, -7), 0.4, s.colour * 0.7);
    }
  }
  const int lx = plot.area().x + plot.area().width + 22, ly = plot.area().y + 14;
  cv::rectangle(canvas, {lx - 8, ly - 12}, {layout.width - 8, ly + 20 * 5 + 14},
                cv::Scalar(180, 180, 180), 1);
  for (std::size_t k = 0; k < series.size(); ++k) {
    const int y = ly + 20 * static_cast<int>(k);
    cv::line(canvas, {lx, y}, {lx + 14, y}, series[k].colour, 2, cv::LINE_AA);
    cv::circle(canvas, {lx + 7, y}, 4, series[k].colour, cv::FILLED, cv::LINE_AA);
    PlainText(canvas, series[k].name, {lx + 20, y + 5}, 0.42);
  }
  PlainText(canvas, "bytes: codes as stored; JPEG", {lx, ly + 20 * 4 + 5}, 0.38);
  PlainText(canvas, "without its shared tables", {lx, ly + 20 * 4 + 21}, 0.38);
  return canvas;
}

// The targets of one sensor as table.json holds them.
// Without a pose model (has_pose_model false) the pose targets are null.
nlohmann::json TargetsJson(const TableEvaluation::Targets& targets, bool has_pose_model) {
  nlohmann::json t;
  const auto& a = targets.psnr_above_pca;
  auto above_pca = [](const TableEvaluation::Targets::PsnrAbovePca& a) {
    return nlohmann::json{{"met", a.met},
                          {"tactfunc_db", NumberOrNull(a.tactfunc_db)},
                          {"pca_db", NumberOrNull(a.pca_db)},
                          {"margin_db", NumberOrNull(a.margin_db)},
                          {"required_margin_db", a.required_margin_db},
                          {"pca_components", a.pca_components},
                          {"bytes_per_frame", a.bytes_per_frame}};
  };
  t["psnr_3db_above_pca"] = above_pca(a);
  // Against the noise-free frames; null where the dataset has none.
  t["psnr_3db_above_pca_clean"] =
      targets.has_clean ? above_pca(targets.psnr_above_pca_clean) : nlohmann::json(nullptr);
  // Against PCA codes stored at the latents' precision (the same bits, spent the same way).
  t["psnr_3db_above_pca_same_bits"] = above_pca(targets.psnr_above_pca_same_bits);
  t["psnr_3db_above_pca_same_bits_clean"] =
      targets.has_clean ? above_pca(targets.psnr_above_pca_same_bits_clean)
                        : nlohmann::json(nullptr);
  // Against PCA codes in the same bytes shared among their values (PCA's strongest
  // codec; reported, not counted in all_targets_met); null below one byte per frame.
  t["psnr_3db_above_pca_shared_bytes"] = targets.has_shared_bytes
                                             ? above_pca(targets.psnr_above_pca_shared_bytes)
                                             : nlohmann::json(nullptr);
  t["psnr_3db_above_pca_shared_bytes_clean"] =
      targets.has_shared_bytes && targets.has_clean
          ? above_pca(targets.psnr_above_pca_shared_bytes_clean)
          : nlohmann::json(nullptr);
  const auto& b = targets.psnr_above_jpeg;
  t["psnr_above_jpeg"] = {{"met", b.met},
                          {"tactfunc_db", NumberOrNull(b.tactfunc_db)},
                          {"jpeg_db", NumberOrNull(b.jpeg_db)},
                          {"margin_db", NumberOrNull(b.margin_db)},
                          {"tactfunc_bytes_per_frame", b.tactfunc_bytes_per_frame},
                          {"jpeg_bytes_per_frame", NumberOrNull(b.jpeg_bytes_per_frame)},
                          {"jpeg_quality", b.jpeg_quality},
                          {"jpeg_target_reachable", b.jpeg_target_reachable}};
  if (targets.has_pose) {
    const auto& c = targets.pose_beats_pca_codes;
    t["pose_beats_pca_codes"] = {{"met", c.met},
                                 {"tactfunc_pose_mse", NumberOrNull(c.tactfunc_pose_mse)},
                                 {"pca_pose_mse", NumberOrNull(c.pca_pose_mse)}};
    const auto& e = targets.pose_not_worse_than_raw;
    t["pose_not_worse_than_raw"] = {{"met", e.met},
                                    {"tactfunc_pose_mse", NumberOrNull(e.tactfunc_pose_mse)},
                                    {"raw_best_pose_mse", NumberOrNull(e.raw_best_pose_mse)},
                                    {"ridge_pose_mse", NumberOrNull(e.ridge_pose_mse)},
                                    {"knn_pose_mse", NumberOrNull(e.knn_pose_mse)}};
  } else if (!has_pose_model) {
    t["pose_beats_pca_codes"] = nullptr;
    t["pose_not_worse_than_raw"] = nullptr;
  }
  return t;
}

// How the baselines of one sensor were set up, as table.json holds it.
nlohmann::json DetailsJson(const TableEvaluation::Details& d) {
  nlohmann::json j;
  if (d.pose) {
    const TableEvaluation::Details::Pose& p = *d.pose;
    j["pose"] = {{"mlp_hidden", p.mlp_hidden},
                 {"mlp_epochs", p.mlp_training.epochs},
                 {"mlp_batch", p.mlp_training.batch_size},
                 {"mlp_learning_rate", p.mlp_training.learning_rate},
                 {"ridge_relative_lambda", p.ridge.relative_lambda},
                 {"ridge_lambda", p.ridge.lambda},
                 {"raw_downsample", p.raw_downsample},
                 {"raw_features", p.raw_features},
                 {"knn_k", p.knn_k},
                 {"labelled_train", p.labelled_train},
                 {"labelled_test", p.labelled_test}};
  }
  j["pca"] = {{"components", d.pca_components},
              {"explained_variance", d.pca.explained_variance},
              {"fit_seconds", d.pca.seconds},
              {"method", d.pca.method}};
  j["jpeg"] = {{"quality", d.jpeg_search.quality},
               {"target_bytes", d.jpeg_search.target_bytes},
               {"mean_train_bytes", d.jpeg_search.mean_bytes},
               {"bracket", {d.jpeg_search.below, d.jpeg_search.below + 1}},
               {"target_reachable", d.jpeg_search.target_reachable},
               {"range", {d.jpeg.lo, d.jpeg.hi}},
               {"table_bytes", d.jpeg_table_bytes}};
  j["working_resolution"] = {d.rows, d.cols, d.channels};
  j["raw_frame_bytes"] = d.raw_frame_bytes;
  return j;
}

// TableEvaluation's log on stdout, its warnings on stderr, its tasks as progress bars.
class ConsoleObserver : public TableEvaluation::Observer {
 public:
  void Message(const std::string& line) override { std::cout << line << std::flush; }
  void Warning(const std::string& line) override { std::cerr << line; }
  void BeginTask(const std::string& label, std::int64_t total, const std::string& unit) override {
    bar_ = std::make_unique<ProgressBar>(label, total, unit, ProgressBar::Lines::kWhenNotDrawn);
  }
  void Tick() override {
    if (bar_) bar_->Tick();
  }
  void EndTask() override {
    if (bar_) bar_->Finish();
    bar_.reset();
  }

 private:
  std::unique_ptr<ProgressBar> bar_;
};

// The pose model's provenance; a malformed one is a DatasetError naming the file.
PoseModelProvenance ReadPoseModelProvenance(const PoseMlp& pose_model, const std::string& path) {
  try {
    return PoseModelProvenance::FromJson(pose_model.info_json(), path);
  } catch (const std::invalid_argument& e) {
    throw DatasetError(std::string("--pose-model: ") + e.what());
  }
}

void WriteTextFile(const std::string& path, const std::string& text) {
  WriteFileAtomically(path, text);
}

// ---- The command -----------------------------------------------------------------------

void RunEval(const EvalFlags& flags) {
  if (flags.extra_functasets.size() != flags.extra_models.size()) {
    throw UsageError("--extra-functaset and --extra-model come in pairs: got " +
                     std::to_string(flags.extra_functasets.size()) + " and " +
                     std::to_string(flags.extra_models.size()));
  }
  for (const auto& [flag, path] :
       std::vector<std::pair<std::string, std::string>>{{"--model", flags.model},
                                                        {"--functaset", flags.functaset},
                                                        {"--pose-model", flags.pose_model}}) {
    if (flag == "--pose-model" && path.empty()) continue;  // optional
    if (!fs::is_regular_file(path)) throw DatasetError(flag + " '" + path + "': no such file");
  }
  for (std::size_t k = 0; k < flags.extra_functasets.size(); ++k) {
    if (!fs::is_regular_file(flags.extra_functasets[k])) {
      throw DatasetError("--extra-functaset '" + flags.extra_functasets[k] + "': no such file");
    }
    if (!fs::is_regular_file(flags.extra_models[k])) {
      throw DatasetError("--extra-model '" + flags.extra_models[k] + "': no such file");
    }
  }
  if (!fs::exists(flags.data)) {
    throw DatasetError("--data '" + flags.data + "': no such dataset folder or video");
  }
  std::vector<NamedPath> outputs =
      FilesIn("--out", flags.out, {"table.md", "table.json", "rate_distortion.png"});
  outputs.push_back({"--out", flags.out});
  std::vector<NamedPath> read = DatasetPathInputs("--data", flags.data, DatasetFlags());
  read.push_back({"--model", flags.model});
  read.push_back({"--functaset", flags.functaset});
  read.push_back({"--pose-model", flags.pose_model});
  for (std::size_t k = 0; k < flags.extra_functasets.size(); ++k) {
    read.push_back({"--extra-functaset", flags.extra_functasets[k]});
    read.push_back({"--extra-model", flags.extra_models[k]});
  }
  RefuseOutputsThatAreInputs(outputs, read);
  const int threads = ResolveThreads(flags.threads);
  // The functaset first: its products' precision is set before the models are read, so
  // that the trunks pack their weights for it.
  const Functaset functaset = Functaset::Load(flags.functaset);
  ApplyProductPrecision(ProductPrecisionFor(flags.products, functaset, flags.functaset, "eval"));
  const FunctaModel model = FunctaModel::Load(flags.model);
  functaset.CheckModel(model, flags.model, flags.functaset);
  const Dataset dataset = OpenDataset(flags.data, flags.dataset);
  RefuseOutputsThatAreInputs(outputs, DatasetFileInputs("--data", dataset));

  // Sensors: --sensors, else every sensor of the functaset.
  std::vector<SensorKind> sensors;
  if (flags.sensors.empty()) {
    sensors = functaset.sensors();
  } else {
    for (const std::string& name : SplitList(flags.sensors)) {
      SensorKind kind;
      if (!ParseSensorFlag(name, &kind)) continue;
      if (!functaset.has_sensor(kind)) {
        throw DatasetError("--functaset '" + flags.functaset + "' has no " + name + " latents");
      }
      sensors.push_back(kind);
    }
  }
  if (sensors.empty()) throw UsageError("no sensor to evaluate");
  for (SensorKind s : sensors) {
    if (!dataset.has_sensor(s)) {
      throw DatasetError("--data '" + flags.data + "' has no " + ToString(s) + " frames");
    }
    CheckModelMatchesData(model, flags.model, dataset, flags.data, s, "eval",
                          "--allow-other-frames", flags.allow_other_frames);
    const FrameFormat& format = model.Trunk(s).format;
    WarnIfStretched(dataset, flags.data, s, format.rows, format.cols, "eval");
  }

  // The pose model's sensor (from its provenance, as train-pose writes it; else the first).
  const bool has_pose = !flags.pose_model.empty();
  SensorKind pose_sensor = sensors[0];
  if (has_pose) {
    const PoseModelProvenance provenance =
        ReadPoseModelProvenance(PoseMlp::Load(flags.pose_model), flags.pose_model);
    if (!provenance.sensor.empty()) {
      SensorKind kind;
      if (!SensorKindFromString(provenance.sensor, &kind)) {
        throw DatasetError("--pose-model '" + flags.pose_model + "' names an unknown sensor '" +
                           provenance.sensor + "'");
      }
      pose_sensor = kind;
    }
    if (std::find(sensors.begin(), sensors.end(), pose_sensor) == sensors.end()) {
      throw DatasetError("--pose-model '" + flags.pose_model + "' was trained on " +
                         ToString(pose_sensor) + " latents, which are not evaluated (--sensors)");
    }
  }
  std::optional<PoseMlp> pose_model;
  if (has_pose) {
    pose_model = LoadPoseModelFor(flags.pose_model, model, pose_sensor, flags.model);
  } else {
    std::cerr << "eval: no --pose-model: the table holds the reconstruction columns only "
                 "(no pose columns, pose targets null)\n";
  }

  // Extra functasets for the rate-distortion picture.
  struct Extra {
    std::string functaset_path, model_path;
    FunctaModel model;
    Functaset functaset;
  };
  std::vector<Extra> extras;
  for (std::size_t k = 0; k < flags.extra_functasets.size(); ++k) {
    Extra e{flags.extra_functasets[k], flags.extra_models[k],
            FunctaModel::Load(flags.extra_models[k]), Functaset::Load(flags.extra_functasets[k])};
    e.functaset.CheckModel(e.model, e.model_path, e.functaset_path);
    extras.push_back(std::move(e));
  }

  // Under mpirun every process evaluates its share of the frames and receives the
  // others' results (docs/SCALING.md); rank 0 alone writes the files.
  const ProcessGroup& processes = Processes();
  if (processes.rank() == 0) fs::create_directories(flags.out);
  TableEvaluation::Inputs inputs;
  inputs.dataset = &dataset;
  inputs.dataset_name = flags.data;
  inputs.model = &model;
  inputs.functaset = &functaset;
  inputs.functaset_name = flags.functaset;
  inputs.pose_model = pose_model ? &*pose_model : nullptr;
  inputs.pose_sensor = pose_sensor;
  inputs.sensors = sensors;
  for (const Extra& e : extras) inputs.extras.push_back({&e.model, &e.functaset, e.functaset_path});
  TableEvaluation::Options options;
  options.threads = threads;
  options.raw_downsample = flags.raw_downsample;
  options.knn_k = flags.knn_k;
  options.processes = &processes;
  ConsoleObserver observer;
  const TableEvaluation::Result evaluation = TableEvaluation::Evaluate(inputs, options, &observer);
  if (processes.rank() != 0) return;
  const std::vector<TableRow>& rows = evaluation.rows;
  const bool all_met = evaluation.all_targets_met;
  std::map<SensorKind, RdCurves> curves;
  nlohmann::json targets = nlohmann::json::object();
  nlohmann::json details = nlohmann::json::object();
  for (const TableEvaluation::SensorResult& r : evaluation.sensors) {
    curves[r.sensor] = r.curves;
    targets[ToString(r.sensor)] = TargetsJson(r.targets, has_pose);
    details[ToString(r.sensor)] = DetailsJson(r.details);
    const std::string& strategy = functaset.fit_strategy(r.sensor);
    details[ToString(r.sensor)]["fit_strategy"] =
        strategy.empty() ? nlohmann::json(nullptr) : nlohmann::json(strategy);
  }

  // ---- Output ------------------------------------------------------------------------------
  const nlohmann::json machine = MachineDescription();
  std::string command;
  for (const std::string& a : flags.argv) {
    if (!a.empty()) command += (command.empty() ? "" : " ") + a;
  }
  // The clean-PSNR column only for data with noise-free frames (simulated, synth --clean).
  const bool any_clean = std::any_of(rows.begin(), rows.end(),
                                     [](const TableRow& r) { return std::isfinite(r.psnr_clean); });
  // Contact and rest columns only when some frame is at rest (else they repeat PSNR).
  const bool any_rest = std::any_of(rows.begin(), rows.end(), [](const TableRow& r) {
    return r.psnr_applicable && r.contact_frames < r.frames;
  });
  // Without a pose model the pose columns are left out.
  std::ostringstream md;
  md << "| approach |" << (has_pose ? " pose from |" : "")
     << " sensor | split | rep. size (MB) | bytes/frame | PSNR (dB) |"
     << (any_clean ? " PSNR clean (dB) |" : "")
     << (any_rest ? " contact frames | PSNR contact (dB) | PSNR at rest (dB) |" : "")
     << (has_pose ? " pose MSE | RMSE (mm) | RMSE (deg) |" : "") << "\n"
     << "|---|" << (has_pose ? "---|" : "") << "---|---|---:|---:|---:|"
     << (any_clean ? "---:|" : "") << (any_rest ? "---:|---:|---:|" : "")
     << (has_pose ? "---:|---:|---:|" : "") << "\n";
  for (const TableRow& r : rows) {
    const bool row_pose = r.pose.count > 0;
    md << "| " << r.approach << (r.note.empty() ? "" : " (" + r.note + ")") << " | ";
    if (has_pose) md << (r.pose_from.empty() ? "-" : r.pose_from) << " | ";
    md << ToString(r.sensor) << " | " << ToString(r.split) << " | "
       << FormatFixed(r.rep_bytes / 1e6, 3, "-") << " | " << FormatFixed(r.bytes_per_frame, 0, "-")
       << " | "
       << (r.psnr_applicable ? FormatFixed(r.psnr, 2, "-") : std::string("n/a (lossless)")) << " |"
       << (any_clean ? " " + FormatFixed(r.psnr_clean, 2, "-") + " |" : std::string());
    if (any_rest) {
      md << " " << (r.psnr_applicable ? std::to_string(r.contact_frames) + "/" +
                                            std::to_string(r.frames)
                                      : std::string("-"))
         << " | " << FormatFixed(r.psnr_contact, 2, "-") << " | "
         << FormatFixed(r.psnr_no_contact, 2, "-") << " |";
    }
    if (has_pose) {
      md << " " << (row_pose ? Sci(r.pose.PoseMse()) : "-") << " | "
         << (row_pose ? FormatFixed(r.pose.RmseMm(), 3, "-") : "-") << " | "
         << (row_pose ? FormatFixed(r.pose.RmseDeg(), 2, "-") : "-") << " |";
    }
    md << "\n";
  }
  std::ostringstream targets_md;
  for (const auto& [sensor, t] : targets.items()) {
    auto yes = [](const nlohmann::json& j) { return j["met"].get<bool>() ? "**met**" : "**NOT met**"; };
    auto num = [](const nlohmann::json& j, int digits) {
      return j.is_number() ? FormatFixed(j.get<double>(), digits, "-") : std::string("-");
    };
    auto sci = [](const nlohmann::json& j) {
      return j.is_number() ? Sci(j.get<double>()) : std::string("-");
    };
    const nlohmann::json& a = t["psnr_3db_above_pca"];
    targets_md << "- " << sensor << ": TactFunc >= 3 dB above PCA at equal bytes (test): "
               << yes(a) << " (" << num(a["tactfunc_db"], 2) << " vs " << num(a["pca_db"], 2)
               << " dB with " << a["pca_components"] << " components, margin "
               << num(a["margin_db"], 2) << " dB)\n";
    if (!t["psnr_3db_above_pca_clean"].is_null()) {
      const nlohmann::json& c = t["psnr_3db_above_pca_clean"];
      targets_md << "- " << sensor
                 << ": TactFunc >= 3 dB above PCA at equal bytes, noise-free frames (test): "
                 << yes(c) << " (" << num(c["tactfunc_db"], 2) << " vs " << num(c["pca_db"], 2)
                 << " dB, margin " << num(c["margin_db"], 2) << " dB)\n";
    }
    for (const char* key : {"psnr_3db_above_pca_same_bits", "psnr_3db_above_pca_same_bits_clean",
                            "psnr_3db_above_pca_shared_bytes",
                            "psnr_3db_above_pca_shared_bytes_clean"}) {
      if (!t.contains(key) || t[key].is_null()) continue;
      const nlohmann::json& c = t[key];
      const bool shared = std::string(key).find("shared") != std::string::npos;
      targets_md << "- " << sensor << ": TactFunc >= 3 dB above PCA codes "
                 << (shared ? "in the same bytes shared among their values"
                            : "stored as the latents are")
                 << (std::string(key).find("clean") != std::string::npos ? ", noise-free frames"
                                                                          : "")
                 << (shared ? " (test; reported, not counted in all targets): " : " (test): ")
                 << yes(c) << " (" << num(c["tactfunc_db"], 2) << " vs "
                 << num(c["pca_db"], 2) << " dB with " << c["pca_components"]
                 << " components, margin " << num(c["margin_db"], 2) << " dB)\n";
    }
    const nlohmann::json& b = t["psnr_above_jpeg"];
    targets_md << "- " << sensor << ": TactFunc above JPEG at matched bytes (test): " << yes(b)
               << " (" << num(b["tactfunc_db"], 2) << " dB at " << num(b["tactfunc_bytes_per_frame"], 0)
               << " B vs " << num(b["jpeg_db"], 2) << " dB at " << num(b["jpeg_bytes_per_frame"], 0)
               << " B, quality " << b["jpeg_quality"]
               << (b["jpeg_target_reachable"].get<bool>() ? "" : "; even quality 1 is larger")
               << ")\n";
    if (t.contains("pose_beats_pca_codes") && !t["pose_beats_pca_codes"].is_null()) {
      const nlohmann::json& c = t["pose_beats_pca_codes"];
      targets_md << "- " << sensor << ": pose from latents better than from PCA codes (test): "
                 << yes(c) << " (pose MSE " << sci(c["tactfunc_pose_mse"]) << " vs "
                 << sci(c["pca_pose_mse"]) << ")\n";
      const nlohmann::json& e = t["pose_not_worse_than_raw"];
      targets_md << "- " << sensor << ": pose from latents not worse than raw pixels (test): "
                 << yes(e) << " (pose MSE " << sci(e["tactfunc_pose_mse"]) << " vs best raw "
                 << sci(e["raw_best_pose_mse"]) << ": ridge " << sci(e["ridge_pose_mse"])
                 << ", k-NN " << sci(e["knn_pose_mse"]) << ")\n";
    }
  }
  std::cout << "\n" << md.str() << "\nTargets:\n" << targets_md.str();

  std::ostringstream file;
  file << "# Table I (tactfunc eval)\n\nCommand: `" << command << "`\n\nMachine: "
       << machine.value("cpu", std::string("?")) << ", " << machine.value("cores", 0)
       << " cores.\n\n"
       << md.str()
       << (has_pose ? ""
                    : "\nNo pose model was given (--pose-model): the table holds the "
                      "reconstruction columns only; pose columns and pose targets are left out.\n")
       << "\nrep. size: model + per-frame data for every frame of the sensor in the functaset "
          "(train + test; the test frames alone for a functaset of test entries only, whose "
          "baselines are fitted on the dataset's train-split frames). "
          "bytes/frame: codes as stored (TactFunc latents as encode --latent-precision stored them, "
          "float16 by default, b-bit codes without their per-dimension offset/step tables "
          "(counted once in rep. size); PCA float32); JPEG without its shared tables "
          "(counted once in rep. size); raw: rows x cols x channels x bytes per sample at the "
          "native resolution. PSNR: mean over the split's frames of THE PSNR of "
          "estimation/data/trunk_targets.h at the model's working resolution (n/a for raw frames: "
          "lossless)."
       << (has_pose ? " pose MSE: mean over frames of (dx^2 + dy^2 + dyaw^2) / 3 in m and rad, "
                      "yaw modulo the tool's symmetry."
                    : "")
       << "\n\nTargets:\n\n"
       << targets_md.str();
  WriteTextFile((fs::path(flags.out) / "table.md").string(), file.str());

  // One rate-distortion panel per sensor, stacked.
  std::vector<cv::Mat> panels;
  nlohmann::json rd = nlohmann::json::object();
  for (SensorKind sensor : sensors) {
    const RdCurves& c = curves[sensor];
    const std::string subtitle =
        std::string("test split; PSNR of estimation/data/trunk_targets.h at the working resolution; ") +
        machine.value("cpu", std::string("?"));
    panels.push_back(RateDistortionPlot(sensor, c, false, subtitle));
    // Where the frames have noise-free copies, the same against them beside it.
    if (HasCleanPoints(c)) {
      cv::Mat both;
      cv::hconcat(panels.back(), RateDistortionPlot(sensor, c, true, subtitle), both);
      panels.back() = both;
    }
    rd[ToString(sensor)] = {{"tactfunc", RdJson(c.tactfunc)},
                            {"pca", RdJson(c.pca)},
                            {"pca_same_storage", RdJson(c.pca_same_storage)},
                            {"jpeg", RdJson(c.jpeg)}};
  }
  // Panels of one width (a sensor without noise-free copies has one plot, not two).
  int width = 0;
  for (const cv::Mat& panel : panels) width = std::max(width, panel.cols);
  for (cv::Mat& panel : panels) {
    if (panel.cols < width) {
      cv::copyMakeBorder(panel, panel, 0, 0, 0, width - panel.cols, cv::BORDER_CONSTANT,
                         cv::Scalar(255, 255, 255));
    }
  }
  cv::Mat picture;
  cv::vconcat(panels, picture);
  const std::string plot_path = (fs::path(flags.out) / "rate_distortion.png").string();
  WritePicture(plot_path, picture);

  nlohmann::json rows_json = nlohmann::json::array();
  for (const TableRow& r : rows) rows_json.push_back(RowJson(r));
  nlohmann::json result = {{"rows", rows_json},
                           {"targets", targets},
                           {"all_targets_met", all_met},
                           {"rate_distortion", rd},
                           {"details", details},
                           {"pose_sensor", has_pose ? nlohmann::json(ToString(pose_sensor))
                                                    : nlohmann::json(nullptr)},
                           {"command", command},
                           {"machine", machine},
                           {"files",
                            {(fs::path(flags.out) / "table.md").string(),
                             (fs::path(flags.out) / "table.json").string(), plot_path}}};
  WriteTextFile((fs::path(flags.out) / "table.json").string(), result.dump(2) + "\n");
  std::cout << "eval: wrote " << flags.out << "/table.md, table.json, rate_distortion.png\n";
  if (flags.json) EmitJson(result);
}

}  // namespace

void RegisterEval(CLI::App& app, CommandBody* selected) {
  auto flags = std::make_shared<EvalFlags>();
  CLI::App* sub = app.add_subcommand(
      "eval",
      "The paper's Table I: representation size, PSNR and pose error of TactFunc against PCA, "
      "JPEG and raw frames (ridge / k-NN on pixels), train and test; writes table.md, "
      "table.json and rate_distortion.png to --out.");
  sub->add_option("--data", flags->data, "Dataset folder the functaset was encoded from")
      ->required();
  sub->add_option("--model", flags->model, "Model (.tfm) of the functaset")->required();
  sub->add_option("--functaset", flags->functaset, "Functaset (.tfs) from `tactfunc encode`")
      ->required();
  sub->add_option("--pose-model", flags->pose_model,
                  "Pose model (.tpm) from `tactfunc train-pose` on this functaset; without "
                  "it the table holds the reconstruction columns only (no pose columns, "
                  "pose targets null)");
  sub->add_option("--out", flags->out, "Folder for table.md, table.json, rate_distortion.png")
      ->required();
  sub->add_option("--sensors", flags->sensors,
                  "Sensors to evaluate, comma-separated (default: the functaset's)");
  sub->add_option("--threads", flags->threads, "Worker threads (default: every core)")
      ->check(CLI::Range(0, 1024));
  sub->add_option("--extra-functaset", flags->extra_functasets,
                  "Another functaset of the same data (e.g. another latent size) for the "
                  "rate-distortion picture; repeatable, each with an --extra-model");
  sub->add_option("--extra-model", flags->extra_models,
                  "The model of the matching --extra-functaset; repeatable");
  sub->add_option("--raw-downsample", flags->raw_downsample,
                  "Block size of the pixel features of the raw-pixel pose baselines (default 2: "
                  "2x2 block means of the working-resolution frame)")
      ->check(CLI::Range(1, 64));
  sub->add_option("--knn-k", flags->knn_k, "Neighbours of the raw-pixel k-NN pose baseline (5)")
      ->check(CLI::Range(1, 1000));
  sub->add_flag("--allow-other-frames", flags->allow_other_frames,
                "Run even when the data's frames (size, channels, sensor description) are not "
                "those the model's trunk was trained on (a warning instead of an error)");
  AddProductPrecisionFlag(sub, &flags->products, /*as_functaset=*/true);
  sub->add_flag("--json", flags->json, "Print {rows, targets, rate_distortion, ...} as one JSON line");
  AddDatasetFlags(sub, &flags->dataset);
  sub->callback([flags, selected]() {
    flags->argv = {"tactfunc eval", "--data " + flags->data, "--model " + flags->model,
                   "--functaset " + flags->functaset,
                   flags->pose_model.empty() ? "" : "--pose-model " + flags->pose_model,
                   "--out " + flags->out,
                   flags->sensors.empty() ? "" : "--sensors " + flags->sensors};
    const DatasetFlags& d = flags->dataset;
    if (!d.sensor.empty()) flags->argv.push_back("--sensor " + d.sensor);
    if (!d.reference.empty()) flags->argv.push_back("--reference " + d.reference);
    if (d.reference_index != 0) {
      flags->argv.push_back("--reference-index " + std::to_string(d.reference_index));
    }
    if (d.pixel_pitch_mm != 0) {
      std::ostringstream pitch;
      pitch << d.pixel_pitch_mm;
      flags->argv.push_back("--pixel-pitch-mm " + pitch.str());
    }
    if (!d.labels.empty()) flags->argv.push_back("--labels " + d.labels);
    for (std::size_t k = 0; k < flags->extra_functasets.size(); ++k) {
      flags->argv.push_back("--extra-functaset " + flags->extra_functasets[k]);
      if (k < flags->extra_models.size()) {
        flags->argv.push_back("--extra-model " + flags->extra_models[k]);
      }
    }
    *selected = [flags]() { RunEval(*flags); };
  });
}

}  // namespace tactfunc::apps
