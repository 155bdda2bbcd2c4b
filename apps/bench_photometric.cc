// Copyright 2026 The tactfunc Authors.
//
// tactfunc bench photometric: the optical sensors' photometric trunk
// (models/trunk/photometric_trunk.h) trained, its test latents fitted and stored as
// float16, against PCA at the same bytes per frame, on a dataset with noise-free frames
// (docs/REPRESENTATION.md, "The photometric trunk in C++"):
//
//   tactfunc bench photometric --data D [--train-data T] [--sensor gelslim]
//       [--steps 3000] [--warmup 1000] [--latent-dim 64] [--width 64] [--layers 3]
//       [--fit-steps 200] [--marker-rate 2e-3] [--narrow-biases] [--seed 1] [--threads 1]
//       [--picture F.png] [--json]
//
// The trunk is trained on the train split of T (default D); PCA is fitted on D's train
// split; both code D's test frames (noisy targets, as a user's frames are) and are
// scored by THE PSNR (estimation/data/trunk_targets.h) against the noise-free and the
// noisy targets. Rows: PCA with d / 2 float32 components and PCA with d float16
// components (2 d bytes per frame, the same bits as the trunk's float16 latents), and
// the trunk. The frame format is the sensor's default (GelSlim 80 x 107 grayscale, the
// dataset's fixed scale); the sensor-resolution reference is the dataset's reference
// frame in the same units.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <optional>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "CLI/CLI.hpp"
#include "apps/bench.h"
#include "apps/command.h"
#include "apps/dataset_flags.h"
#include "apps/model_inputs.h"
#include "apps/pictures.h"
#include "estimation/data/dataset.h"
#include "estimation/data/trunk_targets.h"
#include "estimation/evaluation/baselines.h"
#include "estimation/fitting/photometric_ceres_fit.h"
#include "estimation/training/photometric_trainer.h"
#include "estimation/training/photometric_warm_start.h"
#include "estimation/training/trunk_trainer.h"
#include "models/trunk/functa_model.h"
#include "models/core/parallel_for.h"
#include "models/core/seed.h"

