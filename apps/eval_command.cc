// Copyright 2026 The tactfunc Authors.
//
// tactfunc eval: the paper's Table I on a dataset -- representation size, reconstruction
// PSNR and pose error of TactFunc against baselines (estimation/evaluation/baselines.h), on train
// and test, plus a rate-distortion picture:
//
//   tactfunc eval --data D --model M --functaset F --pose-model P --out DIR [--json]
//       [--sensors LIST] [--threads N] [--extra-functaset F2 --extra-model M2]...
//
// Rows, per sensor and split (every frame of the functaset; the test rows are the
// held-out frames):
//   TactFunc    the functaset's latents decoded by the model's trunk; pose: P on the latents
//   PCA         cv::PCA fitted on the train frames, as many components as the latent has
//               floats; pose: the same MLP architecture, trained as P was, on PCA codes
//   JPEG        8-bit JPEG, quality chosen on the train frames so that its mean bytes per
//               frame match the latent's bytes; no pose row
//   Raw frames  the frames uncompressed; PSNR not applicable; pose: ridge and k-NN on
//               downsampled pixels (stand-ins for the paper's ResNet-18)
// Every PSNR is THE PSNR of estimation/data/trunk_targets.h on the model's working-resolution
// frames; pose errors are scored as train-pose scores them (baselines.h, ScorePoses).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <set>
#include <sstream>

#include <opencv2/imgproc.hpp>

#include "apps/bench.h"
#include "apps/command.h"
#include "apps/model_inputs.h"
#include "apps/pictures.h"
#include "apps/progress_bar.h"
#include "estimation/evaluation/baselines.h"
#include "estimation/data/dataset.h"
#include "estimation/data/image_io.h"
#include "estimation/functaset/functaset.h"
#include "models/core/parallel_for.h"
#include "estimation/evaluation/reconstruction.h"
#include "estimation/data/trunk_targets.h"
#include "models/core/atomic_file.h"
#include "models/trunk/functa_model.h"
#include "models/pose/pose_mlp.h"

