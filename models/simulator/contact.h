// Copyright 2026 The tactfunc Authors.
//
// Contact: a tool pressed into a sensor at a pose to a depth. The one in-memory type
// for that in tactfunc: the simulator renders a Contact (contact_simulator.h), and a
// dataset's pose label (estimation/data/dataset.h, PoseLabel) is one.
#ifndef TACTFUNC_MODELS_SIMULATOR_CONTACT_H_
#define TACTFUNC_MODELS_SIMULATOR_CONTACT_H_

#include <string>

#include "models/core/se2.h"

namespace tactfunc {

// A tool pressed into one sensor at sensor_T_object.
struct Contact {
  std::string tool;  // a tool name (ToolNames() for the simulator)
  // Pose of the tool (object) frame in the sensor frame (models/core/sensor.h):
  // translation in metres, yaw in radians (CCW), normalised into (-pi, pi].
  SE2d sensor_T_object;
  double depth_m = 0;  // press depth beyond first touch, metres (>= 0)
};

// Exact equality of every field (the pose's x, y and yaw compared as doubles).
inline bool operator==(const Contact& a, const Contact& b) {
  return a.tool == b.tool && a.sensor_T_object.x() == b.sensor_T_object.x() &&
         a.sensor_T_object.y() == b.sensor_T_object.y() &&
         a.sensor_T_object.yaw() == b.sensor_T_object.yaw() && a.depth_m == b.depth_m;
}
inline bool operator!=(const Contact& a, const Contact& b) { return !(a == b); }

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_SIMULATOR_CONTACT_H_
