// Copyright 2026 The tactfunc Authors.
//
// tactfunc synth: a paired Soft Bubble + GelSlim dataset from the contact simulator.
#include <algorithm>
#include <atomic>
#include <cstdio>
#include <exception>
#include <filesystem>
#include <iostream>
#include <mutex>
#include <thread>

#include "CLI/CLI.hpp"
#include "apps/command.h"
#include "apps/model_inputs.h"
#include "apps/progress_bar.h"
#include "estimation/data/synthetic_dataset.h"
#include "estimation/data/dataset.h"
#include "models/simulator/contact_simulator.h"
#include "models/simulator/tool.h"

namespace tactfunc::apps {
namespace {

struct SynthFlags {
  std::string out;
  int frames_per_tool = 20;
  std::uint64_t seed = 0;
  std::string tools;  // empty = all twelve
  std::string sensors = "bubble,gelslim";
  int threads = 0;
  double test_fraction = 0.1;
  double marker_darkness = GelSlimOptions().marker_darkness;
  bool overwrite = false;
  bool force = false;
  bool clean = false;
  bool json = false;
};

// Beyond this many bytes synth asks for --force even when the disk has room.
constexpr std::uint64_t kLargeDatasetBytes = std::uint64_t{64} << 30;  // 64 GiB

// Prints the size of the dataset about to be written -- an upper bound: every image's
// uncompressed pixel bytes (PNG files are smaller) -- and refuses, unless --force,
// one larger than the free space where it goes or than kLargeDatasetBytes.
void CheckSize(const SynthFlags& flags, const SynthesisPlan& plan,
               const ContactSimulator::Options& simulator) {
  const std::uint64_t contacts =
      static_cast<std::uint64_t>(plan.tools.size()) * static_cast<std::uint64_t>(plan.frames_per_tool);
  std::uint64_t per_contact = 0;
  for (SensorKind kind : plan.sensors) {
    per_contact += kind == SensorKind::kSoftBubble
                       ? std::uint64_t{2} * simulator.bubble.rows * simulator.bubble.cols
                       : std::uint64_t{3} * simulator.gelslim.rows * simulator.gelslim.cols;
  }
  if (plan.write_clean) per_contact *= 2;
  const std::uint64_t images = contacts * plan.sensors.size() * (plan.write_clean ? 2 : 1);
  const std::uint64_t bound = contacts * per_contact;
  // Free space on the file system the folder will be on (its nearest existing parent).
  std::error_code ec;
  std::filesystem::path where = std::filesystem::absolute(plan.out, ec);
  while (!where.empty() && !std::filesystem::exists(where, ec) && where != where.root_path()) {
    where = where.parent_path();
  }
  const std::filesystem::space_info space = std::filesystem::space(where, ec);
  const bool known = !ec;
  std::cerr << "synth: " << contacts << " contacts, " << images << " images: at most "
            << FormatBytes(bound) << " on disk (uncompressed pixel bytes; PNG files are smaller)";
  if (known) std::cerr << ", " << FormatBytes(space.available) << " free at " << where.string();
  std::cerr << "\n";
  if (flags.force) return;
  if (known && bound > space.available) {
    throw UsageError("--frames-per-tool " + std::to_string(plan.frames_per_tool) + ": " +
                     std::to_string(images) + " images may take up to " + FormatBytes(bound) +
                     ", more than the " + FormatBytes(space.available) + " free at " +
                     where.string() + "; write fewer frames, or pass --force to try anyway");
  }
  if (bound > kLargeDatasetBytes) {
    throw UsageError("--frames-per-tool " + std::to_string(plan.frames_per_tool) + ": " +
                     std::to_string(images) + " images may take up to " + FormatBytes(bound) +
                     " (more than " + FormatBytes(kLargeDatasetBytes) +
                     "); pass --force to write a dataset this large");
  }
}

void RunSynth(const SynthFlags& flags) {
  SynthesisPlan plan;
  plan.out = flags.out;
  plan.frames_per_tool = flags.frames_per_tool;
  plan.seed = flags.seed;
  plan.test_fraction = flags.test_fraction;
  plan.overwrite = flags.overwrite;
  plan.write_clean = flags.clean;
  plan.threads = ResolveThreads(flags.threads);
  plan.tools = flags.tools.empty() ? ToolNames() : SplitList(flags.tools);
  for (const std::string& tool : plan.tools) GetTool(tool);  // throws with the valid names
  // The plan's default is both sensors; --sensors replaces it.
  plan.sensors = ParseSensorsFlag(flags.sensors);
  if (plan.sensors.empty()) throw UsageError("--sensors: expected at least one sensor");

  ContactSimulator::Options simulator_options;
  simulator_options.gelslim.marker_darkness = flags.marker_darkness;
  CheckSize(flags, plan, simulator_options);

  ProgressBar bar("synth", static_cast<std::int64_t>(plan.tools.size()) * plan.frames_per_tool,
                  "contacts", ProgressBar::Lines::kWhenNotDrawn);
  const SynthesisReport report = Synthesize(plan, simulator_options,
                                            [&bar](int n) { bar.Tick(n); });
  bar.Finish();

  std::cout << "synth: wrote " << report.contacts << " paired frames (" << report.frames
            << " images, " << plan.tools.size() << " tools, " << plan.sensors.size()
            << " sensor(s)) to " << plan.out << " in " << report.seconds << " s ("
            << report.contacts / std::max(report.seconds, 1e-9)
            << " contacts/s on " << plan.threads << " threads, "
            << FormatBytes(report.bytes) << ")\n";
  if (flags.json) {
    nlohmann::json sensors = nlohmann::json::array();
    for (SensorKind kind : plan.sensors) sensors.push_back(ToString(kind));
    // "frames" counts paired frames (one per contact, every sensor rendered);
    // "images" counts the files, frames x sensors.
    EmitJson({{"frames", report.contacts},
              {"images", report.frames},
              {"contacts", report.contacts},
              {"tools", plan.tools.size()},
              {"sensors", sensors},
              {"out", plan.out},
              {"seconds", report.seconds},
              {"contacts_per_s", report.contacts / std::max(report.seconds, 1e-9)},
              {"threads", plan.threads},
              {"bytes", report.bytes}});
  }
}

}  // namespace

void RegisterSynth(CLI::App& app, CommandBody* selected) {
  auto flags = std::make_shared<SynthFlags>();
  CLI::App* sub = app.add_subcommand(
      "synth",
      "Synthesize a paired Soft Bubble + GelSlim dataset with known SE(2) poses "
      "(docs/SIMULATOR.md, docs/DATASET_FORMAT.md).");
  sub->add_option("--out", flags->out, "Output dataset folder")->required();
  sub->add_option("--frames-per-tool", flags->frames_per_tool,
                  "Contacts per tool (each renders every sensor)")
      ->check(CLI::Range(1, 1000000));
  sub->add_option("--seed", flags->seed, "Seed; the same seed gives the same dataset");
  sub->add_option("--tools", flags->tools,
                  "Comma-separated tool names (default: all twelve; `tactfunc info "
                  "--tools` lists them)");
  sub->add_option("--sensors", flags->sensors, "Comma-separated: bubble,gelslim");
  sub->add_option("--threads", flags->threads, "Worker threads (default: all cores)")
      ->check(CLI::Range(0, 256));
  sub->add_option("--test-fraction", flags->test_fraction,
                  "Fraction of each tool's contacts in the test split")
      ->check(CLI::Range(0.0, 1.0));
  sub->add_option("--gelslim-marker-darkness", flags->marker_darkness,
                  "Darkness of the GelSlim's printed marker dots, 0 (a sensor without "
                  "markers) to 1 (default 0.7; docs/SIMULATOR.md)")
      ->check(CLI::Range(0.0, 1.0));
  sub->add_flag("--overwrite", flags->overwrite, "Replace an existing dataset at --out");
  sub->add_flag("--force", flags->force,
                "Write the dataset even if its size bound (printed first) exceeds the free "
                "disk space or 68.72 GB (64 GiB)");
  sub->add_flag("--clean", flags->clean,
                "Also store noise-free copies of every frame (for PSNR against clean "
                "frames; about 1.6x the time and 1.5x the bytes)");
  sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
  sub->callback([flags, selected]() { *selected = [flags]() { RunSynth(*flags); }; });
}

}  // namespace tactfunc::apps
