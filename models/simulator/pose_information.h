// Copyright 2026 The tactfunc Authors.
//
// PoseInformation: what one Soft Bubble frame can say about its contact, whatever
// model reads it (docs/POSES.md, "What the frames can say").
//
// The simulator knows a frame's noise-free depth mu(theta) as a function of the
// contact's theta = (x, y, yaw, depth) and its noise: each pixel independently Gaussian
// with standard deviation sigma_i = ContactSimulator::BubbleNoiseStddev(mu_i), or a
// dropout with fixed probability q_i. The Fisher information of one frame about theta is
//   I = sum_i (1 - q_i) (g_i g_i^T + 2 s_i s_i^T) / sigma_i^2,
// g_i = d mu_i / d theta and s_i = d sigma_i / d theta = (2 sigma_i / mu_i) g_i, and its
// inverse is the Cramer-Rao bound: no unbiased estimator of theta from that frame, at
// the sensor's full resolution, has a smaller covariance. It does not depend on the
// trunk, the generator or the search, so it tells how much of an estimator's error is
// the frame's and how much the model's.
//
// The derivatives are central differences of the noise-free frame. The simulator
// samples the tool's face at pixel centres, so the frame moves in small jumps as an edge
// crosses a pixel centre (a rod's flat ends: its frame is piecewise constant along its
// axis, and the limit derivative there is 0). Steps from about half a pixel to a pixel
// average over those jumps and agree with each other (pose_information_test), and the
// bound then describes a sensor that integrates over its pixels; much smaller steps
// read the jumps alone (a shallow rod's position floor grows by an order of magnitude at
// a tenth of the default step). The stored frames' 1 um
// quantisation adds 1/12 um^2 to variances of about (250 um)^2 and is left out.
//
// A tool with continuous symmetry (symmetry order 0) has no observable yaw: its row and
// column are left out of the inversion, and the bound's yaw entries are NaN.
#ifndef TACTFUNC_MODELS_SIMULATOR_POSE_INFORMATION_H_
#define TACTFUNC_MODELS_SIMULATOR_POSE_INFORMATION_H_

#include <Eigen/Core>

#include "models/simulator/contact.h"
#include "models/simulator/contact_simulator.h"

namespace tactfunc {

struct PoseInformationOptions {
  // Central-difference steps (> 0): metres for x, y and depth, radians for yaw. A yaw
  // of 1 degree moves a point 10 mm from the tool's origin by 0.17 mm, about the
  // position step; both are under half of the 0.45 mm pixel.
  double position_step_m = 0.2e-3;
  double yaw_step_rad = 1.0 * 3.14159265358979323846 / 180.0;
  double depth_step_m = 0.2e-3;
  // The frames' size: 0 x 0 = the sensor's own; else the frames area-resized to rows x
  // cols first (cv::INTER_AREA, as the product resizes them to a trunk's working size),
  // each resized pixel's noise variance the area average of its sources' over the number
  // of sources it averages and its chance of being read the area average of theirs. That
  // leaves out the correlation between resized pixels that share a source row or column
  // (none when the sizes divide), so it is close, not exact.
  int rows = 0;
  int cols = 0;
};

struct PoseInformation {
  // About (x, y, yaw, depth) of the contact: metres, radians, metres.
  Eigen::Matrix4d fisher = Eigen::Matrix4d::Zero();
  // The Cramer-Rao bound, fisher's inverse; +infinity on the diagonal where the frame
  // carries no information (fisher singular), NaN in the yaw row and column of a tool
  // without an observable yaw.
  Eigen::Matrix4d bound = Eigen::Matrix4d::Zero();

  // The floor on the position's root mean squared error, metres: sqrt of the trace of
  // the bound's x-y block.
  double PositionRmse() const;
  // The floor on the position's error along its least informed direction (the larger
  // principal standard deviation of the x-y block), metres.
  double PositionWorstSd() const;
  // The floor on the yaw's standard deviation, radians; NaN without an observable yaw.
  double YawSd() const;
};

// The information one Soft Bubble frame of `contact` carries, by `simulator`'s forward
// model and noise model. Renders 8 noise-free frames. Throws std::invalid_argument for
// a non-positive step, a size with one side 0 or negative, or a contact Render rejects; a step that
// would take the depth below 0 is taken one-sided.
PoseInformation SoftBubblePoseInformation(const ContactSimulator& simulator, const Contact& contact,
                                          const PoseInformationOptions& options = {});

// The log-likelihood of a Soft Bubble `frame` (the sensor's own size; NaN = a dropout)
// under `contact` by the simulator's forward and noise models: the sum over the pixels
// read of -(frame - mu)^2 / (2 sigma^2) - log(sigma) (constants and the dropouts, which
// do not depend on the contact, left out). Throws std::invalid_argument for a frame of
// another size.
double SoftBubbleLogLikelihood(const ContactSimulator& simulator, const Image& frame,
                               const Contact& contact);

// The contact near `start` that best explains `frame` by the simulator's own models:
// Levenberg-Marquardt on (x, y, yaw, depth) with the derivatives above (weights
// 1 / sigma^2 at the frame's own depths), each step kept only if the log-likelihood
// grows. What an estimator with a perfect renderer would settle on from that start;
// comparing its fits from two starts tells whether the frame itself prefers one basin
// (an estimator's wrong mode is then its model's failure, not the frame's ambiguity).
struct ContactFit {
  Contact contact;
  double log_likelihood = 0;
  int iterations = 0;
};
ContactFit FitSoftBubbleContact(const ContactSimulator& simulator, const Image& frame,
                                const Contact& start, int max_iterations = 10,
                                const PoseInformationOptions& options = {});

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_SIMULATOR_POSE_INFORMATION_H_
