// Copyright 2026 The tactfunc Authors.
//
// Benchmarks of latent fitting (issue 4; estimation/fitting/latent_fitter.h, knn_index.h):
//
//   tactfunc bench fit      every LatentFitter strategy on the test frames of a dataset:
//                           per-frame time (median, p90) and mean PSNR, against the
//                           converged PSNR (ceres:100, tight tolerances, double), the
//                           autodiff / analytic Jacobian time ratio, a Pareto plot (PNG)
//                           and a markdown table for docs/BENCHMARKS.md.
//   tactfunc bench kernels  Google Benchmark programs of the kernels one fit is made of:
//                           trunk forward, forward + latent Jacobian (analytic), the
//                           autodiff Jacobian, one LM iteration, one meta-SGD step, and an
//                           Eigen float GEMM (GFLOP/s, to re-measure -march=native).
//   tactfunc bench knn      FLANN kd-forest / k-means at several checks against brute force:
//                           recall@8, median ms per query, build time.
//
// `bench fit` and `bench knn` time with std::chrono, one measurement per frame (query),
// and report the distribution (median, p90): they measure what a user waits per frame,
// on real frames whose iteration counts differ, which is a distribution and not the
// steady state of one repeated call that Google Benchmark is made for. `bench kernels`
// is that steady state and uses Google Benchmark (RunRegisteredBenchmarks, medians over
// repetitions).
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <opencv2/imgproc.hpp>
#include <random>
#include <sstream>
#include <thread>

#include "apps/bench.h"
#include "apps/command.h"
#include "apps/dataset_flags.h"
#include "apps/pictures.h"
#include "apps/progress_bar.h"
#include "benchmark/benchmark.h"
#include "ceres/problem.h"
#include "ceres/solver.h"
#include "estimation/data/dataset.h"
#include "estimation/functaset/functaset.h"
#include "estimation/fitting/latent_costs.h"
#include "estimation/knn/knn_index.h"
#include "estimation/fitting/latent_fitter.h"
#include "estimation/evaluation/reconstruction.h"
#include "estimation/data/trunk_targets.h"
#include "models/trunk/functa_model.h"

namespace tactfunc::apps {
namespace {

using Clock = std::chrono::steady_clock;

double MsSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

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

std::vector<SensorKind> ParseSensors(const std::string& text) {
  std::vector<SensorKind> sensors;
  for (const std::string& name : SplitList(text)) {
    SensorKind kind;
    if (!SensorKindFromString(name, &kind)) {
      throw UsageError("--sensors: expected bubble and/or gelslim, got '" + name + "'");
    }
    sensors.push_back(kind);
  }
  return sensors;
}

// ==== bench fit =========================================================================

// One row of the table: a strategy with a precision and a Jacobian mode.
struct Variant {
  std::string strategy;
  LatentProblem::Precision precision = LatentProblem::Precision::kFloat;
  LatentFitter::JacobianMode jacobian = LatentFitter::JacobianMode::kAnalytic;
  int max_frames = 0;  // 0 = all test frames; autodiff runs on a couple only (it is slow)

