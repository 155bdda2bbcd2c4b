// Copyright 2026 The tactfunc Authors.
//
// tactfunc fit: the latent of ONE new frame under a trained model (Sec. III-C of
// "Tactile Functasets"), with any LatentFitter strategy (estimation/fitting/latent_fitter.h):
//
//   tactfunc fit --model M.tfm --frame F.png --reference R.png --strategy ceres:10
//   tactfunc fit --model M.tfm --functaset S.tfs --frame F.png --reference R.png
//       --strategy knn+ceres:5 --out DIR --json
//
// The frame and its sensor's reference are read in the sensor's on-disk encoding
// (estimation/data/image_io.h); the sensor is --sensor, else inferred from the frame as
// Dataset::Open infers a user folder's (16-bit one-channel = bubble, 8-bit = gelslim).
// They become trunk targets with the model's FrameFormat (estimation/data/trunk_targets.h).
//
// The knn strategies search the functaset's latents of that sensor (all splits) with a
// k-NN index kept beside the functaset as "<functaset>.<sensor>.knn"
// (KnnIndex::Save/Load). The file is reused when it holds exactly the functaset's latents
// (same size, dim and CRC-32 of the vectors) and was built with the requested index type
// and parameters; otherwise (missing, stale, corrupt or other parameters) it is rebuilt
// and saved atomically, so a crash never leaves a half-written index.
//
// A photometric trunk (train --head photometric; models/trunk/photometric_trunk.h) is
// fitted as `encode` fits it, by the same LatentEncoder code, so a frame gets the latent
// encode would give it: knn+adam:N (the default where the model holds a warm-start
// table), knn+ceres:N, knn or adam:N (the default without one); its k-NN runs over the
// model's own table, so --functaset, --precision, --jacobian, --sigma, --sigma-z and
// --max-pixels (the direct trunk's Ceres and meta-SGD problem) do not apply and are
// refused.
//
// With --out DIR it writes DIR/latent.json ({sensor, latent, strategy, psnr, ms,
// termination, ...}) and DIR/fit.png (target | reconstruction | error, labelled with the
// PSNR and time).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <limits>
#include <memory>
#include <optional>
#include <utility>
#include <opencv2/imgproc.hpp>

#include "CLI/CLI.hpp"
#include "apps/command.h"
#include "apps/model_inputs.h"
#include "apps/output_paths.h"
#include "apps/pictures.h"
#include "estimation/data/dataset.h"
#include "estimation/data/image_io.h"
#include "estimation/data/photometric_markers.h"
#include "estimation/functaset/functaset.h"
#include "estimation/functaset/latent_encoder.h"
#include "estimation/knn/knn_index.h"
#include "estimation/fitting/latent_fitter.h"
#include "estimation/evaluation/reconstruction.h"
#include "estimation/data/trunk_targets.h"
#include "models/core/atomic_file.h"
#include "models/trunk/functa_model.h"
#include "models/core/tensor_file.h"

