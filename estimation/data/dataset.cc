// Copyright 2026 The tactfunc Authors.
#include "estimation/data/dataset.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <mutex>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <opencv2/videoio.hpp>
#include <set>
#include <stdexcept>
#include <system_error>
#include <utility>

#include "estimation/data/internal/path_util.h"
#include "estimation/data/internal/labels_csv.h"
#include "estimation/data/internal/opencv_image.h"
#include "models/core/text_limits.h"

namespace tactfunc {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr const char* kMetadataFile = "dataset.json";
constexpr const char* kLabelsFile = "labels.csv";
constexpr const char* kFormatName = "tactfunc-dataset";
constexpr int kFormatVersion = 1;
constexpr const char* kCleanFolder = "clean";
constexpr std::size_t kMaxIdLength = 64;

// Reads typed fields of dataset.json with messages naming the dotted field path.
class JsonFields {
 public:
  explicit JsonFields(std::string path) : path_(std::move(path)) {}

  const json& Get(const json& object, const std::string& key, const std::string& field) const {
    const auto it = object.find(key);
    if (it == object.end()) {
      throw DatasetError(path_ + ": field '" + field +
                         "': expected it to be present, "
                         "got no such field");
    }
    return *it;
  }
  std::string String(const json& object, const std::string& key, const std::string& field) const {
    const json& value = Get(object, key, field);
    if (!value.is_string()) throw Bad(field, "a string", value);
    return value.get<std::string>();
  }
  int Int(const json& object, const std::string& key, const std::string& field,
          int min_value) const {
    const json& value = Get(object, key, field);
    if (!value.is_number_integer() || value.get<std::int64_t>() < min_value ||
        value.get<std::int64_t>() > 1000000) {
      throw Bad(field, "an integer in [" + std::to_string(min_value) + ", 1000000]", value);
    }
    return value.get<int>();
  }
  double NonNegative(const json& object, const std::string& key, const std::string& field) const {
    const json& value = Get(object, key, field);
    if (!value.is_number() || !std::isfinite(value.get<double>()) || value.get<double>() < 0) {
      throw Bad(field, "a finite number >= 0", value);
    }
    return value.get<double>();
  }
  bool Bool(const json& object, const std::string& key, const std::string& field) const {
    const json& value = Get(object, key, field);
    if (!value.is_boolean()) throw Bad(field, "true or false", value);
    return value.get<bool>();
  }
  DatasetError Bad(const std::string& field, const std::string& expected, const json& found) const {
    // An excerpt: the value may be a 10 MB string or a deep tree.
    return DatasetError(path_ + ": field '" + field + "': expected " + expected + ", got " +
                        Excerpt(found.is_string() ? "\"" + found.get<std::string>() + "\""
                                                  : found.dump()));
  }

 private:
  std::string path_;
};

bool IsValidFrameId(const std::string& id) {
  if (id.empty() || id.size() > kMaxIdLength || id[0] == '.' || id == "reference") {
    return false;
  }
  return std::all_of(id.begin(), id.end(), [](char c) {
    return (c >= 'a' && c <= 'z') || (c >= 'A' && c <= 'Z') || (c >= '0' && c <= '9') || c == '_' ||
           c == '-' || c == '.';
  });
}

std::string ShapeText(int rows, int cols, int channels) {
  return std::to_string(rows) + "x" + std::to_string(cols) + "x" + std::to_string(channels);
}

// Refuses a frame whose header gives another size than the sensor's, before a pixel
// is decoded (a mismatched frame costs a header read, not its decoded size).
void CheckFrameHeader(const std::string& path, const SensorInfo& info, SensorKind sensor) {
  const ImageHeader header = ReadImageHeader(path);
  if (header.rows != info.rows || header.cols != info.cols) {
    // Channels as ReadImage would give them (rgb8 drops alpha and expands palettes).
    const int channels = info.encoding == PixelEncoding::kRgb8 && header.channels != 1
                             ? 3
                             : header.channels;
    throw DatasetError(path + ": expected a " + ShapeText(info.rows, info.cols, info.channels) +
                       " frame (the " + ToString(sensor) + " reference's shape), got " +
                       ShapeText(header.rows, header.cols, channels) +
                       " (from the file's header, not decoded)");
  }
}

bool IsReferenceStem(const std::string& stem) { return internal::ToLower(stem) == "reference"; }

// Frames of one sensor folder: "<subdir>/<name>" per image file except the
// reference, keyed by id; clean frames from "<subdir>/clean/" if `with_clean`.
void ListSensorFrames(const std::string& root, const std::string& subdir, SensorKind kind,
                      const std::string& reference_name, bool with_clean,
                      std::vector<FrameRecord>* frames, bool* found_clean) {
  const std::string folder = internal::JoinPath(root, subdir);
  std::map<std::string, std::string> by_id;
  for (const internal::ImageFileEntry& entry : internal::ListImageFiles(folder)) {
    if (IsReferenceStem(entry.stem) || entry.name == reference_name) continue;
    if (!IsValidUtf8(entry.stem)) {
      // Frame ids are written to functasets and reports as JSON text (UTF-8 only).
      throw DatasetError(internal::JoinPath(folder, EscapedExcerpt(entry.name)) +
                         ": frame id: expected a file name in UTF-8, got other bytes");
    }
    const auto [it, inserted] = by_id.emplace(entry.stem, entry.name);
    if (!inserted) {
      throw DatasetError(internal::JoinPath(folder, entry.name) + ": frame id '" + entry.stem +
                         "': expected one file per id, got also '" + it->second + "'");
    }
  }
  std::map<std::string, std::string> clean_by_id;
  const std::string clean_folder = internal::JoinPath(folder, kCleanFolder);
  if (with_clean && internal::IsDirectory(clean_folder)) {
    for (const internal::ImageFileEntry& entry : internal::ListImageFiles(clean_folder)) {
      if (by_id.count(entry.stem) == 0) {
        throw DatasetError(internal::JoinPath(clean_folder, entry.name) +
                           ": expected a clean version of an existing frame, got no "
                           "frame '" +
                           entry.stem + "' in " + folder);
      }
      if (!clean_by_id.emplace(entry.stem, entry.name).second) {
        throw DatasetError(internal::JoinPath(clean_folder, entry.name) +
                           ": expected one clean file per frame id, got several for '" +
                           entry.stem + "'");
      }
    }
  }
  for (const auto& [id, name] : by_id) {
    FrameRecord record;
    record.id = id;
    record.sensor = kind;
    record.path = internal::JoinPath(subdir, name);
    const auto clean = clean_by_id.find(id);
    if (clean != clean_by_id.end()) {
      record.clean_path =
          internal::JoinPath(internal::JoinPath(subdir, kCleanFolder), clean->second);
      *found_clean = true;
    }
    frames->push_back(std::move(record));
  }
}

void CheckReferenceShape(const Image& reference, const SensorInfo& info, const std::string& path,
                         const std::string& against) {
  if (reference.rows != info.rows || reference.cols != info.cols ||
      reference.channels != info.channels) {
    throw DatasetError(path + ": reference: expected " +
                       ShapeText(info.rows, info.cols, info.channels) + " (" + against + "), got " +
                       reference.ShapeString());
  }
}

}  // namespace

