// Copyright 2026 The tactfunc Authors.
//
// tactfunc pose: the in-hand pose posterior of ONE tactile frame (Sec. III-C/D, IV-C of
// "Tactile Functasets"; estimation/posterior/pose_posterior.h):
//
//   tactfunc pose --model M.tfm --pose-model P.tpm --frame F.png --reference R.png
//       --sampler sgld --samples 100 --out DIR [--tool NAME] [--json]
//   tactfunc pose --model M.tfm --pose-model P.tpm --data D --id 000010 --tool rod ...
//   tactfunc pose ... --sampler knn --functaset F.tfs
//
// Prints the posterior mean (x mm, y mm, yaw deg), the 3x3 covariance in the tangent
// space at the mean (right perturbations, order x [m], y [m], yaw [rad]) and the nine
// non-zero entries of ROS's 6x6 PoseWithCovariance covariance (parent frame). Writes
// DIR/posterior.json and DIR/posterior.png: the samples (dots with heading ticks) over
// the contact (difference) image in the sensor frame, a zoom on the samples with the
// 90% Gaussian x-y ellipse, and a yaw histogram; the mean, the modes, and the truth
// when it is known (--data/--id with a labelled frame).
//
// Frames: --frame/--reference (sensor inferred as `tactfunc fit` does) or --data D
// --id ID (a dataset frame: the pixel pitch, label and tool come from the dataset).
// The pixel pitch places the samples on the image: --pixel-pitch-mm, else the
// dataset.json of the dataset the frame file lies in; unknown -> no image panel.
// The tool (--tool, else the label's) gives the symmetry order by which the samples
// are folded; an unknown or absent tool gets n = 1 (nothing folded).
//
// The knn sampler searches the functaset's labelled TRAIN-split latents (a brute-force
// index built in memory, apps/model_inputs.h), so that a test frame cannot find itself.
//
// --method generator (docs/POSES.md, "The generator path"): the pose itself is fitted by
// analysis-by-synthesis through --generator G.tpg (`tactfunc train-generator`) and the
// frozen trunk, and the posterior is the Laplace mixture over the modes
// (estimation/synthesis/generator_posterior.h). Starts: the pose MLP, and the k nearest
// labelled train latents of --functaset when given. --tool names the tool; without it
// every tool of the generator is fitted and the tool probabilities are printed. --samples
// draws from the mixture go into posterior.json / .png; with --sampler mala or rwm they
// are MCMC draws of (x, y, yaw, depth) instead (estimation/synthesis/pose_sampler.h: 4
// chains from the chosen tool's Laplace components, 200 burn-in iterations each,
// --samples / 4 kept per chain, mode jumps between the tool's Laplace components), their
// acceptance and split R-hat printed. Other --sampler values do not apply to the
// generator path.
//   tactfunc pose --method generator --generator G.tpg --model M.tfm --pose-model P.tpm
//       --data D --id 000010 [--functaset F.tfs] [--tool NAME] [--out DIR] [--json]
//
// --method both runs the latent path (--sampler) and then the generator path on the same
// frame, each into its own subfolder of --out (latent/, generator/), and stacks their
// pictures into DIR/posterior.png, latent above generator.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <opencv2/imgproc.hpp>
#include <optional>
#include <string>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>

#include "CLI/CLI.hpp"
#include "apps/command.h"
#include "apps/dataset_flags.h"
#include "apps/model_inputs.h"
#include "apps/output_paths.h"
#include "apps/pictures.h"
#include "estimation/data/codecs.h"
#include "estimation/data/dataset.h"
#include "estimation/data/photometric_markers.h"
#include "estimation/data/image_io.h"
#include "estimation/data/preprocess.h"
#include "estimation/functaset/functaset.h"
#include "estimation/functaset/latent_encoder.h"
#include "estimation/data/trunk_targets.h"
#include "models/core/atomic_file.h"
#include "models/trunk/functa_model.h"
#include "models/simulator/tool.h"
#include "estimation/posterior/pose_posterior.h"
#include "estimation/synthesis/generator_posterior.h"
#include "estimation/synthesis/pose_sampler.h"
#include "models/pose/pose_generator.h"

