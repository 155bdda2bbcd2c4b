// Copyright 2026 The tactfunc Authors.
//
// SE2ParticleFilter: tracks the in-hand pose sensor_T_object of a tool over a sequence
// of tactile frames, taking ONE PoseDistribution per frame (what estimation/posterior/pose_posterior.h
// produces) as its measurement. docs/FILTERING.md has the long form and a worked run
// (examples/track_slipping_tool.cc).
//
// State. N weighted particles x_i in SE(2) (models/core/se2.h; sensor_T_object, metres and
// rad), with log-weights l_i (normalised by log-sum-exp after every change, so no weight
// underflows to 0 / 0), and optionally a body-frame velocity v_i in R^3 per particle.
//
// Predict (motion model: a slip of the tool in the grasp). A body-frame random walk,
//   x_i <- x_i * Exp(v_i * dt + w_i),   w_i ~ N(0, dt * Q)     (Q = process_covariance)
// with v_i = 0 unless constant_velocity is set, in which case the velocity itself walks,
//   v_i <- v_i + u_i,   u_i ~ N(0, dt * Q_v)                  (Q_v = velocity_process_covariance)
// (applied before the pose step). dt is in frames (Predict(1) = one frame). Right (body)
// perturbations, as every covariance in tactfunc: Q is the covariance of the tangent
// increment (x m, y m, yaw rad) in the particle's own frame.
//
// Update (measurement model: a kernel density over the measurement's samples). A
// PoseDistribution {s_j, w_j} (j = 1..M) is a posterior over the frame's pose; under the
// flat prior its sampler assumes it is proportional to the frame's likelihood, so its
// kernel density estimate IS the likelihood of a particle:
//   p(z | x_i) = sum_j w_j N(r_ij; 0, K),   r_ij = Log(s_j^-1 * x_i)
// (the residual in the tangent space at the sample, right perturbations), with one kernel
// covariance per measurement
//   K = h^2 * Sigma_z + K_floor.
// Sigma_z is the measurement's covariance: by default the WITHIN-MODE covariance
// sum_k W_k Sigma_k over its modes (PoseDistribution::Modes()), so a multimodal posterior
// -- the two half-turn modes a rod-like face produces when the tool is treated as
// asymmetric -- keeps narrow kernels on each mode and is used as it is, not replaced by a
// mean between its modes; a unimodal one gives its plain Covariance(). h is the bandwidth
// factor: Silverman's rule (4 / ((d + 2) * ESS))^(1 / (d + 4)) by default (d = 3, or 2 for
// a tool with continuous symmetry; ESS = the measurement's Kish effective sample size),
// about 0.5 for 100 equal-weight samples. K_floor (floor_covariance) keeps K positive
// definite when the samples collapse (a k-NN posterior with one neighbour holding all the
// weight has Sigma_z = 0): no measurement can make the kernel a delta function that every
// particle misses. For M samples drawn around the frame's estimate with covariance R, the
// kernel density is approximately N(x; estimate, (1 + h^2) R + K_floor): a Kalman-like
// update with a slightly inflated measurement noise (docs/FILTERING.md).
// Weights: l_i <- l_i + log p(z | x_i) (log-sum-exp over j with the largest term factored
// out, so even a particle a thousand kernel widths away gets a finite log-likelihood).
//
// Gate (an incompatible measurement). If every particle lies farther than
// gate_squared_mahalanobis (in K's metric) from every sample, the measurement is REJECTED:
// its likelihood is numerically zero everywhere the filter believes the tool may be, and
// normalising it would hand all the mass to whichever particle happens to be least far.
// The prior weights are kept and the rejection is counted (UpdateSummary, Summary).
// After max_consecutive_rejections rejections in a row the filter trusts the data over
// itself: the next incompatible measurement re-initialises it (kReinitialized).
//
// Resampling. Systematic (Kitagawa 1996; one uniform draw, N evenly spaced pointers; each
// particle i is copied floor(N w_i) or ceil(N w_i) times) whenever Kish's effective sample
// size 1 / sum_i w_i^2 falls below resample_threshold * N.
//
// Symmetric tools. A tool with C_n symmetry (models/simulator/tool.h, Tool::symmetry_order()) looks
// the same at yaw and yaw + 2 pi k / n, so its measured poses are defined modulo 2 pi / n:
// with Options::symmetry_order = n, each residual r_ij uses the representative of x_i
// (x_i * Rot(2 pi k / n), the symmetry axis being the object frame's origin as for every
// tool in ToolSet()) whose yaw is closest to s_j's, and the measurement is folded
// (PoseDistribution::FoldedBySymmetry) before its covariance is taken. n = 0 (continuous
// symmetry, yaw unobservable): the yaw residual is dropped and the kernel is 2-D (x, y);
// the particles' yaw is then only driven by the process noise and means nothing.
//
// Estimate. CurrentEstimate() = the weighted particle set as a PoseDistribution
// (Posterior(), folded by the symmetry order) and its Mean() (the exponential barycentre)
// and Covariance() (3x3 tangent covariance at the mean, (x, y, yaw), right perturbations):
// the same conventions as a per-frame posterior, so the filter's output can be consumed
// like its input. For a multimodal particle set use Posterior().Modes(), not the mean.
//
// Randomness. One std::mt19937_64 seeded with DeriveSeed(Options::seed, 0) (models/core/seed.h)
// driving Boost.Random's distributions (whose output, unlike <random>'s, is the same on
// every platform); results are a deterministic function of the seed and the sequence of
// calls.
//
// Errors (the three tiers of docs/ARCHITECTURE.md): bad options are reported by
// Options::IsValid() and thrown as std::invalid_argument by the constructor; bad inputs
// (a measurement with no samples, e.g. a moved-from PoseDistribution; a non-finite or
// non-positive-definite initial covariance; a non-finite or negative dt) throw
// std::invalid_argument saying what was expected and found; an incompatible measurement
// is an outcome (kRejected), never thrown.
//
// Thread safety: none; one filter per thread (the const members may run concurrently).
#ifndef TACTFUNC_ESTIMATION_POSE_POSE_FILTER_H_
#define TACTFUNC_ESTIMATION_POSE_POSE_FILTER_H_