// ---------------------------------------------------------------------------------
// Small value types.

const char* ToString(Split split) {
  switch (split) {
    case Split::kTrain:
      return "train";
    case Split::kTest:
      return "test";
  }
  return "unknown";
}

bool SplitFromString(const std::string& name, Split* split) {
  if (name == "train") {
    *split = Split::kTrain;
    return true;
  }
  if (name == "test") {
    *split = Split::kTest;
    return true;
  }
  return false;
}

bool IsValidPoseLabel(const PoseLabel& label, int rows, int cols, double pixel_pitch_m,
                      std::string* error) {
  const std::optional<internal::PoseLabelProblem> problem =
      internal::FindPoseLabelProblem(label, rows, cols, pixel_pitch_m);
  if (!problem) return true;
  if (error != nullptr) {
    *error = std::string("field '") + internal::LabelsColumnName(problem->column) +
             "': " + problem->expected + ", got '" +
             internal::PoseFieldText(label, problem->column) + "'";
  }
  return false;
}

double DefaultNormalizationScale(SensorKind kind) {
  // Bubble: indentations of a few millimetres to about a centimetre are typical, so
  // 1 cm -> 1.0 keeps values O(1). GelSlim: intensity changes under contact rarely
  // exceed half the range.
  return kind == SensorKind::kSoftBubble ? 0.01 : 0.5;
}

PixelEncoding SensorEncoding(SensorKind kind) {
  return kind == SensorKind::kSoftBubble ? PixelEncoding::kDepthU16Micrometres
                                         : PixelEncoding::kRgb8;
}

bool DatasetOpenOptions::IsValid(std::string* error) const {
  auto fail = [&](const std::string& message) {
    if (error != nullptr) *error = message;
    return false;
  };
  if (reference_index < 0) {
    return fail("OpenOptions::reference_index: expected >= 0, got " +
                std::to_string(reference_index));
  }
  if (!std::isfinite(pixel_pitch_m) || pixel_pitch_m < 0) {
    return fail(
        "OpenOptions::pixel_pitch_m: expected a finite number >= 0 (0 = "
        "unknown), got " +
        internal::FormatDoubleShort(pixel_pitch_m));
  }
  return true;
}

// ---------------------------------------------------------------------------------
// Dataset.

namespace {

void CheckOpenOptions(const Dataset::OpenOptions& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
}

}  // namespace

