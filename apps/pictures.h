// Copyright 2026 The tactfunc Authors.
//
// Pictures people look at: tactile frames as colour tiles, pose arrows, tile grids.
// OpenCV stays in apps/, so that the libraries keep no drawing dependency: they hand
// over tactfunc::Image.
#ifndef TACTFUNC_APPS_PICTURES_H_
#define TACTFUNC_APPS_PICTURES_H_

#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "estimation/data/trunk_targets.h"
#include "models/core/image.h"
#include "models/core/sensor.h"

namespace tactfunc::apps {

// The dark grey behind the pictures' tiles and titles.
inline const cv::Scalar kBackground(32, 32, 32);

// A raw frame as a BGR 8-bit picture: depth through a perceptual colour map (near =
// bright, NaN = red), RGB as is.
cv::Mat RawTile(const Image& frame, SensorKind sensor, const Image& reference);
// A difference image (already reference-subtracted, physical units) as BGR: one
// channel through a diverging map in [-scale, scale] (0 = mid grey); three channels as
// 0.5 + diff / (2 scale) per channel. NaN pixels red.
cv::Mat DifferenceTile(const Image& difference, double scale);
// prediction - target (N x C normalised values, mean over channels) through
// DifferenceTile's diverging map in [-scale, scale]; the target's invalid pixels red.
cv::Mat ErrorTile(const Eigen::MatrixXf& prediction, const TrunkTargets& target, double scale);
// The range [lo, hi] of a target's values over its valid pixels, the colour range its
// ValueTiles share; a range of width 1 about the value (about 0 if no pixel is valid)
// when every valid value is the same.
std::pair<double, double> ValidValueRange(const TrunkTargets& target);
// Normalised trunk values (N x C of a rows x cols frame, pixel j = row * cols + col) as a
// BGR tile: one channel through viridis over [lo, hi], three channels as RGB over
// [lo, hi]; pixels with weight <= 0 dark grey.
cv::Mat ValueTile(const Eigen::MatrixXf& values, const Eigen::VectorXf& weights, int rows,
                  int cols, double lo, double hi);
// A 24-pixel-tall caption cell of `width` with `text` on the dark background.
cv::Mat Caption(int width, const std::string& text);
// Resizes a tile to `height` pixels tall (keeps aspect, nearest-neighbour upscaling
// so pixels stay honest, area downscaling).
cv::Mat FitHeight(const cv::Mat& tile, int height);
// Draws the pose (x, y, yaw in the sensor frame, models/core/sensor.h) as an arrow along the
// tool's x axis on a tile showing a rows x cols frame with `pitch` metres per pixel.
void DrawPoseArrow(cv::Mat& tile, int rows, int cols, double pitch, double x_m,
                   double y_m, double yaw_rad, const cv::Scalar& colour);
// Text with a dark outline so it reads on any background.
void PutLabel(cv::Mat& canvas, const std::string& text, cv::Point origin,
              double scale = 0.45, const cv::Scalar& colour = cv::Scalar(255, 255, 255));
// Stacks rows of tiles (each row left to right) into one canvas with `gap` pixels
// between tiles, on a dark background.
cv::Mat TileGrid(const std::vector<std::vector<cv::Mat>>& rows, int gap = 4);
// Encodes as PNG and writes atomically; throws naming the path.
void WritePicture(const std::string& path, const cv::Mat& picture);

// ---- Plots: log-scale x, linear y (bench fit's Pareto plot, eval's rate-distortion plot)

// Dark text (default) on a light plot, anti-aliased.
void PlainText(cv::Mat& canvas, const std::string& text, cv::Point origin, double scale,
               const cv::Scalar& colour = cv::Scalar(30, 30, 30), int thickness = 1);
// A dashed line from a to b (10-pixel dashes).
void DrawDashedLine(cv::Mat& canvas, cv::Point a, cv::Point b, const cv::Scalar& colour);

// The frame of a plot with a log-scale x axis and a linear y axis on a white canvas:
// the data range [x_lo, x_hi] (x > 0) is widened to whole quarter decades, [y_lo, y_hi]
// padded by max(0.5, 6% of its span) and rounded out to whole units. The plot area is
// the canvas less the margins; a legend goes in the right margin.
class LogXPlot {
 public:
  struct Layout {
    int width = 1400, height = 760;                     // canvas, pixels
    int left = 90, right = 270, top = 60, bottom = 80;  // margins around the plot area
    bool log_y = false;  // the y axis logarithmic too (y_lo > 0), ticks as the x axis's
  };
  LogXPlot(const Layout& layout, double x_lo, double x_hi, double y_lo, double y_hi);
  cv::Mat& canvas() { return canvas_; }
  // Pixel column of x (> 0) and row of y (> 0 with log_y).
  int X(double x) const;
  int Y(double y) const;
  const cv::Rect& area() const { return area_; }
  // Grid and ticks (x at 1, 2, 5 x 10^k; y at round steps, or as x with log_y), the frame, axis
  // titles, a bold title and a grey subtitle above the plot.
  void DrawFrame(const std::string& x_label, const std::string& y_label,
                 const std::string& title, const std::string& subtitle);

 private:
  Layout layout_;
  cv::Mat canvas_;
  cv::Rect area_;
  double lx_lo_ = 0, lx_hi_ = 1, y_lo_ = 0, y_hi_ = 1;
};

}  // namespace tactfunc::apps

#endif  // TACTFUNC_APPS_PICTURES_H_