#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "estimation/pose/pose_distribution.h"
#include "models/core/se2.h"

namespace tactfunc {

// What one SE2ParticleFilter::Update() did.
enum class PoseFilterUpdateType {
  kInitialized,    // the filter had no particles: drawn from the measurement's kernel density
  kUpdated,        // weights multiplied by the measurement's likelihood
  kRejected,       // no particle within the gate of any sample: prior weights kept
  kReinitialized,  // incompatible after max_consecutive_rejections rejections in a row:
                   // particles redrawn from this measurement
};
// "INITIALIZED", "UPDATED", "REJECTED", "REINITIALIZED".
const char* ToString(PoseFilterUpdateType type);

// Where the measurement's covariance Sigma_z in the kernel K = h^2 Sigma_z + K_floor comes from.
enum class PoseFilterKernelCovariance {
  // sum_k W_k Sigma_k over the measurement's modes (PoseDistribution::Modes() with
  // Options::modes): the spread within each mode, so separate modes stay separate.
  kWithinModes,
  // The measurement's Covariance() about its Mean(): right for unimodal measurements only
  // (a two-mode posterior gets one kernel as wide as the gap between its modes).
  kWhole,
};
// "within_modes", "whole".
const char* ToString(PoseFilterKernelCovariance source);

class SE2ParticleFilter {
 public:
  struct Options {
    // Particles, >= 1. 1000: enough that the Monte Carlo error of the mean (~ the
    // posterior's spread / sqrt(ESS), ESS >= resample_threshold * N) is a few percent of
    // the spread; the update costs O(N * M) residuals for M measurement samples.
    int num_particles = 1000;
    // Seed of the filter's random stream (DeriveSeed(seed, 0), mt19937_64).
    std::uint64_t seed = 0;
    // Rotational symmetry order n of the tool (models/simulator/tool.h): yaw is compared modulo
    // 2 pi / n. >= 0; 1 = asymmetric (nothing folded); 0 = continuous (yaw ignored).
    int symmetry_order = 1;

