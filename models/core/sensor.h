// Copyright 2026 The tactfunc Authors.
//
// The two vision-based tactile sensors tactfunc models, and the sensor frame.
//
// Sensor frame (both sensors, documented once here): the origin is the centre of the
// image; x points right (increasing column), y points up (decreasing row), z points
// out of the sensing surface towards the viewer, so yaw is counter-clockwise as the
// picture is viewed. A pixel (row r, col c) of a rows x cols image with pitch p metres
// per pixel has its centre at
//   x = (c + 0.5 - cols / 2) * p,   y = (rows / 2 - r - 0.5) * p.
// A tool's pose in this frame is sensor_T_object = (x, y, yaw) (models/core/se2.h).
#ifndef TACTFUNC_MODELS_CORE_SENSOR_H_
#define TACTFUNC_MODELS_CORE_SENSOR_H_

#include <string>

namespace tactfunc {

enum class SensorKind {
  // Soft Bubble: an air-filled latex membrane seen from inside by a time-of-flight
  // depth camera. One channel, depth in metres, NaN where the camera dropped out.
  kSoftBubble,
  // GelSlim 3.0: an elastomer gel with an opaque painted skin and a printed marker
  // grid, lit by LEDs and seen by an RGB camera. Three channels, intensity in [0, 1].
  kGelSlim,
};

// "bubble" / "gelslim": the names used on the command line, in labels.csv and in
// folder names.
const char* ToString(SensorKind kind);
// Parses "bubble" or "gelslim" (also "soft_bubble", "gel_slim"). Returns false and
// leaves *kind untouched for anything else.
bool SensorKindFromString(const std::string& name, SensorKind* kind);
// Number of image channels the sensor produces: 1 for bubble, 3 for gelslim.
int SensorChannels(SensorKind kind);

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_CORE_SENSOR_H_
