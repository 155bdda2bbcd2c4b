// Copyright 2026 The tactfunc Authors.
//
// PosePosterior: the in-hand pose posterior of one tactile frame (Sec. III-C/D, IV-C of
// "Tactile Functasets"): latent samples z_i from the frame's latent posterior
// (samplers/sgld.h, samplers/laplace.h) pushed through the pose MLP g_phi
// (models/pose/pose_mlp.h) -- x_i = PoseMlp::Predict(z_i, n) as an SE2d sensor_T_object --
// or, for the k-NN sampler, the stored poses of the nearest functaset entries
// (estimation/posterior/knn_posterior.h). The result is a PoseDistribution (equal weights for sgld
// and laplace, kernel weights for knn) over sensor_T_object, folded by the tool's
// symmetry order n (PoseDistribution::FoldedBySymmetry; n = 1 for an unknown or
// asymmetric tool, 0 for the hemisphere), and a Summary with its mean and tangent
// covariance (right perturbations at the mean, (x, y, yaw); models/core/se2.h).
//
// Pipeline per frame:
//   sgld     fit (LatentFitter, Options::fit, default ceres:10) -> z*; Sgld chains from
//            z* (+ jitter) on the frame's U -> num_samples latents -> PoseMlp.
//   laplace  fit -> z*; N(z*, H^-1) -> num_samples latents -> PoseMlp.
//   model error (sgld, laplace; Options::model_error): each MLP pose x_i is composed
//            with a residual r_j of the MLP drawn (uniformly, seeded) from its
//            calibration residuals, x_i <- x_i Exp(r_j) (PoseMlp::calibration_residuals,
//            measured by train-pose on held-out contacts). The latent posterior alone
//            leaves out the regressor's own error, which dominates (docs/POSES.md,
//            "Calibration"): without it the 90% regions covered 55-62% of the truths.
//   knn      a cheap query latent (knn_query_meta_sgd_steps meta-SGD steps, the map the
//            trunk was trained for) -> KnnPosterior -> the neighbours' labelled poses.
// With Estimate(targets, latent, ...) the given latent replaces the fit (the mode for
// laplace, the start for sgld, the query for knn).
//
// A photometric trunk (models/trunk/photometric_trunk.h) has no LatentProblem: its
// latent must be given (fitted as `encode` fits it, LatentEncoder::EncodeTargets), and
// sgld and laplace sample samplers/photometric_potential.h's U over every valid pixel
// with the same sigma rule (Options::problem's sigma and sigma_z; its other fields do
// not apply). Its Laplace Hessian comes from 2 d whole-frame passes (central
// differences), far slower than the direct trunk's analytic one.
//
// Each frame has one LatentProblem (estimation/fitting/latent_problem.h, Options::problem):
// the fit finds its mode and the samplers sample it, so z* is the mode of the U sampled.
//
// Errors: bad options throw std::invalid_argument from the constructor (so does a knn
// sampler without a KnnPosterior, or a pose MLP whose input_dim is not the trunk's
// latent_dim); bad targets throw from Estimate (as LatentFitter::Fit); sampler failures
// (all SGLD chains diverged, a singular Laplace Hessian, no labelled neighbour) come
// back as kFailure with the sampler's message and no distribution.
//
// Thread safety: Estimate is const and may run concurrently.
#ifndef TACTFUNC_ESTIMATION_POSTERIOR_POSE_POSTERIOR_H_
#define TACTFUNC_ESTIMATION_POSTERIOR_POSE_POSTERIOR_H_

#include <cstdint>
#include <optional>
#include <string>

#include <Eigen/Core>

#include "estimation/fitting/latent_fitter.h"
#include "estimation/pose/pose_distribution.h"
#include "estimation/data/trunk_targets.h"
#include "models/trunk/functa_model.h"
#include "models/pose/pose_mlp.h"
#include "estimation/posterior/knn_posterior.h"
#include "samplers/laplace.h"
#include "samplers/sgld.h"

