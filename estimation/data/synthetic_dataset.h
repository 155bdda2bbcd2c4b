// Copyright 2026 The tactfunc Authors.
//
// Synthetic paired datasets: the contact simulator (models/simulator/contact_simulator.h) written
// out in the dataset folder format (estimation/data/dataset.h, docs/DATASET_FORMAT.md).
//
// Contact i (0-based, tools in the given order, `frames_per_tool` contacts each) is
// rendered from seeds derived from (seed, i) alone, so the dataset is bit-identical
// for a seed whatever the thread count. Within each tool, contact k is in the test
// split when floor((k+1) f) > floor(k f) for the test fraction f, which spreads the
// test contacts evenly (every 10th for f = 0.1); poses are i.i.d., so this is an
// unbiased split.
#ifndef TACTFUNC_ESTIMATION_DATA_SYNTHETIC_DATASET_H_
#define TACTFUNC_ESTIMATION_DATA_SYNTHETIC_DATASET_H_

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "models/simulator/contact_simulator.h"
#include "models/core/sensor.h"

namespace tactfunc {

struct SynthesisPlan {
  std::string out;                   // dataset folder to write
  std::vector<std::string> tools;    // tool names (models/simulator/tool.h)
  std::vector<SensorKind> sensors = {SensorKind::kSoftBubble, SensorKind::kGelSlim};
  int frames_per_tool = 20;          // contacts per tool, >= 1
  std::uint64_t seed = 0;
  double test_fraction = 0.1;        // in [0, 1]
  bool write_clean = false;          // also store noise-free frames (for clean PSNR);
                                     // about 1.6x the time and 1.5x the bytes
  bool overwrite = false;            // replace an existing dataset at `out`
  int threads = 1;                   // >= 1
  int png_compression = 1;           // zlib level 0-9; 1 is ~3x faster than 6 for ~10% more bytes
  bool IsValid(std::string* error) const;
};

struct SynthesisReport {
  std::int64_t contacts = 0;  // paired contacts rendered
  std::int64_t frames = 0;    // frames written (contacts x sensors)
  double seconds = 0;         // wall time
  std::uint64_t bytes = 0;    // dataset bytes on disk
};

// Progress callback: called with the number of contacts just finished (from any
// worker thread; must be thread-safe).
using SynthesisProgress = std::function<void(int)>;

// Renders and writes the dataset. Throws std::invalid_argument for a bad plan and
// std::runtime_error (naming the file) for I/O failures; on failure no dataset.json
// is written, so the folder is never mistaken for a complete dataset.
SynthesisReport Synthesize(const SynthesisPlan& plan,
                           const ContactSimulator::Options& simulator_options,
                           const SynthesisProgress& progress = nullptr);

// The fixed physical normalisation scale stored with synthetic data: the difference
// (metres of indentation for bubble, intensity for gelslim) that maps to 1.0.
double SyntheticNormalizationScale(const ContactSimulator& simulator, SensorKind sensor);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_DATA_SYNTHETIC_DATASET_H_
