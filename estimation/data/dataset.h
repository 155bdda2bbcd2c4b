// Copyright 2026 The tactfunc Authors.
//
// Tactile datasets: a folder (or a video) of sensor frames, one reference frame per
// sensor (the undeformed sensor) -- or, for a set of recordings ("clips"), one per
// clip -- and optional pose labels.
//
// The folder format is specified in docs/DATASET_FORMAT.md; in short:
//
//   DIR/dataset.json            metadata, written last (its presence marks a complete
//                               dataset written by DatasetWriter)
//   DIR/labels.csv              frame,sensor,tool,x_m,y_m,yaw_rad,depth_m,split
//   DIR/bubble/reference.png    16-bit PNG, micrometres of depth, 0 = invalid pixel
//   DIR/bubble/000000.png ...
//   DIR/bubble/clean/000000.png optional noise-free frames (simulated data)
//   DIR/gelslim/reference.png   8-bit RGB PNG
//   DIR/gelslim/000000.png ...
//   DIR/sensor.json             optional: a sensor description (models/core/
//                               sensor_description.h) cropping / warping one sensor's frames
//
// Frames of the two sensors taken at the same time share their id (the file stem).
// Dataset::Open also reads folders that users bring without metadata (a flat folder
// of images, bubble/ and gelslim/ subfolders, or a set of clips: subfolders of images
// and/or video files, each with its own reference) and Dataset::OpenVideo reads a
// video; see Dataset::Open for the rules.
//
// Frames are decoded lazily by LoadFrame: images from disk, video frames from the
// video, which is read through once when opened and then decoded on demand, so the
// memory a dataset takes does not grow with the length of its videos. Open validates
// the metadata, the references and every labels.csv line; a frame's own size and bit
// depth are validated when it is loaded (call ValidateAllFrames to check them all up
// front). A Dataset is immutable after Open: its const methods, LoadFrame included,
// may be called from several threads.
//
// Every bad input raises DatasetError (estimation/data/image_io.h) with a message naming
// the file, the line and/or field, what was expected and what was found, e.g.
//   labels.csv:17: field 'yaw_rad': expected a finite number in [-3.1416, 3.1416],
//   got '7.2'
#ifndef TACTFUNC_ESTIMATION_DATA_DATASET_H_
#define TACTFUNC_ESTIMATION_DATA_DATASET_H_

#include <cstddef>
#include <cstdint>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "estimation/data/image_io.h"
#include "models/core/image.h"
#include "models/core/sensor.h"
#include "models/core/sensor_description.h"
#include "models/simulator/contact.h"