namespace tactfunc {

enum class PosteriorSampler { kSgld, kLaplace, kKnn };
// "sgld", "laplace", "knn".
const char* ToString(PosteriorSampler sampler);
bool PosteriorSamplerFromString(const std::string& name, PosteriorSampler* sampler);

enum class PosePosteriorTermination {
  kSuccess,  // a distribution (the sampler may still report a warning, e.g. SGLD's
             // STEP_SIZE_TOO_SMALL or some chains DIVERGED: see sampler summaries)
  kFailure,  // no distribution; the message says why
};
const char* ToString(PosePosteriorTermination termination);  // "SUCCESS", "FAILURE"

class PosePosterior {
 public:
  // Pixels per SGLD gradient by default (of 6,160 on the Soft Bubble, 8,560 on the
  // GelSlim). Measured on the committed trunk (tests/samplers/sgld_trunk_test.cc): the
  // whitened sample variance was that of full batches at 1024 (1.183 both), 3.5% wider
  // at 512 and 7.5% at 256.
  static constexpr int kDefaultSgldMinibatch = 1024;
  static Sgld::Options DefaultSgldOptions();

  struct Options {
    // Which sampler; see the header comment and docs/SAMPLERS.md for the trade-off.
    // sgld: the paper's (Sec. III-C, IV-C).
    PosteriorSampler sampler = PosteriorSampler::kSgld;
    // Pose samples wanted. >= 1. 100: the paper's N (Sec. IV-C). sgld runs
    // ceil(num_samples / sgld.num_chains) samples per chain and keeps the first
    // num_samples (chain-major); knn returns at most knn.k (its neighbours).
    int num_samples = 100;
    // Seed of the sampler (overrides sgld.seed and laplace.seed).
    std::uint64_t seed = 0;
    // The latent problem of each frame (sigma, sigma_z, robust loss, pixels, precision).
    // sigma = 0 (automatic): the pose model's calibrated PosteriorSigmaOfPoseModel if it
    // has one, else LatentProblem::AutomaticSigma (the trunk's residual_sigma).
    LatentProblem::Options problem;
    // The latent fit (mode / start) of that problem. Default: LatentFitter's (ceres:10).
    LatentFitter::Options fit;
    // Meta-SGD steps of the knn sampler's query latent; -1 = the trunk's inner_steps
    // (what it was trained for), >= -1.
    int knn_query_meta_sgd_steps = -1;
    // Per-sampler options (num_samples and seed fields are set from the above). sgld
    // defaults to Sgld's options with minibatches of kDefaultSgldMinibatch pixels and the
    // control variate at the fit's mode (samplers/sgld.h): on the committed Soft Bubble
    // trunk they sample the full-batch law (tests/samplers/sgld_trunk_test.cc) at about a
    // third of its cost. minibatch_size = 0 runs full batches.
    Sgld::Options sgld = DefaultSgldOptions();
    LaplaceSampler::Options laplace;
    KnnPosterior::Options knn;
    // Add the pose MLP's own error to each sgld / laplace pose sample (header comment).
    // No effect for a pose model without calibration residuals or for knn.
    bool model_error = true;
    // Fold the yaws by the tool's symmetry order before the mean and covariance.
    bool fold_by_symmetry = true;
    // For the Summary's mean.
    PoseMeanOptions mean;
    bool IsValid(std::string* error) const;
  };

  struct Summary {
    PosteriorSampler sampler = PosteriorSampler::kSgld;
    PosePosteriorTermination termination_type = PosePosteriorTermination::kFailure;
    std::string message;
    int symmetry_order = 1;
    int num_samples = 0;  // in the distribution
    bool fit_ran = false;
    LatentFitter::Summary fit_summary;
    // The summary of the sampler that ran (the others stay default).
    Sgld::Summary sgld_summary;
    LaplaceSampler::Summary laplace_summary;
    KnnPosterior::Summary knn_summary;
    // Of the (folded) distribution: the mean (sensor_T_object) and the 3x3 covariance in
    // the tangent space at the mean, (x m, y m, yaw rad), right perturbations.
    SE2d mean;
    Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();
    PoseMeanSummary mean_summary;
    double fit_time_ms = 0;
    double sample_time_ms = 0;  // latent sampler (or k-NN search)
    double pose_time_ms = 0;    // pose MLP + distribution + mean/covariance
    double total_time_ms = 0;
    bool IsSolutionUsable() const {
      return termination_type == PosePosteriorTermination::kSuccess;
    }
    std::string BriefReport() const;  // one line
    std::string FullReport() const;   // with the fit and the sampler's full report
  };

  // trunk, pose_mlp (and knn, if given) must outlive this object. knn is required for
  // the knn sampler. Throws std::invalid_argument (see the header comment).
  PosePosterior(const SensorTrunk& trunk, const PoseMlp& pose_mlp, const Options& options,
                const KnnPosterior* knn = nullptr);

