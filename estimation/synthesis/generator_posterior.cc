// Copyright 2026 The tactfunc Authors.
#include "estimation/synthesis/generator_posterior.h"

#include <time.h>

#include <Eigen/Cholesky>
#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <algorithm>
#include <boost/random/mersenne_twister.hpp>
#include <boost/random/normal_distribution.hpp>
#include <boost/random/uniform_real_distribution.hpp>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <numeric>
#include <stdexcept>
#include <string>

#include "models/core/internal/log_sum_exp.h"
#include "models/core/seed.h"
#include "models/simulator/tool.h"

namespace tactfunc {
namespace {

constexpr double kChi2_3_90 = 6.251388631170325;  // chi-square(3) 0.9-quantile

// The inverse and the log-determinant of a Laplace Hessian (symmetric, positive
// semi-definite up to rounding) from its eigen-decomposition, the eigenvalues floored at
// 1e-12 of the largest: a direction the frame leaves (nearly) unconstrained gets a wide
// but positive variance, never the negative one an LU inverse of a near-singular matrix
// can round to. *log_det is -inf (the mode is then dropped) when every eigenvalue is 0.
template <int K>
Eigen::Matrix<double, K, K> LaplaceCovariance(const Eigen::Matrix<double, K, K>& hessian,
                                              double* log_det) {
  const Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, K, K>> eigen(
      0.5 * (hessian + hessian.transpose()));
  Eigen::Matrix<double, K, 1> values = eigen.eigenvalues();
  const double floor = 1e-12 * values.maxCoeff();
  if (!(floor > 0)) {
    *log_det = -std::numeric_limits<double>::infinity();
    return Eigen::Matrix<double, K, K>::Zero();
  }
  values = values.cwiseMax(floor);
  *log_det = values.array().log().sum();
  return eigen.eigenvectors() * values.cwiseInverse().asDiagonal() *
         eigen.eigenvectors().transpose();
}

double Ms(std::chrono::steady_clock::time_point a, std::chrono::steady_clock::time_point b) {
  return std::chrono::duration<double, std::milli>(b - a).count();
}

// The calling thread's CPU time, ms (what one core spends, whatever else runs).
double ThreadCpuMs() {
  timespec t{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &t);
  return 1e3 * t.tv_sec + 1e-6 * t.tv_nsec;
}

// The truth's yaw modulo the component's symmetry, nearest the component's mean.
SE2d Folded(const SE2d& t, const LaplaceComponent& c) {
  const double yaw = c.symmetry_order == 0 ? c.mean.yaw()
                                           : FoldYawNear(t.yaw(), c.mean.yaw(), c.symmetry_order);
  return SE2d::FromXYYaw(t.x(), t.y(), yaw);
}

// The squared Mahalanobis distance of t (folded) from c's mean over (x, y, yaw), or over
// (x, y) for a tool without yaw (n = 0).
double SquaredMahalanobis(const LaplaceComponent& c, const SE2d& t) {
  const SE2d::Tangent r = Folded(t, c).Minus(c.mean);
  if (c.symmetry_order == 0) {
    const Eigen::Vector2d v = r.head<2>();
    return v.dot(c.covariance.topLeftCorner<2, 2>().ldlt().solve(v));
  }
  return r.dot(c.covariance.topLeftCorner<3, 3>().ldlt().solve(r));
}

// log of c's Gaussian density at t (folded) over (x, y, yaw), or over (x, y) for n = 0;
// -infinity for a singular covariance.
double ComponentLogDensity(const LaplaceComponent& c, const SE2d& t) {
  const int k = c.symmetry_order == 0 ? 2 : 3;
  const double det = k == 2 ? c.covariance.topLeftCorner<2, 2>().determinant()
                            : c.covariance.topLeftCorner<3, 3>().determinant();
  if (!(det > 0)) return -std::numeric_limits<double>::infinity();
  return -0.5 * SquaredMahalanobis(c, t) - 0.5 * k * std::log(2 * M_PI) - 0.5 * std::log(det);
}

double ComponentDensity(const LaplaceComponent& c, const SE2d& t) {
  return std::exp(ComponentLogDensity(c, t));
}

// Appends every start of *starts turned by each of `offsets` (radians, in that order for
// each start), its source tagged with `suffix`. The turned starts are made from a copy
// of the list as it was: appending reallocates it.
void AppendTurnedStarts(const std::vector<double>& offsets, const std::string& suffix,
                        std::vector<PoseStart>* starts) {
  const std::vector<PoseStart> base = *starts;
  starts->reserve(base.size() * (1 + offsets.size()));
  for (const PoseStart& s : base) {
    const SE2d& p = s.sensor_T_object;
    for (double offset : offsets) {
      starts->push_back(
          {SE2d::FromXYYaw(p.x(), p.y(), p.yaw() + offset), s.depth_m, s.source + suffix});
    }
  }
}

}  // namespace

// ---- PoseMixture ------------------------------------------------------------------------

PoseMixture::PoseMixture(std::vector<LaplaceComponent> components)
    : components_(std::move(components)) {}

SE2d PoseMixture::Mode() const {
  if (components_.empty()) throw std::logic_error("PoseMixture::Mode: empty mixture");
  return std::max_element(components_.begin(), components_.end(),
                          [](const auto& a, const auto& b) { return a.weight < b.weight; })
      ->mean;
}

SE2d PoseMixture::Mean(const std::string& tool) const {
  std::string chosen = tool;
  if (chosen.empty()) {
    std::map<std::string, double> mass;
    for (const LaplaceComponent& c : components_) mass[c.tool] += c.weight;
    double best = -1;
    for (const auto& [name, m] : mass) {
      if (m > best) best = m, chosen = name;
    }
  }
  std::vector<SE2d> means;
  std::vector<double> weights;
  int symmetry_order = 1;
  const LaplaceComponent* heaviest = nullptr;
  for (const LaplaceComponent& c : components_) {
    if (c.tool != chosen) continue;
    means.push_back(c.mean);
    weights.push_back(c.weight);
    symmetry_order = c.symmetry_order;
    if (heaviest == nullptr || c.weight > heaviest->weight) heaviest = &c;
  }
  if (means.empty()) {
    throw std::invalid_argument("PoseMixture::Mean: no component" +
                                (chosen.empty() ? std::string() : " of tool '" + chosen + "'"));
  }
  if (!(std::accumulate(weights.begin(), weights.end(), 0.0) > 0)) weights.assign(means.size(), 1);
  const SE2d mean = PoseDistribution(std::move(means), std::move(weights))
                        .FoldedBySymmetry(symmetry_order)
                        .Mean();
  if (symmetry_order < 2) return mean;  // n = 0: yaw 0; n = 1: nothing was folded
  // Folding put the yaw in a representative of the fold's choosing; the same pose is
  // given in the one nearest the heaviest component, so that one component's mean is
  // that component's pose, not its equivalent turned by a multiple of 2 pi / n.
  const double anchor = heaviest->mean.yaw();
  return SE2d::FromXYYaw(mean.x(), mean.y(), anchor + FoldYaw(mean.yaw() - anchor, symmetry_order));
}

double PoseMixture::Density(const SE2d& t, const std::string& tool) const {
  double sum = 0, total = 0;
  for (const LaplaceComponent& c : components_) {
    if (!tool.empty() && c.tool != tool) continue;
    sum += c.weight * ComponentDensity(c, t);
    total += c.weight;
  }
  return total > 0 ? sum / total : 0;
}

PoseDistribution PoseMixture::Sample(int num, std::uint64_t seed, const std::string& tool) const {
  std::vector<const LaplaceComponent*> chosen;
  std::vector<double> cumulative;
  double total = 0;
  for (const LaplaceComponent& c : components_) {
    if (!tool.empty() && c.tool != tool) continue;
    total += c.weight;
    chosen.push_back(&c);
    cumulative.push_back(total);
  }
  if (chosen.empty() || !(total > 0)) {
    throw std::invalid_argument("PoseMixture::Sample: no component" +
                                (tool.empty() ? std::string() : " of tool '" + tool + "'"));
  }
  boost::random::mt19937_64 rng(seed);
  boost::random::uniform_real_distribution<double> u(0, total);
  boost::random::normal_distribution<double> g;
  std::vector<Eigen::Matrix3d> factors;
  for (const LaplaceComponent* c : chosen) {
    Eigen::Matrix3d s = c->covariance.topLeftCorner<3, 3>();
    s += 1e-18 * Eigen::Matrix3d::Identity();
    factors.push_back(s.llt().matrixL());
  }
  std::vector<SE2d> samples;
  samples.reserve(num);
  for (int i = 0; i < num; ++i) {
    const double pick = u(rng);
    const std::size_t k =
        std::min<std::size_t>(std::lower_bound(cumulative.begin(), cumulative.end(), pick) -
                                  cumulative.begin(),
                              chosen.size() - 1);
    const Eigen::Vector3d e(g(rng), g(rng), g(rng));
    SE2d s = chosen[k]->mean.Plus(factors[k] * e);
    if (chosen[k]->symmetry_order == 0) s = SE2d::FromXYYaw(s.x(), s.y(), 0);
    samples.push_back(s);
  }
  return PoseDistribution(std::move(samples));
}

bool PoseMixture::Contains(const SE2d& t, double p, int num_region_samples, std::uint64_t seed,
                           const std::string& tool) const {
  const PoseDistribution cloud = Sample(num_region_samples, seed, tool);
  std::vector<double> densities;
  densities.reserve(cloud.size());
  for (const SE2d& s : cloud.samples()) densities.push_back(Density(s, tool));
  std::sort(densities.begin(), densities.end());
  const std::size_t k = static_cast<std::size_t>(
      std::clamp(std::floor((1 - p) * densities.size()), 0.0, densities.size() - 1.0));
  return Density(t, tool) >= densities[k];
}

// ---- KnnPoseStarts ------------------------------------------------------------------------

KnnPoseStarts::KnnPoseStarts(const Functaset& functaset, SensorKind sensor,
                             const SensorTrunk* query_trunk)
    : query_trunk_(query_trunk) {
  std::map<std::string, std::vector<const FunctasetEntry*>> by_tool;
  for (const FunctasetEntry& e : functaset.entries(sensor)) {
    if (e.split == Split::kTrain && e.label.has_value()) by_tool[e.label->tool].push_back(&e);
  }
  if (by_tool.empty()) {
    throw std::invalid_argument("KnnPoseStarts: '" + functaset.source() + "' has no labelled " +
                                ToString(sensor) + " train entries");
  }
  const int d = functaset.latent_dim(sensor);
  latent_dim_ = d;
  if (query_trunk != nullptr && query_trunk->siren.latent_dim() != d) {
    throw std::invalid_argument("KnnPoseStarts: '" + functaset.source() + "' holds latents of " +
                                std::to_string(d) + " values, its query trunk's latent_dim is " +
                                std::to_string(query_trunk->siren.latent_dim()));
  }
  for (const auto& [tool, entries] : by_tool) {
    ToolIndex t;
    FlannKnnIndex::Options o;
    o.algorithm = FlannKnnIndex::Algorithm::kKdForest;
    t.index = std::make_unique<FlannKnnIndex>(d, o);
    std::vector<float> data(entries.size() * d);
    for (std::size_t i = 0; i < entries.size(); ++i) {
      std::copy(entries[i]->latent.data(), entries[i]->latent.data() + d, data.data() + i * d);
      t.labels.push_back(*entries[i]->label);
    }
    t.index->Add(data.data(), static_cast<std::int64_t>(entries.size()));
    size_ += static_cast<int>(entries.size());
    tools_.emplace(tool, std::move(t));
  }
}

std::vector<PoseStart> KnnPoseStarts::Starts(const Eigen::VectorXf& query, const std::string& tool,
                                             int k) const {
  std::vector<PoseStart> starts;
  auto it = tools_.find(tool);
  if (it == tools_.end() || k < 1) return starts;
  std::vector<float> distances(k);
  std::vector<std::int64_t> labels(k);
  it->second.index->Search(query.data(), 1, k, distances.data(), labels.data());
  for (int i = 0; i < k; ++i) {
    if (labels[i] < 0) continue;
    const PoseLabel& l = it->second.labels[labels[i]];
    starts.push_back({l.sensor_T_object, l.depth_m, "knn"});
  }
  return starts;
}

// ---- GeneratorPosterior ---------------------------------------------------------------------

LatentProblem::Options GeneratorPosterior::Options::DefaultProblem() {
  LatentProblem::Options o;
  o.max_pixels = 384;
  o.contact_share = 0.5;
  return o;
}

LatentProblem::Options GeneratorPosterior::Options::RankingProblem() const {
  LatentProblem::Options o = problem;
  if (final_pixels > 0) o.max_pixels = final_pixels;
  return o;
}

bool GeneratorPosterior::Options::IsValid(std::string* error) const {
  if (!problem.IsValid(error) || !fit.IsValid(error)) return false;
  auto fail = [&](const std::string& m) {
    if (error != nullptr) *error = "GeneratorPosterior::Options: " + m;
    return false;
  };
  if (knn_k < 0) return fail("knn_k must be >= 0");
  if (yaw_grid < 1) return fail("yaw_grid must be >= 1");
  if (coarse_pixels < 0) return fail("coarse_pixels must be >= 0");
  if (!(tool_prune_ratio == 0 || tool_prune_ratio >= 1)) {
    return fail("tool_prune_ratio must be 0 (off) or >= 1");
  }
  if (final_pixels < -1) return fail("final_pixels must be >= 0, or -1 for the generator's");
  if (position_grid_rings < 0) return fail("position_grid_rings must be >= 0");
  if (!(position_grid_m >= 0) || !std::isfinite(position_grid_m)) {
    return fail("position_grid_m must be finite and >= 0");
  }
  if (!(sigma_inflation >= 0) || !std::isfinite(sigma_inflation)) {
    return fail("sigma_inflation must be finite and >= 0");
  }
  if (!(weight_temperature >= 0) || !std::isfinite(weight_temperature)) {
    return fail("weight_temperature must be finite and >= 0");
  }
  if (num_region_samples < 10) return fail("num_region_samples must be >= 10");
  return true;
}

std::string GeneratorPosterior::Summary::BriefReport() const {
  char buffer[256];
  std::snprintf(buffer, sizeof(buffer),
                "GeneratorPosterior: %s, tool %s (p = %.3f), mode (%.3f mm, %.3f mm, %.2f deg), "
                "%d modes from %d starts, sigma %.4g, %.1f ms",
                usable ? "SUCCESS" : "FAILURE", tool.c_str(),
                tool_probabilities.count(tool) ? tool_probabilities.at(tool) : 0.0,
                1e3 * mean.x(), 1e3 * mean.y(), mean.yaw() * 180 / M_PI, num_modes, num_starts,
                sigma, total_time_ms);
  return std::string(buffer) + (message.empty() ? "" : ": " + message);
}

GeneratorPosterior::GeneratorPosterior(const SensorTrunk& trunk, const PoseGenerator& generator,
                                       const Options& options, const KnnPoseStarts* knn,
                                       const PoseMlp* pose_mlp, const SensorTrunk* pose_mlp_trunk)
    : trunk_(&trunk),
      generator_(&generator),
      options_(options),
      knn_(knn),
      pose_mlp_(pose_mlp),
      pose_mlp_trunk_(pose_mlp_trunk == &trunk ? nullptr : pose_mlp_trunk) {
  std::string error;
  if (!options_.IsValid(&error)) throw std::invalid_argument(error);
  if (options_.final_pixels < 0) options_.final_pixels = generator.final_pixels();
  if (trunk.photometric != nullptr) {
    throw std::invalid_argument(
        "GeneratorPosterior: renders through the direct trunk; the photometric trunk has no "
        "pose generator yet");
  }
  if (generator.latent_dim() != trunk.siren.latent_dim()) {
    throw std::invalid_argument("GeneratorPosterior: the generator's latent_dim " +
                                std::to_string(generator.latent_dim()) + " is not the trunk's " +
                                std::to_string(trunk.siren.latent_dim()));
  }
  // A trunk that reads the frame's latent for a query (the k-NN functaset's, the pose
  // MLP's) takes the same targets as the renderer.
  auto check_same_frames = [&trunk](const SensorTrunk& other, const std::string& whose) {
    if (!trunk.format.SameAs(other.format) || other.photometric != nullptr) {
      throw std::invalid_argument(
          "GeneratorPosterior: " + whose + " works at another frame format (or is "
          "photometric) than the generator's trunk; the frame's targets cannot serve both");
    }
  };
  if (knn != nullptr) {
    const SensorTrunk& knn_trunk = knn->query_trunk() != nullptr ? *knn->query_trunk() : trunk;
    if (knn->latent_dim() != knn_trunk.siren.latent_dim()) {
      throw std::invalid_argument(
          "GeneratorPosterior: the k-NN functaset's latents are not its query trunk's (" +
          std::to_string(knn->latent_dim()) + " against " +
          std::to_string(knn_trunk.siren.latent_dim()) + " values)");
    }
    check_same_frames(knn_trunk, "the k-NN query trunk");
  }
  const SensorTrunk& mlp_trunk = pose_mlp_trunk_ != nullptr ? *pose_mlp_trunk_ : trunk;
  if (pose_mlp != nullptr && pose_mlp->input_dim() != mlp_trunk.siren.latent_dim()) {
    throw std::invalid_argument(
        "GeneratorPosterior: the pose MLP's input_dim is not its trunk's latent_dim");
  }
  if (pose_mlp_trunk_ != nullptr) check_same_frames(*pose_mlp_trunk_, "the pose MLP's trunk");
}

std::vector<PoseStart> GeneratorPosterior::Starts(const LatentProblem& problem,
                                                  const Eigen::VectorXf& query, int tool_index,
                                                  const Eigen::VectorXf* mlp_query,
                                                  bool grids) const {
  (void)problem;
  return ExpandStarts(BaseStarts(query, tool_index, mlp_query), tool_index, grids);
}

std::vector<PoseStart> GeneratorPosterior::BaseStarts(const Eigen::VectorXf& query,
                                                      int tool_index,
                                                      const Eigen::VectorXf* mlp_query) const {
  const std::string& tool = generator_->options().tools[tool_index];
  const int n = generator_->SymmetryOrder(tool_index);
  std::vector<PoseStart> starts;
  if (knn_ != nullptr) starts = knn_->Starts(query, tool, options_.knn_k);
  if (pose_mlp_ != nullptr) {
    const SE2d p =
        pose_mlp_->Predict((mlp_query != nullptr ? *mlp_query : query).cast<double>(), n);
    starts.push_back({p, 0.5 * (options_.fit.depth_min_m + options_.fit.depth_max_m), "mlp"});
  }
  if (knn_ == nullptr) {
    // No labelled neighbours: a coarse grid over yaw at the centre.
    const int count = n == 0 ? 1 : std::max(1, 8 / std::max(1, n));
    for (int k = 0; k < count; ++k) {
      const double yaw = (n == 0 ? 0 : 2 * M_PI / std::max(1, n)) * k / count;
      starts.push_back({SE2d::FromXYYaw(0, 0, yaw), 0.009, "grid"});
    }
  }
  return starts;
}

std::vector<PoseStart> GeneratorPosterior::ExpandStarts(std::vector<PoseStart> starts,
                                                        int tool_index, bool grids) const {
  const int n = generator_->SymmetryOrder(tool_index);
  const bool yaw_grid = grids && yaw_grid_active(n);
  if (options_.flip_starts && n == 1 && !yaw_grid) {
    AppendTurnedStarts({M_PI}, "+pi", &starts);
  }
  if (grids && options_.position_grid_m > 0 && !starts.empty()) {
    const PoseStart first = starts.front();
    const double h = options_.position_grid_m;
    const int rings = options_.position_grid_rings;
    for (int a = -rings; a <= rings; ++a) {
      for (int b = -rings; b <= rings; ++b) {
        if (a == 0 && b == 0) continue;
        const SE2d& p = first.sensor_T_object;
        starts.push_back({SE2d::FromXYYaw(p.x() + a * h, p.y() + b * h, p.yaw()), first.depth_m,
                          first.source + "+shift"});
      }
    }
  }
  if (yaw_grid) {
    // Every start position at the grid's yaws (those inside one symmetry period).
    const int grid = options_.yaw_grid;
    const double period = 2 * M_PI / n;
    std::vector<double> offsets;
    for (int k = 1; k < grid; ++k) {
      const double offset = 2 * M_PI * k / grid;
      if (offset > period - 1e-9) break;
      offsets.push_back(offset);
    }
    AppendTurnedStarts(offsets, "+grid", &starts);
  }
  return starts;
}

GeneratorPosterior::Summary GeneratorPosterior::Estimate(const TrunkTargets& targets,
                                                         const std::string& tool,
                                                         PoseMixture* mixture) const {
  const auto t0 = std::chrono::steady_clock::now();
  const double cpu0 = ThreadCpuMs();
  std::vector<int> candidates;
  if (tool.empty()) {
    for (int i = 0; i < generator_->num_tools(); ++i) candidates.push_back(i);
  } else {
    const int index = generator_->ToolIndex(tool);
    if (index < 0) {
      std::string names;
      for (const std::string& t : generator_->options().tools) names += (names.empty() ? "" : ", ") + t;
      throw std::invalid_argument("GeneratorPosterior: the generator does not know tool '" + tool +
                                  "' (it knows " + names + ")");
    }
    candidates.push_back(index);
  }
  Summary summary;
  const LatentProblem problem(*trunk_, targets, options_.problem);
  std::optional<LatentProblem> final_problem;
  if (options_.final_pixels > 0) final_problem.emplace(*trunk_, targets, options_.RankingProblem());
  // The problem the Laplace approximations are taken on.
  const LatentProblem& laplace_problem = final_problem ? *final_problem : problem;
  std::optional<LatentProblem> coarse;
  if (options_.coarse_pixels > 0 && options_.coarse_pixels < problem.num_pixels()) {
    LatentProblem::Options co = options_.problem;
    co.max_pixels = options_.coarse_pixels;
    coarse.emplace(*trunk_, targets, co);
  }
  if (problem.num_pixels() == 0) {
    summary.message = "the frame has no valid pixel";
    if (mixture != nullptr) *mixture = PoseMixture();
    return summary;
  }
  // The frame's latent as its trunk's encoder gives it: meta-SGD from z = 0.
  auto meta_sgd_latent = [](const LatentProblem& p) -> Eigen::VectorXf {
    return p.MetaSgdSteps(Eigen::VectorXd::Zero(p.dim()), p.trunk().meta_sgd.inner_steps)
        .cast<float>();
  };
  // The frame's latent under each trunk a query needs (the renderer's, the k-NN
  // functaset's, the pose MLP's), each computed once: the same pixels under that trunk.
  std::vector<std::pair<const SensorTrunk*, Eigen::VectorXf>> latents;
  auto latent_under = [&](const SensorTrunk* t) -> const Eigen::VectorXf& {
    if (t == nullptr) t = trunk_;
    for (const auto& [known, z] : latents) {
      if (known == t) return z;
    }
    // (Not a conditional expression: that would copy `problem`.)
    if (t == trunk_) {
      latents.emplace_back(t, meta_sgd_latent(problem));
    } else {
      latents.emplace_back(t, meta_sgd_latent(LatentProblem(*t, targets, options_.problem)));
    }
    return latents.back().second;
  };
  Eigen::VectorXf query, mlp_query;
  if (knn_ != nullptr) query = latent_under(knn_->query_trunk());
  if (pose_mlp_ != nullptr) mlp_query = latent_under(pose_mlp_trunk_);
  struct ToolModes {
    int tool;
    std::vector<PoseFit> modes;
  };
  std::vector<ToolModes> all;
  double best_msr = std::numeric_limits<double>::infinity();
  // The search's modes of tool t, refined once more on the final problem (step 2b).
  auto keep = [&](int t, std::vector<PoseFit> modes) {
    ++summary.tools_refined;
    ToolModes tm{t, std::move(modes)};
    if (final_problem) {
      // Step 2b: each distinct mode refined again, as a start of its own.
      std::vector<PoseStart> starts;
      for (const PoseFit& f : tm.modes) starts.push_back({f.sensor_T_object, f.depth_m, f.start});
      PoseFitOptions fo = options_.fit;
      fo.max_refined_starts = std::max(1, static_cast<int>(starts.size()));
      tm.modes = FitPoseModes(*final_problem, *generator_, t, starts, fo, nullptr);
    }
    for (const PoseFit& f : tm.modes) best_msr = std::min(best_msr, f.mean_squared_residual);
    all.push_back(std::move(tm));
  };
  // Each tool's k-NN and pose MLP starts, made once for the screening and the coarse stage.
  std::map<int, std::vector<PoseStart>> base_starts;
  auto starts_of = [&](int t, bool grids = true) {
    auto it = base_starts.find(t);
    if (it == base_starts.end()) {
      it = base_starts
               .emplace(t, BaseStarts(query, t, pose_mlp_ != nullptr ? &mlp_query : nullptr))
               .first;
    }
    std::vector<PoseStart> starts = ExpandStarts(it->second, t, grids);
    summary.num_starts += static_cast<int>(starts.size());
    return starts;
  };
  if (coarse) {
    const bool prune = candidates.size() > 1 && options_.tool_prune_ratio > 0;
    // The tools that go on: a screening coarse stage without the grids first, if asked.
    std::vector<char> goes_on(candidates.size(), 1);
    auto prune_by = [&](const std::vector<double>& costs) {
      const double lowest = *std::min_element(costs.begin(), costs.end());
      for (std::size_t i = 0; i < candidates.size(); ++i) {
        if (!(costs[i] <= options_.tool_prune_ratio * lowest)) goes_on[i] = 0;
      }
    };
    if (prune && options_.tool_screen) {
      std::vector<double> costs;
      for (int t : candidates) {
        costs.push_back(
            CoarsePoseStarts(*coarse, *generator_, t, starts_of(t, false), options_.fit)
                .BestCost());
      }
      prune_by(costs);
    }
    // The coarse stage for every candidate left first, so that tools can be compared after
    // it.
    std::vector<CoarseStarts> first(candidates.size());
    std::vector<double> costs(candidates.size(), std::numeric_limits<double>::infinity());
    for (std::size_t i = 0; i < candidates.size(); ++i) {
      if (!goes_on[i]) continue;
      ++summary.tools_screened_in;
      first[i] = CoarsePoseStarts(*coarse, *generator_, candidates[i], starts_of(candidates[i]),
                                  options_.fit);
      costs[i] = first[i].BestCost();
    }
    if (prune) prune_by(costs);
    for (std::size_t i = 0; i < candidates.size(); ++i) {
      if (!goes_on[i]) continue;
      keep(candidates[i],
           FitPoseModesFromCoarse(problem, *generator_, candidates[i], first[i], options_.fit));
    }
  } else {
    summary.tools_screened_in = static_cast<int>(candidates.size());  // no screening
    for (int t : candidates) {
      keep(t, FitPoseModes(problem, *generator_, t, starts_of(t), options_.fit, nullptr));
    }
  }
  const auto t1 = std::chrono::steady_clock::now();
  summary.fit_time_ms = Ms(t0, t1);
  if (!std::isfinite(best_msr)) {
    summary.message = "no fit converged to a usable mode";
    if (mixture != nullptr) *mixture = PoseMixture();
    summary.total_time_ms = Ms(t0, std::chrono::steady_clock::now());
    summary.cpu_time_ms = ThreadCpuMs() - cpu0;
    return summary;
  }
  double kappa = options_.sigma_inflation > 0 ? options_.sigma_inflation
                                              : generator_->sigma_inflation();
  if (!(kappa > 0)) kappa = 3;
  summary.rms_residual = std::sqrt(best_msr);
  summary.num_pixels = laplace_problem.num_pixels();
  summary.pixel_factor = std::sqrt(
      laplace_problem.num_pixels() /
      std::min(kReferencePixels, static_cast<double>(laplace_problem.num_valid_pixels())));
  summary.sigma = kappa * std::max(summary.rms_residual, 1e-6) * summary.pixel_factor;
  // r_s^2 = r_0^2 scale
  const double scale = std::pow(laplace_problem.sigma() / summary.sigma, 2);

  std::vector<LaplaceComponent> components;
  for (const ToolModes& tm : all) {
    const int n = generator_->SymmetryOrder(tm.tool);
    for (const PoseFit& f : tm.modes) {
      LaplaceComponent c;
      c.tool = generator_->options().tools[tm.tool];
      c.symmetry_order = n;
      c.mean = f.sensor_T_object;
      c.depth_m = f.depth_m;
      c.start = f.start;
      const Eigen::Matrix4d H = f.JtJ * scale;
      double log_det = 0;
      int k = 4;
      if (n == 0) {
        k = 3;
        Eigen::Matrix3d h3;
        const int idx[3] = {0, 1, 3};
        for (int a = 0; a < 3; ++a) {
          for (int b = 0; b < 3; ++b) h3(a, b) = H(idx[a], idx[b]);
        }
        const Eigen::Matrix3d s3 = LaplaceCovariance<3>(h3, &log_det);
        for (int a = 0; a < 3; ++a) {
          for (int b = 0; b < 3; ++b) c.covariance(idx[a], idx[b]) = s3(a, b);
        }
      } else {
        c.covariance = LaplaceCovariance<4>(H, &log_det);
      }
      c.dimension = k;
      c.log_likelihood = -f.cost * scale;
      c.log_evidence = c.log_likelihood + 0.5 * k * std::log(2 * M_PI) - 0.5 * log_det +
                       (n == 0 ? std::log(2 * M_PI) : std::log(static_cast<double>(n)));
      if (std::isfinite(c.log_evidence) && c.covariance.allFinite()) components.push_back(c);
    }
  }
  if (components.empty()) {
    summary.message = "every mode had a singular Hessian";
    if (mixture != nullptr) *mixture = PoseMixture();
    summary.total_time_ms = Ms(t0, std::chrono::steady_clock::now());
    summary.cpu_time_ms = ThreadCpuMs() - cpu0;
    return summary;
  }
  double tau = options_.weight_temperature > 0 ? options_.weight_temperature
                                               : generator_->weight_temperature();
  if (!(tau > 0)) tau = 1;
  // A generator calibrated before the likelihood alone was tempered keeps the weights its
  // tau was calibrated for, Z^(1/tau) (PoseGenerator::weight_temperature_on_likelihood).
  const bool on_evidence =
      !(options_.weight_temperature > 0) && !generator_->weight_temperature_on_likelihood();
  auto log_weight = [&](const LaplaceComponent& c) {
    return on_evidence ? c.log_evidence / tau : TemperedLogEvidence(c, tau);
  };
  double max_log = -std::numeric_limits<double>::infinity();
  for (const LaplaceComponent& c : components) max_log = std::max(max_log, log_weight(c));
  double total = 0;
  for (LaplaceComponent& c : components) total += c.weight = std::exp(log_weight(c) - max_log);
  for (LaplaceComponent& c : components) {
    c.weight /= total;
    summary.tool_probabilities[c.tool] += c.weight;
  }
  for (int t : candidates) summary.tool_probabilities[generator_->options().tools[t]] += 0;
  std::stable_sort(components.begin(), components.end(),
                   [](const auto& a, const auto& b) { return a.weight > b.weight; });
  summary.tool = std::max_element(summary.tool_probabilities.begin(),
                                  summary.tool_probabilities.end(),
                                  [](const auto& a, const auto& b) { return a.second < b.second; })
                     ->first;
  for (const LaplaceComponent& c : components) {
    if (c.tool == summary.tool) {
      summary.mean = c.mean;
      summary.covariance = c.covariance.topLeftCorner<3, 3>();
      break;
    }
  }
  summary.num_modes = static_cast<int>(components.size());
  summary.usable = true;
  if (mixture != nullptr) *mixture = PoseMixture(std::move(components));
  summary.total_time_ms = Ms(t0, std::chrono::steady_clock::now());
  summary.cpu_time_ms = ThreadCpuMs() - cpu0;
  return summary;
}

double CalibrateSigmaInflation(const GeneratorPosterior& posterior,
                               const std::vector<TrunkTargets>& frames,
                               const std::vector<PoseLabel>& labels) {
  if (frames.size() != labels.size()) {
    throw std::invalid_argument("CalibrateSigmaInflation: one label per frame expected");
  }
  std::vector<double> d2;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    PoseMixture mixture;
    const GeneratorPosterior::Summary s = posterior.Estimate(frames[i], labels[i].tool, &mixture);
    if (!s.usable) continue;
    const LaplaceComponent& c = mixture.components().front();
    // Mahalanobis distance at kappa = 1: the covariance scales with kappa^2.
    const double kappa = s.sigma / std::max(s.rms_residual, 1e-6) / s.pixel_factor;
    const Eigen::Matrix3d cov = c.covariance.topLeftCorner<3, 3>() / (kappa * kappa);
    const SE2d::Tangent r = Folded(labels[i].sensor_T_object, c).Minus(c.mean);
    if (c.symmetry_order == 0) {
      const Eigen::Vector2d v = r.head<2>();
      // Scale a 2-d distance to the 3-d quantile: chi2_2(0.9) = 4.605.
      d2.push_back(v.dot(cov.topLeftCorner<2, 2>().ldlt().solve(v)) * kChi2_3_90 / 4.605170186);
    } else {
      d2.push_back(r.dot(cov.ldlt().solve(r)));
    }
  }
  if (d2.empty()) return 0;
  std::sort(d2.begin(), d2.end());
  const double q = d2[std::min(d2.size() - 1, static_cast<std::size_t>(0.9 * d2.size()))];
  return std::sqrt(q / kChi2_3_90);
}