namespace tactfunc {

namespace internal {
class VideoReader;
}  // namespace internal

enum class Split { kTrain, kTest };
// "train" / "test", as in labels.csv.
const char* ToString(Split split);
// Parses "train" or "test"; returns false and leaves *split untouched otherwise.
bool SplitFromString(const std::string& name, Split* split);

// The label of a frame: the tool, its pose sensor_T_object in the sensor frame
// (models/core/sensor.h) and its press depth when the frame was taken. A label is a
// Contact (models/simulator/contact.h), the same type the simulator renders; ==
// compares every field exactly. Ranges a valid label keeps (IsValidPoseLabel):
//   tool               non-empty, no ',', '"' or line breaks
//   sensor_T_object    x, y finite with |x| <= half the sensor width (cols * pitch / 2)
//                      and |y| <= half its height (rows * pitch / 2) when the pixel
//                      pitch is known, else <= 1 m; yaw finite (SE2d keeps it in
//                      (-pi, pi]; labels.csv accepts [-pi, pi] with 1e-9 slack)
//   depth_m            indentation depth in metres, in [0, 0.1]
using PoseLabel = Contact;

// Checks a label against the ranges above for a sensor of the given size and pitch
// (pitch 0 = unknown). Returns false and sets *error to
// "field '<name>': expected ..., got '<value>'" for the first bad field.
bool IsValidPoseLabel(const PoseLabel& label, int rows, int cols, double pixel_pitch_m,
                      std::string* error);

// The physical scale used when a dataset does not record one (user folders, videos):
// 0.01 m of depth for the bubble, 0.5 of intensity for GelSlim. See
// docs/DATASET_FORMAT.md, "Normalisation".
double DefaultNormalizationScale(SensorKind kind);
// The encoding each sensor uses on disk: depth_u16_um for the bubble, rgb8 for GelSlim.
PixelEncoding SensorEncoding(SensorKind kind);

struct SensorInfo {
  SensorKind kind = SensorKind::kSoftBubble;
  int rows = 0;      // frame height in pixels, > 0
  int cols = 0;      // frame width in pixels, > 0
  int channels = 1;  // 1 for depth; 3 (or 1 for grayscale user data) for rgb8
  PixelEncoding encoding = PixelEncoding::kDepthU16Micrometres;
  double pixel_pitch_m = 0;        // metres per pixel on the sensing surface; 0 = unknown
  double normalization_scale = 0;  // physical units mapping to 1.0 (metres of depth or
                                   // intensity); 0 = unknown (see preprocess.h)
  std::string reference;           // reference image path, relative to Dataset::root();
                                   // "" for a clip set (see ClipInfo::reference)
  // The sensor description the frames were read with (sensor.json or
  // OpenOptions::sensor_file; models/core/sensor_description.h), absent for the built-in
  // reading. With one, rows, cols and channels are those AFTER its geometry (what
  // LoadFrame returns), and pitch and scale are its own.
  std::optional<SensorDescription> description;
  std::string description_path;  // the file it came from, "" without one
};

// The description of a sensor's frames: SensorInfo::description, else the built-in
// description of its kind (BuiltInSensorDescription) with the info's channels, pitch and
// scale (DefaultNormalizationScale if it records none).
SensorDescription DataSensorDescription(const SensorInfo& info);

struct FrameRecord {
  // Frame id = file stem (frames of both sensors taken together share it); in a clip
  // set "<clip>/<stem>" for a folder clip and "<clip>/<index, 6 digits>" for a video
  // clip -- the only ids holding a '/'.
  std::string id;
  SensorKind sensor = SensorKind::kSoftBubble;
  std::string path;                // relative to Dataset::root(); for a video "<file>#<index>"
  std::string clean_path;          // noise-free frame relative to root(), "" if none
  std::optional<PoseLabel> label;  // absent for unlabelled frames
  Split split = Split::kTrain;     // from labels.csv or clips.csv; kTrain when neither says
  int clip = -1;                   // index into Dataset::clips(); -1 outside a clip set
  std::int64_t video_frame = -1;   // a video frame's index in its video (counting every
                                   // frame, the reference included); -1 for images
};

// One recording of a clip set (Dataset::Open): a subfolder of images or a video file.
struct ClipInfo {
  std::string name;       // subfolder name or video file stem; its frame ids start "<name>/"
  std::string path;       // relative to Dataset::root(): the subfolder or the video file
  std::string reference;  // its reference, relative to root(): "<name>/reference.png" or
                          // "<file>#<index, 6 digits>" for a video
  bool video = false;
  std::optional<Split> split;  // from DIR/clips.csv, if the clip is listed there
};

// True if `path` ends in a video extension: .avi .mp4 .mkv .mov .m4v (any case).
bool IsVideoFileName(const std::string& path);

// How Dataset::Open and Dataset::OpenVideo read data without metadata.
struct DatasetOpenOptions {
  // Sensor kind for a folder without dataset.json. Flat folder: the kind of its
  // images (unset = inferred: 16-bit one-channel -> bubble, 8-bit -> gelslim).
  // Folder with dataset.json or bubble/ and gelslim/ subfolders: only that sensor
  // is loaded (unset = all). Video: must be unset or gelslim.
  std::optional<SensorKind> sensor;
  // Reference image for a sensor folder without metadata and without a
  // "reference.<ext>" file: a path relative to the sensor folder (tried first) or
  // to the working directory, or absolute. If the file lies inside the sensor folder
  // it is not also a frame. In a clip set: the file of that name inside each folder
  // clip (only there). Ignored when dataset.json exists and for videos.
  std::string reference;
  // Videos and video clips: the frame used as reference (and left out of the
  // frames). >= 0.
  int reference_index = 0;
  // Pixel pitch in metres for data without metadata; 0 = unknown. >= 0. With a
  // known pitch, label positions are checked against the sensor's extent.
  double pixel_pitch_m = 0;
  // labels.csv to read; "" = DIR/labels.csv if present for folders, none for videos.
  std::string labels;
  // tools.csv declaring the rotational symmetry of the dataset's own tools (header
  // `tool,symmetry_order`); "" = DIR/tools.csv if present for folders, none for videos.
  std::string tools;
  // A sensor description file (models/core/sensor_description.h) for the sensor of its
  // kind: "" = DIR/sensor.json if present for folders, none for videos. Its geometry is
  // applied to that sensor's reference(s) and to every frame LoadFrame returns, its
  // pitch and scale replace the defaults (a pixel_pitch_m or a dataset.json value that
  // disagrees is refused), and labels are in the frame after its geometry.
  std::string sensor_file;
  bool IsValid(std::string* error) const;
};

class Dataset {
 public:
  // Defined outside the class (DatasetOpenOptions) so that it can be a default
  // argument below: GCC rejects a nested struct with member initialisers there.
  using OpenOptions = DatasetOpenOptions;