namespace tactfunc::apps {
namespace {

// What a printed yaw error means for a tool of symmetry order n (the truth's yaw is
// printed as labelled, which may be an equivalent turned by 2 pi k / n).
std::string YawErrorNote(int n) {
  if (n == 1) return "";
  if (n == 0) return " (yaw unobservable for this tool)";
  return " (yaw modulo the tool's " + std::to_string(n) + "-fold symmetry)";
}

// The truth line both paths print: the label, and the estimate's position error and yaw
// error modulo the tool's symmetry order n (YawErrorNote says so). name_tool: the
// label's tool too (the generator path, which may have identified the tool).
void PrintTruth(const PoseLabel& label, const SE2d& estimate, int n, bool name_tool) {
  const SE2d& truth = label.sensor_T_object;
  const double e_mm = 1e3 * std::hypot(estimate.x() - truth.x(), estimate.y() - truth.y());
  const std::string tool = name_tool ? label.tool + " " : "";
  std::printf("pose: truth %sx = %.3f mm, y = %.3f mm, yaw = %.2f deg; error %.3f mm, %.2f deg%s\n",
              tool.c_str(), truth.x() * 1e3, truth.y() * 1e3, truth.yaw() * kDeg, e_mm,
              YawErrorModuloSymmetry(estimate.yaw(), truth.yaw(), n) * kDeg,
              YawErrorNote(n).c_str());
}

// The covariance of a pose estimate in the tangent space at `at` (right perturbations) and
// as ROS PoseWithCovariance's 6x6 (x-y rotated by `yaw_of`), as `pose` prints them;
// returns the ROS covariance.
std::array<double, 36> PrintCovariance(const SE2d& mean, const Eigen::Matrix3d& cov, const char* at,
                     const char* yaw_of) {
  std::printf("pose: covariance, tangent space at the %s (right perturbations), "
              "order x [m], y [m], yaw [rad]:\n", at);
  for (int r = 0; r < 3; ++r) {
    std::printf("  [% .4e  % .4e  % .4e]\n", cov(r, 0), cov(r, 1), cov(r, 2));
  }
  const std::array<double, 36> ros = ToRosPoseCovariance(mean, cov);
  std::printf("pose: ROS PoseWithCovariance.covariance (6x6 row-major over x, y, z, roll, pitch, "
              "yaw; parent frame, x-y rotated by %s; others 0):\n ", yaw_of);
  for (int i : {0, 1, 5, 6, 7, 11, 30, 31, 35}) std::printf(" [%d] %.4e", i, ros[i]);
  std::printf("\n");
  return ros;
}

namespace fs = std::filesystem;

struct PoseFlags {
  bool allow_other_frames = false;
  std::string model;
  std::string pose_model;
  std::string functaset;
  std::string frame;
  std::string reference;
  std::string data;
  // Data without metadata (a video, a user's folder); pose's own --sensor, --reference
  // and --pixel-pitch-mm keep their meanings.
  DatasetFlags dataset;
  std::string id;
  std::string sensor;
  std::string tool;
  std::string sampler;  // "": sgld, or laplace for a photometric trunk
  std::string method = "latent";
  std::string generator;
  std::string generator_model;  // the generator's trunk, if not --model's
  int samples = 100;
  std::uint64_t seed = 0;
  int knn_k = 8;
  int sgld_minibatch = PosePosterior::kDefaultSgldMinibatch;
  int max_pixels = -1;  // -1 = the method's default (latent: every valid pixel)
  int final_pixels = -1;  // --method generator: GeneratorPosterior::Options::final_pixels
  double pixel_pitch_mm = 0;
  std::string out;
  int height = 420;
  bool json = false;
  bool no_model_error = false;
  bool unknown_tool = false;
  int symmetry_order = -1;  // -1 = from the tool
};

const cv::Scalar kSampleColour(0, 165, 255);  // orange (BGR)
const cv::Scalar kMeanColour(255, 255, 0);    // cyan
const cv::Scalar kTruthColour(80, 255, 80);   // green
const cv::Scalar kModeColour(255, 80, 255);   // magenta

// A frame to estimate: its trunk targets, its contact image and what is known about it.
struct Input {
  SensorKind sensor = SensorKind::kSoftBubble;
  Image difference;     // Difference (estimation/data/preprocess.h), physical units
  Image reference;      // the frame's own no-contact reference, physical units
  double pitch_m = 0;   // 0 = unknown
  std::optional<PoseLabel> label;
  std::string name;     // for titles
  std::map<std::string, int> tool_symmetries;  // the dataset's tools.csv (--data)
};

// ---- The picture -------------------------------------------------------------------------

// Maps sensor-frame metres to pixels of a panel.
struct View {
  double x0 = 0, y0 = 0;    // metres at the panel's centre
  double px_per_m = 1;
  int width = 0, height = 0;
  cv::Point2d operator()(double x, double y) const {
    return {width / 2.0 + (x - x0) * px_per_m, height / 2.0 - (y - y0) * px_per_m};
  }
};

cv::Point Fix(cv::Point2d p) {
  return cv::Point(static_cast<int>(std::lround(p.x * 16)), static_cast<int>(std::lround(p.y * 16)));
}

void DrawSamples(cv::Mat& panel, const View& view, const PoseDistribution& d, double tick_px) {
  const double max_weight = *std::max_element(d.weights().begin(), d.weights().end());
  for (int i = 0; i < d.size(); ++i) {
    const SE2d& s = d.samples()[i];
    const cv::Point2d p = view(s.x(), s.y());
    const cv::Point2d q(p.x + tick_px * std::cos(s.yaw()), p.y - tick_px * std::sin(s.yaw()));
    // Weighted (knn) samples: the dot's area follows the weight.
    const double radius = 1.5 + 2.5 * std::sqrt(d.weights()[i] / max_weight);
    cv::line(panel, Fix(p), Fix(q), kSampleColour, 1, cv::LINE_AA, 4);
    cv::circle(panel, Fix(p), static_cast<int>(radius * 16), kSampleColour, cv::FILLED,
               cv::LINE_AA, 4);
  }
}

void DrawArrow(cv::Mat& panel, cv::Point2d p, double yaw, double length, const cv::Scalar& colour) {
  const cv::Point2d q(p.x + length * std::cos(yaw), p.y - length * std::sin(yaw));
  cv::arrowedLine(panel, Fix(p), Fix(q), cv::Scalar(0, 0, 0), 4, cv::LINE_AA, 4, 0.25);
  cv::arrowedLine(panel, Fix(p), Fix(q), colour, 2, cv::LINE_AA, 4, 0.25);
  cv::circle(panel, Fix(p), 5 * 16, cv::Scalar(0, 0, 0), 3, cv::LINE_AA, 4);
  cv::circle(panel, Fix(p), 5 * 16, colour, 2, cv::LINE_AA, 4);
}

void DrawModes(cv::Mat& panel, const View& view, const std::vector<PoseMode>& modes) {
  for (std::size_t k = 0; k < modes.size() && k < 5; ++k) {
    const cv::Point p(view(modes[k].mean.x(), modes[k].mean.y()));
    cv::drawMarker(panel, p, cv::Scalar(0, 0, 0), cv::MARKER_TILTED_CROSS, 16, 4, cv::LINE_AA);
    cv::drawMarker(panel, p, kModeColour, cv::MARKER_TILTED_CROSS, 16, 2, cv::LINE_AA);
    PutLabel(panel, FormatFixed(100 * modes[k].weight, 0) + "%", p + cv::Point(8, -8), 0.4,
             kModeColour);
  }
}

// The 90% ellipse of the Gaussian x-y marginal, in the sensor frame: the tangent
// (body-frame) x-y block rotated by the mean's yaw.
void DrawEllipse(cv::Mat& panel, const View& view, const SE2d& mean, const Eigen::Matrix3d& cov) {
  const Eigen::Matrix2d r = Eigen::Rotation2Dd(mean.yaw()).toRotationMatrix();
  const Eigen::Matrix2d c = r * cov.topLeftCorner<2, 2>() * r.transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(c);
  const double chi2_90 = 4.605170185988091;  // chi-square, 2 dof, p = 0.9
  std::vector<cv::Point> points;
  for (int k = 0; k <= 72; ++k) {
    const double t = 2 * M_PI * k / 72;
    const Eigen::Vector2d u(std::cos(t), std::sin(t));
    const Eigen::Vector2d v = eig.eigenvectors() *
                              (eig.eigenvalues().cwiseMax(0).cwiseSqrt() * std::sqrt(chi2_90))
                                  .cwiseProduct(u);
    points.push_back(Fix(view(mean.x() + v.x(), mean.y() + v.y())));
  }
  cv::polylines(panel, points, false, kMeanColour, 1, cv::LINE_AA, 4);
}

double NiceStep(double span) {
  const double raw = span / 5;
  const double p = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    if (m * p >= raw) return m * p;
  }
  return 10 * p;
}

void DrawGrid(cv::Mat& panel, const View& view, double half_m) {
  const double step = NiceStep(2 * half_m);
  const double lo_x = view.x0 - half_m * 1.2, hi_x = view.x0 + half_m * 1.2;
  const double lo_y = view.y0 - half_m * 1.2, hi_y = view.y0 + half_m * 1.2;
  const int digits = step * 1e3 >= 1 ? 0 : (step * 1e3 >= 0.1 ? 1 : 2);
  for (double x = std::ceil(lo_x / step) * step; x <= hi_x; x += step) {
    const int c = static_cast<int>(std::lround(view(x, 0).x));
    cv::line(panel, {c, 0}, {c, panel.rows}, cv::Scalar(70, 70, 70), 1);
    PutLabel(panel, FormatFixed(x * 1e3, digits), {c + 2, panel.rows - 6}, 0.35,
             cv::Scalar(200, 200, 200));
  }
  for (double y = std::ceil(lo_y / step) * step; y <= hi_y; y += step) {
    const int r = static_cast<int>(std::lround(view(0, y).y));
    cv::line(panel, {0, r}, {panel.cols, r}, cv::Scalar(70, 70, 70), 1);
    PutLabel(panel, FormatFixed(y * 1e3, digits), {3, r - 3}, 0.35, cv::Scalar(200, 200, 200));
  }
}

cv::Mat YawHistogram(int width, int height, const PoseDistribution& d, const SE2d& mean,
                     const std::optional<double>& truth_yaw, int n) {
  cv::Mat panel(height, width, CV_8UC3, cv::Scalar(24, 24, 24));
  if (n == 0) {
    PutLabel(panel, "yaw unobservable (continuous symmetry, n = 0)", {10, height / 2}, 0.5);
    return panel;
  }
  // Folded yaws lie within pi/n of the mean (FoldedBySymmetry): show [mean - pi/n, mean + pi/n].
  const double half = M_PI / n, lo = mean.yaw() - half;
  const int bins = 48, left = 40, right = 10, top = 10, bottom = 28;
  std::vector<double> mass(bins, 0);
  for (int i = 0; i < d.size(); ++i) {
    const double yaw = FoldYawNear(d.samples()[i].yaw(), mean.yaw(), n);
    const int b = std::clamp(static_cast<int>((yaw - lo) / (2 * half) * bins), 0, bins - 1);
    mass[b] += d.weights()[i];
  }
  const double peak = std::max(1e-12, *std::max_element(mass.begin(), mass.end()));
  const double plot_w = width - left - right, plot_h = height - top - bottom;
  auto x_of = [&](double yaw) { return left + (yaw - lo) / (2 * half) * plot_w; };
  for (int b = 0; b < bins; ++b) {
    const int x0 = static_cast<int>(left + plot_w * b / bins);
    const int x1 = static_cast<int>(left + plot_w * (b + 1) / bins) - 1;
    const int y0 = static_cast<int>(top + plot_h * (1 - mass[b] / peak));
    if (mass[b] > 0) {
      cv::rectangle(panel, {x0, y0}, {x1, top + static_cast<int>(plot_h)}, kSampleColour, cv::FILLED);
    }
  }
  cv::line(panel, {left, top + static_cast<int>(plot_h)}, {width - right, top + static_cast<int>(plot_h)},
           cv::Scalar(200, 200, 200), 1);
  for (int k = 0; k <= 4; ++k) {
    const double yaw = lo + 2 * half * k / 4;
    const int x = static_cast<int>(x_of(yaw));
    cv::line(panel, {x, top + static_cast<int>(plot_h)}, {x, top + static_cast<int>(plot_h) + 4},
             cv::Scalar(200, 200, 200), 1);
    PutLabel(panel, FormatFixed(yaw * kDeg, 1), {std::min(x - 14, width - 46), height - 8}, 0.38,
             cv::Scalar(200, 200, 200));
  }
  auto vline = [&](double yaw, const cv::Scalar& colour) {
    const int x = static_cast<int>(x_of(yaw));
    cv::line(panel, {x, top}, {x, top + static_cast<int>(plot_h)}, colour, 2, cv::LINE_AA);
  };
  vline(mean.yaw(), kMeanColour);
  if (truth_yaw) vline(FoldYawNear(*truth_yaw, mean.yaw(), n), kTruthColour);
  PutLabel(panel, "yaw (deg)", {4, top + 12}, 0.4);
  return panel;
}

void WritePosteriorPicture(const std::string& path, const Input& input, const PoseDistribution& d,
                           const PosePosterior::Summary& s, const std::vector<PoseMode>& modes,
                           int height, const std::string& sampler) {
  const int n = s.symmetry_order;
  std::optional<SE2d> truth;
  if (input.label) {
    const SE2d& label = input.label->sensor_T_object;
    truth = SE2d::FromXYYaw(label.x(), label.y(), FoldYawNear(label.yaw(), s.mean.yaw(), n));
  }
  // Sample spread for the zoom and the tick length.
  double spread = 0;
  for (const SE2d& p : d.samples()) {
    spread = std::max({spread, std::abs(p.x() - s.mean.x()), std::abs(p.y() - s.mean.y())});
  }
  std::vector<cv::Mat> panels, captions;

  // Panel 1: the contact image in the sensor frame.
  if (input.pitch_m > 0) {
    double scale = 0;
    for (float v : input.difference.data) {
      if (std::isfinite(v)) scale = std::max<double>(scale, std::abs(v));
    }
    cv::Mat image = FitHeight(DifferenceTile(input.difference, scale), height);
    View view;
    view.width = image.cols;
    view.height = image.rows;
    view.px_per_m = image.rows / (input.difference.rows * input.pitch_m);
    DrawSamples(image, view, d, 8);
    DrawModes(image, view, modes);
    if (truth) DrawArrow(image, view(truth->x(), truth->y()), truth->yaw(), 0.18 * height, kTruthColour);
    DrawArrow(image, view(s.mean.x(), s.mean.y()), s.mean.yaw(), 0.18 * height, kMeanColour);
    // A 5 mm scale bar.
    const int bar = static_cast<int>(std::lround(5e-3 * view.px_per_m));
    cv::rectangle(image, {4, image.rows - 26}, {bar + 60, image.rows - 2}, cv::Scalar(24, 24, 24),
                  cv::FILLED);
    cv::line(image, {10, image.rows - 12}, {10 + bar, image.rows - 12}, cv::Scalar(255, 255, 255), 3);
    PutLabel(image, "5 mm", {14 + bar, image.rows - 8}, 0.4);
    captions.push_back(Caption(image.cols, "contact image, sensor frame (x right, y up)"));
    panels.push_back(image);
  }

  // Panel 2: zoom on the samples, with a millimetre grid.
  {
    double half = std::max({3 * std::sqrt(std::max(s.covariance(0, 0), s.covariance(1, 1))),
                            1.1 * spread, 2e-4});
    if (truth) {
      half = std::max({half, 1.2 * std::abs(truth->x() - s.mean.x()),
                       1.2 * std::abs(truth->y() - s.mean.y())});
    }
    cv::Mat zoom(height, height, CV_8UC3, cv::Scalar(24, 24, 24));
    View view;
    view.x0 = s.mean.x();
    view.y0 = s.mean.y();
    view.width = view.height = height;
    view.px_per_m = height / (2.2 * half);
    DrawGrid(zoom, view, half);
    DrawEllipse(zoom, view, s.mean, s.covariance);
    DrawSamples(zoom, view, d, 14);
    DrawModes(zoom, view, modes);
    if (truth) DrawArrow(zoom, view(truth->x(), truth->y()), truth->yaw(), 0.12 * height, kTruthColour);
    DrawArrow(zoom, view(s.mean.x(), s.mean.y()), s.mean.yaw(), 0.12 * height, kMeanColour);
    captions.push_back(Caption(zoom.cols, "zoom: x, y in mm; ellipse = 90% (Gaussian x-y)"));
    panels.push_back(zoom);
  }
  int total_width = 4;
  for (const cv::Mat& p : panels) total_width += p.cols + 4;
  total_width -= 8;
  const std::optional<double> truth_yaw =
      input.label ? std::optional<double>(input.label->sensor_T_object.yaw()) : std::nullopt;
  const cv::Mat histogram = YawHistogram(total_width, 150, d, s.mean, truth_yaw, n);

  const std::string headline =
      std::string(ToString(input.sensor)) + "  " + input.name + "  " + sampler + ": " +
      std::to_string(d.size()) + " samples, " + FormatFixed(s.total_time_ms, 1) + " ms, n = " +
      std::to_string(n) + "  mean x " + FormatFixed(s.mean.x() * 1e3, 2) + " mm, y " +
      FormatFixed(s.mean.y() * 1e3, 2) + " mm, yaw " + FormatFixed(s.mean.yaw() * kDeg, 1) + " deg";
  std::string legend = "orange: samples (tick = heading)   cyan: mean   magenta: modes";
  if (truth) {
    legend += "   green: truth (" + FormatFixed(truth->x() * 1e3, 2) + ", " +
              FormatFixed(truth->y() * 1e3, 2) + " mm, " + FormatFixed(truth->yaw() * kDeg, 1) +
              " deg)";
  }
  const int title_width = std::max(total_width, 760);
  cv::Mat title(46, title_width, CV_8UC3, kBackground);
  PutLabel(title, headline, {6, 18}, 0.45);
  PutLabel(title, legend, {6, 39}, 0.42);
  WritePicture(path, TileGrid({{title}, captions, panels,
                               {Caption(total_width, "yaw histogram (deg, folded by the symmetry)")},
                               {histogram}}));
}

// ---- The command ---------------------------------------------------------------------------

nlohmann::json PoseJson(const SE2d& pose) {
  return {{"x_m", pose.x()}, {"y_m", pose.y()}, {"yaw_rad", pose.yaw()}};
}

// What the SGLD run was: pixels per gradient (all of them, or a minibatch with or without
// the control variate), chains, gradients and the diagnostics.
nlohmann::json SgldJson(const Sgld::Summary& s) {
  return {{"pixels_per_gradient", s.minibatch_size},
          {"pixels", s.num_data_terms},
          {"minibatched", s.minibatched},
          {"control_variate", s.control_variate},
          {"chains", s.num_chains},
          {"gradients", s.num_gradient_evaluations},
          {"min_ess", NumberOrNull(s.min_effective_sample_size)},
          {"max_split_rhat", NumberOrNull(s.max_split_rhat)},
          {"termination", ToString(s.termination_type)},
          {"ms", s.total_time_ms}};
}

nlohmann::json MatrixJson(const Eigen::Matrix3d& m) {
  nlohmann::json rows = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) rows.push_back({m(r, 0), m(r, 1), m(r, 2)});
  return rows;
}

