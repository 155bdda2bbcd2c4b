// Copyright 2026 The tactfunc Authors.
//
// ContactSimulator: synthetic Soft Bubble and GelSlim frames of a tool pressed into
// the sensor, the forward model behind tactfunc's synthetic datasets.
//
// A contact (models/simulator/contact.h) is a rigid tool (models/simulator/tool.h) at
// pose sensor_T_object = (x, y, yaw) in the sensor frame (models/core/sensor.h), pressed
// `depth` beyond first touch. Rendering a contact takes three steps (docs/SIMULATOR.md
// has the physics and the numbers):
//
// 1. Interference. How far the undeformed sensor surface would sit inside the tool:
//      s(p) = max(0, h(object_T_sensor p) + z0(p) - m + depth)    where h(.) > 0,
//    h the tool's face, z0 the undeformed surface's outward bulge (the Soft Bubble's
//    dome; 0 for the flat gel) and m = max(h + z0) over the face, so first touch is
//    at depth 0. For the GelSlim this is exactly s = max(0, h - (max_height - depth)).
// 2. Elastic response. The surface displacement w >= s of least energy
//      E(w) = integral |grad w|^2 / 2 + w^2 / (2 l^2),
//    a tensioned membrane on a gas spring (Soft Bubble) or a thin gel layer on rigid
//    acrylic (GelSlim, a Pasternak foundation); its Green's function is K0(r / l), so
//    the surface wraps the tool, bridges between close ridges and relaxes over ~l
//    (l = 15 mm for the bubble, 1 mm for the gel). Solved by cascadic multigrid.
// 3. Imaging.
//    Soft Bubble: depth image d = d0 - w of the dome seen from inside by a ToF camera,
//      plus Gaussian noise growing as depth^2 and NaN dropouts (random, and more near
//      the steep rim).
//    GelSlim: RGB image of the gel's painted skin lit by a red, a green and a blue LED
//      from three azimuths (Lambertian shading of the normals of w, plus ambient),
//      with a printed grid of dark markers carried sideways by the gel (displacement
//      -kappa grad w), vignetting, and Gaussian pixel noise; clamped to [0, 1].
//
// Thread safety: every const member may be called concurrently.
#ifndef TACTFUNC_MODELS_SIMULATOR_CONTACT_SIMULATOR_H_
#define TACTFUNC_MODELS_SIMULATOR_CONTACT_SIMULATOR_H_

#include <cstdint>
#include <string>
#include <vector>

#include "models/core/image.h"
#include "models/core/sensor.h"
#include "models/simulator/contact.h"
#include "models/simulator/tool.h"