  std::string Label() const {
    if (jacobian == LatentFitter::JacobianMode::kAutoDiff) return strategy + " autodiff";
    return strategy + (precision == LatentProblem::Precision::kDouble ? " double" : "");
  }
};

std::vector<Variant> FitVariants(int autodiff_frames) {
  using P = LatentProblem::Precision;
  using J = LatentFitter::JacobianMode;
  std::vector<Variant> variants;
  for (const char* s : {"meta_sgd:1", "meta_sgd:3", "meta_sgd:10", "ceres:2", "ceres:5", "ceres:10",
                        "ceres:20", "knn", "knn+meta_sgd:3", "knn+ceres:2", "knn+ceres:5"}) {
    variants.push_back({s, P::kFloat, J::kAnalytic, 0});
  }
  // Double where the precision can matter: the trunk's own steps, LM, and the combination.
  for (const char* s : {"meta_sgd:3", "ceres:5", "ceres:20", "knn+ceres:5"}) {
    variants.push_back({s, P::kDouble, J::kAnalytic, 0});
  }
  // The autodiff reference (always double): the whole solve, on a few frames.
  if (autodiff_frames > 0)
    variants.push_back({"ceres:2", P::kDouble, J::kAutoDiff, autodiff_frames});
  return variants;
}

struct VariantResult {
  Variant variant;
  SensorKind sensor = SensorKind::kSoftBubble;
  std::vector<double> ms, psnr, psnr_clean, iterations;
  double ms_median = 0, ms_p90 = 0, psnr_mean = 0, psnr_clean_mean = 0, iterations_mean = 0;
  double delta_db = 0;                      // psnr_mean - converged PSNR of the same frames
  std::vector<double> converged_of_frames;  // converged PSNR of the frames this variant ran
};

struct SensorFitData {
  SensorKind sensor = SensorKind::kSoftBubble;
  const SensorTrunk* trunk = nullptr;
  std::vector<std::string> ids;
  std::vector<TrunkTargets> targets, clean;  // clean empty if the dataset has none
  std::vector<double> load_ms;               // read + preprocess per frame
  Eigen::MatrixXf train_latents;             // the k-NN base: the functaset's TRAIN latents
  std::unique_ptr<BruteForceKnnIndex> index;
  std::vector<double> converged_psnr, converged_psnr_clean;  // per frame
  double converged_mean = 0, converged_clean_mean = 0;
  double converged_ms_median = 0, converged_iterations_mean = 0;
  // Jacobian timings (ms, median) at the first test frame.
  double jacobian_float_ms = 0, jacobian_double_ms = 0, jacobian_autodiff_ms = 0;
  double residuals_float_ms = 0;
};

// Runs fn(i) for i in [0, n) on `threads` threads (each fit single-threaded).
template <typename Fn>
void ForFrames(int n, int threads, const Fn& fn) {
  if (threads <= 1 || n <= 1) {
    for (int i = 0; i < n; ++i) fn(i);
    return;
  }
  std::atomic<int> next{0};
  std::vector<std::thread> workers;
  for (int t = 0; t < threads; ++t) {
    workers.emplace_back([&]() {
      for (int i = next++; i < n; i = next++) fn(i);
    });
  }
  for (std::thread& w : workers) w.join();
}

LatentFitter::Options VariantOptions(const Variant& v) {
  LatentFitter::Options options;
  options.strategy = FitStrategy::FromString(v.strategy);
  options.jacobian = v.jacobian;
  options.knn_k = 8;
  return options;
}

// The converged reference: ceres:100 in double with tolerances far below Ceres' defaults.
LatentFitter::Options ConvergedOptions() {
  LatentFitter::Options options;
  options.strategy = FitStrategy::FromString("ceres:100");
  options.solver_options.function_tolerance = 1e-12;
  options.solver_options.gradient_tolerance = 1e-14;
  options.solver_options.parameter_tolerance = 1e-12;
  return options;
}

// Median time of `repeats` evaluations of `cost` (residuals and, if with_jacobian, the
// Jacobian) at z.
double TimeEvaluate(const ceres::CostFunction& cost, const Eigen::VectorXd& z, int num_residuals,
                    bool with_jacobian, int repeats) {
  std::vector<double> residuals(num_residuals);
  std::vector<double> jacobian(with_jacobian ? static_cast<std::size_t>(num_residuals) * z.size()
                                             : 0);
  const double* parameters[] = {z.data()};
  double* jacobians[] = {jacobian.data()};
  std::vector<double> times;
  for (int r = 0; r < repeats; ++r) {
    const Clock::time_point start = Clock::now();
    cost.Evaluate(parameters, residuals.data(), with_jacobian ? jacobians : nullptr);
    times.push_back(MsSince(start));
  }
  return Median(times);
}

void MeasureJacobians(SensorFitData* s, const Eigen::VectorXd& z) {
  LatentProblem::Options float_options, double_options;
  double_options.precision = LatentProblem::Precision::kDouble;
  const LatentProblem problem_float(*s->trunk, s->targets[0], float_options);
  const LatentProblem problem_double(*s->trunk, s->targets[0], double_options);
  const int n = problem_float.num_residuals();
  AnalyticLatentCost analytic_float(&problem_float);
  AnalyticLatentCost analytic_double(&problem_double);
  const std::unique_ptr<ceres::CostFunction> autodiff = MakeAutoDiffLatentCost(&problem_double);
  TimeEvaluate(analytic_float, z, n, true, 2);  // warm-up
  s->jacobian_float_ms = TimeEvaluate(analytic_float, z, n, true, 21);
  s->jacobian_double_ms = TimeEvaluate(analytic_double, z, n, true, 21);
  s->residuals_float_ms = TimeEvaluate(analytic_float, z, n, false, 21);
  s->jacobian_autodiff_ms = TimeEvaluate(*autodiff, z, n, true, 3);
}

struct FitBenchFlags {
  std::string model, functaset, data, sensors, plot, table;
  int threads = 1;
  int frames = 20;
  int autodiff_frames = 2;
  bool json = false;
  DatasetFlags dataset;
  std::vector<std::string> argv;  // for the report
};

// ---- The Pareto plot ----------------------------------------------------------------------

cv::Scalar SensorColour(SensorKind sensor) {
  return sensor == SensorKind::kSoftBubble ? cv::Scalar(40, 140, 255)   // orange
                                           : cv::Scalar(230, 160, 40);  // blue
}

cv::Mat ParetoPlot(const std::vector<VariantResult>& results,
                   const std::vector<SensorFitData>& sensors, int threads,
                   const std::string& machine) {
  const LogXPlot::Layout layout;  // 1400 x 760, legend in the right margin
  const int width = layout.width;
  // A variant run on fewer frames than the converged reference (autodiff) is plotted at
  // the sensor's converged PSNR plus its own difference to converged on ITS frames, so
  // that every point compares the same thing; it is left out of the Pareto front.
  std::map<SensorKind, const SensorFitData*> by_sensor;
  for (const SensorFitData& s : sensors) by_sensor[s.sensor] = &s;
  auto subset = [&](const VariantResult& r) {
    return r.ms.size() < by_sensor.at(r.sensor)->converged_psnr.size();
  };
  auto plotted = [&](const VariantResult& r) {
    return subset(r) ? by_sensor.at(r.sensor)->converged_mean + r.delta_db : r.psnr_mean;
  };
  auto drawable = [&](const VariantResult& r) {
    return r.ms_median > 0 && std::isfinite(plotted(r));
  };
  double x_lo = std::numeric_limits<double>::infinity(), x_hi = 0;
  double y_lo = std::numeric_limits<double>::infinity(), y_hi = -y_lo;
  for (const VariantResult& r : results) {
    if (!drawable(r)) continue;
    x_lo = std::min(x_lo, r.ms_median);
    x_hi = std::max(x_hi, r.ms_median);
    y_lo = std::min(y_lo, plotted(r));
    y_hi = std::max(y_hi, plotted(r));
  }
  for (const SensorFitData& s : sensors) {
    if (std::isfinite(s.converged_mean)) {
      y_lo = std::min(y_lo, s.converged_mean);
      y_hi = std::max(y_hi, s.converged_mean);
    }
  }
  if (!std::isfinite(x_lo)) x_lo = 1, x_hi = 10, y_lo = 0, y_hi = 1;
  x_lo = std::min(x_lo, 33.0 / 1.5);
  x_hi = std::max(x_hi, 33.0 * 1.5);
  LogXPlot plot(layout, x_lo, x_hi, y_lo, y_hi);
  cv::Mat& canvas = plot.canvas();
  const int left = plot.area().x, top = plot.area().y, pw = plot.area().width,
            ph = plot.area().height;
  auto X = [&](double ms) { return plot.X(ms); };
  auto Y = [&](double db) { return plot.Y(db); };
  plot.DrawFrame("time per frame, ms (median, log scale)", "mean PSNR vs noisy frame, dB",
                 "LatentFitter strategies: time vs quality (test frames, " +
                     std::to_string(threads) + (threads == 1 ? " thread)" : " threads)"),
                 machine);

  // The 33 ms line (30 frames/s) and each sensor's converged PSNR.
  if (X(33) > left && X(33) < left + pw) {
    DrawDashedLine(canvas, {X(33), top}, {X(33), top + ph}, cv::Scalar(90, 90, 200));
    PlainText(canvas, "33 ms", {X(33) + 4, top + 16}, 0.45, cv::Scalar(90, 90, 200));
  }
  std::vector<cv::Rect> taken;  // label and point boxes, for placing labels
  for (const SensorFitData& s : sensors) {
    if (!std::isfinite(s.converged_mean)) continue;
    const int y = Y(s.converged_mean);
    DrawDashedLine(canvas, {left, y}, {left + pw, y}, SensorColour(s.sensor));
    const std::string text = std::string("converged ") + ToString(s.sensor) + " " +
                             FormatFixed(s.converged_mean, 2) + " dB (ceres:100 double)";
    int base = 0;
    const cv::Size size = cv::getTextSize(text, cv::FONT_HERSHEY_SIMPLEX, 0.42, 1, &base);
    PlainText(canvas, text, {left + 8, y - 5}, 0.42, SensorColour(s.sensor));
    taken.push_back(cv::Rect(left + 8, y - 5 - size.height, size.width, size.height + 2));
  }

  // Pareto front per sensor (no other point is both faster and better).
  for (const SensorFitData& s : sensors) {
    std::vector<const VariantResult*> pts;
    for (const VariantResult& r : results) {
      if (r.sensor == s.sensor && drawable(r) && !subset(r)) pts.push_back(&r);
    }
    std::sort(pts.begin(), pts.end(), [](auto* a, auto* b) { return a->ms_median < b->ms_median; });
    std::vector<cv::Point> front;
    double best = -std::numeric_limits<double>::infinity();
    for (const VariantResult* r : pts) {
      if (r->psnr_mean > best) {
        best = r->psnr_mean;
        front.push_back({X(r->ms_median), Y(r->psnr_mean)});
      }
    }
    if (front.size() > 1)
      cv::polylines(canvas, front, false, SensorColour(s.sensor), 1, cv::LINE_AA);
  }

  // Points, then one label per group of coincident points (same sensor, within 4 px),
  // placed where it overlaps no point and no earlier label.
  struct Group {
    SensorKind sensor;
    cv::Point p;
    std::string text;
  };
  std::vector<Group> groups;
  for (const VariantResult& r : results) {
    if (!drawable(r)) continue;
    const cv::Point p(X(r.ms_median), Y(plotted(r)));
    const cv::Scalar colour = SensorColour(r.sensor);
    if (r.variant.jacobian == LatentFitter::JacobianMode::kAutoDiff) {
      cv::rectangle(canvas, p - cv::Point(5, 5), p + cv::Point(5, 5), colour, 2, cv::LINE_AA);
    } else if (r.variant.precision == LatentProblem::Precision::kDouble) {
      cv::circle(canvas, p, 5, colour, 2, cv::LINE_AA);
    } else {
      cv::circle(canvas, p, 5, colour, cv::FILLED, cv::LINE_AA);
    }
    taken.push_back(cv::Rect(p.x - 6, p.y - 6, 12, 12));
    const std::string label =
        r.variant.Label() + (subset(r) ? " (" + std::to_string(r.ms.size()) + " frames)" : "");
    bool merged = false;
    for (Group& g : groups) {
      if (g.sensor == r.sensor && std::abs(g.p.x - p.x) <= 4 && std::abs(g.p.y - p.y) <= 4) {
        g.text += ", " + label;
        merged = true;
        break;
      }
    }
    if (!merged) groups.push_back({r.sensor, p, label});
  }
  const cv::Rect plot_area(left, top, pw, ph);
  for (const Group& g : groups) {
    const cv::Point p = g.p;
    int base = 0;
    const cv::Size size = cv::getTextSize(g.text, cv::FONT_HERSHEY_SIMPLEX, 0.4, 1, &base);
    const cv::Point offsets[] = {{8, 4},
                                 {8, -8},
                                 {8, 16},
                                 {-size.width - 8, 4},
                                 {-size.width - 8, -8},
                                 {-size.width - 8, 16},
                                 {8, -20},
                                 {8, 28},
                                 {-size.width / 2, -12},
                                 {-size.width / 2, 24},
                                 {-size.width / 2, -24},
                                 {-size.width / 2, 36}};
    cv::Rect chosen;
    bool placed = false;
    for (const cv::Point& o : offsets) {
      const cv::Rect rect(p.x + o.x, p.y + o.y - size.height, size.width, size.height + 3);
      if ((rect & plot_area) != rect) continue;
      bool clash = false;
      for (const cv::Rect& t : taken) clash = clash || (rect & t).area() > 0;
      if (!clash) {
        chosen = rect;
        placed = true;
        break;
      }
    }
    if (!placed) chosen = cv::Rect(p.x + 8, p.y + 4 - size.height, size.width, size.height + 3);
    taken.push_back(chosen);
    // A label moved away from its point gets a faint leader line to the nearer end.
    const cv::Point near_end(std::abs(chosen.x - p.x) < std::abs(chosen.x + chosen.width - p.x)
                                 ? chosen.x - 2
                                 : chosen.x + chosen.width + 2,
                             chosen.y + chosen.height / 2);
    if (std::hypot(near_end.x - p.x, near_end.y - p.y) > 14) {
      cv::line(canvas, p, near_end, SensorColour(g.sensor) * 0.5 + cv::Scalar(120, 120, 120), 1,
               cv::LINE_AA);
    }
    PlainText(canvas, g.text, {chosen.x, chosen.y + size.height}, 0.4,
              SensorColour(g.sensor) * 0.7);
  }

  // Legend, right of the plot.
  const int lx = left + pw + 22, ly = top + 14;
  const int legend_rows = static_cast<int>(sensors.size()) + 5;
  cv::rectangle(canvas, {lx - 8, ly - 12}, {width - 8, ly + 20 * legend_rows},
                cv::Scalar(180, 180, 180), 1);
  int row = 0;
  for (const SensorFitData& s : sensors) {
    cv::circle(canvas, {lx + 6, ly + 20 * row}, 5, SensorColour(s.sensor), cv::FILLED, cv::LINE_AA);
    PlainText(canvas,
              std::string(ToString(s.sensor)) + " (" + std::to_string(s.trunk->format.rows) + "x" +
                  std::to_string(s.trunk->format.cols) +
                  ", d=" + std::to_string(s.trunk->siren.latent_dim()) + ")",
              {lx + 18, ly + 20 * row + 5}, 0.42);
    ++row;
  }
  const cv::Scalar grey(120, 120, 120);
  cv::circle(canvas, {lx + 6, ly + 20 * row}, 5, grey, cv::FILLED, cv::LINE_AA);
  PlainText(canvas, "float, analytic Jacobian", {lx + 18, ly + 20 * row + 5}, 0.42);
  ++row;
  cv::circle(canvas, {lx + 6, ly + 20 * row}, 5, grey, 2, cv::LINE_AA);
  PlainText(canvas, "double, analytic Jacobian", {lx + 18, ly + 20 * row + 5}, 0.42);
  ++row;
  cv::rectangle(canvas, cv::Point(lx + 1, ly + 20 * row - 5), cv::Point(lx + 11, ly + 20 * row + 5),
                grey, 2);
  PlainText(canvas, "autodiff Jacobian (double),", {lx + 18, ly + 20 * row + 5}, 0.42);
  ++row;
  PlainText(canvas, "at converged + its own delta", {lx + 18, ly + 20 * row + 5}, 0.42);
  ++row;
  cv::line(canvas, {lx, ly + 20 * row}, {lx + 12, ly + 20 * row}, grey, 1, cv::LINE_AA);
  PlainText(canvas, "Pareto front per sensor", {lx + 18, ly + 20 * row + 5}, 0.42);
  return canvas;
}

// ---- The table ------------------------------------------------------------------------------

std::string FitTable(const std::vector<VariantResult>& results,
                     const std::vector<SensorFitData>& sensors, const FitBenchFlags& flags,
                     const nlohmann::json& machine, const nlohmann::json& targets) {
  std::ostringstream md;
  const bool clean = !sensors.empty() && !sensors[0].clean.empty();
  md << "Command: `" << CommandLine(flags.argv) << "`\n\n";
  md << "Machine: " << machine.value("cpu", std::string("?")) << ", " << machine.value("cores", 0)
     << " cores, " << flags.threads
     << (flags.threads == 1 ? " thread" : " threads (frames in parallel, one fit per thread)")
     << ". Time per frame is wall time of `LatentFitter::Fit` (std::chrono, one measurement per "
        "frame; reading and preprocessing excluded), median and p90 over the frames: a per-frame "
        "distribution, not a Google Benchmark steady state. PSNR is THE PSNR of "
        "estimation/data/trunk_targets.h against the noisy test frame"
     << (clean ? " (and against its clean copy)" : "")
     << "; \"vs conv.\" is the mean PSNR minus the converged PSNR (ceres:100, double, tolerances "
        "1e-12/1e-14/1e-12) of the same frames. k-NN searches the functaset's TRAIN latents "
        "(exact, brute force, k = 8), so a test frame never finds itself.\n\n";
  md << "| sensor | strategy | precision | Jacobian | frames | ms median | ms p90 | PSNR mean (dB) "
        "| vs conv. (dB) |"
     << (clean ? " PSNR clean (dB) |" : "") << " iterations |\n";
  md << "|---|---|---|---|---|---|---|---|---|" << (clean ? "---|" : "") << "---|\n";
  for (const SensorFitData& s : sensors) {
    for (const VariantResult& r : results) {
      if (r.sensor != s.sensor) continue;
      md << "| " << ToString(r.sensor) << " | `" << r.variant.strategy << "` | "
         << ToString(r.variant.precision) << " | " << ToString(r.variant.jacobian) << " | "
         << r.ms.size() << " | " << Ms(r.ms_median) << " | " << Ms(r.ms_p90) << " | "
         << FormatFixed(r.psnr_mean, 2) << " | " << (r.delta_db >= 0 ? "+" : "")
         << FormatFixed(r.delta_db, 2) << " |";
      if (clean) md << " " << FormatFixed(r.psnr_clean_mean, 2) << " |";
      md << " " << FormatFixed(r.iterations_mean, 1) << " |\n";
    }
    md << "| " << ToString(s.sensor) << " | **converged** `ceres:100` | double | analytic | "
       << s.converged_psnr.size() << " | " << Ms(s.converged_ms_median) << " | | "
       << FormatFixed(s.converged_mean, 2) << " | 0 |";
    if (clean) md << " " << FormatFixed(s.converged_clean_mean, 2) << " |";
    md << " " << FormatFixed(s.converged_iterations_mean, 1) << " |\n";
  }
  md << "\nJacobian of all residuals at the first test frame (one `Evaluate`, median; autodiff "
        "of 3, analytic of 21):\n\n";
  md << "| sensor | frame | residuals only (float) | analytic float | analytic double | autodiff | "
        "autodiff / analytic float | autodiff / analytic double |\n";
  md << "|---|---|---|---|---|---|---|---|\n";
  for (const SensorFitData& s : sensors) {
    md << "| " << ToString(s.sensor) << " | " << s.trunk->format.rows << "x" << s.trunk->format.cols
       << " | " << Ms(s.residuals_float_ms) << " ms | " << Ms(s.jacobian_float_ms) << " ms | "
       << Ms(s.jacobian_double_ms) << " ms | " << Ms(s.jacobian_autodiff_ms) << " ms | "
       << FormatFixed(s.jacobian_autodiff_ms / s.jacobian_float_ms, 0) << "x | "
       << FormatFixed(s.jacobian_autodiff_ms / s.jacobian_double_ms, 0) << "x |\n";
  }
  md << "\nTargets:\n\n";
  for (const auto& [name, t] : targets.items()) {
    md << "- " << name << ": " << (t.value("met", false) ? "**met**" : "**not met**") << " -- "
       << t.value("detail", std::string()) << "\n";
  }
  return md.str();
}

void RunFitBench(const FitBenchFlags& flags) {
  if (flags.threads < 1 || flags.threads > 2) throw UsageError("--threads: expected 1 or 2");
  const FunctaModel model = FunctaModel::Load(flags.model);
  const Functaset functaset = Functaset::Load(flags.functaset);
  functaset.CheckModel(model, flags.model, flags.functaset);
  const Dataset dataset = OpenDataset(flags.data, flags.dataset);

  std::vector<SensorKind> wanted =
      flags.sensors.empty() ? model.sensors() : ParseSensors(flags.sensors);
  std::vector<SensorFitData> sensors;
  for (SensorKind sensor : wanted) {
    const bool usable =
        model.HasSensor(sensor) && functaset.has_sensor(sensor) && dataset.has_sensor(sensor);
    if (!usable) {
      if (!flags.sensors.empty()) {
        throw UsageError(std::string("--sensors: ") + ToString(sensor) +
                         " is not in all of the model, the functaset and the dataset");
      }
      continue;
    }
    SensorFitData s;
    s.sensor = sensor;
    s.trunk = &model.Trunk(sensor);
    std::vector<std::size_t> indices = dataset.FrameIndices(sensor, Split::kTest);
    if (indices.size() > static_cast<std::size_t>(flags.frames)) indices.resize(flags.frames);
    if (indices.empty()) {
      std::cerr << "bench fit: note: no test frames of " << ToString(sensor) << "; skipped\n";
      continue;
    }
    for (std::size_t index : indices) {
      const Clock::time_point start = Clock::now();
      s.targets.push_back(LoadTrunkTargets(dataset, index, s.trunk->format));
      s.load_ms.push_back(MsSince(start));
      s.ids.push_back(dataset.frames()[index].id);
      if (dataset.has_clean() && !dataset.frames()[index].clean_path.empty()) {
        s.clean.push_back(LoadTrunkTargets(dataset, index, s.trunk->format, true));
      }
    }
    if (s.clean.size() != s.targets.size()) s.clean.clear();
    s.train_latents = functaset.Latents(sensor, Split::kTrain);
    if (s.train_latents.rows() == 0) s.train_latents = functaset.Latents(sensor);
    s.index = std::make_unique<BruteForceKnnIndex>(s.trunk->siren.latent_dim());
    const Functaset::LatentMatrix rows = s.train_latents;
    s.index->Add(rows.data(), rows.rows());
    sensors.push_back(std::move(s));
  }
  if (sensors.empty()) {
    throw UsageError("no sensor with test frames in the model, the functaset and the dataset");
  }

  const std::vector<Variant> variants = FitVariants(flags.autodiff_frames);
  auto psnr_of = [](const SensorTrunk& trunk, const Eigen::VectorXd& z, const TrunkTargets& t) {
    return Psnr(Reconstruct(trunk, z.cast<float>()), t);
  };

  // Converged reference, then every variant, sensor by sensor.
  std::vector<VariantResult> results;
  for (SensorFitData& s : sensors) {
    const int n = static_cast<int>(s.targets.size());
    std::cout << "bench fit: " << ToString(s.sensor) << ": " << n << " test frames at "
              << s.trunk->format.rows << "x" << s.trunk->format.cols << ", latent_dim "
              << s.trunk->siren.latent_dim() << ", k-NN over " << s.train_latents.rows()
              << " train latents\n";
    {  // converged
      const LatentFitter fitter(*s.trunk, ConvergedOptions());
      LatentProblem::Options converged_problem;
      converged_problem.precision = LatentProblem::Precision::kDouble;
      s.converged_psnr.assign(n, 0);
      s.converged_psnr_clean.assign(n, std::numeric_limits<double>::quiet_NaN());
      std::vector<double> ms(n), iterations(n);
      std::vector<Eigen::VectorXd> latents(n);
      ForFrames(n, flags.threads, [&](int i) {
        const Clock::time_point start = Clock::now();
        const LatentFitter::Summary summary =
            fitter.Fit(LatentProblem(*s.trunk, s.targets[i], converged_problem), &latents[i]);
        ms[i] = MsSince(start);
        iterations[i] = summary.iterations;
        s.converged_psnr[i] = summary.psnr;
        if (!s.clean.empty()) s.converged_psnr_clean[i] = psnr_of(*s.trunk, latents[i], s.clean[i]);
      });
      s.converged_mean = Mean(s.converged_psnr);
      s.converged_clean_mean = Mean(s.converged_psnr_clean);
      s.converged_ms_median = Median(ms);
      s.converged_iterations_mean = Mean(iterations);
      std::cout << "  converged ceres:100 double: PSNR " << FormatFixed(s.converged_mean, 2)
                << " dB, " << FormatFixed(s.converged_iterations_mean, 1) << " iterations, "
                << Ms(s.converged_ms_median) << " ms median\n";
      MeasureJacobians(&s, latents[0]);
      std::cout << "  Jacobian: analytic float " << Ms(s.jacobian_float_ms) << " ms, double "
                << Ms(s.jacobian_double_ms) << " ms, autodiff " << Ms(s.jacobian_autodiff_ms)
                << " ms (" << FormatFixed(s.jacobian_autodiff_ms / s.jacobian_float_ms, 0)
                << "x float)\n";
    }
    for (const Variant& v : variants) {
      const LatentFitter::Options options = VariantOptions(v);
      LatentProblem::Options problem_options;
      problem_options.precision = v.precision;
      const Eigen::MatrixXf& latents = s.train_latents;
      const LatentFitter fitter = options.strategy.knn
                                      ? LatentFitter(*s.trunk, options, s.index.get(), &latents)
                                      : LatentFitter(*s.trunk, options);
      const int m = v.max_frames > 0 ? std::min(n, v.max_frames) : n;
      // One untimed warm-up fit: first-touch page faults and cold caches are not a frame's cost.
      {
        Eigen::VectorXd z;
        if (v.jacobian == LatentFitter::JacobianMode::kAnalytic) {
          fitter.Fit(LatentProblem(*s.trunk, s.targets[0], problem_options), &z);
        }
      }
      VariantResult r;
      r.variant = v;
      r.sensor = s.sensor;
      r.ms.assign(m, 0);
      r.psnr.assign(m, 0);
      r.iterations.assign(m, 0);
      r.psnr_clean.assign(m, std::numeric_limits<double>::quiet_NaN());
      ForFrames(m, flags.threads, [&](int i) {
        Eigen::VectorXd z;
        const Clock::time_point start = Clock::now();
        const LatentFitter::Summary summary =
            fitter.Fit(LatentProblem(*s.trunk, s.targets[i], problem_options), &z);
        r.ms[i] = MsSince(start);
        r.psnr[i] = summary.psnr;
        r.iterations[i] = summary.iterations;
        if (!s.clean.empty()) r.psnr_clean[i] = psnr_of(*s.trunk, z, s.clean[i]);
      });
      r.ms_median = Median(r.ms);
      r.ms_p90 = Quantile(r.ms, 0.9);
      r.psnr_mean = Mean(r.psnr);
      r.psnr_clean_mean = Mean(r.psnr_clean);
      r.iterations_mean = Mean(r.iterations);
      r.converged_of_frames.assign(s.converged_psnr.begin(), s.converged_psnr.begin() + m);
      r.delta_db = r.psnr_mean - Mean(r.converged_of_frames);
      std::cout << "  " << v.Label() << ": " << Ms(r.ms_median) << " ms median, " << Ms(r.ms_p90)
                << " p90, PSNR " << FormatFixed(r.psnr_mean, 2) << " dB ("
                << (r.delta_db >= 0 ? "+" : "") << FormatFixed(r.delta_db, 2) << " vs converged), "
                << m << " frames\n";
      results.push_back(std::move(r));
    }
  }

  // Targets (issue 4).
  double ratio = std::numeric_limits<double>::infinity();
  nlohmann::json ratio_by_sensor = nlohmann::json::object();
  for (const SensorFitData& s : sensors) {
    const double r = s.jacobian_autodiff_ms / s.jacobian_float_ms;
    ratio = std::min(ratio, r);
    ratio_by_sensor[ToString(s.sensor)] = {
        {"over_float", r}, {"over_double", s.jacobian_autodiff_ms / s.jacobian_double_ms}};
  }
  nlohmann::json targets;
  {
    std::ostringstream detail;
    double ratio_double = std::numeric_limits<double>::infinity();
    for (const SensorFitData& s : sensors) {
      ratio_double = std::min(ratio_double, s.jacobian_autodiff_ms / s.jacobian_double_ms);
    }
    detail << "autodiff / analytic Jacobian time, min over sensors: " << FormatFixed(ratio, 0)
           << "x against the float analytic Jacobian (the default), "
           << FormatFixed(ratio_double, 0)
           << "x against the double one (target >= 100x, checked against float)";
    targets["analytic_100x_faster_than_autodiff"] = {{"met", ratio >= 100},
                                                     {"detail", detail.str()}};
  }
  {
    bool met = true;
    std::ostringstream detail;
    for (const SensorFitData& s : sensors) {
      const VariantResult* worst = nullptr;  // every knn+ceres variant must be within 0.5 dB
      for (const VariantResult& r : results) {
        if (r.sensor == s.sensor && r.variant.strategy.rfind("knn+ceres", 0) == 0 &&
            (worst == nullptr || r.delta_db < worst->delta_db)) {
          worst = &r;
        }
      }
      const bool ok = worst != nullptr && worst->delta_db >= -0.5;
      met = met && ok;
      if (worst != nullptr) {
        detail << ToString(s.sensor) << ": worst knn+ceres variant " << worst->variant.Label()
               << " " << FormatFixed(worst->delta_db, 2) << " dB; ";
      }
    }
    detail << "(target: every knn+ceres variant within 0.5 dB of converged)";
    targets["knn_ceres_within_0.5dB_of_converged"] = {{"met", met}, {"detail", detail.str()}};
  }
  {
    bool met = true;
    std::ostringstream detail;
    for (const SensorFitData& s : sensors) {
      const VariantResult* best = nullptr;  // the fastest within 1 dB of converged
      for (const VariantResult& r : results) {
        if (r.sensor == s.sensor && r.ms.size() == s.converged_psnr.size() && r.delta_db >= -1.0 &&
            (best == nullptr || r.ms_median < best->ms_median)) {
          best = &r;
        }
      }
      const bool ok = flags.threads == 1 && best != nullptr && best->ms_median <= 33.0;
      met = met && ok;
      detail << ToString(s.sensor) << ": ";
      if (best == nullptr) {
        detail << "no strategy within 1 dB; ";
      } else {
        detail << "fastest within 1 dB is " << best->variant.Label() << ", " << Ms(best->ms_median)
               << " ms median, " << FormatFixed(best->delta_db, 2) << " dB; ";
      }
    }
    detail << "(target: median <= 33 ms on one thread within 1 dB of converged"
           << (flags.threads == 1 ? ")" : "; measured with 2 threads, so not checked)");
    targets["realtime_33ms_within_1dB"] = {{"met", met}, {"detail", detail.str()}};
  }

  const nlohmann::json machine = MachineDescription();
  const std::string machine_line = machine.value("cpu", std::string("?")) + ", " +
                                   std::to_string(machine.value("cores", 0)) + " cores";
  const std::string table = FitTable(results, sensors, flags, machine, targets);
  if (flags.table.empty()) {
    std::cout << "\n" << table;
  } else {
    WriteFileAtomically(flags.table, table);
    std::cout << "bench fit: wrote the table to " << flags.table << "\n";
  }
  if (!flags.plot.empty()) {
    WritePicture(flags.plot, ParetoPlot(results, sensors, flags.threads, machine_line));
    std::cout << "bench fit: wrote the Pareto plot to " << flags.plot << "\n";
  }
  for (const auto& [name, t] : targets.items()) {
    std::cout << "target " << name << ": " << (t["met"].get<bool>() ? "met" : "NOT met") << " -- "
              << t["detail"].get<std::string>() << "\n";
  }

  if (flags.json) {
    nlohmann::json list = nlohmann::json::array();
    for (const VariantResult& r : results) {
      list.push_back({{"name", r.variant.strategy},
                      {"label", r.variant.Label()},
                      {"sensor", ToString(r.sensor)},
                      {"precision", ToString(r.variant.precision)},
                      {"jacobian", ToString(r.variant.jacobian)},
                      {"frames", r.ms.size()},
                      {"ms_median", r.ms_median},
                      {"ms_p90", r.ms_p90},
                      {"psnr_mean", FiniteOrNull(r.psnr_mean)},
                      {"psnr_clean_mean", FiniteOrNull(r.psnr_clean_mean)},
                      {"delta_db", FiniteOrNull(r.delta_db)},
                      {"iterations_mean", r.iterations_mean}});
    }
    nlohmann::json converged = nlohmann::json::object(), converged_clean = nlohmann::json::object(),
                   jacobian_ms = nlohmann::json::object(), load_ms = nlohmann::json::object();
    for (const SensorFitData& s : sensors) {
      converged[ToString(s.sensor)] = FiniteOrNull(s.converged_mean);
      converged_clean[ToString(s.sensor)] = FiniteOrNull(s.converged_clean_mean);
      jacobian_ms[ToString(s.sensor)] = {{"analytic_float", s.jacobian_float_ms},
                                         {"analytic_double", s.jacobian_double_ms},
                                         {"autodiff", s.jacobian_autodiff_ms},
                                         {"residuals_float", s.residuals_float_ms}};
      load_ms[ToString(s.sensor)] = Median(s.load_ms);
    }
    EmitJson({{"bench", "fit"},
              {"strategies", list},
              {"converged_psnr", converged},
              {"converged_psnr_clean", converged_clean},
              {"autodiff_over_analytic", FiniteOrNull(ratio)},
              {"autodiff_over_analytic_by_sensor", ratio_by_sensor},
              {"jacobian_ms", jacobian_ms},
              {"load_and_preprocess_ms_median", load_ms},
              {"threads", flags.threads},
              {"targets", targets},
              {"machine", machine}});
  }
}

// ==== bench kernels ===========================================================================

struct KernelFlags {
  std::string model;
  bool json = false;
  std::vector<std::string> extra;
};

// What one trunk's kernels run on: a frame the trunk generates from a random latent plus
// 0.01 noise (no dataset needed; the kernels' cost does not depend on the values).
struct KernelSetup {
  std::string label;
  SensorTrunk trunk;
  TrunkTargets targets;
  // The frame's latent problem at sigma 0.01, evaluated in float and in double.
  std::unique_ptr<LatentProblem> problem_float, problem_double;
  Eigen::VectorXd z;
};

std::shared_ptr<KernelSetup> MakeKernelSetup(const std::string& label, const SensorTrunk& trunk) {
  auto s = std::make_shared<KernelSetup>();
  s->label = label;
  s->trunk = trunk;
  const int rows = trunk.format.rows, cols = trunk.format.cols, d = trunk.siren.latent_dim();
  std::mt19937_64 rng(5);
  std::normal_distribution<double> normal(0.0, 1.0);
  Eigen::VectorXf truth(d);
  for (int k = 0; k < d; ++k) truth[k] = static_cast<float>(0.3 * normal(rng));
  s->targets.rows = rows;
  s->targets.cols = cols;
  s->targets.values = s->trunk.siren.Forward<float>(s->trunk.siren.Grid<float>(rows, cols), truth);
  for (int i = 0; i < s->targets.values.size(); ++i) {
    s->targets.values.data()[i] += static_cast<float>(0.01 * normal(rng));
  }
  s->targets.weights = Eigen::VectorXf::Ones(rows * cols);
  LatentProblem::Options options;
  options.sigma = 0.01;
  s->problem_float = std::make_unique<LatentProblem>(s->trunk, s->targets, options);
  options.precision = LatentProblem::Precision::kDouble;
  s->problem_double = std::make_unique<LatentProblem>(s->trunk, s->targets, options);
  s->z = Eigen::VectorXd::Zero(d);
  for (int k = 0; k < d; ++k) s->z[k] = 0.1 * normal(rng);
  return s;
}

void EvaluateCost(const ceres::CostFunction& cost, const KernelSetup& s, bool jacobian,
                  std::vector<double>* residuals, std::vector<double>* J) {
  const double* parameters[] = {s.z.data()};
  double* jacobians[] = {J->data()};
  cost.Evaluate(parameters, residuals->data(), jacobian ? jacobians : nullptr);
}

void RegisterKernelBenchmarks(const std::shared_ptr<KernelSetup>& s) {
  const std::string p = "kernels/" + s->label + "/";
  const int n = s->problem_float->num_residuals(), d = s->trunk.siren.latent_dim();
  auto pixels = [s](benchmark::State& state) {
    state.SetItemsProcessed(state.iterations() * s->problem_float->num_pixels());
  };
  benchmark::RegisterBenchmark((p + "forward/float").c_str(), [s, pixels](benchmark::State& state) {
    const Eigen::MatrixXf coords = s->problem_float->coords().cast<float>();
    const Eigen::VectorXf z = s->z.cast<float>();
    for (auto _ : state)
      benchmark::DoNotOptimize(s->trunk.siren.Forward<float>(coords, z));
    pixels(state);
  })->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark((p + "forward/double").c_str(), [s,
                                                                pixels](benchmark::State& state) {
    for (auto _ : state) {
      benchmark::DoNotOptimize(
          s->trunk.siren.Forward<double>(s->problem_double->coords(), s->z));
    }
    pixels(state);
  })->Unit(benchmark::kMillisecond);
  for (const bool use_double : {false, true}) {
    benchmark::RegisterBenchmark(
        (p + "forward_latent_jacobian_analytic/" + (use_double ? "double" : "float")).c_str(),
        [s, n, d, use_double, pixels](benchmark::State& state) {
          const AnalyticLatentCost cost(use_double ? s->problem_double.get()
                                                   : s->problem_float.get());
          std::vector<double> r(n), J(static_cast<std::size_t>(n) * d);
          for (auto _ : state) EvaluateCost(cost, *s, true, &r, &J);
          pixels(state);
        })
        ->Unit(benchmark::kMillisecond);
  }
  benchmark::RegisterBenchmark((p + "residuals_analytic/float").c_str(),
                               [s, n, d, pixels](benchmark::State& state) {
                                 const AnalyticLatentCost cost(s->problem_float.get());
                                 std::vector<double> r(n), J(static_cast<std::size_t>(n) * d);
                                 for (auto _ : state) EvaluateCost(cost, *s, false, &r, &J);
                                 pixels(state);
                               })
      ->Unit(benchmark::kMillisecond);
  // One evaluation only: about 2 s at 70x88 with width 128.
  benchmark::RegisterBenchmark((p + "jacobian_autodiff/double").c_str(),
                               [s, n, d, pixels](benchmark::State& state) {
                                 const auto cost =
                                     MakeAutoDiffLatentCost(s->problem_double.get());
                                 std::vector<double> r(n), J(static_cast<std::size_t>(n) * d);
                                 for (auto _ : state) EvaluateCost(*cost, *s, true, &r, &J);
                                 pixels(state);
                               })
      ->Unit(benchmark::kMillisecond)
      ->Iterations(1)
      ->Repetitions(1);
  // A Ceres LM solve of exactly 1 and 3 iterations (tolerances 0), analytic float, from z
  // = 0: (t3 - t1) / 2 is the marginal cost of one LM iteration, reported as lm_iteration.
  for (const int iterations : {1, 3}) {
    benchmark::RegisterBenchmark(
        (p + "lm_solve/float/iterations:" + std::to_string(iterations)).c_str(),
        [s, d, iterations](benchmark::State& state) {
          AnalyticLatentCost cost(s->problem_float.get());
          LatentPriorCost prior(d, 1.0);
          ceres::Solver::Options options = LatentFitter::Options().solver_options;
          options.max_num_iterations = iterations;
          options.function_tolerance = 0;
          options.gradient_tolerance = 0;
          options.parameter_tolerance = 0;
          for (auto _ : state) {
            Eigen::VectorXd z = Eigen::VectorXd::Zero(d);
            ceres::Problem::Options po;
            po.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
            ceres::Problem problem(po);
            problem.AddResidualBlock(&cost, nullptr, z.data());
            problem.AddResidualBlock(&prior, nullptr, z.data());
            ceres::Solver::Summary summary;
            ceres::Solve(options, &problem, &summary);
            benchmark::DoNotOptimize(z.data());
          }
        })
        ->Unit(benchmark::kMillisecond);
  }
  benchmark::RegisterBenchmark((p + "meta_sgd_step/float").c_str(), [s,
                                                                     d](benchmark::State& state) {
    Eigen::VectorXd z = Eigen::VectorXd::Zero(d);
    for (auto _ : state) {
      z = s->problem_float->MetaSgdSteps(z, 1);
      benchmark::DoNotOptimize(z.data());
    }
  })->Unit(benchmark::kMillisecond);
}

void RegisterGemmBenchmark() {
  benchmark::RegisterBenchmark("eigen/gemm_float/4096x256x256", [](benchmark::State& state) {
    const Eigen::MatrixXf a = Eigen::MatrixXf::Random(4096, 256),
                          b = Eigen::MatrixXf::Random(256, 256);
    Eigen::MatrixXf c(4096, 256);
    for (auto _ : state) {
      c.noalias() = a * b;
      benchmark::DoNotOptimize(c.data());
    }
    state.counters["GFLOPS"] = benchmark::Counter(2.0 * 4096 * 256 * 256 / 1e9,
                                                  benchmark::Counter::kIsIterationInvariantRate);
  })->Unit(benchmark::kMillisecond);
}

void RunKernelBench(const KernelFlags& flags) {
  std::vector<std::shared_ptr<KernelSetup>> setups;
  if (!flags.model.empty()) {
    const FunctaModel model = FunctaModel::Load(flags.model);
    for (SensorKind sensor : model.sensors())
      setups.push_back(MakeKernelSetup(ToString(sensor), model.Trunk(sensor)));
  } else {
    // The default: the width-128, 4-layer, d = 64 trunk at 70x88 of docs/FITTING.md.
    SensorTrunk trunk;
    trunk.format.rows = 70;
    trunk.format.cols = 88;
    trunk.format.scale = 0.01;
    trunk.siren = LatentModulatedSiren(LatentModulatedSiren::Options(), 1);
    trunk.alpha = Eigen::VectorXd::Constant(trunk.siren.latent_dim(), 0.5);
    setups.push_back(MakeKernelSetup("default", trunk));
  }
  for (const auto& s : setups) {
    std::cout << "bench kernels: " << s->label << ": " << s->trunk.format.rows << "x"
              << s->trunk.format.cols << " pixels, width " << s->trunk.siren.width() << ", "
              << s->trunk.siren.num_hidden_layers()
              << " layers, d = " << s->trunk.siren.latent_dim()
              << ", C = " << s->trunk.siren.output_channels() << "\n";
    RegisterKernelBenchmarks(s);
  }
  RegisterGemmBenchmark();
  const std::vector<BenchResult> results = RunRegisteredBenchmarks(flags.extra);
  auto find = [&](const std::string& name) -> const BenchResult* {
    for (const BenchResult& r : results) {
      if (r.name.rfind(name, 0) == 0) return &r;
    }
    return nullptr;
  };
  nlohmann::json per_trunk = nlohmann::json::object();
  for (const auto& s : setups) {
    const std::string p = "kernels/" + s->label + "/";
    const BenchResult* one = find(p + "lm_solve/float/iterations:1");
    const BenchResult* three = find(p + "lm_solve/float/iterations:3");
    const BenchResult* jf = find(p + "forward_latent_jacobian_analytic/float");
    const BenchResult* jd = find(p + "forward_latent_jacobian_analytic/double");
    const BenchResult* ad = find(p + "jacobian_autodiff/double");
    nlohmann::json t;
    if (one != nullptr && three != nullptr)
      t["lm_iteration_ms"] = (three->real_ms - one->real_ms) / 2;
    if (jf != nullptr && ad != nullptr)
      t["autodiff_over_analytic_float"] = ad->real_ms / jf->real_ms;
    if (jd != nullptr && ad != nullptr)
      t["autodiff_over_analytic_double"] = ad->real_ms / jd->real_ms;
    std::cout << "bench kernels: " << s->label << ": one LM iteration (marginal) "
              << (t.contains("lm_iteration_ms") ? Ms(t["lm_iteration_ms"].get<double>()) : "n/a")
              << " ms; autodiff / analytic Jacobian "
              << (t.contains("autodiff_over_analytic_float")
                      ? FormatFixed(t["autodiff_over_analytic_float"].get<double>(), 0)
                      : "n/a")
              << "x (float), "
              << (t.contains("autodiff_over_analytic_double")
                      ? FormatFixed(t["autodiff_over_analytic_double"].get<double>(), 0)
                      : "n/a")
              << "x (double)\n";
    per_trunk[s->label] = t;
  }
  double gflops = 0;
  if (const BenchResult* g = find("eigen/gemm_float")) {
    gflops = g->counters.count("GFLOPS") ? g->counters.at("GFLOPS") : 0;
  }
  const nlohmann::json machine = MachineDescription();
  std::cout << "bench kernels: Eigen float GEMM 4096x256x256: " << FormatFixed(gflops, 1)
            << " GFLOP/s (one thread; -march=native "
            << (machine.value("avx512_compiled", false) ? "with" : "without")
            << " AVX-512 compiled in)\n";
  if (flags.json) {
    nlohmann::json list = nlohmann::json::array();
    for (const BenchResult& r : results) {
      nlohmann::json counters = nlohmann::json::object();
      for (const auto& [key, value] : r.counters) counters[key] = value;
      list.push_back({{"name", r.name},
                      {"ms_median", r.real_ms},
                      {"cpu_ms_median", r.cpu_ms},
                      {"counters", counters}});
    }
    EmitJson({{"bench", "kernels"},
              {"machine", machine},
              {"gemm_gflops", gflops},
              {"trunks", per_trunk},
              {"results", list}});
  }
}

// ==== bench knn ===============================================================================

struct KnnFlags {
  std::string functaset;
  std::string sensor;
  int synthetic = 0;
  int queries = 1000;
  bool json = false;
};

// n x 64 vectors near a 16-dimensional subspace, in 64 clusters (docs/FITTING.md's set).
Functaset::LatentMatrix SyntheticLatents(int n, std::uint64_t seed) {
  const int d = 64, sub = 16, clusters = 64;
  std::mt19937_64 rng(42);  // the subspace and centres are fixed; `seed` draws the points
  std::normal_distribution<float> normal(0.0f, 1.0f);
  Eigen::MatrixXf basis(d, sub), centres(sub, clusters);
  for (int i = 0; i < basis.size(); ++i) basis.data()[i] = normal(rng) / std::sqrt(float(sub));
  for (int i = 0; i < centres.size(); ++i) centres.data()[i] = 2.0f * normal(rng);
  std::mt19937_64 points(seed);
  std::uniform_int_distribution<int> pick(0, clusters - 1);
  Functaset::LatentMatrix out(n, d);
  for (int i = 0; i < n; ++i) {
    Eigen::VectorXf local = centres.col(pick(points));
    for (int k = 0; k < sub; ++k) local[k] += 0.5f * normal(points);
    Eigen::VectorXf v = basis * local;
    for (int k = 0; k < d; ++k) v[k] += 0.02f * normal(points);
    out.row(i) = v.transpose();
  }
  return out;
}

struct KnnRow {
  std::string index;
  int checks = 0;  // 0 = exact
  double build_ms = 0, recall = 1, ms_median = 0, ms_p90 = 0, speedup = 1;
};

void RunKnnBench(const KnnFlags& flags) {
  Functaset::LatentMatrix base, queries;
  std::string source;
  if (flags.synthetic > 0) {
    base = SyntheticLatents(flags.synthetic, 1);
    queries = SyntheticLatents(flags.queries, 2);
    source = "synthetic: " + std::to_string(flags.synthetic) +
             " x 64 vectors near a 16-dim subspace, 64 clusters; " + std::to_string(flags.queries) +
             " held-out queries from the same distribution";
  } else {
    if (flags.functaset.empty()) throw UsageError("give --functaset F or --synthetic N");
    const Functaset functaset = Functaset::Load(flags.functaset);
    SensorKind sensor;
    if (flags.sensor.empty()) {
      if (functaset.sensors().empty()) throw DatasetError(flags.functaset + ": holds no sensor");
      sensor = functaset.sensors()[0];
    } else if (!SensorKindFromString(flags.sensor, &sensor)) {
      throw UsageError("--sensor: expected bubble or gelslim, got '" + flags.sensor + "'");
    }
    if (!functaset.has_sensor(sensor)) {
      throw DatasetError(flags.functaset + ": has no " + std::string(ToString(sensor)) +
                         " latents");
    }
    base = functaset.Latents(sensor, Split::kTrain);
    queries = functaset.Latents(sensor, Split::kTest);
    if (queries.rows() > flags.queries) queries.conservativeResize(flags.queries, Eigen::NoChange);
    if (base.rows() == 0 || queries.rows() == 0) {
      throw DatasetError(flags.functaset +
                         ": needs train latents (the index) and test latents "
                         "(the queries) of " +
                         std::string(ToString(sensor)));
    }
    source = flags.functaset + " " + ToString(sensor) + ": " + std::to_string(base.rows()) + " x " +
             std::to_string(base.cols()) + " train latents, " + std::to_string(queries.rows()) +
             " test latents as queries";
  }
  const int d = static_cast<int>(base.cols()), k = 8;
  const std::int64_t nq = queries.rows();
  std::cout << "bench knn: " << source << ", k = " << k << "\n";

  auto time_queries = [&](const KnnIndex& index, KnnRow* row) {
    std::vector<float> distances(k);
    std::vector<std::int64_t> labels(k);
    std::vector<double> ms(nq);
    for (std::int64_t q = 0; q < nq; ++q) {
      const Clock::time_point start = Clock::now();
      index.Search(queries.row(q).data(), 1, k, distances.data(), labels.data());
      ms[q] = MsSince(start);
    }
    row->ms_median = Median(ms);
    row->ms_p90 = Quantile(ms, 0.9);
  };

  std::vector<KnnRow> rows;
  BruteForceKnnIndex exact(d);
  {
    KnnRow row{"brute_force", 0};
    const Clock::time_point start = Clock::now();
    exact.Add(base.data(), base.rows());
    row.build_ms = MsSince(start);
    time_queries(exact, &row);
    rows.push_back(row);
  }
  const double brute_ms = rows[0].ms_median;
  struct Config {
    std::string name;
    FlannKnnIndex::Options options;
  };
  std::vector<Config> configs;
  for (int trees : {4, 8}) {
    FlannKnnIndex::Options o;
    o.algorithm = FlannKnnIndex::Algorithm::kKdForest;
    o.trees = trees;
    configs.push_back({"kd_forest trees=" + std::to_string(trees), o});
  }
  {
    FlannKnnIndex::Options o;
    o.algorithm = FlannKnnIndex::Algorithm::kKMeans;
    configs.push_back({"kmeans branching=32", o});
  }
  for (const Config& c : configs) {
    FlannKnnIndex index(d, c.options);
    const Clock::time_point start = Clock::now();
    index.Add(base.data(), base.rows());
    const double build_ms = MsSince(start);
    for (int checks : {16, 32, 64, 128, 256, 512}) {
      FlannKnnIndex::SearchParams params;
      params.checks = checks;
      index.set_search_params(params);
      KnnRow row{c.name, checks};
      row.build_ms = build_ms;
      row.recall = Recall(index, exact, queries.data(), nq, k);
      time_queries(index, &row);
      row.speedup = brute_ms / row.ms_median;
      rows.push_back(row);
    }
  }
  const KnnRow* best = nullptr;
  for (const KnnRow& r : rows) {
    if (r.checks > 0 && r.recall >= 0.95 && r.speedup >= 10 &&
        (best == nullptr || r.speedup > best->speedup)) {
      best = &r;
    }
  }
  std::ostringstream md;
  md << "| index | build ms | checks | recall@8 | ms/query median | ms/query p90 | speed-up vs "
        "brute force |\n";
  md << "|---|---|---|---|---|---|---|\n";
  for (const KnnRow& r : rows) {
    md << "| " << r.index << " | " << Ms(r.build_ms) << " | "
       << (r.checks ? std::to_string(r.checks) : "exact") << " | " << FormatFixed(r.recall, 3)
       << " | " << Ms(r.ms_median) << " | " << Ms(r.ms_p90) << " | " << FormatFixed(r.speedup, 1)
       << "x |\n";
  }
  std::cout << md.str();
  const std::string verdict =
      best != nullptr
          ? "met: " + best->index + " at " + std::to_string(best->checks) + " checks, recall@8 " +
                FormatFixed(best->recall, 3) + ", " + FormatFixed(best->speedup, 1) +
                "x faster than brute force"
          : "NOT met: no FLANN setting reaches recall@8 >= 0.95 at >= 10x the brute-force speed on "
            "this set";
  std::cout << "target recall@8 >= 0.95 at >= 10x faster than brute force: " << verdict << "\n";
  std::cout << "(one query at a time, std::chrono per query, median over the queries)\n";
  if (flags.json) {
    nlohmann::json list = nlohmann::json::array();
    for (const KnnRow& r : rows) {
      list.push_back({{"index", r.index},
                      {"checks", r.checks},
                      {"build_ms", r.build_ms},
                      {"recall_at_8", r.recall},
                      {"ms_median", r.ms_median},
                      {"ms_p90", r.ms_p90},
                      {"speedup", r.speedup}});
    }
    EmitJson({{"bench", "knn"},
              {"source", source},
              {"size", base.rows()},
              {"dim", d},
              {"queries", nq},
              {"rows", list},
              {"target_met", best != nullptr},
              {"target", verdict},
              {"machine", MachineDescription()}});
  }
}

}  // namespace

void RegisterFitBenchmarks(CLI::App* bench, CommandBody* selected) {
  {
    auto flags = std::make_shared<FitBenchFlags>();
    CLI::App* sub = bench->add_subcommand(
        "fit",
        "Every LatentFitter strategy on a dataset's test frames: median/p90 ms per frame, mean "
        "PSNR vs the converged fit, autodiff/analytic Jacobian ratio; Pareto plot and markdown "
        "table (plain std::chrono timing per frame).");
    sub->add_option("--model", flags->model, "Model file (.tfm)")->required();
    sub->add_option("--functaset", flags->functaset,
                    "Its functaset (.tfs); k-NN uses the train latents")
        ->required();
    sub->add_option("--data", flags->data, "The dataset (test split frames are fitted)")
        ->required();
    sub->add_option("--threads", flags->threads, "1 (default) or 2: frames fitted in parallel")
        ->check(CLI::Range(1, 2));
    sub->add_option("--frames", flags->frames, "Test frames per sensor (the first N; default 20)")
        ->check(CLI::Range(1, 100000));
    sub->add_option("--autodiff-frames", flags->autodiff_frames,
                    "Frames for the (slow) autodiff variant; 0 = skip it (default 2)")
        ->check(CLI::Range(0, 100000));
    sub->add_option("--sensors", flags->sensors, "bubble,gelslim (default: all the model has)");
    sub->add_option("--plot", flags->plot, "Write the Pareto plot (PNG) here");
    sub->add_option("--table", flags->table, "Write the markdown table here (default: stdout)");
    sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
    AddDatasetFlags(sub, &flags->dataset);
    sub->callback([flags, selected]() {
      flags->argv = {"tactfunc bench fit",
                     "--model " + flags->model,
                     "--functaset " + flags->functaset,
                     "--data " + flags->data,
                     "--threads " + std::to_string(flags->threads),
                     "--frames " + std::to_string(flags->frames),
                     flags->sensors.empty() ? "" : "--sensors " + flags->sensors};
      *selected = [flags]() { RunFitBench(*flags); };
    });
  }
  {
    auto flags = std::make_shared<KernelFlags>();
    CLI::App* sub = bench->add_subcommand(
        "kernels",
        "Google Benchmark of the fitting kernels (forward, analytic and autodiff latent "
        "Jacobians, LM iteration, meta-SGD step) at the model's resolution (default trunk: width "
        "128, 4 layers, d = 64, 70x88), and Eigen float GEMM GFLOP/s. Extra --benchmark_* flags "
        "pass through.");
    sub->add_option("--model", flags->model, "Model file (.tfm); every trunk is benchmarked");
    sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
    sub->allow_extras();
    sub->callback([flags, sub, selected]() {
      flags->extra = sub->remaining();
      *selected = [flags]() { RunKernelBench(*flags); };
    });
  }
  {
    auto flags = std::make_shared<KnnFlags>();
    CLI::App* sub = bench->add_subcommand(
        "knn",
        "FLANN kd-forest and k-means at several checks vs brute force: recall@8, median ms per "
        "query, build time, and whether recall@8 >= 0.95 at >= 10x brute-force speed is met.");
    sub->add_option("--functaset", flags->functaset,
                    "Functaset: its train latents are the index, its test latents the queries");
    sub->add_option("--sensor", flags->sensor, "bubble or gelslim (default: the first it holds)");
    sub->add_option("--synthetic", flags->synthetic,
                    "Instead: N synthetic 64-d vectors (clusters near a 16-d subspace)")
        ->check(CLI::Range(1, 10000000));
    sub->add_option("--queries", flags->queries, "At most this many queries (default 1000)")
        ->check(CLI::Range(1, 1000000));
    sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
    sub->callback([flags, selected]() { *selected = [flags]() { RunKnnBench(*flags); }; });
  }
}

}  // namespace tactfunc::apps
