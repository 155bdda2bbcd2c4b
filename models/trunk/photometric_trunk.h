// Copyright 2026 The tactfunc Authors.
//
// PhotometricTrunk: the trunk of an optical tactile sensor (GelSlim, GelSight) that draws
// the CONTACT and lets the sensor's image form from it, instead of drawing the image's
// difference from the reference directly. docs/REPRESENTATION.md ("Optical sensors" and
// "Markers moved at the sensor's resolution") measured why: a SIREN that draws the
// difference directly blurs the printed markers and the thin shading ridges, while this
// head reproduces both from a smooth indentation field.
//
// The latent. z has d values: a rigid motion of the contact (t_0, t_1, phi) in the
// trunk's isotropic coordinates (below), then the SIREN's code (d - 3 - K values), then
// K lighting values a_1..a_K (K = Options::lighting_components, 0 by default). The SIREN
// (models/trunk/latent_modulated_siren.h, latent_dim d - 3 - K, 1 + C outputs) draws the
// contact in its own frame:
//
//   s(p) = SIREN(R(phi)^T (p - t); code),     s_0 = w (the indentation), s_1..s_C
//
// and the head forms the frame's difference from the no-contact reference as the sensor
// forms its image, the skin's printed pattern moved by the slope, plus the shading of the
// slope, plus what neither explains:
//
//   g(p)   = ((w(p + e_0) - w(p - e_0)) / 2, (w(p + e_1) - w(p - e_1)) / 2)
//            (the slope per working pixel by central differences, e_k one pixel along
//             coordinate k: five evaluations of the SIREN's batched passes, no
//             second-order pass; measured level with the exact slope)
//   u(p)   = m g(p)                          (how far the skin moves, working pixels)
//   y_c(p) = S_c(g, w, p) - S_c(0, 0, p) + M_c(p - u) - M_c(p) + s_c(p) + B_c(p)
//            + sum_k a_k L_kc(p)
//
// B is the sensor's background (optional, zero when absent): a fixed per-pixel table on
// the working grid of what every frame shares and the contact cannot draw, since the
// SIREN draws in the contact's frame (a real gel's drift from its reference: lighting,
// the gel's own settling). It has no latent values and no gradient here (the outputs
// are linear in it); PhotometricTrainer learns it with the trunk (Options::
// learn_background, `train --background`, docs/REAL_DATA.md).
//
// L_1..L_K are the sensor's lighting images (optional, K = 0 by default): what varies
// from frame to frame over the whole gel in the SENSOR's frame (a real gel's lighting
// and exposure drifting between frames), a few numbers a frame that the SIREN, drawing
// in the contact's frame, could only spend its code on. Each frame weighs them by its
// own K lighting values; the outputs are linear in both. They start at zero until
// SetLighting; PhotometricTrainer learns them with the trunk (`train --lighting K`).
//
// S is a small shading network (5 -> H -> H -> C, SiLU) of the slope, the depth and the
// position (so it can learn the sensor's vignetting and lighting), and M the reference's
// markers moved by u. By default M is sampled at the SENSOR's resolution: the reference
// as the sensor recorded it, sampled bilinearly on a K x K grid inside each working pixel
// and averaged (the area resize the frames themselves went through), so that a marker a
// pixel wide moves by a fraction of a working pixel without the blur and ringing of
// resampling the already resized reference. M_c(p) at rest is the K x K average at zero
// shift, precomputed once. MarkerSampling::kWorkingResolution instead samples that
// at-rest table bilinearly (smoother gradients: training starts with it while m is
// learned, docs/REPRESENTATION.md). m is ONE scalar: an isotropic skin moves along the
// slope; a learned 2 x 2 matrix was measured to settle on sheared solutions.
//
// Coordinates. Pixel (r, c) of the rows x cols working grid sits at
//   x_0 = (2 c + 1 - cols) / rows,   x_1 = (2 r + 1) / rows - 1
// (x_0 along the columns, x_1 along the rows, as LatentModulatedSiren orders them; one
// unit is rows / 2 pixels along both axes, so a rotation keeps shapes). The slope
// g = (g_0, g_1) is in the same order, per working pixel.
//
// The contact frame touches only the SIREN's first layer: its pre-activation is
// W_0 R^T (p - t) + b_0 + gamma_0, so the reverse pass's dL/dW_0 and dL/db_0 give
//   dL/dt = -R W_0^T dL/db_0,   dL/dphi = <W_0 G, dL/dW_0>_F,  G = [[0, 1], [-1, 0]]
// (dq/dphi = G q for q = R^T (p - t)): no per-pixel coordinate gradient is needed.
//
// Head parameters (one flat vector, double master copy): the shading network's
// W_1 (H x 5), b_1 (H), W_2 (H x H), b_2 (H), W_3 (C x H), b_3 (C), column-major, then m.
// Initialised from a seed (Boost.Random) as PyTorch initialises nn.Linear
// (U(-1/sqrt(fan_in), +1/sqrt(fan_in)) for weights and biases), m = 0.
//
// Loss: the weighted MSE of LatentModulatedSiren (sum_j w_j sum_c (y - t)^2 /
// (C sum_j w_j)). Pixels are named by their index j = r * cols + c on the working grid.
//
// Thread safety: const methods are safe to call concurrently.
#ifndef TACTFUNC_MODELS_TRUNK_PHOTOMETRIC_TRUNK_H_
#define TACTFUNC_MODELS_TRUNK_PHOTOMETRIC_TRUNK_H_