namespace {

// The floor of the temperature grid: in (0, 1].
void CheckMinTemperature(const char* who, double min_temperature) {
  if (!(min_temperature > 0 && min_temperature <= 1)) {
    throw std::invalid_argument(std::string(who) + ": min_temperature must lie in (0, 1], got " +
                                std::to_string(min_temperature));
  }
}

}  // namespace

double TemperedLogEvidence(const LaplaceComponent& component, double tau) {
  return component.log_likelihood / tau + (component.log_evidence - component.log_likelihood) +
         0.5 * component.dimension * std::log(tau);
}

double CalibrateWeightTemperature(const GeneratorPosterior& posterior,
                                  const std::vector<TrunkTargets>& frames,
                                  const std::vector<PoseLabel>& labels, double min_temperature,
                                  int* informative, int* heaviest_wrong) {
  if (frames.size() != labels.size()) {
    throw std::invalid_argument("CalibrateWeightTemperature: one label per frame expected");
  }
  CheckMinTemperature("CalibrateWeightTemperature", min_temperature);  // before the fits
  std::vector<WeightTemperatureCase> cases;
  int wrong = 0;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    PoseMixture mixture;
    const GeneratorPosterior::Summary s = posterior.Estimate(frames[i], labels[i].tool, &mixture);
    if (!s.usable || mixture.components().size() < 2) continue;
    WeightTemperatureCase wc;
    std::size_t nearest = 0;
    double best_d2 = std::numeric_limits<double>::infinity();
    for (std::size_t m = 0; m < mixture.components().size(); ++m) {
      const LaplaceComponent& c = mixture.components()[m];
      wc.log_likelihood.push_back(c.log_likelihood);
      wc.log_occam.push_back(c.log_evidence - c.log_likelihood);
      wc.dimension.push_back(c.dimension);
      wc.log_density.push_back(ComponentLogDensity(c, labels[i].sensor_T_object));
      const double d2 = SquaredMahalanobis(c, labels[i].sensor_T_object);
      if (d2 < best_d2) best_d2 = d2, nearest = m;
    }
    if (!std::isfinite(*std::max_element(wc.log_density.begin(), wc.log_density.end()))) continue;
    // The components come heaviest first.
    if (nearest != 0) ++wrong;
    cases.push_back(std::move(wc));
  }
  if (informative != nullptr) *informative = static_cast<int>(cases.size());
  if (heaviest_wrong != nullptr) *heaviest_wrong = wrong;
  return FitWeightTemperature(cases, min_temperature);
}

