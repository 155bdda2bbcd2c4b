// Copyright 2026 The tactfunc Authors.
//
// `tactfunc bench kernels`: Google Benchmark programs of the kernels one fit is made of
// (trunk forward, forward + latent Jacobian, the autodiff Jacobian, one LM iteration,
// one meta-SGD step, an Eigen float GEMM, the SIREN's float sine and cosine kernel
// against libmvec's), and the Jacobian timings of `bench fit`.
// The latent cost functions (estimation/fitting/latent_costs.h) are timed directly here.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <iostream>
#include <memory>
#include <random>
#include <sstream>

#include "CLI/CLI.hpp"
#include "apps/bench.h"
#include "apps/bench/fit_common.h"
#include "apps/bench/fit_suite.h"
#include "apps/command.h"
#include "benchmark/benchmark.h"
#include "ceres/problem.h"
#include "ceres/solver.h"
#include "estimation/fitting/latent_costs.h"
#include "estimation/fitting/latent_fitter.h"
#include "estimation/fitting/square_root_cost.h"
#include "estimation/data/trunk_targets.h"
#include "models/trunk/functa_model.h"
#include "models/trunk/internal/fast_sincos.h"
#include "models/trunk/internal/small_gemm.h"
#include "models/trunk/product_precision.h"

namespace tactfunc::apps::bench {
namespace {

// Median time of `repeats` evaluations of `cost` (residuals and, if with_jacobian, the
// Jacobian) at z.
double TimeEvaluate(const ceres::CostFunction& cost, const Eigen::VectorXd& z, int num_residuals,
                    bool with_jacobian, int repeats) {
  std::vector<double> residuals(num_residuals);
  std::vector<double> jacobian(with_jacobian ? static_cast<std::size_t>(num_residuals) * z.size()
                                             : 0);
  const double* parameters[] = {z.data()};
  double* jacobians[] = {jacobian.data()};
  std::vector<double> times;
  for (int r = 0; r < repeats; ++r) {
    const Clock::time_point start = Clock::now();
    cost.Evaluate(parameters, residuals.data(), with_jacobian ? jacobians : nullptr);
    times.push_back(MsSince(start));
  }
  return Median(times);
}

}  // namespace

void MeasureJacobians(SensorFitData* s, const Eigen::VectorXd& z) {
  LatentProblem::Options float_options, double_options;
  double_options.precision = LatentProblem::Precision::kDouble;
  const LatentProblem problem_float(*s->trunk, s->targets[0], float_options);
  const LatentProblem problem_double(*s->trunk, s->targets[0], double_options);
  const int n = problem_float.num_residuals();
  AnalyticLatentCost analytic_float(&problem_float);
  AnalyticLatentCost analytic_double(&problem_double);
  const std::unique_ptr<ceres::CostFunction> autodiff = MakeAutoDiffLatentCost(&problem_double);
  TimeEvaluate(analytic_float, z, n, true, 2);  // warm-up
  s->jacobian_float_ms = TimeEvaluate(analytic_float, z, n, true, 21);
  s->jacobian_double_ms = TimeEvaluate(analytic_double, z, n, true, 21);
  s->residuals_float_ms = TimeEvaluate(analytic_float, z, n, false, 21);
  s->jacobian_autodiff_ms = TimeEvaluate(*autodiff, z, n, true, 3);
}

namespace {

struct KernelFlags {
  std::string model;
  bool json = false;
  std::vector<std::string> extra;
};

// What one trunk's kernels run on: a frame the trunk generates (TrunkGeneratedFrame).
struct KernelSetup {
  std::string label;
  SensorTrunk trunk;
  TrunkTargets targets;
  // The frame's latent problem at sigma 0.01, evaluated in float and in double.
  std::unique_ptr<LatentProblem> problem_float, problem_double;
  Eigen::VectorXd z;
};

std::shared_ptr<KernelSetup> MakeKernelSetup(const std::string& label, const SensorTrunk& trunk) {
  auto s = std::make_shared<KernelSetup>();
  s->label = label;
  s->trunk = trunk;
  const int d = trunk.siren.latent_dim();
  s->targets = TrunkGeneratedFrame(s->trunk.siren, trunk.format.rows, trunk.format.cols, 5);
  LatentProblem::Options options;
  options.sigma = 0.01;
  s->problem_float = std::make_unique<LatentProblem>(s->trunk, s->targets, options);
  options.precision = LatentProblem::Precision::kDouble;
  s->problem_double = std::make_unique<LatentProblem>(s->trunk, s->targets, options);
  std::mt19937_64 rng(6);
  std::normal_distribution<double> normal(0.0, 1.0);
  s->z = Eigen::VectorXd::Zero(d);
  for (int k = 0; k < d; ++k) s->z[k] = 0.1 * normal(rng);
  return s;
}

void EvaluateCost(const ceres::CostFunction& cost, const KernelSetup& s, bool jacobian,
                  std::vector<double>* residuals, std::vector<double>* J) {
  const double* parameters[] = {s.z.data()};
  double* jacobians[] = {J->data()};
  cost.Evaluate(parameters, residuals->data(), jacobian ? jacobians : nullptr);
}

void RegisterKernelBenchmarks(const std::shared_ptr<KernelSetup>& s) {
  const std::string p = "kernels/" + s->label + "/";
  const int n = s->problem_float->num_residuals(), d = s->trunk.siren.latent_dim();
  auto pixels = [s](benchmark::State& state) {
    state.SetItemsProcessed(state.iterations() * s->problem_float->num_pixels());
  };
  benchmark::RegisterBenchmark((p + "forward/float").c_str(), [s, pixels](benchmark::State& state) {
    const Eigen::MatrixXf coords = s->problem_float->coords().cast<float>();
    const Eigen::VectorXf z = s->z.cast<float>();
    for (auto _ : state)
      benchmark::DoNotOptimize(s->trunk.siren.Forward<float>(coords, z));
    pixels(state);
  })->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark((p + "forward/double").c_str(), [s,
                                                                pixels](benchmark::State& state) {
    for (auto _ : state) {
      benchmark::DoNotOptimize(
          s->trunk.siren.Forward<double>(s->problem_double->coords(), s->z));
    }
    pixels(state);
  })->Unit(benchmark::kMillisecond);
  for (const bool use_double : {false, true}) {
    benchmark::RegisterBenchmark(
        (p + "forward_latent_jacobian_analytic/" + (use_double ? "double" : "float")).c_str(),
        [s, n, d, use_double, pixels](benchmark::State& state) {
          const AnalyticLatentCost cost(use_double ? s->problem_double.get()
                                                   : s->problem_float.get());
          std::vector<double> r(n), J(static_cast<std::size_t>(n) * d);
          for (auto _ : state) EvaluateCost(cost, *s, true, &r, &J);
          pixels(state);
        })
        ->Unit(benchmark::kMillisecond);
  }
  benchmark::RegisterBenchmark((p + "residuals_analytic/float").c_str(),
                               [s, n, d, pixels](benchmark::State& state) {
                                 const AnalyticLatentCost cost(s->problem_float.get());
                                 std::vector<double> r(n), J(static_cast<std::size_t>(n) * d);
                                 for (auto _ : state) EvaluateCost(cost, *s, false, &r, &J);
                                 pixels(state);
                               })
      ->Unit(benchmark::kMillisecond);
  // One evaluation only: about 2 s at 70x88 with width 128.
  benchmark::RegisterBenchmark((p + "jacobian_autodiff/double").c_str(),
                               [s, n, d, pixels](benchmark::State& state) {
                                 const auto cost =
                                     MakeAutoDiffLatentCost(s->problem_double.get());
                                 std::vector<double> r(n), J(static_cast<std::size_t>(n) * d);
                                 for (auto _ : state) EvaluateCost(*cost, *s, true, &r, &J);
                                 pixels(state);
                               })
      ->Unit(benchmark::kMillisecond)
      ->Iterations(1)
      ->Repetitions(1);
  // A Ceres LM solve of exactly 1 and 3 iterations (tolerances 0), analytic float, from z
  // = 0: (t3 - t1) / 2 is the marginal cost of one LM iteration, reported as lm_iteration.
  // lm_solve hands Ceres the N C data and d prior residuals; lm_solve_square_root their
  // square-root information form, d + 1 residuals (SquareRootCost), as LatentFitter does.
  for (const bool square_root : {false, true}) {
    for (const int iterations : {1, 3}) {
      benchmark::RegisterBenchmark(
          (p + (square_root ? "lm_solve_square_root" : "lm_solve") +
           "/float/iterations:" + std::to_string(iterations))
              .c_str(),
          [s, d, iterations, square_root](benchmark::State& state) {
            AnalyticLatentCost cost(s->problem_float.get());
            LatentPriorCost prior(d, 1.0);
            SquareRootCost compressed(&cost, 1.0);
            ceres::Solver::Options options = LatentFitter::Options().solver_options;
            options.max_num_iterations = iterations;
            options.function_tolerance = 0;
            options.gradient_tolerance = 0;
            options.parameter_tolerance = 0;
            for (auto _ : state) {
              Eigen::VectorXd z = Eigen::VectorXd::Zero(d);
              ceres::Problem::Options po;
              po.cost_function_ownership = ceres::DO_NOT_TAKE_OWNERSHIP;
              ceres::Problem problem(po);
              if (square_root) {
                problem.AddResidualBlock(&compressed, nullptr, z.data());
              } else {
                problem.AddResidualBlock(&cost, nullptr, z.data());
                problem.AddResidualBlock(&prior, nullptr, z.data());
              }
              ceres::Solver::Summary summary;
              ceres::Solve(options, &problem, &summary);
              benchmark::DoNotOptimize(z.data());
            }
          })
          ->Unit(benchmark::kMillisecond);
    }
  }
  benchmark::RegisterBenchmark((p + "meta_sgd_step/float").c_str(), [s,
                                                                     d](benchmark::State& state) {
    Eigen::VectorXd z = Eigen::VectorXd::Zero(d);
    for (auto _ : state) {
      z = s->problem_float->MetaSgdSteps(z, 1);
      benchmark::DoNotOptimize(z.data());
    }
  })->Unit(benchmark::kMillisecond);
}

void RegisterGemmBenchmark() {
  benchmark::RegisterBenchmark("eigen/gemm_float/4096x256x256", [](benchmark::State& state) {
    const Eigen::MatrixXf a = Eigen::MatrixXf::Random(4096, 256),
                          b = Eigen::MatrixXf::Random(256, 256);
    Eigen::MatrixXf c(4096, 256);
    for (auto _ : state) {
      c.noalias() = a * b;
      benchmark::DoNotOptimize(c.data());
    }
    state.counters["GFLOPS"] = benchmark::Counter(2.0 * 4096 * 256 * 256 / 1e9,
                                                  benchmark::Counter::kIsIterationInvariantRate);
  })->Unit(benchmark::kMillisecond);
  // A layer's product in the passes, W (width x width) times 256 pixels' activations (two
  // of the passes' blocks of 128), by Eigen and by the passes' kernel (internal::Product);
  // and the reference product by the kernel.
  // bf16: the kernel with ProductPrecision::kBfloat16 (registered where the CPU has it).
  auto product = [](const char* name, long rows, long depth, bool kernel, bool bf16 = false) {
    benchmark::RegisterBenchmark(name, [=](benchmark::State& state) {
      const Eigen::MatrixXf a = Eigen::MatrixXf::Random(rows, depth),
                            b = Eigen::MatrixXf::Random(depth, 256);
      Eigen::MatrixXf c(rows, 256);
      const ScopedProductPrecision precision(bf16 ? ProductPrecision::kBfloat16
                                                   : ProductPrecision::kFloat);
      for (auto _ : state) {
        if (kernel) {
          internal::Product(a, b, c, /*accumulate=*/false);
        } else {
          c.noalias() = a * b;
        }
        benchmark::DoNotOptimize(c.data());
      }
      state.counters["GFLOPS"] = benchmark::Counter(
          2.0 * rows * depth * 256 / 1e9, benchmark::Counter::kIsIterationInvariantRate);
    })->Unit(benchmark::kMicrosecond);
  };
  // A layer's weight gradient from 256 pixels, dW (width x width) += delta (width x 256)
  // times h^T: the right-hand side is the activations read transposed (row-major), the
  // depth is the pixels.
  auto weight_gradient = [](const char* name, long width, bool kernel, bool bf16 = false) {
    benchmark::RegisterBenchmark(name, [=](benchmark::State& state) {
      const Eigen::MatrixXf delta = Eigen::MatrixXf::Random(width, 256),
                            h = Eigen::MatrixXf::Random(width, 256);
      Eigen::MatrixXf dW = Eigen::MatrixXf::Zero(width, width);
      const ScopedProductPrecision precision(bf16 ? ProductPrecision::kBfloat16
                                                   : ProductPrecision::kFloat);
      for (auto _ : state) {
        if (kernel) {
          internal::Product(delta, h.transpose(), dW, /*accumulate=*/true);
        } else {
          dW.noalias() += delta * h.transpose();
        }
        benchmark::DoNotOptimize(dW.data());
      }
      state.counters["GFLOPS"] = benchmark::Counter(2.0 * width * width * 256 / 1e9,
                                                    benchmark::Counter::kIsIterationInvariantRate);
    })->Unit(benchmark::kMicrosecond);
  };
  const bool bf16 = ProductPrecisionAvailable(ProductPrecision::kBfloat16);
  product("kernel/gemm_float/4096x256x256", 4096, 256, true);
  if (bf16) product("kernel_bf16/gemm/4096x256x256", 4096, 256, true, true);
  for (const long width : {64L, 128L, 256L}) {
    const std::string shape = std::to_string(width) + "x" + std::to_string(width) + "x256";
    product(("eigen/layer_product/" + shape).c_str(), width, width, false);
    product(("kernel/layer_product/" + shape).c_str(), width, width, true);
    if (bf16) product(("kernel_bf16/layer_product/" + shape).c_str(), width, width, true, true);
    const std::string gradient_shape = std::to_string(width) + "x256x" + std::to_string(width);
    weight_gradient(("eigen/weight_gradient/" + gradient_shape).c_str(), width, false);
    weight_gradient(("kernel/weight_gradient/" + gradient_shape).c_str(), width, true);
    if (bf16) {
      weight_gradient(("kernel_bf16/weight_gradient/" + gradient_shape).c_str(), width, true,
                      true);
    }
  }
}

// The SIREN's element-wise step for one block of 256 pixels of a width-64 layer: sin and
// cos of omega_0 = 30 times pre-activations in [-3, 3], by the kernel the passes use
// (one argument reduction for both) and by libmvec's sinf and cosf one after the other;
// and the sine alone (forward-only passes), by the kernel (one reduction by pi, one
// polynomial) and by libmvec's sinf.
constexpr long kSinCosValues = 64 * 256;

void RegisterSinCosBenchmarks() {
  for (const bool with_cosine : {true, false}) {
    for (const bool libmvec : {false, true}) {
      const std::string name = std::string(with_cosine ? "sincos" : "sin") + "/float/" +
                               (libmvec ? "libmvec" : "one_reduction") + "/16384";
      benchmark::RegisterBenchmark(name.c_str(), [libmvec, with_cosine](benchmark::State& state) {
        const Eigen::VectorXf x = 3.0f * Eigen::VectorXf::Random(kSinCosValues);
        Eigen::VectorXf s(kSinCosValues), c(kSinCosValues);
        float* cosine = with_cosine ? c.data() : nullptr;
        for (auto _ : state) {
          if (libmvec) {
            internal::LibmvecScaledSinCos(kSinCosValues, 30.0f, x.data(), s.data(), cosine);
          } else {
            internal::ScaledSinCos(kSinCosValues, 30.0f, x.data(), s.data(), cosine);
          }
          benchmark::DoNotOptimize(s.data());
          benchmark::DoNotOptimize(c.data());
        }
      })->Unit(benchmark::kMicrosecond);
    }
  }
}

void RunKernelBench(const KernelFlags& flags) {
  std::vector<std::shared_ptr<KernelSetup>> setups;
  if (!flags.model.empty()) {
    const FunctaModel model = FunctaModel::Load(flags.model);
    for (SensorKind sensor : model.sensors())
      setups.push_back(MakeKernelSetup(ToString(sensor), model.Trunk(sensor)));
  } else {
    // The default: the width-128, 4-layer, d = 64 trunk at 70x88 of docs/FITTING.md.
    SensorTrunk trunk;
    trunk.format.rows = 70;
    trunk.format.cols = 88;
    trunk.format.scale = 0.01;
    trunk.siren = LatentModulatedSiren(LatentModulatedSiren::Options(), 1);
    trunk.alpha = Eigen::VectorXd::Constant(trunk.siren.latent_dim(), 0.5);
    setups.push_back(MakeKernelSetup("default", trunk));
  }
  for (const auto& s : setups) {
    std::cout << "bench kernels: " << s->label << ": " << s->trunk.format.rows << "x"
              << s->trunk.format.cols << " pixels, width " << s->trunk.siren.width() << ", "
              << s->trunk.siren.num_hidden_layers()
              << " layers, d = " << s->trunk.siren.latent_dim()
              << ", C = " << s->trunk.siren.output_channels() << "\n";
    RegisterKernelBenchmarks(s);
  }
  RegisterGemmBenchmark();
  RegisterSinCosBenchmarks();
  const std::vector<BenchResult> results = RunRegisteredBenchmarks(flags.extra);
  auto find = [&](const std::string& name) -> const BenchResult* {
    for (const BenchResult& r : results) {
      if (r.name.rfind(name, 0) == 0) return &r;
    }
    return nullptr;
  };
  nlohmann::json per_trunk = nlohmann::json::object();
  for (const auto& s : setups) {
    const std::string p = "kernels/" + s->label + "/";
    const BenchResult* one = find(p + "lm_solve/float/iterations:1");
    const BenchResult* three = find(p + "lm_solve/float/iterations:3");
    const BenchResult* jf = find(p + "forward_latent_jacobian_analytic/float");
    const BenchResult* jd = find(p + "forward_latent_jacobian_analytic/double");
    const BenchResult* ad = find(p + "jacobian_autodiff/double");
    const BenchResult* one_sr = find(p + "lm_solve_square_root/float/iterations:1");
    const BenchResult* three_sr = find(p + "lm_solve_square_root/float/iterations:3");
    nlohmann::json t;
    if (one != nullptr && three != nullptr)
      t["lm_iteration_ms"] = (three->real_ms - one->real_ms) / 2;
    if (one_sr != nullptr && three_sr != nullptr)
      t["lm_iteration_square_root_ms"] = (three_sr->real_ms - one_sr->real_ms) / 2;
    if (jf != nullptr && ad != nullptr)
      t["autodiff_over_analytic_float"] = ad->real_ms / jf->real_ms;
    if (jd != nullptr && ad != nullptr)
      t["autodiff_over_analytic_double"] = ad->real_ms / jd->real_ms;
    std::cout << "bench kernels: " << s->label << ": one LM iteration (marginal) "
              << (t.contains("lm_iteration_ms") ? Ms(t["lm_iteration_ms"].get<double>()) : "n/a")
              << " ms (square-root form "
              << (t.contains("lm_iteration_square_root_ms")
                      ? Ms(t["lm_iteration_square_root_ms"].get<double>())
                      : "n/a")
              << " ms); autodiff / analytic Jacobian "
              << (t.contains("autodiff_over_analytic_float")
                      ? FormatFixed(t["autodiff_over_analytic_float"].get<double>(), 0)
                      : "n/a")
              << "x (float), "
              << (t.contains("autodiff_over_analytic_double")
                      ? FormatFixed(t["autodiff_over_analytic_double"].get<double>(), 0)
                      : "n/a")
              << "x (double)\n";
    per_trunk[s->label] = t;
  }
  double gflops = 0;
  if (const BenchResult* g = find("eigen/gemm_float")) {
    gflops = g->counters.count("GFLOPS") ? g->counters.at("GFLOPS") : 0;
  }
  const nlohmann::json machine = MachineDescription();
  std::cout << "bench kernels: Eigen float GEMM 4096x256x256: " << FormatFixed(gflops, 1)
            << " GFLOP/s (one thread; -march=native "
            << (machine.value("avx512_compiled", false) ? "with" : "without")
            << " AVX-512 compiled in)\n";
  if (flags.json) {
    nlohmann::json list = nlohmann::json::array();
    for (const BenchResult& r : results) {
      nlohmann::json counters = nlohmann::json::object();
      for (const auto& [key, value] : r.counters) counters[key] = value;
      list.push_back({{"name", r.name},
                      {"ms_median", r.real_ms},
                      {"cpu_ms_median", r.cpu_ms},
                      {"counters", counters}});
    }
    EmitJson({{"bench", "kernels"},
              {"machine", machine},
              {"gemm_gflops", gflops},
              {"trunks", per_trunk},
              {"results", list}});
  }
}

}  // namespace

void RegisterKernelSuite(CLI::App* bench, CommandBody* selected) {
  {
    auto flags = std::make_shared<KernelFlags>();
    CLI::App* sub = bench->add_subcommand(
        "kernels",
        "Google Benchmark of the fitting kernels (forward, analytic and autodiff latent "
        "Jacobians, LM iteration, meta-SGD step) at the model's resolution (default trunk: width "
        "128, 4 layers, d = 64, 70x88), and Eigen float GEMM GFLOP/s. Extra --benchmark_* flags "
        "pass through.");
    sub->add_option("--model", flags->model, "Model file (.tfm); every trunk is benchmarked");
    sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
    sub->allow_extras();
    sub->callback([flags, sub, selected]() {
      flags->extra = sub->remaining();
      *selected = [flags]() { RunKernelBench(*flags); };
    });
  }
}

}  // namespace tactfunc::apps::bench