#include <cstdint>
#include <memory>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "models/core/image.h"
#include "models/trunk/latent_modulated_siren.h"

namespace tactfunc {

class PhotometricTrunk {
 public:
  template <typename Scalar>
  using MatrixX = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;
  template <typename Scalar>
  using VectorX = Eigen::Matrix<Scalar, Eigen::Dynamic, 1>;

  // The rigid motion's share of z: (t_0, t_1, phi).
  static constexpr int kPoseValues = 3;

  enum class MarkerSampling {
    kSensorResolution,   // K x K bilinear samples of the sensor-resolution reference
    kWorkingResolution,  // one bilinear sample of the at-rest (working-size) table
  };

  struct Options {
    // Working resolution of the frames (the targets' grid). In [3, 4096] each.
    int rows = 0;
    int cols = 0;
    // Output channels C (1 for grayscale differences). In [1, 4].
    int channels = 1;
    // The SIREN (options().siren latent_dim is latent_dim - 3, outputs 1 + C).
    int width = 64;
    int num_hidden_layers = 3;
    double omega_0 = 30.0;
    // d, the pose and lighting values included. > kPoseValues + lighting_components.
    int latent_dim = 64;
    // K, the lighting images and the latent's last K values that weigh them (header
    // comment). In [0, 64].
    int lighting_components = 0;
    // H, units of each of the shading network's two hidden layers. In [1, 4096].
    int shading_width = 64;
    // K of the sensor-resolution marker sampling. In [1, 32].
    int supersample = 4;
    // How the SIREN's biases and modulation matrix start: true (default) = as PyTorch's
    // nn.Linear draws biases (U(+-1/sqrt(fan_in)): the first layer's phases spread over
    // +-omega_0/sqrt(2), the others' over +-omega_0/sqrt(width)) with the modulation
    // matrix at a tenth of nn.Linear's range, as the prototype of docs/REPRESENTATION.md
    // started; false = LatentModulatedSiren's own initialisation (biases within
    // +-sqrt(6/width)/omega_0), measured 5.6 dB worse for this head at width 64
    // (docs/REPRESENTATION.md, "The photometric trunk in C++").
    bool wide_biases = true;
    bool IsValid(std::string* error) const;
  };

  // The markers M of one no-contact reference: the reference at the SENSOR's resolution
  // in the targets' units, and its at-rest table (rows x cols x C, the K x K average at
  // zero shift). A trunk draws against its own reference (the one it was built with)
  // unless a call names other markers: frames of a set of recordings ("clips"), each
  // with its own reference, are drawn against their own clip's markers, made once per
  // clip by MakeMarkers. They depend on the trunk's grid, channels and K, not on its
  // parameters, so they stay valid while a trunk trains.
  struct Markers {
    Image reference;
    Image at_rest;
    // Where the reference has exactly s K rows per working row (s an integer, the
    // GelSlim's 320 rows over 80 with K = 4: s = 1), the K samples of one column of a
    // pixel's K x K lie s reference rows apart and share their fraction: their sum is
    // one bilinear sample of row_sums(y, x) = sum_{a < K} reference(y + a s, x)
    // (reference.rows - (K - 1) s rows), which SampleMarkers reads away from the
    // borders (K samples a pixel instead of K^2). Empty otherwise; MakeMarkers fills it.
    Image row_sums;
  };