Dataset Dataset::Open(const std::string& dir, const OpenOptions& options) {
  CheckOpenOptions(options);
  if (!internal::IsDirectory(dir)) {
    std::error_code ec;
    throw DatasetError(dir + ": expected a dataset directory, got " +
                       (fs::exists(dir, ec) ? "a file" : "nothing (no such directory)"));
  }
  Dataset dataset;
  dataset.root_ = dir;
  const std::string metadata_path = internal::JoinPath(dir, kMetadataFile);
  bool filter_sensor = false;
  if (internal::IsRegularFile(metadata_path)) {
    dataset.has_metadata_ = true;
    dataset.metadata_path_ = metadata_path;
    json doc;
    const std::string text = ReadFile(metadata_path);
    // Bounded before parsing: a deeply nested value would otherwise recurse in every
    // later dump or comparison.
    if (JsonNestingDepth(text) > kMaxJsonDepth) {
      throw DatasetError(metadata_path + ": expected JSON nested at most " +
                         std::to_string(kMaxJsonDepth) + " levels deep, got deeper nesting");
    }
    try {
      doc = json::parse(text);
    } catch (const json::exception& e) {
      throw DatasetError(metadata_path + ": expected valid JSON, got a parse error: " +
                         Excerpt(e.what()));
    }
    const JsonFields fields(metadata_path);
    if (!doc.is_object()) throw fields.Bad("(top level)", "a JSON object", doc);
    const std::string format = fields.String(doc, "format", "format");
    if (format != kFormatName) {
      throw fields.Bad("format", std::string("\"") + kFormatName + "\"", doc["format"]);
    }
    const json& version = fields.Get(doc, "version", "version");
    if (!version.is_number_integer() || version.get<int>() != kFormatVersion) {
      throw fields.Bad("version",
                       std::to_string(kFormatVersion) + " (the only version this build reads)",
                       version);
    }
    dataset.source_ = fields.String(doc, "source", "source");
    const bool has_clean = fields.Bool(doc, "has_clean", "has_clean");
    if (doc.contains("meta")) {
      if (!doc["meta"].is_object()) throw fields.Bad("meta", "a JSON object", doc["meta"]);
      dataset.meta_json_ = doc["meta"].dump();
    }
    const json& sensors = fields.Get(doc, "sensors", "sensors");
    if (!sensors.is_object() || sensors.empty()) {
      throw fields.Bad("sensors", "a non-empty object keyed by sensor name", sensors);
    }
    for (const auto& [name, entry] : sensors.items()) {
      const std::string prefix = "sensors." + Excerpt(name, 40);
      SensorKind kind;
      if (!SensorKindFromString(name, &kind)) {
        throw DatasetError(metadata_path + ": field '" + prefix +
                           "': expected a sensor named 'bubble' or 'gelslim', got '" + Excerpt(name) + "'");
      }
      if (dataset.sensors_.count(kind) != 0) {
        throw DatasetError(metadata_path + ": field '" + prefix +
                           "': expected each sensor once, got it twice");
      }
      if (!entry.is_object()) throw fields.Bad(prefix, "an object", entry);
      SensorInfo info;
      info.kind = kind;
      info.rows = fields.Int(entry, "rows", prefix + ".rows", 1);
      info.cols = fields.Int(entry, "cols", prefix + ".cols", 1);
      info.channels = fields.Int(entry, "channels", prefix + ".channels", 1);
      const std::string encoding = fields.String(entry, "encoding", prefix + ".encoding");
      if (!PixelEncodingFromString(encoding, &info.encoding) ||
          info.encoding != SensorEncoding(kind)) {
        throw fields.Bad(prefix + ".encoding",
                         std::string("\"") + ToString(SensorEncoding(kind)) + "\"",
                         entry["encoding"]);
      }
      const bool channels_ok = info.encoding == PixelEncoding::kRgb8
                                   ? (info.channels == 1 || info.channels == 3)
                                   : info.channels == 1;
      if (!channels_ok) {
        throw fields.Bad(prefix + ".channels",
                         info.encoding == PixelEncoding::kRgb8 ? "1 or 3" : "1", entry["channels"]);
      }
      info.pixel_pitch_m = fields.NonNegative(entry, "pixel_pitch_m", prefix + ".pixel_pitch_m");
      info.normalization_scale =
          fields.NonNegative(entry, "normalization_scale", prefix + ".normalization_scale");
      info.reference = fields.String(entry, "reference", prefix + ".reference");
      if (info.reference.empty()) {
        throw fields.Bad(prefix + ".reference", "a path relative to the dataset folder",
                         entry["reference"]);
      }
      const std::string reference_path = internal::JoinPath(dir, info.reference);
      Image reference = ReadImage(reference_path, info.encoding);
      CheckReferenceShape(reference, info, reference_path,
                          "from " + metadata_path + " field '" + prefix + "'");
      std::vector<FrameRecord> frames;
      bool found_clean = false;
      const std::string subdir = ToString(kind);
      const std::string reference_name =
          fs::path(reference_path).parent_path() == fs::path(internal::JoinPath(dir, subdir))
              ? internal::BaseName(reference_path)
              : std::string();
      if (internal::IsDirectory(internal::JoinPath(dir, subdir))) {
        ListSensorFrames(dir, subdir, kind, reference_name, has_clean, &frames, &found_clean);
      }
      if (entry.contains("num_frames")) {
        const int expected = fields.Int(entry, "num_frames", prefix + ".num_frames", 0);
        if (static_cast<int>(frames.size()) != expected) {
          throw DatasetError(metadata_path + ": field '" + prefix +
                             ".num_frames': "
                             "expected " +
                             std::to_string(expected) + " frames in " +
                             internal::JoinPath(dir, subdir) + ", got " +
                             std::to_string(frames.size()));
        }
      }
      dataset.has_clean_ = dataset.has_clean_ || found_clean;
      dataset.frames_.insert(dataset.frames_.end(), frames.begin(), frames.end());
      dataset.sensors_[kind] = SensorData{info, std::move(reference)};
    }
    if (has_clean && !dataset.has_clean_) {
      throw DatasetError(metadata_path +
                         ": field 'has_clean': expected clean frames in "
                         "<sensor>/clean/ since it is true, got none");
    }
    filter_sensor = options.sensor.has_value();
  } else {
    // A folder brought by a user: bubble/ and/or gelslim/ subfolders, or flat.
    std::vector<std::pair<std::string, std::optional<SensorKind>>> folders;
    for (SensorKind kind : {SensorKind::kSoftBubble, SensorKind::kGelSlim}) {
      if (internal::IsDirectory(internal::JoinPath(dir, ToString(kind)))) {
        folders.emplace_back(ToString(kind), kind);
      }
    }
    filter_sensor = !folders.empty() && options.sensor.has_value();
    if (folders.empty()) folders.emplace_back("", options.sensor);
    for (const auto& [subdir, known_kind] : folders) {
      const std::string folder = internal::JoinPath(dir, subdir);
      const std::string folder_name = subdir.empty() ? dir : folder;
      const std::vector<internal::ImageFileEntry> files = internal::ListImageFiles(folder);
      // The reference: reference.<ext>, else options.reference.
      std::string reference_path;
      std::string reference_in_folder;  // its name if it lies in `folder`
      for (const internal::ImageFileEntry& entry : files) {
        if (!IsReferenceStem(entry.stem)) continue;
        if (!reference_path.empty()) {
          throw DatasetError(folder_name + ": expected one reference image, got both '" +
                             internal::BaseName(reference_path) + "' and '" + entry.name + "'");
        }
        reference_path = internal::JoinPath(folder, entry.name);
        reference_in_folder = entry.name;
      }
      if (reference_path.empty()) {
        if (options.reference.empty()) {
          throw DatasetError(folder_name +
                             ": expected a reference image "
                             "'reference.png' (or .jpg/.jpeg) or OpenOptions::reference "
                             "naming one, got neither (no dataset.json either)");
        }
        const std::string in_folder = internal::JoinPath(folder, options.reference);
        if (internal::IsRegularFile(in_folder)) {
          reference_path = in_folder;
        } else if (internal::IsRegularFile(options.reference)) {
          reference_path = options.reference;
        } else {
          throw DatasetError(folder_name + ": reference '" + options.reference +
                             "': expected an image file in the folder or at that path, "
                             "got no such file");
        }
        for (const internal::ImageFileEntry& entry : files) {
          std::error_code ec;
          if (fs::equivalent(internal::JoinPath(folder, entry.name), reference_path, ec)) {
            reference_in_folder = entry.name;
          }
        }
      }
      SensorKind kind;
      if (known_kind) {
        kind = *known_kind;
      } else {
        const internal::ImageProbe probe = internal::ProbeImage(reference_path);
        if (probe.bit_depth == 16 && probe.channels == 1) {
          kind = SensorKind::kSoftBubble;
        } else if (probe.bit_depth == 8) {
          kind = SensorKind::kGelSlim;
        } else {
          throw DatasetError(reference_path +
                             ": cannot infer the sensor: expected a "
                             "16-bit 1-channel image (bubble depth) or an 8-bit one "
                             "(gelslim rgb), got " +
                             std::to_string(probe.bit_depth) + "-bit with " +
                             std::to_string(probe.channels) +
                             " channel(s); set OpenOptions::sensor");
        }
      }
      SensorInfo info;
      info.kind = kind;
      info.encoding = SensorEncoding(kind);
      Image reference = ReadImage(reference_path, info.encoding);
      info.rows = reference.rows;
      info.cols = reference.cols;
      info.channels = reference.channels;
      info.pixel_pitch_m = options.pixel_pitch_m;
      info.normalization_scale = DefaultNormalizationScale(kind);
      info.reference = reference_in_folder.empty()
                           ? fs::absolute(reference_path).string()
                           : internal::JoinPath(subdir, reference_in_folder);
      if (dataset.sensors_.count(kind) != 0) {
        throw DatasetError(folder_name +
                           ": expected one folder per sensor, got a "
                           "second " +
                           ToString(kind) + " folder");
      }
      bool found_clean = false;
      ListSensorFrames(dir, subdir, kind, reference_in_folder, /*with_clean=*/true,
                       &dataset.frames_, &found_clean);
      dataset.has_clean_ = dataset.has_clean_ || found_clean;
      dataset.sensors_[kind] = SensorData{info, std::move(reference)};
    }
  }
  dataset.SortAndIndexFrames();
  std::string labels_path = options.labels;
  if (labels_path.empty()) {
    const std::string default_path = internal::JoinPath(dir, kLabelsFile);
    if (internal::IsRegularFile(default_path)) labels_path = default_path;
  }
  if (!labels_path.empty()) dataset.AttachLabels(labels_path, false);
  if (filter_sensor) dataset.KeepOnlySensor(*options.sensor);
  return dataset;
}

