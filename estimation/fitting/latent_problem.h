// Copyright 2026 The tactfunc Authors.
//
// LatentProblem: THE latent posterior of one tactile frame under a frozen trunk f_theta
// (Sec. III-C of "Tactile Functasets"). Every consumer of a frame's latent takes one:
// the Ceres fitter (estimation/fitting/latent_fitter.h) minimises it, the meta-SGD steps
// descend it, SGLD (samplers/sgld.h) samples exp(-U), the Laplace approximation
// (samplers/laplace.h) takes its Gauss-Newton Hessian at the mode, and the pose
// posteriors (estimation/posterior/) build one per frame and hand it to all of them, so
// the fitted mode is by construction the mode of what is sampled.
//
// The problem. For the frame's selected valid pixels j (weight w_j > 0, see Options for
// the selection) with C channels each, the latent prior N(0, sigma_z^2 I) and Gaussian
// pixel noise of standard deviation sigma:
//
//   r_{j,c}(z) = sqrt(w_j) (f_theta(x_j; z)_c - y_{j,c}) / sigma        (whitened residual)
//   U(z)       = 1/2 sum_{j,c} rho(r_{j,c}(z)^2) + 1/2 ||z||^2 / sigma_z^2
//              = -log p(z | y) + const
//
// rho is the identity unless a robust loss is chosen; the prior is never robustified.
// With rho = identity, U = sum_j w_j ||f - y_j||^2 / (2 sigma^2) + ||z||^2 / (2 sigma_z^2):
// the paper's Eq. 5 with a Gaussian likelihood. The robust loss acts per residual through
//
//   r'_i = sign(r_i) sqrt(rho(r_i^2)),   J'_i = d r'_i / d z = rho'(r_i^2) |r_i| / r'_i J_i
//
// (J_i = d r_i / d z, a row of the (N C) x d latent Jacobian; J'_i = J_i where r_i = 0),
// so that U = 1/2 ||r'||^2 + 1/2 ||z / sigma_z||^2 exactly and
//
//   grad U(z) = J'^T r' + z / sigma_z^2       (= J^T (rho'(r^2) (*) r) + z / sigma_z^2)
//   H_GN(z)   = J'^T J' + I / sigma_z^2       (the Gauss-Newton Hessian; J^T J without rho)
//
// Ceres minimises exactly this least-squares form (ResidualsAndJacobian); the samplers see
// U, grad U and H_GN through Evaluate and GaussNewtonHessian.
//
// sigma's one automatic rule (AutomaticSigma): Options::sigma = 0 means the trunk's
// residual_sigma -- the RMS per-pixel residual of its K-step fits on training frames,
// estimated by the trainer (estimation/training/trunk_trainer.h) -- if it is known (> 0),
// else 0.01, the paper's pixel noise sigma (Sec. IV-C) on min-max normalised frames.
//
// Errors: bad Options or targets of the wrong shape, a negative or non-finite weight, or
// a non-finite value in a valid pixel throw std::invalid_argument (quoting the shapes)
// from the constructor; a latent of the wrong size throws from every evaluation.
// Evaluations never throw for numerical trouble: they return false or non-finite values.
//
// Thread safety: every member is const and may be called concurrently.
#ifndef TACTFUNC_ESTIMATION_FITTING_LATENT_PROBLEM_H_
#define TACTFUNC_ESTIMATION_FITTING_LATENT_PROBLEM_H_

#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "estimation/data/trunk_targets.h"
#include "models/trunk/functa_model.h"

namespace ceres {
class LossFunction;
}  // namespace ceres

namespace tactfunc {

// The trunk at z = 0 over every pixel of a rows x cols frame: its outputs and latent
// Jacobian, which do not depend on the frame's values. A fit that starts at z = 0 (the
// StartLatent of a trunk without readout branch or spatial latents) takes its first
// residuals, Jacobian and cost from it instead of a trunk pass (LatentFitter keeps one per
// frame size). Float, the default precision: problems in double evaluate as before.
struct StartPass {
  // True if `trunk` starts every fit at z = 0 and gives its Jacobian in output columns.
  static bool Applies(const SensorTrunk& trunk);
  // One ForwardAndLatentJacobian over the frame's grid (the coordinates LatentProblem
  // uses). Throws std::invalid_argument unless Applies(trunk) and rows, cols >= 1.
  StartPass(const SensorTrunk& trunk, int rows, int cols);