namespace tactfunc {

// One contact seen by both sensors: the same tool and pose, a press depth per sensor.
struct PairedContact {
  Contact bubble;
  Contact gelslim;
};

// The Soft Bubble: an air-filled latex dome seen from inside by a time-of-flight
// camera. Frames are rows x cols x 1, depth in metres. With the defaults every depth,
// noise included, lies in (33, 60) mm, below the 65.535 mm a 16-bit micrometre PNG
// can hold.
struct SoftBubbleOptions {
  int rows = 140;  // image height, pixels (> 0); the ToF camera's cropped field
  int cols = 175;  // image width, pixels (> 0)
  // Metres per pixel on the membrane (> 0). 0.45 mm: the frame spans 78.75 x 63 mm,
  // about the size of the Soft Bubble's membrane.
  double pixel_pitch_m = 0.45e-3;
  // Depth of the membrane apex (frame centre) from the camera, metres, in
  // (2 * dome_sag_m, 65.535e-3 - 6 * noise_stddev_m).
  double apex_depth_m = 58.0e-3;
  // The dome: depth d0 = apex_depth_m - dome_sag_m * rho^2 with
  // rho^2 = (x / dome_semi_axis_x_m)^2 + (y / dome_semi_axis_y_m)^2, so the membrane
  // comes dome_sag_m closer to the camera at the inscribed ellipse (rho = 1) and
  // 2 * dome_sag_m at the frame corners. Metres; sag in [0, apex_depth_m / 2), axes > 0.
  double dome_sag_m = 12.0e-3;
  double dome_semi_axis_x_m = 39.375e-3;  // half the default frame width
  double dome_semi_axis_y_m = 31.5e-3;    // half the default frame height
  // Decay length l = sqrt(T / k) of the membrane (tension over gas stiffness), metres
  // (> 0). Chosen so a fingertip-sized press dents a region ~3-5 cm across, as in Soft
  // Bubble depth images; not fitted to data.
  double membrane_decay_length_m = 15.0e-3;
  // ToF depth noise: standard deviation noise_stddev_m at noise_reference_depth_m,
  // growing as (depth / noise_reference_depth_m)^2 (returned light falls as 1/d^2).
  // Metres, >= 0 and > 0. 0.25 mm at 55 mm is ~0.5% of range, typical of close-range
  // ToF cameras.
  double noise_stddev_m = 0.25e-3;
  double noise_reference_depth_m = 55.0e-3;
  // Probability that any pixel drops out (NaN), in [0, 1].
  double dropout_probability = 0.002;
  // Extra dropout probability at the dark, steep rim: rising linearly from 0 at
  // rho = rim_dropout_start to rim_dropout_probability at the frame corners.
  // Probability in [0, 1]; start in (0, sqrt(2)).
  double rim_dropout_probability = 0.35;
  double rim_dropout_start = 1.0;

  bool IsValid(std::string* error) const;
};

// GelSlim 3.0: a thin elastomer gel on acrylic with an opaque painted skin and a
// printed marker grid, lit by LEDs and seen by an RGB camera. Frames are
// rows x cols x 3, intensities in [0, 1].
struct GelSlimOptions {
  int rows = 320;  // image height, pixels (> 0)
  int cols = 427;  // image width, pixels (> 0)
  // Metres per pixel on the gel (> 0). 0.07 mm: the frame spans 29.9 x 22.4 mm, the
  // GelSlim 3.0 sensing area.
  double pixel_pitch_m = 0.07e-3;
  // Decay length of the gel surface around a contact, metres (> 0): for a thin
  // layer bonded to rigid acrylic it is of the order of the gel thickness (~1 mm).
  double gel_decay_length_m = 1.0e-3;
  // The three LEDs (red, green, blue) shine from azimuths 90, 210 and 330 deg (CCW
  // from +x) at this elevation above the gel plane, radians in (0, pi/2). Low light
  // makes slopes bright on the lit side and dark on the other.
  double light_elevation_rad = 0.5;
  // Intensity = ambient + diffuse * max(0, n . l) per channel; each in [0, 1].
  double ambient = 0.15;
  double diffuse = 0.8;
  // Marker grid: dark dots at marker_pitch_m spacing (one at the frame centre) of
  // radius marker_radius_m, multiplying the intensity by (1 - marker_darkness).
  // Metres > 0 (radius < pitch / 2); darkness in [0, 1].
  double marker_pitch_m = 1.2e-3;
  double marker_radius_m = 0.22e-3;
  double marker_darkness = 0.7;
  // Lateral displacement of the skin (and its markers) per unit surface slope,
  // -marker_shear_m * grad w: material squeezed out from under the indenter moves
  // outwards. Metres, >= 0.
  double marker_shear_m = 0.35e-3;
  // Intensity falls as 1 - vignetting * (r / r_corner)^2; in [0, 1).
  double vignetting = 0.25;
  // Standard deviation of the per-channel pixel noise, intensity units, >= 0.
  double noise_stddev = 0.01;