    // Per-frame covariance Q of the body-frame tangent increment (x m, y m, yaw rad) of
    // the random walk; symmetric positive semi-definite. Default: standard deviations of
    // 0.2 mm and 1 deg per frame, about the per-frame motion of a slow slip (a few mm and
    // ~20 deg over ~30 frames: 0.1-0.2 mm and ~0.7 deg per frame). Larger follows faster
    // slips; smaller averages more frames.
    Eigen::Matrix3d process_covariance =
        Eigen::Vector3d(0.2e-3 * 0.2e-3, 0.2e-3 * 0.2e-3,
                        0.017453292519943295 * 0.017453292519943295)
            .asDiagonal();
    // Constant-velocity term: each particle carries a body-frame velocity v (tangent per
    // frame) added to every step, itself a random walk with per-frame covariance
    // velocity_process_covariance (PSD), and drawn at initialisation from
    // N(0, initial_velocity_covariance) (PSD). Off by default: the plain random walk
    // assumes nothing about how long a slip persists. On, a steady slip is followed
    // without the random walk's lag of (1 - K) v / K per frame (K the steady-state gain;
    // see the constant-velocity test in tests/estimation/pose/pose_filter_test.cc).
    bool constant_velocity = false;
    // Default: 0.02 mm and 0.1 deg per frame per frame (a tenth of the random walk's).
    Eigen::Matrix3d velocity_process_covariance =
        Eigen::Vector3d(0.02e-3 * 0.02e-3, 0.02e-3 * 0.02e-3,
                        0.0017453292519943295 * 0.0017453292519943295)
            .asDiagonal();
    // Default: 0.2 mm and 1 deg per frame, the same scale as process_covariance.
    Eigen::Matrix3d initial_velocity_covariance =
        Eigen::Vector3d(0.2e-3 * 0.2e-3, 0.2e-3 * 0.2e-3,
                        0.017453292519943295 * 0.017453292519943295)
            .asDiagonal();

    // The measurement kernel K = h^2 Sigma_z + floor_covariance (header comment).
    PoseFilterKernelCovariance kernel_covariance = PoseFilterKernelCovariance::kWithinModes;
    // For kWithinModes: the mean-shift mode finder's options (bandwidths 2 mm, 0.2 rad by
    // default; modes closer than that are one mode).
    PoseModeOptions modes;
    // h, > 0; or 0 (default) for Silverman's rule of thumb (4 / ((d + 2) ESS))^(1/(d+4)),
    // which minimises the kernel density's mean integrated squared error for Gaussian data
    // (Silverman 1986, the normal reference rule); ~0.50 for 100 equal-weight samples in
    // d = 3, ~0.55 for 50.
    double bandwidth_factor = 0;
    // K_floor, symmetric positive definite (x m^2, y m^2, yaw rad^2). Default: standard
    // deviations of 0.1 mm and 1 deg, below the smallest posterior spreads the samplers
    // report on the Soft Bubble (x ~0.12 mm, yaw ~4 deg; docs/SAMPLERS.md) and about a
    // quarter of its 0.45 mm pixel pitch. For n = 0 only its (x, y) block is used.
    Eigen::Matrix3d floor_covariance = Eigen::Vector3d(0.1e-3 * 0.1e-3, 0.1e-3 * 0.1e-3,
                                                       0.017453292519943295 * 0.017453292519943295)
                                           .asDiagonal();

