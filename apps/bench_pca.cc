// Copyright 2026 The tactfunc Authors.
//
// tactfunc bench pca: the wall time of PcaCodec::Fit (the PCA baseline of `eval`) on a
// synthetic M x P frame matrix, and with --reference the same fit by OpenCV's cv::PCA
// (what PcaCodec used before) with the agreement of the two:
//
//   tactfunc bench pca [--frames 3991] [--pixels 8560] [--components 256] [--reference] [--json]
//
// The frames: a smooth rank-`--rank` signal (component i with scale 1 / (1 + i)) plus
// white noise of standard deviation 0.01, from a fixed seed. One fit each (no
// repetitions: a fit of the default size takes seconds to minutes).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <random>

#include <opencv2/core.hpp>

#include "apps/bench.h"
#include "apps/command.h"
#include "estimation/evaluation/baselines.h"

namespace tactfunc::apps {
namespace {

struct PcaBenchFlags {
  int frames = 3991;
  int pixels = 8560;
  int components = 256;
  int rank = 64;
  bool reference = false;
  bool json = false;
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

void RunPcaBench(const PcaBenchFlags& flags) {
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
  sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
  sub->callback([flags, selected]() { *selected = [flags]() { RunPcaBench(*flags); }; });
}

}  // namespace tactfunc::apps
