// Copyright 2026 The tactfunc Authors.
//
// `tactfunc bench fit` (fit_suite.cc): the variants it times, their results, and the
// per-sensor data; the Pareto plot and the table (fit_report.cc); the Jacobian timings
// (fit_kernels.cc).
#ifndef TACTFUNC_APPS_BENCH_FIT_SUITE_H_
#define TACTFUNC_APPS_BENCH_FIT_SUITE_H_

#include <limits>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "apps/dataset_flags.h"
#include "estimation/data/trunk_targets.h"
#include "estimation/fitting/latent_fitter.h"
#include "estimation/knn/knn_index.h"
#include "models/trunk/functa_model.h"
#include "nlohmann/json.hpp"

namespace tactfunc::apps::bench {

// One row of the table: a strategy with a precision and a Jacobian mode.
struct Variant {
  std::string strategy;
  LatentProblem::Precision precision = LatentProblem::Precision::kFloat;
  LatentFitter::JacobianMode jacobian = LatentFitter::JacobianMode::kAnalytic;
  int max_frames = 0;  // 0 = all test frames; autodiff runs on a couple only (it is slow)

  std::string Label() const {
    if (jacobian == LatentFitter::JacobianMode::kAutoDiff) return strategy + " autodiff";
    return strategy + (precision == LatentProblem::Precision::kDouble ? " double" : "");
  }
};

struct VariantResult {
  Variant variant;
  SensorKind sensor = SensorKind::kSoftBubble;
  std::vector<double> ms, psnr, psnr_clean, iterations;
  double ms_median = 0, ms_p90 = 0, psnr_mean = 0, psnr_clean_mean = 0, iterations_mean = 0;
  double delta_db = 0;                      // psnr_mean - converged PSNR of the same frames
  // meta_sgd:K from the start latent only: the median time of the K steps alone
  // (LatentProblem::MetaSgdSteps) and what a whole Fit pays on top of them -- building the
  // problem, the start latent, the costs and the PSNR -- as a fraction of the steps
  // (median over frames of (fit - steps) / steps). NaN for other strategies.
  double steps_ms_median = std::numeric_limits<double>::quiet_NaN();
  double fixed_cost_share = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> converged_of_frames;  // converged PSNR of the frames this variant ran
};

struct SensorFitData {
  SensorKind sensor = SensorKind::kSoftBubble;
  const SensorTrunk* trunk = nullptr;
  std::vector<std::string> ids;
  std::vector<TrunkTargets> targets, clean;  // clean empty if the dataset has none
  std::vector<double> load_ms;               // read + preprocess per frame
  Eigen::MatrixXf train_latents;             // the k-NN base: the functaset's TRAIN latents
  std::unique_ptr<KnnIndex> index;  // over train_latents (BuildKnnIndex)
  std::vector<double> converged_psnr, converged_psnr_clean;  // per frame
  double converged_mean = 0, converged_clean_mean = 0;
  double converged_ms_median = 0, converged_iterations_mean = 0;
  // Jacobian timings (ms, median) at the first test frame.
  double jacobian_float_ms = 0, jacobian_double_ms = 0, jacobian_autodiff_ms = 0;
  double residuals_float_ms = 0;
};

struct FitBenchFlags {
  std::string model, functaset, data, sensors, plot, table;
  int threads = 1;
  int frames = 20;
  int autodiff_frames = 2;
  bool json = false;
  DatasetFlags dataset;
  std::vector<std::string> argv;  // for the report
};

// The Pareto plot: mean PSNR against median ms per frame of every variant.
cv::Mat ParetoPlot(const std::vector<VariantResult>& results,
                   const std::vector<SensorFitData>& sensors, int threads,
                   const std::string& machine);
// The markdown table of docs/BENCHMARKS.md.
std::string FitTable(const std::vector<VariantResult>& results,
                     const std::vector<SensorFitData>& sensors, const FitBenchFlags& flags,
                     const nlohmann::json& machine, const nlohmann::json& targets);
// Times the analytic (float, double) and autodiff latent Jacobians and the float
// residuals at z on s->targets[0] (medians, ms) into s.
void MeasureJacobians(SensorFitData* s, const Eigen::VectorXd& z);

}  // namespace tactfunc::apps::bench

#endif  // TACTFUNC_APPS_BENCH_FIT_SUITE_H_
