// Copyright 2026 The tactfunc Authors.
#include "estimation/data/contact.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <vector>

#include "estimation/data/dataset.h"
#include "estimation/data/preprocess.h"

namespace tactfunc {
namespace {

// Box sums of every channel and of the valid-pixel count over window x window boxes
// (clipped at the borders), from integral images: the local mean of the change and how
// many pixels it rests on.
struct BoxMeans {
  int rows = 0, cols = 0, channels = 0;
  std::vector<double> mean;   // rows * cols * channels; 0 where count == 0
  std::vector<double> count;  // rows * cols
};

BoxMeans ComputeBoxMeans(const Image& d, int window) {
  const int R = d.rows, C = d.cols, K = d.channels, h = window / 2;
  const int W = C + 1;
  // Integral images with a zero first row and column.
  std::vector<double> sum(static_cast<std::size_t>(R + 1) * W * K, 0.0);
  std::vector<double> n(static_cast<std::size_t>(R + 1) * W, 0.0);
  for (int r = 0; r < R; ++r) {
    for (int c = 0; c < C; ++c) {
      bool valid = true;
      for (int k = 0; k < K; ++k) valid = valid && std::isfinite(d.at(r, c, k));
      const std::size_t at = static_cast<std::size_t>(r + 1) * W + (c + 1);
      const std::size_t up = static_cast<std::size_t>(r) * W + (c + 1);
      const std::size_t left = static_cast<std::size_t>(r + 1) * W + c;
      const std::size_t diag = static_cast<std::size_t>(r) * W + c;
      n[at] = (valid ? 1.0 : 0.0) + n[up] + n[left] - n[diag];
      for (int k = 0; k < K; ++k) {
        sum[at * K + k] = (valid ? static_cast<double>(d.at(r, c, k)) : 0.0) + sum[up * K + k] +
                          sum[left * K + k] - sum[diag * K + k];
      }
    }
  }
  BoxMeans out;
  out.rows = R;
  out.cols = C;
  out.channels = K;
  out.mean.assign(static_cast<std::size_t>(R) * C * K, 0.0);
  out.count.assign(static_cast<std::size_t>(R) * C, 0.0);
  for (int r = 0; r < R; ++r) {
    const int r0 = std::max(0, r - h), r1 = std::min(R, r + h + 1);
    for (int c = 0; c < C; ++c) {
      const int c0 = std::max(0, c - h), c1 = std::min(C, c + h + 1);
      const std::size_t a = static_cast<std::size_t>(r1) * W + c1;
      const std::size_t b = static_cast<std::size_t>(r0) * W + c1;
      const std::size_t e = static_cast<std::size_t>(r1) * W + c0;
      const std::size_t f = static_cast<std::size_t>(r0) * W + c0;
      const std::size_t i = static_cast<std::size_t>(r) * C + c;
      const double count = n[a] - n[b] - n[e] + n[f];
      out.count[i] = count;
      if (count < 0.5) continue;
      for (int k = 0; k < K; ++k) {
        out.mean[i * K + k] =
            (sum[a * K + k] - sum[b * K + k] - sum[e * K + k] + sum[f * K + k]) / count;
      }
    }
  }
  return out;
}

// M at every pixel: the length of the local mean change over the channels.
std::vector<double> Magnitudes(const BoxMeans& box) {
  std::vector<double> m(box.count.size(), 0.0);
  for (std::size_t i = 0; i < m.size(); ++i) {
    double s = 0;
    for (int k = 0; k < box.channels; ++k) s += box.mean[i * box.channels + k] * box.mean[i * box.channels + k];
    m[i] = std::sqrt(s);
  }
  return m;
}

void CentreOf(const std::vector<double>& m, const std::vector<double>& count, int cols,
              double* row, double* col) {
  *row = *col = std::numeric_limits<double>::quiet_NaN();
  double peak = 0;
  for (std::size_t i = 0; i < m.size(); ++i) {
    if (count[i] > 0.5) peak = std::max(peak, m[i]);
  }
  if (!(peak > 0) || !std::isfinite(peak)) return;
  double w = 0, wr = 0, wc = 0;
  for (std::size_t i = 0; i < m.size(); ++i) {
    if (count[i] < 0.5 || m[i] < 0.5 * peak) continue;
    const double weight = m[i] * m[i];
    w += weight;
    wr += weight * static_cast<double>(i / cols);
    wc += weight * static_cast<double>(i % cols);
  }
  *row = wr / w;
  *col = wc / w;
}

void CheckImage(const Image& d, const char* where) {
  if (d.empty() || d.size() != d.pixels() * d.channels) {
    throw std::invalid_argument(std::string(where) + ": expected a non-empty image, got " +
                                d.ShapeString());
  }
}

}  // namespace

bool ContactOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& message) {
    if (error != nullptr) *error = "ContactOptions: " + message;
    return false;
  };
  if (!(std::isfinite(threshold) && threshold > 0)) {
    return fail("threshold: expected a finite number > 0, got " + std::to_string(threshold));
  }
  if (window < 1 || window % 2 == 0) {
    return fail("window: expected an odd number >= 1, got " + std::to_string(window));
  }
  if (!(std::isfinite(noise_floor) && noise_floor >= 0)) {
    return fail("noise_floor: expected a finite number >= 0, got " + std::to_string(noise_floor));
  }
  return true;
}

