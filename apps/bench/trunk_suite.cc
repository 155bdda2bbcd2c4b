// Copyright 2026 The tactfunc Authors.
//
// `tactfunc bench trunk`: the trunk's two workloads at any size, on frames the trunk
// generates itself (TrunkGeneratedFrame; no model or dataset needed):
//
//   fit        a meta_sgd:K fit of one whole frame, single thread, float: the K steps alone
//              (LatentProblem::MetaSgdSteps from the start latent, as `bench fit` times
//              them) and the whole fit as `bench fit` times it (building the
//              LatentProblem, then LatentFitter::Fit: the objective at the start latent,
//              the K steps, the objective at z_K, whose trunk pass also gives the PSNR).
//   meta-step  one outer step of TrunkTrainer (a batch of frames, a random pixel subset of
//              each, K inner steps, the exact second-order meta-gradient, Adam), timed
//              between the trainer's step callbacks.
//
// Each is repeated and reported as median, min and max (std::chrono), with its GEMM
// FLOP count (the multiply-adds of the trunk's matrix products, from the passes in
// models/trunk/latent_modulated_siren.cc) and the rate that makes, as a share of the
// single-thread float GEMM rate measured in the same run (MeasureGemmGflops: the better
// of Eigen's product and the passes' own kernel, internal::SmallGemm, on one product).
#include <algorithm>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include "CLI/CLI.hpp"
#include "apps/bench.h"
#include "apps/bench/fit_common.h"
#include "apps/command.h"
#include "benchmark/benchmark.h"
#include "estimation/fitting/latent_fitter.h"
#include "estimation/fitting/latent_problem.h"
#include "estimation/training/trunk_trainer.h"
#include "models/trunk/functa_model.h"
#include "models/trunk/internal/small_gemm.h"

