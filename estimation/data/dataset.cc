// Copyright 2026 The tactfunc Authors.
#include "estimation/data/dataset.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <mutex>
#include <nlohmann/json.hpp>
#include <opencv2/core.hpp>
#include <set>
#include <stdexcept>
#include <system_error>
#include <utility>

#include "estimation/data/internal/labels_csv.h"
#include "estimation/data/internal/opencv_image.h"
#include "estimation/data/internal/path_util.h"
#include "estimation/data/internal/video_reader.h"
#include "models/core/text_limits.h"
#include "models/simulator/tool.h"

namespace tactfunc {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;

constexpr const char* kMetadataFile = "dataset.json";
constexpr const char* kLabelsFile = "labels.csv";
constexpr const char* kClipsFile = "clips.csv";
constexpr const char* kToolsFile = "tools.csv";
constexpr const char* kSensorFile = "sensor.json";
constexpr const char* kFormatName = "tactfunc-dataset";
constexpr int kFormatVersion = 1;
constexpr const char* kCleanFolder = "clean";
constexpr std::size_t kMaxIdLength = 64;
// Video clips of a clip set that keep a decoder open at once (the least recently read
// one is closed beyond this): memory stays bounded however many clips there are.
constexpr std::size_t kMaxOpenVideoClips = 4;

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

// The reference of a sensor folder without metadata (`folder`, `files` its images,
// `folder_name` for messages): reference.<ext>, else `named` looked up in the folder
// and, if `anywhere`, as a path. Sets *in_folder to its name if it lies in the folder.
std::string FindFolderReference(const std::string& folder, const std::string& folder_name,
                                const std::vector<internal::ImageFileEntry>& files,
                                const std::string& named, bool anywhere,
                                std::string* in_folder) {
  std::string reference_path;
  in_folder->clear();
  for (const internal::ImageFileEntry& entry : files) {
    if (!IsReferenceStem(entry.stem)) continue;
    if (!reference_path.empty()) {
      throw DatasetError(folder_name + ": expected one reference image, got both '" +
                         internal::BaseName(reference_path) + "' and '" + entry.name + "'");
    }
    reference_path = internal::JoinPath(folder, entry.name);
    *in_folder = entry.name;
  }
  if (!reference_path.empty()) return reference_path;
  if (named.empty()) {
    throw DatasetError(folder_name +
                       ": expected a reference image "
                       "'reference.png' (or .jpg/.jpeg) or OpenOptions::reference "
                       "naming one, got neither (no dataset.json either)");
  }
  const std::string named_in_folder = internal::JoinPath(folder, named);
  if (internal::IsRegularFile(named_in_folder)) {
    reference_path = named_in_folder;
  } else if (anywhere && internal::IsRegularFile(named)) {
    reference_path = named;
  } else {
    throw DatasetError(folder_name + ": reference '" + named + "': expected an image file " +
                       (anywhere ? "in the folder or at that path" : "in the clip's folder") +
                       ", got no such file");
  }
  for (const internal::ImageFileEntry& entry : files) {
    std::error_code ec;
    if (fs::equivalent(internal::JoinPath(folder, entry.name), reference_path, ec)) {
      *in_folder = entry.name;
    }
  }
  return reference_path;
}

// The sensor kind of a user folder whose reference is `reference_path`: `given`, else
// inferred from the reference's header (16-bit 1-channel -> bubble, 8-bit -> gelslim).
SensorKind FolderSensorKind(const std::optional<SensorKind>& given,
                            const std::string& reference_path) {
  if (given) return *given;
  const internal::ImageProbe probe = internal::ProbeImage(reference_path);
  if (probe.bit_depth == 16 && probe.channels == 1) return SensorKind::kSoftBubble;
  if (probe.bit_depth == 8) return SensorKind::kGelSlim;
  throw DatasetError(reference_path +
                     ": cannot infer the sensor: expected a "
                     "16-bit 1-channel image (bubble depth) or an 8-bit one "
                     "(gelslim rgb), got " +
                     std::to_string(probe.bit_depth) + "-bit with " +
                     std::to_string(probe.channels) + " channel(s); set OpenOptions::sensor");
}

// The SensorInfo of data without metadata, from its reference and the options.
SensorInfo UserSensorInfo(SensorKind kind, const Image& reference,
                          const Dataset::OpenOptions& options) {
  SensorInfo info;
  info.kind = kind;
  info.encoding = SensorEncoding(kind);
  info.rows = reference.rows;
  info.cols = reference.cols;
  info.channels = reference.channels;
  info.pixel_pitch_m = options.pixel_pitch_m;
  info.normalization_scale = DefaultNormalizationScale(kind);
  return info;
}

// A video frame's index as it appears in ids and paths: 6 digits, zero-padded.
std::string VideoFrameId(std::size_t index) {
  char id[32];
  std::snprintf(id, sizeof(id), "%06zu", index);
  return id;
}

// One record per frame of a video of `count` frames except `reference_index`: id
// `id_prefix` + VideoFrameId(i), path "<file_name>#<VideoFrameId(i)>".
void AppendVideoFrames(const std::string& file_name, const std::string& id_prefix, int clip,
                       std::size_t count, std::size_t reference_index,
                       std::vector<FrameRecord>* frames) {
  for (std::size_t i = 0; i < count; ++i) {
    if (i == reference_index) continue;
    FrameRecord record;
    record.id = id_prefix + VideoFrameId(i);
    record.sensor = SensorKind::kGelSlim;
    record.path = file_name + "#" + VideoFrameId(i);
    record.clip = clip;
    record.video_frame = static_cast<std::int64_t>(i);
    frames->push_back(std::move(record));
  }
}

// Refuses options.sensor other than gelslim for a video (`path`).
void CheckVideoSensor(const Dataset::OpenOptions& options, const std::string& path) {
  if (options.sensor && *options.sensor != SensorKind::kGelSlim) {
    throw DatasetError(path +
                       ": a video holds 8-bit colour frames: expected sensor "
                       "'gelslim', got '" +
                       ToString(*options.sensor) + "'");
  }
}

// An entry of a clip set folder: a subfolder holding images, or a video file.
struct ClipEntry {
  std::string name;       // the clip name: the subfolder's name or the video's stem
  std::string file_name;  // the entry's name in the folder
  bool video = false;
};

// The clip entries of `dir`, sorted by clip name; subfolders without images, hidden
// entries and other files are left out. Throws DatasetError for two entries of one
// name and for names that cannot be a clip name.
std::vector<ClipEntry> ListClipEntries(const std::string& dir) {
  std::error_code ec;
  fs::directory_iterator it(dir, ec);
  if (ec) {
    throw DatasetError(dir + ": expected a readable directory, got error '" + ec.message() + "'");
  }
  std::map<std::string, ClipEntry> by_name;
  for (const fs::directory_entry& entry : it) {
    const std::string file_name = entry.path().filename().string();
    if (file_name.empty() || file_name[0] == '.') continue;
    std::error_code type_ec;
    ClipEntry clip;
    clip.file_name = file_name;
    if (entry.is_directory(type_ec)) {
      if (internal::ListImageFiles(entry.path().string()).empty()) continue;
      clip.name = file_name;
    } else if (entry.is_regular_file(type_ec) && IsVideoFileName(file_name)) {
      clip.name = entry.path().stem().string();
      clip.video = true;
    } else {
      continue;
    }
    const std::string where = internal::JoinPath(dir, EscapedExcerpt(file_name));
    // Clip names start frame ids, which go to functasets as JSON text and to CSV files
    // unquoted (labels.csv, clips.csv).
    if (!IsValidUtf8(clip.name)) {
      throw DatasetError(where + ": clip name: expected a name in UTF-8, got other bytes");
    }
    if (clip.name.empty() || !internal::IsCsvSafe(clip.name)) {
      throw DatasetError(where + ": clip name: expected a non-empty name without ',', '\"' or "
                         "line breaks, got '" + EscapedExcerpt(clip.name) + "'");
    }
    const auto [existing, inserted] = by_name.emplace(clip.name, clip);
    if (!inserted) {
      throw DatasetError(where + ": clip '" + clip.name + "': expected one folder or video per " +
                         "clip name, got also '" + existing->second.file_name + "'");
    }
  }
  std::vector<ClipEntry> entries;
  for (auto& [name, clip] : by_name) entries.push_back(std::move(clip));
  return entries;
}

// True if `dir` (without dataset.json, bubble/ or gelslim/) is a clip set: no images
// of its own and at least one clip entry.
bool IsClipSetFolder(const std::string& dir) {
  return internal::ListImageFiles(dir).empty() && !ListClipEntries(dir).empty();
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

SensorDescription DataSensorDescription(const SensorInfo& info) {
  if (info.description) return *info.description;
  SensorDescription d = BuiltInSensorDescription(info.kind);
  d.channels = info.channels;
  d.pixel_pitch_m = info.pixel_pitch_m;
  d.normalization_scale = info.normalization_scale > 0 ? info.normalization_scale
                                                       : DefaultNormalizationScale(info.kind);
  return d;
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

bool IsVideoFileName(const std::string& path) {
  const std::string extension = internal::ToLower(fs::path(path).extension().string());
  for (const char* known : {".avi", ".mp4", ".mkv", ".mov", ".m4v"}) {
    if (extension == known) return true;
  }
  return false;
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
      if (info.reference.empty() || info.reference.front() == '/') {
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
      dataset.sensors_[kind] = SensorData{info, std::move(reference), info};
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
    const bool clip_set = folders.empty() && IsClipSetFolder(dir);
    if (clip_set) dataset.OpenClips(options);
    if (folders.empty() && !clip_set) folders.emplace_back("", options.sensor);
    for (const auto& [subdir, known_kind] : folders) {
      const std::string folder = internal::JoinPath(dir, subdir);
      const std::string folder_name = subdir.empty() ? dir : folder;
      const std::vector<internal::ImageFileEntry> files = internal::ListImageFiles(folder);
      // The reference: reference.<ext>, else options.reference.
      std::string reference_in_folder;  // its name if it lies in `folder`
      const std::string reference_path =
          FindFolderReference(folder, folder_name, files, options.reference,
                              /*anywhere=*/true, &reference_in_folder);
      const SensorKind kind = FolderSensorKind(known_kind, reference_path);
      Image reference = ReadImage(reference_path, SensorEncoding(kind));
      SensorInfo info = UserSensorInfo(kind, reference, options);
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
      dataset.sensors_[kind] = SensorData{info, std::move(reference), info};
    }
  }
  dataset.SortAndIndexFrames();
  dataset.AttachDescription(options, /*folder=*/true);
  if (!dataset.clips_.empty()) {
    const std::string clips_path = internal::JoinPath(dir, kClipsFile);
    if (internal::IsRegularFile(clips_path)) dataset.AttachClipSplits(clips_path);
  }
  std::string labels_path = options.labels;
  if (labels_path.empty()) {
    const std::string default_path = internal::JoinPath(dir, kLabelsFile);
    if (internal::IsRegularFile(default_path)) labels_path = default_path;
  }
  if (!labels_path.empty()) dataset.AttachLabels(labels_path, false);
  std::string tools_path = options.tools;
  if (tools_path.empty()) {
    const std::string default_path = internal::JoinPath(dir, kToolsFile);
    if (internal::IsRegularFile(default_path)) tools_path = default_path;
  }
  if (!tools_path.empty()) dataset.AttachTools(tools_path);
  if (filter_sensor) dataset.KeepOnlySensor(*options.sensor);
  return dataset;
}

Dataset Dataset::OpenVideo(const std::string& path, const OpenOptions& options) {
  CheckOpenOptions(options);
  CheckVideoSensor(options, path);
  if (!internal::IsRegularFile(path)) {
    throw DatasetError(path + ": expected a video file, got no such file");
  }
  const std::size_t reference_index = static_cast<std::size_t>(options.reference_index);
  Image reference;
  auto video = std::make_shared<internal::VideoReader>(path, reference_index, &reference,
                                                       internal::VideoReader::Options());
  Dataset dataset;
  dataset.root_ = path;
  dataset.source_ = path;
  const std::string name = internal::BaseName(path);
  SensorInfo info = UserSensorInfo(SensorKind::kGelSlim, reference, options);
  info.reference = name + "#" + VideoFrameId(reference_index);
  dataset.sensors_[info.kind] = SensorData{info, std::move(reference), info};
  // Ids are zero-padded, so the frames come out sorted.
  AppendVideoFrames(name, "", -1, video->num_frames(), reference_index, &dataset.frames_);
  dataset.video_ = std::move(video);
  dataset.AttachDescription(options, /*folder=*/false);
  if (!options.labels.empty()) dataset.AttachLabels(options.labels, false);
  if (!options.tools.empty()) dataset.AttachTools(options.tools);
  return dataset;
}

void Dataset::OpenClips(const OpenOptions& options) {
  const std::vector<ClipEntry> entries = ListClipEntries(root_);
  const auto budget = std::make_shared<internal::VideoDecoderBudget>(kMaxOpenVideoClips);
  std::optional<SensorInfo> shared;  // the first clip's kind and shape, which all share
  for (const ClipEntry& entry : entries) {
    const int clip_index = static_cast<int>(clips_.size());
    const std::string clip_path = internal::JoinPath(root_, entry.file_name);
    ClipInfo clip;
    clip.name = entry.name;
    clip.path = entry.file_name;
    clip.video = entry.video;
    Image reference;
    SensorKind kind = SensorKind::kGelSlim;
    std::shared_ptr<internal::VideoReader> video;
    std::vector<FrameRecord> frames;
    if (entry.video) {
      CheckVideoSensor(options, clip_path);
      const std::size_t reference_index = static_cast<std::size_t>(options.reference_index);
      internal::VideoReader::Options video_options;
      video_options.budget = budget;
      video = std::make_shared<internal::VideoReader>(clip_path, reference_index, &reference,
                                                      video_options);
      clip.reference = entry.file_name + "#" + VideoFrameId(reference_index);
      AppendVideoFrames(entry.file_name, entry.name + "/", clip_index, video->num_frames(),
                        reference_index, &frames);
    } else {
      std::string in_folder;
      const std::string reference_path =
          FindFolderReference(clip_path, clip_path, internal::ListImageFiles(clip_path),
                              options.reference, /*anywhere=*/false, &in_folder);
      kind = FolderSensorKind(options.sensor, reference_path);
      reference = ReadImage(reference_path, SensorEncoding(kind));
      clip.reference = internal::JoinPath(entry.file_name, in_folder);
      bool found_clean = false;
      ListSensorFrames(root_, entry.file_name, kind, in_folder, /*with_clean=*/true, &frames,
                       &found_clean);
      has_clean_ = has_clean_ || found_clean;
      for (FrameRecord& record : frames) {
        record.id = entry.name + "/" + record.id;
        record.clip = clip_index;
      }
    }
    const SensorInfo info = UserSensorInfo(kind, reference, options);
    if (!shared) {
      shared = info;
    } else if (info.kind != shared->kind || info.rows != shared->rows ||
               info.cols != shared->cols || info.channels != shared->channels) {
      throw DatasetError(clip_path + ": clip '" + entry.name + "': expected " +
                         ToString(shared->kind) + " frames of " +
                         ShapeText(shared->rows, shared->cols, shared->channels) +
                         " (rows x cols x channels, like clip '" + clips_.front().name +
                         "'), got " + ToString(info.kind) + " frames of " +
                         ShapeText(info.rows, info.cols, info.channels));
    }
    frames_.insert(frames_.end(), std::make_move_iterator(frames.begin()),
                   std::make_move_iterator(frames.end()));
    clips_.push_back(std::move(clip));
    clip_references_.push_back(std::move(reference));
    clip_videos_.push_back(std::move(video));
  }
  // The sensor's own reference stays empty: each clip has its own (FrameReference).
  sensors_[shared->kind] = SensorData{*shared, Image(), *shared};
}

void Dataset::AttachClipSplits(const std::string& clips_path) {
  clips_path_ = clips_path;
  std::map<std::string, std::size_t> by_name;
  for (std::size_t k = 0; k < clips_.size(); ++k) by_name[clips_[k].name] = k;
  for (const internal::ClipSplitRow& row :
       internal::ParseClipsCsv(ReadFile(clips_path), clips_path)) {
    const auto it = by_name.find(row.clip);
    if (it == by_name.end()) {
      throw DatasetError(clips_path + ":" + std::to_string(row.line) +
                         ": field 'clip': expected the name of a clip of " + root_ + ", got '" +
                         EscapedExcerpt(row.clip) + "' (no such subfolder or video)");
    }
    clips_[it->second].split = row.split;
  }
  for (FrameRecord& record : frames_) {
    if (record.clip >= 0 && clips_[record.clip].split) record.split = *clips_[record.clip].split;
  }
}

void Dataset::AttachDescription(const OpenOptions& options, bool folder) {
  for (auto& entry : sensors_) entry.second.raw = entry.second.info;
  std::string path = options.sensor_file;
  if (path.empty() && folder) {
    const std::string default_path = internal::JoinPath(root_, kSensorFile);
    if (internal::IsRegularFile(default_path)) path = default_path;
  }
  if (path.empty()) return;
  SensorDescription description;
  try {
    description = ReadSensorDescriptionFile(path);
  } catch (const SensorDescriptionError& e) {
    throw DatasetError(e.what());
  }
  const auto it = sensors_.find(description.kind);
  if (it == sensors_.end()) {
    std::string present;
    for (const auto& entry : sensors_) {
      present += (present.empty() ? "" : " or ") + std::string("\"") +
                 SensorKindDescriptionName(entry.first) + "\" (" + ToString(entry.first) + ")";
    }
    throw DatasetError(path + ": field 'kind': expected the kind of " + root_ + "'s frames, " +
                       present + ", got \"" + SensorKindDescriptionName(description.kind) + "\"");
  }
  SensorData& data = it->second;
  SensorInfo& info = data.info;
  const int raw_channels = info.channels;
  if (!(description.channels == raw_channels || (description.channels == 1 && raw_channels == 3))) {
    throw DatasetError(path + ": field 'channels': expected " + std::to_string(raw_channels) +
                       (raw_channels == 3 ? " (or 1 for luma)" : "") + ", as " + root_ +
                       "'s frames have, got " + std::to_string(description.channels));
  }
  int rows = 0, cols = 0;
  try {
    GeometryOutputSize(description, info.rows, info.cols, path, &rows, &cols);
  } catch (const SensorDescriptionError& e) {
    throw DatasetError(e.what());
  }
  // A pitch or scale given twice must agree: which one the user meant cannot be guessed.
  auto agree = [&](double other, double own, const std::string& field, const std::string& where) {
    if (other > 0 && std::abs(other / own - 1.0) > 1e-9) {
      throw DatasetError(path + ": field '" + field + "': " + where + " gives " +
                         internal::FormatDoubleShort(other) + ", the description " +
                         internal::FormatDoubleShort(own) + " (give it once)");
    }
  };
  agree(options.pixel_pitch_m * 1e3, description.pixel_pitch_m * 1e3, "pixel_pitch_mm",
        "--pixel-pitch-mm (OpenOptions::pixel_pitch_m)");
  if (has_metadata_) {
    agree(info.pixel_pitch_m * 1e3, description.pixel_pitch_m * 1e3, "pixel_pitch_mm",
          metadata_path_);
    agree(info.normalization_scale, description.normalization_scale, "normalization_scale",
          metadata_path_);
  }
  info.rows = rows;
  info.cols = cols;
  info.channels = description.channels;
  info.pixel_pitch_m = description.pixel_pitch_m;
  info.normalization_scale = description.normalization_scale;
  info.description = description;
  info.description_path = path;
  description_path_ = path;
  const std::string reference_where = info.reference.empty() ? root_ : info.reference;
  if (!data.reference.empty()) data.reference = Describe(data.reference, it->first, reference_where);
  for (std::size_t k = 0; k < clip_references_.size(); ++k) {
    clip_references_[k] = Describe(clip_references_[k], it->first, clips_[k].reference);
  }
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
    if (record.clip >= 0 && clips_[record.clip].split && *clips_[record.clip].split != row.split) {
      const ClipInfo& clip = clips_[record.clip];
      throw DatasetError(where + "field 'split': expected '" + ToString(*clip.split) +
                         "' (clip '" + clip.name + "' is " + ToString(*clip.split) + " in " +
                         clips_path_ + "), got '" + ToString(row.split) + "'");
    }
    record.label = row.label;
    record.split = row.split;
  }
}

void Dataset::AttachTools(const std::string& tools_path) {
  tools_path_ = tools_path;
  for (const internal::ToolSymmetryRow& row :
       internal::ParseToolsCsv(ReadFile(tools_path), tools_path)) {
    bool built_in = false;
    const int builtin_order = SymmetryOrderOfTool(row.tool, &built_in);
    if (built_in && builtin_order != row.symmetry_order) {
      throw DatasetError(tools_path + ":" + std::to_string(row.line) +
                         ": field 'symmetry_order': tool '" + row.tool +
                         "' is a built-in tool of symmetry order " + std::to_string(builtin_order) +
                         ", got " + std::to_string(row.symmetry_order));
    }
    tool_symmetries_[row.tool] = row.symmetry_order;
  }
}

int Dataset::ToolSymmetryOrder(const std::string& tool, bool* known) const {
  return SymmetryOrderOfTool(tool, tool_symmetries_, known);
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

const Image& Dataset::Reference(SensorKind kind) const {
  const SensorData& data = sensor_data(kind);
  if (!clips_.empty()) {
    throw DatasetError(root_ + ": a set of " + std::to_string(clips_.size()) +
                       " clips has one reference per clip: expected the reference of a frame "
                       "(Dataset::FrameReference), got a request for the " + ToString(kind) +
                       " sensor's");
  }
  return data.reference;
}

const Image& Dataset::FrameReference(std::size_t index) const {
  if (index >= frames_.size()) {
    throw std::out_of_range("Dataset::FrameReference: index " + std::to_string(index) +
                            " >= number of frames " + std::to_string(frames_.size()));
  }
  const FrameRecord& record = frames_[index];
  if (record.clip >= 0) return clip_references_[static_cast<std::size_t>(record.clip)];
  return sensor_data(record.sensor).reference;
}

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
  const FrameRecord& record = frames_[index];
  if (record.video_frame >= 0) {
    internal::VideoReader& video =
        record.clip >= 0 ? *clip_videos_[static_cast<std::size_t>(record.clip)] : *video_;
    return Describe(video.Frame(static_cast<std::size_t>(record.video_frame)), record.sensor,
                    internal::JoinPath(root_, record.path));
  }
  const SensorInfo& info = sensor_data(record.sensor).raw;
  const std::string path = internal::JoinPath(root_, record.path);
  CheckFrameHeader(path, info, record.sensor);
  Image image = ReadImage(path, info.encoding);
  if (image.rows != info.rows || image.cols != info.cols || image.channels != info.channels) {
    throw DatasetError(path + ": expected a " + ShapeText(info.rows, info.cols, info.channels) +
                       " frame (the " + ToString(record.sensor) + " reference's shape), got " +
                       image.ShapeString());
  }
  return Describe(std::move(image), record.sensor, path);
}

Image Dataset::Describe(Image raw, SensorKind sensor, const std::string& path) const {
  const SensorInfo& info = sensor_info(sensor);
  if (!info.description) return raw;
  try {
    return ApplySensorGeometry(raw, *info.description, info.description_path);
  } catch (const SensorDescriptionError& e) {
    throw DatasetError(path + ": " + e.what());
  }
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
  const SensorInfo& info = sensor_data(record.sensor).raw;
  const std::string path = internal::JoinPath(root_, record.clean_path);
  CheckFrameHeader(path, info, record.sensor);
  Image image = ReadImage(path, info.encoding);
  if (image.rows != info.rows || image.cols != info.cols || image.channels != info.channels) {
    throw DatasetError(path + ": expected a " + ShapeText(info.rows, info.cols, info.channels) +
                       " clean frame, got " + image.ShapeString());
  }
  return Describe(std::move(image), record.sensor, path);
}

void Dataset::ValidateAllFrames() const {
  for (std::size_t i = 0; i < frames_.size(); ++i) {
    LoadFrame(i);
    if (!frames_[i].clean_path.empty()) LoadCleanFrame(i);
  }
}

std::vector<std::string> Dataset::Files() const {
  std::set<std::string> files;
  if (video_) {
    files.insert(root_);
  } else {
    for (const auto& entry : sensors_) {
      if (!entry.second.info.reference.empty()) {
        files.insert(internal::JoinPath(root_, entry.second.info.reference));
      }
    }
    for (const ClipInfo& clip : clips_) {
      files.insert(internal::JoinPath(root_, clip.video ? clip.path : clip.reference));
    }
    for (const FrameRecord& record : frames_) {
      if (record.video_frame >= 0) continue;  // its video is listed with its clip
      files.insert(internal::JoinPath(root_, record.path));
      if (!record.clean_path.empty()) {
        files.insert(internal::JoinPath(root_, record.clean_path));
      }
    }
  }
  if (!metadata_path_.empty()) files.insert(metadata_path_);
  if (!clips_path_.empty()) files.insert(clips_path_);
  if (!description_path_.empty()) files.insert(description_path_);
  if (!labels_path_.empty()) files.insert(labels_path_);
  if (!tools_path_.empty()) files.insert(tools_path_);
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
