// Copyright 2026 The tactfunc Authors.
#include "estimation/data/synthetic_dataset.h"

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <stdexcept>

#include "estimation/data/dataset.h"
#include "estimation/data/internal/path_util.h"
#include "models/core/parallel_for.h"
#include "estimation/data/image_io.h"
#include "models/core/seed.h"
#include "models/simulator/tool.h"

namespace tactfunc {
namespace {

bool IsTestContact(int k, double test_fraction) {
  return std::floor((k + 1) * test_fraction) > std::floor(k * test_fraction);
}

std::string FrameId(std::int64_t index) {
  char buffer[24];
  std::snprintf(buffer, sizeof(buffer), "%06lld", static_cast<long long>(index));
  return buffer;
}

}  // namespace

bool SynthesisPlan::IsValid(std::string* error) const {
  if (out.empty()) {
    *error = "SynthesisPlan::out must name a folder";
    return false;
  }
  if (tools.empty()) {
    *error = "SynthesisPlan::tools must name at least one tool";
    return false;
  }
  if (sensors.empty()) {
    *error = "SynthesisPlan::sensors must name at least one sensor";
    return false;
  }
  if (frames_per_tool < 1) {
    *error = "SynthesisPlan::frames_per_tool must be >= 1, got " +
             std::to_string(frames_per_tool);
    return false;
  }
  if (!(test_fraction >= 0.0 && test_fraction <= 1.0)) {
    *error = "SynthesisPlan::test_fraction must be in [0, 1], got " +
             std::to_string(test_fraction);
    return false;
  }
  if (threads < 1) {
    *error = "SynthesisPlan::threads must be >= 1, got " + std::to_string(threads);
    return false;
  }
  if (png_compression < 0 || png_compression > 9) {
    *error = "SynthesisPlan::png_compression must be in [0, 9], got " +
             std::to_string(png_compression);
    return false;
  }
  return true;
}

double SyntheticNormalizationScale(const ContactSimulator& simulator,
                                   SensorKind sensor) {
  // Bubble: the deepest press the sampler draws, so indentations land in [0, 1].
  // GelSlim: intensity differences stay well inside +-0.5 (docs/SIMULATOR.md), so 0.5
  // maps them into [-1, 1] while a blank frame stays exactly 0.
  if (sensor == SensorKind::kSoftBubble) {
    return simulator.options().sampling.bubble_depth_max_m;
  }
  return 0.5;
}

SynthesisReport Synthesize(const SynthesisPlan& plan,
                           const ContactSimulator::Options& simulator_options,
                           const SynthesisProgress& progress) {
  std::string error;
  if (!plan.IsValid(&error)) throw std::invalid_argument(error);
  const auto start = std::chrono::steady_clock::now();
  const ContactSimulator simulator(simulator_options);
  for (const std::string& tool : plan.tools) GetTool(tool);

  DatasetWriter::Options writer_options;
  writer_options.png_compression = plan.png_compression;
  writer_options.source = "tactfunc synth";
  writer_options.overwrite = plan.overwrite;
  writer_options.meta_json = "{\"seed\": " + std::to_string(plan.seed) +
                             ", \"frames_per_tool\": " +
                             std::to_string(plan.frames_per_tool);
  // Simulator settings a user can change from the CLI are recorded when not default.
  if (simulator_options.gelslim.marker_darkness != GelSlimOptions().marker_darkness) {
    writer_options.meta_json += ", \"gelslim_marker_darkness\": " +
                                internal::FormatDoubleShort(simulator_options.gelslim.marker_darkness);
  }
  writer_options.meta_json += "}";
  DatasetWriter writer(plan.out, writer_options);
  for (SensorKind sensor : plan.sensors) {
    SensorInfo info;
    info.kind = sensor;
    const Image& reference = simulator.Reference(sensor);
    info.rows = reference.rows;
    info.cols = reference.cols;
    info.channels = reference.channels;
    info.encoding = sensor == SensorKind::kSoftBubble
                        ? PixelEncoding::kDepthU16Micrometres
                        : PixelEncoding::kRgb8;
    info.pixel_pitch_m = simulator.PixelPitch(sensor);
    info.normalization_scale = SyntheticNormalizationScale(simulator, sensor);
    writer.AddSensor(info, reference);
  }

  const std::int64_t contacts =
      static_cast<std::int64_t>(plan.tools.size()) * plan.frames_per_tool;
  internal::ParallelFor(contacts, plan.threads, [&](std::int64_t i) {
    const std::string& tool = plan.tools[i / plan.frames_per_tool];
    const int k = static_cast<int>(i % plan.frames_per_tool);
    const std::uint64_t contact_seed = DeriveSeed(plan.seed, 3 * i);
    const PairedContact paired = simulator.SamplePairedContact(tool, contact_seed);
    const Split split = IsTestContact(k, plan.test_fraction) ? Split::kTest : Split::kTrain;
    for (SensorKind sensor : plan.sensors) {
      const Contact& contact =
          sensor == SensorKind::kSoftBubble ? paired.bubble : paired.gelslim;
      const std::uint64_t noise_seed =
          DeriveSeed(plan.seed, 3 * i + (sensor == SensorKind::kSoftBubble ? 1 : 2));
      const ContactSimulator::Rendering rendering =
          simulator.Render(sensor, contact, noise_seed);
      // The contact is the frame's label (PoseLabel is Contact).
      writer.AddFrame(FrameId(i), sensor, rendering.frame,
                      plan.write_clean ? &rendering.clean : nullptr, contact, split);
    }
    if (progress) progress(1);
  });
  writer.Finish();

  SynthesisReport report;
  report.contacts = contacts;
  report.frames = contacts * static_cast<std::int64_t>(plan.sensors.size());
  report.seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  report.bytes = Dataset::Open(plan.out).BytesOnDisk();
  return report;
}

}  // namespace tactfunc
