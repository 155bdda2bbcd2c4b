// Copyright 2026 The tactfunc Authors.
//
// `tactfunc bench <suite>`: Google Benchmark suites for the speed targets. Each suite
// registers its benchmarks, runs them with repetitions and reports medians; speed
// targets are checked here, never in unit tests.
#ifndef TACTFUNC_APPS_BENCH_H_
#define TACTFUNC_APPS_BENCH_H_

#include <map>
#include <string>
#include <vector>

#include "apps/command.h"
#include "nlohmann/json.hpp"

namespace tactfunc::apps {

// One aggregated result (the median over repetitions).
struct BenchResult {
  std::string name;         // benchmark name, e.g. "synth/paired_contact/threads:2"
  double real_ms = 0;       // median wall time per iteration, milliseconds
  double cpu_ms = 0;        // median CPU time per iteration, milliseconds
  std::map<std::string, double> counters;  // e.g. items_per_second
};

// Runs the benchmarks registered so far with `args` (Google Benchmark flags such as
// --benchmark_filter, --benchmark_repetitions) and returns the medians.
std::vector<BenchResult> RunRegisteredBenchmarks(const std::vector<std::string>& args);

// The machine, for reports: {"cpu": ..., "cores": ..., "native": bool}.
nlohmann::json MachineDescription();

// Suites.
void RegisterSynthBenchmarks();
// `bench fit`, `bench kernels` and `bench knn` (apps/bench/): adds the three subcommands
// to `bench`.
void RegisterFitBenchmarks(CLI::App* bench, CommandBody* selected);
// `bench posterior` (apps/bench_posterior.cc): calibration and speed of the pose posteriors.
void RegisterPosteriorBenchmark(CLI::App* bench, CommandBody* selected);
// `bench pose-mcmc` (apps/bench_pose_mcmc.cc): which MCMC kernel mixes better over the
// generator path's pose.
void RegisterPoseMcmcBenchmark(CLI::App* bench, CommandBody* selected);
// `bench pca` (apps/bench_pca.cc): the wall time of eval's PCA fit.
void RegisterPcaBenchmark(CLI::App* bench, CommandBody* selected);
// `bench photometric` (apps/bench_photometric.cc): the optical sensors' photometric trunk
// against PCA at the same bytes per frame.
void RegisterPhotometricBenchmark(CLI::App* bench, CommandBody* selected);
// `bench video-memory` (apps/bench_video_memory.cc): peak memory of reading long videos.
void RegisterVideoMemoryBenchmark(CLI::App* bench, CommandBody* selected);

}  // namespace tactfunc::apps

#endif  // TACTFUNC_APPS_BENCH_H_