namespace tactfunc::apps {
namespace {

namespace fs = std::filesystem;

struct FitFlags {
  std::string model;
  std::string functaset;
  std::string frame;
  std::string reference;
  std::string sensor;
  std::string sensor_file;
  bool allow_other_frames = false;
  std::string strategy;  // "": ceres:10, or the encoder's default for a photometric trunk
  std::string out;
  std::string precision = "float";
  std::string products = "float";
  std::string jacobian = "analytic";
  std::string knn_index = "brute_force";
  int knn_k = 8;
  int knn_checks = 256;
  double sigma = 0;
  double sigma_z = 1.0;
  int max_pixels = 0;
  int tile_height = 180;
  bool full_report = false;
  bool json = false;
};

// ---- The k-NN index beside the functaset -------------------------------------------------

// The index options of --knn-index and --knn-checks (fit's FLANN build parameters are
// the defaults).
KnnIndexOptions IndexOptions(const FitFlags& flags) {
  KnnIndexOptions options;
  FlannKnnIndex::Algorithm algorithm;
  if (flags.knn_index != "brute_force" &&
      (!FlannAlgorithmFromString(flags.knn_index, &algorithm) ||
       algorithm == FlannKnnIndex::Algorithm::kAutotuned)) {
    // Autotuning takes minutes and tunes recall@1 (docs/FITTING.md): not offered here.
    throw UsageError("--knn-index: expected brute_force, kd_forest, kmeans or linear, got '" +
                     flags.knn_index + "'");
  }
  options.type = flags.knn_index;
  options.search.checks = flags.knn_checks;
  return options;
}

// Loads "<functaset>.<sensor>.knn" if it is current, else builds the index and saves it
// there atomically (LoadOrBuildKnnIndex). Prints what it did to stderr.
std::unique_ptr<KnnIndex> LoadOrBuildIndex(const std::string& functaset_path, SensorKind sensor,
                                           const Functaset::LatentMatrix& latents,
                                           const FitFlags& flags, std::string* index_path,
                                           bool* rebuilt) {
  *index_path = functaset_path + "." + ToString(sensor) + ".knn";
  KnnIndexCacheSummary summary;
  std::unique_ptr<KnnIndex> index =
      LoadOrBuildKnnIndex(*index_path, latents, IndexOptions(flags), &summary);
  if (summary.rebuilt && summary.save_error.empty()) {
    std::cerr << "fit: note: built the k-NN index " << *index_path << " ("
              << summary.why_rebuilt << ")\n";
  } else if (summary.rebuilt) {
    // A read-only functaset folder must not stop the fit: the index is then used unsaved.
    std::cerr << "fit: warning: could not save the k-NN index " << *index_path << ": "
              << summary.save_error << "\n";
  }
  *rebuilt = summary.rebuilt;
  return index;
}

// ---- The picture -------------------------------------------------------------------------

void WriteFitPicture(const std::string& path, const TrunkTargets& target,
                     const Eigen::MatrixXf& recon, const LatentFitter::Summary& summary,
                     SensorKind sensor, int height) {
  const int rows = target.rows, cols = target.cols, n = rows * cols;
  const auto [lo, hi] = ValidValueRange(target);
  double error_scale = 0;
  Image error(rows, cols, 1);
  for (int j = 0; j < n; ++j) {
    if (!(target.weights[j] > 0)) {
      error.data[j] = std::numeric_limits<float>::quiet_NaN();
      continue;
    }
    error.data[j] = (recon.row(j) - target.values.row(j)).mean();
    error_scale = std::max<double>(error_scale, std::abs(error.data[j]));
  }
  if (!(error_scale > 0)) error_scale = 1.0;
  const cv::Mat target_tile =
      FitHeight(ValueTile(target.values, target.weights, rows, cols, lo, hi), height);
  const cv::Mat recon_tile =
      FitHeight(ValueTile(recon, target.weights, rows, cols, lo, hi), height);
  const cv::Mat error_tile = FitHeight(DifferenceTile(error, error_scale), height);
  const int w = target_tile.cols;
  char error_title[64];
  std::snprintf(error_title, sizeof(error_title), "error (+-%.3g)", error_scale);
  const std::string headline =
      std::string(ToString(sensor)) + " " + std::to_string(rows) + "x" + std::to_string(cols) +
      "  " + summary.strategy.ToString() + ": PSNR " + FormatFixed(summary.psnr, 2) + " dB, " +
      FormatFixed(summary.total_time_ms, 1) + " ms, " + ToString(summary.termination_type);
  cv::Mat title(26, 3 * w + 8, CV_8UC3, kBackground);
  PutLabel(title, headline, {6, 18}, 0.45);
  WritePicture(
      path, TileGrid({{title},
                      {Caption(w, "target"), Caption(w, "reconstruction"), Caption(w, error_title)},
                      {target_tile, recon_tile, error_tile}}));
}

nlohmann::json FiniteOrNull(double value) {
  return std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(nullptr);
}

// ---- The command -------------------------------------------------------------------------

// The photometric trunk's fit (header comment): `encode`'s own per-frame fit. Fills the
// parts of a LatentFitter::Summary that describe it (no Ceres stage, no costs).
LatentFitter::Summary FitPhotometric(const FunctaModel& model, SensorKind sensor,
                                     const TrunkTargets& targets,
                                     const PhotometricTrunk::Markers& markers,
                                     const FitFlags& flags, Eigen::VectorXd* latent) {
  std::vector<std::string> direct_only;
  if (!flags.functaset.empty()) direct_only.push_back("--functaset");
  if (flags.precision != "float") direct_only.push_back("--precision");
  if (flags.jacobian != "analytic") direct_only.push_back("--jacobian");
  if (flags.sigma != 0) direct_only.push_back("--sigma");
  if (flags.sigma_z != FitFlags().sigma_z) direct_only.push_back("--sigma-z");
  if (flags.max_pixels != 0) direct_only.push_back("--max-pixels");
  if (!direct_only.empty()) {
    std::string names;
    for (const std::string& name : direct_only) names += (names.empty() ? "" : ", ") + name;
    throw UsageError(names + ": the " + ToString(sensor) + " trunk of '" + flags.model +
                     "' is photometric; its latents are fitted with adam:N, knn+adam:N, "
                     "knn+ceres:N or knn (k-NN over the model's own warm-start table), which "
                     "these options do not apply to");
  }
  LatentEncoder::Options options;
  options.strategy = flags.strategy;
  options.sensors = {sensor};
  std::optional<LatentEncoder> encoder;
  try {
    encoder.emplace(model, options);
  } catch (const std::invalid_argument& e) {
    throw UsageError((flags.strategy.empty() ? std::string("the model's default fit")
                                             : "--strategy " + flags.strategy) +
                     ": " + e.what());
  }
  EncodedFrameFit fitted = EncodeFrame(*encoder, sensor, targets, &markers);
  LatentFitter::Summary summary;
  summary.total_time_ms = fitted.ms;
  summary.strategy = encoder->StrategyOf(sensor);
  summary.termination_type = FitTermination::kCompleted;
  summary.psnr = fitted.psnr;
  summary.iterations = summary.strategy.steps;
  summary.initial_cost = summary.final_cost = std::numeric_limits<double>::quiet_NaN();
  *latent = std::move(fitted.latent);
  return summary;
}

void RunFit(const FitFlags& flags) {
  FitStrategy strategy;
  std::string error;
  if (!flags.strategy.empty() && !FitStrategy::Parse(flags.strategy, &strategy, &error))
    throw UsageError("--strategy: " + error);
  if (flags.strategy.empty()) strategy = FitStrategy::FromString("ceres:10");
  LatentFitter::Options options;
  options.strategy = strategy;
  options.knn_k = flags.knn_k;
  LatentProblem::Options problem_options;
  problem_options.sigma = flags.sigma;
  problem_options.sigma_z = flags.sigma_z;
  problem_options.max_pixels = flags.max_pixels;
  if (flags.precision == "double") {
    problem_options.precision = LatentProblem::Precision::kDouble;
  } else if (flags.precision != "float") {
    throw UsageError("--precision: expected float or double, got '" + flags.precision + "'");
  }
  if (flags.jacobian == "autodiff") {
    options.jacobian = LatentFitter::JacobianMode::kAutoDiff;
  } else if (flags.jacobian != "analytic") {
    throw UsageError("--jacobian: expected analytic or autodiff, got '" + flags.jacobian + "'");
  }
  if (!problem_options.IsValid(&error) || !options.IsValid(&error)) throw UsageError(error);

  // --sensor-file: the frames are raw camera frames of that sensor; its kind is the
  // sensor and its geometry is applied to both before they are compared.
  const FramePair pair =
      ReadFramePair(flags.frame, flags.reference, flags.sensor, flags.sensor_file);
  const SensorKind sensor = pair.sensor;
  const std::optional<SensorDescription>& description = pair.description;
  const Image& frame = pair.frame;
  const Image& reference = pair.reference;

  ApplyProductPrecision(flags.products);
  const FunctaModel model = FunctaModel::Load(flags.model);
  if (!model.HasSensor(sensor)) {
    std::string have;
    for (SensorKind s : model.sensors())
      have += (have.empty() ? "" : ", ") + std::string(ToString(s));
    throw DatasetError("--model '" + flags.model + "' has no trunk for sensor " + ToString(sensor) +
                       " (it has: " + have + "); the frame '" + flags.frame + "' was read as " +
                       ToString(sensor) + (flags.sensor.empty() ? " (inferred)" : ""));
  }
  if (description) {
    CheckModelDescription(model, flags.model, *description,
                          "--sensor-file '" + flags.sensor_file + "'", sensor, "fit",
                          "--allow-other-frames", flags.allow_other_frames);
  }
  const SensorTrunk& trunk = model.Trunk(sensor);
  const bool photometric = trunk.photometric != nullptr;
  if (photometric) strategy = FitStrategy();  // the k-NN below is the direct trunk's
  if (strategy.knn && flags.functaset.empty()) {
    throw UsageError("--strategy " + flags.strategy +
                     " needs --functaset (the k-NN search runs over its latents)");
  }
  // Nothing fit writes -- --out's files, the k-NN index cached beside the functaset --
  // may be a file it reads.
  std::vector<NamedPath> inputs = {{"--model", flags.model},
                                   {"--functaset", flags.functaset},
                                   {"--frame", flags.frame},
                                   {"--reference", flags.reference}};
  if (!flags.sensor_file.empty()) inputs.push_back({"--sensor-file", flags.sensor_file});
  std::vector<NamedPath> knn_files;
  if (strategy.knn) {
    for (const char* name : {"bubble", "gelslim"}) {
      knn_files.push_back({"the k-NN index", flags.functaset + "." + name + ".knn"});
    }
    RefuseOutputsThatAreInputs(knn_files, inputs);
  }
  if (!flags.out.empty()) {
    std::vector<NamedPath> outputs = FilesIn("--out", flags.out, {"latent.json", "fit.png"});
    outputs.push_back({"--out", flags.out});
    inputs.insert(inputs.end(), knn_files.begin(), knn_files.end());
    RefuseOutputsThatAreInputs(outputs, inputs);
  }

  const TrunkTargets targets = MakeTrunkTargets(frame, reference, sensor, trunk.format);

  // k-NN: the functaset's latents of this sensor and the index beside the functaset.
  Functaset functaset;
  Eigen::MatrixXf latents;
  std::unique_ptr<KnnIndex> index;
  std::string index_path;
  bool index_rebuilt = false;
  if (strategy.knn) {
    functaset = Functaset::Load(flags.functaset);
    functaset.CheckModel(model, flags.model, flags.functaset);
    if (!functaset.has_sensor(sensor) || functaset.entries(sensor).empty()) {
      throw DatasetError("--functaset '" + flags.functaset + "' has no " + ToString(sensor) +
                         " latents to search");
    }
    const Functaset::LatentMatrix rows = functaset.Latents(sensor);
    index = LoadOrBuildIndex(flags.functaset, sensor, rows, flags, &index_path, &index_rebuilt);
    latents = rows;  // LatentFitter takes the column-major M x d matrix
  }

  Eigen::VectorXd latent;
  LatentFitter::Summary summary;
  // A photometric trunk draws the frame against its own reference (--reference).
  std::shared_ptr<const PhotometricTrunk::Markers> markers;
  if (photometric) {
    markers = FrameMarkers(trunk, reference);
    summary = FitPhotometric(model, sensor, targets, *markers, flags, &latent);
    std::cout << "fit: " << ToString(sensor) << " " << targets.rows << "x" << targets.cols
              << ", PSNR " << FormatFixed(summary.psnr, 2) << " dB in "
              << FormatFixed(summary.total_time_ms, 1) << " ms (" << summary.strategy.ToString()
              << ", photometric trunk)\n";
  } else {
    const LatentFitter fitter = strategy.knn
                                    ? LatentFitter(trunk, options, index.get(), &latents)
                                    : LatentFitter(trunk, options);
    const LatentProblem problem(trunk, targets, problem_options);
    summary = fitter.Fit(problem, &latent);
    std::cout << (flags.full_report ? summary.FullReport() : summary.BriefReport() + "\n");
    std::cout << "fit: " << ToString(sensor) << " " << targets.rows << "x" << targets.cols
              << ", PSNR " << FormatFixed(summary.psnr, 2) << " dB in "
              << FormatFixed(summary.total_time_ms, 1) << " ms ("
              << summary.strategy.ToString() << ", " << ToString(problem_options.precision)
              << ", " << ToString(options.jacobian) << ")\n";
  }
  if (strategy.knn && !summary.neighbor_labels.empty()) {
    const auto& entries = functaset.entries(sensor);
    std::cout << "fit: nearest functaset frame " << entries[summary.neighbor_labels[0]].id
              << " (weight " << FormatFixed(summary.neighbor_weights[0], 3) << ") via "
              << index_path << (index_rebuilt ? " (rebuilt)" : "") << "\n";
  }

  if (!flags.out.empty()) {
    fs::create_directories(flags.out);
    nlohmann::json neighbours = nlohmann::json::array();
    for (std::size_t i = 0; i < summary.neighbor_labels.size(); ++i) {
      neighbours.push_back({{"id", functaset.entries(sensor)[summary.neighbor_labels[i]].id},
                            {"weight", summary.neighbor_weights[i]},
                            {"squared_distance", summary.neighbor_squared_distances[i]}});
    }
    const nlohmann::json record = {
        {"sensor", ToString(sensor)},
        {"latent", std::vector<double>(latent.data(), latent.data() + latent.size())},
        {"strategy", summary.strategy.ToString()},
        {"psnr", FiniteOrNull(summary.psnr)},
        {"ms", summary.total_time_ms},
        {"termination", ToString(summary.termination_type)},
        {"message", summary.message},
        {"iterations", summary.iterations},
        {"initial_cost", FiniteOrNull(summary.initial_cost)},
        {"final_cost", FiniteOrNull(summary.final_cost)},
        {"trunk", photometric ? "photometric" : "direct"},
        {"precision", photometric ? nlohmann::json(nullptr)
                                  : nlohmann::json(ToString(problem_options.precision))},
        {"jacobian", photometric ? nlohmann::json(nullptr)
                                 : nlohmann::json(ToString(options.jacobian))},
        {"frame", flags.frame},
        {"reference", flags.reference},
        {"model", flags.model},
        {"model_checksum", model.checksum()},
        {"neighbours", neighbours}};
    const std::string json_path = (fs::path(flags.out) / "latent.json").string();
    const std::string png_path = (fs::path(flags.out) / "fit.png").string();
    WriteFileAtomically(json_path, record.dump(2) + "\n");
    WriteFitPicture(png_path, targets, Reconstruct(trunk, latent.cast<float>(), markers.get()),
                    summary, sensor, flags.tile_height);
    std::cout << "fit: wrote " << json_path << " and " << png_path << "\n";
  }

  if (flags.json) {
    EmitJson({{"psnr", FiniteOrNull(summary.psnr)},
              {"ms", summary.total_time_ms},
              {"strategy", summary.strategy.ToString()},
              {"termination", ToString(summary.termination_type)},
              {"iterations", summary.iterations},
              {"latent_dim", static_cast<int>(latent.size())},
              {"sensor", ToString(sensor)}});
  }
}

}  // namespace

void RegisterFit(CLI::App& app, CommandBody* selected) {
  auto flags = std::make_shared<FitFlags>();
  CLI::App* sub = app.add_subcommand(
      "fit",
      "Fit the latent of one new frame with a trained model (meta-SGD, Ceres LM, k-NN over a "
      "functaset, or k-NN refined; a photometric trunk as encode fits it); prints PSNR and "
      "time, optionally writes latent.json and fit.png.");
  sub->add_option("--model", flags->model, "Model file (.tfm) from `tactfunc train`")->required();
  sub->add_option("--functaset", flags->functaset,
                  "Functaset (.tfs) of the model, for the knn strategies; its k-NN index is "
                  "kept beside it as <functaset>.<sensor>.knn");
  sub->add_option("--frame", flags->frame, "The frame to fit (PNG/JPG in the sensor's encoding)")
      ->required();
  sub->add_option("--reference", flags->reference,
                  "The sensor's no-contact reference image (same size as the frame)")
      ->required();
  sub->add_option("--sensor", flags->sensor,
                  "bubble or gelslim; default: inferred from the frame (16-bit one-channel = "
                  "bubble, 8-bit = gelslim)");
  sub->add_option("--sensor-file", flags->sensor_file,
                  "The sensor description (docs/DATASET_FORMAT.md) of the raw frames: its crop "
                  "or perspective warp is applied to --frame and --reference, and it must be "
                  "the one the model was trained on");
  sub->add_flag("--allow-other-frames", flags->allow_other_frames,
                "Fit even when --sensor-file is not the description the model's trunk was "
                "trained on (a warning instead of an error)");
  sub->add_option("--strategy", flags->strategy,
                  "knn, meta_sgd:K, ceres:N, knn+meta_sgd:K or knn+ceres:N (default ceres:10); "
                  "for a photometric trunk adam:N, knn+adam:N, knn+ceres:N or knn over the "
                  "model's warm-start table (default: encode's, " +
                      LatentEncoder::DefaultPhotometricStrategy(true, 64) +
                      " with a table and a latent of 64 values, in proportion for longer "
                      "ones; " +
                      LatentEncoder::DefaultPhotometricStrategy(false, 64) + " without)");
  sub->add_option("--out", flags->out, "Folder for latent.json and fit.png (created)");
  sub->add_option("--precision", flags->precision, "float (default) or double trunk evaluations");
  AddProductPrecisionFlag(sub, &flags->products);
  sub->add_option("--jacobian", flags->jacobian,
                  "analytic (default) or autodiff (the slow ceres::Jet reference)");
  sub->add_option("--sigma", flags->sigma,
                  "Pixel noise sigma in normalised units (0 = the model's residual sigma)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--sigma-z", flags->sigma_z, "Latent prior standard deviation")
      ->check(CLI::PositiveNumber);
  sub->add_option("--max-pixels", flags->max_pixels, "Fit at most this many pixels (0 = all)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--knn-k", flags->knn_k, "Neighbours of the knn strategies (default 8)")
      ->check(CLI::Range(1, 1000));
  sub->add_option("--knn-index", flags->knn_index,
                  "brute_force (default: exact, and under 1 ms per query up to ~1e5 latents), "
                  "kd_forest, kmeans or linear");
  sub->add_option("--knn-checks", flags->knn_checks, "FLANN checks per query (default 256)")
      ->check(CLI::Range(1, 1 << 20));
  sub->add_option("--tile-height", flags->tile_height, "fit.png tile height in pixels")
      ->check(CLI::Range(16, 2000));
  sub->add_flag("--full-report", flags->full_report, "Print the Summary's FullReport");
  sub->add_flag("--json", flags->json,
                "Print {psnr, ms, strategy, termination, iterations, latent_dim} as one JSON line");
  sub->callback([flags, selected]() { *selected = [flags]() { RunFit(*flags); }; });
}

}  // namespace tactfunc::apps