Dataset Dataset::OpenVideo(const std::string& path, const OpenOptions& options) {
  CheckOpenOptions(options);
  if (options.sensor && *options.sensor != SensorKind::kGelSlim) {
    throw DatasetError(path +
                       ": a video holds 8-bit colour frames: expected sensor "
                       "'gelslim', got '" +
                       ToString(*options.sensor) + "'");
  }
  if (!internal::IsRegularFile(path)) {
    throw DatasetError(path + ": expected a video file, got no such file");
  }
  // FFmpeg first: it reads AVI and MP4 without the other backends' noisy attempts
  // (GStreamer, image sequences) on files they cannot open.
  cv::VideoCapture capture;
  try {
    if (!capture.open(path, cv::CAP_FFMPEG)) capture.open(path, cv::CAP_ANY);
  } catch (const cv::Exception& e) {
    throw DatasetError(path + ": expected a video OpenCV can open, got an error: " + e.what());
  }
  if (!capture.isOpened()) {
    throw DatasetError(path +
                       ": expected a video OpenCV can open (AVI/MP4 with a "
                       "codec this OpenCV build decodes), got one it cannot open");
  }
  std::vector<Image> decoded;
  cv::Mat mat;
  const std::string name = internal::BaseName(path);
  while (capture.read(mat)) {
    if (mat.empty()) break;
    const std::string frame_name = path + "#" + std::to_string(decoded.size());
    decoded.push_back(internal::ImageFromRgb8Mat(mat, frame_name));
    if (!decoded.back().SameShape(decoded.front())) {
      throw DatasetError(frame_name + ": expected " + decoded.front().ShapeString() +
                         " like frame 0, got " + decoded.back().ShapeString());
    }
  }
  if (decoded.empty()) {
    throw DatasetError(path + ": expected at least one decodable frame, got none");
  }
  const std::size_t reference_index = static_cast<std::size_t>(options.reference_index);
  if (reference_index >= decoded.size()) {
    throw DatasetError(path + ": OpenOptions::reference_index: expected a frame index < " +
                       std::to_string(decoded.size()) + " (the number of frames), got " +
                       std::to_string(options.reference_index));
  }
  Dataset dataset;
  dataset.root_ = path;
  dataset.source_ = path;
  SensorInfo info;
  info.kind = SensorKind::kGelSlim;
  info.encoding = PixelEncoding::kRgb8;
  info.rows = decoded.front().rows;
  info.cols = decoded.front().cols;
  info.channels = decoded.front().channels;
  info.pixel_pitch_m = options.pixel_pitch_m;
  info.normalization_scale = DefaultNormalizationScale(info.kind);
  char id[32];
  std::snprintf(id, sizeof(id), "%06zu", reference_index);
  info.reference = name + "#" + id;
  dataset.sensors_[info.kind] = SensorData{info, decoded[reference_index]};
  auto frames = std::make_shared<std::vector<Image>>();
  for (std::size_t i = 0; i < decoded.size(); ++i) {
    if (i == reference_index) continue;
    std::snprintf(id, sizeof(id), "%06zu", i);
    FrameRecord record;
    record.id = id;
    record.sensor = info.kind;
    record.path = name + "#" + id;
    dataset.frames_.push_back(std::move(record));
    frames->push_back(std::move(decoded[i]));
  }
  dataset.video_frames_ = std::move(frames);
  // Ids are zero-padded, so frames_ is already sorted and aligned with video_frames_.
  if (!options.labels.empty()) dataset.AttachLabels(options.labels, false);
  return dataset;
}