// OUT/posterior.json (the record) and OUT/posterior.png, written atomically, and the line
// that names them.
void WritePosteriorFiles(const std::string& out, const nlohmann::json& record, const Input& input,
                         const PoseDistribution& d, const PosePosterior::Summary& summary,
                         const std::vector<PoseMode>& modes, int height, const std::string& method) {
  const std::string json_path = (fs::path(out) / "posterior.json").string();
  const std::string png_path = (fs::path(out) / "posterior.png").string();
  WriteFileAtomically(json_path, record.dump(1) + "\n");
  WritePosteriorPicture(png_path, input, d, summary, modes, height, method);
  std::cout << "pose: wrote " << json_path << " and " << png_path
            << (input.pitch_m > 0 ? "" : " (pixel pitch unknown: no image panel; give "
                                         "--pixel-pitch-mm)")
            << "\n";
}

void RunGeneratorPose(const PoseFlags& flags, const FunctaModel& model, const Input& input,
                      const TrunkTargets& targets, const std::string& tool) {
  if (input.sensor != SensorKind::kSoftBubble) {
    throw UsageError("--method generator: the generator path models Soft Bubble frames; the "
                     "frame is " + std::string(ToString(input.sensor)));
  }
  if (flags.generator.empty()) {
    throw UsageError("--method generator needs --generator G.tpg (from `tactfunc "
                     "train-generator`, e.g. models/pretrained/pose_generator_bubble.tpg)");
  }
  // The trunk the generator renders through: --generator-model's, else --model's. The pose
  // model's start reads --model's latents either way (GeneratorPosterior's pose_mlp_trunk).
  const GeneratorModel renderer =
      LoadGeneratorModel(flags.generator_model, model, flags.model, input.sensor);
  const FunctaModel* generator_model = renderer.model;
  const std::string& generator_model_path = renderer.path;
  const SensorTrunk& trunk = generator_model->Trunk(input.sensor);
  const PoseGenerator generator =
      LoadPoseGeneratorFor(flags.generator, *generator_model, input.sensor, generator_model_path);
  if (!tool.empty() && generator.ToolIndex(tool) < 0) {
    std::string names;
    for (const std::string& t : generator.options().tools) names += (names.empty() ? "" : ", ") + t;
    throw UsageError("--tool '" + tool + "': the generator '" + flags.generator +
                     "' does not know it (it knows " + names + ")");
  }
  const PoseMlp pose_model = LoadPoseModelFor(flags.pose_model, model, input.sensor, flags.model);
  std::unique_ptr<KnnPoseStarts> knn;
  if (!flags.functaset.empty()) {
    const Functaset functaset = Functaset::Load(flags.functaset);
    if (generator_model != &model && functaset.model_checksum() == model.checksum()) {
      // The latent path's functaset (--method both): its latents are not the generator
      // trunk's, so they cannot place the generator's k-NN starts.
      std::cout << "pose: --functaset holds --model's latents, not --generator-model's: the "
                   "generator path starts from the pose model and its grids\n";
    } else {
      functaset.CheckModel(*generator_model, generator_model_path, flags.functaset);
      knn = std::make_unique<KnnPoseStarts>(functaset, input.sensor);
    }
  }
  GeneratorPosterior::Options options;
  options.seed = flags.seed;
  if (flags.max_pixels >= 0) options.problem.max_pixels = flags.max_pixels;
  options.final_pixels = flags.final_pixels;
  const GeneratorPosterior posterior(trunk, generator, options, knn.get(), &pose_model,
                                     &model.Trunk(input.sensor));
  PoseMixture mixture;
  const GeneratorPosterior::Summary gs = posterior.Estimate(targets, tool, &mixture);
  std::cout << gs.BriefReport() << "\n";
  if (!gs.usable) throw std::runtime_error("the generator posterior failed: " + gs.message);
  const std::string chosen = gs.tool;
  const int n = generator.SymmetryOrder(generator.ToolIndex(chosen));
  MetropolisKernel kernel = MetropolisKernel::kMala;
  const bool mcmc = ParseMetropolisKernel(flags.sampler, &kernel);
  nlohmann::json mcmc_record;
  double sampling_ms = 0;  // MCMC: the chains' wall time, after the posterior's fit
  std::optional<PoseDistribution> drawn;
  if (mcmc) {
    std::vector<LaplaceComponent> modes;  // the chosen tool's modes, heaviest first
    for (const LaplaceComponent& c : mixture.components()) {
      if (c.tool == chosen) modes.push_back(c);
    }
    PoseSamplerOptions so;
    so.chain.kernel = kernel;
    so.chain.burn_in = 200;
    so.chain.num_samples_per_chain = std::max(4, (flags.samples + 3) / 4);
    so.chain.seed = flags.seed;
    so.depth_min_m = options.fit.depth_min_m;
    so.depth_max_m = options.fit.depth_max_m;
    const LatentProblem problem(trunk, targets, options.problem);
    const PoseSamples ps = SamplePosePosterior(problem, generator, generator.ToolIndex(chosen),
                                               gs.sigma, modes, so);
    const MetropolisResult& r = ps.chains;
    std::printf("pose: %s, %d chains x %d samples, acceptance %.3f, split R-hat x %.3f y %.3f "
                "yaw %.3f depth %.3f, ESS %.0f %.0f %.0f %.0f, %ld trunk evaluations, %.1f ms\n",
                ToString(kernel), so.chain.num_chains, so.chain.num_samples_per_chain,
                r.MeanAcceptance(), r.split_rhat[0], r.split_rhat[1], r.split_rhat[2],
                r.split_rhat[3], r.effective_sample_size[0], r.effective_sample_size[1],
                r.effective_sample_size[2], r.effective_sample_size[3], ps.trunk_evaluations,
                r.time_ms);
    mcmc_record = {{"kernel", ToString(kernel)},
                   {"chains", so.chain.num_chains},
                   {"burn_in", so.chain.burn_in},
                   {"acceptance", r.MeanAcceptance()},
                   {"split_rhat", {r.split_rhat[0], r.split_rhat[1], r.split_rhat[2], r.split_rhat[3]}},
                   {"ess", {r.effective_sample_size[0], r.effective_sample_size[1],
                            r.effective_sample_size[2], r.effective_sample_size[3]}},
                   {"coordinates", {"x_m", "y_m", "yaw_rad", "depth_m"}},
                   {"modes", modes.size()},
                   {"jump_acceptance", NumberOrNull(r.JumpAcceptance())},
                   {"trunk_evaluations", ps.trunk_evaluations},
                   {"ms", r.time_ms}};
    sampling_ms = r.time_ms;
    drawn.emplace(ps.Poses());
  } else {
    drawn.emplace(mixture.Sample(flags.samples, flags.seed, chosen));
  }
  const PoseDistribution& distribution = *drawn;
  const SE2d& mean = gs.mean;
  const Eigen::Matrix3d& cov = gs.covariance;
  std::printf("pose: %s %s, tool %s%s (n = %d), %d modes, %d samples in %.1f ms\n",
              ToString(input.sensor), input.name.c_str(), chosen.c_str(),
              tool.empty() ? " (most probable)" : "", n, gs.num_modes, distribution.size(),
              gs.total_time_ms + sampling_ms);
  if (tool.empty()) {
    for (const auto& [name, p] : gs.tool_probabilities) {
      if (p >= 1e-4) std::printf("pose: P(tool = %s) = %.4f\n", name.c_str(), p);
    }
  }
  std::printf("pose: mode x = %.3f mm, y = %.3f mm, yaw = %.2f deg (sensor_T_object)\n",
              mean.x() * 1e3, mean.y() * 1e3, mean.yaw() * kDeg);
  std::printf("pose: sd   x = %.3f mm, y = %.3f mm, yaw = %.2f deg (its Laplace component)\n",
              std::sqrt(cov(0, 0)) * 1e3, std::sqrt(cov(1, 1)) * 1e3, std::sqrt(cov(2, 2)) * kDeg);
  // The posterior mean of the tool's modes (PoseMixture::Mean): the mode when there is one.
  const SE2d posterior_mean = mixture.Mean(chosen);
  std::printf("pose: posterior mean x = %.3f mm, y = %.3f mm, yaw = %.2f deg (over the tool's "
              "%d modes)\n",
              posterior_mean.x() * 1e3, posterior_mean.y() * 1e3, posterior_mean.yaw() * kDeg,
              static_cast<int>(std::count_if(mixture.components().begin(),
                                             mixture.components().end(),
                                             [&](const LaplaceComponent& c) {
                                               return c.tool == chosen;
                                             })));
  if (input.label) PrintTruth(*input.label, mean, n, /*name_tool=*/true);
  const std::array<double, 36> ros = PrintCovariance(mean, cov, "mode", "the mode's yaw");
  nlohmann::json components = nlohmann::json::array();
  for (const LaplaceComponent& c : mixture.components()) {
    components.push_back({{"tool", c.tool},
                          {"weight", c.weight},
                          {"log_evidence", c.log_evidence},
                          {"mean", PoseJson(c.mean)},
                          {"depth_m", c.depth_m},
                          {"covariance", MatrixJson(c.covariance.topLeftCorner<3, 3>())},
                          {"start", c.start}});
  }
  nlohmann::json probabilities = nlohmann::json::object();
  for (const auto& [name, p] : gs.tool_probabilities) probabilities[name] = p;
  if (!flags.out.empty()) {
    fs::create_directories(flags.out);
    nlohmann::json samples = nlohmann::json::array();
    for (int i = 0; i < distribution.size(); ++i) {
      const SE2d& p = distribution.samples()[i];
      samples.push_back({p.x(), p.y(), p.yaw(), distribution.weights()[i]});
    }
    nlohmann::json record = {
        {"sensor", ToString(input.sensor)},
        {"method", "generator"},
        {"tool", chosen},
        {"tool_probabilities", probabilities},
        {"symmetry_order", n},
        {"mean", PoseJson(mean)},
        {"posterior_mean", PoseJson(posterior_mean)},
        {"covariance", MatrixJson(cov)},
        {"covariance_convention",
         "tangent space at the heaviest mode of the tool, right perturbations, order x (m), "
         "y (m), yaw (rad)"},
        {"ros_covariance", ros},
        {"components", components},
        {"samples_columns", {"x_m", "y_m", "yaw_rad", "weight"}},
        {"samples", samples},
        {"ms", gs.total_time_ms + sampling_ms},
        {"pixel_sigma", gs.sigma},
        {"sampler", mcmc ? ToString(kernel) : "laplace_mixture"},
        {"model", flags.model},
        {"generator", flags.generator},
        {"generator_model", generator_model_path},
        {"pose_model", flags.pose_model}};
    if (input.label) {
      record["truth"] = PoseJson(input.label->sensor_T_object);
      record["truth"]["tool"] = input.label->tool;
    }
    if (mcmc) record["mcmc"] = mcmc_record;
    // The picture takes the latent path's summary: fill what it draws.
    PosePosterior::Summary ps;
    ps.termination_type = PosePosteriorTermination::kSuccess;
    ps.symmetry_order = n == 0 ? 1 : n;
    ps.num_samples = distribution.size();
    ps.mean = mean;
    ps.covariance = cov;
    ps.total_time_ms = gs.total_time_ms + sampling_ms;
    WritePosteriorFiles(flags.out, record, input, distribution, ps, distribution.Modes(),
                        flags.height, mcmc ? std::string("generator ") + ToString(kernel) : "generator");
  }
  if (flags.json) {
    nlohmann::json j = {{"mean", PoseJson(mean)},
                        {"posterior_mean", PoseJson(posterior_mean)},
                        {"covariance", MatrixJson(cov)},
                        {"ms", gs.total_time_ms + sampling_ms},
                        {"method", "generator"},
                        {"tool", chosen},
                        {"tool_probabilities", probabilities},
                        {"modes", gs.num_modes},
                        {"samples", distribution.size()},
                        {"symmetry_order", n},
                        {"sensor", ToString(input.sensor)},
                        {"termination", "SUCCESS"}};
    if (input.label) j["truth"] = PoseJson(input.label->sensor_T_object);
    EmitJson(j);
  }
}

