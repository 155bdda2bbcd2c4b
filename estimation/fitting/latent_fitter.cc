// Copyright 2026 The tactfunc Authors.
#include "estimation/fitting/latent_fitter.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <mutex>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <utility>
#include <vector>

#include "ceres/problem.h"
#include "estimation/fitting/latent_costs.h"
#include "estimation/fitting/square_root_cost.h"
#include "models/core/internal/elapsed.h"

namespace tactfunc {
namespace {

using Clock = std::chrono::steady_clock;

using internal::MsSince;

const char* kStrategyForms =
    "expected one of knn, meta_sgd:K, ceres:N, knn+meta_sgd:K, knn+ceres:N, adam:N, "
    "knn+adam:N (K >= 0, N >= 1 integers; adam:N and knn+adam:N for photometric trunks)";

bool ParseCount(const std::string& text, int* value) {
  if (text.empty() || text.size() > 9) return false;
  for (char ch : text) {
    if (ch < '0' || ch > '9') return false;
  }
  *value = std::stoi(text);
  return true;
}

std::string Format(const char* format, double value) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), format, value);
  return buffer;
}

}  // namespace

// ---- FitStrategy -----------------------------------------------------------------------

bool FitStrategy::Parse(const std::string& text, FitStrategy* strategy, std::string* error) {
  auto fail = [&](const std::string& why) {
    if (error != nullptr) *error = "bad fit strategy '" + text + "': " + why + "; " + kStrategyForms;
    return false;
  };
  FitStrategy out;
  std::string rest = text;
  if (rest == "knn") {
    out.knn = true;
    out.refinement = Refinement::kNone;
    out.steps = 0;
    *strategy = out;
    return true;
  }
  if (rest.rfind("knn+", 0) == 0) {
    out.knn = true;
    rest = rest.substr(4);
  }
  const size_t colon = rest.find(':');
  const std::string name = rest.substr(0, colon);
  if (name == "meta_sgd") {
    out.refinement = Refinement::kMetaSgd;
  } else if (name == "ceres") {
    out.refinement = Refinement::kCeres;
  } else if (name == "adam") {
    out.refinement = Refinement::kAdam;
  } else if (name.empty()) {
    return fail("no method");
  } else {
    return fail("unknown method '" + name + "'");
  }
  if (colon == std::string::npos) return fail("'" + name + "' needs a step count, as " + name + ":10");
  if (!ParseCount(rest.substr(colon + 1), &out.steps)) {
    return fail("step count '" + rest.substr(colon + 1) + "' is not a non-negative integer");
  }
  std::string why;
  if (!out.IsValid(&why)) return fail(why);
  *strategy = out;
  return true;
}

FitStrategy FitStrategy::FromString(const std::string& text) {
  FitStrategy strategy;
  std::string error;
  if (!Parse(text, &strategy, &error)) throw std::invalid_argument(error);
  return strategy;
}

std::string FitStrategy::ToString() const {
  std::string out = knn ? "knn" : "";
  switch (refinement) {
    case Refinement::kNone:
      return knn ? out : "none";
    case Refinement::kMetaSgd:
      return out + (knn ? "+" : "") + "meta_sgd:" + std::to_string(steps);
    case Refinement::kCeres:
      return out + (knn ? "+" : "") + "ceres:" + std::to_string(steps);
    case Refinement::kAdam:
      return out + (knn ? "+" : "") + "adam:" + std::to_string(steps);
  }
  return "unknown";
}

bool FitStrategy::IsValid(std::string* error) const {
  std::string message;
  if (refinement == Refinement::kNone && !knn) {
    message = "a strategy without knn needs a refinement (meta_sgd:K or ceres:N)";
  } else if (refinement == Refinement::kMetaSgd && steps < 0) {
    message = "meta_sgd:K needs K >= 0, found " + std::to_string(steps);
  } else if (refinement == Refinement::kCeres && steps < 1) {
    message = "ceres:N needs N >= 1, found " + std::to_string(steps);
  } else if (refinement == Refinement::kAdam && steps < 1) {
    message = "adam:N needs N >= 1, found " + ToString();
  } else if (refinement != Refinement::kNone && refinement != Refinement::kMetaSgd &&
             refinement != Refinement::kCeres && refinement != Refinement::kAdam) {
    message = "refinement is not a Refinement";
  } else {
    return true;
  }
  if (error != nullptr) *error = message;
  return false;
}

