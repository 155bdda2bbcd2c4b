// Copyright 2026 The tactfunc Authors.
//
// GeneratorPosterior: the pose posterior of one frame by analysis-by-synthesis
// (docs/POSES.md, "The generator path"). For each candidate tool t (the one the scene
// names, or every tool of the generator when the tool is unknown):
//
//   1. starts: the labels of the k nearest labelled functaset latents of tool t
//      (KnnPoseStarts: a FLANN index per tool over the train split's meta-SGD latents,
//      queried with the frame's meta-SGD latent -- the map the functaset stores), the pose
//      MLP's prediction at the same latent (if a PoseMlp is given), and, for asymmetric
//      tools, each of these turned by pi (near-symmetric faces: half_disc, l_shape,
//      lines3_*). The generator is invariant under the tool's symmetry by construction
//      (models/pose/pose_generator.h), so the symmetry-equivalent yaws of a C_n tool are
//      the same start and are not repeated; without k-NN starts, a yaw grid at the centre;
//      every start position is also tried at a grid of yaws (Options::yaw_grid);
//   2. modes: FitPoseModes (estimation/synthesis/pose_fitter.h) in Ceres on SE(2), the
//      starts scored and first refined on Options::coarse_pixels pixels of the frame (both
//      stages draw their pixels partly towards the contact, Options::problem); with the
//      tool unknown, the coarse stage of every tool runs first, and a tool whose lowest
//      coarse cost exceeds Options::tool_prune_ratio times the lowest of any tool goes no
//      further (no modes, probability 0; docs/POSES.md, "Pruning tools when the tool is
//      unknown", measures what it changes); before it, a screening coarse stage from
//      each tool's starts without the position and yaw grids prunes by the same ratio
//      (Options::tool_screen; "Screening the tools first");
//   2b. optionally (Options::final_pixels > 0), every distinct mode refined again on a
//      problem of that many pixels (all valid pixels when the frame has no more), where
//      its cost and Jacobian for step 3 are then taken: the few pixels of the search can
//      rank two nearby modes wrongly (docs/POSES.md, "The final ranking on more pixels");
//   3. Laplace: at mode m with whitened residuals r at the posterior's pixel sigma s and
//      Jacobian J over (tangent x, y, theta of the right perturbation, depth),
//        H_m = J^T J,  Sigma_m = H_m^-1 (4 x 4; H_m's eigenvalues floored at 1e-12 of
//        the largest, so an unconstrained direction gets a wide, positive variance),
//        log Z_m = -1/2 ||r||^2 + (k/2) log 2 pi - 1/2 log det H_m + log c_t,
//      k = 4, c_t = n for a C_n tool (its n copies of every mode), and for n = 0 (yaw
//      unobservable) k = 3 over (x, y, depth) and c_t = 2 pi (the yaw integrates out);
//      the uniform pose prior is the same for every tool and cancels.
//   Mixture weights: the Laplace evidence of the likelihood tempered by 1/tau,
//        log Z_m(tau) = -1/(2 tau) ||r||^2 + (k/2) log 2 pi - 1/2 log det H_m
//                       + (k/2) log tau + log c_t
//   (the integral of exp(-||r||^2 / (2 tau)) over the mode's basin: its Hessian is H_m /
//   tau), w_m = Z_m(tau) / sum Z(tau) over the modes of every candidate tool; the tool
//   probabilities P(t | y) = sum of its modes' weights. tau, the likelihood's temperature
//   (PoseGenerator::weight_temperature, or Options::weight_temperature; 1 for a generator
//   without one), is calibrated on held-out labelled contacts (CalibrateWeightTemperature):
//   the pixel sigma below is inflated so that each mode's Gaussian covers the truth near
//   it, which also shrinks the likelihood ratios between modes by kappa^2, and the mode
//   with the best fit holds the truth far more often than that ratio alone would say
//   (docs/POSES.md, "The mode weights' temperature"). Only the likelihood is tempered:
//   the Occam factor -1/2 log det H_m of a mode's width is not a model error to correct
//   (raising Z_m itself to 1/tau, as the posterior did before, weighed widths against
//   fits 1/tau times too strongly; docs/POSES.md, "Tempering the likelihood, not the
//   evidence"). A generator file calibrated before keeps w ~ Z^(1/tau), the weights its
//   tau was calibrated for (PoseGenerator::weight_temperature_on_likelihood), unless
//   Options::weight_temperature is set.
//
// The pixel sigma s. The residuals of a rendering are dominated by the generator's and
// the trunk's model error, spatially correlated, not by independent pixel noise, so the
// trunk's residual_sigma would give far too narrow regions. s = kappa * RMS residual of
// the frame's best mode (over all candidate tools) * sqrt(N / N_ref), N the pixels of the
// problem and N_ref = min(768, the frame's valid pixels): a correlated model error carries
// about as much information at any N, so the regions stay the same when fewer pixels are
// used for speed (N_ref is the pixel count kappa is defined at); kappa (PoseGenerator::sigma_inflation, or
// Options::sigma_inflation) is calibrated on held-out labelled contacts
// (CalibrateSigmaInflation) and checked on fresh contacts
// (tests/estimation/synthesis/generator_coverage_test.cc).
//
// Regions: PoseMixture::Contains(T, p) is the highest-density region of the mixture's
// (x, y, yaw) marginal, {density >= c_p}, with c_p the (1 - p)-quantile of the density at
// num_region_samples draws from the mixture (seeded); the truth's yaw is taken modulo the
// tool's symmetry (the copy nearest each component).
//
// Errors: bad options throw std::invalid_argument; an unknown tool name throws naming
// the tools the generator knows. Thread-safe (const).
#ifndef TACTFUNC_ESTIMATION_SYNTHESIS_GENERATOR_POSTERIOR_H_
#define TACTFUNC_ESTIMATION_SYNTHESIS_GENERATOR_POSTERIOR_H_