  // The posterior of one frame for a tool of symmetry order n >= 0. *posterior receives
  // the distribution (nullopt on kFailure); *latent_samples (optional) the latents
  // (num_samples x d; empty for knn). Throws std::invalid_argument for n < 0, a null
  // posterior, or bad targets.
  Summary Estimate(const TrunkTargets& targets, int symmetry_order,
                   std::optional<PoseDistribution>* posterior,
                   Eigen::MatrixXd* latent_samples = nullptr) const;
  // The same with `latent` (size d, finite) in place of the fit. A photometric trunk
  // draws the frame against `markers` (its own reference's, PhotometricTrunk::MakeMarkers)
  // if given, else against the trunk's own reference.
  Summary Estimate(const TrunkTargets& targets, const Eigen::VectorXd& latent,
                   int symmetry_order, std::optional<PoseDistribution>* posterior,
                   Eigen::MatrixXd* latent_samples = nullptr,
                   const PhotometricTrunk::Markers* markers = nullptr) const;

  const Options& options() const { return options_; }

 private:
  Summary EstimateImpl(const TrunkTargets& targets, const Eigen::VectorXd* latent,
                       int symmetry_order, std::optional<PoseDistribution>* posterior,
                       Eigen::MatrixXd* latent_samples,
                       const PhotometricTrunk::Markers* markers) const;

  const SensorTrunk* trunk_;
  const PoseMlp* pose_mlp_;
  Options options_;
  const KnnPosterior* knn_;
  // The direct trunk's fits (none for a photometric trunk, whose latent is given).
  std::optional<LatentFitter> fitter_;
  std::optional<LatentFitter> query_fitter_;  // meta-SGD query of the knn sampler
};

// The calibration residuals of `model` (PoseMlp::calibration_residuals: R x 3,
// r_j = Log(T_pred^-1 T_true) with the true yaw taken modulo the tool's symmetry) on
// held-out latents inputs (R x d) with their true poses and symmetry orders. Throws
// std::invalid_argument for mismatched shapes.
Eigen::MatrixXd CalibrationResiduals(const PoseMlp& model, const Eigen::MatrixXf& inputs,
                                     const PoseTargets& targets);

// The latent map a pose model was trained on, as a fit strategy: its info's
// "latent_map" (written by train-pose: "functaset" = the trunk's K meta-SGD steps, what
// `encode` stores; else a strategy such as "ceres:10" from --refit), or the older
// "latents" field ("functaset" / "refit <strategy>"). Posteriors centre on this map so
// that the MLP sees the kind of latent it was trained on (docs/CLI.md, "Latent maps").
// A model without either field gives the trunk's meta_sgd:K. The info is read as
// PoseModelProvenance (models/pose/pose_model_provenance.h), which throws
// std::invalid_argument naming a field of the wrong type.
FitStrategy LatentMapOfPoseModel(const PoseMlp& pose_model, const SensorTrunk& trunk);

// The fit a photometric trunk's frame gets for `pose_model`: the strategy of the
// functaset it was trained on, which train-pose records as its "latent_map" (e.g.
// "knn+adam:140"), or "" -- the encoder's default -- for a model that records
// "functaset" (written before train-pose recorded the functaset's strategy). Read as
// PoseModelProvenance; throws std::invalid_argument as it does.
std::string PhotometricLatentMapOfPoseModel(const PoseMlp& pose_model);

// The pixel sigma the pose model was calibrated with (its info's "posterior_sigma",
// `train-pose --posterior-sigma`, read as PoseModelProvenance), or 0 if it has none.
// PosePosterior uses it when Options::problem.sigma is 0 (automatic) -- see
// "Calibration" in docs/POSES.md: the
// calibration residuals already hold the pose error that the latent's noise causes at
// the fit, so the latent posterior is tempered (a smaller sigma) to avoid counting that
// error twice; the value is chosen on calibration data and checked on fresh contacts
// (tests/estimation/posterior/coverage_test.cc).
double PosteriorSigmaOfPoseModel(const PoseMlp& pose_model);

// One call: PosePosterior(trunk, pose_mlp, options, knn).Estimate(targets, n, posterior).
PosePosterior::Summary EstimatePosePosterior(const SensorTrunk& trunk, const PoseMlp& pose_mlp,
                                             const TrunkTargets& targets, int symmetry_order,
                                             const PosePosterior::Options& options,
                                             std::optional<PoseDistribution>* posterior,
                                             const KnnPosterior* knn = nullptr);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_POSTERIOR_POSE_POSTERIOR_H_
