// Copyright 2026 The tactfunc Authors.
#include "apps/bench/fit_common.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <random>

namespace tactfunc::apps::bench {

// q-quantile (nearest rank) of a sample; NaN if empty.
double Quantile(std::vector<double> values, double q) {
  if (values.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::sort(values.begin(), values.end());
  const double rank = std::ceil(q * values.size());
  const std::size_t i = static_cast<std::size_t>(std::clamp(rank - 1.0, 0.0, values.size() - 1.0));
  return values[i];
}

double Median(const std::vector<double>& values) {
  if (values.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::vector<double> v = values;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

double Mean(const std::vector<double>& values) {
  double sum = 0;
  int n = 0;
  for (double v : values) {
    if (std::isfinite(v)) {
      sum += v;
      ++n;
    }
  }
  return n ? sum / n : std::numeric_limits<double>::quiet_NaN();
}

// Three significant digits for times that span 0.01 .. 10,000 ms.
std::string Ms(double value) {
  if (!std::isfinite(value)) return "n/a";
  char buffer[48];
  if (value >= 100) {
    std::snprintf(buffer, sizeof(buffer), "%.0f", value);
  } else if (value >= 10) {
    std::snprintf(buffer, sizeof(buffer), "%.1f", value);
  } else if (value >= 1) {
    std::snprintf(buffer, sizeof(buffer), "%.2f", value);
  } else {
    std::snprintf(buffer, sizeof(buffer), "%.3f", value);
  }
  return buffer;
}

nlohmann::json FiniteOrNull(double value) {
  return std::isfinite(value) ? nlohmann::json(value) : nlohmann::json(nullptr);
}

std::string CommandLine(const std::vector<std::string>& parts) {
  std::string out;
  for (const std::string& p : parts) {
    if (p.empty()) continue;
    out += (out.empty() ? "" : " ") + p;
  }
  return out;
}

TrunkTargets TrunkGeneratedFrame(const LatentModulatedSiren& siren, int rows, int cols,
                                 std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::VectorXf truth(siren.latent_dim());
  for (int k = 0; k < truth.size(); ++k) truth[k] = static_cast<float>(0.3 * normal(rng));
  TrunkTargets targets;
  targets.rows = rows;
  targets.cols = cols;
  targets.values = siren.Forward<float>(siren.Grid<float>(rows, cols), truth);
  for (int i = 0; i < targets.values.size(); ++i) {
    targets.values.data()[i] += static_cast<float>(0.01 * normal(rng));
  }
  targets.weights = Eigen::VectorXf::Ones(static_cast<long>(rows) * cols);
  return targets;
}

}  // namespace tactfunc::apps::bench