#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "estimation/data/trunk_targets.h"
#include "estimation/fitting/latent_problem.h"
#include "estimation/functaset/functaset.h"
#include "estimation/knn/knn_index.h"
#include "estimation/pose/pose_distribution.h"
#include "estimation/synthesis/pose_fitter.h"
#include "models/pose/pose_generator.h"
#include "models/pose/pose_mlp.h"
#include "models/trunk/functa_model.h"

namespace tactfunc {

// One Laplace component: a mode of tool `tool` with its tangent covariance over
// (x, y, theta, depth) (right perturbations at `mean`).
struct LaplaceComponent {
  std::string tool;
  int symmetry_order = 1;
  double weight = 0;
  double log_evidence = 0;    // log Z_m at tau = 1 (header comment)
  double log_likelihood = 0;  // its data term, -1/2 ||r||^2 at the pixel sigma s
  int dimension = 4;          // k: 4, or 3 for a tool whose yaw is unobservable
  SE2d mean;
  double depth_m = 0;
  Eigen::Matrix4d covariance = Eigen::Matrix4d::Zero();
  std::string start;
};

// The mixture of Laplace components (weights sum to 1).
class PoseMixture {
 public:
  PoseMixture() = default;
  explicit PoseMixture(std::vector<LaplaceComponent> components);
  const std::vector<LaplaceComponent>& components() const { return components_; }
  bool empty() const { return components_.empty(); }
  // The heaviest component's mean (the MAP mode).
  SE2d Mode() const;
  // The posterior pose mean conditional on `tool` (empty: the most probable tool, the
  // largest sum of weights): the exponential barycentre (PoseDistribution::Mean) of that
  // tool's component means weighted by their weights, yaws first folded by its symmetry
  // order (PoseDistribution::FoldedBySymmetry; n = 0: yaw 0). Each Laplace component is
  // centred on its mean in the tangent space, so this is the mixture's mean to first
  // order in the components' spread; with one component it is that component's mean.
  // Of a symmetric tool's equivalent yaws the one nearest the heaviest component's is
  // returned.
  // Between two mirrored modes of an asymmetric tool it falls between them: the Bayes
  // estimate under squared error, not a pose either mode explains (Mode() or the
  // components give hypotheses). Throws std::invalid_argument if no component matches.
  SE2d Mean(const std::string& tool = "") const;
  // Density of the (x, y, yaw) marginal at T (the yaw folded per component by its tool's
  // symmetry; n = 0 components: the (x, y) marginal, yaw ignored). Only components of
  // `tool` count when it is not empty (density conditional on that tool, renormalised).
  double Density(const SE2d& sensor_T_object, const std::string& tool = "") const;
  // num draws (seeded) of (tool index in components, pose): as a PoseDistribution of
  // the poses of `tool`'s components (all components if empty).
  PoseDistribution Sample(int num, std::uint64_t seed, const std::string& tool = "") const;
  // Highest-density region of probability p (header comment), conditional on `tool`.
  bool Contains(const SE2d& sensor_T_object, double p, int num_region_samples,
                std::uint64_t seed, const std::string& tool = "") const;

