// Copyright 2026 The tactfunc Authors.
//
// tactfunc bench photometric: the optical sensors' photometric trunk
// (models/trunk/photometric_trunk.h) trained, its test latents fitted and stored as
// float16, against PCA at the same bytes per frame, on a dataset with noise-free frames
// (docs/REPRESENTATION.md, "The photometric trunk in C++"):
//
//   tactfunc bench photometric --data D [--train-data T] [--sensor gelslim]
//       [--steps 3000] [--warmup 1000] [--latent-dim 64] [--width 64] [--layers 3]
//       [--fit-steps 400] [--marker-rate 2e-3] [--narrow-biases] [--seed 1] [--threads 1]
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
#include <map>
#include <memory>

#include <opencv2/core.hpp>

#include "apps/bench.h"
#include "apps/command.h"
#include "apps/dataset_flags.h"
#include "apps/pictures.h"
#include "estimation/data/dataset.h"
#include "estimation/data/trunk_targets.h"
#include "estimation/evaluation/baselines.h"
#include "estimation/training/photometric_trainer.h"
#include "estimation/training/trunk_trainer.h"
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
  int fit_steps = 400;
  int max_test_frames = 0;
  std::uint64_t seed = 1;
  int threads = 1;
  double marker_rate = PhotometricTrainer::Options().marker_learning_rate;
  bool narrow_biases = false;
  std::string picture;
  bool json = false;
};

float Half(double v) { return static_cast<float>(Eigen::half(static_cast<float>(v))); }

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
  const SensorInfo& info = train_data.sensor_info(sensor);
  const double scale =
      info.normalization_scale > 0 ? info.normalization_scale : DefaultNormalizationScale(sensor);
  const FrameFormat format = TrunkTrainer(TrunkTrainer::Options()).ResolveFormat(sensor, scale);

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
  std::cerr << "bench photometric: loading " << train_indices.size() << " + "
            << pca_indices.size() << " train and " << test_indices.size() << " test frames"
            << std::endl;
  const auto train = LoadTrunkTargets(train_data, train_indices, format, false, flags.threads);
  const auto pca_train = LoadTrunkTargets(data, pca_indices, format, false, flags.threads);
  const auto test = LoadTrunkTargets(data, test_indices, format, false, flags.threads);
  const auto test_clean = LoadTrunkTargets(data, test_indices, format, true, flags.threads);
  const Image reference =
      PhotometricReference(train_data.FrameReference(train_indices[0]), format);
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
  struct Row {
    std::string name;
    std::vector<double> clean, noisy;
  };
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

  // The trunk.
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
  const double train_seconds = trained.summary.seconds;
  if (!std::isfinite(trained.summary.final_loss)) {
    throw std::runtime_error("bench photometric: training diverged (loss " +
                             std::to_string(trained.summary.final_loss) + ")");
  }
  const PhotometricTrunk& trunk = trained.trunk;
  PhotometricFitOptions fit_options;
  fit_options.steps = flags.fit_steps;
  std::vector<Eigen::VectorXd> latents(test.size());
  std::vector<char> flipped(test.size(), 0);
  const auto fit_start = std::chrono::steady_clock::now();
  std::atomic<int> done{0};
  internal::ParallelFor(static_cast<int>(test.size()), flags.threads, [&](int i) {
    const PhotometricFit fit =
        FitPhotometricLatent(trunk, test[i], fit_options, DeriveSeed(flags.seed, 7000000 + i));
    latents[i] = fit.latent.unaryExpr([](double v) { return static_cast<double>(Half(v)); });
    flipped[i] = fit.flipped;
    const int n = ++done;
    if (n % 20 == 0 || n == static_cast<int>(test.size())) {
      std::fprintf(stderr, "  fitted %d/%zu test latents\n", n, test.size());
    }
  });
  const double fit_seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - fit_start).count();
  Row trunk_row{"photometric trunk, float16 latents", {}, {}};
  std::vector<Eigen::MatrixXf> predictions(test.size());
  for (std::size_t i = 0; i < test.size(); ++i) {
    predictions[i] = trunk.Forward<float>(trunk.AllPixels(), latents[i].cast<float>());
    trunk_row.clean.push_back(Psnr(predictions[i], test_clean[i]));
    trunk_row.noisy.push_back(Psnr(predictions[i], test[i]));
  }
  rows.push_back(trunk_row);

  auto mean = [](const std::vector<double>& v) {
    double s = 0;
    for (double x : v) s += x;
    return v.empty() ? 0.0 : s / v.size();
  };
  std::printf("bench photometric: %s, %zu test frames (%s), %d B per frame, trunk trained on "
              "%zu frames of %s\n",
              sensor_name.c_str(), test.size(), flags.data.c_str(), bytes, train.size(),
              train_path.c_str());
  std::printf("%-38s  %10s  %6s\n", "representation", "noise-free", "noisy");
  nlohmann::json json_rows = nlohmann::json::array();
  for (const Row& row : rows) {
    std::printf("%-38s  %10.2f  %6.2f\n", row.name.c_str(), mean(row.clean), mean(row.noisy));
    json_rows.push_back({{"representation", row.name},
                         {"psnr_clean", mean(row.clean)},
                         {"psnr", mean(row.noisy)}});
  }
  const double margin = mean(rows[2].clean) - mean(rows[1].clean);
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
    std::printf("  %-16s PCA %6.2f  trunk %6.2f  (%+.2f)\n", tool.c_str(), mean(values.first),
                mean(values.second), mean(values.second) - mean(values.first));
    per_tool[tool] = {{"pca_same_bits_clean", mean(values.first)},
                      {"trunk_clean", mean(values.second)}};
  }
  const int num_flipped = static_cast<int>(std::count(flipped.begin(), flipped.end(), 1));
  std::printf("marker scale %.3f px per unit slope; training %.0f s, fits %.0f s (%d of %zu "
              "kept the start turned by pi)\n",
              trunk.marker_scale(), train_seconds, fit_seconds, num_flipped, test.size());
  std::fflush(stdout);

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
              {"train_data", train_path},
              {"sensor", sensor_name},
              {"bytes_per_frame", bytes},
              {"steps", flags.steps},
              {"marker_warmup", flags.warmup},
              {"seed", flags.seed},
              {"train_frames", train.size()},
              {"test_frames", test.size()},
              {"rows", json_rows},
              {"margin_vs_pca_same_bits_clean", margin},
              {"per_tool", per_tool},
              {"marker_scale", trunk.marker_scale()},
              {"train_seconds", train_seconds},
              {"fit_seconds", fit_seconds},
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
  sub->add_option("--fit-steps", flags->fit_steps, "Adam steps per test fit and start (default 400)")
      ->check(CLI::Range(1, 1000000));
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
