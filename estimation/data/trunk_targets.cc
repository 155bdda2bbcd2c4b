// Copyright 2026 The tactfunc Authors.
#include "estimation/data/trunk_targets.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <stdexcept>
#include <string>

#include "estimation/data/dataset.h"
#include "models/core/parallel_for.h"

namespace tactfunc {

PreprocessOptions ToPreprocessOptions(const FrameFormat& format) {
  PreprocessOptions options;
  options.rows = format.rows;
  options.cols = format.cols;
  options.grayscale = format.grayscale;
  options.normalization = format.per_image_min_max
                              ? PreprocessOptions::Normalization::kPerImageMinMax
                              : PreprocessOptions::Normalization::kFixedScale;
  options.fixed_scale = format.per_image_min_max ? 0.0 : format.scale;
  return options;
}

TrunkTargets MakeTrunkTargets(const Image& frame, const Image& reference, SensorKind sensor,
                              const FrameFormat& format) {
  const PreprocessedFrame pre =
      Preprocess(frame, reference, sensor, ToPreprocessOptions(format), format.scale);
  TrunkTargets out;
  out.rows = pre.values.rows;
  out.cols = pre.values.cols;
  const int n = out.rows * out.cols;
  const int c = pre.values.channels;
  out.values = Eigen::Map<const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic,
                                              Eigen::RowMajor>>(pre.values.data.data(), n, c);
  out.weights.resize(n);
  for (int j = 0; j < n; ++j) out.weights[j] = pre.valid[j] ? 1.0f : 0.0f;
  out.flat = pre.flat;
  out.scale = pre.scale;
  out.offset = pre.offset;
  out.source_range = pre.source_range / pre.scale;
  return out;
}

TrunkTargets LoadTrunkTargets(const Dataset& dataset, std::size_t index,
                              const FrameFormat& format, bool clean) {
  return DatasetFrameTargets(
      dataset, index, clean ? dataset.LoadCleanFrame(index) : dataset.LoadFrame(index), format);
}

std::vector<TrunkTargets> LoadTrunkTargets(const Dataset& dataset,
                                           const std::vector<std::size_t>& indices,
                                           const FrameFormat& format, bool clean, int threads) {
  std::vector<TrunkTargets> out(indices.size());
  internal::ParallelFor(static_cast<int>(indices.size()), threads, [&](int i) {
    out[i] = LoadTrunkTargets(dataset, indices[i], format, clean);
  });
  return out;
}

TrunkTargets DatasetFrameTargets(const Dataset& dataset, std::size_t index, const Image& frame,
                                 const FrameFormat& format) {
  const FrameRecord& record = dataset.frames().at(index);
  return MakeTrunkTargets(frame, dataset.FrameReference(index), record.sensor, format);
}

namespace {

// Sum of squared errors over the valid pixels, their count and the target's range.
struct ErrorAndRange {
  double sse = 0;
  std::int64_t count = 0;
  double range = 0;
};

ErrorAndRange MeasureError(const Eigen::MatrixXf& prediction, const TrunkTargets& target) {
  if (prediction.rows() != target.values.rows() || prediction.cols() != target.values.cols()) {
    throw std::invalid_argument("Psnr: prediction is " + std::to_string(prediction.rows()) +
                                "x" + std::to_string(prediction.cols()) + ", target " +
                                std::to_string(target.values.rows()) + "x" +
                                std::to_string(target.values.cols()));
  }
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  ErrorAndRange out;
  for (Eigen::Index j = 0; j < target.values.rows(); ++j) {
    if (!(target.weights[j] > 0)) continue;
    for (Eigen::Index c = 0; c < target.values.cols(); ++c) {
      const double t = target.values(j, c);
      const double d = static_cast<double>(prediction(j, c)) - t;
      lo = std::min(lo, t);
      hi = std::max(hi, t);
      out.sse += d * d;
      ++out.count;
    }
  }
  out.range = out.count > 0 ? hi - lo : 0.0;
  return out;
}

double PsnrAtPeak(const ErrorAndRange& e, double range) {
  if (e.count == 0) return std::numeric_limits<double>::quiet_NaN();
  if (!(range >= 1e-9)) range = 1.0;
  const double mse = e.sse / e.count;
  if (mse == 0) return std::numeric_limits<double>::infinity();
  return 10.0 * std::log10(range * range / mse);
}

}  // namespace

double Psnr(const Eigen::MatrixXf& prediction, const TrunkTargets& target) {
  const ErrorAndRange e = MeasureError(prediction, target);
  return PsnrAtPeak(e, e.range);
}

double PsnrSourcePeak(const Eigen::MatrixXf& prediction, const TrunkTargets& target) {
  return PsnrAtPeak(MeasureError(prediction, target), target.source_range);
}

double TargetRange(const TrunkTargets& target) {
  return MeasureError(target.values, target).range;
}

double Rmse(const Eigen::MatrixXf& prediction, const TrunkTargets& target) {
  const ErrorAndRange e = MeasureError(prediction, target);
  if (e.count == 0) return std::numeric_limits<double>::quiet_NaN();
  return std::sqrt(e.sse / e.count);
}

Image TargetsToImage(const Eigen::MatrixXf& values, int rows, int cols) {
  if (values.rows() != static_cast<Eigen::Index>(rows) * cols) {
    throw std::invalid_argument("TargetsToImage: " + std::to_string(values.rows()) +
                                " rows, expected " + std::to_string(rows) + "x" +
                                std::to_string(cols));
  }
  Image image(rows, cols, static_cast<int>(values.cols()));
  for (int j = 0; j < rows * cols; ++j) {
    for (int c = 0; c < image.channels; ++c) image.data[j * image.channels + c] = values(j, c);
  }
  return image;
}

void CheckTargetsShape(const TrunkTargets& targets, int rows, int cols, int channels,
                       const std::string& who) {
  const Eigen::Index n = static_cast<Eigen::Index>(rows) * cols;
  if (targets.rows != rows || targets.cols != cols || targets.values.rows() != n ||
      targets.values.cols() != channels ||
      (targets.weights.size() != 0 && targets.weights.size() != n)) {
    throw std::invalid_argument(
        who + ": expected the targets of a " + std::to_string(rows) + " x " +
        std::to_string(cols) + " frame (" + std::to_string(n) + " x " +
        std::to_string(channels) + " values and as many weights), found a " +
        std::to_string(targets.rows) + " x " + std::to_string(targets.cols) + " frame of " +
        std::to_string(targets.values.rows()) + " x " + std::to_string(targets.values.cols()) +
        " values and " + std::to_string(targets.weights.size()) + " weights");
  }
}

std::vector<int> ValidPixels(const TrunkTargets& targets) {
  std::vector<int> valid;
  const Eigen::Index n = targets.values.rows();
  for (Eigen::Index j = 0; j < n; ++j) {
    if (targets.weights.size() == 0 || targets.weights[j] > 0) {
      valid.push_back(static_cast<int>(j));
    }
  }
  return valid;
}

std::vector<double> ContactDrawProbabilities(const TrunkTargets& targets,
                                             const std::vector<int>& pixels, double share) {
  const size_t n = pixels.size();
  std::vector<double> energy(n);
  double total = 0;
  for (size_t i = 0; i < n; ++i) {
    const int j = pixels[i];
    const double w = targets.weights.size() == 0 ? 1.0 : targets.weights[j];
    energy[i] = w * targets.values.row(j).cast<double>().squaredNorm();
    total += energy[i];
  }
  if (!(total > 0) || !std::isfinite(total)) share = 0;
  std::vector<double> p(n);
  for (size_t i = 0; i < n; ++i) {
    p[i] = (1 - share) / static_cast<double>(n) + (share > 0 ? share * energy[i] / total : 0);
  }
  return p;
}

ContactDraw::ContactDraw(const TrunkTargets& targets, double share, bool with_guide) {
  std::vector<int> all(targets.values.rows());
  std::iota(all.begin(), all.end(), 0);
  cdf = ContactDrawProbabilities(targets, all, share);
  std::partial_sum(cdf.begin(), cdf.end(), cdf.begin());
  if (!cdf.empty()) cdf.back() = 1.0;
  if (!with_guide) return;
  const int n = static_cast<int>(cdf.size());
  guide.resize(n);
  for (int b = 0, j = 0; b < n; ++b) {
    const double lower = static_cast<double>(b) / n;
    while (j < n - 1 && cdf[j] <= lower) ++j;
    guide[b] = j;
  }
}

int ContactDraw::Pixel(double u) const {
  const int n = static_cast<int>(cdf.size());
  if (guide.empty()) {
    return std::min<int>(
        n - 1, static_cast<int>(std::upper_bound(cdf.begin(), cdf.end(), u) - cdf.begin()));
  }
  // The guide's bucket of u; the two walks make the answer exact whatever u n rounds to.
  int j = guide[std::min(n - 1, static_cast<int>(u * n))];
  while (j > 0 && cdf[j - 1] > u) --j;
  while (j < n - 1 && cdf[j] <= u) ++j;
  return j;
}

void ContactSample(const TrunkTargets& targets, int m, double share, std::vector<int>* pixels,
                   std::vector<double>* weight_factor) {
  const size_t n = pixels->size();
  const std::vector<double> p = ContactDrawProbabilities(targets, *pixels, share);
  std::vector<int> kept;
  weight_factor->clear();
  double cumulative = 0;
  int next = 0;  // the next sampling position (next + 1/2) / m
  for (size_t i = 0; i < n && next < m; ++i) {
    cumulative += p[i];
    int count = 0;
    while (next < m && (next + 0.5) / m < cumulative) {
      ++count;
      ++next;
    }
    if (count == 0) continue;
    kept.push_back((*pixels)[i]);
    weight_factor->push_back(count / (static_cast<double>(n) * p[i]));
  }
  pixels->swap(kept);
}

}  // namespace tactfunc
