// Copyright 2026 The tactfunc Authors.
//
// PoseDistribution: a pose posterior given by weighted samples of SE(2) -- what the
// posterior samplers (SGLD over latents pushed through the pose MLP, k-NN neighbours'
// poses) produce, and what state estimators consume: a particle filter takes the
// samples, an EKF takes Mean() and Covariance(), a data-association gate takes
// Contains(), a multi-hypothesis tracker takes Modes().
//
// Conventions (models/core/se2.h; docs/POSES.md has the long form):
//   * Every sample is a pose sensor_T_object (object frame -> sensor frame), x and y
//     in metres, yaw in rad.
//   * Tangent vectors are ordered (x, y, yaw) and perturb on the RIGHT: a sample is
//     written  x_i = mean * Exp(r_i),  r_i = Log(mean^-1 x_i)  (the body frame of the
//     mean).
//   * Covariance() is the 3x3 covariance of r in the tangent space AT THE MEAN, rows
//     and columns (x, y, yaw): the same order in which ROS's PoseWithCovariance lays
//     out a planar pose in its 6x6 row-major matrix over (x, y, z, roll, pitch, yaw):
//     our row/col 0, 1, 2 go to ROS row/col 0, 1, 5, i.e. ros[6*i + j] for
//     i, j in {0, 1, 5}. ToRosPoseCovariance() does it (and the frame change ROS'
//     consumers expect; see there).
//
// The mean (Mean()). The exponential barycentre: the pose m with
//   sum_i w_i Log(m^-1 x_i) = 0,
// found by Gauss-Newton on the manifold with right perturbations: residuals
// r_i(m) = Log(m^-1 x_i), step delta = sum_i w_i r_i, update m <- m * Exp(delta). This
// is the Gauss-Newton step with the residual Jacobian -Jl^-1(r_i) taken at r_i = 0
// (= -I). We keep that approximation on purpose: its fixed point is exactly the mean of
// the concentrated Gaussian  x = m * Exp(e), E[e] = 0, that Covariance() describes,
// whereas the exact Gauss-Newton minimiser of sum w |Log(m^-1 x_i)|^2 is biased for
// that model (SE(2) has no bi-invariant metric). It converges linearly at a rate of
// order (spread)^2, typically in 3-6 iterations; the initial guess is the weighted
// circular mean of yaw and the weighted mean of the translations. It is only
// meaningful for a unimodal set with a yaw spread well below pi: for multimodal
// posteriors use Modes(), for symmetric tools FoldedBySymmetry() first.
//
// Credible regions (CredibleRegion(), Contains()). The p-credible region is a set of
// poses of posterior probability p, defined through the squared Mahalanobis distance
// in the tangent space at the mean,
//   d^2(T) = Log(mean^-1 T)^T Sigma^-1 Log(mean^-1 T),
// as  { T : d^2(T) <= threshold(p) }, with two choices of threshold:
//   kSampleQuantile (default): the weighted p-quantile of the samples' own d^2(x_i)
//     (the smallest d^2(x_k) whose cumulative weight, in order of increasing d^2,
//     reaches p). It keeps the elliptical shape but takes its size from the samples,
//     so it stays calibrated when the posterior is heavier- or lighter-tailed than a
//     Gaussian (only the nesting of the regions is assumed, not the tail).
//   kGaussian: the chi-square quantile with rank(Sigma) (= 3) degrees of freedom --
//     exact for a Gaussian posterior, the textbook gate of an EKF.
// Neither is a true highest-density region of a multimodal posterior: apply it per mode
// (PoseMode). A zero-variance direction (eigenvalue of Sigma below 1e-20, i.e. a
// standard deviation below 1e-10 m or rad) admits displacements of at most 1e-10 along
// it (else d^2 = infinity); so for identical samples the region is that one pose.
//
// Modes (Modes()). Mean shift (Comaniciu & Meer 2002) with a Gaussian kernel on the
// features (x / h_t, y / h_t, cos(yaw) / h_yaw, sin(yaw) / h_yaw) -- yaw on the unit
// circle, so +pi and -pi are one place, and h_yaw acts as an angle for small
// differences (the chord 2 sin(dyaw/2) ~ dyaw). Every sample (or an evenly spaced
// subset of max_seeds of them) climbs the weighted kernel density estimate to a local
// maximum; maxima closer than merge_distance (in bandwidths) are one mode; every
// sample joins the mode its own climb reached (or, when not a seed, the nearest mode);
// modes lighter than min_mode_weight give their samples to the nearest heavier mode.
// Each mode reports its weight (sum of its samples' weights), mean and covariance as
// above. So a rod (C_2) pressed at yaw 0.3 yields two modes, at 0.3 and 0.3 - pi,
// rather than a meaningless mean between them.
//
// Symmetric tools (FoldYaw(), FoldedBySymmetry()). A tool with C_n symmetry
// (models/simulator/tool.h, Tool::symmetry_order()) looks the same at yaw and yaw + 2 pi k / n:
// its pose is only defined modulo 2 pi / n, so sample yaws should be folded onto one
// representative before the mean, covariance or regions make sense, and errors should
// be scored with YawErrorModuloSymmetry (models/simulator/tool.h). The symmetry axis is the
// object frame's origin (as for every tool in ToolSet()), so folding changes the yaw
// only. n = 1: nothing to fold; n = 0 (hemisphere): yaw is unobservable and is set to
// 0, so the yaw row and column of the covariance are 0 and mean nothing.
//
// Errors (the three tiers of docs/ARCHITECTURE.md): bad options are reported by
// IsValid() and thrown as std::invalid_argument by the functions taking them; bad
// inputs (no samples, NaN or infinite samples or weights, negative weights, all weights
// zero, a p outside (0, 1]) throw std::invalid_argument saying what was expected and
// found; a Mean() that does not converge is reported in its MeanSummary, never thrown.
#ifndef TACTFUNC_ESTIMATION_POSE_POSE_DISTRIBUTION_H_
#define TACTFUNC_ESTIMATION_POSE_POSE_DISTRIBUTION_H_

