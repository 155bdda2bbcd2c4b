// Copyright 2026 The tactfunc Authors.
#include "models/simulator/contact_simulator.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>

#include <boost/random/mersenne_twister.hpp>
#include <boost/random/uniform_real_distribution.hpp>

#include "models/core/internal/checks.h"
#include "models/simulator/internal/membrane.h"
#include "models/simulator/internal/noise_stream.h"
#include "models/core/seed.h"

namespace tactfunc {
namespace {

using internal::kPi;
// Largest depth a 16-bit micrometre PNG can store.
constexpr double kMaxStorableDepthM = 65.535e-3;
// The surface is solved on the contact's bounding box grown by this many decay
// lengths; beyond it w < ~e^-5 of the press and is taken as exactly 0.
constexpr double kMarginDecayLengths = 5.0;
// The noise table is bounded at |z| <= 4.17.
constexpr double kMaxNoiseSigmas = 4.2;

template <typename T>
std::string Str(const T& value) {
  std::ostringstream out;
  out << value;
  return out.str();
}

bool Fail(std::string* error, const std::string& message) {
  if (error != nullptr) *error = message;
  return false;
}

// A region of interest of a frame and the interference s over it (row-major).
struct Patch {
  int r0 = 0, c0 = 0, rows = 0, cols = 0;
  std::vector<float> s;
  bool empty() const { return rows == 0; }
};

// Step 1 of the header: the interference of `tool` at `contact` on a rows x cols grid
// of pitch `pitch`. `lift` (rows x cols, may be empty) is the undeformed surface's
// outward bulge z0; with it, first touch is found over the face's pixels, without it
// first touch is at max_height. The patch is the bounding box of s > 0 grown by
// `margin_px`, clipped to the frame; empty when nothing touches.
Patch ComputeInterference(const Tool& tool, const Contact& contact, int rows, int cols,
                          double pitch, const std::vector<float>& lift, int margin_px) {
  Patch patch;
  const SE2d& sensor_T_object = contact.sensor_T_object;
  const double cc = sensor_T_object.x() / pitch + 0.5 * cols - 0.5;
  const double rc = 0.5 * rows - 0.5 - sensor_T_object.y() / pitch;
  const double radius = tool.footprint_radius() / pitch + 1.0;
  const int c_lo = std::max(0, static_cast<int>(std::floor(cc - radius)));
  const int c_hi = std::min(cols - 1, static_cast<int>(std::ceil(cc + radius)));
  const int r_lo = std::max(0, static_cast<int>(std::floor(rc - radius)));
  const int r_hi = std::min(rows - 1, static_cast<int>(std::ceil(rc + radius)));
  if (c_lo > c_hi || r_lo > r_hi) return patch;

  const int box_cols = c_hi - c_lo + 1, box_rows = r_hi - r_lo + 1;
  constexpr float kNoFace = -std::numeric_limits<float>::infinity();
  std::vector<float> value(static_cast<std::size_t>(box_rows) * box_cols, kNoFace);
  const double cos_yaw = std::cos(sensor_T_object.yaw()), sin_yaw = std::sin(sensor_T_object.yaw());
  float first_touch = lift.empty() ? static_cast<float>(tool.max_height()) : kNoFace;
  for (int r = r_lo; r <= r_hi; ++r) {
    const double dy = (0.5 * rows - r - 0.5) * pitch - sensor_T_object.y();
    float* out = value.data() + static_cast<std::size_t>(r - r_lo) * box_cols;
    for (int c = c_lo; c <= c_hi; ++c) {
      const double dx = (c + 0.5 - 0.5 * cols) * pitch - sensor_T_object.x();
      // object_T_sensor: rotate the offset by -yaw.
      const double u = cos_yaw * dx + sin_yaw * dy;
      const double v = -sin_yaw * dx + cos_yaw * dy;
      const double h = tool.Height(u, v);
      if (h <= 0.0) continue;
      float z = static_cast<float>(h);
      if (!lift.empty()) {
        z += lift[static_cast<std::size_t>(r) * cols + c];
        first_touch = std::max(first_touch, z);
      }
      out[c - c_lo] = z;
    }
  }

  const float offset = static_cast<float>(contact.depth_m) - first_touch;
  int sr_lo = rows, sr_hi = -1, sc_lo = cols, sc_hi = -1;
  for (int r = 0; r < box_rows; ++r) {
    float* row = value.data() + static_cast<std::size_t>(r) * box_cols;
    for (int c = 0; c < box_cols; ++c) {
      const float s = row[c] + offset;  // -inf stays -inf
      row[c] = s > 0.0f ? s : 0.0f;
      if (s > 0.0f) {
        sr_lo = std::min(sr_lo, r + r_lo);
        sr_hi = std::max(sr_hi, r + r_lo);
        sc_lo = std::min(sc_lo, c + c_lo);
        sc_hi = std::max(sc_hi, c + c_lo);
      }
    }
  }
  if (sr_hi < 0) return patch;

  patch.r0 = std::max(0, sr_lo - margin_px);
  patch.c0 = std::max(0, sc_lo - margin_px);
  patch.rows = std::min(rows - 1, sr_hi + margin_px) - patch.r0 + 1;
  patch.cols = std::min(cols - 1, sc_hi + margin_px) - patch.c0 + 1;
  patch.s.assign(static_cast<std::size_t>(patch.rows) * patch.cols, 0.0f);
  for (int r = sr_lo; r <= sr_hi; ++r) {
    const float* in = value.data() + static_cast<std::size_t>(r - r_lo) * box_cols;
    float* out = patch.s.data() + static_cast<std::size_t>(r - patch.r0) * patch.cols;
    for (int c = sc_lo; c <= sc_hi; ++c) out[c - patch.c0] = in[c - c_lo];
  }
  return patch;
}

// Step 2: the surface displacement over the patch (patch.rows x patch.cols).
std::vector<float> SolveSurface(const Patch& patch, double decay_length_m, double pitch) {
  std::vector<float> w;
  internal::SolveMembraneObstacle(patch.s, patch.rows, patch.cols,
                                  decay_length_m / pitch, internal::MembraneSchedule(),
                                  &w);
  return w;
}

// The GelSlim's optics at one pixel: sensor-frame position (x, y), surface slope
// (gx, gy) = grad w, vignetting factor; writes three intensities in [0, 1]. Both the
// reference and contact frames go through this one function, so that a pixel whose
// slope is 0 renders bit-identically to the reference.
struct GelOptics {
  float light[3][3];  // unit vectors towards the red, green and blue LEDs
  float ambient, diffuse;
  float marker_pitch, inv_marker_pitch, marker_radius, marker_darkness, inv_edge;
  float shear;
  float x_first, dx;  // centre of column 0 and the pixel pitch, metres