void Dataset::SortAndIndexFrames() {
  std::sort(frames_.begin(), frames_.end(), [](const FrameRecord& a, const FrameRecord& b) {
    return a.id != b.id ? a.id < b.id : a.sensor < b.sensor;
  });
}

void Dataset::AttachLabels(const std::string& labels_path, bool ignore_absent_sensors) {
  labels_path_ = labels_path;
  const std::vector<internal::LabelRow> rows =
      internal::ParseLabelsCsv(ReadFile(labels_path), labels_path);
  for (const internal::LabelRow& row : rows) {
    const std::string where = labels_path + ":" + std::to_string(row.line) + ": ";
    const auto sensor = sensors_.find(row.sensor);
    if (sensor == sensors_.end()) {
      if (ignore_absent_sensors) continue;
      std::string present;
      for (const auto& entry : sensors_) {
        present += (present.empty() ? "" : " or ") + std::string("'") + ToString(entry.first) + "'";
      }
      throw DatasetError(where + "field 'sensor': expected a sensor of this dataset (" + present +
                         "), got '" + ToString(row.sensor) + "'");
    }
    const std::optional<std::size_t> index = FindFrame(row.frame, row.sensor);
    if (!index) {
      throw DatasetError(where + "field 'frame': expected the id of an existing " +
                         ToString(row.sensor) + " frame, got '" + EscapedExcerpt(row.frame) +
                         "' (no such image)");
    }
    if (row.label) {
      const SensorInfo& info = sensor->second.info;
      if (std::optional<internal::PoseLabelProblem> problem = internal::FindPoseLabelProblem(
              *row.label, info.rows, info.cols, info.pixel_pitch_m)) {
        throw DatasetError(where + "field '" + internal::LabelsColumnName(problem->column) +
                           "': " + problem->expected + ", got '" +
                           internal::PoseFieldText(*row.label, problem->column) + "'");
      }
    }
    FrameRecord& record = frames_[*index];
    record.label = row.label;
    record.split = row.split;
  }
}

