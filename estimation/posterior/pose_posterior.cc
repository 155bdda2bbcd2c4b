// Copyright 2026 The tactfunc Authors.
#include "estimation/posterior/pose_posterior.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <utility>
#include <vector>

#include <boost/random/mersenne_twister.hpp>
#include <boost/random/uniform_int_distribution.hpp>

#include <nlohmann/json.hpp>

#include "models/core/internal/elapsed.h"
#include "models/core/seed.h"
#include "samplers/photometric_potential.h"
#include "models/pose/pose_model_provenance.h"
#include "models/simulator/tool.h"

namespace tactfunc {
namespace {

// DeriveSeed stream of the model-error draws (distinct from the samplers' own streams,
// which are seeded with options.seed directly).
constexpr std::uint64_t kModelErrorStream = 0x6d6f64656c457272ull;  // "modelErr"

using internal::MsSince;

LatentFitter::Options FitOptions(const PosePosterior::Options& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  return options.fit;
}

LatentFitter::Options QueryOptions(const PosePosterior::Options& options,
                                   const SensorTrunk& trunk) {
  LatentFitter::Options fit = FitOptions(options);
  fit.strategy.knn = false;
  fit.strategy.refinement = FitStrategy::Refinement::kMetaSgd;
  fit.strategy.steps = options.knn_query_meta_sgd_steps >= 0 ? options.knn_query_meta_sgd_steps
                                                             : trunk.meta_sgd.inner_steps;
  return fit;
}

// problem.sigma = 0 (automatic) takes the pose model's calibrated posterior sigma if
// it has one (header comment); otherwise LatentProblem's own rule applies.
PosePosterior::Options WithPoseModelSigma(PosePosterior::Options options,
                                          const PoseMlp& pose_mlp) {
  if (options.problem.sigma == 0) {
    const double sigma = PosteriorSigmaOfPoseModel(pose_mlp);
    if (sigma > 0) options.problem.sigma = sigma;
  }
  return options;
}

}  // namespace

double PosteriorSigmaOfPoseModel(const PoseMlp& pose_model) {
  return PoseModelProvenance::FromJson(pose_model.info_json(), "pose model").posterior_sigma;
}

const char* ToString(PosteriorSampler sampler) {
  switch (sampler) {
    case PosteriorSampler::kSgld:
      return "sgld";
    case PosteriorSampler::kLaplace:
      return "laplace";
    case PosteriorSampler::kKnn:
      return "knn";
  }
  return "unknown";
}

bool PosteriorSamplerFromString(const std::string& name, PosteriorSampler* sampler) {
  for (PosteriorSampler s :
       {PosteriorSampler::kSgld, PosteriorSampler::kLaplace, PosteriorSampler::kKnn}) {
    if (name == ToString(s)) {
      *sampler = s;
      return true;
    }
  }
  return false;
}

const char* ToString(PosePosteriorTermination termination) {
  return termination == PosePosteriorTermination::kSuccess ? "SUCCESS" : "FAILURE";
}

bool PosePosterior::Options::IsValid(std::string* error) const {
  std::ostringstream m;
  std::string why;
  if (num_samples < 1) {
    m << "PosePosterior::Options::num_samples must be >= 1, got " << num_samples;
  } else if (knn_query_meta_sgd_steps < -1) {
    m << "PosePosterior::Options::knn_query_meta_sgd_steps must be >= -1, got "
      << knn_query_meta_sgd_steps;
  } else if (!problem.IsValid(&why)) {
    m << "PosePosterior::Options::problem: " << why;
  } else if (!fit.IsValid(&why)) {
    m << "PosePosterior::Options::fit: " << why;
  } else if (!sgld.IsValid(&why)) {
    m << "PosePosterior::Options::sgld: " << why;
  } else if (!laplace.IsValid(&why)) {
    m << "PosePosterior::Options::laplace: " << why;
  } else if (!knn.IsValid(&why)) {
    m << "PosePosterior::Options::knn: " << why;
  } else if (!mean.IsValid(&why)) {
    m << "PosePosterior::Options::mean: " << why;
  } else {
    return true;
  }
  if (error != nullptr) *error = m.str();
  return false;
}

std::string PosePosterior::Summary::BriefReport() const {
  std::ostringstream s;
  s << "Pose posterior (" << ToString(sampler) << "): " << ToString(termination_type) << ", "
    << num_samples << " samples";
  if (IsSolutionUsable()) {
    s << ", mean (" << mean.x() << " m, " << mean.y() << " m, " << mean.yaw()
      << " rad), std (" << std::sqrt(covariance(0, 0)) << " m, " << std::sqrt(covariance(1, 1))
      << " m, " << std::sqrt(covariance(2, 2)) << " rad)";
  }
  s << ", " << total_time_ms << " ms (fit " << fit_time_ms << ", sampler " << sample_time_ms
    << ", poses " << pose_time_ms << ")";
  return s.str();
}

std::string PosePosterior::Summary::FullReport() const {
  std::ostringstream s;
  s << BriefReport() << "\n  " << message << "\n";
  if (fit_ran) s << "  fit: " << fit_summary.BriefReport() << "\n";
  switch (sampler) {
    case PosteriorSampler::kSgld:
      s << sgld_summary.FullReport();
      break;
    case PosteriorSampler::kLaplace:
      s << laplace_summary.FullReport();
      break;
    case PosteriorSampler::kKnn:
      s << knn_summary.BriefReport() << "\n";
      break;
  }
  if (IsSolutionUsable()) s << "  " << mean_summary.BriefReport() << "\n";
  return s.str();
}

Sgld::Options PosePosterior::DefaultSgldOptions() {
  Sgld::Options options;
  options.minibatch_size = kDefaultSgldMinibatch;
  options.control_variate = true;
  return options;
}

PosePosterior::PosePosterior(const SensorTrunk& trunk, const PoseMlp& pose_mlp,
                             const Options& options, const KnnPosterior* knn)
    : trunk_(&trunk),
      pose_mlp_(&pose_mlp),
      options_(WithPoseModelSigma(options, pose_mlp)),
      knn_(knn) {
  if (trunk.photometric == nullptr) {
    fitter_.emplace(trunk, FitOptions(options_));
    query_fitter_.emplace(trunk, QueryOptions(options_, trunk));
  } else {
    FitOptions(options_);  // validates the options
  }
  if (pose_mlp.input_dim() != TrunkLatentDim(trunk)) {
    throw std::invalid_argument("PosePosterior: the pose MLP takes latents of size " +
                                std::to_string(pose_mlp.input_dim()) + ", the trunk makes " +
                                std::to_string(TrunkLatentDim(trunk)));
  }
  if (options.sampler == PosteriorSampler::kKnn && knn == nullptr) {
    throw std::invalid_argument("PosePosterior: the knn sampler needs a KnnPosterior");
  }
}

PosePosterior::Summary PosePosterior::Estimate(const TrunkTargets& targets, int symmetry_order,
                                               std::optional<PoseDistribution>* posterior,
                                               Eigen::MatrixXd* latent_samples) const {
  return EstimateImpl(targets, nullptr, symmetry_order, posterior, latent_samples, nullptr);
}

PosePosterior::Summary PosePosterior::Estimate(const TrunkTargets& targets,
                                               const Eigen::VectorXd& latent, int symmetry_order,
                                               std::optional<PoseDistribution>* posterior,
                                               Eigen::MatrixXd* latent_samples,
                                               const PhotometricTrunk::Markers* markers) const {
  const int d = TrunkLatentDim(*trunk_);
  if (latent.size() != d || !latent.allFinite()) {
    throw std::invalid_argument("PosePosterior::Estimate: expected a finite latent of size " +
                                std::to_string(d) + ", got size " + std::to_string(latent.size()));
  }
  return EstimateImpl(targets, &latent, symmetry_order, posterior, latent_samples, markers);
}

PosePosterior::Summary PosePosterior::EstimateImpl(const TrunkTargets& targets,
                                                   const Eigen::VectorXd* latent,
                                                   int symmetry_order,
                                                   std::optional<PoseDistribution>* posterior,
                                                   Eigen::MatrixXd* latent_samples,
                                                   const PhotometricTrunk::Markers* markers) const {
  const auto start = std::chrono::steady_clock::now();
  if (posterior == nullptr) {
    throw std::invalid_argument("PosePosterior::Estimate: posterior must not be null");
  }
  if (symmetry_order < 0) {
    throw std::invalid_argument("PosePosterior::Estimate: symmetry order must be >= 0, got " +
                                std::to_string(symmetry_order));
  }
  posterior->reset();
  const int d = TrunkLatentDim(*trunk_);
  const bool photometric = trunk_->photometric != nullptr;
  if (photometric && latent == nullptr) {
    throw std::invalid_argument(
        "PosePosterior::Estimate: a photometric trunk's latent must be given (fit it as "
        "encode does, LatentEncoder::EncodeTargets)");
  }
  Summary summary;
  summary.sampler = options_.sampler;
  summary.symmetry_order = symmetry_order;
  if (latent_samples != nullptr) latent_samples->resize(0, d);
  auto fail = [&](const std::string& why) {
    summary.termination_type = PosePosteriorTermination::kFailure;
    summary.message = why;
    summary.total_time_ms = MsSince(start);
    return summary;
  };

  // The frame's one latent problem: the fit finds its mode, the samplers sample it (a
  // photometric trunk: its potential, header comment).
  std::optional<LatentProblem> problem;
  std::unique_ptr<LatentPotential> potential;
  if (photometric) {
    const double sigma = options_.problem.sigma > 0 ? options_.problem.sigma
                                                    : LatentProblem::AutomaticSigma(*trunk_);
    potential = std::make_unique<PhotometricPotential>(*trunk_->photometric, targets, sigma,
                                                       options_.problem.sigma_z, markers);
  } else {
    problem.emplace(*trunk_, targets, options_.problem);
    potential = std::make_unique<TrunkPotential>(*problem);
  }

  // The latent the sampler starts from: given, or fitted.
  auto t = std::chrono::steady_clock::now();
  Eigen::VectorXd z0;
  if (latent != nullptr) {
    z0 = *latent;
  } else {
    const LatentFitter& fitter =
        options_.sampler == PosteriorSampler::kKnn ? *query_fitter_ : *fitter_;
    summary.fit_summary = fitter.Fit(*problem, &z0);
    summary.fit_ran = true;
    if (!summary.fit_summary.IsSolutionUsable() &&
        summary.fit_summary.termination_type != FitTermination::kNoValidPixels) {
      summary.fit_time_ms = MsSince(t);
      return fail("the latent fit failed: " + summary.fit_summary.message);
    }
  }
  summary.fit_time_ms = MsSince(t);

  // Samples.
  t = std::chrono::steady_clock::now();
  std::vector<SE2d> poses;
  std::vector<double> weights;
  Eigen::MatrixXd z_samples;
  if (options_.sampler == PosteriorSampler::kKnn) {
    std::optional<PoseDistribution> neighbours;
    summary.knn_summary = knn_->Posterior(z0, &neighbours);
    summary.sample_time_ms = MsSince(t);
    if (!neighbours) return fail("k-NN: " + summary.knn_summary.message);
    poses = neighbours->samples();
    weights = neighbours->weights();
  } else {
    if (options_.sampler == PosteriorSampler::kSgld) {
      Sgld::Options sgld_options = options_.sgld;
      sgld_options.seed = options_.seed;
      sgld_options.num_samples_per_chain =
          (options_.num_samples + sgld_options.num_chains - 1) / sgld_options.num_chains;
      const Sgld sgld(sgld_options);
      summary.sgld_summary = sgld.Sample(*potential, z0, &z_samples);
      summary.sample_time_ms = MsSince(t);
      if (!summary.sgld_summary.IsSolutionUsable()) {
        return fail("SGLD: " + summary.sgld_summary.message);
      }
      if (z_samples.rows() > options_.num_samples) {
        z_samples.conservativeResize(options_.num_samples, d);
      }
    } else {
      LaplaceSampler::Options laplace_options = options_.laplace;
      laplace_options.seed = options_.seed;
      laplace_options.num_samples = options_.num_samples;
      const LaplaceSampler laplace(laplace_options);
      // At a fit's result, the Hessian the fit formed there (no pass of its own).
      summary.laplace_summary = summary.fit_ran
                                    ? laplace.SampleAtFit(*potential, summary.fit_summary, z0,
                                                          &z_samples)
                                    : laplace.Sample(*potential, z0, &z_samples);
      summary.sample_time_ms = MsSince(t);
      if (!summary.laplace_summary.IsSolutionUsable()) {
        return fail("Laplace: " + summary.laplace_summary.message);
      }
    }
    // Pose MLP, batched in float (PredictBatch); n = 0 gives yaw 0.
    poses = pose_mlp_->PredictBatch(z_samples.cast<float>(), symmetry_order);
    for (std::size_t i = 0; i < poses.size(); ++i) {
      if (!(std::isfinite(poses[i].x()) && std::isfinite(poses[i].y()) &&
            std::isfinite(poses[i].yaw()))) {
        return fail("the pose MLP gave a non-finite pose for latent sample " + std::to_string(i));
      }
    }
    const Eigen::MatrixXd& residuals = pose_mlp_->calibration_residuals();
    if (options_.model_error && residuals.rows() > 0) {
      boost::random::mt19937_64 engine(DeriveSeed(options_.seed, kModelErrorStream));
      boost::random::uniform_int_distribution<Eigen::Index> pick(0, residuals.rows() - 1);
      for (SE2d& pose : poses) {
        const Eigen::Vector3d r = residuals.row(pick(engine)).transpose();
        pose = pose * SE2d::Exp(r);
      }
    }
  }

  // The distribution, folded, and its moments.
  PoseDistribution distribution(std::move(poses), std::move(weights));
  if (options_.fold_by_symmetry && symmetry_order != 1) {
    distribution = distribution.FoldedBySymmetry(symmetry_order);
  }
  summary.mean = distribution.Mean(options_.mean, &summary.mean_summary);
  summary.covariance = distribution.CovarianceAbout(summary.mean);
  summary.num_samples = distribution.size();
  *posterior = std::move(distribution);
  if (latent_samples != nullptr) *latent_samples = z_samples;
  summary.termination_type = PosePosteriorTermination::kSuccess;
  summary.message = std::to_string(summary.num_samples) + " pose samples from " +
                    ToString(options_.sampler) +
                    (summary.fit_ran ? " after a " + summary.fit_summary.strategy.ToString() + " fit"
                                     : " from the given latent");
  summary.total_time_ms = MsSince(start);
  summary.pose_time_ms = summary.total_time_ms - summary.fit_time_ms - summary.sample_time_ms;
  return summary;
}

Eigen::MatrixXd CalibrationResiduals(const PoseMlp& model, const Eigen::MatrixXf& inputs,
                                     const PoseTargets& targets) {
  const Eigen::Index m = inputs.rows();
  if (targets.poses.rows() != m || targets.poses.cols() != 3 ||
      (targets.symmetry_orders.size() != 0 && targets.symmetry_orders.size() != m)) {
    throw std::invalid_argument(
        "CalibrationResiduals: expected " + std::to_string(m) + " x 3 poses and " +
        std::to_string(m) + " symmetry orders, got " + std::to_string(targets.poses.rows()) +
        " x " + std::to_string(targets.poses.cols()) + " and " +
        std::to_string(targets.symmetry_orders.size()));
  }
  Eigen::MatrixXd residuals(m, 3);
  for (Eigen::Index i = 0; i < m; ++i) {
    const int n = targets.symmetry_orders.size() ? targets.symmetry_orders[i] : 1;
    const SE2d predicted = model.Predict(inputs.row(i).transpose().cast<double>(), n);
    const Eigen::Vector3d t = targets.poses.row(i).transpose();
    // n = 0: FoldYawNear gives 0, the yaw Predict returns: no yaw residual.
    const double true_yaw = FoldYawNear(t[2], predicted.yaw(), n);
    residuals.row(i) = (predicted.Inverse() * SE2d::FromXYYaw(t[0], t[1], true_yaw)).Log().transpose();
  }
  return residuals;
}

FitStrategy LatentMapOfPoseModel(const PoseMlp& pose_model, const SensorTrunk& trunk) {
  std::string map =
      PoseModelProvenance::FromJson(pose_model.info_json(), "pose model").latent_map;
  if (map == "functaset") map = "meta_sgd:" + std::to_string(trunk.meta_sgd.inner_steps);
  FitStrategy strategy;
  std::string error;
  if (!FitStrategy::Parse(map, &strategy, &error)) {
    throw std::invalid_argument("pose model: latent map '" + map + "' is not a fit strategy: " +
                                error);
  }
  return strategy;
}

std::string PhotometricLatentMapOfPoseModel(const PoseMlp& pose_model) {
  const std::string map =
      PoseModelProvenance::FromJson(pose_model.info_json(), "pose model").latent_map;
  return map == "functaset" ? std::string() : map;
}

PosePosterior::Summary EstimatePosePosterior(const SensorTrunk& trunk, const PoseMlp& pose_mlp,
                                             const TrunkTargets& targets, int symmetry_order,
                                             const PosePosterior::Options& options,
                                             std::optional<PoseDistribution>* posterior,
                                             const KnnPosterior* knn) {
  return PosePosterior(trunk, pose_mlp, options, knn)
      .Estimate(targets, symmetry_order, posterior);
}

}  // namespace tactfunc