void RunLatentPose(const PoseFlags& flags, PosteriorSampler sampler, const FunctaModel& model,
                   const Input& input, const TrunkTargets& targets);

void RunPose(const PoseFlags& flags) {
  if (flags.method != "latent" && flags.method != "generator" && flags.method != "both") {
    throw UsageError("--method: expected latent, generator or both, got '" + flags.method + "'");
  }
  if (flags.method == "both" && flags.generator.empty()) {
    throw UsageError("--method both: give --generator (the generator path's model)");
  }
  if (flags.final_pixels >= 0 && flags.method == "latent") {
    throw UsageError("--final-pixels: refines the generator path's modes; give --method generator "
                     "or both");
  }
  PosteriorSampler sampler = PosteriorSampler::kSgld;
  if (!flags.sampler.empty() && !PosteriorSamplerFromString(flags.sampler, &sampler)) {
    MetropolisKernel kernel;
    if (!ParseMetropolisKernel(flags.sampler, &kernel)) {
      throw UsageError("--sampler: expected sgld, laplace or knn (--method latent) or mala, rwm "
                       "(--method generator), got '" + flags.sampler + "'");
    }
    if (flags.method == "both") {
      throw UsageError("--method both: --sampler picks the latent path's sampler (sgld, laplace "
                       "or knn); the generator path draws from its Laplace mixture");
    }
    if (flags.method != "generator") {
      throw UsageError("--sampler " + flags.sampler + ": MCMC over the pose needs --method generator");
    }
  }
  const bool from_data = !flags.data.empty() || !flags.id.empty();
  const bool from_files = !flags.frame.empty() || !flags.reference.empty();
  if (from_data == from_files) {
    throw UsageError("give either --frame and --reference, or --data and --id");
  }
  if (from_data && (flags.data.empty() || flags.id.empty())) {
    throw UsageError("--data and --id go together (the frame <id> of dataset <data>)");
  }
  if (from_files && (flags.frame.empty() || flags.reference.empty())) {
    throw UsageError("--frame and --reference go together");
  }
  if (sampler == PosteriorSampler::kKnn && flags.functaset.empty() && flags.method != "generator") {
    throw UsageError("--sampler knn needs --functaset (its labelled latents are the samples)");
  }

  std::vector<NamedPath> outputs;
  if (!flags.out.empty()) {
    outputs = flags.method == "both"
                  ? FilesIn("--out", flags.out,
                            {"posterior.png", "latent/posterior.json", "latent/posterior.png",
                             "generator/posterior.json", "generator/posterior.png"})
                  : FilesIn("--out", flags.out, {"posterior.json", "posterior.png"});
    outputs.push_back({"--out", flags.out});
    std::vector<NamedPath> inputs = {{"--model", flags.model},
                                     {"--pose-model", flags.pose_model},
                                     {"--functaset", flags.functaset},
                                     {"--frame", flags.frame},
                                     {"--reference", flags.reference}};
    if (from_data) {
      const std::vector<NamedPath> data = DatasetPathInputs("--data", flags.data, flags.dataset);
      inputs.insert(inputs.end(), data.begin(), data.end());
    } else if (!flags.dataset.sensor_file.empty()) {
      inputs.push_back({"--sensor-file", flags.dataset.sensor_file});
    }
    RefuseOutputsThatAreInputs(outputs, inputs);
  }

  const FunctaModel model = FunctaModel::Load(flags.model);
  Input input;
  TrunkTargets targets;
  SensorKind sensor;
  const bool sensor_given = ParseSensorFlag(flags.sensor, &sensor);
  if (from_data) {
    const Dataset dataset = OpenDataset(flags.data, flags.dataset);
    RefuseOutputsThatAreInputs(outputs, DatasetFileInputs("--data", dataset));
    if (!sensor_given) {
      sensor = dataset.has_sensor(SensorKind::kSoftBubble) ? SensorKind::kSoftBubble
                                                           : dataset.sensors().at(0);
    }
    const std::optional<std::size_t> index = dataset.FindFrame(flags.id, sensor);
    if (!index) {
      throw DatasetError("--id '" + flags.id + "': dataset '" + flags.data + "' has no " +
                         ToString(sensor) + " frame of that id");
    }
    if (!model.HasSensor(sensor)) {
      throw DatasetError("--model '" + flags.model + "' has no trunk for sensor " +
                         ToString(sensor));
    }
    CheckModelMatchesData(model, flags.model, dataset, flags.data, sensor, "pose",
                          "--allow-other-frames", flags.allow_other_frames);
    targets = LoadTrunkTargets(dataset, *index, model.Trunk(sensor).format);
    input.reference = dataset.FrameReference(*index);
    input.difference = Difference(dataset.LoadFrame(*index), input.reference, sensor);
    input.pitch_m = dataset.sensor_info(sensor).pixel_pitch_m;
    input.label = dataset.frames()[*index].label;
    input.name = "frame " + flags.id;
    input.tool_symmetries = dataset.tool_symmetries();
  } else {
    // --sensor-file: raw camera frames of that sensor, its geometry applied to both.
    const FramePair pair = ReadFramePair(flags.frame, flags.reference, flags.sensor,
                                         flags.dataset.sensor_file);
    sensor = pair.sensor;
    if (!model.HasSensor(sensor)) {
      throw DatasetError("--model '" + flags.model + "' has no trunk for sensor " +
                         ToString(sensor) + "; the frame '" + flags.frame + "' was read as " +
                         ToString(sensor));
    }
    if (pair.description) {
      CheckModelDescription(model, flags.model, *pair.description,
                            "--sensor-file '" + flags.dataset.sensor_file + "'", sensor, "pose",
                            "--allow-other-frames", flags.allow_other_frames);
    }
    targets = MakeTrunkTargets(pair.frame, pair.reference, sensor, model.Trunk(sensor).format);
    input.reference = pair.reference;
    input.difference = Difference(pair.frame, pair.reference, sensor);
    input.pitch_m = pair.description && pair.description->pixel_pitch_m > 0
                        ? pair.description->pixel_pitch_m
                        : DatasetPixelPitch(flags.frame, sensor);
    input.name = fs::path(flags.frame).filename().string();
  }
  if (flags.pixel_pitch_mm > 0) input.pitch_m = flags.pixel_pitch_mm * 1e-3;
  input.sensor = sensor;
  std::string generator_tool = flags.tool;
  if (generator_tool.empty() && input.label && !flags.unknown_tool) {
    generator_tool = input.label->tool;
  }
  if (flags.method == "generator") {
    RunGeneratorPose(flags, model, input, targets, generator_tool);
    return;
  }
  if (flags.method == "latent") {
    RunLatentPose(flags, sampler, model, input, targets);
    return;
  }
  // Both paths on the same frame: each writes into its own subfolder, then one picture
  // stacks the two.
  PoseFlags latent = flags, generator = flags;
  if (!flags.out.empty()) {
    latent.out = (fs::path(flags.out) / "latent").string();
    generator.out = (fs::path(flags.out) / "generator").string();
  }
  std::cout << "pose: --- latent path (" << ToString(sampler) << ") ---\n";
  RunLatentPose(latent, sampler, model, input, targets);
  std::cout << "pose: --- generator path ---\n";
  RunGeneratorPose(generator, model, input, targets, generator_tool);
  if (!flags.out.empty()) {
    const std::string path = (fs::path(flags.out) / "posterior.png").string();
    std::vector<std::vector<cv::Mat>> rows;
    for (const std::string& part : {latent.out, generator.out}) {
      const std::string png = (fs::path(part) / "posterior.png").string();
      const std::string bytes = ReadFile(png);
      const cv::Mat picture =
          codecs::Decode(reinterpret_cast<const std::uint8_t*>(bytes.data()), bytes.size(),
                         codecs::DecodeMode::kColor);
      if (picture.empty()) throw std::runtime_error(png + ": could not read the picture back");
      rows.push_back({picture});
    }
    WritePicture(path, TileGrid(rows));
    std::cout << "pose: wrote " << path << " (latent path above, generator path below)\n";
  }
}