namespace tactfunc::apps {
namespace {

namespace fs = std::filesystem;

struct EvalFlags {
  std::string data, model, functaset, pose_model, out, sensors;
  std::vector<std::string> extra_functasets, extra_models;
  int threads = 0;
  int raw_downsample = 2;
  int knn_k = 5;
  bool json = false;
  std::vector<std::string> argv;  // for the report
};

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();

std::string Sci(double v) {
  if (!std::isfinite(v)) return "-";
  char buffer[48];
  std::snprintf(buffer, sizeof(buffer), "%.3g", v);
  return buffer;
}

// Mean of the finite values (ComputePsnrStats' rule: NaN and +inf left out).
double MeanPsnr(const std::vector<double>& values) { return ComputePsnrStats(values).mean; }

// internal::ParallelFor over [0, n) that ticks `bar` (thread-safe) after each item.
template <typename Fn>
void ParallelFor(std::size_t n, int threads, ProgressBar* bar, const Fn& fn) {
  internal::ParallelFor(static_cast<int>(n), threads, [&](int i) {
    fn(static_cast<std::size_t>(i));
    if (bar) bar->Tick();
  });
}

// One sensor's frames as every approach sees them.
struct SensorFrames {
  SensorKind sensor = SensorKind::kSoftBubble;
  const SensorTrunk* trunk = nullptr;
  std::vector<const FunctasetEntry*> entries;  // the functaset's, in its order
  std::vector<TrunkTargets> targets;           // the same frames at the working resolution
  std::vector<std::size_t> train, test;        // indices into entries
  const std::vector<std::size_t>& Of(Split split) const {
    return split == Split::kTrain ? train : test;
  }
  std::vector<const TrunkTargets*> Targets(const std::vector<std::size_t>& indices) const {
    std::vector<const TrunkTargets*> out;
    for (std::size_t i : indices) out.push_back(&targets[i]);
    return out;
  }
};

SensorFrames LoadSensorFrames(const Functaset& functaset, const SensorTrunk& trunk,
                              const Dataset& dataset, const std::string& data_path, int threads) {
  SensorFrames s;
  s.sensor = trunk.sensor;
  s.trunk = &trunk;
  std::vector<std::size_t> dataset_index;
  for (const FunctasetEntry& e : functaset.entries(trunk.sensor)) {
    const std::optional<std::size_t> index = dataset.FindFrame(e.id, trunk.sensor);
    if (!index) {
      throw DatasetError("--data '" + data_path + "' has no " + ToString(trunk.sensor) +
                         " frame '" + e.id + "' of --functaset '" + functaset.source() +
                         "' (a functaset of another dataset?)");
    }
    (e.split == Split::kTrain ? s.train : s.test).push_back(s.entries.size());
    s.entries.push_back(&e);
    dataset_index.push_back(*index);
  }
  s.targets.resize(s.entries.size());
  ProgressBar bar(std::string("eval: loading ") + ToString(trunk.sensor), s.entries.size(),
                  "frames");
  ParallelFor(s.entries.size(), threads, &bar, [&](std::size_t i) {
    s.targets[i] = LoadTrunkTargets(dataset, dataset_index[i], trunk.format);
  });
  bar.Finish();
  return s;
}

// Per-frame PSNR of f(grid; z) for every entry of `frames` with the latents of `entries`.
std::vector<double> LatentPsnrs(const SensorTrunk& trunk,
                                const std::vector<const FunctasetEntry*>& entries,
                                const std::vector<const TrunkTargets*>& targets, int threads,
                                const std::string& label) {
  std::vector<double> psnr(entries.size(), kNan);
  ProgressBar bar(label, entries.size(), "frames");
  ParallelFor(entries.size(), threads, &bar, [&](std::size_t i) {
    psnr[i] = Psnr(Reconstruct(trunk, entries[i]->latent), *targets[i]);
  });
  bar.Finish();
  return psnr;
}

std::vector<double> Pick(const std::vector<double>& values, const std::vector<std::size_t>& idx) {
  std::vector<double> out;
  for (std::size_t i : idx) out.push_back(values[i]);
  return out;
}

// Labelled frames of one split as pose samples.
struct PoseSamples {
  std::vector<std::size_t> frames;  // indices into SensorFrames::entries
  PoseTargets targets;
};

PoseSamples LabelledSamples(const SensorFrames& s, Split split) {
  PoseSamples p;
  for (std::size_t i : s.Of(split)) {
    if (s.entries[i]->label.has_value()) p.frames.push_back(i);
  }
  const int m = static_cast<int>(p.frames.size());
  p.targets.poses.resize(m, 3);
  p.targets.symmetry_orders.resize(m);
  for (int k = 0; k < m; ++k) {
    const PoseLabel& label = *s.entries[p.frames[k]]->label;
    p.targets.poses.row(k) << label.x_m, label.y_m, label.yaw_rad;
    p.targets.symmetry_orders[k] = SymmetryOrderOfTool(label.tool);
  }
  return p;
}

// Rows of `source` (one per frame of s.entries) picked for the samples.
Eigen::MatrixXf Rows(const Eigen::MatrixXf& source, const std::vector<std::size_t>& frames) {
  Eigen::MatrixXf out(static_cast<Eigen::Index>(frames.size()), source.cols());
  for (std::size_t k = 0; k < frames.size(); ++k) out.row(k) = source.row(frames[k]);
  return out;
}

// One row of the table.
struct Row {
  std::string approach;   // TactFunc, PCA, JPEG, Raw frames
  std::string pose_from;  // how the pose column was obtained ("" = no pose)
  SensorKind sensor = SensorKind::kSoftBubble;
  Split split = Split::kTrain;
  std::uint64_t rep_bytes = 0;  // model + per-frame data, all frames of the sensor
  double bytes_per_frame = kNan;
  double psnr = kNan;           // NaN: not applicable (raw) or no finite value
  bool psnr_applicable = true;
  int frames = 0;
  PoseErrors pose;  // count 0: no pose
  std::string note;
};

nlohmann::json RowJson(const Row& r) {
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
          {"frames", r.frames},
          {"pose_frames", r.pose.count},
          {"pose_mse", has_pose ? NumberOrNull(r.pose.PoseMse()) : nlohmann::json(nullptr)},
          {"rmse_mm", has_pose ? NumberOrNull(r.pose.RmseMm()) : nlohmann::json(nullptr)},
          {"rmse_deg", has_pose ? NumberOrNull(r.pose.RmseDeg()) : nlohmann::json(nullptr)},
          {"note", r.note}};
}

// A point of the rate-distortion picture (test split).
struct RdPoint {
  double bytes_per_frame = 0;
  double psnr = kNan;
  std::string label;  // "d=64", "n=32", "q=20"
};

struct RdCurves {
  std::vector<RdPoint> tactfunc, pca, jpeg;
};

nlohmann::json RdJson(const std::vector<RdPoint>& points) {
  nlohmann::json out = nlohmann::json::array();
  for (const RdPoint& p : points) {
    out.push_back({{"label", p.label},
                   {"bytes_per_frame", p.bytes_per_frame},
                   {"psnr_test", NumberOrNull(p.psnr)}});
  }
  return out;
}

// The rate-distortion picture of one sensor: PSNR (test) vs bytes per frame (log).
cv::Mat RateDistortionPlot(SensorKind sensor, const RdCurves& curves, const std::string& subtitle) {
  struct Series {
    const std::vector<RdPoint>* points;
    std::string name;
    cv::Scalar colour;
  };
  const std::vector<Series> series = {
      {&curves.tactfunc, "TactFunc (latent sizes)", cv::Scalar(40, 140, 255)},
      {&curves.pca, "PCA (component counts)", cv::Scalar(230, 160, 40)},
      {&curves.jpeg, "JPEG (qualities)", cv::Scalar(90, 170, 60)}};
  double x_lo = std::numeric_limits<double>::infinity(), x_hi = 0, y_lo = x_lo, y_hi = -x_lo;
  for (const Series& s : series) {
    for (const RdPoint& p : *s.points) {
      if (!(p.bytes_per_frame > 0) || !std::isfinite(p.psnr)) continue;
      x_lo = std::min(x_lo, p.bytes_per_frame);
      x_hi = std::max(x_hi, p.bytes_per_frame);
      y_lo = std::min(y_lo, p.psnr);
      y_hi = std::max(y_hi, p.psnr);
    }
  }
  LogXPlot::Layout layout;
  layout.height = 620;
  LogXPlot plot(layout, x_lo, x_hi, y_lo, y_hi);
  plot.DrawFrame("bytes per frame (log scale)", "mean PSNR, test split, dB",
                 std::string("Rate-distortion, ") + ToString(sensor), subtitle);
  cv::Mat& canvas = plot.canvas();
  for (const Series& s : series) {
    std::vector<RdPoint> pts;
    for (const RdPoint& p : *s.points) {
      if (p.bytes_per_frame > 0 && std::isfinite(p.psnr)) pts.push_back(p);
    }
    std::sort(pts.begin(), pts.end(),
              [](const RdPoint& a, const RdPoint& b) { return a.bytes_per_frame < b.bytes_per_frame; });
    std::vector<cv::Point> line;
    for (const RdPoint& p : pts) line.push_back({plot.X(p.bytes_per_frame), plot.Y(p.psnr)});
    if (line.size() > 1) cv::polylines(canvas, line, false, s.colour, 2, cv::LINE_AA);
    for (std::size_t k = 0; k < pts.size(); ++k) {
      cv::circle(canvas, line[k], 5, s.colour, cv::FILLED, cv::LINE_AA);
      PlainText(canvas, pts[k].label, line[k] + cv::Point(7, -7), 0.4, s.colour * 0.7);
    }
  }
  const int lx = plot.area().x + plot.area().width + 22, ly = plot.area().y + 14;
  cv::rectangle(canvas, {lx - 8, ly - 12}, {layout.width - 8, ly + 20 * 4 + 14},
                cv::Scalar(180, 180, 180), 1);
  for (std::size_t k = 0; k < series.size(); ++k) {
    const int y = ly + 20 * static_cast<int>(k);
    cv::line(canvas, {lx, y}, {lx + 14, y}, series[k].colour, 2, cv::LINE_AA);
    cv::circle(canvas, {lx + 7, y}, 4, series[k].colour, cv::FILLED, cv::LINE_AA);
    PlainText(canvas, series[k].name, {lx + 20, y + 5}, 0.42);
  }
  PlainText(canvas, "bytes: codes as stored; JPEG", {lx, ly + 20 * 3 + 5}, 0.38);
  PlainText(canvas, "without its shared tables", {lx, ly + 20 * 3 + 21}, 0.38);
  return canvas;
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
  if (!fs::is_directory(flags.data)) {
    throw DatasetError("--data '" + flags.data + "': no such dataset folder");
  }
  const int threads = ResolveThreads(flags.threads);
  const FunctaModel model = FunctaModel::Load(flags.model);
  const Functaset functaset = Functaset::Load(flags.functaset);
  functaset.CheckModel(model, flags.model, flags.functaset);
  const Dataset dataset = Dataset::Open(flags.data);

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
  }