  // Opens a dataset folder. If DIR/dataset.json exists it is the metadata. Otherwise:
  // if DIR has bubble/ and/or gelslim/ subfolders each is a sensor folder, else DIR
  // itself is one. In a sensor folder without metadata the frames are all *.png,
  // *.jpg and *.jpeg files (any case, hidden files skipped), sorted by name, frame
  // id = stem; the reference is "reference.<ext>" if present, else
  // options.reference, else DatasetError. Pixel pitch and normalisation scale come
  // from the options / DefaultNormalizationScale. labels.csv is optional.
  //
  // A clip set: a folder without dataset.json, without bubble/ or gelslim/ and
  // without images of its own, whose subfolders holding images and video files
  // (IsVideoFileName) are recordings ("clips"), each with its own reference: a
  // folder clip's reference.<ext> (or options.reference inside it), a video clip's
  // frame options.reference_index. Clip name = subfolder name or video stem; frame
  // id = "<clip>/<stem>" or "<clip>/<index, 6 digits>". Every clip must be of the
  // same sensor kind and frame shape. DIR/clips.csv ("clip,split") optionally gives
  // each listed clip's frames their split; a labels.csv row of such a frame must
  // agree. See docs/DATASET_FORMAT.md, "A set of recordings (clips)".
  // Throws DatasetError for any bad input and std::invalid_argument for bad options.
  static Dataset Open(const std::string& dir, const OpenOptions& options = OpenOptions());
  // Opens an AVI/MP4/MKV/MOV (anything cv::VideoCapture reads) as a GelSlim rgb8
  // dataset. Frame ids are "000000", "000001", ... counting every frame of the video;
  // frame options.reference_index is the reference and not a frame. The video is read
  // through once here (counting the frames, checking their size, keeping the
  // reference); LoadFrame decodes frames on demand, so memory does not grow with the
  // video's length.
  static Dataset OpenVideo(const std::string& path, const OpenOptions& options = OpenOptions());

