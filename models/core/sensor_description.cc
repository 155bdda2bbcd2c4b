// Copyright 2026 The tactfunc Authors.
#include "models/core/sensor_description.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <fstream>
#include <iterator>
#include <limits>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <set>
#include <sstream>
#include <string>

#include "models/core/text_limits.h"

namespace tactfunc {
namespace {

using nlohmann::json;

constexpr const char* kFormatName = "tactfunc-sensor";
constexpr int kFormatVersion = 1;
// Descriptions are a few hundred bytes; anything far larger is not one.
constexpr std::size_t kMaxFileBytes = 1 << 16;
constexpr int kMaxPixels = 100000;  // per side, raw or working
constexpr std::size_t kMaxNameLength = 64;

// A warped pixel is valid where at least half its interpolation weight was valid; the
// slack absorbs float rounding of weights that are exactly one half.
constexpr float kMinValidFraction = 0.5f - 1e-6f;

constexpr float kLumaR = 0.299f;
constexpr float kLumaG = 0.587f;
constexpr float kLumaB = 0.114f;

std::string Number(double value) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.10g", value);
  return buffer;
}

std::string Number12(double value) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.12g", value);
  return buffer;
}

bool IsValidName(const std::string& name) {
  if (name.empty() || name.size() > kMaxNameLength) return false;
  return std::all_of(name.begin(), name.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') ||
           c == '_' || c == '-' || c == '.';
  });
}

// Typed fields of one JSON object with messages naming the file and the dotted field.
class Fields {
 public:
  explicit Fields(std::string source) : source_(std::move(source)) {}

  SensorDescriptionError Bad(const std::string& field, const std::string& expected,
                             const json& found) const {
    const std::string text =
        found.is_string() ? "\"" + found.get<std::string>() + "\"" : found.dump();
    return SensorDescriptionError(source_ + ": field '" + field + "': expected " + expected +
                                  ", got " + EscapedExcerpt(text));
  }
  SensorDescriptionError Missing(const std::string& field, const std::string& expected) const {
    return SensorDescriptionError(source_ + ": field '" + field + "': expected " + expected +
                                  ", got no such field");
  }
  // Refuses keys of `object` not in `known`.
  void OnlyKnown(const json& object, const std::set<std::string>& known,
                 const std::string& prefix) const {
    for (const auto& item : object.items()) {
      if (known.count(item.key()) != 0) continue;
      std::string list;
      for (const std::string& k : known) list += (list.empty() ? "" : ", ") + k;
      throw SensorDescriptionError(source_ + ": field '" + prefix + EscapedExcerpt(item.key(), 40) +
                                   "': expected one of the fields " + list +
                                   ", got an unknown field");
    }
  }
  int Int(const json& object, const std::string& key, const std::string& field, int lo,
          int hi) const {
    const auto it = object.find(key);
    const std::string expected =
        "an integer in [" + std::to_string(lo) + ", " + std::to_string(hi) + "]";
    if (it == object.end()) throw Missing(field, expected);
    if (!it->is_number_integer() || it->get<std::int64_t>() < lo || it->get<std::int64_t>() > hi) {
      throw Bad(field, expected, *it);
    }
    return it->get<int>();
  }
  double Positive(const json& object, const std::string& key, const std::string& field,
                  const std::string& expected) const {
    const auto it = object.find(key);
    if (it == object.end()) throw Missing(field, expected);
    if (!it->is_number() || !std::isfinite(it->get<double>()) || !(it->get<double>() > 0)) {
      throw Bad(field, expected, *it);
    }
    return it->get<double>();
  }
  const std::string& source() const { return source_; }

 private:
  std::string source_;
};

// Step 1's output size (before the aspect crop).
void GeometrySize(const SensorDescription& d, int raw_rows, int raw_cols, int* rows, int* cols) {
  switch (d.geometry) {
    case SensorDescription::Geometry::kNone:
      *rows = raw_rows;
      *cols = raw_cols;
      return;
    case SensorDescription::Geometry::kCrop:
      *rows = d.crop_height;
      *cols = d.crop_width;
      return;
    case SensorDescription::Geometry::kPerspective:
      *rows = d.warp_rows;
      *cols = d.warp_cols;
      return;
  }
}

