// Copyright 2026 The tactfunc Authors.
#include "models/simulator/pose_information.h"

#include <Eigen/Eigenvalues>
#include <array>
#include <cmath>
#include <limits>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <stdexcept>
#include <string>
#include <vector>

#include "models/simulator/tool.h"

namespace tactfunc {

namespace {

constexpr double kInf = std::numeric_limits<double>::infinity();

// The noise-free frame of `contact` (the noise seed does not matter for it).
Image CleanFrame(const ContactSimulator& simulator, const Contact& contact) {
  return simulator.Render(SensorKind::kSoftBubble, contact, 0).clean;
}

Contact Moved(const Contact& contact, int parameter, double step) {
  Contact moved = contact;
  const SE2d& t = contact.sensor_T_object;
  double x = t.x(), y = t.y(), yaw = t.yaw();
  if (parameter == 0) x += step;
  if (parameter == 1) y += step;
  if (parameter == 2) yaw += step;
  if (parameter == 3) moved.depth_m += step;
  moved.sensor_T_object = SE2d::FromXYYaw(x, y, yaw);
  return moved;
}

// The inverse of the symmetric positive semi-definite `fisher` over `index`, +infinity
// on the diagonal (NaN off it) where it is singular. Scaled to unit diagonal first so
// that the test for singularity does not depend on the units.
void InvertInto(const Eigen::Matrix4d& fisher, const std::vector<int>& index,
                Eigen::Matrix4d* bound) {
  const int n = static_cast<int>(index.size());
  Eigen::MatrixXd block(n, n);
  for (int a = 0; a < n; ++a) {
    for (int b = 0; b < n; ++b) block(a, b) = fisher(index[a], index[b]);
  }
  Eigen::VectorXd scale(n);
  bool singular = false;
  for (int a = 0; a < n; ++a) {
    singular |= !(block(a, a) > 0);
    scale[a] = block(a, a) > 0 ? 1 / std::sqrt(block(a, a)) : 0;
  }
  Eigen::MatrixXd inverse(n, n);
  if (!singular) {
    const Eigen::MatrixXd unit = scale.asDiagonal() * block * scale.asDiagonal();
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eigen(unit);
    singular = eigen.info() != Eigen::Success || !(eigen.eigenvalues().minCoeff() > 1e-12);
    if (!singular) {
      inverse = scale.asDiagonal() *
                (eigen.eigenvectors() * eigen.eigenvalues().cwiseInverse().asDiagonal() *
                 eigen.eigenvectors().transpose()) *
                scale.asDiagonal();
    }
  }
  if (singular) {
    inverse.setConstant(std::numeric_limits<double>::quiet_NaN());
    inverse.diagonal().setConstant(kInf);
  }
  for (int a = 0; a < n; ++a) {
    for (int b = 0; b < n; ++b) (*bound)(index[a], index[b]) = inverse(a, b);
  }
}

// The noise-free frame of `contact` and its central-difference derivatives by x, y,
// yaw and depth (one image per parameter, row-major).
struct FrameDerivatives {
  Image centre;
  std::array<std::vector<double>, 4> gradient;
};

FrameDerivatives Differentiate(const ContactSimulator& simulator, const Contact& contact,
                               const PoseInformationOptions& options) {
  const std::array<double, 4> step = {options.position_step_m, options.position_step_m,
                                      options.yaw_step_rad, options.depth_step_m};
  for (double h : step) {
    if (!(h > 0) || !std::isfinite(h)) {
      throw std::invalid_argument("PoseInformationOptions: every step must be > 0 and finite");
    }
  }
  FrameDerivatives out;
  out.centre = CleanFrame(simulator, contact);
  for (int k = 0; k < 4; ++k) {
    const Image plus = CleanFrame(simulator, Moved(contact, k, step[k]));
    const bool one_sided = k == 3 && contact.depth_m - step[k] < 0;
    const Image minus = one_sided ? out.centre : CleanFrame(simulator, Moved(contact, k, -step[k]));
    const double inverse_span = 1 / (one_sided ? step[k] : 2 * step[k]);
    out.gradient[k].resize(out.centre.size());
    for (std::size_t i = 0; i < out.centre.size(); ++i) {
      out.gradient[k][i] =
          (static_cast<double>(plus.data[i]) - static_cast<double>(minus.data[i])) * inverse_span;
    }
  }
  return out;
}

void CheckFrameSize(const ContactSimulator& simulator, const Image& frame) {
  const SoftBubbleOptions& o = simulator.options().bubble;
  if (frame.rows != o.rows || frame.cols != o.cols || frame.channels != 1) {
    throw std::invalid_argument("Soft Bubble frame of " + std::to_string(frame.rows) + "x" +
                                std::to_string(frame.cols) + "x" + std::to_string(frame.channels) +
                                ", expected " + std::to_string(o.rows) + "x" +
                                std::to_string(o.cols) + "x1");
  }
}

}  // namespace

double PoseInformation::PositionRmse() const { return std::sqrt(bound(0, 0) + bound(1, 1)); }

double PoseInformation::PositionWorstSd() const {
  if (!std::isfinite(bound(0, 0)) || !std::isfinite(bound(1, 1))) return kInf;
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eigen(bound.topLeftCorner<2, 2>());
  return std::sqrt(std::max(0.0, eigen.eigenvalues()[1]));
}

double PoseInformation::YawSd() const { return std::sqrt(bound(2, 2)); }

PoseInformation SoftBubblePoseInformation(const ContactSimulator& simulator, const Contact& contact,
                                          const PoseInformationOptions& options) {
  const bool resized = options.rows != 0 || options.cols != 0;
  if (resized && (options.rows <= 0 || options.cols <= 0)) {
    throw std::invalid_argument("SoftBubblePoseInformation: rows and cols must both be 0 or > 0");
  }
  const FrameDerivatives d = Differentiate(simulator, contact, options);
  const int rows = d.centre.rows, cols = d.centre.cols;
  // Each pixel's noise-free depth, noise variance and chance of being read, and the
  // depth's derivative by each parameter; then resized where asked.
  cv::Mat mu(rows, cols, CV_64F), variance(rows, cols, CV_64F), read(rows, cols, CV_64F);
  const std::vector<float>& dropout = simulator.BubbleDropoutProbability();
  for (int i = 0; i < rows * cols; ++i) {
    mu.at<double>(i) = d.centre.data[i];
    const double sigma = simulator.BubbleNoiseStddev(d.centre.data[i]);
    variance.at<double>(i) = sigma * sigma;
    read.at<double>(i) = 1.0 - dropout[i];
  }
  std::array<cv::Mat, 4> gradient;
  for (int k = 0; k < 4; ++k) {
    gradient[k] = cv::Mat(rows, cols, CV_64F, const_cast<double*>(d.gradient[k].data())).clone();
  }
  if (resized) {
    const cv::Size size(options.cols, options.rows);
    const auto resize = [&size](cv::Mat* m) {
      cv::Mat out;
      cv::resize(*m, out, size, 0, 0, cv::INTER_AREA);
      *m = out;
    };
    for (cv::Mat* m :
         {&mu, &variance, &read, &gradient[0], &gradient[1], &gradient[2], &gradient[3]}) {
      resize(m);
    }
    // An area average of m sources has 1 / m of their (mean) variance.
    variance *=
        static_cast<double>(options.rows) * options.cols / (static_cast<double>(rows) * cols);
  }
  PoseInformation info;
  for (int i = 0; i < static_cast<int>(mu.total()); ++i) {
    const double m = mu.at<double>(i), v = variance.at<double>(i);
    // The mean's term plus the stddev's: sigma = c mu^2, so s = 2 sigma / mu g and
    // 2 s s^T / sigma^2 = 8 sigma^2 / mu^2 g g^T / sigma^2.
    const double weight = read.at<double>(i) * (1.0 + 8.0 * v / (m * m)) / v;
    const Eigen::Vector4d g(gradient[0].at<double>(i), gradient[1].at<double>(i),
                            gradient[2].at<double>(i), gradient[3].at<double>(i));
    info.fisher.noalias() += weight * g * g.transpose();
  }
  const bool yaw_observable = GetTool(contact.tool).symmetry_order() != 0;
  info.bound.setConstant(std::numeric_limits<double>::quiet_NaN());
  InvertInto(info.fisher, yaw_observable ? std::vector<int>{0, 1, 2, 3} : std::vector<int>{0, 1, 3},
             &info.bound);
  return info;
}

double SoftBubbleLogLikelihood(const ContactSimulator& simulator, const Image& frame,
                               const Contact& contact) {
  CheckFrameSize(simulator, frame);
  const Image mu = CleanFrame(simulator, contact);
  double sum = 0;
  for (std::size_t i = 0; i < frame.size(); ++i) {
    if (std::isnan(frame.data[i])) continue;
    const double sigma = simulator.BubbleNoiseStddev(mu.data[i]);
    const double r = (frame.data[i] - static_cast<double>(mu.data[i])) / sigma;
    sum -= 0.5 * r * r + std::log(sigma);
  }
  return sum;
}

ContactFit FitSoftBubbleContact(const ContactSimulator& simulator, const Image& frame,
                                const Contact& start, int max_iterations,
                                const PoseInformationOptions& options) {
  CheckFrameSize(simulator, frame);
  const bool yaw_observable = GetTool(start.tool).symmetry_order() != 0;
  ContactFit fit;
  fit.contact = start;
  fit.log_likelihood = SoftBubbleLogLikelihood(simulator, frame, start);
  double lambda = 1e-3;
  for (int iteration = 0; iteration < max_iterations; ++iteration) {
    const FrameDerivatives d = Differentiate(simulator, fit.contact, options);
    Eigen::Matrix4d jtj = Eigen::Matrix4d::Zero();
    Eigen::Vector4d jtr = Eigen::Vector4d::Zero();
    for (std::size_t i = 0; i < frame.size(); ++i) {
      if (std::isnan(frame.data[i])) continue;
      const double sigma = simulator.BubbleNoiseStddev(frame.data[i]);
      const double w = 1 / (sigma * sigma);
      const Eigen::Vector4d g(d.gradient[0][i], d.gradient[1][i], d.gradient[2][i],
                              d.gradient[3][i]);
      jtj.noalias() += w * g * g.transpose();
      jtr += w * (frame.data[i] - static_cast<double>(d.centre.data[i])) * g;
    }
    if (!yaw_observable) {  // the yaw stays where it is
      jtj.row(2).setZero();
      jtj.col(2).setZero();
      jtj(2, 2) = 1;
      jtr[2] = 0;
    }
    fit.iterations = iteration + 1;
    bool improved = false;
    for (int attempt = 0; attempt < 8 && !improved; ++attempt) {
      Eigen::Matrix4d damped = jtj;
      damped.diagonal() *= 1 + lambda;
      const Eigen::Vector4d delta = damped.ldlt().solve(jtr);
      if (!delta.allFinite()) break;
      const SE2d& t = fit.contact.sensor_T_object;
      Contact candidate = fit.contact;
      candidate.sensor_T_object =
          SE2d::FromXYYaw(t.x() + delta[0], t.y() + delta[1], t.yaw() + delta[2]);
      candidate.depth_m = std::max(0.0, fit.contact.depth_m + delta[3]);
      const double ll = SoftBubbleLogLikelihood(simulator, frame, candidate);
      if (ll > fit.log_likelihood) {
        fit.contact = candidate;
        fit.log_likelihood = ll;
        lambda = std::max(1e-6, lambda / 3);
        improved = true;
      } else {
        lambda *= 4;
      }
    }
    if (!improved) break;
  }
  return fit;
}

}  // namespace tactfunc