double QuantisationNoise(PixelEncoding encoding) {
  const double step = encoding == PixelEncoding::kDepthU16Micrometres ? 1e-6 : 1.0 / 255.0;
  return step / std::sqrt(12.0);
}

double EstimateNoiseSigma(const Image& d, double floor) {
  CheckImage(d, "EstimateNoiseSigma");
  std::vector<float> steps;
  steps.reserve(d.size());
  for (int r = 0; r < d.rows; ++r) {
    for (int c = 0; c + 1 < d.cols; ++c) {
      for (int k = 0; k < d.channels; ++k) {
        const float a = d.at(r, c, k), b = d.at(r, c + 1, k);
        if (std::isfinite(a) && std::isfinite(b)) steps.push_back(std::fabs(b - a));
      }
    }
  }
  if (steps.empty()) return floor;
  const auto middle = steps.begin() + static_cast<std::ptrdiff_t>(steps.size() / 2);
  std::nth_element(steps.begin(), middle, steps.end());
  // For Gaussian noise of sigma, a neighbour difference has sigma sqrt(2) and
  // median |.| = 0.6745 sigma sqrt(2).
  const double sigma = 1.4826 * static_cast<double>(*middle) / std::sqrt(2.0);
  return std::max(sigma, floor);
}

ContactReport DetectContact(const Image& difference, const ContactOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  CheckImage(difference, "DetectContact");
  ContactReport report;
  const double floor =
      options.noise_floor > 0 ? options.noise_floor : QuantisationNoise(options.encoding);
  report.noise_sigma = EstimateNoiseSigma(difference, floor);
  const BoxMeans box = ComputeBoxMeans(difference, options.window);
  const std::vector<double> m = Magnitudes(box);
  for (std::size_t i = 0; i < m.size(); ++i) {
    if (box.count[i] < 0.5) continue;
    report.peak = std::max(report.peak, m[i]);
    // A box mean over n pixels has noise sigma / sqrt(n) per channel.
    report.score = std::max(report.score, m[i] * std::sqrt(box.count[i]) / report.noise_sigma);
  }
  report.contact = report.score >= options.threshold;
  CentreOf(m, box.count, difference.cols, &report.centre_row, &report.centre_col);
  return report;
}

ContactReport DetectFrameContact(const Dataset& dataset, std::size_t index,
                                 ContactOptions options) {
  return DetectFrameContact(dataset, index, dataset.LoadFrame(index), options);
}

ContactReport DetectFrameContact(const Dataset& dataset, std::size_t index, const Image& frame,
                                 ContactOptions options) {
  const FrameRecord& record = dataset.frames().at(index);
  options.encoding = dataset.sensor_info(record.sensor).encoding;
  return DetectContact(Difference(frame, dataset.FrameReference(index), record.sensor), options);
}

void ContactCentre(const Image& difference, int window, double* row, double* col) {
  CheckImage(difference, "ContactCentre");
  if (window < 1 || window % 2 == 0) {
    throw std::invalid_argument("ContactCentre: window: expected an odd number >= 1, got " +
                                std::to_string(window));
  }
  const BoxMeans box = ComputeBoxMeans(difference, window);
  CentreOf(Magnitudes(box), box.count, difference.cols, row, col);
}

}  // namespace tactfunc
