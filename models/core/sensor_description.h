// Copyright 2026 The tactfunc Authors.
//
// A sensor description: the facts about a vision-based tactile sensor that turn its raw
// camera frames into the frames tactfunc models, as data rather than code. A user's
// GelSight Wedge, DIGIT or TacTip is described by a small JSON file (sensor.json in a
// dataset folder, or --sensor-file); the Soft Bubble and the GelSlim are the two
// built-in descriptions (BuiltInSensorDescription), which change nothing in how their
// frames are read.
//
// The file (docs/DATASET_FORMAT.md, "Sensor description"):
//
//   {
//     "format": "tactfunc-sensor", "version": 1,      optional; if present exactly these
//     "name": "gelsight_wedge",                       1-64 of [A-Za-z0-9_.-]
//     "kind": "optical",                              "depth" (Soft Bubble processing:
//                                                     16-bit micrometres, reference - frame)
//                                                     or "optical" (8-bit intensity,
//                                                     frame - reference)
//     "channels": 3,                                  depth: 1; optical: 3, or 1 = luma
//     "crop": {"x": 20, "y": 10, "width": 120, "height": 90},        or
//     "perspective": {"corners": [[x, y], [x, y], [x, y], [x, y]],   top-left, top-right,
//                     "rows": 90, "cols": 120},                      bottom-right, bottom-left
//     "working_size": {"rows": 60, "cols": 80},       optional: the trunk's resolution
//     "aspect": "crop",                               "crop" (default), "pad" or "stretch"
//     "pixel_pitch_mm": 0.1245,                       > 0, of the cropped / warped frame
//     "normalization_scale": 0.5,                     > 0, physical units mapping to 1.0
//     "markers": false                                the gel carries markers (recorded)
//   }
//
// Geometry, in the order ApplySensorGeometry applies it to every frame AND to the
// reference (so they are differenced on the same grid):
//   1. crop: the raw pixels [y, y + height) x [x, x + width); or perspective: the
//      quadrilateral of `corners` (in raw pixel-edge coordinates: (0, 0) is the top-left
//      corner of the top-left pixel, (cols, rows) the bottom-right corner of the image)
//      warped onto a rows x cols rectangle (cv::getPerspectiveTransform and
//      cv::warpPerspective, bilinear). A quadrilateral that is an axis-aligned rectangle
//      of those sizes gives the crop of that rectangle (to float rounding). Depth frames are warped
//      mask-aware: value * valid and valid are warped apart, a pixel is valid where at
//      least half its interpolation weight was, and holds their ratio; else NaN.
//   2. aspect (only with working_size): "crop" cuts the centred largest window of the
//      working size's aspect ratio out of step 1's frame, so resizing it to the working
//      size never stretches; "pad" centres the frame in the smallest window of that
//      aspect ratio that holds all of it (nothing is lost, nothing stretched), the border
//      invalid (NaN) on depth frames and 0 on optical ones -- the same border in frame and
//      reference, so their difference is exactly 0 there; "stretch" keeps the frame and
//      lets the resize distort it. A pad or crop of an odd number of pixels puts the extra
//      one at the bottom / right.
//   3. channels 1 on 3-channel optical frames: ITU-R BT.601 luma, 0.299 R + 0.587 G +
//      0.114 B (linear, so the luma of a difference is the difference of the lumas).
// The sensor frame (models/core/sensor.h) and every pose label are those of the frame
// after the geometry: its centre is the origin, pixel_pitch_mm its pitch.
#ifndef TACTFUNC_MODELS_CORE_SENSOR_DESCRIPTION_H_
#define TACTFUNC_MODELS_CORE_SENSOR_DESCRIPTION_H_

#include <array>
#include <stdexcept>
#include <string>
#include <vector>

#include "models/core/image.h"
#include "models/core/sensor.h"

namespace tactfunc {

// A bad sensor description (its message names the file, the field, what was expected
// and what was found) or a geometry that does not fit a frame.
class SensorDescriptionError : public std::runtime_error {
 public:
  explicit SensorDescriptionError(const std::string& message) : std::runtime_error(message) {}
};

struct SensorDescription {
  std::string name;
  // kSoftBubble = "depth", kGelSlim = "optical": the processing path of its frames.
  SensorKind kind = SensorKind::kSoftBubble;
  int channels = 1;  // after the geometry: depth 1; optical 3 or 1 (luma)

