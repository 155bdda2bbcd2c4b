// Copyright 2026 The tactfunc Authors.
#include "apps/dataset_flags.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>

#include "CLI/CLI.hpp"
#include "apps/command.h"

namespace tactfunc::apps {

void AddDatasetFlags(CLI::App* sub, DatasetFlags* flags, const std::vector<std::string>& skip) {
  auto wanted = [&](const char* name) {
    return std::find(skip.begin(), skip.end(), name) == skip.end();
  };
  if (wanted("--sensor")) {
    sub->add_option("--sensor", flags->sensor,
                    "For your own data: the sensor kind (bubble or gelslim); default: "
                    "inferred from the images (16-bit one-channel = bubble)");
  }
  if (wanted("--reference")) {
    sub->add_option("--reference", flags->reference,
                    "For your own folder (or each folder of a set of clips): the no-contact "
                    "reference image, if it is not named reference.png/.jpg");
  }
  if (wanted("--reference-index")) {
    sub->add_option("--reference-index", flags->reference_index,
                    "For a video (or each video of a set of clips): the frame that is the "
                    "reference (default 0)")
        ->check(CLI::NonNegativeNumber);
  }
  if (wanted("--pixel-pitch-mm")) {
    sub->add_option("--pixel-pitch-mm", flags->pixel_pitch_mm,
                    "For your own data: millimetres per pixel (enables pose arrows and "
                    "label range checks)")
        ->check(CLI::NonNegativeNumber);
  }
  if (wanted("--labels")) {
    sub->add_option("--labels", flags->labels, "A labels.csv to use instead of DIR/labels.csv");
  }
  if (wanted("--tool-symmetry")) {
    sub->add_option("--tool-symmetry", flags->tools,
                    "A tools.csv (tool,symmetry_order) declaring your tools' rotational "
                    "symmetry, instead of DIR/tools.csv");
  }
  if (wanted("--sensor-file")) {
    sub->add_option("--sensor-file", flags->sensor_file,
                    "A sensor description (JSON: kind, channels, crop or perspective corners, "
                    "working size, pixel pitch, scale; docs/DATASET_FORMAT.md) to read instead "
                    "of DIR/sensor.json, or to apply to --frame and --reference where the "
                    "command takes them");
  }
}

Dataset OpenDataset(const std::string& path, const DatasetFlags& flags) {
  Dataset::OpenOptions options;
  if (!flags.sensor.empty()) {
    SensorKind kind;
    if (!SensorKindFromString(flags.sensor, &kind)) {
      throw UsageError("--sensor: expected bubble or gelslim, got '" + flags.sensor + "'");
    }
    options.sensor = kind;
  }
  options.reference = flags.reference;
  options.reference_index = flags.reference_index;
  options.pixel_pitch_m = flags.pixel_pitch_mm * 1e-3;
  options.labels = flags.labels;
  options.tools = flags.tools;
  options.sensor_file = flags.sensor_file;
  const bool video = std::filesystem::is_regular_file(path) && IsVideoFileName(path);
  return video ? Dataset::OpenVideo(path, options) : Dataset::Open(path, options);
}

bool WarnIfStretched(const Dataset& dataset, const std::string& path, SensorKind sensor,
                     int rows, int cols, const std::string& command) {
  if (!dataset.has_sensor(sensor) || rows <= 0 || cols <= 0) return false;
  const SensorInfo& info = dataset.sensor_info(sensor);
  if (info.rows <= 0 || info.cols <= 0) return false;
  const double native = static_cast<double>(info.cols) / info.rows;
  const double working = static_cast<double>(cols) / rows;
  if (std::abs(native / working - 1.0) <= 0.02) return false;
  char aspects[96];
  std::snprintf(aspects, sizeof(aspects), "%.2f", native);
  const std::string native_text = aspects;
  std::snprintf(aspects, sizeof(aspects), "%.2f", working);
  std::cerr << command << ": warning: " << path << ": " << ToString(sensor) << " frames are "
            << info.rows << "x" << info.cols << " (rows x cols, aspect " << native_text
            << ") but are resized to " << rows << "x" << cols << " (aspect " << aspects
            << "): stretched, a round contact becomes an ellipse\n";
  return true;
}

}  // namespace tactfunc::apps