void Dataset::KeepOnlySensor(SensorKind kind) {
  if (sensors_.count(kind) == 0) {
    throw DatasetError(root_ +
                       ": OpenOptions::sensor: expected a sensor of this dataset, "
                       "got '" +
                       ToString(kind) + "' which it does not hold");
  }
  for (auto it = sensors_.begin(); it != sensors_.end();) {
    it = it->first == kind ? std::next(it) : sensors_.erase(it);
  }
  frames_.erase(std::remove_if(frames_.begin(), frames_.end(),
                               [kind](const FrameRecord& f) { return f.sensor != kind; }),
                frames_.end());
  has_clean_ = std::any_of(frames_.begin(), frames_.end(),
                           [](const FrameRecord& f) { return !f.clean_path.empty(); });
}

std::vector<SensorKind> Dataset::sensors() const {
  std::vector<SensorKind> kinds;
  for (const auto& entry : sensors_) kinds.push_back(entry.first);
  return kinds;
}

bool Dataset::has_sensor(SensorKind kind) const { return sensors_.count(kind) != 0; }

const Dataset::SensorData& Dataset::sensor_data(SensorKind kind) const {
  const auto it = sensors_.find(kind);
  if (it == sensors_.end()) {
    throw DatasetError(root_ + ": expected a " + ToString(kind) +
                       " sensor, got a dataset without one");
  }
  return it->second;
}

const SensorInfo& Dataset::sensor_info(SensorKind kind) const { return sensor_data(kind).info; }

const Image& Dataset::Reference(SensorKind kind) const { return sensor_data(kind).reference; }

std::vector<std::size_t> Dataset::FrameIndices(SensorKind sensor,
                                               std::optional<Split> split) const {
  std::vector<std::size_t> indices;
  for (std::size_t i = 0; i < frames_.size(); ++i) {
    if (frames_[i].sensor == sensor && (!split || frames_[i].split == *split)) {
      indices.push_back(i);
    }
  }
  return indices;
}

std::optional<std::size_t> Dataset::FindFrame(const std::string& id, SensorKind sensor) const {
  const auto it =
      std::lower_bound(frames_.begin(), frames_.end(), std::make_pair(id, sensor),
                       [](const FrameRecord& f, const std::pair<std::string, SensorKind>& key) {
                         return f.id != key.first ? f.id < key.first : f.sensor < key.second;
                       });
  if (it == frames_.end() || it->id != id || it->sensor != sensor) return std::nullopt;
  return static_cast<std::size_t>(it - frames_.begin());
}

Image Dataset::LoadFrame(std::size_t index) const {
  if (index >= frames_.size()) {
    throw std::out_of_range("Dataset::LoadFrame: index " + std::to_string(index) +
                            " >= number of frames " + std::to_string(frames_.size()));
  }
  if (video_frames_) return (*video_frames_)[index];
  const FrameRecord& record = frames_[index];
  const SensorInfo& info = sensor_info(record.sensor);
  const std::string path = internal::JoinPath(root_, record.path);
  CheckFrameHeader(path, info, record.sensor);
  Image image = ReadImage(path, info.encoding);
  if (image.rows != info.rows || image.cols != info.cols || image.channels != info.channels) {
    throw DatasetError(path + ": expected a " + ShapeText(info.rows, info.cols, info.channels) +
                       " frame (the " + ToString(record.sensor) + " reference's shape), got " +
                       image.ShapeString());
  }
  return image;
}

Image Dataset::LoadCleanFrame(std::size_t index) const {
  if (index >= frames_.size()) {
    throw std::out_of_range("Dataset::LoadCleanFrame: index " + std::to_string(index) +
                            " >= number of frames " + std::to_string(frames_.size()));
  }
  const FrameRecord& record = frames_[index];
  if (record.clean_path.empty()) {
    throw DatasetError(internal::JoinPath(root_, record.path) +
                       ": expected a clean version, got none (no " + ToString(record.sensor) +
                       "/clean/" + record.id + ".png)");
  }
  const SensorInfo& info = sensor_info(record.sensor);
  const std::string path = internal::JoinPath(root_, record.clean_path);
  CheckFrameHeader(path, info, record.sensor);
  Image image = ReadImage(path, info.encoding);
  if (image.rows != info.rows || image.cols != info.cols || image.channels != info.channels) {
    throw DatasetError(path + ": expected a " + ShapeText(info.rows, info.cols, info.channels) +
                       " clean frame, got " + image.ShapeString());
  }
  return image;
}

void Dataset::ValidateAllFrames() const {
  for (std::size_t i = 0; i < frames_.size(); ++i) {
    LoadFrame(i);
    if (!frames_[i].clean_path.empty()) LoadCleanFrame(i);
  }
}

std::vector<std::string> Dataset::Files() const {
  std::set<std::string> files;
  if (video_frames_) {
    files.insert(root_);
  } else {
    for (const auto& entry : sensors_) {
      files.insert(internal::JoinPath(root_, entry.second.info.reference));
    }
    for (const FrameRecord& record : frames_) {
      files.insert(internal::JoinPath(root_, record.path));
      if (!record.clean_path.empty()) {
        files.insert(internal::JoinPath(root_, record.clean_path));
      }
    }
  }
  if (!metadata_path_.empty()) files.insert(metadata_path_);
  if (!labels_path_.empty()) files.insert(labels_path_);
  return std::vector<std::string>(files.begin(), files.end());
}