#include <array>
#include <string>
#include <utility>
#include <vector>

#include "Eigen/Core"
#include "models/core/se2.h"

namespace tactfunc {

// One mode of a PoseDistribution (see Modes()).
struct PoseMode {
  double weight = 0;                                     // posterior mass, in (0, 1]
  SE2d mean;                                             // sensor_T_object
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // tangent at mean, (x, y, yaw)
  int num_samples = 0;                                   // samples assigned to the mode
};

struct PoseMeanOptions {
  // Gauss-Newton iterations at most. >= 1. The iteration is linear with rate
  // ~ spread^2, so 100 is ample for any spread where a mean makes sense.
  int max_iterations = 100;
  // Converged when the last step moved the translation by at most this (metres,
  // >= 0) and the yaw by at most angle_tolerance (rad, >= 0). 1e-10 is about 1e6
  // times the rounding error of poses of metre size.
  double translation_tolerance = 1e-10;
  double angle_tolerance = 1e-10;
  bool IsValid(std::string* error) const;
};

enum class PoseMeanTermination {
  kConverged,      // the last step was within both tolerances
  kNoConvergence,  // max_iterations reached: the result is the last iterate
};

struct PoseMeanSummary {
  PoseMeanTermination termination = PoseMeanTermination::kNoConvergence;
  std::string message;
  int iterations = 0;                 // Gauss-Newton steps taken
  double final_step_translation = 0;  // |delta_xy| of the last step, metres
  double final_step_angle = 0;        // |delta_yaw| of the last step, rad
  SE2d initial;                       // the initial guess
  bool converged() const { return termination == PoseMeanTermination::kConverged; }
  // One line: "Mean: CONVERGED in 4 iterations (last step 1e-14 m, 2e-15 rad)".
  std::string BriefReport() const;
};

enum class CredibleRegionMethod {
  kSampleQuantile,  // threshold = weighted p-quantile of the samples' own d^2
  kGaussian,        // threshold = chi-square(rank) p-quantile
};

struct CredibleRegionOptions {
  CredibleRegionMethod method = CredibleRegionMethod::kSampleQuantile;
  PoseMeanOptions mean;  // for the mean the region is centred on
  bool IsValid(std::string* error) const;
};

// A p-credible region: { T : SquaredMahalanobis(T) <= threshold } (PoseDistribution::Region()).
class PoseCredibleRegion {
 public:
  PoseCredibleRegion(const SE2d& mean, const Eigen::Matrix3d& covariance, double p,
                     CredibleRegionMethod method, double threshold);
  // d^2(T) at the mean, with the degenerate-direction rule of the header comment.
  double SquaredMahalanobis(const SE2d& pose) const;
  bool Contains(const SE2d& pose) const { return SquaredMahalanobis(pose) <= threshold_; }
  const SE2d& mean() const { return mean_; }
  const Eigen::Matrix3d& covariance() const { return covariance_; }
  double probability() const { return p_; }
  CredibleRegionMethod method() const { return method_; }
  double threshold() const { return threshold_; }
  // Rank of the covariance (directions with variance above 1e-20).
  int rank() const { return rank_; }