    // Resample when ESS < resample_threshold * num_particles; in [0, 1]. 0 never
    // resamples, 1 resamples after every update. 0.5: the usual choice (Doucet &
    // Johansen 2011).
    double resample_threshold = 0.5;
    // The gate, > 0 (may be +infinity: never reject): a measurement is rejected when the
    // smallest squared Mahalanobis distance r^T K^-1 r over all particle-sample pairs
    // exceeds it. 30.66 = the chi-square(3) quantile at 1 - 1e-6: a particle drawn from
    // a sample's own kernel lies beyond it once in a million draws.
    double gate_squared_mahalanobis = 30.664849706213598;
    // Incompatible measurements rejected in a row at most (>= 0); the next one
    // re-initialises the filter from itself (the tool jumped, or the filter diverged).
    // 0: every incompatible measurement re-initialises; INT_MAX: (practically) never.
    // 3: one or two outlier frames are ignored, a persistent disagreement is not.
    int max_consecutive_rejections = 3;

    // For the mean of the estimate and of the measurement (kWhole).
    PoseMeanOptions mean;

    bool IsValid(std::string* error) const;
  };

  struct UpdateSummary {
    PoseFilterUpdateType type = PoseFilterUpdateType::kUpdated;
    std::string message;
    // Kish's ESS of the particle weights after the likelihood was applied and before any
    // resampling, and after the update (N after a resampling or an initialisation).
    double ess_before_resampling = 0;
    double ess = 0;
    bool resampled = false;
    // log p(z | past measurements) ~ log sum_i w_i p(z | x_i): the log marginal likelihood
    // density of this measurement under the predicted particles (nats; units of
    // 1 / (m^2 rad)); -infinity when rejected, 0 when (re)initialised (nothing predicted it).
    double log_evidence = 0;
    // min_ij r_ij^T K^-1 r_ij: how far the closest particle was from the closest sample,
    // in kernel standard deviations squared (what the gate tests); 0 when initialised.
    double min_squared_mahalanobis = 0;
    // The measurement kernel: K (3x3, (x, y, yaw), tangent at each sample; for n = 0 the
    // yaw row and column are 0), the bandwidth factor h used, and the number of modes
    // Sigma_z was pooled over (1 for kWhole).
    Eigen::Matrix3d kernel_covariance = Eigen::Matrix3d::Zero();
    double bandwidth_factor = 0;
    int measurement_modes = 0;
    int measurement_samples = 0;
    double time_ms = 0;
    // One line: "Update: UPDATED, ESS 612.3 -> 612.3 of 1000, log evidence 21.4, ...".
    std::string BriefReport() const;
  };

  // Counts over the filter's life (since construction; Reset() clears them).
  struct Summary {
    int num_predictions = 0;
    int num_updates = 0;            // Update() calls
    int num_initializations = 0;    // Initialize() calls and kInitialized updates
    int num_rejected = 0;           // kRejected updates (incompatible, prior kept)
    int num_reinitializations = 0;  // kReinitialized updates
    int num_resamples = 0;
    int consecutive_rejections = 0;  // current run of kRejected
    double last_ess = 0;             // after the last update
    double min_ess_before_resampling = std::numeric_limits<double>::infinity();
    double total_update_time_ms = 0;
    // "SE2ParticleFilter: 30 updates (1 initialisation, 0 rejected, 0 reinitialisations),
    //  9 resamples, ESS 640 / 1000 (min 212 before resampling), 4.1 ms per update".
    std::string BriefReport(int num_particles) const;
  };

  // Pose estimate (CurrentEstimate()).
  struct Estimate {
    SE2d mean;                                             // sensor_T_object
    Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // tangent at mean, (x, y, yaw)
    PoseMeanSummary mean_summary;
    double effective_sample_size = 0;  // of the particle weights
    Eigen::Vector3d mean_velocity =
        Eigen::Vector3d::Zero();  // weighted, per frame (constant_velocity)
  };

  // Throws std::invalid_argument with IsValid()'s message.
  explicit SE2ParticleFilter(const Options& options);
  SE2ParticleFilter();  // default Options

