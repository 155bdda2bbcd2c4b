// Copyright 2026 The tactfunc Authors.
// `tactfunc bench fit`: every LatentFitter strategy on the test frames of a dataset
// (the suites' description: apps/bench/fit_common.h).
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <sstream>

#include "CLI/CLI.hpp"
#include "apps/bench.h"
#include "apps/bench/fit_common.h"
#include "apps/bench/fit_suite.h"
#include "apps/command.h"
#include "apps/dataset_flags.h"
#include "apps/model_inputs.h"
#include "apps/pictures.h"
#include "apps/progress_bar.h"
#include "estimation/data/dataset.h"
#include "estimation/data/trunk_targets.h"
#include "estimation/evaluation/reconstruction.h"
#include "estimation/fitting/latent_fitter.h"
#include "estimation/functaset/functaset.h"
#include "estimation/knn/knn_index.h"
#include "models/core/parallel_for.h"
#include "models/trunk/functa_model.h"

namespace tactfunc::apps {
namespace bench {
namespace {

std::vector<Variant> FitVariants(int autodiff_frames) {
  using P = LatentProblem::Precision;
  using J = LatentFitter::JacobianMode;
  std::vector<Variant> variants;
  for (const char* s : {"meta_sgd:1", "meta_sgd:3", "meta_sgd:10", "ceres:2", "ceres:5", "ceres:10",
                        "ceres:20", "knn", "knn+meta_sgd:3", "knn+ceres:2", "knn+ceres:5"}) {
    variants.push_back({s, P::kFloat, J::kAnalytic, 0});
  }
  // Double where the precision can matter: the trunk's own steps, LM, and the combination.
  for (const char* s : {"meta_sgd:3", "ceres:5", "ceres:20", "knn+ceres:5"}) {
    variants.push_back({s, P::kDouble, J::kAnalytic, 0});
  }
  // The autodiff reference (always double): the whole solve, on a few frames.
  if (autodiff_frames > 0)
    variants.push_back({"ceres:2", P::kDouble, J::kAutoDiff, autodiff_frames});
  return variants;
}

LatentFitter::Options VariantOptions(const Variant& v) {
  LatentFitter::Options options;
  options.strategy = FitStrategy::FromString(v.strategy);
  options.jacobian = v.jacobian;
  options.knn_k = 8;
  return options;
}

// The converged reference: ceres:100 in double with tolerances far below Ceres' defaults.
LatentFitter::Options ConvergedOptions() {
  LatentFitter::Options options;
  options.strategy = FitStrategy::FromString("ceres:100");
  options.solver_options.function_tolerance = 1e-12;
  options.solver_options.gradient_tolerance = 1e-14;
  options.solver_options.parameter_tolerance = 1e-12;
  return options;
}

void RunFitBench(const FitBenchFlags& flags) {
  if (flags.threads < 1 || flags.threads > 2) throw UsageError("--threads: expected 1 or 2");
  const FunctaModel model = FunctaModel::Load(flags.model);
  const Functaset functaset = Functaset::Load(flags.functaset);
  functaset.CheckModel(model, flags.model, flags.functaset);
  const Dataset dataset = OpenDataset(flags.data, flags.dataset);

  std::vector<SensorKind> wanted =
      flags.sensors.empty() ? model.sensors() : ParseSensorsFlag(flags.sensors);
  std::vector<SensorFitData> sensors;
  for (SensorKind sensor : wanted) {
    const bool usable =
        model.HasSensor(sensor) && functaset.has_sensor(sensor) && dataset.has_sensor(sensor);
    if (!usable) {
      if (!flags.sensors.empty()) {
        throw UsageError(std::string("--sensors: ") + ToString(sensor) +
                         " is not in all of the model, the functaset and the dataset");
      }
      continue;
    }
    if (model.Trunk(sensor).photometric != nullptr) {
      // The variants are LatentFitter's strategies on the direct trunk's problem.
      const std::string why = std::string("the ") + ToString(sensor) + " trunk of '" +
                              flags.model + "' is photometric: its fits (adam:N, knn+adam:N) "
                              "are timed by `tactfunc bench photometric --model` "
                              "(--fit-steps, --fit-knn)";
      if (!flags.sensors.empty()) throw UsageError("--sensors: " + why);
      std::cerr << "bench fit: note: " << why << "; skipped\n";
      continue;
    }
    SensorFitData s;
    s.sensor = sensor;
    s.trunk = &model.Trunk(sensor);
    std::vector<std::size_t> indices = dataset.FrameIndices(sensor, Split::kTest);
    if (indices.size() > static_cast<std::size_t>(flags.frames)) indices.resize(flags.frames);
    if (indices.empty()) {
      std::cerr << "bench fit: note: no test frames of " << ToString(sensor) << "; skipped\n";
      continue;
    }
    for (std::size_t index : indices) {
      const Clock::time_point start = Clock::now();
      s.targets.push_back(LoadTrunkTargets(dataset, index, s.trunk->format));
      s.load_ms.push_back(MsSince(start));
      s.ids.push_back(dataset.frames()[index].id);
      if (dataset.has_clean() && !dataset.frames()[index].clean_path.empty()) {
        s.clean.push_back(LoadTrunkTargets(dataset, index, s.trunk->format, true));
      }
    }
    if (s.clean.size() != s.targets.size()) s.clean.clear();
    s.train_latents = functaset.Latents(sensor, Split::kTrain);
    if (s.train_latents.rows() == 0) s.train_latents = functaset.Latents(sensor);
    s.index = BuildKnnIndex(Functaset::LatentMatrix(s.train_latents), KnnIndexOptions());
    sensors.push_back(std::move(s));
  }
  if (sensors.empty()) {
    throw UsageError("no sensor with test frames in the model, the functaset and the dataset");
  }

  const std::vector<Variant> variants = FitVariants(flags.autodiff_frames);
  auto psnr_of = [](const SensorTrunk& trunk, const Eigen::VectorXd& z, const TrunkTargets& t) {
    return Psnr(Reconstruct(trunk, z.cast<float>()), t);
  };

  // Converged reference, then every variant, sensor by sensor.
  std::vector<VariantResult> results;
  for (SensorFitData& s : sensors) {
    const int n = static_cast<int>(s.targets.size());
    std::cout << "bench fit: " << ToString(s.sensor) << ": " << n << " test frames at "
              << s.trunk->format.rows << "x" << s.trunk->format.cols << ", latent_dim "
              << s.trunk->siren.latent_dim() << ", k-NN over " << s.train_latents.rows()
              << " train latents\n";
    {  // converged
      const LatentFitter fitter(*s.trunk, ConvergedOptions());
      LatentProblem::Options converged_problem;
      converged_problem.precision = LatentProblem::Precision::kDouble;
      s.converged_psnr.assign(n, 0);
      s.converged_psnr_clean.assign(n, std::numeric_limits<double>::quiet_NaN());
      std::vector<double> ms(n), iterations(n);
      std::vector<Eigen::VectorXd> latents(n);
      internal::ParallelFor(n, flags.threads, [&](int i) {
        const Clock::time_point start = Clock::now();
        const LatentFitter::Summary summary =
            fitter.Fit(LatentProblem(*s.trunk, s.targets[i], converged_problem), &latents[i]);
        ms[i] = MsSince(start);
        iterations[i] = summary.iterations;
        s.converged_psnr[i] = summary.psnr;
        if (!s.clean.empty()) s.converged_psnr_clean[i] = psnr_of(*s.trunk, latents[i], s.clean[i]);
      });
      s.converged_mean = Mean(s.converged_psnr);
      s.converged_clean_mean = Mean(s.converged_psnr_clean);
      s.converged_ms_median = Median(ms);
      s.converged_iterations_mean = Mean(iterations);
      std::cout << "  converged ceres:100 double: PSNR " << FormatFixed(s.converged_mean, 2)
                << " dB, " << FormatFixed(s.converged_iterations_mean, 1) << " iterations, "
                << Ms(s.converged_ms_median) << " ms median\n";
      MeasureJacobians(&s, latents[0]);
      std::cout << "  Jacobian: analytic float " << Ms(s.jacobian_float_ms) << " ms, double "
                << Ms(s.jacobian_double_ms) << " ms, autodiff " << Ms(s.jacobian_autodiff_ms)
                << " ms (" << FormatFixed(s.jacobian_autodiff_ms / s.jacobian_float_ms, 0)
                << "x float)\n";
    }
    for (const Variant& v : variants) {
      const LatentFitter::Options options = VariantOptions(v);
      LatentProblem::Options problem_options;
      problem_options.precision = v.precision;
      const Eigen::MatrixXf& latents = s.train_latents;
      const LatentFitter fitter = options.strategy.knn
                                      ? LatentFitter(*s.trunk, options, s.index.get(), &latents)
                                      : LatentFitter(*s.trunk, options);
      const int m = v.max_frames > 0 ? std::min(n, v.max_frames) : n;
      // One untimed warm-up fit: first-touch page faults and cold caches are not a frame's cost.
      {
        Eigen::VectorXd z;
        if (v.jacobian == LatentFitter::JacobianMode::kAnalytic) {
          fitter.Fit(LatentProblem(*s.trunk, s.targets[0], problem_options), &z);
        }
      }
      VariantResult r;
      r.variant = v;
      r.sensor = s.sensor;
      r.ms.assign(m, 0);
      r.psnr.assign(m, 0);
      r.iterations.assign(m, 0);
      r.psnr_clean.assign(m, std::numeric_limits<double>::quiet_NaN());
      internal::ParallelFor(m, flags.threads, [&](int i) {
        Eigen::VectorXd z;
        const Clock::time_point start = Clock::now();
        const LatentFitter::Summary summary =
            fitter.Fit(LatentProblem(*s.trunk, s.targets[i], problem_options), &z);
        r.ms[i] = MsSince(start);
        r.psnr[i] = summary.psnr;
        r.iterations[i] = summary.iterations;
        if (!s.clean.empty()) r.psnr_clean[i] = psnr_of(*s.trunk, z, s.clean[i]);
      });
      if (!options.strategy.knn &&
          options.strategy.refinement == FitStrategy::Refinement::kMetaSgd) {
        // The same frames' K steps alone, after their fits (caches as warm as the fit's),
        // as the fit runs them: a fit from z = 0 takes its first step from the fitter's
        // pass at z = 0 (StartPassFor: made once per frame size, by the warm-up fit, and
        // not timed here), so the share below is the rest of the fit alone.
        std::vector<double> steps_ms(m), share(m);
        for (int i = 0; i < m; ++i) {
          const LatentProblem problem(*s.trunk, s.targets[i], problem_options);
          const Eigen::VectorXd start = problem.StartLatent();
          const StartPass* pass = start.isZero(0.0) ? fitter.StartPassFor(problem) : nullptr;
          const Clock::time_point began = Clock::now();
          const Eigen::VectorXd z =
              problem.MetaSgdSteps(start, options.strategy.steps, nullptr, nullptr, pass);
          steps_ms[i] = MsSince(began);
          share[i] = (r.ms[i] - steps_ms[i]) / steps_ms[i];
        }
        r.steps_ms_median = Median(steps_ms);
        r.fixed_cost_share = Median(share);
      }
      r.ms_median = Median(r.ms);
      r.ms_p90 = Quantile(r.ms, 0.9);
      r.psnr_mean = Mean(r.psnr);
      r.psnr_clean_mean = Mean(r.psnr_clean);
      r.iterations_mean = Mean(r.iterations);
      r.converged_of_frames.assign(s.converged_psnr.begin(), s.converged_psnr.begin() + m);
      r.delta_db = r.psnr_mean - Mean(r.converged_of_frames);
      std::cout << "  " << v.Label() << ": " << Ms(r.ms_median) << " ms median, " << Ms(r.ms_p90)
                << " p90, PSNR " << FormatFixed(r.psnr_mean, 2) << " dB ("
                << (r.delta_db >= 0 ? "+" : "") << FormatFixed(r.delta_db, 2) << " vs converged), "
                << m << " frames";
      if (std::isfinite(r.fixed_cost_share)) {
        std::cout << "; the " << options.strategy.steps << " steps as the fit runs them "
                  << Ms(r.steps_ms_median)
                  << " ms median, the rest of the fit " << FormatFixed(100 * r.fixed_cost_share, 0)
                  << "% of them";
      }
      std::cout << "\n";
      results.push_back(std::move(r));
    }
  }

  // Targets: the speed and accuracy the latent fit must reach (docs/BENCHMARKS.md).
  double ratio = std::numeric_limits<double>::infinity();
  nlohmann::json ratio_by_sensor = nlohmann::json::object();
  for (const SensorFitData& s : sensors) {
    const double r = s.jacobian_autodiff_ms / s.jacobian_float_ms;
    ratio = std::min(ratio, r);
    ratio_by_sensor[ToString(s.sensor)] = {
        {"over_float", r}, {"over_double", s.jacobian_autodiff_ms / s.jacobian_double_ms}};
  }
  nlohmann::json targets;
  {
    std::ostringstream detail;
    double ratio_double = std::numeric_limits<double>::infinity();
    for (const SensorFitData& s : sensors) {
      ratio_double = std::min(ratio_double, s.jacobian_autodiff_ms / s.jacobian_double_ms);
    }
    detail << "autodiff / analytic Jacobian time, min over sensors: " << FormatFixed(ratio, 0)
           << "x against the float analytic Jacobian (the default), "
           << FormatFixed(ratio_double, 0)
           << "x against the double one (target >= 100x, checked against float)";
    targets["analytic_100x_faster_than_autodiff"] = {{"met", ratio >= 100},
                                                     {"detail", detail.str()}};
  }
  {
    bool met = true;
    std::ostringstream detail;
    for (const SensorFitData& s : sensors) {
      const VariantResult* worst = nullptr;  // every knn+ceres variant must be within 0.5 dB
      for (const VariantResult& r : results) {
        if (r.sensor == s.sensor && r.variant.strategy.rfind("knn+ceres", 0) == 0 &&
            (worst == nullptr || r.delta_db < worst->delta_db)) {
          worst = &r;
        }
      }
      const bool ok = worst != nullptr && worst->delta_db >= -0.5;
      met = met && ok;
      if (worst != nullptr) {
        detail << ToString(s.sensor) << ": worst knn+ceres variant " << worst->variant.Label()
               << " " << FormatFixed(worst->delta_db, 2) << " dB; ";
      }
    }
    detail << "(target: every knn+ceres variant within 0.5 dB of converged)";
    targets["knn_ceres_within_0.5dB_of_converged"] = {{"met", met}, {"detail", detail.str()}};
  }
  {
    bool met = true;
    std::ostringstream detail;
    for (const SensorFitData& s : sensors) {
      const VariantResult* best = nullptr;  // the fastest within 1 dB of converged
      for (const VariantResult& r : results) {
        if (r.sensor == s.sensor && r.ms.size() == s.converged_psnr.size() && r.delta_db >= -1.0 &&
            (best == nullptr || r.ms_median < best->ms_median)) {
          best = &r;
        }
      }
      const bool ok = flags.threads == 1 && best != nullptr && best->ms_median <= 33.0;
      met = met && ok;
      detail << ToString(s.sensor) << ": ";
      if (best == nullptr) {
        detail << "no strategy within 1 dB; ";
      } else {
        detail << "fastest within 1 dB is " << best->variant.Label() << ", " << Ms(best->ms_median)
               << " ms median, " << FormatFixed(best->delta_db, 2) << " dB; ";
      }
    }
    detail << "(target: median <= 33 ms on one thread within 1 dB of converged"
           << (flags.threads == 1 ? ")" : "; measured with 2 threads, so not checked)");
    targets["realtime_33ms_within_1dB"] = {{"met", met}, {"detail", detail.str()}};
  }

  const nlohmann::json machine = MachineDescription();
  const std::string machine_line = machine.value("cpu", std::string("?")) + ", " +
                                   std::to_string(machine.value("cores", 0)) + " cores";
  const std::string table = FitTable(results, sensors, flags, machine, targets);
  if (flags.table.empty()) {
    std::cout << "\n" << table;
  } else {
    WriteFileAtomically(flags.table, table);
    std::cout << "bench fit: wrote the table to " << flags.table << "\n";
  }
  if (!flags.plot.empty()) {
    WritePicture(flags.plot, ParetoPlot(results, sensors, flags.threads, machine_line));
    std::cout << "bench fit: wrote the Pareto plot to " << flags.plot << "\n";
  }
  for (const auto& [name, t] : targets.items()) {
    std::cout << "target " << name << ": " << (t["met"].get<bool>() ? "met" : "NOT met") << " -- "
              << t["detail"].get<std::string>() << "\n";
  }

  if (flags.json) {
    nlohmann::json list = nlohmann::json::array();
    for (const VariantResult& r : results) {
      list.push_back({{"name", r.variant.strategy},
                      {"label", r.variant.Label()},
                      {"sensor", ToString(r.sensor)},
                      {"precision", ToString(r.variant.precision)},
                      {"jacobian", ToString(r.variant.jacobian)},
                      {"frames", r.ms.size()},
                      {"ms_median", r.ms_median},
                      {"ms_p90", r.ms_p90},
                      {"psnr_mean", FiniteOrNull(r.psnr_mean)},
                      {"psnr_clean_mean", FiniteOrNull(r.psnr_clean_mean)},
                      {"delta_db", FiniteOrNull(r.delta_db)},
                      {"iterations_mean", r.iterations_mean},
                      {"steps_ms_median", FiniteOrNull(r.steps_ms_median)},
                      {"fixed_cost_share", FiniteOrNull(r.fixed_cost_share)}});
    }
    nlohmann::json converged = nlohmann::json::object(), converged_clean = nlohmann::json::object(),
                   jacobian_ms = nlohmann::json::object(), load_ms = nlohmann::json::object();
    for (const SensorFitData& s : sensors) {
      converged[ToString(s.sensor)] = FiniteOrNull(s.converged_mean);
      converged_clean[ToString(s.sensor)] = FiniteOrNull(s.converged_clean_mean);
      jacobian_ms[ToString(s.sensor)] = {{"analytic_float", s.jacobian_float_ms},
                                         {"analytic_double", s.jacobian_double_ms},
                                         {"autodiff", s.jacobian_autodiff_ms},
                                         {"residuals_float", s.residuals_float_ms}};
      load_ms[ToString(s.sensor)] = Median(s.load_ms);
    }
    EmitJson({{"bench", "fit"},
              {"strategies", list},
              {"converged_psnr", converged},
              {"converged_psnr_clean", converged_clean},
              {"autodiff_over_analytic", FiniteOrNull(ratio)},
              {"autodiff_over_analytic_by_sensor", ratio_by_sensor},
              {"jacobian_ms", jacobian_ms},
              {"load_and_preprocess_ms_median", load_ms},
              {"threads", flags.threads},
              {"targets", targets},
              {"machine", machine}});
  }
}

}  // namespace

void RegisterFitSuite(CLI::App* bench, CommandBody* selected) {
  {
    auto flags = std::make_shared<FitBenchFlags>();
    CLI::App* sub = bench->add_subcommand(
        "fit",
        "Every LatentFitter strategy on a dataset's test frames: median/p90 ms per frame, mean "
        "PSNR vs the converged fit, autodiff/analytic Jacobian ratio; Pareto plot and markdown "
        "table (plain std::chrono timing per frame).");
    sub->add_option("--model", flags->model, "Model file (.tfm)")->required();
    sub->add_option("--functaset", flags->functaset,
                    "Its functaset (.tfs); k-NN uses the train latents")
        ->required();
    sub->add_option("--data", flags->data, "The dataset (test split frames are fitted)")
        ->required();
    sub->add_option("--threads", flags->threads, "1 (default) or 2: frames fitted in parallel")
        ->check(CLI::Range(1, 2));
    sub->add_option("--frames", flags->frames, "Test frames per sensor (the first N; default 20)")
        ->check(CLI::Range(1, 100000));
    sub->add_option("--autodiff-frames", flags->autodiff_frames,
                    "Frames for the (slow) autodiff variant; 0 = skip it (default 2)")
        ->check(CLI::Range(0, 100000));
    sub->add_option("--sensors", flags->sensors, "bubble,gelslim (default: all the model has)");
    sub->add_option("--plot", flags->plot, "Write the Pareto plot (PNG) here");
    sub->add_option("--table", flags->table, "Write the markdown table here (default: stdout)");
    sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
    AddDatasetFlags(sub, &flags->dataset);
    sub->callback([flags, selected]() {
      flags->argv = {"tactfunc bench fit",
                     "--model " + flags->model,
                     "--functaset " + flags->functaset,
                     "--data " + flags->data,
                     "--threads " + std::to_string(flags->threads),
                     "--frames " + std::to_string(flags->frames),
                     flags->sensors.empty() ? "" : "--sensors " + flags->sensors};
      *selected = [flags]() { RunFitBench(*flags); };
    });
  }
}

}  // namespace bench

void RegisterFitBenchmarks(CLI::App* bench, CommandBody* selected) {
  bench::RegisterFitSuite(bench, selected);
  bench::RegisterKernelSuite(bench, selected);
  bench::RegisterKnnSuite(bench, selected);
  bench::RegisterTrunkSuite(bench, selected);
}

}  // namespace tactfunc::apps