  explicit GelOptics(const GelSlimOptions& o) {
    x_first = static_cast<float>((0.5 - 0.5 * o.cols) * o.pixel_pitch_m);
    dx = static_cast<float>(o.pixel_pitch_m);
    const double azimuth_deg[3] = {90.0, 210.0, 330.0};
    for (int k = 0; k < 3; ++k) {
      const double az = azimuth_deg[k] * kPi / 180.0;
      light[k][0] = static_cast<float>(std::cos(o.light_elevation_rad) * std::cos(az));
      light[k][1] = static_cast<float>(std::cos(o.light_elevation_rad) * std::sin(az));
      light[k][2] = static_cast<float>(std::sin(o.light_elevation_rad));
    }
    ambient = static_cast<float>(o.ambient);
    diffuse = static_cast<float>(o.diffuse);
    marker_pitch = static_cast<float>(o.marker_pitch_m);
    inv_marker_pitch = static_cast<float>(1.0 / o.marker_pitch_m);
    marker_radius = static_cast<float>(o.marker_radius_m);
    marker_darkness = static_cast<float>(o.marker_darkness);
    inv_edge = static_cast<float>(1.0 / o.pixel_pitch_m);  // one-pixel antialiasing
    shear = static_cast<float>(o.marker_shear_m);
  }