// ---- Names -------------------------------------------------------------------------------

const char* ToString(FitTermination termination) {
  switch (termination) {
    case FitTermination::kCompleted:
      return "COMPLETED";
    case FitTermination::kConvergence:
      return "CONVERGENCE";
    case FitTermination::kNoConvergence:
      return "NO_CONVERGENCE";
    case FitTermination::kNoValidPixels:
      return "NO_VALID_PIXELS";
    case FitTermination::kFailure:
      return "FAILURE";
  }
  return "UNKNOWN";
}

const char* ToString(LatentFitter::JacobianMode jacobian) {
  return jacobian == LatentFitter::JacobianMode::kAnalytic ? "analytic" : "autodiff";
}

// ---- Options -------------------------------------------------------------------------------

LatentFitter::Options::Options() {
  strategy.knn = false;
  strategy.refinement = FitStrategy::Refinement::kCeres;
  strategy.steps = 10;
  solver_options.minimizer_type = ceres::TRUST_REGION;
  solver_options.trust_region_strategy_type = ceres::LEVENBERG_MARQUARDT;
  solver_options.linear_solver_type = ceres::DENSE_NORMAL_CHOLESKY;
  solver_options.num_threads = 1;
  solver_options.logging_type = ceres::SILENT;
  solver_options.minimizer_progress_to_stdout = false;
}

bool LatentFitter::Options::IsValid(std::string* error) const {
  std::ostringstream message;
  std::string why;
  if (!strategy.IsValid(&why)) {
    message << "strategy: " << why;
  } else if (jacobian != JacobianMode::kAnalytic && jacobian != JacobianMode::kAutoDiff) {
    message << "jacobian is not a JacobianMode, found " << static_cast<int>(jacobian);
  } else if (residual_form != ResidualForm::kSquareRoot &&
             residual_form != ResidualForm::kPerPixel) {
    message << "residual_form is not a ResidualForm, found " << static_cast<int>(residual_form);
  } else if (knn_k < 1) {
    message << "knn_k must be >= 1, found " << knn_k;
  } else if (solver_options.minimizer_type != ceres::TRUST_REGION) {
    message << "solver_options.minimizer_type must be TRUST_REGION (LM or dogleg)";
  } else if (!solver_options.IsValid(&why)) {
    message << "solver_options: " << why;
  } else {
    return true;
  }
  if (error != nullptr) *error = "LatentFitter::Options::" + message.str();
  return false;
}

// ---- Summary ---------------------------------------------------------------------------------

bool LatentFitter::Summary::IsSolutionUsable() const {
  return termination_type != FitTermination::kFailure &&
         termination_type != FitTermination::kNoValidPixels;
}

std::string LatentFitter::Summary::BriefReport() const {
  std::ostringstream out;
  out << "LatentFitter " << strategy.ToString() << ": " << tactfunc::ToString(termination_type)
      << ", cost " << Format("%.4g", initial_cost) << " -> " << Format("%.4g", final_cost)
      << ", PSNR " << Format("%.2f", psnr) << " dB, " << iterations << " iterations, "
      << Format("%.2f", total_time_ms) << " ms";
  if (!message.empty()) out << " (" << message << ")";
  return out.str();
}