// The centred window of the working aspect ratio for a rows x cols frame (step 2):
// top-left (*r0, *c0) and size (*out_rows, *out_cols), inside the frame for aspect
// "crop", around it for "pad" (a negative corner). The whole frame without a working
// size or with aspect "stretch".
void AspectWindow(const SensorDescription& d, int rows, int cols, int* r0, int* c0,
                  int* out_rows, int* out_cols) {
  *r0 = 0;
  *c0 = 0;
  *out_rows = rows;
  *out_cols = cols;
  if (d.working_rows <= 0 || d.aspect == SensorDescription::Aspect::kStretch) return;
  // Integer products, so an aspect that already matches crops or pads nothing.
  const std::int64_t wide = static_cast<std::int64_t>(cols) * d.working_rows;
  const std::int64_t tall = static_cast<std::int64_t>(rows) * d.working_cols;
  if (d.aspect == SensorDescription::Aspect::kPad) {
    if (wide > tall) {  // too wide: add rows
      const long keep = std::lround(static_cast<double>(cols) * d.working_rows / d.working_cols);
      *out_rows = static_cast<int>(std::clamp<long>(keep, rows, 4 * 4096L));
      *r0 = -((*out_rows - rows) / 2);
    } else if (tall > wide) {  // too tall: add columns
      const long keep = std::lround(static_cast<double>(rows) * d.working_cols / d.working_rows);
      *out_cols = static_cast<int>(std::clamp<long>(keep, cols, 4 * 4096L));
      *c0 = -((*out_cols - cols) / 2);
    }
    return;
  }
  if (wide > tall) {  // too wide: keep every row
    const int keep = static_cast<int>(std::lround(static_cast<double>(rows) * d.working_cols /
                                                  d.working_rows));
    *out_cols = std::clamp(keep, 1, cols);
    *c0 = (cols - *out_cols) / 2;
  } else if (tall > wide) {  // too tall: keep every column
    const int keep = static_cast<int>(std::lround(static_cast<double>(cols) * d.working_rows /
                                                  d.working_cols));
    *out_rows = std::clamp(keep, 1, rows);
    *r0 = (rows - *out_rows) / 2;
  }
}

void CheckGeometryFits(const SensorDescription& d, int raw_rows, int raw_cols,
                       const std::string& source) {
  const std::string size =
      std::to_string(raw_rows) + "x" + std::to_string(raw_cols) + " (rows x cols)";
  if (d.geometry == SensorDescription::Geometry::kCrop) {
    if (d.crop_x + d.crop_width > raw_cols || d.crop_y + d.crop_height > raw_rows) {
      throw SensorDescriptionError(
          source + ": field 'crop': expected a rectangle inside the " + size +
          " frames, got x " + std::to_string(d.crop_x) + " + width " +
          std::to_string(d.crop_width) + ", y " + std::to_string(d.crop_y) + " + height " +
          std::to_string(d.crop_height));
    }
  } else if (d.geometry == SensorDescription::Geometry::kPerspective) {
    for (int k = 0; k < 4; ++k) {
      const double x = d.corners[k][0], y = d.corners[k][1];
      if (x < 0 || y < 0 || x > raw_cols || y > raw_rows) {
        throw SensorDescriptionError(
            source + ": field 'perspective.corners[" + std::to_string(k) +
            "]': expected a point inside the " + size + " frames (x in [0, " +
            std::to_string(raw_cols) + "], y in [0, " + std::to_string(raw_rows) + "]), got [" +
            Number(x) + ", " + Number(y) + "]");
      }
    }
  }
}

// Bilinear perspective warp of `src` (CV_32FC(n)) onto rows x cols.
cv::Mat Warp(const cv::Mat& src, const cv::Mat& transform, int rows, int cols) {
  cv::Mat out;
  cv::warpPerspective(src, out, transform, cv::Size(cols, rows), cv::INTER_LINEAR,
                      cv::BORDER_REPLICATE);
  return out;
}