  // The pose model's sensor (from its info, as train-pose writes it; else the first).
  SensorKind pose_sensor = sensors[0];
  {
    const PoseMlp probe = PoseMlp::Load(flags.pose_model);
    const nlohmann::json info = nlohmann::json::parse(probe.info_json(), nullptr, false);
    if (info.is_object() && info.contains("sensor") && info["sensor"].is_string()) {
      SensorKind kind;
      if (!SensorKindFromString(info["sensor"].get<std::string>(), &kind)) {
        throw DatasetError("--pose-model '" + flags.pose_model + "' names an unknown sensor '" +
                           info["sensor"].get<std::string>() + "'");
      }
      pose_sensor = kind;
    }
    if (std::find(sensors.begin(), sensors.end(), pose_sensor) == sensors.end()) {
      throw DatasetError("--pose-model '" + flags.pose_model + "' was trained on " +
                         ToString(pose_sensor) + " latents, which are not evaluated (--sensors)");
    }
  }
  const PoseMlp pose_model = LoadPoseModelFor(flags.pose_model, model, pose_sensor, flags.model);
  const nlohmann::json pose_info = nlohmann::json::parse(pose_model.info_json(), nullptr, false);

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

  fs::create_directories(flags.out);
  std::vector<Row> rows;
  std::map<SensorKind, RdCurves> curves;
  nlohmann::json targets = nlohmann::json::object();
  nlohmann::json details = nlohmann::json::object();
  bool all_met = true;