namespace tactfunc::apps {
namespace {

struct PhotometricBenchFlags {
  std::string data;
  std::string train_data;
  DatasetFlags dataset;
  int steps = 3000;
  int warmup = 1000;
  int latent_dim = 64;
  int width = 64;
  int layers = 3;
  std::vector<int> fit_steps{PhotometricFitOptions().steps};
  int fit_probe = 0;
  int fit_knn = 0;
  int fit_batch = PhotometricFitOptions().batch_pixels;
  int fit_block = PhotometricFitOptions().pixel_block;
  double fit_contact_share = PhotometricFitOptions().contact_share;
  std::vector<double> fit_rate{PhotometricFitOptions().learning_rate};
  std::vector<int> fit_ceres;  // Ceres iteration counts fitted beside the Adam settings
  int fit_pixels = PhotometricCeresOptions().pixels;
  std::string trade_picture;
  std::string model;
  bool allow_other_frames = false;
  int max_test_frames = 0;
  std::uint64_t seed = 1;
  int threads = 1;
  double marker_rate = PhotometricTrainer::Options().marker_learning_rate;
  bool narrow_biases = false;
  std::string picture;
  bool json = false;
};

float Half(double v) { return static_cast<float>(Eigen::half(static_cast<float>(v))); }

struct Row {
  std::string name;
  std::vector<double> clean, noisy;
};

double Mean(const std::vector<double>& v) {
  double s = 0;
  for (double x : v) s += x;
  return v.empty() ? 0.0 : s / v.size();
}

// One fit setting of the bench and what it measured.
struct FitRun {
  PhotometricFitOptions options;
  bool ceres = false;  // Ceres' Levenberg-Marquardt (options.steps iterations), not Adam
  double seconds = 0;
  int flipped = 0;
  Row row;
};

// Noise-free PSNR against seconds per frame (log scale), one line per step size through
// its step counts, and same-bits PCA as a dashed line.
cv::Mat FitTradePicture(const std::vector<FitRun>& fits, double pca_db,
                        const std::string& pca_name, int threads, int frames, int bytes,
                        int knn) {
  double x_lo = std::numeric_limits<double>::infinity(), x_hi = 0;
  double y_lo = pca_db, y_hi = pca_db;
  // One line per Adam step size (key: the rate) and one for Ceres (key: -1).
  std::map<double, std::vector<const FitRun*>> by_rate;
  for (const FitRun& run : fits) {
    const double x = run.seconds / frames;
    x_lo = std::min(x_lo, x);
    x_hi = std::max(x_hi, x);
    y_lo = std::min(y_lo, Mean(run.row.clean));
    y_hi = std::max(y_hi, Mean(run.row.clean));
    by_rate[run.ceres ? -1.0 : run.options.learning_rate].push_back(&run);
  }
  if (!(x_hi > x_lo)) x_hi = 2 * x_lo;
  LogXPlot::Layout layout;
  layout.height = 620;
  LogXPlot plot(layout, x_lo, x_hi, y_lo, y_hi);
  plot.DrawFrame("seconds per frame, " + std::to_string(threads) + " thread(s) (log scale)",
                 "mean noise-free PSNR, dB",
                 "Photometric fit: steps and step size against time",
                 std::to_string(frames) + " test frames, " + std::to_string(bytes) +
                     " B per frame (float16 latents), " +
                     std::to_string(fits.front().options.batch_pixels) +
                     " pixels a step" +
                     (fits.front().options.pixel_block > 1
                          ? " in " + std::to_string(fits.front().options.pixel_block) + "x" +
                                std::to_string(fits.front().options.pixel_block) + " blocks"
                          : std::string()) +
                     "; labels: Adam steps or Ceres iterations " +
                     (knn > 0 ? "from the best of " + std::to_string(knn) +
                                    " training latents (0: that latent as it is)"
                              : std::string("per start")));
  cv::Mat& canvas = plot.canvas();
  const cv::Scalar colours[] = {cv::Scalar(200, 110, 30), cv::Scalar(40, 120, 220),
                                cv::Scalar(60, 160, 60), cv::Scalar(150, 60, 170),
                                cv::Scalar(30, 30, 160)};
  const int lx = plot.area().x + plot.area().width + 22, ly = plot.area().y + 14;
  int k = 0;
  for (auto& [rate, runs] : by_rate) {
    std::sort(runs.begin(), runs.end(),
              [](const FitRun* a, const FitRun* b) { return a->seconds < b->seconds; });
    const cv::Scalar colour = colours[k % 5];
    std::vector<cv::Point> line;
    for (const FitRun* run : runs) {
      line.push_back({plot.X(run->seconds / frames), plot.Y(Mean(run->row.clean))});
    }
    if (line.size() > 1) cv::polylines(canvas, line, false, colour, 2, cv::LINE_AA);
    for (std::size_t i = 0; i < runs.size(); ++i) {
      cv::circle(canvas, line[i], 5, colour, cv::FILLED, cv::LINE_AA);
      PlainText(canvas, std::to_string(runs[i]->options.steps), line[i] + cv::Point(7, -7), 0.4,
                colour * 0.7);
    }
    char name[64];
    if (rate < 0) {
      std::snprintf(name, sizeof(name), "Ceres LM (iterations)");
    } else {
      std::snprintf(name, sizeof(name), "Adam from %g", rate);
    }
    const int y = ly + 20 * k;
    cv::line(canvas, {lx, y}, {lx + 14, y}, colour, 2, cv::LINE_AA);
    PlainText(canvas, name, {lx + 20, y + 5}, 0.42);
    ++k;
  }
  const int y = plot.Y(pca_db);
  DrawDashedLine(canvas, {plot.area().x, y}, {plot.area().x + plot.area().width, y},
                 cv::Scalar(120, 120, 120));
  PlainText(canvas, pca_name, {plot.area().x + 8, y - 6}, 0.4, cv::Scalar(90, 90, 90));
  return canvas;
}

void RunPhotometricBench(const PhotometricBenchFlags& flags) {
  const std::string sensor_name = flags.dataset.sensor.empty() ? "gelslim" : flags.dataset.sensor;
  SensorKind sensor;
  if (!SensorKindFromString(sensor_name, &sensor)) {
    throw UsageError("--sensor: expected bubble or gelslim, got '" + sensor_name + "'");
  }
  const Dataset data = OpenDataset(flags.data, flags.dataset);
  if (!data.has_clean()) {
    throw std::runtime_error(flags.data + ": the dataset has no noise-free frames (write it "
                             "with `tactfunc synth --clean`); the bench scores against them");
  }
  const std::string train_path = flags.train_data.empty() ? flags.data : flags.train_data;
  const Dataset train_data = OpenDataset(train_path, flags.dataset);
  if (!train_data.has_sensor(sensor) || !data.has_sensor(sensor)) {
    throw std::runtime_error(train_path + " or " + flags.data + " has no " + sensor_name +
                             " frames");
  }
  // A trained model's trunk (--model), checked against the data as the other commands
  // check theirs; its frame format, else the one training resolves from the train data.
  std::optional<FunctaModel> model;
  if (!flags.model.empty()) {
    model = FunctaModel::Load(flags.model);
    if (!model->HasSensor(sensor) || model->Trunk(sensor).photometric == nullptr) {
      throw std::runtime_error(flags.model + ": the model has no photometric " + sensor_name +
                               " trunk (train it with `tactfunc train --head photometric`)");
    }
    CheckModelMatchesData(*model, flags.model, data, flags.data, sensor, "bench photometric",
                          "--allow-other-frames", flags.allow_other_frames);
    const int model_d = model->Trunk(sensor).photometric->latent_dim();
    if (model_d != flags.latent_dim) {
      throw UsageError("--latent-dim " + std::to_string(flags.latent_dim) +
                       " differs from the model's " + std::to_string(model_d) + " (" +
                       flags.model + ")");
    }
  }
  const SensorInfo& info = train_data.sensor_info(sensor);
  const double scale =
      info.normalization_scale > 0 ? info.normalization_scale : DefaultNormalizationScale(sensor);
  const FrameFormat format =
      model ? model->Trunk(sensor).format
            : TrunkTrainer(TrunkTrainer::Options()).ResolveFormat(sensor, scale);

  // The bench draws every frame against one reference and scores against noise-free
  // frames: simulated data. A set of clips (each with its own reference) is for train,
  // encode and eval, which draw each frame against its own clip's.
  for (const auto& [set, path] : {std::pair<const Dataset*, std::string>{&train_data, train_path},
                                  {&data, flags.data}}) {
    if (!set->clips().empty()) {
      throw DatasetError(path + ": a set of " + std::to_string(set->clips().size()) +
                         " clips, each with its own reference; bench photometric measures "
                         "datasets of one reference (simulated ones: it scores against the "
                         "noise-free frames). train --head photometric, encode and eval draw "
                         "each clip's frames against its own reference");
    }
  }
  const auto train_indices = train_data.FrameIndices(sensor, Split::kTrain);
  const auto pca_indices = data.FrameIndices(sensor, Split::kTrain);
  auto test_indices = data.FrameIndices(sensor, Split::kTest);
  if (flags.max_test_frames > 0 && static_cast<int>(test_indices.size()) > flags.max_test_frames) {
    // Evenly spaced, so that every tool keeps its share.
    std::vector<std::size_t> kept;
    for (int i = 0; i < flags.max_test_frames; ++i) {
      kept.push_back(test_indices[i * test_indices.size() / flags.max_test_frames]);
    }
    test_indices = kept;
  }
  if (train_indices.empty() || pca_indices.size() < 2 || test_indices.empty()) {
    throw std::runtime_error("bench photometric: needs train frames in " + train_path +
                             ", at least 2 train and 1 test frame in " + flags.data);
  }
  // A trained model's trunk needs no train frames.
  const std::size_t num_train = model ? 0 : train_indices.size();
  std::cerr << "bench photometric: loading " << num_train << " + " << pca_indices.size()
            << " train and " << test_indices.size() << " test frames" << std::endl;
  const auto train =
      model ? std::vector<TrunkTargets>()
            : LoadTrunkTargets(train_data, train_indices, format, false, flags.threads);
  const auto pca_train = LoadTrunkTargets(data, pca_indices, format, false, flags.threads);
  const auto test = LoadTrunkTargets(data, test_indices, format, false, flags.threads);
  const auto test_clean = LoadTrunkTargets(data, test_indices, format, true, flags.threads);
  const int channels = static_cast<int>(test[0].values.cols());
  const int d = flags.latent_dim;
  const int bytes = 2 * d;

  // PCA at the same bytes: d / 2 float32 components and d float16 components.
  auto pointers = [](const std::vector<TrunkTargets>& v) {
    std::vector<const TrunkTargets*> p;
    for (const TrunkTargets& t : v) p.push_back(&t);
    return p;
  };
  const Eigen::MatrixXf test_matrix = StackFrames(pointers(test));
  PcaCodec::Options pca_options;
  pca_options.components = d;
  const PcaCodec pca_full = PcaCodec::Fit(StackFrames(pointers(pca_train)), pca_options);
  std::vector<Row> rows;
  Eigen::MatrixXf same_bits;  // the float16 PCA's decoded test frames, for the picture
  for (int half : {0, 1}) {
    const int n = std::min(half ? d : std::max(1, d / 2), pca_full.components());
    const PcaCodec pca = pca_full.Truncated(n);
    Eigen::MatrixXf codes = pca.Encode(test_matrix);
    if (half) codes = codes.unaryExpr([](float v) { return Half(v); });
    const Eigen::MatrixXf decoded = pca.Decode(codes);
    if (half) same_bits = decoded;
    // Fewer train frames than components cap PCA (it has no more): the name says so.
    const bool capped = n < (half ? d : std::max(1, d / 2));
    Row row{"PCA-" + std::to_string(n) + (half ? " float16" : " float32") +
                (capped ? " (capped by the train frames)" : half ? " (same bits)" : ""),
            {}, {}};
    for (std::size_t i = 0; i < test.size(); ++i) {
      const Eigen::MatrixXf p = UnflattenFrame(decoded.row(static_cast<Eigen::Index>(i)), channels);
      row.clean.push_back(Psnr(p, test_clean[i]));
      row.noisy.push_back(Psnr(p, test[i]));
    }
    rows.push_back(row);
  }

  // The trunk: trained here, or a trained model's; with --fit-knn its warm-start table
  // (the model's, or built here from the training latents).
  std::optional<PhotometricTrunk> trunk_storage;
  std::shared_ptr<const WarmStartTable> table;
  double train_seconds = 0;
  if (model) {
    trunk_storage.emplace(*model->Trunk(sensor).photometric);
    table = model->Trunk(sensor).warm_start;
    if (flags.fit_knn > 0 && table == nullptr) {
      throw UsageError("--fit-knn: the model " + flags.model + " has no warm-start table (it "
                       "was trained before train --head photometric stored one)");
    }
    std::cerr << "bench photometric: the trunk of " << flags.model << " (not trained here)"
              << std::endl;
  } else {
    const Image reference =
        PhotometricReference(train_data.FrameReference(train_indices[0]), format);
    PhotometricTrainer::Options options;
    options.trunk.width = flags.width;
    options.trunk.num_hidden_layers = flags.layers;
    options.trunk.latent_dim = d;
    options.steps = flags.steps;
    options.marker_warmup_steps = flags.warmup;
    options.marker_learning_rate = flags.marker_rate;
    options.trunk.wide_biases = !flags.narrow_biases;
    options.seed = flags.seed;
    options.threads = flags.threads;
    const PhotometricTrainer trainer(options);
    std::cerr << "bench photometric: training " << flags.steps << " steps (markers at the "
              << "working resolution for " << flags.warmup << ") on " << flags.threads
              << " thread(s)" << std::endl;
    const auto start = std::chrono::steady_clock::now();
    auto elapsed = [&start] {
      return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    };
    const int every = std::max(1, flags.steps / 20);
    PhotometricTrainer::Result trained =
        trainer.Train(train, reference, [&](int step, double loss) {
          if (step % every == 0 || step == flags.steps) {
            std::fprintf(stderr, "  step %d/%d: batch loss %.3e (%.0f s)\n", step, flags.steps,
                         loss, elapsed());
          }
          return true;
        });
    train_seconds = trained.summary.seconds;
    if (!std::isfinite(trained.summary.final_loss)) {
      throw std::runtime_error("bench photometric: training diverged (loss " +
                               std::to_string(trained.summary.final_loss) + ")");
    }
    if (flags.fit_knn > 0) {
      table = std::make_shared<WarmStartTable>(PhotometricWarmStart::BuildTable(
          trained.trunk, train, trained.latents, PhotometricWarmStart::Options(), flags.threads));
    }
    trunk_storage.emplace(std::move(trained.trunk));
  }
  const PhotometricTrunk& trunk = *trunk_storage;
  std::optional<PhotometricWarmStart> warm_start;
  if (flags.fit_knn > 0) warm_start.emplace(trunk, table);
  // The fits: every step size of --fit-rate with every step count of --fit-steps; the
  // first setting is the bench's row, the others only the fit trade table and picture.
  std::vector<FitRun> fits;
  for (double rate : flags.fit_rate) {
    for (int steps : flags.fit_steps) {
      if (steps == 0 && flags.fit_knn == 0) {
        throw UsageError("--fit-steps 0 (the neighbour's latent as it is) needs --fit-knn");
      }
      if (flags.fit_probe > steps) {
        throw UsageError("--fit-probe " + std::to_string(flags.fit_probe) +
                         " exceeds --fit-steps " + std::to_string(steps));
      }
      FitRun run;
      run.options.steps = steps;
      run.options.probe_steps = flags.fit_probe;
      run.options.batch_pixels = flags.fit_batch;
      run.options.pixel_block = flags.fit_block;
      run.options.contact_share = flags.fit_contact_share;
      run.options.learning_rate = rate;
      run.options.final_learning_rate = std::min(run.options.final_learning_rate, rate);
      fits.push_back(std::move(run));
    }
  }
  if (!flags.fit_ceres.empty() && flags.fit_knn == 0) {
    throw UsageError("--fit-ceres starts from the best neighbour: it needs --fit-knn");
  }
  for (int iterations : flags.fit_ceres) {
    FitRun run;
    run.ceres = true;
    run.options.steps = iterations;
    fits.push_back(std::move(run));
  }
  const std::vector<int> all_pixels = trunk.AllPixels();
  std::vector<Eigen::MatrixXf> predictions(test.size());  // the first setting's, for --picture
  for (FitRun& run : fits) {
    std::vector<Eigen::VectorXd> latents(test.size());
    std::vector<char> flipped(test.size(), 0);
    const auto fit_start = std::chrono::steady_clock::now();
    std::atomic<int> done{0};
    internal::ParallelFor(static_cast<int>(test.size()), flags.threads, [&](int i) {
      const std::uint64_t seed = DeriveSeed(flags.seed, 7000000 + i);
      PhotometricFit fit;
      if (run.ceres) {
        // Ceres from the best neighbour, as encode's knn+ceres:N.
        const Eigen::VectorXd start = warm_start->BestStart(test[i], flags.fit_knn);
        PhotometricCeresOptions ceres_options;
        ceres_options.iterations = run.options.steps;
        ceres_options.pixels = flags.fit_pixels;
        fit.latent = FitPhotometricLatentCeres(trunk, test[i], start, ceres_options).latent;
      } else {
        fit = warm_start ? warm_start->Fit(test[i], flags.fit_knn, run.options, seed)
                         : FitPhotometricLatent(trunk, test[i], run.options, seed);
      }
      latents[i] = fit.latent.unaryExpr([](double v) { return static_cast<double>(Half(v)); });
      flipped[i] = fit.flipped;
      const int n = ++done;
      if (n % 20 == 0 || n == static_cast<int>(test.size())) {
        if (run.ceres) {
          std::fprintf(stderr, "  ceres:%d: fitted %d/%zu test latents\n", run.options.steps, n,
                       test.size());
        } else {
          std::fprintf(stderr, "  adam:%d from %g: fitted %d/%zu test latents\n",
                       run.options.steps, run.options.learning_rate, n, test.size());
        }
      }
    });
    run.seconds =
        std::chrono::duration<double>(std::chrono::steady_clock::now() - fit_start).count();
    run.flipped = static_cast<int>(std::count(flipped.begin(), flipped.end(), 1));
    run.row.name = "photometric trunk, float16 latents";
    for (std::size_t i = 0; i < test.size(); ++i) {
      Eigen::MatrixXf prediction = trunk.Forward<float>(all_pixels, latents[i].cast<float>());
      run.row.clean.push_back(Psnr(prediction, test_clean[i]));
      run.row.noisy.push_back(Psnr(prediction, test[i]));
      if (&run == &fits[0]) predictions[i] = std::move(prediction);
    }
  }
  rows.push_back(fits[0].row);
  const double fit_seconds = fits[0].seconds;

  std::printf("bench photometric: %s, %zu test frames (%s), %d B per frame, ", sensor_name.c_str(),
              test.size(), flags.data.c_str(), bytes);
  if (flags.model.empty()) {
    std::printf("trunk trained on %zu frames of %s\n", train.size(), train_path.c_str());
  } else {
    std::printf("the trunk of %s\n", flags.model.c_str());
  }
  std::printf("%-38s  %10s  %6s\n", "representation", "noise-free", "noisy");
  nlohmann::json json_rows = nlohmann::json::array();
  for (const Row& row : rows) {
    std::printf("%-38s  %10.2f  %6.2f\n", row.name.c_str(), Mean(row.clean), Mean(row.noisy));
    json_rows.push_back({{"representation", row.name},
                         {"psnr_clean", Mean(row.clean)},
                         {"psnr", Mean(row.noisy)}});
  }
  const double margin = Mean(rows[2].clean) - Mean(rows[1].clean);
  std::printf("margin over PCA at the same bits (noise-free): %+.2f dB (target +3)\n", margin);
  // Per tool, where the frames are labelled.
  std::map<std::string, std::pair<std::vector<double>, std::vector<double>>> tools;
  for (std::size_t i = 0; i < test.size(); ++i) {
    const auto& label = data.frames()[test_indices[i]].label;
    if (!label) continue;
    tools[label->tool].first.push_back(rows[1].clean[i]);
    tools[label->tool].second.push_back(rows[2].clean[i]);
  }
  nlohmann::json per_tool = nlohmann::json::object();
  for (const auto& [tool, values] : tools) {
    std::printf("  %-16s PCA %6.2f  trunk %6.2f  (%+.2f)\n", tool.c_str(), Mean(values.first),
                Mean(values.second), Mean(values.second) - Mean(values.first));
    per_tool[tool] = {{"pca_same_bits_clean", Mean(values.first)},
                      {"trunk_clean", Mean(values.second)}};
  }
  const int num_flipped = fits[0].flipped;
  std::printf("marker scale %.3f px per unit slope; training %.0f s, fits %.0f s (adam:%d, "
              "probe %d, %d pixels a step in blocks of side %d, a share of %.2f drawn towards "
              "the contact; %.3f s per frame on %d thread(s); %d of %zu kept the start "
              "turned by pi)\n",
              trunk.marker_scale(), train_seconds, fit_seconds, fits[0].options.steps,
              flags.fit_probe, flags.fit_batch, flags.fit_block, flags.fit_contact_share,
              fit_seconds / test.size(),
              flags.threads,
              num_flipped, test.size());
  // The fit's trade of time against PSNR, where more than one setting was asked for.
  nlohmann::json json_fits = nlohmann::json::array();
  for (const FitRun& run : fits) {
    json_fits.push_back({{"steps", run.options.steps},
                         {"solver", run.ceres ? "ceres" : "adam"},
                         {"learning_rate", run.options.learning_rate},
                         {"psnr_clean", Mean(run.row.clean)},
                         {"psnr", Mean(run.row.noisy)},
                         {"margin_vs_pca_same_bits_clean",
                          Mean(run.row.clean) - Mean(rows[1].clean)},
                         {"seconds", run.seconds},
                         {"seconds_per_frame", run.seconds / test.size()},
                         {"flipped_starts_kept", run.flipped}});
  }
  if (fits.size() > 1) {
    std::printf("fit trade (probe %d, %d pixels a step in blocks of side %d, a share of %.2f "
                "drawn towards the contact, %d thread(s)):\n",
                flags.fit_probe, flags.fit_batch, flags.fit_block, flags.fit_contact_share,
                flags.threads);
    std::printf("  %-22s  %10s  %8s  %11s\n", "fit", "noise-free", "vs PCA", "s per frame");
    for (const FitRun& run : fits) {
      char name[64];
      if (run.ceres) {
        std::snprintf(name, sizeof(name), "ceres:%d on %d px", run.options.steps,
                      flags.fit_pixels);
      } else {
        std::snprintf(name, sizeof(name), "adam:%d from %g", run.options.steps,
                      run.options.learning_rate);
      }
      std::printf("  %-22s  %10.2f  %+8.2f  %11.3f\n", name, Mean(run.row.clean),
                  Mean(run.row.clean) - Mean(rows[1].clean), run.seconds / test.size());
    }
  }
  std::fflush(stdout);
  if (!flags.trade_picture.empty()) {
    WritePicture(flags.trade_picture,
                 FitTradePicture(fits, Mean(rows[1].clean), rows[1].name, flags.threads,
                                 static_cast<int>(test.size()), bytes, flags.fit_knn));
  }

  if (!flags.picture.empty()) {
    // Six test frames spread over the split: noise-free, PCA at the same bits, trunk.
    const int count = std::min<int>(6, static_cast<int>(test.size()));
    std::vector<std::vector<cv::Mat>> grid(3);
    for (int k = 0; k < count; ++k) {
      const std::size_t i = k * test.size() / count;
      const TrunkTargets& t = test_clean[i];
      const double lo = t.values.minCoeff(), hi = t.values.maxCoeff();
      const Eigen::MatrixXf pca_frame =
          UnflattenFrame(same_bits.row(static_cast<Eigen::Index>(i)), channels);
      grid[0].push_back(FitHeight(ValueTile(t.values, t.weights, t.rows, t.cols, lo, hi), 240));
      grid[1].push_back(FitHeight(ValueTile(pca_frame, t.weights, t.rows, t.cols, lo, hi), 240));
      grid[2].push_back(
          FitHeight(ValueTile(predictions[i], t.weights, t.rows, t.cols, lo, hi), 240));
    }
    cv::Mat picture = TileGrid(grid);
    const cv::Mat caption = Caption(
        picture.cols, "rows: noise-free frame, PCA at the same " + std::to_string(bytes) +
                          " B, photometric trunk (" + std::to_string(bytes) + " B)");
    cv::vconcat(picture, caption, picture);
    WritePicture(flags.picture, picture);
  }
  if (flags.json) {
    EmitJson({{"bench", "photometric"},
              {"data", flags.data},
              {"train_data", flags.model.empty() ? train_path : std::string()},
              {"model", flags.model},
              {"sensor", sensor_name},
              {"bytes_per_frame", bytes},
              // Training's figures; null for a trained model's trunk (--model).
              {"steps", flags.model.empty() ? nlohmann::json(flags.steps) : nlohmann::json()},
              {"marker_warmup",
               flags.model.empty() ? nlohmann::json(flags.warmup) : nlohmann::json()},
              {"seed", flags.seed},
              {"train_frames", train.size()},
              {"test_frames", test.size()},
              {"rows", json_rows},
              {"margin_vs_pca_same_bits_clean", margin},
              {"per_tool", per_tool},
              {"marker_scale", trunk.marker_scale()},
              {"train_seconds", train_seconds},
              {"fit_seconds", fit_seconds},
              {"fit_steps", fits[0].options.steps},
              {"fit_probe", flags.fit_probe},
              {"fit_knn", flags.fit_knn},
              {"fit_batch", flags.fit_batch},
              {"fit_block", flags.fit_block},
              {"fit_contact_share", flags.fit_contact_share},
              {"fit_rate", fits[0].options.learning_rate},
              {"fits", json_fits},
              {"threads", flags.threads},
              {"flipped_starts_kept", num_flipped}});
  }
}

}  // namespace

void RegisterPhotometricBenchmark(CLI::App* bench, CommandBody* selected) {
  auto flags = std::make_shared<PhotometricBenchFlags>();
  CLI::App* sub = bench->add_subcommand(
      "photometric",
      "The optical sensors' photometric trunk trained, its test latents fitted and stored as "
      "float16, against PCA at the same bytes per frame, scored against noise-free frames "
      "(docs/REPRESENTATION.md).");
  sub->add_option("--data", flags->data,
                  "Dataset with noise-free frames (synth --clean): PCA on its train split, "
                  "scores on its test split")
      ->required();
  sub->add_option("--train-data", flags->train_data,
                  "Train the trunk on this dataset's train split instead of --data's");
  AddDatasetFlags(sub, &flags->dataset);
  sub->add_option("--steps", flags->steps, "Training steps (default 3000)")
      ->check(CLI::Range(1, 10000000));
  sub->add_option("--warmup", flags->warmup,
                  "Steps with markers at the working resolution first (default 1000)")
      ->check(CLI::Range(0, 10000000));
  sub->add_option("--latent-dim", flags->latent_dim,
                  "Latent values d, the pose's 3 included (default 64: 128 B per frame)")
      ->check(CLI::Range(4, 4096));
  sub->add_option("--width", flags->width, "SIREN width (default 64)")->check(CLI::Range(1, 4096));
  sub->add_option("--layers", flags->layers, "SIREN layers (default 3)")->check(CLI::Range(1, 64));
  sub->add_option("--fit-steps", flags->fit_steps,
                  "Adam steps per test fit and start (default 200); a comma-separated list "
                  "fits the test frames once per count (the fit trade table)")
      ->delimiter(',')
      ->check(CLI::Range(0, 1000000));
  sub->add_option("--fit-knn", flags->fit_knn,
                  "Start each fit from the best of this many neighbours in the trunk's "
                  "warm-start table (one start, not two; 0 = off, the default; "
                  "estimation/training/photometric_warm_start.h); with it --fit-steps 0 "
                  "scores the neighbour's latent as it is")
      ->check(CLI::Range(0, 1000));
  sub->add_option("--fit-probe", flags->fit_probe,
                  "After this many steps only the better of the two starts goes on "
                  "(PhotometricFitOptions::probe_steps; default 0: both run all steps)")
      ->check(CLI::Range(0, 1000000));
  sub->add_option("--fit-batch", flags->fit_batch,
                  "Pixels per fit step (PhotometricFitOptions::batch_pixels; default 512)")
      ->check(CLI::Range(1, 1000000));
  sub->add_option("--fit-block", flags->fit_block,
                  "Fit steps draw their pixels in square blocks of this side, --fit-batch "
                  "/ side^2 blocks (PhotometricFitOptions::pixel_block; default 1: "
                  "independent pixels)")
      ->check(CLI::Range(1, 16));
  sub->add_option("--fit-contact-share", flags->fit_contact_share,
                  "Share of a fit step's pixels drawn towards the contact, in [0, 1) "
                  "(PhotometricFitOptions::contact_share; default 0: every pixel alike; "
                  "needs --fit-block 1)")
      ->check(CLI::Range(0.0, 0.999));
  sub->add_option("--fit-rate", flags->fit_rate,
                  "Adam's first step size in a fit, falling by a cosine to 1e-4 "
                  "(PhotometricFitOptions::learning_rate; default 5e-2); a comma-separated "
                  "list as --fit-steps, every rate with every count")
      ->delimiter(',')
      ->check(CLI::Range(1e-8, 10.0));
  sub->add_option("--fit-ceres", flags->fit_ceres,
                  "Also fit the test frames by Levenberg-Marquardt in Ceres from the best "
                  "neighbour (needs --fit-knn; encode's knn+ceres:N; estimation/fitting/"
                  "photometric_ceres_fit.h), once per iteration count of this comma-separated "
                  "list: rows of the fit trade table and a line of its picture")
      ->delimiter(',')
      ->check(CLI::Range(1, 1000000));
  sub->add_option("--fit-pixels", flags->fit_pixels,
                  "With --fit-ceres: the residuals' pixels, evenly spaced over the frame's "
                  "valid ones (0 = all, the default and encode's)")
      ->check(CLI::Range(0, 100000000));
  sub->add_option("--trade-picture", flags->trade_picture,
                  "Write a PNG of the fit trade: noise-free PSNR against seconds per frame, "
                  "one line per --fit-rate, PCA at the same bits as a dashed line");
  sub->add_option("--model", flags->model,
                  "Fit and score the photometric trunk of this trained model (train --head "
                  "photometric) instead of training one; --latent-dim must be the model's, "
                  "and the training flags (--train-data, --steps, --warmup, --width, --layers, "
                  "--marker-rate, --narrow-biases) do not apply");
  sub->add_flag("--allow-other-frames", flags->allow_other_frames,
                "With --model: run even when the data's frames (size, channels, sensor "
                "description) are not those the model's trunk was trained on (a warning "
                "instead of an error)");
  sub->add_option("--max-test-frames", flags->max_test_frames,
                  "Score at most this many test frames, evenly spaced (default 0: all)")
      ->check(CLI::Range(0, 100000000));
  sub->add_option("--marker-rate", flags->marker_rate,
                  "Adam step size of the marker scale (default 2e-3; 0: the trunk's)")
      ->check(CLI::Range(0.0, 1.0));
  sub->add_flag("--narrow-biases", flags->narrow_biases,
                "Start the SIREN's biases as LatentModulatedSiren does, not as nn.Linear "
                "(PhotometricTrunk::Options::wide_biases)");
  sub->add_option("--seed", flags->seed, "Seed (default 1)");
  sub->add_option("--threads", flags->threads, "Worker threads (default 1)")
      ->check(CLI::Range(1, 1024));
  sub->add_option("--picture", flags->picture,
                  "Write a PNG of six test frames: noise-free, PCA at the same bits, trunk");
  sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
  sub->callback([flags, selected] { *selected = [flags] { RunPhotometricBench(*flags); }; });
}

}  // namespace tactfunc::apps