std::string LatentFitter::Summary::FullReport() const {
  std::ostringstream out;
  out << BriefReport() << "\n";
  out << "  pixels: " << num_pixels_used << " used of " << num_valid_pixels << " valid, "
      << num_residuals << " residuals; sigma " << sigma << ", sigma_z " << sigma_z << "\n";
  for (const Stage& stage : stages) {
    out << "  stage " << stage.name << ": cost " << Format("%.6g", stage.cost) << ", "
        << stage.iterations << " iterations, " << Format("%.3f", stage.time_ms) << " ms\n";
  }
  if (!neighbor_labels.empty()) {
    out << "  neighbours (label: squared distance, weight):";
    for (size_t i = 0; i < neighbor_labels.size(); ++i) {
      out << " " << neighbor_labels[i] << ": " << Format("%.4g", neighbor_squared_distances[i])
          << ", " << Format("%.3f", neighbor_weights[i]) << ";";
    }
    out << "\n";
  }
  // Ceres' own full report: its iterations and where its time went (residual and
  // Jacobian evaluations, the linear solver).
  if (ceres_ran) {
    if (ceres_residual_form == ResidualForm::kSquareRoot) {
      out << "  ceres saw U as " << solver_summary.num_residuals
          << " residuals, its square-root information form (same steps as per pixel)\n";
    }
    out << "  ceres: " << solver_summary.FullReport() << "\n";
  }
  return out.str();
}

// ---- LatentFitter ---------------------------------------------------------------------------

LatentFitter::LatentFitter(const SensorTrunk& trunk, const Options& options)
    : LatentFitter(trunk, options, nullptr, nullptr) {}

struct LatentFitter::StartPasses {
  // A handful of frame sizes per trunk at most, each at most 2^24 Jacobian values (64 MB;
  // the 70 x 88 Soft Bubble at d = 64 needs 0.39 M); beyond that fits evaluate as usual.
  static constexpr std::size_t kMaxSizes = 4;
  static constexpr long kMaxJacobianValues = 1L << 24;
  std::mutex mutex;
  std::vector<std::unique_ptr<const StartPass>> passes;
};

const StartPass* LatentFitter::StartPassFor(const LatentProblem& problem) const {
  // Only the fitter's own trunk, which outlives it unchanged: a pass of another trunk
  // object could outlive that object.
  if (&problem.trunk() != trunk_ || options_.jacobian != JacobianMode::kAnalytic ||
      !StartPass::Applies(problem.trunk()) ||
      problem.options().precision != LatentProblem::Precision::kFloat) {
    return nullptr;
  }
  if (static_cast<long>(problem.targets().rows) * problem.targets().cols * problem.channels() *
          problem.dim() >
      StartPasses::kMaxJacobianValues) {
    return nullptr;
  }
  const std::lock_guard<std::mutex> lock(start_passes_->mutex);
  for (const auto& pass : start_passes_->passes) {
    if (problem.CanUse(*pass)) return pass.get();
  }
  if (start_passes_->passes.size() >= StartPasses::kMaxSizes) return nullptr;
  start_passes_->passes.push_back(std::make_unique<const StartPass>(
      problem.trunk(), problem.targets().rows, problem.targets().cols));
  return start_passes_->passes.back().get();
}

LatentFitter::LatentFitter(const SensorTrunk& trunk, const Options& options,
                           const KnnIndex* index, const Eigen::MatrixXf* latents)
    : start_passes_(std::make_shared<StartPasses>()),
      trunk_(&trunk),
      options_(options),
      index_(index),
      latents_(latents) {
  std::string error;
  if (!options_.IsValid(&error)) throw std::invalid_argument(error);
  if (trunk.photometric != nullptr || options_.strategy.refinement == FitStrategy::Refinement::kAdam) {
    throw std::invalid_argument(
        "LatentFitter: fits the direct trunk with meta_sgd:K or ceres:N; a photometric "
        "trunk's latents are fitted by FitPhotometricLatent (adam:N)");
  }
  const int d = trunk.siren.latent_dim();
  if (trunk.alpha.size() != d) {
    throw std::invalid_argument("LatentFitter: trunk.alpha must have latent_dim = " +
                                std::to_string(d) + " entries, found " +
                                std::to_string(trunk.alpha.size()));
  }
  if (options_.strategy.knn && (index == nullptr || latents == nullptr)) {
    throw std::invalid_argument("LatentFitter: strategy " + options_.strategy.ToString() +
                                " needs a k-NN index and the functaset latents");
  }
  if (index != nullptr || latents != nullptr) {
    if (index == nullptr || latents == nullptr) {
      throw std::invalid_argument("LatentFitter: give both the k-NN index and the latents, or neither");
    }
    if (index->dim() != d || latents->cols() != d || latents->rows() != index->size()) {
      throw std::invalid_argument(
          "LatentFitter: the k-NN index (" + std::to_string(index->size()) + " x " +
          std::to_string(index->dim()) + ") and the latents (" + std::to_string(latents->rows()) +
          " x " + std::to_string(latents->cols()) + ") must both be M x latent_dim (M x " +
          std::to_string(d) + ") with the same M");
    }
  }
}

