// Copyright 2026 The tactfunc Authors.
//
// tactfunc bench pca: the wall time of PcaCodec::Fit (the PCA baseline of `eval`) on a
// synthetic M x P frame matrix, and with --reference the same fit by OpenCV's cv::PCA
// (what PcaCodec used before) with the agreement of the two, and with --exact the exact
// fit (PcaCodec::Options::exact) and how much more variance the default fit leaves out:
//
//   tactfunc bench pca [--frames 3991] [--pixels 8560] [--components 256] [--reference]
//                      [--exact] [--json]
//
// The frames: a smooth rank-`--rank` signal (component i with scale 1 / (1 + i)) plus
// white noise of standard deviation 0.01, from a fixed seed. One fit each (no
// repetitions: a fit of the default size takes seconds to minutes).
//
// With --data D --model M it measures instead what the sensor noise leaves a linear
// basis on a dataset with noise-free frames (`synth --clean`; docs/REPRESENTATION.md):
//
//   tactfunc bench pca --data D --model M [--sensor S] [--sizes 32,64,128] [--smooth 0.8] [--json]
//
// For each sensor of the model that D has, the trunk's frame format gives the targets
// (the trunk itself is not used). Three bases are fitted on the train split: PCA of the
// noisy frames (eval's baseline), PCA of the noise-free frames (what no user's data
// offers: a bound on any basis learned from these frames), and PCA of the noisy frames
// after a Gaussian blur of --smooth pixels (a smooth basis). Each test frame's NOISY
// targets are projected on each basis, the codes rounded to float16 (2 bytes a
// component, as `encode`'s default latents), decoded and scored by THE PSNR against the
// noise-free and the noisy targets of the frame.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <random>

#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "CLI/CLI.hpp"
#include "apps/bench.h"
#include "apps/command.h"
#include "apps/dataset_flags.h"
#include "estimation/data/trunk_targets.h"
#include "estimation/evaluation/baselines.h"
#include "models/trunk/functa_model.h"