namespace tactfunc::apps::bench {
namespace {

struct TrunkFlags {
  int width = 64;
  int layers = 3;
  int latent = 64;
  int channels = 1;
  int rows = 70;
  int cols = 88;
  int steps = 3;
  int batch = 32;
  int pixels = 512;
  int threads = 1;
  int repeats = 20;
  std::string workloads = "fit,meta-step";
  std::string spatial;  // "GHxGWxC", empty = one global latent
  std::string products = "float";
  bool json = false;
};

// Multiply-adds per pixel of the trunk's matrix products (first layer, square hidden
// layers, output layer): one forward pass is first + hidden + out.
struct PassMacs {
  double first = 0, hidden = 0, out = 0;
  explicit PassMacs(const LatentModulatedSiren& siren) {
    const double w = siren.width();
    first = 2 * w;
    hidden = (siren.num_hidden_layers() - 1) * w * w;
    out = w * siren.output_channels();
  }
  double Forward() const { return first + hidden + out; }
  // LossAndGradient w.r.t. z only: the forward pass, then W_out^T and W_l^T (l >= 1).
  double GradientZ() const { return Forward() + hidden + out; }
  // LossAndGradient w.r.t. z and theta: also the weight gradients of every layer.
  double GradientTheta() const { return GradientZ() + Forward(); }
  // HessianProduct with v_theta = 0 from the tape of the inner step's LossAndGradient
  // (MetaSgd), which holds that step's forward pass and dL/dh_l: the tangent forward pass
  // (W_l for l >= 1, and W_out) and the reverse pass's tangent: two output-weight
  // products and one W_out^T product, then per sine layer the weight product of ddm
  // (every layer) and of dm (l >= 1) and one W_l^T product (l >= 1).
  double HessianProduct() const { return first + 4 * hidden + 4 * out; }
};

// GEMM FLOPs (2 per multiply-add) of a meta_sgd:K fit's steps over n pixels, of the
// whole fit (one more forward pass, at z_K; the start's cost comes from the first step's
// pass, and K = 0 pays a pass at the start instead), and of one meta-training step.
double FitStepsFlops(const PassMacs& m, int steps, long n) { return 2.0 * steps * n * m.GradientZ(); }
// The fit as LatentFitter runs it from z = 0: its first step from the StartPass (one
// d x (n C) matrix-vector product, `gemv_macs`), the others full, one closing forward pass.
double FitFlops(const PassMacs& m, int steps, long n, double gemv_macs) {
  return steps > 0 ? FitStepsFlops(m, steps - 1, n) + 2.0 * gemv_macs + 2.0 * n * m.Forward()
                   : 2.0 * 2 * n * m.Forward();
}
double MetaStepFlops(const PassMacs& m, int steps, int batch, long pixels) {
  return 2.0 * batch * pixels *
         (steps * m.GradientZ() + m.GradientTheta() + steps * m.HessianProduct());
}

struct Spread {
  double median = 0, min = 0, max = 0;
  explicit Spread(const std::vector<double>& v)
      : median(Median(v)),
        min(*std::min_element(v.begin(), v.end())),
        max(*std::max_element(v.begin(), v.end())) {}
  nlohmann::json Json(const std::string& prefix) const {
    return {{prefix + "median", median}, {prefix + "min", min}, {prefix + "max", max}};
  }
};

// The single-thread float GEMM rate the shares are taken against: the best GFLOP/s of
// `repeats` products 4096x256 by 256x256 (the `bench kernels` reference product) after
// one untimed, by Eigen and by the passes' own kernel (internal::Product, which is
// Eigen's product where the build has no kernel), and the better of the two. The best,
// not the median, so that the reference rate is what the core can do even when the
// machine is shared; the better of the two, so that a share never credits the passes
// with beating a slow reference.
struct GemmRates {
  double eigen = 0, kernel = 0;
  double Reference() const { return std::max(eigen, kernel); }
};
GemmRates MeasureGemmGflops(int repeats) {
  const Eigen::MatrixXf a = Eigen::MatrixXf::Random(4096, 256), b = Eigen::MatrixXf::Random(256, 256);
  Eigen::MatrixXf c(4096, 256);
  auto best = [&](auto&& product) {
    std::vector<double> rates;
    for (int r = 0; r <= repeats; ++r) {
      const Clock::time_point start = Clock::now();
      product();
      benchmark::DoNotOptimize(c.data());
      const double ms = MsSince(start);
      if (r > 0) rates.push_back(2.0 * 4096 * 256 * 256 / (ms * 1e6));
    }
    return *std::max_element(rates.begin(), rates.end());
  };
  GemmRates rates;
  rates.eigen = best([&] { c.noalias() = a * b; });
  rates.kernel = best([&] { internal::Product(a, b, c, /*accumulate=*/false); });
  return rates;
}

SensorTrunk MakeTrunk(const TrunkFlags& flags) {
  SensorTrunk trunk;
  trunk.format.rows = flags.rows;
  trunk.format.cols = flags.cols;
  trunk.format.scale = 0.01;
  trunk.format.grayscale = true;
  LatentModulatedSiren::Options options = TrunkTrainer::Options::DefaultSirenOptions();
  options.width = flags.width;
  options.num_hidden_layers = flags.layers;
  options.latent_dim = flags.latent;
  options.output_channels = flags.channels;
  if (!flags.spatial.empty()) {
    char x1 = 0, x2 = 0, extra = 0;
    std::istringstream in(flags.spatial);
    if (!(in >> options.spatial_rows >> x1 >> options.spatial_cols >> x2 >>
          options.spatial_channels) ||
        x1 != 'x' || x2 != 'x' || (in >> extra)) {
      throw UsageError("--spatial: expected GHxGWxC, got '" + flags.spatial + "'");
    }
  }
  std::string error;
  if (!options.IsValid(&error)) throw UsageError(error);
  trunk.siren = LatentModulatedSiren(options, 1);
  trunk.alpha = Eigen::VectorXd::Ones(flags.latent);  // the trainer's initial rates
  trunk.meta_sgd = TrunkTrainer::Options::DefaultMetaSgdOptions();
  trunk.meta_sgd.inner_steps = flags.steps;
  return trunk;
}

nlohmann::json RunFit(const TrunkFlags& flags, const SensorTrunk& trunk, double gemm_gflops) {
  const TrunkTargets frame = TrunkGeneratedFrame(trunk.siren, flags.rows, flags.cols, 5);
  LatentFitter::Options options;
  options.strategy = FitStrategy::FromString("meta_sgd:" + std::to_string(flags.steps));
  const LatentFitter fitter(trunk, options);
  const LatentProblem::Options problem_options;  // float, every pixel
  const LatentProblem problem(trunk, frame, problem_options);
  // The trunk's pass at z = 0 over the frame (StartPass), made once per frame size: the
  // fitter makes its own on the warm-up fit below; this one times it and runs the steps as
  // the fit runs them.
  Clock::time_point began = Clock::now();
  const StartPass start_pass(trunk, flags.rows, flags.cols);
  const double start_pass_ms = MsSince(began);
  Eigen::VectorXd z;
  LatentFitter::Summary summary = fitter.Fit(problem, &z);  // untimed warm-up
  // core: the K steps, each a full trunk pass (the work the peer's K steps do); fit steps:
  // the K steps as the fit runs them, the first from the start pass; full: the whole fit.
  std::vector<double> core_ms, fit_steps_ms, full_ms;
  for (int r = 0; r < flags.repeats; ++r) {
    const Eigen::VectorXd start = problem.StartLatent();
    began = Clock::now();
    const Eigen::VectorXd steps = problem.MetaSgdSteps(start, flags.steps);
    core_ms.push_back(MsSince(began));
    began = Clock::now();
    const Eigen::VectorXd fit_steps =
        problem.MetaSgdSteps(start, flags.steps, nullptr, nullptr, &start_pass);
    fit_steps_ms.push_back(MsSince(began));
    began = Clock::now();
    summary = fitter.Fit(LatentProblem(trunk, frame, problem_options), &z);
    full_ms.push_back(MsSince(began));
  }
  const long n = static_cast<long>(flags.rows) * flags.cols;
  const PassMacs macs(trunk.siren);
  const double gemv_macs = static_cast<double>(start_pass.jacobian.size());
  const double core_flops = FitStepsFlops(macs, flags.steps, n);
  const double fit_steps_flops =
      flags.steps > 0 ? FitStepsFlops(macs, flags.steps - 1, n) + 2.0 * gemv_macs : 0.0;
  const double full_flops = FitFlops(macs, flags.steps, n, gemv_macs);
  const Spread core(core_ms), fit_steps(fit_steps_ms), full(full_ms);
  const double core_rate = core_flops / (core.median * 1e6);
  std::cout << "bench trunk: fit meta_sgd:" << flags.steps << " of " << flags.rows << "x"
            << flags.cols << ": the steps " << Ms(core.median) << " ms median (" << Ms(core.min)
            << "-" << Ms(core.max) << "), as the fit runs them (the first from the pass at z = 0) "
            << Ms(fit_steps.median) << " ms, the whole fit " << Ms(full.median) << " ms ("
            << Ms(full.min) << "-" << Ms(full.max) << "), its fixed costs "
            << FormatFixed(100 * (full.median / fit_steps.median - 1), 0)
            << " % of its steps; the pass at z = 0, once per frame size, " << Ms(start_pass_ms)
            << " ms; PSNR " << FormatFixed(summary.psnr, 2) << " dB; steps at "
            << FormatFixed(core_rate, 1) << " GFLOP/s of GEMM, "
            << FormatFixed(100 * core_rate / gemm_gflops, 0) << " % of the GEMM rate\n";
  nlohmann::json out = {{"pixels", n},
                        {"psnr", FiniteOrNull(summary.psnr)},
                        {"core_gemm_gflop", core_flops / 1e9},
                        {"fit_steps_gemm_gflop", fit_steps_flops / 1e9},
                        {"full_gemm_gflop", full_flops / 1e9},
                        {"core_gflops", core_rate},
                        {"core_share_of_gemm_rate", core_rate / gemm_gflops},
                        {"start_pass_ms", start_pass_ms},
                        {"core_ms", core_ms},
                        {"fit_steps_ms", fit_steps_ms},
                        {"full_ms", full_ms}};
  out.update(core.Json("core_ms_"));
  out.update(fit_steps.Json("fit_steps_ms_"));
  out.update(full.Json("full_ms_"));
  return out;
}

nlohmann::json RunMetaStep(const TrunkFlags& flags, const SensorTrunk& trunk,
                           double gemm_gflops) {
  std::vector<TrunkTargets> frames;
  for (int i = 0; i < flags.batch; ++i) {
    frames.push_back(TrunkGeneratedFrame(trunk.siren, flags.rows, flags.cols, 100 + i));
  }
  TrunkTrainer::Options o;
  o.siren = trunk.siren.options();
  o.meta_sgd = trunk.meta_sgd;
  o.batch_size = flags.batch;
  o.pixels_per_frame = flags.pixels;
  o.threads = flags.threads;
  o.steps = flags.repeats + 1;  // the first step is a warm-up
  o.monitor_every = o.steps + 1;
  o.monitor_frames = 1;
  o.residual_frames = 1;
  o.checkpoint_every = 0;
  o.divergence_drop_db = 0;
  std::vector<Clock::time_point> ends;
  const TrunkTrainer trainer(o);
  const TrunkTrainer::Summary summary =
      trainer.Train(frames, SensorKind::kSoftBubble, trunk.format, 0, nullptr,
                    [&ends](const TrunkTrainer::StepReport&) {
                      ends.push_back(Clock::now());
                      return true;
                    });
  std::vector<double> ms;
  for (std::size_t i = 1; i < ends.size(); ++i) {
    ms.push_back(std::chrono::duration<double, std::milli>(ends[i] - ends[i - 1]).count());
  }
  const long pixels = flags.pixels > 0 ? std::min<long>(flags.pixels, static_cast<long>(flags.rows) * flags.cols)
                                       : static_cast<long>(flags.rows) * flags.cols;
  const double flops = MetaStepFlops(PassMacs(trunk.siren), flags.steps, flags.batch, pixels);
  const Spread step(ms);
  const double rate = flops / (step.median * 1e6);
  std::cout << "bench trunk: meta-training step (batch " << flags.batch << " x " << pixels
            << " pixels, K = " << flags.steps << ", second order, Adam; " << flags.threads
            << " thread" << (flags.threads > 1 ? "s" : "") << "): " << Ms(step.median)
            << " ms median (" << Ms(step.min) << "-" << Ms(step.max) << "); "
            << FormatFixed(rate, 1) << " GFLOP/s of GEMM, "
            << FormatFixed(100 * rate / gemm_gflops, 0) << " % of the GEMM rate ("
            << ToString(summary.termination_type) << ")\n";
  nlohmann::json out = {{"pixels", pixels},
                        {"gemm_gflop", flops / 1e9},
                        {"gflops", rate},
                        {"share_of_gemm_rate", rate / gemm_gflops},
                        {"ms", ms}};
  out.update(step.Json("ms_"));
  return out;
}

void RunTrunkBench(const TrunkFlags& flags) {
  const std::vector<std::string> workloads = SplitList(flags.workloads);
  for (const std::string& w : workloads) {
    if (w != "fit" && w != "meta-step") {
      throw UsageError("--workloads: expected fit and/or meta-step, got '" + w + "'");
    }
  }
  auto wants = [&](const char* name) {
    return std::find(workloads.begin(), workloads.end(), name) != workloads.end();
  };
  // The reference rate is the float product's, measured before the precision is set, so
  // that bfloat16 products read as a share of what float reaches (above 100 % if faster);
  // the trunk is made after it, so that it packs its weights for bfloat16 products.
  const GemmRates gemm = MeasureGemmGflops(20);
  ApplyProductPrecision(flags.products);
  const SensorTrunk trunk = MakeTrunk(flags);
  std::cout << "bench trunk: width " << flags.width << ", " << flags.layers << " layers, d = "
            << flags.latent
            << (flags.spatial.empty() ? "" : " (spatial latents " + flags.spatial + ")")
            << ", C = " << flags.channels << ", " << trunk.siren.NumParameters()
            << " parameters, " << flags.rows << "x" << flags.cols << " frames, float, "
            << flags.products << " products\n";
  const double gemm_gflops = gemm.Reference();
  std::cout << "bench trunk: float GEMM 4096x256x256, one thread (best of 20): Eigen "
            << FormatFixed(gemm.eigen, 1) << " GFLOP/s, the passes' kernel "
            << FormatFixed(gemm.kernel, 1) << "; the GEMM rate below is the better, "
            << FormatFixed(gemm_gflops, 1) << "\n";
  nlohmann::json figures = {{"bench", "trunk"},
                            {"machine", MachineDescription()},
                            {"width", flags.width},
                            {"layers", flags.layers},
                            {"latent", flags.latent},
                            {"channels", flags.channels},
                            {"spatial", flags.spatial.empty() ? nlohmann::json(nullptr)
                                                              : nlohmann::json(flags.spatial)},
                            {"rows", flags.rows},
                            {"cols", flags.cols},
                            {"steps", flags.steps},
                            {"batch", flags.batch},
                            {"threads", flags.threads},
                            {"products", flags.products},
                            {"repeats", flags.repeats},
                            {"parameters", trunk.siren.NumParameters()},
                            {"gemm_gflops", gemm_gflops},
                            {"gemm_gflops_eigen", gemm.eigen},
                            {"gemm_gflops_kernel", gemm.kernel}};
  if (wants("fit")) figures["fit"] = RunFit(flags, trunk, gemm_gflops);
  if (wants("meta-step")) figures["meta_step"] = RunMetaStep(flags, trunk, gemm_gflops);
  if (flags.json) EmitJson(figures);
}

}  // namespace

void RegisterTrunkSuite(CLI::App* bench, CommandBody* selected) {
  auto flags = std::make_shared<TrunkFlags>();
  CLI::App* sub = bench->add_subcommand(
      "trunk",
      "The trunk's workloads at any size on frames it generates: a meta_sgd:K fit of one frame "
      "(the K steps and the whole fit) and one second-order meta-training step (batch x "
      "pixels, Adam); median/min/max ms over repeats, GEMM FLOPs and GFLOP/s.");
  sub->add_option("--width", flags->width, "Units per sine layer (default 64)")
      ->check(CLI::Range(1, 4096));
  sub->add_option("--layers", flags->layers, "Sine layers (default 3)")->check(CLI::Range(1, 64));
  sub->add_option("--latent", flags->latent, "Latent dimension d (default 64)")
      ->check(CLI::Range(1, 4096));
  sub->add_option("--channels", flags->channels, "Output channels C (default 1)")
      ->check(CLI::Range(1, 3));
  sub->add_option("--rows", flags->rows, "Frame rows (default 70, the bubble's)")
      ->check(CLI::Range(1, 4096));
  sub->add_option("--cols", flags->cols, "Frame columns (default 88)")->check(CLI::Range(1, 4096));
  sub->add_option("--steps", flags->steps, "Meta-SGD steps K, of the fit and the inner loop (default 3)")
      ->check(CLI::Range(0, 1000));
  sub->add_option("--batch", flags->batch, "Frames per meta-training step (default 32)")
      ->check(CLI::Range(1, 4096));
  sub->add_option("--pixels", flags->pixels,
                  "Random pixels per frame per meta-training step; 0 = all (default 512)")
      ->check(CLI::Range(0, 1 << 24));
  sub->add_option("--threads", flags->threads,
                  "Trainer threads of the meta-training step (the fit runs on one; default 1)")
      ->check(CLI::Range(1, 256));
  sub->add_option("--repeats", flags->repeats, "Timed repetitions of each workload (default 20)")
      ->check(CLI::Range(1, 100000));
  sub->add_option("--workloads", flags->workloads, "fit,meta-step (default both)");
  sub->add_option("--spatial", flags->spatial,
                  "Spatial latents GHxGWxC counted in --latent (train --spatial-latent; default "
                  "none)");
  AddProductPrecisionFlag(sub, &flags->products);
  sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
  sub->callback([flags, selected]() { *selected = [flags]() { RunTrunkBench(*flags); }; });
}

}  // namespace tactfunc::apps::bench