LatentFitter::Summary LatentFitter::Fit(const LatentProblem& problem,
                                        Eigen::VectorXd* latent) const {
  return FitImpl(problem, nullptr, latent);
}

LatentFitter::Summary LatentFitter::Fit(const LatentProblem& problem,
                                        const Eigen::VectorXd& initial_latent,
                                        Eigen::VectorXd* latent) const {
  return FitImpl(problem, &initial_latent, latent);
}

LatentFitter::Summary LatentFitter::FitImpl(const LatentProblem& problem,
                                            const Eigen::VectorXd* initial,
                                            Eigen::VectorXd* latent) const {
  const Clock::time_point start_time = Clock::now();
  const int d = trunk_->siren.latent_dim();
  if (latent == nullptr) throw std::invalid_argument("LatentFitter::Fit: latent must not be null");
  if (problem.dim() != d) {
    throw std::invalid_argument("LatentFitter::Fit: the problem's latent has " +
                                std::to_string(problem.dim()) + " entries, the fitter's trunk " +
                                std::to_string(d));
  }
  if (initial != nullptr) {
    if (initial->size() != d) {
      throw std::invalid_argument("LatentFitter::Fit: the initial latent must have latent_dim = " +
                                  std::to_string(d) + " entries, found " +
                                  std::to_string(initial->size()));
    }
    if (!initial->allFinite()) {
      throw std::invalid_argument("LatentFitter::Fit: the initial latent has a non-finite entry");
    }
  }
  Summary summary;
  summary.strategy = options_.strategy;
  summary.sigma = problem.sigma();
  summary.sigma_z = problem.sigma_z();
  summary.num_valid_pixels = problem.num_valid_pixels();
  summary.num_pixels_used = problem.num_pixels();
  summary.num_residuals = problem.num_residuals() + d;

  Eigen::VectorXd z = initial != nullptr ? *initial : problem.StartLatent();
  if (problem.num_pixels() == 0) {
    latent->setZero(d);
    summary.termination_type = FitTermination::kNoValidPixels;
    summary.message = "the frame has no valid pixel (every weight is 0): the latent is the prior mean, 0";
    summary.total_time_ms = MsSince(start_time);
    return summary;
  }

  // A fit from z = 0 takes its start from the trunk's pass at z = 0 (StartPass): a Ceres
  // fit its start's cost and first Jacobian, meta-SGD steps (alone, or as the knn query)
  // their first step.
  const StartPass* start_pass =
      initial == nullptr && z.isZero(0.0) ? StartPassFor(problem) : nullptr;
  const StartPass* ceres_start_pass =
      !options_.strategy.knn && options_.strategy.refinement == FitStrategy::Refinement::kCeres
          ? start_pass
          : nullptr;
  // The Ceres stage's data residuals: U as Ceres sees it (the robust loss is inside the
  // data residuals, LatentProblem).
  std::unique_ptr<ceres::CostFunction> data_cost;
  const AnalyticLatentCost* analytic = nullptr;  // data_cost when analytic
  if (options_.jacobian == JacobianMode::kAutoDiff) {
    data_cost = MakeAutoDiffLatentCost(&problem);
  } else {
    auto cost = std::make_unique<AnalyticLatentCost>(&problem, ceres_start_pass);
    analytic = cost.get();
    data_cost = std::move(cost);
  }
  LatentPriorCost prior_cost(d, problem.sigma_z());
  // U at a latent and, when the problem covers the whole frame, its PSNR from the same
  // trunk pass (LatentProblem::DataCost): every latent the fit accepts is evaluated
  // once, and the last one's PSNR is the fit's.
  auto objective = [&](const Eigen::VectorXd& at, std::optional<double>* psnr) {
    return problem.DataCost(at, psnr) + HalfSquaredNorm(prior_cost, at.data());
  };

  auto add_stage = [&](const char* name, double cost, Clock::time_point began, int iterations) {
    summary.stages.push_back(Stage{name, cost, MsSince(began), iterations});
    summary.iterations += iterations;
  };
  // A fit that is meta-SGD steps alone takes the start's cost (and PSNR) from its first
  // step's forward pass instead of a pass of its own.
  const int steps = options_.strategy.steps;
  const bool meta_sgd_only = !options_.strategy.knn && steps >= 1 &&
                             options_.strategy.refinement == FitStrategy::Refinement::kMetaSgd;
  std::optional<double> psnr;
  double cost = 0;
  Eigen::VectorXd meta_sgd_latent;
  Clock::time_point meta_sgd_began;
  if (meta_sgd_only) {
    summary.stages.push_back(Stage{"start", 0, MsSince(start_time), 0});
    meta_sgd_began = Clock::now();
    double data_cost = 0;
    meta_sgd_latent = problem.MetaSgdSteps(z, steps, &data_cost, &psnr, start_pass);
    cost = data_cost + HalfSquaredNorm(prior_cost, z.data());
    summary.stages.back().cost = cost;
  } else if (ceres_start_pass != nullptr) {
    cost = problem.DataCostAtStart(*ceres_start_pass, &psnr);  // the prior is 0 at z = 0
    add_stage("start", cost, start_time, 0);
  } else {
    cost = objective(z, &psnr);
    add_stage("start", cost, start_time, 0);
  }
  summary.initial_cost = cost;
  summary.termination_type = FitTermination::kCompleted;

  // A stage whose result is not finite is undone: the fit keeps the last finite latent.
  // `outputs`, if not null, are the trunk's outputs at the candidate (no pass then).
  auto accept = [&](const Eigen::VectorXd& candidate, const char* stage,
                    const Eigen::MatrixXd* outputs = nullptr) {
    std::optional<double> candidate_psnr;
    const double candidate_cost =
        !candidate.allFinite() ? std::numeric_limits<double>::quiet_NaN()
        : outputs != nullptr   ? problem.DataCostOfOutputs(*outputs, &candidate_psnr) +
                                   HalfSquaredNorm(prior_cost, candidate.data())
                               : objective(candidate, &candidate_psnr);
    if (!std::isfinite(candidate_cost)) {
      summary.termination_type = FitTermination::kFailure;
      summary.message = std::string("the ") + stage +
                        " stage produced a non-finite latent or cost; kept the latent before it";
      return false;
    }
    z = candidate;
    cost = candidate_cost;
    psnr = candidate_psnr;
    return true;
  };

  if (options_.strategy.knn) {
    const Clock::time_point began = Clock::now();
    Eigen::VectorXd query =
        initial != nullptr
            ? *initial
            : problem.MetaSgdSteps(z, problem.trunk().meta_sgd.inner_steps, nullptr, nullptr,
                                   start_pass);
    if (!query.allFinite()) query.setZero();
    const Eigen::VectorXf query_float = query.cast<float>();
    const int k = options_.knn_k;
    std::vector<float> distances(k);
    std::vector<std::int64_t> labels(k);
    index_->Search(query_float.data(), 1, k, distances.data(), labels.data());
    Eigen::VectorXd estimate = Eigen::VectorXd::Zero(d);
    double weight_sum = 0;
    int exact_matches = 0;
    for (int i = 0; i < k; ++i) {
      if (labels[i] >= 0 && distances[i] <= 0.0f) ++exact_matches;
    }
    for (int i = 0; i < k; ++i) {
      if (labels[i] < 0) continue;
      const double distance = std::sqrt(static_cast<double>(distances[i]));
      const double w = exact_matches > 0 ? (distances[i] <= 0.0f ? 1.0 : 0.0) : 1.0 / distance;
      summary.neighbor_labels.push_back(labels[i]);
      summary.neighbor_squared_distances.push_back(distances[i]);
      summary.neighbor_weights.push_back(w);
      estimate += w * latents_->row(labels[i]).transpose().cast<double>();
      weight_sum += w;
    }
    if (weight_sum > 0 && std::isfinite(weight_sum)) {
      estimate /= weight_sum;
      for (double& w : summary.neighbor_weights) w /= weight_sum;
      accept(estimate, "knn");
    } else {
      summary.message = "k-NN found no neighbour (empty index); kept the query latent";
      accept(query, "knn");
    }
    add_stage("knn", cost, began, 0);
  }

  if (options_.strategy.refinement == FitStrategy::Refinement::kMetaSgd &&
      summary.termination_type != FitTermination::kFailure) {
    const Clock::time_point began = meta_sgd_only ? meta_sgd_began : Clock::now();
    const Eigen::VectorXd candidate =
        meta_sgd_only ? std::move(meta_sgd_latent) : problem.MetaSgdSteps(z, steps);
    accept(candidate, "meta_sgd");
    add_stage("meta_sgd", cost, began, steps);
  }

  if (options_.strategy.refinement == FitStrategy::Refinement::kCeres &&
      summary.termination_type != FitTermination::kFailure) {
    const Clock::time_point began = Clock::now();
    Eigen::VectorXd parameters = z;
    ceres::Problem::Options problem_options;
    problem_options.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    problem_options.loss_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
    ceres::Problem ceres_problem(problem_options);
    std::unique_ptr<SquareRootCost> square_root;
    if (options_.residual_form == ResidualForm::kSquareRoot &&
        options_.jacobian == JacobianMode::kAnalytic &&
        !options_.solver_options.check_gradients) {
      square_root = std::make_unique<SquareRootCost>(data_cost.get(), 1.0 / problem.sigma_z());
      ceres_problem.AddResidualBlock(square_root.get(), nullptr, parameters.data());
      summary.ceres_residual_form = ResidualForm::kSquareRoot;
    } else {
      ceres_problem.AddResidualBlock(data_cost.get(), nullptr, parameters.data());
      ceres_problem.AddResidualBlock(&prior_cost, nullptr, parameters.data());
    }
    ceres::Solver::Options solver_options = options_.solver_options;
    solver_options.max_num_iterations = steps;
    ceres::Solve(solver_options, &ceres_problem, &summary.solver_summary);
    summary.ceres_ran = true;
    const ceres::Solver::Summary& s = summary.solver_summary;
    // Ceres' iterations[0] is the starting point, not a step.
    const int iterations = std::max(0, static_cast<int>(s.iterations.size()) - 1);
    switch (s.termination_type) {
      case ceres::CONVERGENCE:
      case ceres::USER_SUCCESS:
        summary.termination_type = FitTermination::kConvergence;
        break;
      case ceres::NO_CONVERGENCE:
        summary.termination_type = FitTermination::kNoConvergence;
        break;
      case ceres::FAILURE:
      case ceres::USER_FAILURE:
        summary.termination_type = FitTermination::kFailure;
        summary.message = "ceres: " + s.message;
        break;
    }
    const Eigen::VectorXd before = z;
    const double cost_before = cost;
    const std::optional<double> psnr_before = psnr;
    // The result's outputs from Ceres' last Jacobian evaluation there, if it was (analytic).
    if (accept(parameters, "ceres",
               analytic != nullptr ? analytic->OutputsAt(parameters.data()) : nullptr)) {
      // Ceres keeps the best point it accepted, so the cost cannot rise; if rounding in
      // a float evaluation made it, the previous latent is kept.
      if (cost > cost_before) {
        z = before;
        cost = cost_before;
        psnr = psnr_before;
      } else if (square_root != nullptr) {
        if (const Eigen::MatrixXd* g = square_root->GaussNewtonMatrixAt(z.data())) {
          summary.gauss_newton_hessian = *g;
        }
      }
      if (summary.termination_type != FitTermination::kFailure && summary.message.empty() &&
          summary.termination_type == FitTermination::kNoConvergence) {
        summary.message = "ceres used its " + std::to_string(steps) + " iterations";
      }
    }
    add_stage("ceres", cost, began, iterations);
  }

  summary.final_cost = cost;
  // PSNR over every valid pixel of the frame, not only the subsample (objective above).
  summary.psnr = psnr ? *psnr : problem.Psnr(z);
  *latent = z;
  summary.total_time_ms = MsSince(start_time);
  return summary;
}

}  // namespace tactfunc
