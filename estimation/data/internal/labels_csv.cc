// Copyright 2026 The tactfunc Authors.
#include "estimation/data/internal/labels_csv.h"

#include <cmath>
#include <cstdlib>
#include <set>
#include <utility>

#include "estimation/data/internal/path_util.h"
#include "models/core/text_limits.h"

namespace tactfunc::internal {
namespace {

constexpr int kNumColumns = 8;
constexpr const char* kColumnNames[kNumColumns] = {"frame", "sensor",  "tool",    "x_m",
                                                   "y_m",   "yaw_rad", "depth_m", "split"};
// 1e-9 rad of slack so that yaws computed as +-pi (atan2, wrapping) are accepted.
constexpr double kYawSlack = 1e-9;
constexpr double kMaxDepthM = 0.1;
constexpr double kMaxPositionWithoutPitchM = 1.0;
// Relative slack on the half extent, so a position exactly on the edge passes after
// the pitch itself went through decimal text.
constexpr double kExtentSlack = 1e-9;

std::vector<std::string> SplitCommas(const std::string& line) {
  std::vector<std::string> fields;
  std::size_t start = 0;
  while (true) {
    const std::size_t comma = line.find(',', start);
    if (comma == std::string::npos) {
      fields.push_back(line.substr(start));
      return fields;
    }
    fields.push_back(line.substr(start, comma - start));
    start = comma + 1;
  }
}

std::string Where(const std::string& path, int line) {
  return path + ":" + std::to_string(line) + ": ";
}

// The lines of a CSV text after a UTF-8 byte order mark, each without its '\r', with
// their 1-based numbers. The first is the header; blank lines after it are left out.
// Throws DatasetError if the text has no line or the header is not `header`.
std::vector<std::pair<int, std::string>> CsvRows(const std::string& text, const std::string& path,
                                                 const char* header) {
  std::vector<std::pair<int, std::string>> rows;
  std::size_t pos = text.compare(0, 3, "\xEF\xBB\xBF") == 0 ? 3 : 0;
  int line_number = 0;
  bool header_seen = false;
  while (pos < text.size()) {
    std::size_t end = text.find('\n', pos);
    if (end == std::string::npos) end = text.size();
    std::string line = text.substr(pos, end - pos);
    pos = end + 1;
    ++line_number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (!header_seen) {
      if (line != header) {
        throw DatasetError(Where(path, line_number) + "header: expected '" + header + "', got '" +
                           EscapedExcerpt(line) + "'");
      }
      header_seen = true;
      continue;
    }
    if (line.find_first_not_of(" \t") == std::string::npos) continue;
    rows.emplace_back(line_number, std::move(line));
  }
  if (!header_seen) {
    throw DatasetError(Where(path, 1) + "header: expected '" + header + "', got an empty file");
  }
  return rows;
}

std::string RangeText(double lo, double hi) {
  return "[" + FormatDoubleShort(lo) + ", " + FormatDoubleShort(hi) + "]";
}

}  // namespace

const char* LabelsColumnName(int column) {
  return column >= 0 && column < kNumColumns ? kColumnNames[column] : "?";
}

std::string PoseFieldText(const PoseLabel& label, int column) {
  switch (column) {
    case 2:
      return label.tool;
    case 3:
      return FormatDoubleExact(label.sensor_T_object.x());
    case 4:
      return FormatDoubleExact(label.sensor_T_object.y());
    case 5:
      return FormatDoubleExact(label.sensor_T_object.yaw());
    case 6:
      return FormatDoubleExact(label.depth_m);
    default:
      return "";
  }
}

namespace {

// The checks of FindPoseLabelProblem on the raw fields, so that the reader can check a
// yaw before SE2d normalises it.
std::optional<PoseLabelProblem> FindPoseFieldProblem(const std::string& tool, double x_m,
                                                     double y_m, double yaw_rad, double depth_m,
                                                     int rows, int cols, double pixel_pitch_m) {
  if (tool.empty() || !IsCsvSafe(tool)) {
    return PoseLabelProblem{2,
                            "expected a non-empty tool name without ',', '\"' or "
                            "line breaks"};
  }
  const bool pitch_known = pixel_pitch_m > 0 && rows > 0 && cols > 0;
  const double half_x = pitch_known ? 0.5 * cols * pixel_pitch_m : kMaxPositionWithoutPitchM;
  const double half_y = pitch_known ? 0.5 * rows * pixel_pitch_m : kMaxPositionWithoutPitchM;
  const char* why = pitch_known ? " (half the sensor's extent)" : " (pixel pitch unknown)";
  if (!(std::isfinite(x_m) && std::abs(x_m) <= half_x * (1 + kExtentSlack))) {
    return PoseLabelProblem{3, "expected a finite number in " + RangeText(-half_x, half_x) + why};
  }
  if (!(std::isfinite(y_m) && std::abs(y_m) <= half_y * (1 + kExtentSlack))) {
    return PoseLabelProblem{4, "expected a finite number in " + RangeText(-half_y, half_y) + why};
  }
  if (!(std::isfinite(yaw_rad) && std::abs(yaw_rad) <= M_PI + kYawSlack)) {
    return PoseLabelProblem{5, "expected a finite number in " + RangeText(-M_PI, M_PI)};
  }
  if (!(std::isfinite(depth_m) && depth_m >= 0 && depth_m <= kMaxDepthM)) {
    return PoseLabelProblem{6, "expected a finite number in " + RangeText(0, kMaxDepthM)};
  }
  return std::nullopt;
}

}  // namespace

std::optional<PoseLabelProblem> FindPoseLabelProblem(const PoseLabel& label, int rows, int cols,
                                                     double pixel_pitch_m) {
  const SE2d& pose = label.sensor_T_object;
  return FindPoseFieldProblem(label.tool, pose.x(), pose.y(), pose.yaw(), label.depth_m, rows,
                              cols, pixel_pitch_m);
}

bool IsCsvSafe(const std::string& text) {
  return text.find_first_of(",\"\r\n") == std::string::npos;
}

std::vector<LabelRow> ParseLabelsCsv(const std::string& text, const std::string& path) {
  std::vector<LabelRow> rows;
  std::set<std::pair<std::string, SensorKind>> seen;
  for (const auto& [line_number, line] : CsvRows(text, path, kLabelsHeader)) {
    const std::vector<std::string> fields = SplitCommas(line);
    const std::string where = Where(path, line_number);
    if (fields.size() != kNumColumns) {
      throw DatasetError(where + "expected " + std::to_string(kNumColumns) +
                         " comma-separated fields (" + kLabelsHeader + "), got " +
                         std::to_string(fields.size()) + " in '" + EscapedExcerpt(line) + "'");
    }
    auto bad = [&](int column, const std::string& expected) {
      // Quoted as an excerpt with unprintable bytes escaped: a line may be megabytes.
      return DatasetError(where + "field '" + kColumnNames[column] + "': " + expected + ", got '" +
                          EscapedExcerpt(fields[column]) + "'");
    };
    LabelRow row;
    row.line = line_number;
    row.frame = fields[0];
    if (row.frame.empty()) throw bad(0, "expected a frame id (the image file's stem)");
    // Frame ids and tool names end up in functasets and reports as JSON text, which
    // must be UTF-8: checked here, where the file and line can be named.
    if (!IsValidUtf8(row.frame)) throw bad(0, "expected UTF-8 text");
    if (!SensorKindFromString(fields[1], &row.sensor)) {
      throw bad(1, "expected 'bubble' or 'gelslim'");
    }
    if (!SplitFromString(fields[7], &row.split)) throw bad(7, "expected 'train' or 'test'");
    bool all_empty = true;
    for (int c = 2; c <= 6; ++c) all_empty = all_empty && fields[c].empty();
    if (!all_empty) {
      if (!IsValidUtf8(fields[2])) throw bad(2, "expected a tool name in UTF-8");
      if (fields[2].empty()) {
        throw bad(2,
                  "expected a tool name (or all five pose fields empty for an "
                  "unlabelled frame)");
      }
      double values[4] = {0, 0, 0, 0};  // x_m, y_m, yaw_rad, depth_m
      for (int c = 3; c <= 6; ++c) {
        if (!ParseDouble(fields[c], &values[c - 3]) || !std::isfinite(values[c - 3])) {
          throw bad(c, "expected a finite number");
        }
      }
      if (std::optional<PoseLabelProblem> problem = FindPoseFieldProblem(
              fields[2], values[0], values[1], values[2], values[3], 0, 0, 0)) {
        throw bad(problem->column, problem->expected);
      }
      // The one conversion from the file's columns to the in-memory pose. A yaw in the
      // file's 1e-9 slack beyond +-pi (and -pi itself) becomes its (-pi, pi] equivalent.
      PoseLabel label;
      label.tool = fields[2];
      label.sensor_T_object = SE2d::FromXYYaw(values[0], values[1], values[2]);
      label.depth_m = values[3];
      row.label = std::move(label);
    }
    if (!seen.insert({row.frame, row.sensor}).second) {
      throw DatasetError(where + "duplicate label for frame '" + Excerpt(row.frame) + "', sensor '" +
                         ToString(row.sensor) + "': expected one row per (frame, sensor)");
    }
    rows.push_back(std::move(row));
  }
  return rows;
}

std::vector<ClipSplitRow> ParseClipsCsv(const std::string& text, const std::string& path) {
  std::vector<ClipSplitRow> rows;
  std::set<std::string> seen;
  for (const auto& [line_number, line] : CsvRows(text, path, kClipsHeader)) {
    const std::string where = Where(path, line_number);
    const std::vector<std::string> fields = SplitCommas(line);
    if (fields.size() != 2) {
      throw DatasetError(where + "expected 2 comma-separated fields (" + kClipsHeader + "), got " +
                         std::to_string(fields.size()) + " in '" + EscapedExcerpt(line) + "'");
    }
    ClipSplitRow row;
    row.line = line_number;
    row.clip = fields[0];
    if (row.clip.empty() || !IsValidUtf8(row.clip)) {
      throw DatasetError(where + "field 'clip': expected a clip name in UTF-8, got '" +
                         EscapedExcerpt(row.clip) + "'");
    }
    if (!SplitFromString(fields[1], &row.split)) {
      throw DatasetError(where + "field 'split': expected 'train' or 'test', got '" +
                         EscapedExcerpt(fields[1]) + "'");
    }
    if (!seen.insert(row.clip).second) {
      throw DatasetError(where + "field 'clip': expected one row per clip, got a second for '" +
                         EscapedExcerpt(row.clip) + "'");
    }
    rows.push_back(std::move(row));
  }
  return rows;
}

std::vector<ToolSymmetryRow> ParseToolsCsv(const std::string& text, const std::string& path) {
  std::vector<ToolSymmetryRow> rows;
  std::set<std::string> seen;
  for (const auto& [line_number, line] : CsvRows(text, path, kToolsHeader)) {
    const std::string where = Where(path, line_number);
    const std::vector<std::string> fields = SplitCommas(line);
    if (fields.size() != 2) {
      throw DatasetError(where + "expected 2 fields (" + kToolsHeader + "), got " +
                         std::to_string(fields.size()) + " in '" + EscapedExcerpt(line) + "'");
    }
    ToolSymmetryRow row;
    row.line = line_number;
    row.tool = fields[0];
    if (row.tool.empty() || !IsCsvSafe(row.tool)) {
      throw DatasetError(where + "field 'tool': expected a tool name without '\"', got '" +
                         EscapedExcerpt(row.tool) + "'");
    }
    const std::string& order = fields[1];
    char* end = nullptr;
    const long n = std::strtol(order.c_str(), &end, 10);
    if (order.empty() || *end != '\0' || n < 0 || n > 360) {
      throw DatasetError(where + "field 'symmetry_order': expected an integer in [0, 360] (0 = no " +
                         "observable yaw, 1 = asymmetric), got '" + EscapedExcerpt(order) + "'");
    }
    row.symmetry_order = static_cast<int>(n);
    if (!seen.insert(row.tool).second) {
      throw DatasetError(where + "field 'tool': expected each tool once, got '" +
                         EscapedExcerpt(row.tool) + "' again");
    }
    rows.push_back(std::move(row));
  }
  return rows;
}

std::string FormatLabelsCsv(const std::vector<LabelRow>& rows) {
  std::string out = std::string(kLabelsHeader) + "\n";
  for (const LabelRow& row : rows) {
    out += row.frame;
    out += ',';
    out += ToString(row.sensor);
    for (int c = 2; c <= 6; ++c) {
      out += ',';
      if (row.label) out += PoseFieldText(*row.label, c);
    }
    out += ',';
    out += ToString(row.split);
    out += '\n';
  }
  return out;
}

}  // namespace tactfunc::internal