void RunLatentPose(const PoseFlags& flags, PosteriorSampler sampler, const FunctaModel& model,
                   const Input& input, const TrunkTargets& targets) {
  const SensorKind sensor = input.sensor;
  const PoseMlp pose_model = LoadPoseModelFor(flags.pose_model, model, sensor, flags.model);

  std::string tool = flags.tool;
  if (tool.empty() && input.label) tool = input.label->tool;
  // The symmetry order: --symmetry-order, else the dataset's tools.csv, else the built-in
  // tool's, else 1.
  bool known = true;
  const int n = flags.symmetry_order >= 0
                    ? flags.symmetry_order
                    : SymmetryOrderOfTool(tool, input.tool_symmetries, &known);
  if (!tool.empty() && !known) {
    std::cerr << "pose: warning: unknown tool '" << tool
              << "': symmetry order 1 assumed (nothing folded)\n";
  }

  const SensorTrunk& trunk = model.Trunk(sensor);
  const bool photometric = trunk.photometric != nullptr;
  // A photometric trunk's default is laplace: its sgld chains wander off the fit with
  // the contact's pose values (docs/POSES.md, "Pose posteriors on a photometric trunk").
  if (photometric && flags.sampler.empty()) sampler = PosteriorSampler::kLaplace;
  PosePosterior::Options options;
  options.sampler = sampler;
  options.num_samples = flags.samples;
  options.seed = flags.seed;
  options.knn.k = flags.knn_k;
  options.sgld.minibatch_size = flags.sgld_minibatch;
  if (photometric && flags.max_pixels >= 0) {
    throw UsageError("--max-pixels: the " + std::string(ToString(sensor)) + " trunk of '" +
                     flags.model + "' is photometric; its posterior uses every valid pixel");
  }
  if (flags.max_pixels >= 0) options.problem.max_pixels = flags.max_pixels;
  // Centre on the latent map the pose MLP was trained on (estimation/posterior/pose_posterior.h);
  // a photometric trunk's latent is fitted below as encode fits it.
  if (!photometric) options.fit.strategy = LatentMapOfPoseModel(pose_model, trunk);
  options.model_error = !flags.no_model_error;
  std::string error;
  if (!options.IsValid(&error)) throw UsageError(error);
  FunctasetKnn knn;
  if (sampler == PosteriorSampler::kKnn) {
    const Functaset functaset = Functaset::Load(flags.functaset);
    functaset.CheckModel(model, flags.model, flags.functaset);
    knn = MakeFunctasetKnn(functaset, sensor, /*train_only=*/true, options.knn, flags.functaset);
  }
  const PosePosterior posterior(trunk, pose_model, options, knn.posterior.get());
  std::optional<PoseDistribution> distribution;
  PosePosterior::Summary summary;
  if (photometric) {
    // encode's own fit of the frame (the latents train-pose saw), then the posterior
    // about it; the fit's time counts in the total.
    const std::unique_ptr<LatentEncoder> encoder_holder =
        PhotometricPoseEncoder(model, flags.model, sensor, pose_model, flags.pose_model);
    const LatentEncoder& encoder = *encoder_holder;
    // The frame is drawn against its own reference.
    const std::shared_ptr<const PhotometricTrunk::Markers> markers =
        FrameMarkers(trunk, input.reference);
    const EncodedFrameFit fit = EncodeFrame(encoder, sensor, targets, markers.get());
    summary = posterior.Estimate(targets, fit.latent, n, &distribution, nullptr, markers.get());
    summary.fit_time_ms = fit.ms;
    summary.total_time_ms += fit.ms;
    std::cout << "pose: the latent fitted as encode fits it ("
              << encoder.StrategyOf(sensor).ToString() << ", " << FormatFixed(fit.ms, 1)
              << " ms); " << ToString(sampler) << " samples the photometric trunk's posterior\n";
  } else {
    summary = posterior.Estimate(targets, n, &distribution);
  }
  std::cout << summary.BriefReport() << "\n";
  if (!summary.IsSolutionUsable() || !distribution) {
    throw std::runtime_error(std::string("the ") + ToString(sampler) +
                             " posterior failed: " + summary.message);
  }

  const SE2d& mean = summary.mean;
  const Eigen::Matrix3d& cov = summary.covariance;
  std::printf("pose: %s %s, tool %s (n = %d), %d samples in %.1f ms\n", ToString(sensor),
              input.name.c_str(), tool.empty() ? "unknown" : tool.c_str(), n, summary.num_samples,
              summary.total_time_ms);
  std::printf("pose: mean x = %.3f mm, y = %.3f mm, yaw = %.2f deg (sensor_T_object)\n",
              mean.x() * 1e3, mean.y() * 1e3, mean.yaw() * kDeg);
  std::printf("pose: sd   x = %.3f mm, y = %.3f mm, yaw = %.2f deg\n",
              std::sqrt(cov(0, 0)) * 1e3, std::sqrt(cov(1, 1)) * 1e3, std::sqrt(cov(2, 2)) * kDeg);
  if (input.label) PrintTruth(*input.label, mean, n, /*name_tool=*/false);
  const std::array<double, 36> ros = PrintCovariance(mean, cov, "mean", "the mean yaw");

  const std::vector<PoseMode> modes = distribution->Modes();
  if (!flags.out.empty()) {
    fs::create_directories(flags.out);
    nlohmann::json samples = nlohmann::json::array();
    for (int i = 0; i < distribution->size(); ++i) {
      const SE2d& p = distribution->samples()[i];
      samples.push_back({p.x(), p.y(), p.yaw(), distribution->weights()[i]});
    }
    nlohmann::json mode_list = nlohmann::json::array();
    for (const PoseMode& m : modes) {
      mode_list.push_back({{"weight", m.weight}, {"mean", PoseJson(m.mean)},
                           {"covariance", MatrixJson(m.covariance)}, {"num_samples", m.num_samples}});
    }
    nlohmann::json record = {
        {"sensor", ToString(sensor)},
        {"sampler", ToString(sampler)},
        {"tool", tool},
        {"symmetry_order", n},
        {"mean", PoseJson(mean)},
        {"covariance", MatrixJson(cov)},
        {"covariance_convention",
         "tangent space at the mean, right perturbations, order x (m), y (m), yaw (rad)"},
        {"ros_covariance", ros},
        {"samples_columns", {"x_m", "y_m", "yaw_rad", "weight"}},
        {"samples", samples},
        {"modes", mode_list},
        {"ms", summary.total_time_ms},
        {"termination", ToString(summary.termination_type)},
        {"message", summary.message},
        {"model", flags.model},
        {"pose_model", flags.pose_model}};
    if (input.label) {
      record["truth"] = PoseJson(input.label->sensor_T_object);
      record["truth"]["tool"] = input.label->tool;
    }
    if (sampler == PosteriorSampler::kSgld) record["sgld"] = SgldJson(summary.sgld_summary);
    WritePosteriorFiles(flags.out, record, input, *distribution, summary, modes, flags.height,
                        ToString(sampler));
  }
  if (flags.json) {
    nlohmann::json j = {{"mean", PoseJson(mean)},
                        {"covariance", MatrixJson(cov)},
                        {"ms", summary.total_time_ms},
                        {"sampler", ToString(sampler)},
                        {"samples", summary.num_samples},
                        {"symmetry_order", n},
                        {"sensor", ToString(sensor)},
                        {"termination", ToString(summary.termination_type)}};
    if (input.label) {
      j["truth"] = PoseJson(input.label->sensor_T_object);
    }
    if (sampler == PosteriorSampler::kSgld) j["sgld"] = SgldJson(summary.sgld_summary);
    EmitJson(j);
  }
}

}  // namespace