std::uint64_t Dataset::BytesOnDisk() const {
  std::uint64_t total = 0;
  for (const std::string& file : Files()) total += internal::FileSizeOrThrow(file);
  return total;
}

// ---------------------------------------------------------------------------------
// DatasetWriter.

bool DatasetWriter::Options::IsValid(std::string* error) const {
  auto fail = [&](const std::string& message) {
    if (error != nullptr) *error = message;
    return false;
  };
  if (png_compression < 0 || png_compression > 9) {
    return fail(
        "DatasetWriter::Options::png_compression: expected an integer in [0, 9], "
        "got " +
        std::to_string(png_compression));
  }
  json meta = json::parse(meta_json, nullptr, /*allow_exceptions=*/false);
  if (meta.is_discarded() || !meta.is_object()) {
    return fail("DatasetWriter::Options::meta_json: expected a JSON object, got '" + meta_json +
                "'");
  }
  return true;
}

struct DatasetWriter::Impl {
  struct Entry {
    std::optional<PoseLabel> label;
    Split split = Split::kTrain;
    bool written = false;  // false while the files are being written
  };
  std::string dir;
  Options options;
  std::mutex mutex;
  std::map<SensorKind, SensorInfo> sensors;
  std::map<std::pair<std::string, SensorKind>, Entry> frames;
  bool has_clean = false;
  bool finished = false;

  void CheckNotFinished(const char* what) const {
    if (finished) {
      throw std::logic_error(std::string("DatasetWriter::") + what + ": called after Finish()");
    }
  }
};

DatasetWriter::DatasetWriter(const std::string& dir, const Options& options)
    : impl_(std::make_unique<Impl>()) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  impl_->dir = dir;
  impl_->options = options;
  const std::string owned[] = {kMetadataFile, kLabelsFile, ToString(SensorKind::kSoftBubble),
                               ToString(SensorKind::kGelSlim)};
  std::error_code ec;
  for (const std::string& name : owned) {
    const std::string path = internal::JoinPath(dir, name);
    if (!fs::exists(fs::symlink_status(path, ec))) continue;
    if (!options.overwrite) {
      throw DatasetError(dir +
                         ": expected a folder without dataset content (or "
                         "DatasetWriter::Options::overwrite), got existing '" +
                         name + "'");
    }
    // dataset.json goes first (it is first in `owned`), so a folder whose overwrite
    // is interrupted is never mistaken for a complete dataset.
    fs::remove_all(path, ec);
    if (ec) {
      throw std::runtime_error(path + ": cannot remove for overwrite: " + ec.message());
    }
  }
  fs::create_directories(dir, ec);
  if (ec || !internal::IsDirectory(dir)) {
    throw std::runtime_error(dir + ": cannot create the dataset folder: " + ec.message());
  }
}

DatasetWriter::~DatasetWriter() = default;

void DatasetWriter::AddSensor(const SensorInfo& info_in, const Image& reference) {
  SensorInfo info = info_in;
  const std::string name = ToString(info.kind);
  info.reference = name + "/reference.png";
  const std::string where = impl_->dir + ": AddSensor(" + name + "): ";
  if (info.rows <= 0 || info.cols <= 0) {
    throw DatasetError(where + "field 'rows'/'cols': expected > 0, got " +
                       std::to_string(info.rows) + "x" + std::to_string(info.cols));
  }
  if (info.encoding != SensorEncoding(info.kind)) {
    throw DatasetError(where + "field 'encoding': expected '" +
                       ToString(SensorEncoding(info.kind)) + "', got '" + ToString(info.encoding) +
                       "'");
  }
  const bool channels_ok = info.encoding == PixelEncoding::kRgb8
                               ? (info.channels == 1 || info.channels == 3)
                               : info.channels == 1;
  if (!channels_ok) {
    throw DatasetError(where + "field 'channels': expected " +
                       (info.encoding == PixelEncoding::kRgb8 ? "1 or 3" : "1") + ", got " +
                       std::to_string(info.channels));
  }
  if (!(std::isfinite(info.pixel_pitch_m) && info.pixel_pitch_m >= 0)) {
    throw DatasetError(where + "field 'pixel_pitch_m': expected a finite number >= 0, got " +
                       internal::FormatDoubleShort(info.pixel_pitch_m));
  }
  if (!(std::isfinite(info.normalization_scale) && info.normalization_scale >= 0)) {
    throw DatasetError(where +
                       "field 'normalization_scale': expected a finite number "
                       ">= 0, got " +
                       internal::FormatDoubleShort(info.normalization_scale));
  }
  CheckReferenceShape(reference, info, where + "reference", "from the SensorInfo");
  std::lock_guard<std::mutex> lock(impl_->mutex);
  impl_->CheckNotFinished("AddSensor");
  if (impl_->sensors.count(info.kind) != 0) {
    throw DatasetError(where + "expected each sensor once, got it twice");
  }
  const std::string folder = internal::JoinPath(impl_->dir, name);
  std::error_code ec;
  fs::create_directories(folder, ec);
  if (ec) throw std::runtime_error(folder + ": cannot create: " + ec.message());
  WritePngAtomically(internal::JoinPath(impl_->dir, info.reference), reference, info.encoding,
                     impl_->options.png_compression);
  impl_->sensors[info.kind] = info;
}

