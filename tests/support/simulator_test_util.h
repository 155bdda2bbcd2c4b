// Copyright 2026 The tactfunc Authors.
//
// One contact simulator for a whole suite (building its references takes a few ms) and
// contacts written out by hand, for the simulator's tests.
#ifndef TACTFUNC_TESTS_SUPPORT_SIMULATOR_TEST_UTIL_H_
#define TACTFUNC_TESTS_SUPPORT_SIMULATOR_TEST_UTIL_H_

#include <string>

#include "models/simulator/contact.h"
#include "models/simulator/contact_simulator.h"

namespace tactfunc::testing_util {

inline const ContactSimulator& Simulator() {
  static const ContactSimulator simulator;
  return simulator;
}

inline Contact MakeContact(const std::string& tool, double x, double y, double yaw,
                           double depth) {
  Contact contact;
  contact.tool = tool;
  contact.sensor_T_object = SE2d::FromXYYaw(x, y, yaw);
  contact.depth_m = depth;
  return contact;
}

}  // namespace tactfunc::testing_util

#endif  // TACTFUNC_TESTS_SUPPORT_SIMULATOR_TEST_UTIL_H_