  for (SensorKind sensor : sensors) {
    const SensorTrunk& trunk = model.Trunk(sensor);
    const SensorFrames s = LoadSensorFrames(functaset, trunk, dataset, flags.data, threads);
    if (s.train.empty()) {
      throw DatasetError("--functaset '" + flags.functaset + "' has no train-split " +
                         ToString(sensor) + " entries: the baselines are fitted on those");
    }
    const std::uint64_t m = s.entries.size();
    const int d = functaset.latent_dim(sensor);
    const int channels = static_cast<int>(s.targets[0].values.cols());
    std::vector<const TrunkTargets*> all_targets = s.Targets(s.train);
    {
      const std::vector<const TrunkTargets*> test_targets = s.Targets(s.test);
      all_targets.insert(all_targets.end(), test_targets.begin(), test_targets.end());
    }
    std::cout << "eval: " << ToString(sensor) << ": " << s.train.size() << " train + "
              << s.test.size() << " test frames at " << trunk.format.rows << "x"
              << trunk.format.cols << "x" << channels << ", latent " << d << " floats\n";
    nlohmann::json sensor_details;

    // -- TactFunc ------------------------------------------------------------------------
    std::vector<const TrunkTargets*> frame_targets;
    for (const TrunkTargets& t : s.targets) frame_targets.push_back(&t);
    const std::vector<double> tf_psnr = LatentPsnrs(
        trunk, s.entries, frame_targets, threads, std::string("eval: TactFunc ") + ToString(sensor));
    const std::uint64_t trunk_bytes = 4ull * (trunk.siren.NumParameters() + trunk.alpha.size());
    // Bytes per frame as stored (4 or 2 per latent float: encode --latent-precision).
    const double tf_frame_bytes = static_cast<double>(functaset.BytesPerLatentFloat()) * d;
    const std::uint64_t tf_rep = trunk_bytes + m * static_cast<std::uint64_t>(tf_frame_bytes);
    curves[sensor].tactfunc.push_back(
        {tf_frame_bytes, MeanPsnr(Pick(tf_psnr, s.test)), "d=" + std::to_string(d)});

    // -- PCA -----------------------------------------------------------------------------
    const Eigen::MatrixXf train_matrix = StackFrames(s.Targets(s.train));
    std::set<int> sweep = {std::max(1, d / 4), std::max(1, d / 2), d, 2 * d, 4 * d};
    for (const Extra& e : extras) {
      if (e.functaset.has_sensor(sensor)) sweep.insert(e.functaset.latent_dim(sensor));
    }
    PcaCodec::Options pca_options;
    pca_options.components = *sweep.rbegin();
    PcaCodec::Summary pca_summary;
    std::cout << "eval: fitting PCA (cv::PCA) on " << s.train.size() << " frames of "
              << train_matrix.cols() << " floats..." << std::endl;
    const PcaCodec pca_full = PcaCodec::Fit(train_matrix, pca_options, &pca_summary);
    std::cout << pca_summary.BriefReport() << "\n";
    const int pca_n = std::min(d, pca_full.components());
    const PcaCodec pca = pca_full.Truncated(pca_n);
    Eigen::MatrixXf all_matrix(static_cast<Eigen::Index>(m), train_matrix.cols());
    for (std::size_t i = 0; i < m; ++i) all_matrix.row(i) = FlattenFrame(s.targets[i]);
    const Eigen::MatrixXf full_codes = pca_full.Encode(all_matrix);  // m x n_max
    auto pca_psnrs = [&](int n) {
      const Eigen::MatrixXf decoded = pca_full.Truncated(n).Decode(full_codes.leftCols(n));
      std::vector<double> psnr(m);
      for (std::size_t i = 0; i < m; ++i) {
        psnr[i] = Psnr(UnflattenFrame(decoded.row(i), channels), s.targets[i]);
      }
      return psnr;
    };
    const std::vector<double> pca_psnr = pca_psnrs(pca_n);
    for (int n : sweep) {
      if (n > pca_full.components()) continue;
      curves[sensor].pca.push_back(
          {4.0 * n, MeanPsnr(Pick(pca_psnrs(n), s.test)), "n=" + std::to_string(n)});
    }
    std::string pca_note;
    if (pca_n < d) {
      pca_note = "only " + std::to_string(pca_n) + " components (train frames)";
    }

    // -- JPEG ----------------------------------------------------------------------------
    JpegCodec::Options jpeg_options;
    JpegRangeOfFrames(s.Targets(s.train), &jpeg_options.lo, &jpeg_options.hi);
    const JpegQualitySearchSummary search =
        FindJpegQuality(s.Targets(s.train), jpeg_options, tf_frame_bytes);
    std::cout << search.BriefReport() << "\n";
    jpeg_options.quality = search.quality;
    auto jpeg_eval = [&](const JpegCodec::Options& o, std::vector<double>* psnr,
                         std::vector<double>* bytes) {
      const JpegCodec codec(o);
      psnr->assign(m, kNan);
      bytes->assign(m, 0);
      ParallelFor(m, threads, nullptr, [&](std::size_t i) {
        Eigen::MatrixXf decoded;
        (*bytes)[i] = static_cast<double>(
            codec.EncodeDecode(s.targets[i].values, s.targets[i].rows, s.targets[i].cols, &decoded));
        (*psnr)[i] = Psnr(decoded, s.targets[i]);
      });
    };
    std::vector<double> jpeg_psnr, jpeg_bytes;
    jpeg_eval(jpeg_options, &jpeg_psnr, &jpeg_bytes);
    const std::uint64_t jpeg_tables =
        JpegCodec(jpeg_options).TableBytes(s.targets[0].values, s.targets[0].rows, s.targets[0].cols);
    double jpeg_total = 0;
    for (double b : jpeg_bytes) jpeg_total += b;
    const std::uint64_t jpeg_rep = jpeg_tables + static_cast<std::uint64_t>(jpeg_total);
    for (int quality : {1, 3, 5, 10, 20, 30, 50, 70, 90}) {
      JpegCodec::Options o = jpeg_options;
      o.quality = quality;
      std::vector<double> p, b;
      jpeg_eval(o, &p, &b);
      const std::vector<double> test_bytes = Pick(b, s.test.empty() ? s.train : s.test);
      double mean_bytes = 0;
      for (double v : test_bytes) mean_bytes += v / test_bytes.size();
      curves[sensor].jpeg.push_back(
          {mean_bytes, MeanPsnr(Pick(p, s.test)), "q=" + std::to_string(quality)});
    }

    // -- Raw frames ----------------------------------------------------------------------
    const std::uint64_t raw_frame = RawFrameBytes(dataset.sensor_info(sensor));

    // -- Extra TactFunc points -----------------------------------------------------------
    for (const Extra& e : extras) {
      if (!e.functaset.has_sensor(sensor)) continue;
      const SensorTrunk& t2 = e.model.Trunk(sensor);
      std::vector<const FunctasetEntry*> test_entries;
      for (const FunctasetEntry& entry : e.functaset.entries(sensor)) {
        if (entry.split == Split::kTest) test_entries.push_back(&entry);
      }
      std::vector<TrunkTargets> own(test_entries.size());
      std::vector<const TrunkTargets*> t_targets(test_entries.size());
      const bool same_format = t2.format.rows == trunk.format.rows &&
                               t2.format.cols == trunk.format.cols &&
                               t2.format.grayscale == trunk.format.grayscale &&
                               t2.format.per_image_min_max == trunk.format.per_image_min_max &&
                               t2.format.scale == trunk.format.scale;
      for (std::size_t k = 0; k < test_entries.size(); ++k) {
        const std::optional<std::size_t> in_main = functaset.Find(sensor, test_entries[k]->id);
        if (same_format && in_main) {
          t_targets[k] = &s.targets[*in_main];
          continue;
        }
        const std::optional<std::size_t> index = dataset.FindFrame(test_entries[k]->id, sensor);
        if (!index) {
          throw DatasetError("--data '" + flags.data + "' has no " + ToString(sensor) + " frame '" +
                             test_entries[k]->id + "' of --extra-functaset '" + e.functaset_path + "'");
        }
        own[k] = LoadTrunkTargets(dataset, *index, t2.format);
        t_targets[k] = &own[k];
      }
      const int d2 = e.functaset.latent_dim(sensor);
      const std::vector<double> psnr =
          LatentPsnrs(t2, test_entries, t_targets, threads,
                      "eval: TactFunc d=" + std::to_string(d2) + " " + ToString(sensor));
      curves[sensor].tactfunc.push_back({e.functaset.BytesPerLatentFloat() * 1.0 * d2, MeanPsnr(psnr), "d=" + std::to_string(d2)});
    }

    // -- Poses ---------------------------------------------------------------------------
    std::map<std::pair<std::string, Split>, PoseErrors> pose;
    if (sensor == pose_sensor) {
      const PoseSamples train = LabelledSamples(s, Split::kTrain);
      const PoseSamples test = LabelledSamples(s, Split::kTest);
      if (train.frames.empty()) {
        throw DatasetError("--functaset '" + flags.functaset + "' has no labelled train-split " +
                           ToString(sensor) + " entries: the pose baselines are trained on those");
      }
      Eigen::MatrixXf latents(static_cast<Eigen::Index>(m), d);
      for (std::size_t i = 0; i < m; ++i) latents.row(i) = s.entries[i]->latent.transpose();
      const Eigen::MatrixXf codes = full_codes.leftCols(pca_n);
      const int factor = flags.raw_downsample;
      Eigen::MatrixXf pixels;
      for (std::size_t i = 0; i < m; ++i) {
        const Eigen::RowVectorXf row = DownsamplePixels(s.targets[i], factor);
        if (i == 0) pixels.resize(static_cast<Eigen::Index>(m), row.size());
        pixels.row(i) = row;
      }
      auto score = [&](const std::string& key, const auto& predict) {
        for (const PoseSamples* p : {&train, &test}) {
          if (p->frames.empty()) continue;
          const Split split = p == &train ? Split::kTrain : Split::kTest;
          pose[{key, split}] =
              ScorePoses(predict(p->frames, p->targets.symmetry_orders), p->targets.poses,
                         p->targets.symmetry_orders);
        }
      };
      // TactFunc: P on the latents.
      score("tactfunc", [&](const std::vector<std::size_t>& f, const Eigen::VectorXi& n) {
        return PredictPoses(pose_model, Rows(latents, f), n);
      });
      // PCA codes: the same architecture, trained as P was (its info: epochs, batch,
      // learning rate, seed; train-pose's defaults where it says nothing).
      PoseMlp::Options mlp_options = pose_model.options();
      mlp_options.input_dim = pca_n;
      PoseMlpTrainingOptions training;
      const nlohmann::json& info = pose_info;
      if (info.is_object()) {
        training.epochs = info.value("epochs", training.epochs);
        training.batch_size = info.value("batch", training.batch_size);
        training.learning_rate = info.value("learning_rate", training.learning_rate);
        training.seed = info.value("seed", training.seed);
      }
      PoseMlp pca_mlp(mlp_options, training.seed);
      {
        ProgressBar bar("eval: pose MLP on PCA codes", training.epochs, "epochs");
        const PoseMlpTrainingSummary summary =
            TrainPoseMlp(&pca_mlp, Rows(codes, train.frames), train.targets, training,
                         [&](int, double) {
                           bar.Tick();
                           return true;
                         });
        bar.Finish();
        std::cout << "eval: pose MLP on PCA codes: " << summary.BriefReport() << "\n";
        if (summary.termination == PoseMlpTrainingTermination::kNonFinite) {
          std::cerr << "eval: warning: the pose MLP on PCA codes diverged (" << summary.message
                    << "); its last finite parameters are scored\n";
        }
      }
      score("pca", [&](const std::vector<std::size_t>& f, const Eigen::VectorXi& n) {
        return PredictPoses(pca_mlp, Rows(codes, f), n);
      });
      // Raw pixels: ridge and k-NN.
      RidgePoseRegressor::Options ridge_options;
      ridge_options.position_scale = pose_model.options().position_scale;
      RidgePoseRegressor::Summary ridge_summary;
      const RidgePoseRegressor ridge = RidgePoseRegressor::Fit(
          Rows(pixels, train.frames), train.targets, ridge_options, &ridge_summary);
      std::cout << "eval: " << ridge_summary.BriefReport() << "\n";
      score("ridge", [&](const std::vector<std::size_t>& f, const Eigen::VectorXi& n) {
        return ridge.Predict(Rows(pixels, f), n);
      });
      KnnPoseRegressor::Options knn_options;
      knn_options.k = flags.knn_k;
      const KnnPoseRegressor knn(Rows(pixels, train.frames), train.targets, knn_options);
      score("knn", [&](const std::vector<std::size_t>& f, const Eigen::VectorXi& n) {
        return knn.Predict(Rows(pixels, f), n);
      });
      sensor_details["pose"] = {
          {"mlp_hidden", pose_model.options().hidden_sizes},
          {"mlp_epochs", training.epochs},
          {"mlp_batch", training.batch_size},
          {"mlp_learning_rate", training.learning_rate},
          {"ridge_relative_lambda", ridge_summary.relative_lambda},
          {"ridge_lambda", ridge_summary.lambda},
          {"raw_downsample", factor},
          {"raw_features", pixels.cols()},
          {"knn_k", flags.knn_k},
          {"labelled_train", train.frames.size()},
          {"labelled_test", test.frames.size()}};
    }

    // -- Rows ----------------------------------------------------------------------------
    const std::string down = std::to_string(flags.raw_downsample);
    for (Split split : {Split::kTrain, Split::kTest}) {
      const std::vector<std::size_t>& idx = s.Of(split);
      if (idx.empty()) continue;
      auto find_pose = [&](const std::string& key) {
        const auto it = pose.find({key, split});
        return it == pose.end() ? PoseErrors() : it->second;
      };
      const bool posed = sensor == pose_sensor;
      Row tf{"TactFunc", posed ? "pose MLP on latents" : "", sensor, split, tf_rep, tf_frame_bytes,
             MeanPsnr(Pick(tf_psnr, idx)), true, static_cast<int>(idx.size()),
             find_pose("tactfunc"), ""};
      Row pc{"PCA", posed ? "pose MLP on PCA codes" : "", sensor, split,
             pca.ModelBytes() + m * pca.BytesPerFrame(), static_cast<double>(pca.BytesPerFrame()),
             MeanPsnr(Pick(pca_psnr, idx)), true, static_cast<int>(idx.size()), find_pose("pca"),
             pca_note};
      double jb = 0;
      for (std::size_t i : idx) jb += jpeg_bytes[i] / idx.size();
      Row jp{"JPEG", "", sensor, split, jpeg_rep, jb, MeanPsnr(Pick(jpeg_psnr, idx)), true,
             static_cast<int>(idx.size()), PoseErrors(),
             "quality " + std::to_string(search.quality)};
      Row raw_ridge{"Raw frames", posed ? "ridge on pixels /" + down : "", sensor, split,
                    m * raw_frame, static_cast<double>(raw_frame), kNan, false,
                    static_cast<int>(idx.size()), find_pose("ridge"), ""};
      rows.push_back(tf);
      rows.push_back(pc);
      rows.push_back(jp);
      rows.push_back(raw_ridge);
      if (posed) {
        Row raw_knn = raw_ridge;
        raw_knn.pose_from = "k-NN (k=" + std::to_string(flags.knn_k) + ") on pixels /" + down;
        raw_knn.pose = find_pose("knn");
        rows.push_back(raw_knn);
      }
    }

    // -- Targets (test split) --------------------------------------------------------------
    const double tf_test = MeanPsnr(Pick(tf_psnr, s.test));
    // The PSNR target compares at equal bytes per frame: PCA with as many float32
    // components as TactFunc's stored latent has bytes / 4 (= d for float32 latents,
    // d / 2 for float16 ones); the PCA row itself keeps d components (the row).
    const int pca_equal_n =
        std::max(1, std::min(pca_full.components(), static_cast<int>(tf_frame_bytes / 4)));
    const double pca_test = pca_equal_n == pca_n ? MeanPsnr(Pick(pca_psnr, s.test))
                                                 : MeanPsnr(Pick(pca_psnrs(pca_equal_n), s.test));
    const double jpeg_test = MeanPsnr(Pick(jpeg_psnr, s.test));
    double jpeg_test_bytes = 0;
    for (std::size_t i : s.test) jpeg_test_bytes += jpeg_bytes[i] / s.test.size();
    nlohmann::json t;
    const bool pca_met = std::isfinite(tf_test) && std::isfinite(pca_test) && tf_test >= pca_test + 3;
    t["psnr_3db_above_pca"] = {{"met", pca_met},
                               {"tactfunc_db", NumberOrNull(tf_test)},
                               {"pca_db", NumberOrNull(pca_test)},
                               {"margin_db", NumberOrNull(tf_test - pca_test)},
                               {"required_margin_db", 3},
                               {"pca_components", pca_equal_n},
                               {"bytes_per_frame", tf_frame_bytes}};
    const bool jpeg_met = std::isfinite(tf_test) && std::isfinite(jpeg_test) && tf_test > jpeg_test;
    t["psnr_above_jpeg"] = {{"met", jpeg_met},
                            {"tactfunc_db", NumberOrNull(tf_test)},
                            {"jpeg_db", NumberOrNull(jpeg_test)},
                            {"margin_db", NumberOrNull(tf_test - jpeg_test)},
                            {"tactfunc_bytes_per_frame", tf_frame_bytes},
                            {"jpeg_bytes_per_frame", NumberOrNull(jpeg_test_bytes)},
                            {"jpeg_quality", search.quality},
                            {"jpeg_target_reachable", search.target_reachable}};
    all_met = all_met && pca_met && jpeg_met;
    if (sensor == pose_sensor) {
      const auto mse = [&](const std::string& key) {
        const auto it = pose.find({key, Split::kTest});
        return it == pose.end() ? kNan : it->second.PoseMse();
      };
      const double tf_mse = mse("tactfunc"), pca_mse = mse("pca");
      const double raw_mse = std::min(mse("ridge"), mse("knn"));
      const bool beats_pca = std::isfinite(tf_mse) && std::isfinite(pca_mse) && tf_mse < pca_mse;
      const bool not_worse_raw =
          std::isfinite(tf_mse) && std::isfinite(raw_mse) && tf_mse <= raw_mse;
      t["pose_beats_pca_codes"] = {{"met", beats_pca},
                                   {"tactfunc_pose_mse", NumberOrNull(tf_mse)},
                                   {"pca_pose_mse", NumberOrNull(pca_mse)}};
      t["pose_not_worse_than_raw"] = {{"met", not_worse_raw},
                                      {"tactfunc_pose_mse", NumberOrNull(tf_mse)},
                                      {"raw_best_pose_mse", NumberOrNull(raw_mse)},
                                      {"ridge_pose_mse", NumberOrNull(mse("ridge"))},
                                      {"knn_pose_mse", NumberOrNull(mse("knn"))}};
      all_met = all_met && beats_pca && not_worse_raw;
    }
    targets[ToString(sensor)] = t;
    sensor_details["pca"] = {{"components", pca_n},
                             {"explained_variance", pca_summary.explained_variance},
                             {"fit_seconds", pca_summary.seconds}};
    sensor_details["jpeg"] = {{"quality", search.quality},
                              {"target_bytes", search.target_bytes},
                              {"mean_train_bytes", search.mean_bytes},
                              {"bracket", {search.below, search.below + 1}},
                              {"target_reachable", search.target_reachable},
                              {"range", {jpeg_options.lo, jpeg_options.hi}},
                              {"table_bytes", jpeg_tables}};
    sensor_details["working_resolution"] = {trunk.format.rows, trunk.format.cols, channels};
    sensor_details["raw_frame_bytes"] = raw_frame;
    details[ToString(sensor)] = sensor_details;
  }