 private:
  std::vector<LaplaceComponent> components_;
};

// Starts from the labelled functaset: one FLANN index per tool over the train-split
// latents. Built once; Search is const. query_trunk: the trunk whose latents the
// functaset holds when it is not the one the posterior renders through (a generator with
// a trunk of its own, `pose --generator-model`); the posterior then takes the frame's
// query latent under that trunk. Null: the posterior's own trunk. Not owned; it must
// outlive this object.
class KnnPoseStarts {
 public:
  // Throws std::invalid_argument if the functaset has no labelled train entries of
  // `sensor`, or query_trunk's latent_dim is not the functaset's.
  KnnPoseStarts(const Functaset& functaset, SensorKind sensor,
                const SensorTrunk* query_trunk = nullptr);
  // The labels of the k nearest latents of `tool` (empty if the tool has none).
  std::vector<PoseStart> Starts(const Eigen::VectorXf& query, const std::string& tool,
                                int k) const;
  int size() const { return size_; }
  int latent_dim() const { return latent_dim_; }
  const SensorTrunk* query_trunk() const { return query_trunk_; }

 private:
  struct ToolIndex {
    std::unique_ptr<KnnIndex> index;
    std::vector<PoseLabel> labels;
  };
  std::map<std::string, ToolIndex> tools_;
  int size_ = 0;
  int latent_dim_ = 0;
  const SensorTrunk* query_trunk_ = nullptr;
};

class GeneratorPosterior {
 public:
  // The pixel count kappa is defined at (header comment).
  static constexpr double kReferencePixels = 768;

  struct Options {
    // The frame's latent problem. Its sigma only scales the fit (the posterior sets its
    // own, header comment); max_pixels bounds the time per trunk pass (default 384 of the
    // 70 x 88 bubble frame's 6160 pixels), half of them drawn towards the contact
    // (contact_share 0.5, importance-weighted): a shallow contact covers a few per cent of
    // the frame, and evenly spaced pixels leave it a dozen (docs/POSES.md).
    LatentProblem::Options problem = DefaultProblem();
    PoseFitOptions fit;
    int knn_k = 4;                 // k-NN starts per tool, >= 0
    bool flip_starts = true;       // add yaw + pi starts for asymmetric tools
    // Yaw grid: every start position is also tried at yaw_grid yaws evenly spaced over the
    // full turn (those equivalent under the tool's symmetry once), >= 1 (1 = no grid;
    // it subsumes flip_starts when even).
    int yaw_grid = 12;
    // Pixels of the coarse stage (scoring the starts, their first refinement,
    // pose_fitter.h); 0 = no coarse stage (the starts are scored on the full problem).
    int coarse_pixels = 128;
    // Tool pruning, with two or more candidate tools (the tool unknown) and a coarse
    // stage: a tool whose lowest cost after the coarse stage exceeds this ratio times the
    // lowest of any tool is not refined further and gets no weight; 0 = every tool refined,
    // else >= 1.
    double tool_prune_ratio = 2;
    // Tool screening, with pruning on (tool_prune_ratio > 0) and two or more candidate
    // tools: before the coarse stage, each tool's coarse stage runs from its starts without
    // the position and yaw grids, and a tool whose lowest cost there exceeds
    // tool_prune_ratio times the lowest of any tool goes no further.
    bool tool_screen = true;
    // Pixels of the final stage (step 2b; drawn as Options::problem draws, all valid
    // pixels evenly when it holds as many); 0 = none, the modes as the search left them;
    // -1 = the generator's (the stage its kappa and tau were calibrated with,
    // PoseGenerator::final_pixels; the posterior's options() hold the value resolved).
    // When set, s and N below are the final problem's.
    int final_pixels = -1;
    // Position grid: the first start (the nearest neighbour's label, else the pose MLP's)
    // is also tried at the positions (a, b) * position_grid_m away in x and y for
    // |a|, |b| <= position_grid_rings (each at the yaw grid); 0 = none. Catches a wrong
    // mirror mode whose position is off by millimetres too.
    double position_grid_m = 2.5e-3;
    int position_grid_rings = 2;
    // kappa of the header comment; 0 = the generator's sigma_inflation (3 if it has none).
    double sigma_inflation = 0;
    // tau of the header comment; 0 = the generator's weight_temperature (1 if it has none).
    double weight_temperature = 0;
    int num_region_samples = 400;  // for regions and sample clouds, >= 10
    std::uint64_t seed = 0;
    bool IsValid(std::string* error) const;
    static LatentProblem::Options DefaultProblem();
    // The problem the modes are finally ranked on and their Laplace approximations taken
    // on: `problem`, with final_pixels pixels when the final stage is on (call it on a
    // posterior's options(), where -1 is resolved).
    LatentProblem::Options RankingProblem() const;
  };

