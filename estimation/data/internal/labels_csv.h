// Copyright 2026 The tactfunc Authors.
//
// labels.csv reading and writing (private to estimation/data/dataset.cc). The format is in
// docs/DATASET_FORMAT.md: a fixed header, then one row per frame:
//   frame,sensor,tool,x_m,y_m,yaw_rad,depth_m,split
// A row whose five pose fields (tool .. depth_m) are all empty carries only a split.
// No quoting: no field may contain ',', '"' or a line break.
#ifndef TACTFUNC_ESTIMATION_DATA_INTERNAL_LABELS_CSV_H_
#define TACTFUNC_ESTIMATION_DATA_INTERNAL_LABELS_CSV_H_

#include <optional>
#include <string>
#include <vector>

#include "estimation/data/dataset.h"

namespace tactfunc::internal {

inline constexpr const char* kLabelsHeader = "frame,sensor,tool,x_m,y_m,yaw_rad,depth_m,split";

struct LabelRow {
  int line = 0;  // 1-based line number in the file (the header is line 1)
  std::string frame;
  SensorKind sensor = SensorKind::kSoftBubble;
  std::optional<PoseLabel> label;
  Split split = Split::kTrain;
};

// Parses the text of a labels.csv. Checks the syntax of every line and the ranges
// that do not depend on the sensor (finite numbers, yaw, depth, split, sensor name,
// duplicate (frame, sensor)); position ranges are checked by the caller, which knows
// the sensor's size. Throws DatasetError "<path>:<line>: ..." naming the field.
// Skips blank lines, a UTF-8 byte order mark and '\r' line ends.
std::vector<LabelRow> ParseLabelsCsv(const std::string& text, const std::string& path);

// clips.csv of a clip set (docs/DATASET_FORMAT.md): the header, then one row per clip
// giving the split of all its frames.
inline constexpr const char* kClipsHeader = "clip,split";
struct ClipSplitRow {
  int line = 0;  // 1-based line number in the file
  std::string clip;
  Split split = Split::kTrain;
};
// Parses the text of a clips.csv. Checks the syntax of every line, the split and
// duplicate clips; whether a clip exists is checked by the caller. Throws DatasetError
// "<path>:<line>: ..." naming the field. Skips blank lines, a UTF-8 byte order mark
// and '\r' line ends, as ParseLabelsCsv does.
std::vector<ClipSplitRow> ParseClipsCsv(const std::string& text, const std::string& path);

// tools.csv of a dataset (docs/DATASET_FORMAT.md): the header, then one row per tool of
// the user's own giving its rotational symmetry order.
inline constexpr const char* kToolsHeader = "tool,symmetry_order";
struct ToolSymmetryRow {
  int line = 0;  // 1-based line number in the file
  std::string tool;
  int symmetry_order = 1;
};
// Parses the text of a tools.csv. Checks the syntax of every line, the order (an integer
// in [0, 360]) and duplicate tools; whether a built-in tool keeps its own order is checked
// by the caller. Throws DatasetError "<path>:<line>: ..." naming the field. Skips blank
// lines, a UTF-8 byte order mark and '\r' line ends, as ParseLabelsCsv does.
std::vector<ToolSymmetryRow> ParseToolsCsv(const std::string& text, const std::string& path);

// The text of a labels.csv holding `rows` in the given order.
std::string FormatLabelsCsv(const std::vector<LabelRow>& rows);

// The first field of `label` out of range for a sensor of rows x cols pixels and the
// given pitch (0 = unknown: positions must be within 1 m), or nullopt if it is fine.
// `column` is the labels.csv column index (2 = tool .. 6 = depth_m) and `expected`
// reads "expected ..." for the message.
struct PoseLabelProblem {
  int column = 0;
  std::string expected;
};
std::optional<PoseLabelProblem> FindPoseLabelProblem(const PoseLabel& label, int rows, int cols,
                                                     double pixel_pitch_m);
// Column names of labels.csv, indexed like the header.
const char* LabelsColumnName(int column);
// The text of a pose field of `label` (column 2..6), as written to labels.csv.
std::string PoseFieldText(const PoseLabel& label, int column);

// True if `text` may appear in a labels.csv field (no ',', '"', '\r', '\n').
bool IsCsvSafe(const std::string& text);

}  // namespace tactfunc::internal

#endif  // TACTFUNC_ESTIMATION_DATA_INTERNAL_LABELS_CSV_H_
