// Copyright 2026 The tactfunc Authors.
#include "apps/dataset_flags.h"

#include <algorithm>
#include <filesystem>

#include "apps/command.h"

namespace tactfunc::apps {

void AddDatasetFlags(CLI::App* sub, DatasetFlags* flags) {
  sub->add_option("--sensor", flags->sensor,
                  "For your own data: the sensor kind (bubble or gelslim); default: "
                  "inferred from the images (16-bit one-channel = bubble)");
  sub->add_option("--reference", flags->reference,
                  "For your own folder: the no-contact reference image, if it is not "
                  "named reference.png/.jpg");
  sub->add_option("--reference-index", flags->reference_index,
                  "For a video: the frame that is the reference (default 0)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--pixel-pitch-mm", flags->pixel_pitch_mm,
                  "For your own data: millimetres per pixel (enables pose arrows and "
                  "label range checks)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--labels", flags->labels, "A labels.csv to use instead of DIR/labels.csv");
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
  std::string extension = std::filesystem::path(path).extension().string();
  std::transform(extension.begin(), extension.end(), extension.begin(), ::tolower);
  const bool video = std::filesystem::is_regular_file(path) &&
                     (extension == ".avi" || extension == ".mp4" || extension == ".mov" ||
                      extension == ".mkv" || extension == ".m4v");
  return video ? Dataset::OpenVideo(path, options) : Dataset::Open(path, options);
}

}  // namespace tactfunc::apps