namespace tactfunc::apps {
namespace {

struct PcaBenchFlags {
  int frames = 3991;
  int pixels = 8560;
  int components = 256;
  int rank = 64;
  bool reference = false;
  bool exact = false;
  bool json = false;
  // The dataset study (header comment).
  std::string data;
  std::string model;
  std::string sizes = "32,64,128";
  double smooth = 0.8;
  DatasetFlags dataset;
};

double Seconds(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Fraction of the frames' variance the reconstructions mean + B^T B (x - mean) keep:
// 1 - |X - X_hat|^2 / |X - mean(X)|^2 (what PSNR sees; no orthonormality assumed).
double ExplainedBy(const Eigen::MatrixXf& frames, const Eigen::RowVectorXf& mean,
                   const Eigen::MatrixXf& basis) {
  const Eigen::MatrixXd b = basis.cast<double>();
  const Eigen::MatrixXd centred = (frames.rowwise() - mean).cast<double>();
  const Eigen::MatrixXd error = centred - (centred * b.transpose()) * b;
  const Eigen::RowVectorXd own_mean = frames.cast<double>().colwise().mean();
  const double total = (frames.cast<double>().rowwise() - own_mean).squaredNorm();
  return total > 0 ? 1.0 - error.squaredNorm() / total : 1.0;
}

// `t` with each channel blurred by OpenCV's Gaussian of standard deviation `sigma`
// pixels (edges replicated); invalid pixels blur as their stored 0.
TrunkTargets BlurTargets(const TrunkTargets& t, double sigma) {
  TrunkTargets blurred = t;
  for (Eigen::Index ch = 0; ch < t.values.cols(); ++ch) {
    // A channel is one contiguous column of N = rows x cols pixels, pixel-major.
    const cv::Mat plane(t.rows, t.cols, CV_32F, const_cast<float*>(t.values.col(ch).data()));
    cv::Mat out(t.rows, t.cols, CV_32F, blurred.values.col(ch).data());
    cv::GaussianBlur(plane, out, cv::Size(0, 0), sigma, sigma, cv::BORDER_REPLICATE);
  }
  return blurred;
}

void RunPcaDataStudy(const PcaBenchFlags& flags) {
  if (flags.model.empty()) throw UsageError("--data needs --model (the trunks' frame formats)");
  const std::vector<int> sizes = ParsePositiveIntList(flags.sizes, "--sizes", "component counts");
  const int largest = *std::max_element(sizes.begin(), sizes.end());
  const FunctaModel model = FunctaModel::Load(flags.model);
  const Dataset dataset = OpenDataset(flags.data, flags.dataset);
  if (!dataset.has_clean()) {
    throw std::runtime_error(flags.data + ": the dataset has no noise-free frames (write it "
                             "with `tactfunc synth --clean`); the study scores against them");
  }
  nlohmann::json rows = nlohmann::json::array();
  std::cout << "bench pca: " << flags.data << ", bases fitted on the train split, test frames "
            << "coded as float16 PCA codes (2 bytes a component), PSNR in dB\n"
            << "sensor   basis fitted on            components  bytes/frame  noise-free  noisy\n";
  for (SensorKind sensor : model.sensors()) {
    if (!dataset.has_sensor(sensor)) continue;
    if (!flags.dataset.sensor.empty() && flags.dataset.sensor != ToString(sensor)) continue;
    const FrameFormat& format = model.Trunk(sensor).format;
    std::vector<TrunkTargets> train_noisy, train_clean, test_noisy, test_clean;
    for (std::size_t i : dataset.FrameIndices(sensor, Split::kTrain)) {
      train_noisy.push_back(LoadTrunkTargets(dataset, i, format, false));
      train_clean.push_back(LoadTrunkTargets(dataset, i, format, true));
    }
    for (std::size_t i : dataset.FrameIndices(sensor, Split::kTest)) {
      test_noisy.push_back(LoadTrunkTargets(dataset, i, format, false));
      test_clean.push_back(LoadTrunkTargets(dataset, i, format, true));
    }
    if (train_noisy.size() < 2 || test_noisy.empty()) {
      throw std::runtime_error(flags.data + ": " + ToString(sensor) + " needs at least 2 train "
                               "and 1 test frame, found " + std::to_string(train_noisy.size()) +
                               " and " + std::to_string(test_noisy.size()));
    }
    auto pointers = [](const std::vector<TrunkTargets>& v) {
      std::vector<const TrunkTargets*> p;
      for (const TrunkTargets& t : v) p.push_back(&t);
      return p;
    };
    const Eigen::MatrixXf noisy_matrix = StackFrames(pointers(train_noisy));
    Eigen::MatrixXf smooth_matrix(noisy_matrix.rows(), noisy_matrix.cols());
    for (std::size_t i = 0; i < train_noisy.size(); ++i) {
      smooth_matrix.row(static_cast<Eigen::Index>(i)) =
          FlattenFrame(BlurTargets(train_noisy[i], flags.smooth));
    }
    const Eigen::MatrixXf test_matrix = StackFrames(pointers(test_noisy));
    const int channels = static_cast<int>(test_noisy.front().values.cols());
    struct Basis {
      std::string name;
      Eigen::MatrixXf frames;
    };
    char smooth_name[64];
    std::snprintf(smooth_name, sizeof(smooth_name), "noisy frames, blurred %.2g px", flags.smooth);
    const std::vector<Basis> bases = {{"noisy frames (eval's PCA)", noisy_matrix},
                                      {"noise-free frames (bound)",
                                       StackFrames(pointers(train_clean))},
                                      {smooth_name, smooth_matrix}};
    for (const Basis& basis : bases) {
      PcaCodec::Options options;
      options.components = largest;
      options.exact = true;  // a bound: the exact fit, not the fast one
      const PcaCodec full = PcaCodec::Fit(basis.frames, options);
      for (int n : sizes) {
        if (n > full.components()) continue;
        const PcaCodec pca = full.Truncated(n);
        Eigen::MatrixXf codes = pca.Encode(test_matrix);
        for (Eigen::Index i = 0; i < codes.size(); ++i) {
          codes.data()[i] = static_cast<float>(Eigen::half(codes.data()[i]));
        }
        const Eigen::MatrixXf decoded = pca.Decode(codes);
        double clean_sum = 0, noisy_sum = 0;
        for (std::size_t i = 0; i < test_noisy.size(); ++i) {
          const Eigen::MatrixXf prediction =
              UnflattenFrame(decoded.row(static_cast<Eigen::Index>(i)), channels);
          clean_sum += Psnr(prediction, test_clean[i]);
          noisy_sum += Psnr(prediction, test_noisy[i]);
        }
        const double clean = clean_sum / test_noisy.size(), noisy = noisy_sum / test_noisy.size();
        std::printf("%-8s %-28s %10d  %11d  %10.2f  %5.2f\n", ToString(sensor),
                    basis.name.c_str(), n, 2 * n, clean, noisy);
        rows.push_back({{"sensor", ToString(sensor)}, {"basis", basis.name},
                        {"components", n}, {"bytes_per_frame", 2 * n},
                        {"psnr_clean", clean}, {"psnr", noisy},
                        {"train_frames", train_noisy.size()}, {"test_frames", test_noisy.size()}});
      }
    }
  }
  std::fflush(stdout);
  if (flags.json) {
    EmitJson({{"bench", "pca"}, {"data", flags.data}, {"smooth_px", flags.smooth}, {"rows", rows}});
  }
}

void RunPcaBench(const PcaBenchFlags& flags) {
  if (!flags.data.empty()) {
    RunPcaDataStudy(flags);
    return;
  }
  const int m = flags.frames, p = flags.pixels, r = flags.rank;
  std::mt19937 rng(7);
  std::normal_distribution<float> normal(0.f, 1.f);
  Eigen::MatrixXf components(r, p), weights(m, r), frames(m, p);
  for (int i = 0; i < r; ++i) {
    // Smooth components: sums of a few sinusoids along the pixel index.
    const float f1 = 0.5f + i, f2 = 1.5f + 0.5f * i, phase = normal(rng);
    for (int j = 0; j < p; ++j) {
      const float x = static_cast<float>(j) / p;
      components(i, j) = std::sin(6.2832f * f1 * x + phase) + 0.5f * std::cos(6.2832f * f2 * x);
    }
  }
  for (int k = 0; k < m; ++k) {
    for (int i = 0; i < r; ++i) weights(k, i) = normal(rng) / (1.0f + i);
  }
  frames = weights * components;
  for (int k = 0; k < m; ++k) {
    for (int j = 0; j < p; ++j) frames(k, j) += 0.01f * normal(rng) + 0.5f;
  }
  std::cout << "bench pca: " << m << " frames of " << p << " floats, " << flags.components
            << " components (rank-" << r << " signal + noise 0.01)\n";

  PcaCodec::Options options;
  options.components = flags.components;
  PcaCodec::Summary summary;
  const auto start = std::chrono::steady_clock::now();
  const PcaCodec codec = PcaCodec::Fit(frames, options, &summary);
  const double seconds = Seconds(start);
  const double explained = ExplainedBy(frames, codec.mean(), codec.basis());
  std::cout << "PcaCodec::Fit: " << seconds << " s, variance left out of the reconstructions "
            << 1 - explained << " (" << summary.method << ")\n";
  nlohmann::json out = {{"bench", "pca"},         {"frames", m},
                        {"pixels", p},            {"components", codec.components()},
                        {"seconds", seconds},     {"explained_variance", explained},
                        {"method", summary.method}, {"machine", MachineDescription()}};
  if (flags.exact) {
    PcaCodec::Options exact_options = options;
    exact_options.exact = true;
    PcaCodec::Summary exact_summary;
    const auto exact_start = std::chrono::steady_clock::now();
    const PcaCodec exact = PcaCodec::Fit(frames, exact_options, &exact_summary);
    const double exact_seconds = Seconds(exact_start);
    const double exact_explained = ExplainedBy(frames, exact.mean(), exact.basis());
    const double excess = (1 - explained) / (1 - exact_explained) - 1;
    std::cout << "PcaCodec::Fit exact: " << exact_seconds << " s, variance left out "
              << 1 - exact_explained << " (" << exact_summary.method << "); the default fit "
              << "leaves out " << 100 * excess << "% more, "
              << 10 * std::log10(1 + excess) << " dB of PSNR\n";
    out["exact"] = {{"seconds", exact_seconds},
                    {"explained_variance", exact_explained},
                    {"method", exact_summary.method},
                    {"excess_left_out", excess}};
  }
  if (flags.reference) {
    const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows = frames;
    const cv::Mat data(m, p, CV_32F, const_cast<float*>(rows.data()));
    const auto cv_start = std::chrono::steady_clock::now();
    const cv::PCA pca(data, cv::Mat(), cv::PCA::DATA_AS_ROW, codec.components());
    const double cv_seconds = Seconds(cv_start);
    Eigen::MatrixXf basis(pca.eigenvectors.rows, p);
    Eigen::RowVectorXf mean(p);
    for (int j = 0; j < p; ++j) mean[j] = pca.mean.at<float>(0, j);
    for (int i = 0; i < basis.rows(); ++i) {
      for (int j = 0; j < p; ++j) basis(i, j) = pca.eigenvectors.at<float>(i, j);
    }
    const double cv_explained = ExplainedBy(frames, mean, basis);
    double max_eigen_gap = 0;
    // Over the signal's components (the noise floor's lie below float32 resolution of a
    // float32 covariance).
    for (int i = 0; i < std::min({static_cast<int>(basis.rows()), codec.components(), r}); ++i) {
      const double a = pca.eigenvalues.at<float>(i, 0), b = codec.eigenvalues()[i];
      max_eigen_gap = std::max(max_eigen_gap, std::abs(a - b) / std::max(1e-30, std::abs(a)));
    }
    std::cout << "cv::PCA (reference): " << cv_seconds << " s, variance left out "
              << 1 - cv_explained << "; speed-up " << cv_seconds / seconds
              << "x; largest relative difference of the first " << r << " eigenvalues "
              << max_eigen_gap << "\n";
    out["reference"] = {{"method", "cv::PCA"},
                        {"seconds", cv_seconds},
                        {"explained_variance", cv_explained},
                        {"speedup", cv_seconds / seconds},
                        {"max_relative_eigenvalue_difference", max_eigen_gap}};
  }
  if (flags.json) EmitJson(out);
}

}  // namespace

void RegisterPcaBenchmark(CLI::App* bench, CommandBody* selected) {
  auto flags = std::make_shared<PcaBenchFlags>();
  CLI::App* sub = bench->add_subcommand(
      "pca", "eval's PCA baseline: wall time of one PcaCodec::Fit on synthetic frames; "
             "--reference also times cv::PCA on the same frames.");
  sub->add_option("--frames", flags->frames, "Frames M (default 3991)")->check(CLI::Range(2, 1000000));
  sub->add_option("--pixels", flags->pixels, "Floats per frame P (default 8560 = 80 x 107)")
      ->check(CLI::Range(2, 10000000));
  sub->add_option("--components", flags->components, "Components kept (default 256)")
      ->check(CLI::Range(1, 100000));
  sub->add_option("--rank", flags->rank, "Rank of the smooth signal (default 64)")
      ->check(CLI::Range(1, 10000));
  sub->add_flag("--reference", flags->reference, "Also fit with cv::PCA and compare");
  sub->add_flag("--exact", flags->exact,
                "Also fit the exact PCA (Gram or covariance matrix in double) and compare");
  sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
  sub->add_option("--data", flags->data,
                  "Instead: what the sensor noise leaves a linear basis on this dataset "
                  "(needs noise-free frames, synth --clean; docs/REPRESENTATION.md)");
  sub->add_option("--model", flags->model, "With --data: the model whose frame formats give "
                  "the targets");
  sub->add_option("--sizes", flags->sizes, "With --data: component counts (default 32,64,128)");
  sub->add_option("--smooth", flags->smooth,
                  "With --data: Gaussian blur of the smoothed basis's frames, pixels "
                  "(default 0.8)")
      ->check(CLI::Range(0.05, 100.0));
  sub->add_option("--sensor", flags->dataset.sensor,
                  "With --data: one sensor (bubble or gelslim; default: every sensor of the "
                  "model the dataset has)");
  sub->callback([flags, selected]() { *selected = [flags]() { RunPcaBench(*flags); }; });
}

}  // namespace tactfunc::apps