  const SensorTrunk* trunk;  // what it was computed for (not owned)
  int rows = 0, cols = 0;
  Eigen::MatrixXf outputs;   // rows*cols x C
  Eigen::MatrixXf jacobian;  // d x rows*cols*C: column j*C + c = d y_{j,c} / d z at z = 0
};

class LatentProblem {
 public:
  enum class RobustLoss { kNone, kHuber, kCauchy };
  enum class Precision { kFloat, kDouble };

  struct Options {
    // Pixel noise standard deviation sigma, normalised target units (TrunkTargets). > 0,
    // or 0 = automatic (AutomaticSigma). It weighs the data against the prior; with no
    // prior (sigma_z huge) it does not move the mode, only the posterior's width.
    double sigma = 0;
    // Prior standard deviation of each latent entry, latent units. > 0. 1.0: trained
    // latents are O(1) per entry (the modulation matrix A is initialised so that a unit
    // change of one z_k moves the phases by O(1) rad), so N(0, I) is weakly informative:
    // against thousands of pixel residuals at sigma = 0.01 it only decides directions the
    // pixels leave unconstrained (blank or masked frames), and keeps H_GN positive definite.
    double sigma_z = 1.0;
    // Per-residual robust loss rho and its scale a, in units of sigma (Huber: quadratic
    // below a, linear above; Cauchy: a^2 log(1 + s / a^2)). > 0. 1.345 is Huber's
    // 95%-efficiency constant for Gaussian noise (Cauchy's is 2.385).
    RobustLoss robust_loss = RobustLoss::kNone;
    double robust_loss_scale = 1.345;
    // Pixel selection: every pixel_stride-th valid pixel (>= 1), then at most max_pixels
    // of them, evenly spaced (>= 0; 0 = no limit), in pixel order (deterministic). U is
    // over the selected pixels; Psnr over all valid ones.
    int pixel_stride = 1;
    int max_pixels = 0;
    // How max_pixels thins, in [0, 1]. 0: evenly spaced, as above. a > 0: importance
    // sampling towards the contact: pixel j (of the N left after the stride) is drawn with
    // probability p_j = (1 - a) / N + a e_j / sum(e), e_j = w_j * sum_c target_jc^2 (the
    // frame's difference energy; p uniform if every e_j is 0), by systematic sampling over
    // the pixel order (deterministic; a pixel drawn c_j times is kept once), and its weight
    // becomes w_j c_j / (N p_j): the weighted sum over the kept pixels estimates the sum
    // over all N times m / N without bias, as even thinning does, so costs and mean squared
    // residuals keep their scale while a small contact gets a share of the pixels.
    double contact_share = 0;
    // Precision of the trunk passes (Ceres always accumulates in double). float is about
    // 2x faster; latents agree with double within 1e-4 relative (latent_fitter_test), U
    // and its gradient carry ~1e-6 relative rounding, far below SGLD's injected noise.
    Precision precision = Precision::kFloat;

    // True if every field is valid; otherwise false and *error names the field.
    bool IsValid(std::string* error) const;
  };

  // The automatic pixel sigma of the header comment: trunk.residual_sigma if > 0, else 0.01.
  static double AutomaticSigma(const SensorTrunk& trunk);

  // `trunk` and `targets` must outlive the problem (targets: rows*cols x C values for the
  // trunk's C, rows*cols weights; any resolution, the trunk is continuous). Throws
  // std::invalid_argument as the header comment says. Also throws if trunk.alpha does not
  // have latent_dim entries (the meta-SGD steps need it).
  LatentProblem(const SensorTrunk& trunk, const TrunkTargets& targets, const Options& options);

  const SensorTrunk& trunk() const { return *trunk_; }
  const TrunkTargets& targets() const { return *frame_; }
  const Options& options() const { return options_; }
  int dim() const;       // d, the latent size
  int channels() const;  // C
  double sigma() const { return sigma_; }  // after the automatic choice
  double sigma_z() const { return options_.sigma_z; }
  int num_valid_pixels() const { return num_valid_pixels_; }  // in the whole frame
  int num_pixels() const { return static_cast<int>(coords_.rows()); }  // selected, N
  int num_residuals() const { return num_pixels() * channels(); }     // data residuals, N C