  // The dataset folder (or the video file), as given to Open.
  const std::string& root() const { return root_; }
  // The sensors present, in enum order.
  std::vector<SensorKind> sensors() const;
  bool has_sensor(SensorKind kind) const;
  // Throws DatasetError if the sensor is absent.
  const SensorInfo& sensor_info(SensorKind kind) const;
  // Sorted by (id, sensor).
  const std::vector<FrameRecord>& frames() const { return frames_; }
  // Indices into frames() of one sensor's frames, optionally of one split, in order.
  std::vector<std::size_t> FrameIndices(SensorKind sensor,
                                        std::optional<Split> split = std::nullopt) const;
  // The index of frame (id, sensor) in frames(), or nullopt.
  std::optional<std::size_t> FindFrame(const std::string& id, SensorKind sensor) const;

  // Decodes frame `index` in physical units (file_io.h). Throws std::out_of_range for
  // a bad index and DatasetError if the file is missing, corrupt, or not of the
  // sensor's size, channel count or bit depth.
  Image LoadFrame(std::size_t index) const;
  // The noise-free version of frame `index`; throws DatasetError if it has none.
  Image LoadCleanFrame(std::size_t index) const;
  // Loads every frame (and clean frame) once; throws on the first bad one.
  void ValidateAllFrames() const;
  // The reference (undeformed) frame of a sensor, in physical units. Throws
  // DatasetError if the sensor is absent, and for a clip set, whose clips each have
  // their own reference (use FrameReference).
  const Image& Reference(SensorKind sensor) const;
  // The reference frame `index` is differenced against: its clip's reference in a
  // clip set, else its sensor's reference. Throws std::out_of_range for a bad index.
  const Image& FrameReference(std::size_t index) const;
  // The clips of a clip set, sorted by name (FrameRecord::clip indexes them); empty
  // for any other dataset.
  const std::vector<ClipInfo>& clips() const { return clips_; }

  // Bytes of every file the dataset consists of: frames, references, clean frames,
  // dataset.json, labels.csv and clips.csv (for a video: the video file and labels
  // file; for a video clip: its video file).
  std::uint64_t BytesOnDisk() const;
  // The rotational symmetry order n of `tool` (the tool looks the same at yaw and yaw +
  // 2 pi / n; 0 = no observable yaw): as tools.csv declares it, else the built-in tool's
  // (SymmetryOrderOfTool), else 1. *known (optional): declared or built in.
  int ToolSymmetryOrder(const std::string& tool, bool* known = nullptr) const;
  // The symmetry orders tools.csv declares (empty without one).
  const std::map<std::string, int>& tool_symmetries() const { return tool_symmetries_; }

  // The paths of those files (joined to root(), sorted): what a command writing
  // outputs must not overwrite.
  std::vector<std::string> Files() const;
  // True if any frame has a clean version.
  bool has_clean() const { return has_clean_; }
  // True if the folder had a dataset.json.
  bool has_metadata() const { return has_metadata_; }
  // dataset.json's "source" ("" without metadata; the video path for videos).
  const std::string& source() const { return source_; }
  // dataset.json's "meta" object as JSON text ("{}" if none).
  const std::string& meta_json() const { return meta_json_; }

 private:
  struct SensorData {
    SensorInfo info;
    Image reference;
    // The frames as they are on disk (shape and encoding), which LoadFrame checks before
    // it applies info.description; equal to info without a description.
    SensorInfo raw;
  };
  Dataset() = default;
  const SensorData& sensor_data(SensorKind kind) const;
  void SortAndIndexFrames();
  void AttachLabels(const std::string& labels_path, bool ignore_absent_sensors);
  void AttachTools(const std::string& tools_path);
  void KeepOnlySensor(SensorKind kind);
  void OpenClips(const OpenOptions& options);
  void AttachClipSplits(const std::string& clips_path);
  // Reads the description (options.sensor_file, else DIR/sensor.json for a folder) and
  // applies it to the sensor of its kind: references, rows/cols/channels, pitch, scale.
  void AttachDescription(const OpenOptions& options, bool folder);
  // A raw frame of `sensor` (or its reference) through the sensor's description, if any.
  Image Describe(Image raw, SensorKind sensor, const std::string& path) const;