  // ---- Output ------------------------------------------------------------------------------
  const nlohmann::json machine = MachineDescription();
  std::string command;
  for (const std::string& a : flags.argv) {
    if (!a.empty()) command += (command.empty() ? "" : " ") + a;
  }
  std::ostringstream md;
  md << "| approach | pose from | sensor | split | rep. size (MB) | bytes/frame | PSNR (dB) | "
        "pose MSE | RMSE (mm) | RMSE (deg) |\n"
     << "|---|---|---|---|---:|---:|---:|---:|---:|---:|\n";
  for (const Row& r : rows) {
    const bool has_pose = r.pose.count > 0;
    md << "| " << r.approach << (r.note.empty() ? "" : " (" + r.note + ")") << " | "
       << (r.pose_from.empty() ? "-" : r.pose_from) << " | " << ToString(r.sensor) << " | "
       << ToString(r.split) << " | " << FormatFixed(r.rep_bytes / 1e6, 3, "-") << " | "
       << FormatFixed(r.bytes_per_frame, 0, "-") << " | "
       << (r.psnr_applicable ? FormatFixed(r.psnr, 2, "-") : std::string("n/a (lossless)")) << " | "
       << (has_pose ? Sci(r.pose.PoseMse()) : "-") << " | "
       << (has_pose ? FormatFixed(r.pose.RmseMm(), 3, "-") : "-") << " | "
       << (has_pose ? FormatFixed(r.pose.RmseDeg(), 2, "-") : "-") << " |\n";
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
    const nlohmann::json& b = t["psnr_above_jpeg"];
    targets_md << "- " << sensor << ": TactFunc above JPEG at matched bytes (test): " << yes(b)
               << " (" << num(b["tactfunc_db"], 2) << " dB at " << num(b["tactfunc_bytes_per_frame"], 0)
               << " B vs " << num(b["jpeg_db"], 2) << " dB at " << num(b["jpeg_bytes_per_frame"], 0)
               << " B, quality " << b["jpeg_quality"]
               << (b["jpeg_target_reachable"].get<bool>() ? "" : "; even quality 1 is larger")
               << ")\n";
    if (t.contains("pose_beats_pca_codes")) {
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
       << "\nrep. size: model + per-frame data for every frame of the sensor (train + test). "
          "bytes/frame: codes as stored (TactFunc latents float16 by default, PCA float32); JPEG without its shared tables "
          "(counted once in rep. size); raw: rows x cols x channels x bytes per sample at the "
          "native resolution. PSNR: mean over the split's frames of THE PSNR of "
          "estimation/data/trunk_targets.h at the model's working resolution (n/a for raw frames: "
          "lossless). pose MSE: mean over frames of (dx^2 + dy^2 + dyaw^2) / 3 in m and rad, "
          "yaw modulo the tool's symmetry.\n\nTargets:\n\n"
       << targets_md.str();
  WriteTextFile((fs::path(flags.out) / "table.md").string(), file.str());

  // One rate-distortion panel per sensor, stacked.
  std::vector<cv::Mat> panels;
  nlohmann::json rd = nlohmann::json::object();
  for (SensorKind sensor : sensors) {
    const RdCurves& c = curves[sensor];
    panels.push_back(RateDistortionPlot(
        sensor, c,
        std::string("test split; PSNR of estimation/data/trunk_targets.h at the working resolution; ") +
            machine.value("cpu", std::string("?"))));
    rd[ToString(sensor)] = {{"tactfunc", RdJson(c.tactfunc)},
                            {"pca", RdJson(c.pca)},
                            {"jpeg", RdJson(c.jpeg)}};
  }
  cv::Mat picture;
  cv::vconcat(panels, picture);
  const std::string plot_path = (fs::path(flags.out) / "rate_distortion.png").string();
  WritePicture(plot_path, picture);

  nlohmann::json rows_json = nlohmann::json::array();
  for (const Row& r : rows) rows_json.push_back(RowJson(r));
  nlohmann::json result = {{"rows", rows_json},
                           {"targets", targets},
                           {"all_targets_met", all_met},
                           {"rate_distortion", rd},
                           {"details", details},
                           {"pose_sensor", ToString(pose_sensor)},
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
                  "Pose model (.tpm) from `tactfunc train-pose` on this functaset")
      ->required();
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
  sub->add_flag("--json", flags->json, "Print {rows, targets, rate_distortion, ...} as one JSON line");
  sub->callback([flags, selected]() {
    flags->argv = {"tactfunc eval", "--data " + flags->data, "--model " + flags->model,
                   "--functaset " + flags->functaset, "--pose-model " + flags->pose_model,
                   "--out " + flags->out,
                   flags->sensors.empty() ? "" : "--sensors " + flags->sensors};
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
