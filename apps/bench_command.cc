// Copyright 2026 The tactfunc Authors.
#include <unistd.h>

#include <algorithm>
#include <fstream>
#include <iostream>
#include <thread>

#include "CLI/CLI.hpp"
#include "apps/bench.h"
#include "apps/command.h"
#include "benchmark/benchmark.h"

namespace tactfunc::apps {
namespace {

// Keeps the console output and collects the medians.
class CollectingReporter : public benchmark::ConsoleReporter {
 public:
  // Colour only on a terminal: redirected output (docs, CI logs) stays plain text.
  explicit CollectingReporter(std::vector<BenchResult>* results)
      : benchmark::ConsoleReporter(isatty(fileno(stdout)) ? OO_Defaults : OO_Tabular),
        results_(results) {}
  void ReportRuns(const std::vector<Run>& runs) override {
    for (const Run& run : runs) {
      const bool is_median = run.run_type == Run::RT_Aggregate && run.aggregate_name == "median";
      const bool single = run.run_type == Run::RT_Iteration && run.repetitions <= 1;
      if (!is_median && !single) continue;
      BenchResult result;
      result.name = run.run_name.str();
      const double to_ms = 1e3 / benchmark::GetTimeUnitMultiplier(run.time_unit);
      result.real_ms = run.GetAdjustedRealTime() * to_ms;
      result.cpu_ms = run.GetAdjustedCPUTime() * to_ms;
      for (const auto& [key, counter] : run.counters) result.counters[key] = counter.value;
      results_->push_back(result);
    }
    ConsoleReporter::ReportRuns(runs);
  }

 private:
  std::vector<BenchResult>* results_;
};

nlohmann::json ResultsJson(const std::vector<BenchResult>& results) {
  nlohmann::json list = nlohmann::json::array();
  for (const BenchResult& r : results) {
    nlohmann::json counters = nlohmann::json::object();
    for (const auto& [key, value] : r.counters) counters[key] = value;
    list.push_back({{"name", r.name}, {"ms_median", r.real_ms},
                    {"cpu_ms_median", r.cpu_ms}, {"counters", counters}});
  }
  return list;
}

struct BenchFlags {
  bool json = false;
  std::vector<std::string> extra;
};

void RunSynthBench(const BenchFlags& flags) {
  RegisterSynthBenchmarks();
  const std::vector<BenchResult> results = RunRegisteredBenchmarks(flags.extra);
  double one = 0, two = 0;
  for (const BenchResult& r : results) {
    if (r.name.find("paired_contact/") == std::string::npos) continue;
    const double rate = r.counters.count("items_per_second") ? r.counters.at("items_per_second") : 0;
    if (r.name.find("threads:2") != std::string::npos) two = rate;
    if (r.name.find("threads:1") != std::string::npos) one = rate;
  }
  std::cout << "synth: " << one << " paired frames/s on 1 thread, " << two
            << " on 2 threads (render + PNG encode both sensors; target >= 200 on 2 cores)\n";
  if (flags.json) {
    EmitJson({{"bench", "synth"},
              {"machine", MachineDescription()},
              {"paired_frames_per_s_1thread", one},
              {"paired_frames_per_s_2threads", two},
              {"target_paired_frames_per_s", 200},
              {"results", ResultsJson(results)}});
  }
}

}  // namespace

std::vector<BenchResult> RunRegisteredBenchmarks(const std::vector<std::string>& args) {
  std::vector<std::string> storage = {"tactfunc-bench"};
  bool has_repetitions = false;
  for (const std::string& a : args) {
    if (a.rfind("--benchmark_repetitions", 0) == 0) has_repetitions = true;
    storage.push_back(a);
  }
  if (!has_repetitions) storage.push_back("--benchmark_repetitions=5");
  storage.push_back("--benchmark_report_aggregates_only=true");
  std::vector<char*> argv;
  for (std::string& s : storage) argv.push_back(s.data());
  int argc = static_cast<int>(argv.size());
  benchmark::Initialize(&argc, argv.data());
  if (benchmark::ReportUnrecognizedArguments(argc, argv.data())) {
    throw UsageError("unrecognised benchmark flags (see --benchmark_* in --help)");
  }
  std::vector<BenchResult> results;
  CollectingReporter reporter(&results);
  benchmark::RunSpecifiedBenchmarks(&reporter);
  benchmark::Shutdown();
  return results;
}

nlohmann::json MachineDescription() {
  std::string cpu = "unknown";
  std::ifstream cpuinfo("/proc/cpuinfo");
  for (std::string line; std::getline(cpuinfo, line);) {
    if (line.rfind("model name", 0) == 0) {
      cpu = line.substr(line.find(':') + 2);
      break;
    }
  }
#if defined(__AVX512F__)
  const std::string gemm_kernel = "avx512";  // internal::SmallGemm's kernel in this build
#elif defined(__AVX2__) && defined(__FMA__)
  const std::string gemm_kernel = "avx2";
#else
  const std::string gemm_kernel = "eigen";
#endif
  return {{"cpu", cpu},
          {"cores", std::thread::hardware_concurrency()},
          {"avx512_compiled", gemm_kernel == "avx512"},
          {"gemm_kernel", gemm_kernel}};
}

void RegisterBench(CLI::App& app, CommandBody* selected) {
  CLI::App* bench = app.add_subcommand(
      "bench",
      "Google Benchmark suites for the speed targets; reports medians and the machine. "
      "Extra --benchmark_* flags pass through.");
  bench->require_subcommand(1);
  auto flags = std::make_shared<BenchFlags>();
  CLI::App* synth = bench->add_subcommand(
      "synth", "Contact simulator: paired frames/s (render + PNG encode), 1 and 2 threads.");
  synth->add_flag("--json", flags->json, "Print the figures as one JSON line");
  synth->allow_extras();
  synth->callback([flags, synth, selected]() {
    flags->extra = synth->remaining();
    *selected = [flags]() { RunSynthBench(*flags); };
  });
  RegisterFitBenchmarks(bench, selected);
  RegisterPosteriorBenchmark(bench, selected);
  RegisterPoseMcmcBenchmark(bench, selected);
  RegisterPcaBenchmark(bench, selected);
  RegisterPhotometricBenchmark(bench, selected);
  RegisterVideoMemoryBenchmark(bench, selected);
}

}  // namespace tactfunc::apps