  std::string root_;
  std::map<SensorKind, SensorData> sensors_;
  std::vector<FrameRecord> frames_;
  bool has_clean_ = false;
  bool has_metadata_ = false;
  std::string source_;
  std::string meta_json_ = "{}";
  std::string labels_path_;  // absolute or relative-to-cwd path of labels.csv, "" if none
  std::string tools_path_;   // tools.csv, "" if none
  std::map<std::string, int> tool_symmetries_;
  std::string metadata_path_;
  std::string clips_path_;  // DIR/clips.csv of a clip set, "" if none
  std::string description_path_;  // the sensor description read, "" if none
  // A video dataset's decoder (shared by copies; thread-safe), null otherwise.
  std::shared_ptr<internal::VideoReader> video_;
  // A clip set: clips_[k]'s reference and, for a video clip, its decoder.
  std::vector<ClipInfo> clips_;
  std::vector<Image> clip_references_;
  std::vector<std::shared_ptr<internal::VideoReader>> clip_videos_;
};

// Writes a dataset in the folder format above. Frames are encoded and written as they
// are added (each file atomically); Finish writes labels.csv and then dataset.json,
// which marks the dataset complete. Until Finish, the folder reads as a user folder
// without metadata. AddSensor and AddFrame may be called from several threads at once.
class DatasetWriter {
 public:
  struct Options {
    // zlib level of the PNG files, in [0, 9]. 1 is the fast choice (measured: about
    // as small as 9 for smooth tactile frames).
    int png_compression = 1;
    // dataset.json's "source": free text naming what produced the data.
    std::string source = "tactfunc";
    // dataset.json's "meta": a JSON object as text (e.g. simulator settings).
    std::string meta_json = "{}";
    // If false (default) the constructor refuses a folder that already holds dataset
    // content (dataset.json, labels.csv, bubble/ or gelslim/). If true that content is
    // deleted first (dataset.json first, so a half-overwritten folder never looks
    // complete); other files in the folder are left alone.
    bool overwrite = false;
    bool IsValid(std::string* error) const;
  };

  // Creates `dir` (and parents). Throws std::invalid_argument for invalid options,
  // DatasetError if `dir` holds a dataset and !options.overwrite, std::runtime_error
  // if it cannot be created.
  DatasetWriter(const std::string& dir, const Options& options);
  ~DatasetWriter();
  DatasetWriter(const DatasetWriter&) = delete;
  DatasetWriter& operator=(const DatasetWriter&) = delete;

  // Declares a sensor and writes its reference frame to "<sensor>/reference.png"
  // (info.reference is ignored and set to that). info must be consistent: rows, cols
  // > 0; encoding == SensorEncoding(kind); channels 1 for depth, 1 or 3 for rgb8;
  // pitch and scale >= 0; reference of shape rows x cols x channels. Throws
  // DatasetError otherwise or if the sensor was already added.
  void AddSensor(const SensorInfo& info, const Image& reference);
  // Writes "<sensor>/<id>.png" (and "<sensor>/clean/<id>.png" if clean != nullptr)
  // and records the label and split. id: 1-64 characters from [A-Za-z0-9_.-], not
  // starting with '.', not "reference". Throws DatasetError for a bad id, an
  // unknown sensor, a duplicate (id, sensor), a frame of the wrong shape, a value
  // that cannot be encoded or a label out of range (IsValidPoseLabel).
  void AddFrame(const std::string& id, SensorKind sensor, const Image& frame, const Image* clean,
                const std::optional<PoseLabel>& label, Split split);
  // Writes labels.csv (one row per frame, sorted by (id, sensor); unlabelled frames
  // get a row with empty pose fields to carry their split) and then dataset.json,
  // both atomically. Further calls throw std::logic_error.
  void Finish();

  std::size_t num_frames() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_DATA_DATASET_H_