// The raw-to-rectangle transform in OpenCV's pixel-centre coordinates (edge coordinate
// = centre coordinate + 0.5 on both sides, so the half pixel cancels only where it must).
cv::Mat PerspectiveTransform(const SensorDescription& d) {
  std::vector<cv::Point2f> from(4), to(4);
  for (int k = 0; k < 4; ++k) {
    from[k] = cv::Point2f(static_cast<float>(d.corners[k][0] - 0.5),
                          static_cast<float>(d.corners[k][1] - 0.5));
  }
  const float w = static_cast<float>(d.warp_cols), h = static_cast<float>(d.warp_rows);
  to[0] = {-0.5f, -0.5f};
  to[1] = {w - 0.5f, -0.5f};
  to[2] = {w - 0.5f, h - 0.5f};
  to[3] = {-0.5f, h - 0.5f};
  return cv::getPerspectiveTransform(from, to);
}

bool ConvexQuadrilateral(const std::array<std::array<double, 2>, 4>& p) {
  // Every turn along top-left, top-right, bottom-right, bottom-left has the same sign
  // (clockwise as seen in image coordinates, y down): positive cross products.
  for (int k = 0; k < 4; ++k) {
    const auto& a = p[k];
    const auto& b = p[(k + 1) % 4];
    const auto& c = p[(k + 2) % 4];
    const double cross = (b[0] - a[0]) * (c[1] - b[1]) - (b[1] - a[1]) * (c[0] - b[0]);
    if (!(cross > 0)) return false;
  }
  return true;
}

}  // namespace

SensorDescription BuiltInSensorDescription(SensorKind kind) {
  SensorDescription d;
  d.kind = kind;
  if (kind == SensorKind::kSoftBubble) {
    d.name = "soft_bubble";
    d.channels = 1;
    d.normalization_scale = 0.01;
    d.markers = false;
  } else {
    d.name = "gelslim";
    d.channels = 3;
    d.normalization_scale = 0.5;
    d.markers = true;
  }
  return d;
}

const char* SensorKindDescriptionName(SensorKind kind) {
  return kind == SensorKind::kSoftBubble ? "depth" : "optical";
}

const char* AspectName(SensorDescription::Aspect aspect) {
  switch (aspect) {
    case SensorDescription::Aspect::kCrop:
      return "crop";
    case SensorDescription::Aspect::kPad:
      return "pad";
    case SensorDescription::Aspect::kStretch:
      return "stretch";
  }
  return "unknown";
}

