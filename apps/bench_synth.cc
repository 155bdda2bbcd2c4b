// Copyright 2026 The tactfunc Authors.
//
// Benchmarks of the contact simulator: one rendering per sensor, and a whole paired
// contact as `tactfunc synth` produces it (sample, render both sensors, PNG-encode
// both; with_clean also encodes the noise-free copies, as `synth --clean`) on 1 and 2
// threads. items_per_second of paired_contact is paired frames/s.
#include <atomic>

#include "apps/bench.h"
#include "benchmark/benchmark.h"
#include "estimation/data/image_io.h"
#include "models/simulator/contact_simulator.h"
#include "models/core/seed.h"
#include "models/simulator/tool.h"

namespace tactfunc::apps {
namespace {

const ContactSimulator& Simulator() {
  static const ContactSimulator simulator{ContactSimulator::Options()};
  return simulator;
}

void BM_Render(benchmark::State& state, SensorKind sensor) {
  const ContactSimulator& simulator = Simulator();
  const std::vector<std::string> tools = ToolNames();
  std::uint64_t i = 0;
  for (auto _ : state) {
    const PairedContact paired =
        simulator.SamplePairedContact(tools[i % tools.size()], DeriveSeed(1, i));
    const Contact& contact =
        sensor == SensorKind::kSoftBubble ? paired.bubble : paired.gelslim;
    benchmark::DoNotOptimize(simulator.Render(sensor, contact, DeriveSeed(2, i)));
    ++i;
  }
  state.SetItemsProcessed(state.iterations());
}

void BM_PairedContact(benchmark::State& state, bool with_clean) {
  const ContactSimulator& simulator = Simulator();
  const std::vector<std::string> tools = ToolNames();
  std::uint64_t i = state.thread_index() * 1000003ull;
  for (auto _ : state) {
    const PairedContact paired =
        simulator.SamplePairedContact(tools[i % tools.size()], DeriveSeed(1, i));
    const auto bubble = simulator.Render(SensorKind::kSoftBubble, paired.bubble, DeriveSeed(2, i));
    const auto gel = simulator.Render(SensorKind::kGelSlim, paired.gelslim, DeriveSeed(3, i));
    benchmark::DoNotOptimize(EncodePng(bubble.frame, PixelEncoding::kDepthU16Micrometres));
    benchmark::DoNotOptimize(EncodePng(gel.frame, PixelEncoding::kRgb8));
    if (with_clean) {
      benchmark::DoNotOptimize(EncodePng(bubble.clean, PixelEncoding::kDepthU16Micrometres));
      benchmark::DoNotOptimize(EncodePng(gel.clean, PixelEncoding::kRgb8));
    }
    ++i;
  }
  state.SetItemsProcessed(state.iterations());
}

}  // namespace

void RegisterSynthBenchmarks() {
  benchmark::RegisterBenchmark("synth/render_bubble", BM_Render, SensorKind::kSoftBubble)
      ->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("synth/render_gelslim", BM_Render, SensorKind::kGelSlim)
      ->Unit(benchmark::kMillisecond);
  benchmark::RegisterBenchmark("synth/paired_contact", BM_PairedContact, false)
      ->Unit(benchmark::kMillisecond)
      ->UseRealTime()
      ->Threads(1)
      ->Threads(2);
  benchmark::RegisterBenchmark("synth/paired_contact_with_clean", BM_PairedContact, true)
      ->Unit(benchmark::kMillisecond)
      ->UseRealTime()
      ->Threads(1)
      ->Threads(2);
}

}  // namespace tactfunc::apps