  // Columns c0 .. c0 + n - 1 of the row at height y, with slopes gx[k], gy[k] and
  // vignetting factors vignette[k]; writes n RGB triples to out.
  // The reference goes through this same function with zero slopes, so a contact
  // pixel whose slope is 0 renders bit-identically to the reference.
  void ShadeRow(int c0, int n, float y, const float* gx, const float* gy,
                const float* vignette, float* out) const {
    for (int k = 0; k < n; ++k) {
      const float sx = gx[k], sy = gy[k];
      const float inv_norm = 1.0f / std::sqrt(1.0f + sx * sx + sy * sy);
      // Markers are printed on the skin: the pixel sees the skin point that rested
      // at p - u, u = -shear * grad w.
      const float mx = x_first + static_cast<float>(c0 + k) * dx + shear * sx;
      const float my = y + shear * sy;
      const float ex = mx - marker_pitch * std::floor(mx * inv_marker_pitch + 0.5f);
      const float ey = my - marker_pitch * std::floor(my * inv_marker_pitch + 0.5f);
      const float edge = (marker_radius - std::sqrt(ex * ex + ey * ey)) * inv_edge + 0.5f;
      const float coverage = std::min(1.0f, std::max(0.0f, edge));
      const float factor = (1.0f - marker_darkness * coverage) * vignette[k];
      for (int c = 0; c < 3; ++c) {
        const float n_dot_l = (light[c][2] - sx * light[c][0] - sy * light[c][1]) * inv_norm;
        const float value = (ambient + diffuse * std::max(0.0f, n_dot_l)) * factor;
        out[3 * k + c] = std::min(1.0f, std::max(0.0f, value));
      }
    }
  }
};


// Row centres of the GelSlim frame (models/core/sensor.h), computed one way everywhere.
float GelPixelY(int r, const GelSlimOptions& o) {
  return static_cast<float>((0.5 * o.rows - r - 0.5) * o.pixel_pitch_m);
}

}  // namespace

bool SoftBubbleOptions::IsValid(std::string* error) const {
  const std::string p = "SoftBubbleOptions::";
  if (rows <= 0) return Fail(error, p + "rows must be > 0, got " + Str(rows));
  if (cols <= 0) return Fail(error, p + "cols must be > 0, got " + Str(cols));
  if (!(pixel_pitch_m > 0.0) || !std::isfinite(pixel_pitch_m)) {
    return Fail(error, p + "pixel_pitch_m must be > 0, got " + Str(pixel_pitch_m));
  }
  if (!(dome_sag_m >= 0.0) || !std::isfinite(dome_sag_m)) {
    return Fail(error, p + "dome_sag_m must be >= 0, got " + Str(dome_sag_m));
  }
  if (!(noise_stddev_m >= 0.0) || !std::isfinite(noise_stddev_m)) {
    return Fail(error, p + "noise_stddev_m must be >= 0, got " + Str(noise_stddev_m));
  }
  if (!(noise_reference_depth_m > 0.0)) {
    return Fail(error, p + "noise_reference_depth_m must be > 0, got " +
                           Str(noise_reference_depth_m));
  }
  // The deepest pixel is the apex; its noise is bounded by the table's 4.2 sigma.
  const double apex_noise = kMaxNoiseSigmas * noise_stddev_m * (apex_depth_m / noise_reference_depth_m) *
                            (apex_depth_m / noise_reference_depth_m);
  if (!(apex_depth_m > 2.0 * dome_sag_m && apex_depth_m + apex_noise < kMaxStorableDepthM)) {
    return Fail(error, p + "apex_depth_m must exceed 2 * dome_sag_m = " +
                           Str(2.0 * dome_sag_m) + " and, with 4.2 sigma of noise, stay below "
                           "65.535e-3 m (16-bit micrometres), got " + Str(apex_depth_m));
  }
  if (!(dome_semi_axis_x_m > 0.0)) {
    return Fail(error, p + "dome_semi_axis_x_m must be > 0, got " + Str(dome_semi_axis_x_m));
  }
  if (!(dome_semi_axis_y_m > 0.0)) {
    return Fail(error, p + "dome_semi_axis_y_m must be > 0, got " + Str(dome_semi_axis_y_m));
  }
  if (!(membrane_decay_length_m > 0.0) || !std::isfinite(membrane_decay_length_m)) {
    return Fail(error, p + "membrane_decay_length_m must be > 0, got " +
                           Str(membrane_decay_length_m));
  }
  if (!(dropout_probability >= 0.0 && dropout_probability <= 1.0)) {
    return Fail(error, p + "dropout_probability must be in [0, 1], got " +
                           Str(dropout_probability));
  }
  if (!(rim_dropout_probability >= 0.0 && rim_dropout_probability <= 1.0)) {
    return Fail(error, p + "rim_dropout_probability must be in [0, 1], got " +
                           Str(rim_dropout_probability));
  }
  if (!(rim_dropout_start > 0.0 && rim_dropout_start < std::sqrt(2.0))) {
    return Fail(error, p + "rim_dropout_start must be in (0, sqrt(2)), got " +
                           Str(rim_dropout_start));
  }
  return true;
}

bool GelSlimOptions::IsValid(std::string* error) const {
  const std::string p = "GelSlimOptions::";
  auto in01 = [](double v) { return v >= 0.0 && v <= 1.0; };
  if (rows <= 0) return Fail(error, p + "rows must be > 0, got " + Str(rows));
  if (cols <= 0) return Fail(error, p + "cols must be > 0, got " + Str(cols));
  if (!(pixel_pitch_m > 0.0) || !std::isfinite(pixel_pitch_m)) {
    return Fail(error, p + "pixel_pitch_m must be > 0, got " + Str(pixel_pitch_m));
  }
  if (!(gel_decay_length_m > 0.0) || !std::isfinite(gel_decay_length_m)) {
    return Fail(error, p + "gel_decay_length_m must be > 0, got " + Str(gel_decay_length_m));
  }
  if (!(light_elevation_rad > 0.0 && light_elevation_rad < 0.5 * kPi)) {
    return Fail(error, p + "light_elevation_rad must be in (0, pi/2), got " +
                           Str(light_elevation_rad));
  }
  if (!in01(ambient)) return Fail(error, p + "ambient must be in [0, 1], got " + Str(ambient));
  if (!in01(diffuse)) return Fail(error, p + "diffuse must be in [0, 1], got " + Str(diffuse));
  if (!(marker_pitch_m > 0.0) || !std::isfinite(marker_pitch_m)) {
    return Fail(error, p + "marker_pitch_m must be > 0, got " + Str(marker_pitch_m));
  }
  if (!(marker_radius_m > 0.0 && marker_radius_m < 0.5 * marker_pitch_m)) {
    return Fail(error, p + "marker_radius_m must be in (0, marker_pitch_m / 2), got " +
                           Str(marker_radius_m));
  }
  if (!in01(marker_darkness)) {
    return Fail(error, p + "marker_darkness must be in [0, 1], got " + Str(marker_darkness));
  }
  if (!(marker_shear_m >= 0.0) || !std::isfinite(marker_shear_m)) {
    return Fail(error, p + "marker_shear_m must be >= 0, got " + Str(marker_shear_m));
  }
  if (!(vignetting >= 0.0 && vignetting < 1.0)) {
    return Fail(error, p + "vignetting must be in [0, 1), got " + Str(vignetting));
  }
  if (!(noise_stddev >= 0.0) || !std::isfinite(noise_stddev)) {
    return Fail(error, p + "noise_stddev must be >= 0, got " + Str(noise_stddev));
  }
  return true;
}

bool ContactSamplingOptions::IsValid(std::string* error) const {
  const std::string p = "ContactSamplingOptions::";
  auto range = [&](const char* lo_name, double lo, const char* hi_name, double hi,
                   double floor) {
    if (!std::isfinite(lo) || !std::isfinite(hi) || !(lo <= hi) || lo < floor) {
      return Fail(error, p + lo_name + " and " + hi_name + " must be finite with " +
                             (floor == 0.0 ? "0 <= " : "") + lo_name + " <= " + hi_name +
                             ", got " + Str(lo) + " and " + Str(hi));
    }
    return true;
  };
  const double any = -std::numeric_limits<double>::infinity();
  return range("x_min_m", x_min_m, "x_max_m", x_max_m, any) &&
         range("y_min_m", y_min_m, "y_max_m", y_max_m, any) &&
         range("yaw_min_rad", yaw_min_rad, "yaw_max_rad", yaw_max_rad, any) &&
         range("bubble_depth_min_m", bubble_depth_min_m, "bubble_depth_max_m",
               bubble_depth_max_m, 0.0) &&
         range("gelslim_depth_min_m", gelslim_depth_min_m, "gelslim_depth_max_m",
               gelslim_depth_max_m, 0.0);
}

bool ContactSimulator::Options::IsValid(std::string* error) const {
  return bubble.IsValid(error) && gelslim.IsValid(error) && sampling.IsValid(error);
}

ContactSimulator::ContactSimulator(const Options& options) : options_(options) {
  std::string error;
  if (!options_.IsValid(&error)) {
    throw std::invalid_argument("ContactSimulator: " + error);
  }

  // Soft Bubble: the dome, its bulge and where the ToF camera drops out.
  const SoftBubbleOptions& b = options_.bubble;
  bubble_reference_ = Image(b.rows, b.cols, 1);
  bubble_lift_.resize(bubble_reference_.pixels());
  bubble_dropout_.resize(bubble_reference_.pixels());
  for (int r = 0; r < b.rows; ++r) {
    for (int c = 0; c < b.cols; ++c) {
      const double x = (c + 0.5 - 0.5 * b.cols) * b.pixel_pitch_m;
      const double y = (0.5 * b.rows - r - 0.5) * b.pixel_pitch_m;
      const double rho2 = (x / b.dome_semi_axis_x_m) * (x / b.dome_semi_axis_x_m) +
                          (y / b.dome_semi_axis_y_m) * (y / b.dome_semi_axis_y_m);
      const std::size_t i = static_cast<std::size_t>(r) * b.cols + c;
      bubble_lift_[i] = static_cast<float>(-b.dome_sag_m * rho2);
      bubble_reference_.data[i] = static_cast<float>(b.apex_depth_m - b.dome_sag_m * rho2);
      const double rim = std::max(0.0, std::min(1.0, (std::sqrt(rho2) - b.rim_dropout_start) /
                                                         (std::sqrt(2.0) - b.rim_dropout_start)));
      bubble_dropout_[i] = static_cast<float>(
          std::min(1.0, b.dropout_probability + b.rim_dropout_probability * rim));
    }
  }

  // GelSlim: the flat, lit gel with its markers at rest, vignetted.
  const GelSlimOptions& g = options_.gelslim;
  gelslim_reference_ = Image(g.rows, g.cols, 3);
  gelslim_vignette_.resize(gelslim_reference_.pixels());
  const GelOptics optics(g);
  const double corner2 = 0.25 * (static_cast<double>(g.rows) * g.rows +
                                 static_cast<double>(g.cols) * g.cols);
  for (int r = 0; r < g.rows; ++r) {
    for (int c = 0; c < g.cols; ++c) {
      const double xp = c + 0.5 - 0.5 * g.cols, yp = 0.5 * g.rows - r - 0.5;
      gelslim_vignette_[static_cast<std::size_t>(r) * g.cols + c] =
          static_cast<float>(1.0 - g.vignetting * (xp * xp + yp * yp) / corner2);
    }
  }
  const std::vector<float> flat(g.cols, 0.0f);
  for (int r = 0; r < g.rows; ++r) {
    const std::size_t i = static_cast<std::size_t>(r) * g.cols;
    optics.ShadeRow(0, g.cols, GelPixelY(r, g), flat.data(),
                    flat.data(), &gelslim_vignette_[i], &gelslim_reference_.data[3 * i]);
  }
}

const Image& ContactSimulator::Reference(SensorKind sensor) const {
  return sensor == SensorKind::kSoftBubble ? bubble_reference_ : gelslim_reference_;
}

double ContactSimulator::PixelPitch(SensorKind sensor) const {
  return sensor == SensorKind::kSoftBubble ? options_.bubble.pixel_pitch_m
                                           : options_.gelslim.pixel_pitch_m;
}

ContactSimulator::Rendering ContactSimulator::Render(SensorKind sensor,
                                                     const Contact& contact,
                                                     std::uint64_t seed) const {
  const Tool& tool = GetTool(contact.tool);
  const SE2d& sensor_T_object = contact.sensor_T_object;
  if (!std::isfinite(sensor_T_object.x()) || !std::isfinite(sensor_T_object.y()) ||
      !std::isfinite(sensor_T_object.yaw())) {
    throw std::invalid_argument("ContactSimulator::Render: the pose must be finite, got (" +
                                Str(sensor_T_object.x()) + ", " + Str(sensor_T_object.y()) +
                                ", " + Str(sensor_T_object.yaw()) + ")");
  }
  if (!std::isfinite(contact.depth_m) || contact.depth_m < 0.0) {
    throw std::invalid_argument(
        "ContactSimulator::Render: depth_m must be finite and >= 0, got " +
        Str(contact.depth_m));
  }
  return sensor == SensorKind::kSoftBubble ? RenderBubble(tool, contact, seed)
                                           : RenderGelSlim(tool, contact, seed);
}

ContactSimulator::Rendering ContactSimulator::RenderBubble(const Tool& tool,
                                                           const Contact& contact,
                                                           std::uint64_t seed) const {
  const SoftBubbleOptions& o = options_.bubble;
  Rendering out;
  out.clean = bubble_reference_;
  const int margin =
      static_cast<int>(std::ceil(kMarginDecayLengths * o.membrane_decay_length_m /
                                 o.pixel_pitch_m));
  const Patch patch = ComputeInterference(tool, contact, o.rows, o.cols, o.pixel_pitch_m,
                                          bubble_lift_, margin);
  if (!patch.empty()) {
    const std::vector<float> w =
        SolveSurface(patch, o.membrane_decay_length_m, o.pixel_pitch_m);
    for (int r = 0; r < patch.rows; ++r) {
      float* dst = &out.clean.at(patch.r0 + r, patch.c0);
      const float* src = w.data() + static_cast<std::size_t>(r) * patch.cols;
      for (int c = 0; c < patch.cols; ++c) dst[c] -= src[c];  // towards the camera
    }
  }

  out.frame = out.clean;
  internal::NoiseStream noise(DeriveSeed(seed, 0));
  // BubbleNoiseStddev(d) in float: sigma * (d / reference)^2.
  const float sigma = static_cast<float>(o.noise_stddev_m);
  const float inv_ref2 =
      static_cast<float>(1.0 / (o.noise_reference_depth_m * o.noise_reference_depth_m));
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (std::size_t i = 0; i < out.frame.size(); ++i) {
    const float d = out.frame.data[i];
    const float z = noise.Normal();
    const float u = noise.Uniform();
    out.frame.data[i] = u < bubble_dropout_[i] ? nan : d + sigma * d * d * inv_ref2 * z;
  }
  return out;
}

ContactSimulator::Rendering ContactSimulator::RenderGelSlim(const Tool& tool,
                                                            const Contact& contact,
                                                            std::uint64_t seed) const {
  const GelSlimOptions& o = options_.gelslim;
  Rendering out;
  out.clean = gelslim_reference_;
  const int margin = static_cast<int>(
      std::ceil(kMarginDecayLengths * o.gel_decay_length_m / o.pixel_pitch_m));
  const Patch patch = ComputeInterference(tool, contact, o.rows, o.cols, o.pixel_pitch_m,
                                          {}, margin);
  if (!patch.empty()) {
    const std::vector<float> w = SolveSurface(patch, o.gel_decay_length_m, o.pixel_pitch_m);
    const GelOptics optics(o);
    const float inv_2p = static_cast<float>(0.5 / o.pixel_pitch_m);
    // Central differences; w is 0 on and beyond the patch's rim (the solver clamps
    // it there), so a zero-padded copy handles the edges.
    const int stride = patch.cols + 2;
    std::vector<float> padded(static_cast<std::size_t>(patch.rows + 2) * stride, 0.0f);
    for (int r = 0; r < patch.rows; ++r) {
      std::copy_n(w.data() + static_cast<std::size_t>(r) * patch.cols, patch.cols,
                  padded.data() + static_cast<std::size_t>(r + 1) * stride + 1);
    }
    std::vector<float> gx(patch.cols), gy(patch.cols);
    for (int r = 0; r < patch.rows; ++r) {
      const float* wc = padded.data() + static_cast<std::size_t>(r + 1) * stride + 1;
      for (int c = 0; c < patch.cols; ++c) {
        gx[c] = (wc[c + 1] - wc[c - 1]) * inv_2p;
        gy[c] = (wc[c - stride] - wc[c + stride]) * inv_2p;  // y is up
      }
      const int fr = patch.r0 + r;
      const std::size_t i = static_cast<std::size_t>(fr) * o.cols + patch.c0;
      optics.ShadeRow(patch.c0, patch.cols, GelPixelY(fr, o),
                      gx.data(), gy.data(), &gelslim_vignette_[i], &out.clean.data[3 * i]);
    }
  }

  out.frame = out.clean;
  internal::NoiseStream noise(DeriveSeed(seed, 1));
  const float sigma = static_cast<float>(o.noise_stddev);
  float* data = out.frame.data.data();
  const std::size_t n = out.frame.size();
  float z[4];
  for (std::size_t i = 0; i < n; i += 4) {
    noise.Normal4(z);
    for (std::size_t k = 0; k < 4 && i + k < n; ++k) {
      data[i + k] = std::min(1.0f, std::max(0.0f, data[i + k] + sigma * z[k]));
    }
  }
  return out;
}

PairedContact ContactSimulator::SamplePairedContact(const std::string& tool,
                                                    std::uint64_t seed) const {
  GetTool(tool);  // throws for an unknown name
  const ContactSamplingOptions& o = options_.sampling;
  boost::random::mt19937_64 engine(seed);
  auto uniform = [&engine](double lo, double hi) {
    return boost::random::uniform_real_distribution<double>(lo, hi)(engine);
  };
  Contact pose;
  pose.tool = tool;
  // Drawn in this order (x, y, yaw): the draws are part of the seed's meaning.
  const double x = uniform(o.x_min_m, o.x_max_m);
  const double y = uniform(o.y_min_m, o.y_max_m);
  const double yaw = uniform(o.yaw_min_rad, o.yaw_max_rad);
  pose.sensor_T_object = SE2d::FromXYYaw(x, y, yaw);
  const double press = uniform(0.0, 1.0);
  PairedContact paired{pose, pose};
  paired.bubble.depth_m =
      o.bubble_depth_min_m + press * (o.bubble_depth_max_m - o.bubble_depth_min_m);
  paired.gelslim.depth_m =
      o.gelslim_depth_min_m + press * (o.gelslim_depth_max_m - o.gelslim_depth_min_m);
  return paired;
}

}  // namespace tactfunc