SensorDescription ParseSensorDescription(const std::string& text, const std::string& source,
                                         bool allow_unknown_pitch) {
  if (JsonNestingDepth(text) > kMaxJsonDepth) {
    throw SensorDescriptionError(source + ": expected JSON nested at most " +
                                 std::to_string(kMaxJsonDepth) + " levels deep, got deeper");
  }
  json doc;
  try {
    doc = json::parse(text);
  } catch (const json::exception& e) {
    throw SensorDescriptionError(source + ": expected valid JSON, got a parse error: " +
                                 Excerpt(e.what()));
  }
  const Fields f(source);
  if (!doc.is_object()) throw f.Bad("(top level)", "a JSON object", doc);
  f.OnlyKnown(doc,
              {"format", "version", "name", "kind", "channels", "crop", "perspective",
               "working_size", "aspect", "pixel_pitch_mm", "normalization_scale", "markers"},
              "");
  if (doc.contains("format") &&
      !(doc["format"].is_string() && doc["format"].get<std::string>() == kFormatName)) {
    throw f.Bad("format", std::string("\"") + kFormatName + "\"", doc["format"]);
  }
  if (doc.contains("version") &&
      !(doc["version"].is_number_integer() && doc["version"].get<std::int64_t>() == kFormatVersion)) {
    throw f.Bad("version", std::to_string(kFormatVersion) + " (the only version this build reads)",
                doc["version"]);
  }
  SensorDescription d;
  // name
  const char* name_expected = "a name of 1-64 characters from [A-Za-z0-9_.-]";
  if (!doc.contains("name")) throw f.Missing("name", name_expected);
  if (!doc["name"].is_string() || !IsValidName(doc["name"].get<std::string>())) {
    throw f.Bad("name", name_expected, doc["name"]);
  }
  d.name = doc["name"].get<std::string>();
  // kind
  const char* kind_expected = "\"depth\" (Soft Bubble-like) or \"optical\" (GelSight-like)";
  if (!doc.contains("kind")) throw f.Missing("kind", kind_expected);
  const json& kind = doc["kind"];
  if (kind.is_string() && kind.get<std::string>() == "depth") {
    d.kind = SensorKind::kSoftBubble;
  } else if (kind.is_string() && kind.get<std::string>() == "optical") {
    d.kind = SensorKind::kGelSlim;
  } else {
    throw f.Bad("kind", kind_expected, kind);
  }
  // channels
  const bool depth = d.kind == SensorKind::kSoftBubble;
  d.channels = depth ? 1 : 3;
  if (doc.contains("channels")) {
    const json& c = doc["channels"];
    const bool ok = c.is_number_integer() &&
                    (c.get<std::int64_t>() == 1 || (!depth && c.get<std::int64_t>() == 3));
    if (!ok) {
      throw f.Bad("channels",
                  depth ? "1 (a depth sensor has one channel)"
                        : "3 (RGB) or 1 (luma) for an optical sensor",
                  c);
    }
    d.channels = c.get<int>();
  }
  // crop / perspective
  if (doc.contains("crop") && doc.contains("perspective")) {
    throw SensorDescriptionError(source +
                                 ": field 'perspective': expected either 'crop' or "
                                 "'perspective', got both");
  }
  if (doc.contains("crop")) {
    const json& c = doc["crop"];
    if (!c.is_object()) {
      throw f.Bad("crop", "an object {\"x\", \"y\", \"width\", \"height\"} in raw pixels", c);
    }
    f.OnlyKnown(c, {"x", "y", "width", "height"}, "crop.");
    d.geometry = SensorDescription::Geometry::kCrop;
    d.crop_x = f.Int(c, "x", "crop.x", 0, kMaxPixels);
    d.crop_y = f.Int(c, "y", "crop.y", 0, kMaxPixels);
    d.crop_width = f.Int(c, "width", "crop.width", 1, kMaxPixels);
    d.crop_height = f.Int(c, "height", "crop.height", 1, kMaxPixels);
  }
  if (doc.contains("perspective")) {
    const json& p = doc["perspective"];
    if (!p.is_object()) {
      throw f.Bad("perspective", "an object {\"corners\", \"rows\", \"cols\"}", p);
    }
    f.OnlyKnown(p, {"corners", "rows", "cols"}, "perspective.");
    d.geometry = SensorDescription::Geometry::kPerspective;
    const char* corners_expected =
        "four [x, y] points (top-left, top-right, bottom-right, bottom-left) in raw pixel "
        "coordinates";
    if (!p.contains("corners")) throw f.Missing("perspective.corners", corners_expected);
    const json& corners = p["corners"];
    if (!corners.is_array() || corners.size() != 4) {
      throw f.Bad("perspective.corners", corners_expected, corners);
    }
    for (int k = 0; k < 4; ++k) {
      const json& point = corners[k];
      const std::string field = "perspective.corners[" + std::to_string(k) + "]";
      if (!point.is_array() || point.size() != 2 || !point[0].is_number() ||
          !point[1].is_number() || !std::isfinite(point[0].get<double>()) ||
          !std::isfinite(point[1].get<double>()) || point[0].get<double>() < 0 ||
          point[1].get<double>() < 0 || point[0].get<double>() > kMaxPixels ||
          point[1].get<double>() > kMaxPixels) {
        throw f.Bad(field, "[x, y] with finite x, y in [0, " + std::to_string(kMaxPixels) + "]",
                    point);
      }
      d.corners[k] = {point[0].get<double>(), point[1].get<double>()};
    }
    if (!ConvexQuadrilateral(d.corners)) {
      throw f.Bad("perspective.corners",
                  "a convex quadrilateral listed top-left, top-right, bottom-right, "
                  "bottom-left (clockwise on the image)",
                  corners);
    }
    d.warp_rows = f.Int(p, "rows", "perspective.rows", 1, kMaxPixels);
    d.warp_cols = f.Int(p, "cols", "perspective.cols", 1, kMaxPixels);
  }
  // working_size and aspect
  if (doc.contains("working_size")) {
    const json& w = doc["working_size"];
    if (!w.is_object()) throw f.Bad("working_size", "an object {\"rows\", \"cols\"}", w);
    f.OnlyKnown(w, {"rows", "cols"}, "working_size.");
    d.working_rows = f.Int(w, "rows", "working_size.rows", 1, 4096);
    d.working_cols = f.Int(w, "cols", "working_size.cols", 1, 4096);
  }
  if (doc.contains("aspect")) {
    const json& a = doc["aspect"];
    const char* expected = "\"crop\", \"pad\" or \"stretch\"";
    if (a.is_string() && a.get<std::string>() == "crop") {
      d.aspect = SensorDescription::Aspect::kCrop;
    } else if (a.is_string() && a.get<std::string>() == "pad") {
      d.aspect = SensorDescription::Aspect::kPad;
    } else if (a.is_string() && a.get<std::string>() == "stretch") {
      d.aspect = SensorDescription::Aspect::kStretch;
    } else {
      throw f.Bad("aspect", expected, a);
    }
    if (d.working_rows == 0) {
      throw SensorDescriptionError(source +
                                   ": field 'aspect': expected it only with 'working_size' (it "
                                   "says how frames meet the working size's aspect ratio), got "
                                   "no working_size");
    }
  }
  // pitch, scale, markers
  const char* pitch_expected =
      "millimetres per pixel of the cropped / warped frame, a finite number > 0";
  if (allow_unknown_pitch && doc.contains("pixel_pitch_mm") && doc["pixel_pitch_mm"].is_number() &&
      doc["pixel_pitch_mm"].get<double>() == 0) {
    d.pixel_pitch_m = 0;
  } else {
    d.pixel_pitch_m = f.Positive(doc, "pixel_pitch_mm", "pixel_pitch_mm", pitch_expected) * 1e-3;
  }
  if (d.pixel_pitch_m > 0.1) {
    throw f.Bad("pixel_pitch_mm", "at most 100 mm per pixel", doc["pixel_pitch_mm"]);
  }
  d.normalization_scale = f.Positive(
      doc, "normalization_scale", "normalization_scale",
      depth ? "metres of depth mapping to 1.0, a finite number > 0 (e.g. 0.01)"
            : "intensity (0-1) mapping to 1.0, a finite number > 0 (e.g. 0.5)");
  if (doc.contains("markers")) {
    if (!doc["markers"].is_boolean()) throw f.Bad("markers", "true or false", doc["markers"]);
    d.markers = doc["markers"].get<bool>();
  }
  return d;
}