  struct Summary {
    bool usable = false;
    std::string message;
    std::string tool;  // the most probable tool
    std::map<std::string, double> tool_probabilities;
    SE2d mean;  // the mode of the heaviest component
    Eigen::Matrix3d covariance = Eigen::Matrix3d::Zero();  // its (x, y, yaw) block
    double sigma = 0;       // the pixel sigma the posterior used
    int num_pixels = 0;     // N, the pixels of the frame's problem
    double pixel_factor = 1;  // sqrt(N / min(768, valid pixels)) (header comment)
    double rms_residual = 0;  // of the best mode (normalised units)
    int num_starts = 0, num_modes = 0;  // starts: every one scored, the screening's too
    // Tools past the screening (Options::tool_screen) and past the coarse stage
    // (Options::tool_prune_ratio).
    int tools_screened_in = 0, tools_refined = 0;
    double fit_time_ms = 0, total_time_ms = 0;  // wall clock
    double cpu_time_ms = 0;  // the calling thread's CPU time over the whole estimate
    std::string BriefReport() const;
  };

  // trunk, generator (and knn, pose_mlp, pose_mlp_trunk if given) must outlive this.
  // pose_mlp_trunk: the trunk whose latents the pose MLP reads, when it is not `trunk`
  // (a generator trained through a larger trunk than the pose MLP's): its start then comes
  // from the frame's meta-SGD latent under pose_mlp_trunk, which must work at trunk's
  // frame format (the same targets serve both). Throws std::invalid_argument for bad
  // options, a generator whose latent_dim is not the trunk's, a pose MLP whose input is not
  // its trunk's latent, or formats that differ.
  GeneratorPosterior(const SensorTrunk& trunk, const PoseGenerator& generator,
                     const Options& options, const KnnPoseStarts* knn = nullptr,
                     const PoseMlp* pose_mlp = nullptr,
                     const SensorTrunk* pose_mlp_trunk = nullptr);

  // The posterior of one frame. tool = "" fits every tool of the generator; else only
  // that tool (throws std::invalid_argument if the generator does not know it).
  Summary Estimate(const TrunkTargets& targets, const std::string& tool,
                   PoseMixture* mixture) const;

  const Options& options() const { return options_; }

  // The starts of one tool's search (k-NN labels near `query`, the frame's meta-SGD
  // latent under the k-NN functaset's trunk (KnnPoseStarts::query_trunk, else this
  // posterior's); the pose MLP at it, or at `mlp_query` if given (the latent under the
  // pose MLP's own trunk); else a yaw grid at the centre; then the flipped yaws, the position
  // grid around the first start and the yaw grid at every start position, as Options
  // says). Estimate scores and refines them (FitPoseModes).
  // grids = false leaves out the position and yaw grids (the screening of tools).
  std::vector<PoseStart> Starts(const LatentProblem& problem, const Eigen::VectorXf& query,
                                int tool_index, const Eigen::VectorXf* mlp_query = nullptr,
                                bool grids = true) const;