 private:
  friend class PoseDistribution;
  SE2d mean_;
  SE2d mean_inverse_;
  Eigen::Matrix3d covariance_;
  double p_;
  CredibleRegionMethod method_;
  double threshold_;
  Eigen::Matrix3d eigenvectors_;         // columns, of the covariance
  Eigen::Vector3d inverse_eigenvalues_;  // 0 for zero-variance directions
  int rank_ = 0;
};

struct PoseModeOptions {
  // Kernel bandwidth in translation, metres, > 0. 2 mm: a guess at the per-mode
  // posterior spread of in-hand poses from Touch2Touch-sized tools; set it near the
  // spread you expect within one mode.
  double translation_bandwidth = 2e-3;
  // Kernel bandwidth in yaw, rad, in (0, pi]. 0.2 rad (11 deg), likewise a guess.
  double yaw_bandwidth = 0.2;
  // Mean-shift iterations per seed at most (>= 1) and the step (in bandwidths, > 0)
  // below which a climb has converged.
  int max_iterations = 300;
  double tolerance = 1e-6;
  // Maxima closer than this (in bandwidths, > 0) are one mode.
  double merge_distance = 0.5;
  // Modes lighter than this ([0, 1)) are merged into the nearest heavier one.
  double min_mode_weight = 0.01;
  // At most this many samples (>= 1) climb; the others join the nearest mode. Mean
  // shift costs O(seeds * samples) per iteration.
  int max_seeds = 2000;
  bool IsValid(std::string* error) const;
};

class PoseDistribution {
 public:
  using MeanOptions = PoseMeanOptions;
  using MeanSummary = PoseMeanSummary;
  using MeanTermination = PoseMeanTermination;
  using RegionMethod = CredibleRegionMethod;
  using RegionOptions = CredibleRegionOptions;
  using CredibleRegion = PoseCredibleRegion;
  using ModeOptions = PoseModeOptions;

  // samples: sensor_T_object poses. weights: one per sample, finite, >= 0, not all
  // zero; empty means equal weights. They are normalised to sum to 1. Throws
  // std::invalid_argument for no samples, a non-finite sample (naming its index and
  // components), a weights size other than 0 or samples.size(), or a bad weight.
  explicit PoseDistribution(std::vector<SE2d> samples, std::vector<double> weights = {});

  int size() const { return static_cast<int>(samples_.size()); }
  const std::vector<SE2d>& samples() const { return samples_; }
  // Normalised weights (sum 1).
  const std::vector<double>& weights() const { return weights_; }
  // Kish's effective sample size 1 / sum w_i^2, in [1, size()].
  double EffectiveSampleSize() const;

  // The exponential barycentre (header comment). Throws std::invalid_argument if
  // !options.IsValid(); non-convergence is reported in *summary (may be null).
  SE2d Mean(const MeanOptions& options = MeanOptions(), MeanSummary* summary = nullptr) const;