void DatasetWriter::AddFrame(const std::string& id, SensorKind sensor, const Image& frame,
                             const Image* clean, const std::optional<PoseLabel>& label,
                             Split split) {
  const std::string name = ToString(sensor);
  const std::string where = impl_->dir + ": AddFrame(" + id + ", " + name + "): ";
  if (!IsValidFrameId(id)) {
    throw DatasetError(where +
                       "field 'id': expected 1-64 characters from "
                       "[A-Za-z0-9_.-], not starting with '.', not 'reference', got '" +
                       id + "'");
  }
  SensorInfo info;
  {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    impl_->CheckNotFinished("AddFrame");
    const auto it = impl_->sensors.find(sensor);
    if (it == impl_->sensors.end()) {
      throw DatasetError(where +
                         "field 'sensor': expected a sensor added with "
                         "AddSensor, got '" +
                         name + "'");
    }
    info = it->second;
  }
  const std::string expected_shape = ShapeText(info.rows, info.cols, info.channels);
  if (!(frame.rows == info.rows && frame.cols == info.cols && frame.channels == info.channels)) {
    throw DatasetError(where + "frame: expected " + expected_shape + ", got " +
                       frame.ShapeString());
  }
  if (clean != nullptr &&
      !(clean->rows == info.rows && clean->cols == info.cols && clean->channels == info.channels)) {
    throw DatasetError(where + "clean frame: expected " + expected_shape + ", got " +
                       clean->ShapeString());
  }
  std::string error;
  if (label && !IsValidPoseLabel(*label, info.rows, info.cols, info.pixel_pitch_m, &error)) {
    throw DatasetError(where + error);
  }
  const auto key = std::make_pair(id, sensor);
  {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    if (!impl_->frames.emplace(key, Impl::Entry{label, split, false}).second) {
      throw DatasetError(where + "expected each (id, sensor) once, got a duplicate");
    }
  }
  try {
    const std::string folder = internal::JoinPath(impl_->dir, name);
    // Frames skip the per-file fsync; Finish() syncs the file system once before it
    // writes dataset.json, the file that marks the dataset complete.
    WritePngAtomically(internal::JoinPath(folder, id + ".png"), frame, info.encoding,
                       impl_->options.png_compression, Durability::kDeferred);
    if (clean != nullptr) {
      const std::string clean_folder = internal::JoinPath(folder, kCleanFolder);
      std::error_code ec;
      fs::create_directories(clean_folder, ec);
      if (!internal::IsDirectory(clean_folder)) {
        throw std::runtime_error(clean_folder + ": cannot create: " + ec.message());
      }
      WritePngAtomically(internal::JoinPath(clean_folder, id + ".png"), *clean, info.encoding,
                         impl_->options.png_compression, Durability::kDeferred);
    }
  } catch (...) {
    std::lock_guard<std::mutex> lock(impl_->mutex);
    impl_->frames.erase(key);
    throw;
  }
  std::lock_guard<std::mutex> lock(impl_->mutex);
  impl_->frames[key].written = true;
  if (clean != nullptr) impl_->has_clean = true;
}

std::size_t DatasetWriter::num_frames() const {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  return impl_->frames.size();
}

void DatasetWriter::Finish() {
  std::lock_guard<std::mutex> lock(impl_->mutex);
  impl_->CheckNotFinished("Finish");
  std::vector<internal::LabelRow> rows;
  std::map<SensorKind, int> counts;
  for (const auto& [key, entry] : impl_->frames) {
    if (!entry.written) {
      throw std::logic_error("DatasetWriter::Finish: frame '" + key.first +
                             "' is still being written by AddFrame");
    }
    internal::LabelRow row;
    row.frame = key.first;
    row.sensor = key.second;
    row.label = entry.label;
    row.split = entry.split;
    rows.push_back(std::move(row));
    ++counts[key.second];
  }
  SyncFileSystem(impl_->dir);
  WriteFileAtomically(internal::JoinPath(impl_->dir, kLabelsFile), internal::FormatLabelsCsv(rows));
  // ordered_json keeps the documented field order, for people reading the file.
  nlohmann::ordered_json doc;
  doc["format"] = kFormatName;
  doc["version"] = kFormatVersion;
  doc["source"] = impl_->options.source;
  nlohmann::ordered_json sensors = nlohmann::ordered_json::object();
  for (const auto& [kind, info] : impl_->sensors) {
    sensors[ToString(kind)] = {
        {"rows", info.rows},
        {"cols", info.cols},
        {"channels", info.channels},
        {"encoding", ToString(info.encoding)},
        {"pixel_pitch_m", info.pixel_pitch_m},
        {"reference", info.reference},
        {"normalization_scale", info.normalization_scale},
        {"num_frames", counts[kind]},
    };
  }
  doc["sensors"] = std::move(sensors);
  doc["has_clean"] = impl_->has_clean;
  doc["meta"] = nlohmann::ordered_json::parse(impl_->options.meta_json);
  WriteFileAtomically(internal::JoinPath(impl_->dir, kMetadataFile), doc.dump(2) + "\n");
  impl_->finished = true;
}

}  // namespace tactfunc
