// Copyright 2026 The tactfunc Authors.
//
// The flags every data-reading subcommand shares, for data without metadata: a user's
// own folder of PNG/JPG frames, a video file, or a folder of such recordings ("clips")
// (docs/DATASET_FORMAT.md).
#ifndef TACTFUNC_APPS_DATASET_FLAGS_H_
#define TACTFUNC_APPS_DATASET_FLAGS_H_

#include <string>
#include <vector>

#include "apps/command.h"  // CLI::App, declared
#include "estimation/data/dataset.h"

namespace tactfunc::apps {

struct DatasetFlags {
  std::string sensor;         // "", "bubble" or "gelslim"
  std::string reference;      // reference image of a folder without reference.<ext>
  int reference_index = 0;    // video: the frame that is the reference
  double pixel_pitch_mm = 0;  // pixel pitch for data without metadata, millimetres
  std::string labels;         // labels.csv to read instead of DIR/labels.csv
  std::string tools;          // tools.csv to read instead of DIR/tools.csv
  std::string sensor_file;    // sensor description to read instead of DIR/sensor.json
};

// Adds --sensor, --reference, --reference-index, --pixel-pitch-mm, --labels, --tool-symmetry,
// --sensor-file to `sub`, but for the names in `skip`: flags the command already has with
// its own meaning (e.g. pose's --reference for --frame); the command then fills those
// fields of `flags` itself if they apply.
void AddDatasetFlags(CLI::App* sub, DatasetFlags* flags,
                     const std::vector<std::string>& skip = {});

// Opens `path`: a dataset folder (ours or a user's, a set of clips included), or a video
// file (a regular file with a video extension, IsVideoFileName), with the flags' options.
Dataset OpenDataset(const std::string& path, const DatasetFlags& flags);

// When `sensor`'s frames of `dataset` (read from `path`) have another aspect ratio than
// the working resolution rows x cols they are resized to (more than 2 % apart), writes
// one warning line to stderr naming the path and both sizes, e.g.
//   "encode: warning: DIR: gelslim frames are 320x320 (aspect 1.00) but are resized to
//    80x107 (aspect 1.34): stretched, a round contact becomes an ellipse"
// and returns true; else writes nothing and returns false. `command` starts the line.
bool WarnIfStretched(const Dataset& dataset, const std::string& path, SensorKind sensor,
                     int rows, int cols, const std::string& command);

}  // namespace tactfunc::apps

#endif  // TACTFUNC_APPS_DATASET_FLAGS_H_