  // Weighted covariance of r_i = Log(mean^-1 x_i), 3x3 (x, y, yaw), in the tangent
  // space at `reference_T_mean`, with the unbiased correction for reliability weights
  //   Sigma = sum_i w_i r_i r_i^T / (1 - sum_i w_i^2)
  // (the usual N / (N - 1) for equal weights). When one sample holds all the weight
  // (sum w^2 = 1) the distribution is a point mass and Sigma = 0.
  Eigen::Matrix3d CovarianceAbout(const SE2d& reference_T_mean) const;
  // CovarianceAbout(Mean(options)).
  Eigen::Matrix3d Covariance(const MeanOptions& options = MeanOptions()) const;

  // The p-credible region (header comment). p in (0, 1]; throws std::invalid_argument
  // otherwise or for bad options.
  CredibleRegion Region(double p, const RegionOptions& options = RegionOptions()) const;
  // Region(p, options).Contains(pose). Build the region once to test many poses.
  bool Contains(const SE2d& pose, double p, const RegionOptions& options = RegionOptions()) const;

  // Modes by mean shift (header comment), heaviest first; weights sum to 1. Throws
  // std::invalid_argument for bad options.
  std::vector<PoseMode> Modes(const ModeOptions& options = ModeOptions()) const;

  // The same samples and weights with every yaw replaced by its representative modulo
  // 2 pi / n closest to the circular mean of n * yaw divided by n (so a cloud that
  // straddles a fold boundary stays together). n = 1: unchanged; n = 0: yaw set to 0.
  // Throws std::invalid_argument for n < 0.
  PoseDistribution FoldedBySymmetry(int symmetry_order) const;

 private:
  std::vector<SE2d> samples_;
  std::vector<double> weights_;
};

const char* ToString(PoseMeanTermination termination);
const char* ToString(CredibleRegionMethod method);

// `yaw` folded into [-pi/n, pi/n) modulo 2 pi / n for a tool with C_n symmetry
// (n >= 1; n = 1 gives [-pi, pi)); 0 for n = 0 (yaw unobservable). Throws
// std::invalid_argument for n < 0.
double FoldYaw(double yaw, int symmetry_order);

// In which frame ToRosPoseCovariance expresses the (x, y) perturbation.
enum class RosCovarianceFrame {
  // The message's header frame (the parent, "sensor" of sensor_T_object): the
  // (x, y) block rotated by the mean's yaw, Sigma_ros = J Sigma J^T with
  // J = diag(R(yaw), 1) -- first order, since T * Exp(d) moves the position by
  // R(yaw) d_xy + O(|d|^2) and the yaw by d_yaw. What AMCL publishes and
  // robot_localization reads for poses.
  kParent,
  // Copied unchanged: right (body-frame) perturbations, our own convention.
  kBody,
};

// A 3x3 (x, y, yaw) covariance at the mean of reference_T_mean as ROS's 6x6 row-major
// PoseWithCovariance::covariance over (x, y, z, roll, pitch, yaw): our rows/columns
// 0, 1, 2 go to ROS's 0, 1, 5; the diagonal entries of z, roll and pitch (indices 14,
// 21, 28) are `unobserved_variance` (0: the planar constraint holds exactly; use a
// large value if your consumer expects "unknown"); every other entry is 0.
std::array<double, 36> ToRosPoseCovariance(const SE2d& reference_T_mean,
                                           const Eigen::Matrix3d& covariance,
                                           RosCovarianceFrame frame = RosCovarianceFrame::kParent,
                                           double unobserved_variance = 0);

// Calibration checks. The central 99% interval [lo, hi] of Binomial(n, p) / n (each
// tail holds at most 0.5%): the coverage of n independent truths by nominal p-credible
// regions falls outside it with probability <= 1% if the regions are calibrated. The
// tolerance of every coverage check in tactfunc follows from n this way and is never
// widened by hand. n <= 0 gives [0, 1].
std::pair<double, double> BinomialInterval99(int n, double p);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_POSE_POSE_DISTRIBUTION_H_