  // `reference` is the no-contact reference at the SENSOR's resolution, in the targets'
  // units (the frame format's grayscale conversion and scale applied, not resized), with
  // Options::channels channels; any size >= 1 x 1. Throws std::invalid_argument for
  // invalid options or a reference with other channels.
  PhotometricTrunk(const Options& options, const Image& reference, std::uint64_t seed = 0);

  // The markers of `reference` (as the constructor's) on this trunk's grid. Throws
  // std::invalid_argument for an empty reference or one with other channels.
  std::shared_ptr<const Markers> MakeMarkers(const Image& reference) const;

  const Options& options() const { return options_; }
  int latent_dim() const { return options_.latent_dim; }
  int channels() const { return options_.channels; }
  const LatentModulatedSiren& siren() const { return siren_; }
  LatentModulatedSiren& mutable_siren() { return siren_; }
  // The trunk's own markers; at_rest() is M(p) at rest, rows x cols x C, the K x K
  // average of reference().
  const Markers& markers() const { return *markers_; }
  const Image& at_rest() const { return markers_->at_rest; }
  const Image& reference() const { return markers_->reference; }

  int NumHeadParameters() const { return num_head_parameters_; }
  // The head's parameter count for a shading width H and C channels.
  static int HeadParameterCount(int shading_width, int channels);
  const Eigen::VectorXd& head_parameters() const { return head_; }
  // Throws std::invalid_argument if the size is not NumHeadParameters().
  void SetHeadParameters(const Eigen::VectorXd& head);
  // m, the last head parameter (working pixels of skin motion per unit of slope).
  double marker_scale() const { return head_[num_head_parameters_ - 1]; }

  // The background B (header comment): rows x cols x C, or empty (none, the default).
  const Image& background() const { return background_; }
  // Throws std::invalid_argument for a table of another shape or a non-finite value; an
  // empty image removes it.
  void SetBackground(const Image& background);
  // Root mean square of the background's values, 0 without one.
  double BackgroundRms() const;

  // The lighting images L (header comment): (rows cols C) x K, row j C + c holding pixel
  // j's channel c (Image's layout), one column per lighting value; zero until set.
  const Eigen::MatrixXf& lighting() const { return lighting_; }
  // Throws std::invalid_argument for a matrix of another shape or a non-finite value.
  void SetLighting(const Eigen::MatrixXf& lighting);
  int lighting_components() const { return options_.lighting_components; }
  // Root mean square of the lighting images' values, 0 without any.
  double LightingRms() const;
  // The SIREN's code values, d - 3 - K; the code is z.segment(kPoseValues, CodeValues()).
  int CodeValues() const {
    return options_.latent_dim - kPoseValues - options_.lighting_components;
  }

  MarkerSampling marker_sampling() const { return marker_sampling_; }
  void set_marker_sampling(MarkerSampling sampling) { marker_sampling_ = sampling; }

  // The isotropic coordinate of pixel j (x_0, x_1).
  Eigen::Vector2d PixelCoordinate(int pixel) const;
  // Every pixel index of the working grid, 0 .. rows * cols - 1.
  std::vector<int> AllPixels() const;

  // Outputs, N x C, for the N pixels named. Throws std::invalid_argument for a latent
  // of the wrong size or a pixel index outside the grid. AllPixels() (and
  // LossAndGradient over them without gradients) runs the SIREN once per pixel and
  // border pixel instead of five times per pixel, a neighbour's coordinate then taken
  // from its own index: equal to the per-pixel pass up to the last bits of float. Any
  // other pixel set (here and in the reverse pass) runs the SIREN once per distinct
  // grid position its pixels and their four neighbours name, so neighbouring or
  // repeated pixels share evaluations (a training step's 512 random pixels of an
  // 80 x 107 frame: about 13% fewer); with none shared it is the per-pixel pass.
  //
  // Every pass below draws the markers from `markers` if given (MakeMarkers of the
  // frame's own reference), else from the trunk's own reference.
  template <typename Scalar>
  MatrixX<Scalar> Forward(const std::vector<int>& pixels, const VectorX<Scalar>& z,
                          const Markers* markers = nullptr) const;