SensorDescription ReadSensorDescriptionFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw SensorDescriptionError(path + ": expected a sensor description file, got none");
  std::string text;
  text.resize(kMaxFileBytes + 1);
  in.read(&text[0], static_cast<std::streamsize>(text.size()));
  text.resize(static_cast<std::size_t>(in.gcount()));
  if (text.size() > kMaxFileBytes) {
    throw SensorDescriptionError(path + ": expected a sensor description of at most " +
                                 std::to_string(kMaxFileBytes) + " bytes, got a larger file");
  }
  return ParseSensorDescription(text, path);
}

std::string SensorDescriptionToJson(const SensorDescription& d) {
  json doc = json::object();
  doc["format"] = kFormatName;
  doc["version"] = kFormatVersion;
  doc["name"] = d.name;
  doc["kind"] = SensorKindDescriptionName(d.kind);
  doc["channels"] = d.channels;
  if (d.geometry == SensorDescription::Geometry::kCrop) {
    doc["crop"] = {{"x", d.crop_x}, {"y", d.crop_y}, {"width", d.crop_width},
                   {"height", d.crop_height}};
  } else if (d.geometry == SensorDescription::Geometry::kPerspective) {
    json corners = json::array();
    for (const auto& c : d.corners) corners.push_back({c[0], c[1]});
    doc["perspective"] = {{"corners", corners}, {"rows", d.warp_rows}, {"cols", d.warp_cols}};
  }
  if (d.working_rows > 0) {
    doc["working_size"] = {{"rows", d.working_rows}, {"cols", d.working_cols}};
    doc["aspect"] = AspectName(d.aspect);
  }
  // A built-in's unknown pitch is written as 0, which only allow_unknown_pitch reads back.
  // 12 significant digits: the millimetres as written, not the float noise of mm -> m ->
  // mm, so a description re-written from its own file is byte-identical.
  doc["pixel_pitch_mm"] = std::stod(Number12(d.pixel_pitch_m * 1e3));
  doc["normalization_scale"] = d.normalization_scale;
  doc["markers"] = d.markers;
  return doc.dump();
}