  // Particles drawn from N(mean, covariance) in the tangent space at `mean`:
  // mean * Exp(delta), delta ~ N(0, covariance); covariance symmetric PSD (a zero
  // covariance puts every particle on `mean`). Equal weights. Throws
  // std::invalid_argument for a non-finite mean or a bad covariance.
  void Initialize(const SE2d& mean, const Eigen::Matrix3d& covariance);
  // Particles drawn from the measurement's kernel density (the likelihood of the header
  // comment): a sample chosen by its weight (systematic), moved by N(0, K). Throws
  // std::invalid_argument for a distribution with no samples.
  void Initialize(const PoseDistribution& measurement);
  // Particles and weights given directly (weights: empty = equal, else one per particle,
  // finite, >= 0, not all 0); their number replaces num_particles. Velocities are drawn
  // as at every initialisation. Throws std::invalid_argument for bad input.
  void Initialize(std::vector<SE2d> particles, std::vector<double> weights = {});
  bool initialized() const { return !particles_.empty(); }
  // Drops the particles and the Summary; the random stream continues.
  void Reset();

  // Moves every particle by the motion model over dt frames (dt >= 0, finite; throws
  // std::invalid_argument otherwise). Before the first initialisation: nothing to move,
  // only counted.
  void Predict(double dt = 1.0);

  // Applies one frame's posterior. Before the first initialisation it initialises from
  // it (kInitialized). Throws std::invalid_argument for a measurement with no samples.
  UpdateSummary Update(const PoseDistribution& measurement);

  // The particles and their normalised weights as a PoseDistribution, folded by the
  // symmetry order (PoseDistribution::FoldedBySymmetry; unchanged for n = 1). Throws
  // std::logic_error before initialisation.
  PoseDistribution Posterior() const;
  // Mean and covariance of Posterior() (header comment). Throws std::logic_error before
  // initialisation.
  Estimate CurrentEstimate() const;

  // Kish's effective sample size 1 / sum w_i^2 of the current weights (0 before
  // initialisation).
  double EffectiveSampleSize() const;
  int num_particles() const { return static_cast<int>(particles_.size()); }
  // The raw particles (not folded) and their normalised weights, and the velocities
  // (zero unless constant_velocity), all of num_particles().
  const std::vector<SE2d>& particles() const { return particles_; }
  std::vector<double> weights() const;
  const std::vector<Eigen::Vector3d>& velocities() const { return velocities_; }

  const Options& options() const { return options_; }
  const Summary& summary() const { return summary_; }

 private:
  struct Kernel;  // a measurement turned into its kernel density (pose_filter.cc)

  Kernel MakeKernel(const PoseDistribution& measurement) const;
  void InitializeFromKernel(const Kernel& kernel);
  void DrawVelocities();
  void NormalizeLogWeights();
  void ResampleIfNeeded(UpdateSummary* summary);

  Options options_;
  // Matrix square roots of the motion covariances (PSD), for the draws.
  Eigen::Matrix3d process_sqrt_;
  Eigen::Matrix3d velocity_process_sqrt_;
  Eigen::Matrix3d initial_velocity_sqrt_;
  std::mt19937_64 rng_;  // engine only; the distributions are Boost.Random's (portable)
  std::vector<SE2d> particles_;
  std::vector<double> log_weights_;  // normalised: log-sum-exp = 0
  std::vector<Eigen::Vector3d> velocities_;
  Summary summary_;
};

// Systematic resampling (Kitagawa 1996): the indices i of the N = weights.size() pointers
// (u0 + k) / N, k = 0..N-1, into the cumulative weights. weights: normalised (sum 1,
// within rounding), >= 0; u0 in [0, 1). Every index appears floor(N w_i) or
// ceil(N w_i) times, in increasing order. Throws std::invalid_argument for an empty
// vector, a negative or non-finite weight, or u0 outside [0, 1).
std::vector<int> SystematicResample(const std::vector<double>& weights, double u0);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_POSE_POSE_FILTER_H_
