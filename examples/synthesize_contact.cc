// Copyright 2026 The tactfunc Authors.
//
// Synthesise one paired tactile contact: a tool pressed into a Soft Bubble and a
// GelSlim at the same pose (models/simulator/contact_simulator.h, docs/SIMULATOR.md).
//
// The tool's face h(u, v) is placed at sensor_T_object = (x, y, yaw) and pressed
// `depth` beyond first touch. The rigid interference
//   s(p) = max(0, h(object_T_sensor p) + z0(p) - m + depth)
// is wrapped by an elastic surface w >= s of least energy
//   E(w) = integral |grad w|^2 / 2 + w^2 / (2 l^2)
// (a tensioned membrane on a gas spring, l = 15 mm, for the bubble; a gel layer on
// acrylic, l = 1 mm, for the GelSlim). The bubble reports depth d0 - w seen by a ToF
// camera; the GelSlim reports the gel's shading under three coloured LEDs, with its
// marker grid carried sideways by -kappa grad w.
//
// The example draws one contact for the `lines2_60` tool with a fixed seed, renders
// both sensors and reports, per sensor, the contact area and the peak change before
// (no contact: the reference frame) and after the press.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <vector>

#include "models/simulator/contact_simulator.h"

namespace {

constexpr double kPi = 3.14159265358979323846;

// Pixels that changed by more than `threshold` from the reference (summed over
// channels, absolute), and the largest change.
void Measure(const tactfunc::Image& frame, const tactfunc::Image& reference,
             double threshold, int* area, double* peak) {
  *area = 0;
  *peak = 0.0;
  for (std::size_t p = 0; p < frame.pixels(); ++p) {
    double change = 0.0;
    for (int k = 0; k < frame.channels; ++k) {
      const std::size_t i = p * frame.channels + k;
      change += std::abs(frame.data[i] - reference.data[i]);
    }
    *area += change > threshold;
    *peak = std::max(*peak, change);
  }
}

}  // namespace

int main() {
  using tactfunc::SensorKind;
  const tactfunc::ContactSimulator simulator;
  const tactfunc::PairedContact contact = simulator.SamplePairedContact("lines2_60", 2026);
  std::printf("tool %s at x = %.2f mm, y = %.2f mm, yaw = %.1f deg; press %.2f mm (bubble), "
              "%.2f mm (gelslim)\n",
              contact.bubble.tool.c_str(), 1e3 * contact.bubble.sensor_T_object.x(),
              1e3 * contact.bubble.sensor_T_object.y(),
              contact.bubble.sensor_T_object.yaw() * 180.0 / kPi,
              1e3 * contact.bubble.depth_m, 1e3 * contact.gelslim.depth_m);

  const auto bubble = simulator.Render(SensorKind::kSoftBubble, contact.bubble, 1);
  const auto gelslim = simulator.Render(SensorKind::kGelSlim, contact.gelslim, 2);

  // Area touched by the press: where the membrane moved by more than 0.5 mm (it
  // spreads far beyond the tool), and where the gel changed colour by more than 0.05
  // (summed over RGB).
  int bubble_area = 0, gel_area = 0;
  double bubble_peak = 0.0, gel_peak = 0.0;
  Measure(bubble.clean, simulator.Reference(SensorKind::kSoftBubble), 0.5e-3, &bubble_area,
          &bubble_peak);
  Measure(gelslim.clean, simulator.Reference(SensorKind::kGelSlim), 0.05, &gel_area,
          &gel_peak);
  int dropouts = 0;
  for (float d : bubble.frame.data) dropouts += std::isnan(d);
  const double bubble_pixel_area = std::pow(1e3 * simulator.PixelPitch(SensorKind::kSoftBubble), 2);
  const double gel_pixel_area = std::pow(1e3 * simulator.PixelPitch(SensorKind::kGelSlim), 2);

  std::printf("bubble  %s: area dented > 0.5 mm 0 -> %.0f mm^2, peak indentation 0 -> %.2f mm "
              "(%d ToF dropouts in the noisy frame)\n",
              bubble.frame.ShapeString().c_str(), bubble_area * bubble_pixel_area,
              1e3 * bubble_peak, dropouts);
  std::printf("gelslim %s: area changed > 0.05 0 -> %.0f mm^2, peak RGB change 0 -> %.2f\n",
              gelslim.frame.ShapeString().c_str(), gel_area * gel_pixel_area, gel_peak);
  return 0;
}