  enum class Geometry { kNone, kCrop, kPerspective };
  Geometry geometry = Geometry::kNone;
  // kCrop: top-left pixel (x = column, y = row) and size, in raw pixels.
  int crop_x = 0, crop_y = 0, crop_width = 0, crop_height = 0;
  // kPerspective: (x, y) of the top-left, top-right, bottom-right and bottom-left
  // corners in raw pixel-edge coordinates, and the rectangle they are warped onto.
  std::array<std::array<double, 2>, 4> corners{};
  int warp_rows = 0, warp_cols = 0;

  // The trunk's working resolution; both 0 = not set (the trainer's preset decides).
  int working_rows = 0, working_cols = 0;
  enum class Aspect { kCrop, kPad, kStretch };
  Aspect aspect = Aspect::kCrop;

  double pixel_pitch_m = 0;        // metres per pixel after the geometry; 0 = unknown
  double normalization_scale = 0;  // physical units mapping to 1.0, > 0
  bool markers = false;            // informational
};

// The Soft Bubble and GelSlim as tactfunc has always read them: no geometry, no working
// size, pitch unknown (0: a user folder's pitch comes from --pixel-pitch-mm, a
// simulated dataset's from its dataset.json), scale DefaultNormalizationScale's
// (0.01 m, 0.5), channels 1 / 3, markers false / true.
SensorDescription BuiltInSensorDescription(SensorKind kind);

// "depth" / "optical".
const char* SensorKindDescriptionName(SensorKind kind);
// "crop" / "pad" / "stretch".
const char* AspectName(SensorDescription::Aspect aspect);

// Parses the JSON text of a description; `source` (the file) starts every message.
// Every field is validated; unknown fields are refused (a typo must not pass for a
// default). Throws SensorDescriptionError. allow_unknown_pitch: also accept
// "pixel_pitch_mm": 0 (pitch unknown), as SensorDescriptionToJson writes it for a built-in
// description in a model file; a user's file must give the pitch.
SensorDescription ParseSensorDescription(const std::string& text, const std::string& source,
                                         bool allow_unknown_pitch = false);
// Reads and parses the file at `path`. Throws SensorDescriptionError.
SensorDescription ReadSensorDescriptionFile(const std::string& path);
// The description as JSON text in the file format above (ParseSensorDescription reads it
// back to an equal description, with allow_unknown_pitch for an unknown pitch).
std::string SensorDescriptionToJson(const SensorDescription& description);
// Two descriptions describe the same frames if every field but name and markers is
// equal (the pitch to 1e-9 relative, as it round-trips through millimetres).
bool SameFrames(const SensorDescription& a, const SensorDescription& b);
// The fields in which `a` and `b` differ (SameFrames's fields), each as
// "field: <a's value> vs <b's value>"; empty if SameFrames.
std::vector<std::string> FrameDifferences(const SensorDescription& a, const SensorDescription& b);
// One-line summaries of the description for `tactfunc info`, e.g.
//   "gelsight_wedge: optical, 3 channels, perspective [[12,8],...] -> 90x120, working
//    60x80 (aspect crop), pitch 0.1245 mm, scale 0.5, no markers"
std::string DescribeSensor(const SensorDescription& description);
// The geometry alone: "none", "crop x=.. y=.. 120x90 (rows x cols)" or "perspective ...".
std::string DescribeGeometry(const SensorDescription& description);

// The size (rows x cols) of a raw_rows x raw_cols frame after the geometry (steps 1 and
// 2 above). Throws SensorDescriptionError naming `source` and the field if the crop
// rectangle or a corner lies outside the frame, or if the result is empty.
void GeometryOutputSize(const SensorDescription& description, int raw_rows, int raw_cols,
                        const std::string& source, int* rows, int* cols);
// Applies the geometry and the luma conversion (steps 1-3) to a raw frame of the
// description's kind (1-channel depth in metres with NaN = invalid, or 1/3-channel
// intensity). No geometry, no aspect crop and no luma: returns `raw` unchanged. Throws
// SensorDescriptionError (naming `source`) as GeometryOutputSize does, and for a frame
// whose channel count the description cannot give (3 channels wanted from 1).
Image ApplySensorGeometry(const Image& raw, const SensorDescription& description,
                          const std::string& source);

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_CORE_SENSOR_DESCRIPTION_H_
