// Copyright 2026 The tactfunc Authors.
#include "apps/pictures.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

#include "estimation/data/codecs.h"
#include "estimation/data/image_io.h"

namespace tactfunc::apps {
namespace {

const cv::Vec3b kInvalid(40, 40, 220);  // BGR red for NaN pixels

cv::Mat ColourMapped(const cv::Mat& unit, int colormap) {
  // unit: CV_32F in [0, 1], NaN allowed.
  cv::Mat bytes(unit.size(), CV_8U);
  for (int r = 0; r < unit.rows; ++r) {
    for (int c = 0; c < unit.cols; ++c) {
      const float v = unit.at<float>(r, c);
      bytes.at<uchar>(r, c) =
          std::isfinite(v) ? cv::saturate_cast<uchar>(255.0f * std::clamp(v, 0.0f, 1.0f))
                           : 0;
    }
  }
  cv::Mat coloured;
  cv::applyColorMap(bytes, coloured, colormap);
  for (int r = 0; r < unit.rows; ++r) {
    for (int c = 0; c < unit.cols; ++c) {
      if (!std::isfinite(unit.at<float>(r, c))) coloured.at<cv::Vec3b>(r, c) = kInvalid;
    }
  }
  return coloured;
}

cv::Mat RgbToBgr8(const Image& image, float offset, float gain) {
  cv::Mat out(image.rows, image.cols, CV_8UC3);
  for (int r = 0; r < image.rows; ++r) {
    for (int c = 0; c < image.cols; ++c) {
      cv::Vec3b& px = out.at<cv::Vec3b>(r, c);
      for (int k = 0; k < 3; ++k) {
        const float v = image.at(r, c, image.channels == 3 ? k : 0);
        px[2 - k] = std::isfinite(v)
                        ? cv::saturate_cast<uchar>(255.0f * (offset + gain * v))
                        : kInvalid[2 - k];
      }
    }
  }
  return out;
}

}  // namespace

cv::Mat RawTile(const Image& frame, SensorKind sensor, const Image& reference) {
  if (frame.channels == 1 && sensor == SensorKind::kSoftBubble) {
    // Map the reference's depth range (slightly widened) so near = bright.
    float lo = INFINITY, hi = -INFINITY;
    for (float v : reference.data) {
      if (std::isfinite(v)) {
        lo = std::min(lo, v);
        hi = std::max(hi, v);
      }
    }
    for (float v : frame.data) {
      if (std::isfinite(v)) lo = std::min(lo, v);
    }
    if (!(hi > lo)) hi = lo + 1e-3f;
    cv::Mat unit(frame.rows, frame.cols, CV_32F);
    for (int r = 0; r < frame.rows; ++r) {
      for (int c = 0; c < frame.cols; ++c) {
        unit.at<float>(r, c) = (hi - frame.at(r, c)) / (hi - lo);
      }
    }
    return ColourMapped(unit, cv::COLORMAP_BONE);
  }
  return RgbToBgr8(frame, 0.0f, 1.0f);
}

cv::Mat DifferenceTile(const Image& difference, double scale) {
  if (!(scale > 0)) scale = 1.0;
  if (difference.channels == 3) {
    return RgbToBgr8(difference, 0.5f, static_cast<float>(0.5 / scale));
  }
  cv::Mat unit(difference.rows, difference.cols, CV_32F);
  for (int r = 0; r < difference.rows; ++r) {
    for (int c = 0; c < difference.cols; ++c) {
      unit.at<float>(r, c) = static_cast<float>(0.5 + 0.5 * difference.at(r, c) / scale);
    }
  }
  return ColourMapped(unit, cv::COLORMAP_TWILIGHT_SHIFTED);
}

cv::Mat ErrorTile(const Eigen::MatrixXf& prediction, const TrunkTargets& target, double scale) {
  Image error(target.rows, target.cols, 1);
  for (int j = 0; j < target.rows * target.cols; ++j) {
    error.data[j] = target.weights[j] > 0 ? (prediction.row(j) - target.values.row(j)).mean()
                                          : std::numeric_limits<float>::quiet_NaN();
  }
  return DifferenceTile(error, scale);
}

std::pair<double, double> ValidValueRange(const TrunkTargets& target) {
  double lo = std::numeric_limits<double>::infinity(), hi = -lo;
  for (int j = 0; j < target.values.rows(); ++j) {
    if (!(target.weights[j] > 0)) continue;
    lo = std::min<double>(lo, target.values.row(j).minCoeff());
    hi = std::max<double>(hi, target.values.row(j).maxCoeff());
  }
  if (!(hi > lo)) {
    lo = std::isfinite(lo) ? lo - 0.5 : -0.5;
    hi = lo + 1.0;
  }
  return {lo, hi};
}

cv::Mat ValueTile(const Eigen::MatrixXf& values, const Eigen::VectorXf& weights, int rows,
                  int cols, double lo, double hi) {
  const double span = hi > lo ? hi - lo : 1.0;
  auto unit = [&](float v) {
    return static_cast<uchar>(std::lround(255.0 * std::clamp((v - lo) / span, 0.0, 1.0)));
  };
  cv::Mat tile;
  if (values.cols() == 1) {
    cv::Mat grey(rows, cols, CV_8U);
    for (int j = 0; j < rows * cols; ++j) grey.at<uchar>(j / cols, j % cols) = unit(values(j, 0));
    cv::applyColorMap(grey, tile, cv::COLORMAP_VIRIDIS);
  } else {
    tile = cv::Mat(rows, cols, CV_8UC3);
    for (int j = 0; j < rows * cols; ++j) {
      cv::Vec3b& p = tile.at<cv::Vec3b>(j / cols, j % cols);
      for (int c = 0; c < 3; ++c) p[2 - c] = unit(values(j, std::min<int>(c, values.cols() - 1)));
    }
  }
  for (int j = 0; j < rows * cols; ++j) {
    if (!(weights[j] > 0)) tile.at<cv::Vec3b>(j / cols, j % cols) = cv::Vec3b(60, 60, 60);
  }
  return tile;
}

cv::Mat Caption(int width, const std::string& text) {
  cv::Mat cell(24, width, CV_8UC3, kBackground);
  PutLabel(cell, text, {6, 17}, 0.45);
  return cell;
}

cv::Mat FitHeight(const cv::Mat& tile, int height) {
  const int width = std::max(1, static_cast<int>(std::lround(
                                     tile.cols * static_cast<double>(height) / tile.rows)));
  cv::Mat out;
  cv::resize(tile, out, cv::Size(width, height), 0, 0,
             height >= tile.rows ? cv::INTER_NEAREST : cv::INTER_AREA);
  return out;
}

void DrawPoseArrow(cv::Mat& tile, int rows, int cols, double pitch, double x_m,
                   double y_m, double yaw_rad, const cv::Scalar& colour) {
  if (!(pitch > 0)) return;
  const double sx = static_cast<double>(tile.cols) / cols;
  const double sy = static_cast<double>(tile.rows) / rows;
  const double c = (x_m / pitch + cols / 2.0) * sx;
  const double r = (rows / 2.0 - y_m / pitch) * sy;
  const double length = 0.22 * std::min(tile.rows, tile.cols);
  const cv::Point2d tail(c, r);
  const cv::Point2d head(c + length * std::cos(yaw_rad), r - length * std::sin(yaw_rad));
  const int shift = 4;  // sub-pixel drawing
  auto fixed = [&](cv::Point2d p) {
    return cv::Point(static_cast<int>(std::lround(p.x * (1 << shift))),
                     static_cast<int>(std::lround(p.y * (1 << shift))));
  };
  cv::arrowedLine(tile, fixed(tail), fixed(head), cv::Scalar(0, 0, 0), 4, cv::LINE_AA,
                  shift, 0.3);
  cv::arrowedLine(tile, fixed(tail), fixed(head), colour, 2, cv::LINE_AA, shift, 0.3);
  cv::circle(tile, fixed(tail), 4 << shift, cv::Scalar(0, 0, 0), 3, cv::LINE_AA, shift);
  cv::circle(tile, fixed(tail), 4 << shift, colour, 2, cv::LINE_AA, shift);
}

void PutLabel(cv::Mat& canvas, const std::string& text, cv::Point origin, double scale,
              const cv::Scalar& colour) {
  cv::putText(canvas, text, origin, cv::FONT_HERSHEY_SIMPLEX, scale, cv::Scalar(0, 0, 0),
              3, cv::LINE_AA);
  cv::putText(canvas, text, origin, cv::FONT_HERSHEY_SIMPLEX, scale, colour, 1,
              cv::LINE_AA);
}

cv::Mat TileGrid(const std::vector<std::vector<cv::Mat>>& rows, int gap) {
  int width = 0, height = gap;
  for (const auto& row : rows) {
    int row_width = gap, row_height = 0;
    for (const cv::Mat& tile : row) {
      row_width += tile.cols + gap;
      row_height = std::max(row_height, tile.rows);
    }
    width = std::max(width, row_width);
    height += row_height + gap;
  }
  cv::Mat canvas(std::max(height, 1), std::max(width, 1), CV_8UC3, kBackground);
  int y = gap;
  for (const auto& row : rows) {
    int x = gap, row_height = 0;
    for (const cv::Mat& tile : row) {
      tile.copyTo(canvas(cv::Rect(x, y, tile.cols, tile.rows)));
      x += tile.cols + gap;
      row_height = std::max(row_height, tile.rows);
    }
    y += row_height + gap;
  }
  return canvas;
}

void WritePicture(const std::string& path, const cv::Mat& picture) {
  std::vector<std::uint8_t> bytes;
  if (!codecs::Encode(".png", picture, {}, &bytes)) {
    throw std::runtime_error(path + ": could not encode the picture as PNG");
  }
  WriteFileAtomically(path, std::string(bytes.begin(), bytes.end()));
}

// ---- Plots -------------------------------------------------------------------------------

void PlainText(cv::Mat& canvas, const std::string& text, cv::Point origin, double scale,
               const cv::Scalar& colour, int thickness) {
  cv::putText(canvas, text, origin, cv::FONT_HERSHEY_SIMPLEX, scale, colour, thickness,
              cv::LINE_AA);
}

void DrawDashedLine(cv::Mat& canvas, cv::Point a, cv::Point b, const cv::Scalar& colour) {
  const double length = std::hypot(b.x - a.x, b.y - a.y);
  const int dashes = std::max(1, static_cast<int>(length / 10));
  for (int i = 0; i < dashes; i += 2) {
    const double t0 = static_cast<double>(i) / dashes, t1 = std::min(1.0, (i + 1.0) / dashes);
    cv::line(canvas, a + (b - a) * t0, a + (b - a) * t1, colour, 1, cv::LINE_AA);
  }
}

LogXPlot::LogXPlot(const Layout& layout, double x_lo, double x_hi, double y_lo, double y_hi)
    : layout_(layout),
      canvas_(layout.height, layout.width, CV_8UC3, cv::Scalar(255, 255, 255)),
      area_(layout.left, layout.top, layout.width - layout.left - layout.right,
            layout.height - layout.top - layout.bottom) {
  if (!(x_lo > 0) || !std::isfinite(x_hi) || !std::isfinite(y_lo) || !std::isfinite(y_hi)) {
    x_lo = 1, x_hi = 10, y_lo = 0, y_hi = 1;
  }
  lx_lo_ = std::floor(std::log10(x_lo) * 4) / 4;
  lx_hi_ = std::ceil(std::log10(std::max(x_hi, x_lo)) * 4) / 4;
  if (lx_hi_ <= lx_lo_) lx_hi_ = lx_lo_ + 0.25;
  if (layout.log_y) {
    // y_lo_ and y_hi_ hold log10 of the range, in quarter decades.
    if (!(y_lo > 0)) y_lo = 1, y_hi = std::max(y_hi, 10.0);
    y_lo_ = std::floor(std::log10(y_lo) * 4) / 4;
    y_hi_ = std::ceil(std::log10(std::max(y_hi, y_lo)) * 4) / 4;
    if (y_hi_ <= y_lo_) y_hi_ = y_lo_ + 0.25;
    return;
  }
  const double pad = std::max(0.5, 0.06 * (y_hi - y_lo));
  y_lo_ = std::floor(y_lo - pad);
  y_hi_ = std::ceil(y_hi + pad);
}

int LogXPlot::X(double x) const {
  return area_.x +
         static_cast<int>(std::lround((std::log10(x) - lx_lo_) / (lx_hi_ - lx_lo_) * area_.width));
}

int LogXPlot::Y(double y) const {
  const double v = layout_.log_y ? std::log10(y) : y;
  return area_.y + static_cast<int>(std::lround((y_hi_ - v) / (y_hi_ - y_lo_) * area_.height));
}

void LogXPlot::DrawFrame(const std::string& x_label, const std::string& y_label,
                         const std::string& title, const std::string& subtitle) {
  const cv::Scalar grid(225, 225, 225), axis(60, 60, 60);
  const int left = area_.x, top = area_.y, pw = area_.width, ph = area_.height;
  for (int e = static_cast<int>(std::floor(lx_lo_)); e <= static_cast<int>(std::ceil(lx_hi_)); ++e) {
    for (int m : {1, 2, 5}) {
      const double v = m * std::pow(10.0, e);
      if (std::log10(v) < lx_lo_ - 1e-9 || std::log10(v) > lx_hi_ + 1e-9) continue;
      const int x = X(v);
      cv::line(canvas_, {x, top}, {x, top + ph}, grid, 1);
      cv::line(canvas_, {x, top + ph}, {x, top + ph + 6}, axis, 1);
      char label[32];
      std::snprintf(label, sizeof(label), "%g", v);
      int base = 0;
      const cv::Size size = cv::getTextSize(label, cv::FONT_HERSHEY_SIMPLEX, 0.45, 1, &base);
      PlainText(canvas_, label, {x - size.width / 2, top + ph + 22}, 0.45, axis);
    }
  }
  // The y ticks: values and their labels.
  std::vector<std::pair<double, std::string>> y_ticks;
  if (layout_.log_y) {
    for (int e = static_cast<int>(std::floor(y_lo_)); e <= static_cast<int>(std::ceil(y_hi_));
         ++e) {
      for (int m : {1, 2, 5}) {
        const double v = m * std::pow(10.0, e);
        if (std::log10(v) < y_lo_ - 1e-9 || std::log10(v) > y_hi_ + 1e-9) continue;
        char label[32];
        std::snprintf(label, sizeof(label), "%g", v);
        y_ticks.emplace_back(v, label);
      }
    }
  } else {
    const double span = y_hi_ - y_lo_;
    const double step = span > 20 ? 5 : (span > 8 ? 2 : (span > 4 ? 1 : 0.5));
    for (double v = std::ceil(y_lo_ / step) * step; v <= y_hi_ + 1e-9; v += step) {
      char label[32];
      std::snprintf(label, sizeof(label), "%.*f", step < 1 ? 1 : 0, v);
      y_ticks.emplace_back(v, label);
    }
  }
  for (const auto& [v, label] : y_ticks) {
    const int y = Y(v);
    cv::line(canvas_, {left, y}, {left + pw, y}, grid, 1);
    cv::line(canvas_, {left - 6, y}, {left, y}, axis, 1);
    PlainText(canvas_, label, {left - 50, y + 5}, 0.45, axis);
  }
  cv::rectangle(canvas_, {left, top}, {left + pw, top + ph}, axis, 1);
  int base = 0;
  const cv::Size x_size = cv::getTextSize(x_label, cv::FONT_HERSHEY_SIMPLEX, 0.55, 1, &base);
  PlainText(canvas_, x_label, {left + pw / 2 - x_size.width / 2, layout_.height - 30}, 0.55, axis);
  const int label_width = std::min(ph, 360);
  cv::Mat ylabel(30, label_width, CV_8UC3, cv::Scalar(255, 255, 255));
  PlainText(ylabel, y_label, {4, 21}, 0.55, axis);
  cv::rotate(ylabel, ylabel, cv::ROTATE_90_COUNTERCLOCKWISE);
  ylabel.copyTo(canvas_(cv::Rect(8, top + ph / 2 - label_width / 2, 30, label_width)));
  PlainText(canvas_, title, {left, 24}, 0.65, axis, 2);
  PlainText(canvas_, subtitle, {left, 46}, 0.42, cv::Scalar(110, 110, 110));
}

}  // namespace tactfunc::apps