  // The selected pixels: trunk coordinates N x 2, targets N x C, weights N.
  const Eigen::MatrixXd& coords() const { return coords_; }
  const Eigen::MatrixXd& pixel_targets() const { return pixel_targets_; }
  const Eigen::VectorXd& pixel_weights() const { return weights_; }
  // Each selected pixel's index in the frame (row of targets), increasing.
  const std::vector<int>& pixel_index() const { return pixel_index_; }

  // The (robustified) whitened data residuals r' at z (num_residuals(), residual j*C + c)
  // and, if jacobian is not null, d r' / d z row-major (num_residuals() x d), as Ceres
  // wants them: one batched trunk pass and one reverse pass per channel. z has d entries.
  // Returns false if a residual or Jacobian entry is not finite.
  bool ResidualsAndJacobian(const double* z, double* residuals, double* jacobian) const;
  // The same, and the trunk's outputs over the selected pixels (N x C) from the same pass
  // when outputs is not null (DataCostOfOutputs takes them).
  bool ResidualsAndJacobian(const double* z, double* residuals, double* jacobian,
                            Eigen::MatrixXd* outputs) const;
  // The residuals and their Jacobian along the k columns of `directions` (d x k):
  // jacobian, row-major num_residuals() x k, receives (d r' / d z) directions, taken
  // through the trunk's reverse passes times A D (LatentModulatedSiren::
  // ForwardAndLatentJacobian), so it costs far less than the whole Jacobian when k is
  // small (a pose generator's 4 pose coordinates). Equal to ResidualsAndJacobian's
  // Jacobian times `directions` up to rounding. Returns false as ResidualsAndJacobian.
  bool ResidualsAndJacobianAlong(const double* z, const Eigen::MatrixXd& directions,
                                 double* residuals, double* jacobian) const;
  // True if `pass` was computed for this problem's trunk and frame size and the problem
  // evaluates in float: then the two calls below equal ResidualsAndJacobian(0, ...) and
  // DataCost(0, psnr) up to rounding, without a trunk pass.
  bool CanUse(const StartPass& pass) const;
  bool ResidualsAndJacobianAtStart(const StartPass& pass, double* residuals,
                                   double* jacobian) const;
  double DataCostAtStart(const StartPass& pass, std::optional<double>* psnr) const;
  // The robust transform of the header comment applied in place to whitened residuals
  // (and, if not null, their row-major Jacobian rows of `cols` entries). No-op without a
  // robust loss. Public for the autodiff reference cost, which must robustify the same way.
  void Robustify(int num_residuals, double* residuals, double* jacobian, int cols) const;

  // U(z) and, if gradient is not null, grad U(z) (size d).
  double Evaluate(const Eigen::VectorXd& z, Eigen::VectorXd* gradient = nullptr) const;
  // The unbiased minibatch estimate over the selected pixels `rows` (distinct, in
  // [0, num_pixels())): (N / n) times their data terms, plus the exact prior. Empty rows:
  // Evaluate. Throws std::invalid_argument for a row out of range.
  double EvaluateMinibatch(const Eigen::VectorXd& z, const std::vector<int>& rows,
                           Eigen::VectorXd* gradient) const;
  // H_GN(z), d x d symmetric positive definite.
  void GaussNewtonHessian(const Eigen::VectorXd& z, Eigen::MatrixXd* hessian) const;
  // Every selected pixel's data term at z from one Jacobian pass: values (size N), u_j =
  // ||r'_j||^2 / 2 over its channels, and gradients (N x d), row j = J'_j^T r'_j, so
  // that U = sum_j u_j + prior and grad U = sum_j row j + z / sigma_z^2; and, if hessian
  // is not null, H_GN(z) from the same Jacobian. (SGLD's control variate, samplers/sgld.h.)
  void DataTerms(const Eigen::VectorXd& z, Eigen::VectorXd* values, Eigen::MatrixXd* gradients,
                 Eigen::MatrixXd* hessian) const;

