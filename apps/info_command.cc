// Copyright 2026 The tactfunc Authors.
//
// tactfunc info: what a dataset holds -- counts per sensor and split, resolutions,
// tools, bytes on disk; or, with --tools, the simulator's twelve tools.
#include <cstdio>
#include <iostream>
#include <map>

#include "apps/command.h"
#include "apps/dataset_flags.h"
#include "estimation/dataset.h"
#include "models/tool.h"

namespace tactfunc::apps {
namespace {

struct InfoFlags {
  std::string dir;
  DatasetFlags data;
  bool tools = false;
  bool json = false;
};

void PrintTools(bool json) {
  nlohmann::json list = nlohmann::json::array();
  std::printf("%-12s %-9s %-8s %s\n", "tool", "symmetry", "height", "description");
  for (const Tool& tool : ToolSet()) {
    const std::string symmetry = tool.symmetry_order() == 0
                                     ? "SO(2)"
                                     : "C" + std::to_string(tool.symmetry_order());
    std::printf("%-12s %-9s %5.1f mm %s\n", tool.name().c_str(), symmetry.c_str(),
                tool.max_height() * 1e3, tool.description().c_str());
    list.push_back({{"name", tool.name()}, {"symmetry_order", tool.symmetry_order()}});
  }
  if (json) EmitJson({{"tools", list}});
}

void RunInfo(const InfoFlags& flags) {
  if (flags.tools) {
    PrintTools(flags.json);
    return;
  }
  if (flags.dir.empty()) throw UsageError("a dataset folder is required (or --tools)");
  const Dataset dataset = OpenDataset(flags.dir, flags.data);
  nlohmann::json sensors = nlohmann::json::object();
  std::cout << "dataset " << dataset.root() << "\n";
  for (SensorKind sensor : dataset.sensors()) {
    const SensorInfo& info = dataset.sensor_info(sensor);
    const auto all = dataset.FrameIndices(sensor);
    const auto train = dataset.FrameIndices(sensor, Split::kTrain);
    const auto test = dataset.FrameIndices(sensor, Split::kTest);
    std::map<std::string, int> tools;
    int labelled = 0;
    for (std::size_t i : all) {
      const FrameRecord& record = dataset.frames()[i];
      if (record.label) {
        ++labelled;
        ++tools[record.label->tool];
      }
    }
    std::printf("  %-8s %5zu frames (%zu train, %zu test, %d labelled)  %dx%dx%d %s",
                ToString(sensor), all.size(), train.size(), test.size(), labelled,
                info.rows, info.cols, info.channels, ToString(info.encoding));
    if (info.pixel_pitch_m > 0) {
      std::printf("  %.3f mm/px (%.1f x %.1f mm)", info.pixel_pitch_m * 1e3,
                  info.cols * info.pixel_pitch_m * 1e3, info.rows * info.pixel_pitch_m * 1e3);
    }
    std::printf("\n");
    nlohmann::json tool_counts = nlohmann::json::object();
    for (const auto& [tool, count] : tools) tool_counts[tool] = count;
    sensors[ToString(sensor)] = {{"frames", all.size()},
                                 {"train", train.size()},
                                 {"test", test.size()},
                                 {"labelled", labelled},
                                 {"rows", info.rows},
                                 {"cols", info.cols},
                                 {"channels", info.channels},
                                 {"encoding", ToString(info.encoding)},
                                 {"pixel_pitch_m", info.pixel_pitch_m},
                                 {"tools", tool_counts}};
  }
  const std::uint64_t bytes = dataset.BytesOnDisk();
  std::cout << "  tools: ";
  std::map<std::string, int> all_tools;
  for (const FrameRecord& record : dataset.frames()) {
    if (record.label) all_tools[record.label->tool]++;
  }
  bool first = true;
  for (const auto& [tool, count] : all_tools) {
    std::cout << (first ? "" : ", ") << tool;
    first = false;
  }
  if (all_tools.empty()) std::cout << "(no labels)";
  std::cout << "\n  bytes on disk: " << FormatBytes(bytes) << " (" << bytes << ")"
            << (dataset.has_clean() ? ", including noise-free copies" : "") << "\n";
  if (flags.json) {
    EmitJson({{"dir", dataset.root()},
              {"sensors", sensors},
              {"tools", all_tools.size()},
              {"bytes", bytes},
              {"has_clean", dataset.has_clean()}});
  }
}

}  // namespace

void RegisterInfo(CLI::App& app, CommandBody* selected) {
  auto flags = std::make_shared<InfoFlags>();
  CLI::App* sub = app.add_subcommand(
      "info", "Summarise a dataset: counts, resolutions, tools, bytes on disk.");
  sub->add_option("dir", flags->dir, "Dataset folder (ours or your own, see "
                                     "docs/DATASET_FORMAT.md)");
  AddDatasetFlags(sub, &flags->data);
  sub->add_flag("--tools", flags->tools, "List the simulator's tools and symmetries");
  sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
  sub->callback([flags, selected]() { *selected = [flags]() { RunInfo(*flags); }; });
}

}  // namespace tactfunc::apps