  // The weighted MSE against targets (N x C) with weights (N, or empty for all ones),
  // and its gradients w.r.t. z (d values, the pose first), the SIREN's flat parameters
  // and the head's parameters; each output may be null. outputs (may be null) receives
  // the N x C outputs of the same pass, dL_dY (may be null) the loss's gradient w.r.t.
  // them (N x C), which is the gradient w.r.t. the background at those pixels.
  template <typename Scalar>
  Scalar LossAndGradient(const std::vector<int>& pixels, const VectorX<Scalar>& z,
                         const MatrixX<Scalar>& targets, const VectorX<Scalar>& weights,
                         VectorX<Scalar>* dL_dz, VectorX<Scalar>* dL_dsiren,
                         VectorX<Scalar>* dL_dhead, MatrixX<Scalar>* outputs = nullptr,
                         const Markers* markers = nullptr,
                         MatrixX<Scalar>* dL_dY = nullptr) const;

  // Outputs (N x C, may be null) and the Jacobian of every output w.r.t. z, J: (N*C) x d
  // with row i*C + c holding d y_ic / d z (pixel-major, channels interleaved, as
  // LatentModulatedSiren::ForwardAndLatentJacobian), exact, from 2 + C batched passes of
  // the SIREN over the distinct grid positions the pixels and their neighbours name
  // (one forward, one reverse per SIREN output) instead of 2 d forward passes of central
  // differences. Each position's row is d s / d [t, phi, code]: the code's columns from
  // the shifts, the pose's from the coordinate Jacobian d s / d q through q = R^T (p - t)
  // (d q / d t = -R^T, d q / d phi = G q); a pixel's row then mixes its five positions'
  // rows with the head's derivatives w.r.t. the slope, the depth and s_c. `layout`
  // kOutputColumns gives J transposed, d x (N*C), with the same values. Throws
  // std::invalid_argument as Forward.
  template <typename Scalar>
  void ForwardAndLatentJacobian(const std::vector<int>& pixels, const VectorX<Scalar>& z,
                                MatrixX<Scalar>* outputs, MatrixX<Scalar>* J,
                                const Markers* markers = nullptr,
                                JacobianLayout layout = JacobianLayout::kOutputRows) const;

  // The reverse pass for any dL/dY (N x C): gradients as LossAndGradient's.
  template <typename Scalar>
  void Backward(const std::vector<int>& pixels, const VectorX<Scalar>& z,
                const MatrixX<Scalar>& dL_dY, VectorX<Scalar>* dL_dz,
                VectorX<Scalar>* dL_dsiren, VectorX<Scalar>* dL_dhead,
                const Markers* markers = nullptr) const;

 private:
  struct Pass;  // the forward pass's intermediate values, defined in the .cc
  // What follows a forward pass, and so what it keeps.
  struct PassUse {
    // A reverse pass or a Jacobian follows. If not, the whole grid may share the
    // SIREN's evaluations between neighbours (the .cc says how).
    bool reverse = true;
    // The reverse pass differentiates the head: the flat input's shading is then run
    // and kept for it; otherwise it is read from the whole grid's cache.
    bool head_gradient = true;
    // ForwardAndLatentJacobian: the SIREN's Jacobians at the positions are kept, from
    // the same pass that gives its outputs.
    bool jacobian = false;
  };
  template <typename Scalar>
  void RunForward(const std::vector<int>& pixels, const VectorX<Scalar>& z,
                  Pass* pass, MatrixX<Scalar>* outputs, const PassUse& use,
                  const Markers* markers) const;
  template <typename Scalar>
  void RunBackward(const Pass& pass, const std::vector<int>& pixels,
                   const VectorX<Scalar>& z, const MatrixX<Scalar>& dL_dY,
                   VectorX<Scalar>* dL_dz, VectorX<Scalar>* dL_dsiren,
                   VectorX<Scalar>* dL_dhead) const;
  // The markers of `markers` at working-pixel position (row, col) (fractional) under
  // `sampling`, C values, and their derivatives along rows and columns (C values each;
  // may be null).
  void SampleMarkers(const Markers& markers, MarkerSampling sampling, double row, double col,
                     double* value, double* d_row, double* d_col) const;
  void InitializeHead(std::uint64_t seed);
  struct AtRestShading;  // the .cc's cache of the flat input's shading
  template <typename Scalar>
  const MatrixX<Scalar>& AtRestShadingOf() const;

  Options options_;
  LatentModulatedSiren siren_;
  std::shared_ptr<const Markers> markers_;
  MarkerSampling marker_sampling_ = MarkerSampling::kSensorResolution;
  int num_head_parameters_ = 0;
  Eigen::VectorXd head_;
  Image background_;
  Eigen::MatrixXf lighting_;
  std::shared_ptr<AtRestShading> at_rest_shading_;
};

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_TRUNK_PHOTOMETRIC_TRUNK_H_