  bool IsValid(std::string* error) const;
};

// How SamplePairedContact draws a contact. Each quantity is uniform in [min, max]
// (min <= max). One press fraction f ~ U[0, 1] is shared by the two sensors and mapped
// into each sensor's depth range, so a firm press is firm on both.
struct ContactSamplingOptions {
  // Tool position in the sensor frame, metres. +-4 x +-3 mm keeps the contact
  // mostly inside the GelSlim's 30 x 22 mm view.
  double x_min_m = -4.0e-3, x_max_m = 4.0e-3;
  double y_min_m = -3.0e-3, y_max_m = 3.0e-3;
  // Tool yaw, radians: the full circle [-pi, pi) by default.
  double yaw_min_rad = -3.14159265358979323846;
  double yaw_max_rad = 3.14159265358979323846;
  // Press depth beyond first touch, metres, >= 0. The bubble's membrane is pressed
  // centimetres, the gel a fraction of a millimetre.
  double bubble_depth_min_m = 3.0e-3, bubble_depth_max_m = 15.0e-3;
  double gelslim_depth_min_m = 0.3e-3, gelslim_depth_max_m = 1.5e-3;

  bool IsValid(std::string* error) const;
};

class ContactSimulator {
 public:
  struct Options {
    SoftBubbleOptions bubble;
    GelSlimOptions gelslim;
    ContactSamplingOptions sampling;
    bool IsValid(std::string* error) const;
  };

  struct Rendering {
    Image frame;  // what the sensor reports: noise, ToF dropouts (NaN, bubble only), not quantised
    Image clean;  // the same contact noise-free, no dropouts
  };

  // Throws std::invalid_argument with IsValid's message.
  explicit ContactSimulator(const Options& options = Options());

  const Options& options() const { return options_; }

  // Noise-free no-contact frame. Bubble: depth in metres (rows x cols x 1). GelSlim:
  // RGB in [0, 1] (rows x cols x 3).
  const Image& Reference(SensorKind sensor) const;

  // Renders a contact on one sensor; `seed` drives that frame's sensor noise only.
  // Throws std::invalid_argument for an unknown tool, a non-finite pose or a
  // negative/non-finite depth.
  Rendering Render(SensorKind sensor, const Contact& contact, std::uint64_t seed) const;

  // Draws a pose (shared by both sensors) and a press depth per sensor for `tool`,
  // deterministic in `seed`. Throws std::invalid_argument for an unknown tool.
  PairedContact SamplePairedContact(const std::string& tool, std::uint64_t seed) const;

  // Metres per pixel of the sensor's frames.
  double PixelPitch(SensorKind sensor) const;

  // The Soft Bubble's noise model, as Render draws it: pixel i of a frame whose
  // noise-free depth is d reads NaN with probability BubbleDropoutProbability()[i], and
  // otherwise d + BubbleNoiseStddev(d) * N(0, 1), independently of every other pixel.
  // Metres in, metres out.
  double BubbleNoiseStddev(double clean_depth_m) const {
    const SoftBubbleOptions& o = options_.bubble;
    const double q = clean_depth_m / o.noise_reference_depth_m;
    return o.noise_stddev_m * q * q;
  }
  // Row-major, rows x cols of the Soft Bubble's frames; each in [0, 1].
  const std::vector<float>& BubbleDropoutProbability() const { return bubble_dropout_; }

 private:
  Rendering RenderBubble(const Tool& tool, const Contact& contact,
                         std::uint64_t seed) const;
  Rendering RenderGelSlim(const Tool& tool, const Contact& contact,
                          std::uint64_t seed) const;

  Options options_;
  Image bubble_reference_;
  Image gelslim_reference_;
  // Per-pixel precomputations (row-major, rows x cols).
  std::vector<float> bubble_lift_;      // d0(p) - apex_depth_m: the dome's bulge, <= 0
  std::vector<float> bubble_dropout_;   // dropout probability
  std::vector<float> gelslim_vignette_;  // intensity factor
};

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_SIMULATOR_CONTACT_SIMULATOR_H_