bool SameFrames(const SensorDescription& a, const SensorDescription& b) {
  return FrameDifferences(a, b).empty();
}

std::vector<std::string> FrameDifferences(const SensorDescription& a, const SensorDescription& b) {
  std::vector<std::string> out;
  if (a.kind != b.kind) {
    out.push_back(std::string("kind: ") + SensorKindDescriptionName(a.kind) + " vs " +
                  SensorKindDescriptionName(b.kind));
  }
  if (a.channels != b.channels) {
    out.push_back("channels: " + std::to_string(a.channels) + " vs " + std::to_string(b.channels));
  }
  const std::string ga = DescribeGeometry(a), gb = DescribeGeometry(b);
  if (ga != gb) out.push_back("geometry: " + ga + " vs " + gb);
  auto working = [](const SensorDescription& d) {
    if (d.working_rows <= 0) return std::string("unset");
    return std::to_string(d.working_rows) + "x" + std::to_string(d.working_cols) + " (aspect " +
           AspectName(d.aspect) + ")";
  };
  if (working(a) != working(b)) out.push_back("working_size: " + working(a) + " vs " + working(b));
  auto close = [](double x, double y) { return std::abs(x - y) <= 1e-9 * std::max(std::abs(x), std::abs(y)); };
  if (!close(a.pixel_pitch_m, b.pixel_pitch_m)) {
    out.push_back("pixel_pitch_mm: " + Number(a.pixel_pitch_m * 1e3) + " vs " +
                  Number(b.pixel_pitch_m * 1e3));
  }
  if (!close(a.normalization_scale, b.normalization_scale)) {
    out.push_back("normalization_scale: " + Number(a.normalization_scale) + " vs " +
                  Number(b.normalization_scale));
  }
  return out;
}

std::string DescribeGeometry(const SensorDescription& d) {
  switch (d.geometry) {
    case SensorDescription::Geometry::kNone:
      return "none";
    case SensorDescription::Geometry::kCrop:
      return "crop x " + std::to_string(d.crop_x) + " y " + std::to_string(d.crop_y) + " -> " +
             std::to_string(d.crop_height) + "x" + std::to_string(d.crop_width);
    case SensorDescription::Geometry::kPerspective: {
      std::string text = "perspective [";
      for (int k = 0; k < 4; ++k) {
        text += (k ? ", [" : "[") + Number(d.corners[k][0]) + ", " + Number(d.corners[k][1]) + "]";
      }
      return text + "] -> " + std::to_string(d.warp_rows) + "x" + std::to_string(d.warp_cols);
    }
  }
  return "unknown";
}

std::string DescribeSensor(const SensorDescription& d) {
  std::string text = d.name + ": " + SensorKindDescriptionName(d.kind) + ", " +
                     std::to_string(d.channels) + (d.channels == 1 ? " channel" : " channels") +
                     ", geometry " + DescribeGeometry(d) + ", working size ";
  text += d.working_rows > 0
              ? std::to_string(d.working_rows) + "x" + std::to_string(d.working_cols) +
                    " (aspect " + AspectName(d.aspect) + ")"
              : std::string("unset");
  text += ", pitch " + (d.pixel_pitch_m > 0 ? Number(d.pixel_pitch_m * 1e3) + " mm"
                                            : std::string("unknown"));
  text += ", scale " + Number(d.normalization_scale) + (d.markers ? ", markers" : ", no markers");
  return text;
}

void GeometryOutputSize(const SensorDescription& d, int raw_rows, int raw_cols,
                        const std::string& source, int* rows, int* cols) {
  CheckGeometryFits(d, raw_rows, raw_cols, source);
  int r = 0, c = 0;
  GeometrySize(d, raw_rows, raw_cols, &r, &c);
  int r0 = 0, c0 = 0;
  AspectWindow(d, r, c, &r0, &c0, rows, cols);
}

