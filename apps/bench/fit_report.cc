// Copyright 2026 The tactfunc Authors.
// `tactfunc bench fit`'s Pareto plot and markdown table.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <sstream>

#include <opencv2/imgproc.hpp>

#include "apps/bench/fit_common.h"
#include "apps/bench/fit_suite.h"
#include "apps/command.h"
#include "apps/pictures.h"

namespace tactfunc::apps::bench {

// ---- The Pareto plot ----------------------------------------------------------------------

namespace {

cv::Scalar SensorColour(SensorKind sensor) {
  return sensor == SensorKind::kSoftBubble ? cv::Scalar(40, 140, 255)   // orange
                                           : cv::Scalar(230, 160, 40);  // blue
}

}  // namespace

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

}  // namespace tactfunc::apps::bench