void RegisterPose(CLI::App& app, CommandBody* selected) {
  auto flags = std::make_shared<PoseFlags>();
  CLI::App* sub = app.add_subcommand(
      "pose",
      "In-hand pose posterior of one frame (--method latent: sgld, laplace or knn; --method "
      "generator: analysis-by-synthesis, a Laplace mixture over the pose modes): mean, tangent "
      "covariance, ROS covariance; optionally posterior.json and posterior.png.");
  sub->add_option("--model", flags->model, "Model file (.tfm) from `tactfunc train`")->required();
  sub->add_option("--pose-model", flags->pose_model, "Pose model from `tactfunc train-pose`")
      ->required();
  sub->add_option("--functaset", flags->functaset,
                  "Functaset (.tfs) of the model: the knn sampler's labelled train latents");
  sub->add_option("--frame", flags->frame, "The frame (PNG/JPG in the sensor's encoding)");
  sub->add_option("--reference", flags->reference, "The sensor's no-contact reference image");
  sub->add_option("--data", flags->data,
                  "A dataset folder or video (instead of --frame/--reference)");
  AddDatasetFlags(sub, &flags->dataset, {"--sensor", "--reference", "--pixel-pitch-mm"});
  sub->add_option("--id", flags->id, "Frame id in --data (its label is the truth)");
  sub->add_option("--sensor", flags->sensor,
                  "bubble or gelslim; default: inferred from --frame, or bubble for --data");
  sub->add_option("--tool", flags->tool,
                  "Tool name (sets the symmetry order; default: the frame's label, else none)");
  sub->add_option("--symmetry-order", flags->symmetry_order,
                  "Rotational symmetry order n of the tool (yaw folded modulo 360/n deg; 0 = no "
                  "observable yaw), for a tool of your own (default: the dataset's tools.csv with "
                  "--data, else the built-in tool's, else 1)")
      ->check(CLI::Range(0, 360));
  sub->add_option("--method", flags->method,
                  "latent (default: the pose MLP on the frame's latent posterior, --sampler) or "
                  "generator (the pose fitted through --generator and the trunk; a Laplace "
                  "mixture over its modes, tools identified when --tool is not given) or both "
                  "(each into its own subfolder of --out, and one posterior.png with the latent "
                  "path above the generator path)");
  sub->add_option("--generator", flags->generator,
                  "Generator (.tpg) from `tactfunc train-generator`, for --method generator");
  sub->add_option("--generator-model", flags->generator_model,
                  "Model whose trunk --generator renders through, if not --model's (the pose "
                  "model's start still reads --model's latents; the same frame format)");
  sub->add_flag("--unknown-tool", flags->unknown_tool,
                "--method generator: ignore the label's tool and fit every tool");
  sub->add_option("--sampler", flags->sampler,
                  "sgld (default, the paper's; laplace for a photometric trunk), laplace or "
                  "knn (--method latent); mala or rwm "
                  "(--method generator: MCMC over the pose instead of draws from the Laplace "
                  "mixture)");
  sub->add_option("--samples", flags->samples,
                  "Pose samples (default 100; knn gives at most --knn-k)")
      ->check(CLI::Range(1, 1000000));
  sub->add_option("--seed", flags->seed, "Sampler seed (default 0)");
  sub->add_option("--knn-k", flags->knn_k, "Neighbours of the knn sampler (default 8)")
      ->check(CLI::Range(1, 100000));
  sub->add_option("--sgld-minibatch", flags->sgld_minibatch,
                  "Pixels per SGLD gradient, with the control variate at the fitted latent; 0 = "
                  "every pixel (default " +
                      std::to_string(PosePosterior::kDefaultSgldMinibatch) + ")")
      ->check(CLI::Range(0, 100000000));
  sub->add_option("--max-pixels", flags->max_pixels,
                  "Fit and sample at most N of the frame's valid pixels, evenly spaced; 0 = "
                  "every one (default: every one for --method latent, " +
                      std::to_string(GeneratorPosterior::Options().problem.max_pixels) +
                      " for --method generator)")
      ->check(CLI::Range(0, 100000000));
  sub->add_option("--final-pixels", flags->final_pixels,
                  "--method generator: refine every distinct mode again on N pixels (all "
                  "valid pixels when the frame has fewer) and take its Laplace approximation "
                  "there; slower, ranks nearby modes on more of the frame (0 = none; default: "
                  "the stage the generator was calibrated with, as `info` shows)")
      ->check(CLI::Range(0, 100000000));
  sub->add_option("--pixel-pitch-mm", flags->pixel_pitch_mm,
                  "Pixel pitch for posterior.png (default: the frame's dataset.json)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--out", flags->out, "Folder for posterior.json and posterior.png (created)");
  sub->add_option("--height", flags->height, "posterior.png panel height in pixels")
      ->check(CLI::Range(120, 2000));
  sub->add_flag("--no-model-error", flags->no_model_error,
                "Leave the pose MLP's calibrated error out of the sgld/laplace samples (the "
                "latent posterior alone; docs/POSES.md, Calibration)");
  sub->add_flag("--allow-other-frames", flags->allow_other_frames,
                "With --data: run even when its frames (size, channels, sensor description) "
                "are not those the model's trunk was trained on (a warning instead of an error)");
  sub->add_flag("--json", flags->json,
                "Print {mean, covariance, ms, sampler, samples} as one JSON line");
  sub->callback([flags, selected]() { *selected = [flags]() { RunPose(*flags); }; });
}

}  // namespace tactfunc::apps