double FitWeightTemperature(const std::vector<WeightTemperatureCase>& cases,
                            double min_temperature) {
  CheckMinTemperature("FitWeightTemperature", min_temperature);
  // Each case's components as the posterior holds them (the fields TemperedLogEvidence
  // reads), made once for the whole grid.
  std::vector<std::vector<LaplaceComponent>> components;
  for (const WeightTemperatureCase& c : cases) {
    const std::size_t m = c.log_likelihood.size();
    if (m == 0 || c.log_density.size() != m || !(c.log_occam.empty() || c.log_occam.size() == m) ||
        !(c.dimension.empty() || c.dimension.size() == m)) {
      throw std::invalid_argument(
          "FitWeightTemperature: a case needs one log density (and one log_occam and dimension "
          "where given) per log likelihood, got " + std::to_string(c.log_density.size()) + ", " +
          std::to_string(c.log_occam.size()) + " and " + std::to_string(c.dimension.size()) +
          " for " + std::to_string(m));
    }
    std::vector<LaplaceComponent>& made = components.emplace_back(m);
    for (std::size_t k = 0; k < m; ++k) {
      made[k].log_likelihood = c.log_likelihood[k];
      made[k].log_evidence = c.log_likelihood[k] + (c.log_occam.empty() ? 0 : c.log_occam[k]);
      made[k].dimension = c.dimension.empty() ? 4 : c.dimension[k];
    }
  }
  if (cases.empty()) return 1;
  constexpr int kGrid = 61;
  double best_tau = 1, best_score = -std::numeric_limits<double>::infinity();
  for (int g = 0; g < kGrid; ++g) {
    const double tau = std::exp(std::log(min_temperature) * g / (kGrid - 1.0));  // 1 first
    double score = 0;
    for (std::size_t i = 0; i < cases.size(); ++i) {
      // log sum_m w_m p_m with w = softmax(log Z(tau)), both sums by log-sum-exp.
      const std::size_t size = components[i].size();
      std::vector<double> log_weight(size), joint(size);
      for (std::size_t m = 0; m < size; ++m) {
        log_weight[m] = TemperedLogEvidence(components[i][m], tau);
        joint[m] = log_weight[m] + cases[i].log_density[m];
      }
      score += internal::LogSumExp(joint) - internal::LogSumExp(log_weight);
    }
    // Ties (the weights saturated) keep the larger tau.
    if (score > best_score + 1e-12) best_score = score, best_tau = tau;
  }
  return best_tau;
}

}  // namespace tactfunc