Image ApplySensorGeometry(const Image& raw, const SensorDescription& d, const std::string& source) {
  const bool luma = d.channels == 1 && raw.channels == 3;
  if (raw.channels != d.channels && !luma) {
    throw SensorDescriptionError(source + ": field 'channels': expected frames that give " +
                                 std::to_string(d.channels) + " channel(s), got frames of " +
                                 std::to_string(raw.channels));
  }
  CheckGeometryFits(d, raw.rows, raw.cols, source);
  int rows = 0, cols = 0;
  GeometrySize(d, raw.rows, raw.cols, &rows, &cols);
  int r0 = 0, c0 = 0, out_rows = 0, out_cols = 0;
  AspectWindow(d, rows, cols, &r0, &c0, &out_rows, &out_cols);
  if (d.geometry == SensorDescription::Geometry::kNone && out_rows == rows && out_cols == cols &&
      !luma) {
    return raw;  // the built-ins: exactly what was read
  }
  const cv::Mat source_mat(raw.rows, raw.cols, CV_32FC(raw.channels),
                           const_cast<float*>(raw.data.data()));
  cv::Mat shaped;  // step 1
  if (d.geometry == SensorDescription::Geometry::kNone) {
    shaped = source_mat;
  } else if (d.geometry == SensorDescription::Geometry::kCrop) {
    shaped = source_mat(cv::Rect(d.crop_x, d.crop_y, d.crop_width, d.crop_height));
  } else {
    const cv::Mat transform = PerspectiveTransform(d);
    if (d.kind == SensorKind::kSoftBubble) {
      // Mask-aware: NaN (a camera dropout) must neither spread nor become a zero depth.
      cv::Mat valid(raw.rows, raw.cols, CV_32F), weighted(raw.rows, raw.cols, CV_32FC(raw.channels));
      for (int r = 0; r < raw.rows; ++r) {
        for (int c = 0; c < raw.cols; ++c) {
          bool ok = true;
          for (int k = 0; k < raw.channels; ++k) ok = ok && std::isfinite(raw.at(r, c, k));
          valid.at<float>(r, c) = ok ? 1.0f : 0.0f;
          for (int k = 0; k < raw.channels; ++k) {
            weighted.ptr<float>(r)[c * raw.channels + k] = ok ? raw.at(r, c, k) : 0.0f;
          }
        }
      }
      const cv::Mat warped_valid = Warp(valid, transform, rows, cols);
      cv::Mat warped = Warp(weighted, transform, rows, cols);
      for (int r = 0; r < rows; ++r) {
        const float* w = warped_valid.ptr<float>(r);
        float* v = warped.ptr<float>(r);
        for (int c = 0; c < cols; ++c) {
          for (int k = 0; k < raw.channels; ++k) {
            float& value = v[c * raw.channels + k];
            value = w[c] >= kMinValidFraction ? value / w[c]
                                              : std::numeric_limits<float>::quiet_NaN();
          }
        }
      }
      shaped = warped;
    } else {
      shaped = Warp(source_mat, transform, rows, cols);
    }
  }
  cv::Mat window;  // step 2
  if (r0 >= 0 && c0 >= 0) {
    window = shaped(cv::Rect(c0, r0, out_cols, out_rows));
  } else {
    const float border = d.kind == SensorKind::kSoftBubble
                             ? std::numeric_limits<float>::quiet_NaN()
                             : 0.0f;
    cv::copyMakeBorder(shaped, window, -r0, out_rows - shaped.rows + r0, -c0,
                       out_cols - shaped.cols + c0, cv::BORDER_CONSTANT,
                       cv::Scalar::all(border));
  }
  Image out(out_rows, out_cols, d.channels);
  for (int r = 0; r < out_rows; ++r) {
    const float* row = window.ptr<float>(r);
    for (int c = 0; c < out_cols; ++c) {
      if (luma) {  // step 3
        const float* rgb = row + c * 3;
        out.at(r, c) = kLumaR * rgb[0] + kLumaG * rgb[1] + kLumaB * rgb[2];
      } else {
        for (int k = 0; k < d.channels; ++k) out.at(r, c, k) = row[c * d.channels + k];
      }
    }
  }
  return out;
}

}  // namespace tactfunc
