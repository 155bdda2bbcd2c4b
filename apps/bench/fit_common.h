// Copyright 2026 The tactfunc Authors.
//
// Benchmarks of latent fitting (estimation/fitting/latent_fitter.h, knn_index.h):
//
//   tactfunc bench fit      every LatentFitter strategy on the test frames of a dataset:
//                           per-frame time (median, p90) and mean PSNR, against the
//                           converged PSNR (ceres:100, tight tolerances, double), the
//                           autodiff / analytic Jacobian time ratio, a Pareto plot (PNG)
//                           and a markdown table for docs/BENCHMARKS.md.
//   tactfunc bench kernels  Google Benchmark programs of the kernels one fit is made of:
//                           trunk forward, forward + latent Jacobian (analytic), the
//                           autodiff Jacobian, one LM iteration, one meta-SGD step, and an
//                           Eigen float GEMM (GFLOP/s, to re-measure -march=native).
//   tactfunc bench knn      FLANN kd-forest / k-means at several checks against brute force:
//                           recall@8, median ms per query, build time.
//   tactfunc bench trunk    the trunk's two workloads at any size on generated frames: a
//                           meta_sgd:K fit (its steps and the whole fit) and one second-order
//                           meta-training step, median/min/max over repeats, GEMM FLOPs
//                           (scripts/bench_peer.sh runs it beside PyTorch).
//
// `bench fit` and `bench knn` time with std::chrono, one measurement per frame (query),
// and report the distribution (median, p90): they measure what a user waits per frame,
// on real frames whose iteration counts differ, which is a distribution and not the
// steady state of one repeated call that Google Benchmark is made for. `bench kernels`
// is that steady state and uses Google Benchmark (RunRegisteredBenchmarks, medians over
// repetitions).
//
// Files: fit_suite.cc (bench fit; its plot and table in fit_report.cc), fit_kernels.cc
// (bench kernels), knn_suite.cc (bench knn), trunk_suite.cc (bench trunk); this header
// holds what they share: timing, sample statistics and report helpers.
#ifndef TACTFUNC_APPS_BENCH_FIT_COMMON_H_
#define TACTFUNC_APPS_BENCH_FIT_COMMON_H_

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

#include "apps/command.h"
#include "estimation/data/trunk_targets.h"
#include "models/core/internal/elapsed.h"
#include "models/core/sensor.h"
#include "models/trunk/latent_modulated_siren.h"
#include "nlohmann/json.hpp"

namespace tactfunc::apps::bench {

using Clock = std::chrono::steady_clock;

using internal::MsSince;  // milliseconds since a Clock::time_point
// q-quantile (nearest rank) of a sample; NaN if empty.
double Quantile(std::vector<double> values, double q);
// Median; NaN if empty.
double Median(const std::vector<double>& values);
// Mean of the finite values; NaN if there is none.
double Mean(const std::vector<double>& values);
// Three significant digits for times that span 0.01 .. 10,000 ms ("n/a" if not finite).
std::string Ms(double value);
nlohmann::json FiniteOrNull(double value);
// The non-empty parts joined by spaces (the command line of a report).
std::string CommandLine(const std::vector<std::string>& parts);

// A rows x cols frame that `siren` generates from a random latent (each entry 0.3 N(0, 1))
// plus Gaussian noise of standard deviation 0.01, every pixel valid, drawn from `seed`:
// what the kernel and trunk benchmarks fit (no dataset needed; their cost does not depend
// on the values).
TrunkTargets TrunkGeneratedFrame(const LatentModulatedSiren& siren, int rows, int cols,
                                 std::uint64_t seed);

// The suites (registered by RegisterFitBenchmarks, apps/bench.h).
void RegisterFitSuite(CLI::App* bench, CommandBody* selected);      // fit_suite.cc
void RegisterKernelSuite(CLI::App* bench, CommandBody* selected);   // fit_kernels.cc
void RegisterKnnSuite(CLI::App* bench, CommandBody* selected);      // knn_suite.cc
void RegisterTrunkSuite(CLI::App* bench, CommandBody* selected);    // trunk_suite.cc

}  // namespace tactfunc::apps::bench

#endif  // TACTFUNC_APPS_BENCH_FIT_COMMON_H_
