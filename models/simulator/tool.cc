// Copyright 2026 The tactfunc Authors.
#include "models/simulator/tool.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>
#include <utility>

#include "models/core/internal/checks.h"

namespace tactfunc {
namespace {

using internal::kPi;
constexpr double kDeg = kPi / 180.0;

// Ridges: 1.5 mm wide walls, 3 mm high, with a half-cylinder top of 0.75 mm radius,
// 20 mm long. The rounded top gives the GelSlim a contact line ~1-1.5 mm wide at its
// press depths (0.3-1.5 mm), like a printed ridge.
constexpr double kRidgeHalfWidth = 0.75e-3;
constexpr double kRidgeHeight = 3.0e-3;
constexpr double kRidgeLength = 20.0e-3;
// Prisms (triangle, square, L, half disc): 4 mm high, 1 mm fillet on the top edge.
constexpr double kPrismHeight = 4.0e-3;
constexpr double kFillet = 1.0e-3;

struct Point {
  double u, v;
};

struct Segment {
  Point a, b;
};

// A wall of half-width `half_width` whose top is a half-cylinder, seen across at
// distance d from its centre line.
double RidgeProfile(double d, double half_width, double height) {
  if (d >= half_width) return 0.0;
  return height - half_width + std::sqrt(half_width * half_width - d * d);
}

// A prism of height `height` whose top edge is rounded with radius `fillet`, as a
// function of the signed distance sd to its outline (negative inside).
double FilletedPrism(double sd, double height, double fillet) {
  if (sd >= 0.0) return 0.0;
  if (sd <= -fillet) return height;
  const double t = sd + fillet;  // in (0, fillet)
  return height - fillet + std::sqrt(fillet * fillet - t * t);
}

// A segment prepared for fast distance queries: origin, unit direction, length.
struct Ridge {
  double au, av, du, dv, length;
};

// The union (pointwise max) of ridges along `segments`. Height() is the inner loop
// of rendering, so each ridge is rejected by its perpendicular distance first and
// one square root is taken at the end.
Tool MakeRidges(std::string name, std::string description, int symmetry_order,
                const std::vector<Segment>& segments) {
  double radius = 0.0;
  std::vector<Ridge> ridges;
  for (const Segment& s : segments) {
    for (const Point& p : {s.a, s.b}) radius = std::max(radius, std::hypot(p.u, p.v));
    const double length = std::hypot(s.b.u - s.a.u, s.b.v - s.a.v);
    ridges.push_back({s.a.u, s.a.v, (s.b.u - s.a.u) / length, (s.b.v - s.a.v) / length,
                      length});
  }
  auto height = [ridges](double u, double v) {
    constexpr double kW2 = kRidgeHalfWidth * kRidgeHalfWidth;
    double d2 = kW2;
    for (const Ridge& r : ridges) {
      const double pu = u - r.au, pv = v - r.av;
      const double perp = r.du * pv - r.dv * pu;
      if (perp * perp >= d2) continue;
      const double along = r.du * pu + r.dv * pv;
      const double beyond =
          along < 0.0 ? along : (along > r.length ? along - r.length : 0.0);
      d2 = std::min(d2, perp * perp + beyond * beyond);
    }
    if (d2 >= kW2) return 0.0;
    return RidgeProfile(std::sqrt(d2), kRidgeHalfWidth, kRidgeHeight);
  };
  return Tool(std::move(name), std::move(description), symmetry_order, height,
              kRidgeHeight, radius + kRidgeHalfWidth);
}

// A ridge of length kRidgeLength through the origin at angle `angle`.
Segment CentredSegment(double angle) {
  const double c = 0.5 * kRidgeLength * std::cos(angle);
  const double s = 0.5 * kRidgeLength * std::sin(angle);
  return {{-c, -s}, {c, s}};
}

Tool MakeLines2(int degrees, int symmetry_order) {
  const double half = 0.5 * degrees * kDeg;
  return MakeRidges("lines2_" + std::to_string(degrees),
                    "two 20 mm ridges crossing at the origin at " +
                        std::to_string(degrees) + " deg",
                    symmetry_order, {CentredSegment(half), CentredSegment(-half)});
}

// Three 16 mm ridges fanning out from a vertex at (-7 mm, 0), `degrees` apart, the
// middle one along +u.
Tool MakeLines3(int degrees) {
  const Point vertex{-7.0e-3, 0.0};
  const double length = 16.0e-3;
  std::vector<Segment> segments;
  for (int k = -1; k <= 1; ++k) {
    const double angle = k * degrees * kDeg;
    segments.push_back({vertex,
                        {vertex.u + length * std::cos(angle),
                         vertex.v + length * std::sin(angle)}});
  }
  return MakeRidges("lines3_" + std::to_string(degrees),
                    "three 16 mm ridges fanning from a common vertex " +
                        std::to_string(degrees) + " deg apart",
                    1, segments);
}

Tool MakeLines5() {
  std::vector<Segment> segments;
  for (int k = -2; k <= 2; ++k) {
    const double v = 4.0e-3 * k;
    segments.push_back({{-0.5 * kRidgeLength, v}, {0.5 * kRidgeLength, v}});
  }
  return MakeRidges("lines5", "five parallel 20 mm ridges, 4 mm apart", 2, segments);
}

Tool MakeRod() {
  const double radius = 2.5e-3, half_length = 12.0e-3;
  auto height = [=](double u, double v) {
    if (std::abs(u) > half_length || std::abs(v) >= radius) return 0.0;
    return radius + std::sqrt(radius * radius - v * v);
  };
  return Tool("rod", "a 5 mm diameter, 24 mm long cylinder lying along u", 2, height,
              2.0 * radius, std::hypot(half_length, radius));
}

Tool MakeHemisphere() {
  const double radius = 6.0e-3;
  auto height = [=](double u, double v) {
    const double r2 = u * u + v * v;
    return r2 >= radius * radius ? 0.0 : std::sqrt(radius * radius - r2);
  };
  return Tool("hemisphere", "a 6 mm radius hemisphere", 0, height, radius, radius);
}

Tool MakeTriangle() {
  // Equilateral, circumradius 9 mm, vertices at 90, 210 and 330 deg: the signed
  // distance is the largest distance beyond the three edge lines (exact inside,
  // which is all the fillet needs), and is C3-symmetric by construction.
  const double circumradius = 9.0e-3, inradius = 0.5 * circumradius;
  std::vector<Point> normals;
  for (double deg : {270.0, 30.0, 150.0}) {
    normals.push_back({std::cos(deg * kDeg), std::sin(deg * kDeg)});
  }
  auto height = [=](double u, double v) {
    double sd = -1.0;
    for (const Point& n : normals) sd = std::max(sd, n.u * u + n.v * v - inradius);
    return FilletedPrism(sd, kPrismHeight, kFillet);
  };
  return Tool("triangle", "an equilateral prism, 9 mm circumradius, filleted top edges",
              3, height, kPrismHeight, circumradius);
}

Tool MakeSquare() {
  const double half_side = 7.0e-3;
  auto height = [=](double u, double v) {
    return FilletedPrism(std::max(std::abs(u), std::abs(v)) - half_side, kPrismHeight,
                         kFillet);
  };
  return Tool("square", "a 14 mm square flat punch with filleted top edges", 4, height,
              kPrismHeight, std::sqrt(2.0) * half_side);
}

// Signed distance (exact inside) to an axis-aligned box [u0, u1] x [v0, v1].
double BoxDistance(double u, double v, double u0, double u1, double v0, double v1) {
  return std::max(std::max(u0 - u, u - u1), std::max(v0 - v, v - v1));
}

Tool MakeLShape() {
  // Arms [0, 16] x [0, 5] mm and [0, 5] x [0, 12] mm; the origin is moved to the
  // area centroid so that x_m, y_m label where the tool's mass of contact is.
  const double a = 80.0, b = 35.0;  // mm^2: the long arm, the rest of the short arm
  const double cu = (a * 8.0 + b * 2.5) / (a + b) * 1e-3;
  const double cv = (a * 2.5 + b * 8.5) / (a + b) * 1e-3;
  auto height = [=](double u, double v) {
    const double pu = u + cu, pv = v + cv;
    const double sd = std::min(BoxDistance(pu, pv, 0.0, 16e-3, 0.0, 5e-3),
                               BoxDistance(pu, pv, 0.0, 5e-3, 0.0, 12e-3));
    return FilletedPrism(sd, kPrismHeight, kFillet);
  };
  double radius = 0.0;
  for (Point p : std::vector<Point>{{0, 0}, {16e-3, 0}, {16e-3, 5e-3}, {0, 12e-3},
                                    {5e-3, 12e-3}}) {
    radius = std::max(radius, std::hypot(p.u - cu, p.v - cv));
  }
  return Tool("l_shape", "an L-shaped prism, arms 16 x 5 and 12 x 5 mm, filleted", 1,
              height, kPrismHeight, radius);
}

Tool MakeHalfDisc() {
  // Disc of radius 9 mm cut along u; the centroid of a half disc lies 4R/(3 pi) from
  // the cut, and the origin is put there.
  const double radius = 9.0e-3;
  const double cut_v = -4.0 * radius / (3.0 * kPi);
  auto height = [=](double u, double v) {
    const double dv = v - cut_v;
    const double sd = std::max(std::sqrt(u * u + dv * dv) - radius, -dv);
    return FilletedPrism(sd, kPrismHeight, kFillet);
  };
  return Tool("half_disc", "a half-disc prism, 9 mm radius, filleted top edges", 1,
              height, kPrismHeight, std::hypot(radius, cut_v));
}

}  // namespace

Tool::Tool(std::string name, std::string description, int symmetry_order,
           std::function<double(double, double)> height, double max_height,
           double footprint_radius)
    : name_(std::move(name)),
      description_(std::move(description)),
      symmetry_order_(symmetry_order),
      height_(std::move(height)),
      max_height_(max_height),
      footprint_radius_(footprint_radius) {
  if (name_.empty()) throw std::invalid_argument("Tool: name must not be empty");
  if (symmetry_order_ < 0) {
    throw std::invalid_argument("Tool '" + name_ + "': symmetry_order must be >= 0, got " +
                                std::to_string(symmetry_order_));
  }
  if (!height_) throw std::invalid_argument("Tool '" + name_ + "': height is empty");
  if (!(max_height_ > 0.0) || !(footprint_radius_ > 0.0)) {
    throw std::invalid_argument("Tool '" + name_ +
                                "': max_height and footprint_radius must be > 0");
  }
}

const std::vector<Tool>& ToolSet() {
  static const std::vector<Tool> tools = {
      MakeLines2(30, 2), MakeLines2(60, 2), MakeLines2(90, 4), MakeLines3(20),
      MakeLines3(40),    MakeLines5(),      MakeRod(),         MakeHemisphere(),
      MakeTriangle(),    MakeSquare(),      MakeLShape(),      MakeHalfDisc(),
  };
  return tools;
}

const Tool& GetTool(const std::string& name) {
  for (const Tool& tool : ToolSet()) {
    if (tool.name() == name) return tool;
  }
  std::string valid;
  for (const Tool& tool : ToolSet()) valid += (valid.empty() ? "" : ", ") + tool.name();
  throw std::invalid_argument("unknown tool '" + name + "'; valid tools are: " + valid);
}

int SymmetryOrderOfTool(const std::string& name, bool* known) {
  if (known != nullptr) *known = false;
  for (const Tool& tool : ToolSet()) {
    if (tool.name() == name) {
      if (known != nullptr) *known = true;
      return tool.symmetry_order();
    }
  }
  return 1;
}

int SymmetryOrderOfTool(const std::string& name, const std::map<std::string, int>& declared,
                        bool* known) {
  const auto it = declared.find(name);
  if (it == declared.end()) return SymmetryOrderOfTool(name, known);
  if (known != nullptr) *known = true;
  return it->second;
}

std::vector<std::string> ToolNames() {
  std::vector<std::string> names;
  for (const Tool& tool : ToolSet()) names.push_back(tool.name());
  return names;
}

double YawErrorModuloSymmetry(double yaw_a, double yaw_b, int symmetry_order) {
  if (symmetry_order < 0) {
    throw std::invalid_argument("YawErrorModuloSymmetry: symmetry_order must be >= 0, got " +
                                std::to_string(symmetry_order));
  }
  if (symmetry_order == 0) return 0.0;
  const double period = 2.0 * kPi / symmetry_order;
  double d = std::fmod(yaw_a - yaw_b, period);
  if (d < 0.0) d += period;
  return std::min(d, period - d);
}

double FoldYawNear(double yaw, double reference_yaw, int symmetry_order) {
  if (symmetry_order == 0) return 0;
  const double period = 2 * kPi / symmetry_order;
  return reference_yaw + std::remainder(yaw - reference_yaw, period);
}

}  // namespace tactfunc