  // `steps` steps of the trunk's meta-SGD inner loop (MetaSgd::InnerLoop: the trunk's
  // weighted MSE over the selected pixels plus its latent_l2_weight, rates trunk.alpha)
  // from z0. They descend the loss the trunk was meta-trained on, not U: sigma, sigma_z
  // and the robust loss do not enter. If start_cost is not null it receives DataCost(z0)
  // and *start_psnr (not null then) its PSNR as DataCost gives it, both from the first
  // step's own forward pass (no extra pass).
  // With `start` (CanUse(*start)) and z0 = 0, the first step's outputs and gradient come
  // from the pass at z = 0 (the gradient is J_0 times the weighted residuals, one
  // matrix-vector product) instead of a trunk pass; the other steps run as usual.
  Eigen::VectorXd MetaSgdSteps(const Eigen::VectorXd& z0, int steps, double* start_cost = nullptr,
                               std::optional<double>* start_psnr = nullptr,
                               const StartPass* start = nullptr) const;

  // Where every fit of this frame starts without a warm start: the trunk's StartLatent
  // over the selected pixels (z = 0, or the readout branch's projection;
  // models/trunk/latent_modulated_siren.h).
  Eigen::VectorXd StartLatent() const;

  // PSNR (estimation/data/trunk_targets.h, THE definition) of f_theta(.; z) over all valid
  // pixels of the frame, in the problem's precision. +inf for an exact fit; 0 when the
  // frame has no valid pixel.
  double Psnr(const Eigen::VectorXd& z) const;
  // Half the squared norm of the (robustified) whitened data residuals at z -- the data
  // part of U as Ceres sees it, ResidualsAndJacobian's residuals -- from one forward
  // pass over the selected pixels. When they are every valid pixel of the frame (no
  // pixel_stride or max_pixels thinning) the same pass also gives *psnr = Psnr(z) (the
  // PSNR reads valid pixels only); otherwise *psnr is reset (Psnr needs its own pass
  // over the valid pixels). psnr must not be null.
  double DataCost(const Eigen::VectorXd& z, std::optional<double>* psnr) const;
  // DataCost (and *psnr as DataCost gives it) from the trunk's outputs over the selected
  // pixels at z (N x C), e.g. those a Jacobian evaluation at z returned: no pass.
  double DataCostOfOutputs(const Eigen::MatrixXd& outputs, std::optional<double>* psnr) const;

 private:
  // ResidualsAndJacobian (directions null) and ResidualsAndJacobianAlong: one trunk pass.
  bool ResidualPass(const double* z, double* residuals, double* jacobian,
                    Eigen::MatrixXd* outputs, const Eigen::MatrixXd* directions) const;
  // U over the selected pixels (rows == nullptr) or the minibatch `rows` (scaled by N / n).
  double EvaluateRows(const Eigen::VectorXd& z, const std::vector<int>* rows,
                      Eigen::VectorXd* gradient) const;
  Eigen::MatrixXf FramePrediction(const Eigen::VectorXd& z) const;
  template <typename Scalar>
  double DataTermAndGradient(const Eigen::VectorXd& z, const std::vector<int>* rows,
                             double scale, Eigen::VectorXd* gradient) const;
  void CheckLatent(const Eigen::VectorXd& z, const char* where) const;

  const SensorTrunk* trunk_;
  const TrunkTargets* frame_;
  Options options_;
  double sigma_ = 0.01;
  int num_valid_pixels_ = 0;
  std::vector<int> pixel_index_;  // N: each selected pixel's row in the frame (targets)
  Eigen::MatrixXd coords_;
  Eigen::MatrixXd pixel_targets_;
  Eigen::VectorXd weights_;
  Eigen::MatrixXf coords_float_;
  Eigen::MatrixXf targets_float_;
  Eigen::VectorXf weights_float_;
  Eigen::VectorXd residual_scale_;  // N C: sqrt(w_j) / sigma for every channel of pixel j
  // rho of Options::robust_loss (null without one), made once; Evaluate is const.
  std::shared_ptr<const ceres::LossFunction> loss_;
};

const char* ToString(LatentProblem::RobustLoss loss);       // "none", "huber", "cauchy"
const char* ToString(LatentProblem::Precision precision);   // "float", "double"

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_FITTING_LATENT_PROBLEM_H_