 private:
  // Starts' two parts: the k-NN, pose MLP (or centre grid) starts, and those extended by
  // the flips and, if grids, the position and yaw grids.
  std::vector<PoseStart> BaseStarts(const Eigen::VectorXf& query, int tool_index,
                                    const Eigen::VectorXf* mlp_query) const;
  std::vector<PoseStart> ExpandStarts(std::vector<PoseStart> starts, int tool_index,
                                      bool grids) const;
  bool yaw_grid_active(int symmetry_order) const {
    return options_.yaw_grid > 1 && symmetry_order > 0 && 2 * symmetry_order <= options_.yaw_grid;
  }

  const SensorTrunk* trunk_;
  const PoseGenerator* generator_;
  Options options_;
  const KnnPoseStarts* knn_;
  const PoseMlp* pose_mlp_;
  const SensorTrunk* pose_mlp_trunk_;  // null: the pose MLP reads trunk_'s latents
};

// kappa such that the 90% regions of the best mode's Laplace Gaussian (x, y, yaw; sigma =
// RMS of the best mode) cover 90% of the truths of the given labelled frames: the root
// of the 0.9-quantile of the truths' squared Mahalanobis distances over chi2_3(0.9).
// Returns 0 if no frame gave a usable fit.
double CalibrateSigmaInflation(const GeneratorPosterior& posterior,
                               const std::vector<TrunkTargets>& frames,
                               const std::vector<PoseLabel>& labels);

// log Z_m(tau) of the header comment: the component's evidence with its likelihood
// tempered by 1/tau (tau > 0). At tau = 1, log_evidence.
double TemperedLogEvidence(const LaplaceComponent& component, double tau);

// One labelled frame for the weights' temperature: its mixture's components.
struct WeightTemperatureCase {
  std::vector<double> log_likelihood;  // each component's log_likelihood
  std::vector<double> log_density;     // log N_m(truth) of each component
  // log_evidence - log_likelihood of each component (empty: all 0), and its dimension
  // (empty: all 4).
  std::vector<double> log_occam;
  std::vector<int> dimension;
};

// tau of the header comment by temperature scaling on a proper score: the value on a log
// grid of 61 points over [min_temperature, 1] that maximises the summed log density of the
// truth under the mixture, sum_i log sum_m w_m(tau) N_m(truth_i) with w_m(tau) from
// TemperedLogEvidence, over the given labelled
// frames (each fitted with its tool known, with `posterior`'s kappa; N_m the component's
// (x, y, yaw) Gaussian, the truth folded by the tool's symmetry; (x, y) for n = 0). Frames
// with one component do not depend on tau and are left out. Modes near each other share
// the truth's density, so splitting one basin into two close modes does not pull tau up;
// a truth in a distant, lighter mode does. When the truth always lies in the heaviest
// mode the score grows as tau falls and the grid's floor is returned. `informative` (if
// given) receives the number of frames with two or more components, `heaviest_wrong` the
// number of those whose truth is nearest (Mahalanobis) to a component other than the
// heaviest. Returns 1 if no frame had two components. Throws std::invalid_argument unless
// 0 < min_temperature <= 1 and frames and labels have the same length.
double CalibrateWeightTemperature(const GeneratorPosterior& posterior,
                                  const std::vector<TrunkTargets>& frames,
                                  const std::vector<PoseLabel>& labels,
                                  double min_temperature = 0.05, int* informative = nullptr,
                                  int* heaviest_wrong = nullptr);

// CalibrateWeightTemperature's search on given cases (the grid and the rule for ties
// above). Returns 1 for no cases. Throws std::invalid_argument unless 0 < min_temperature
// <= 1 and every case has one log density (and, where given, one log_occam and one
// dimension) per log likelihood (at least one).
double FitWeightTemperature(const std::vector<WeightTemperatureCase>& cases,
                            double min_temperature = 0.05);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_SYNTHESIS_GENERATOR_POSTERIOR_H_
