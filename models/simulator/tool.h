// Copyright 2026 The tactfunc Authors.
//
// Tool: a rigid object pressed into a tactile sensor, described by its contact face.
//
// tactfunc synthesises tactile datasets after the Touch2Touch tool set (twelve small
// 3D-printed tools pressed into a Soft Bubble and a GelSlim): patterns of two lines at
// three angles, three lines at two angles, five lines, a rod and five other shapes.
// Each tool is a height field h(u, v) >= 0 in its own frame (u right, v up, origin at
// the tool's centre, metres): the height of the contact face above the tool's base.
// h == 0 means "no material within reach of the sensor there" -- the body behind the
// face is narrower -- so a press deeper than max_height() does not bring a base plate
// into contact (see docs/SIMULATOR.md, "Tools").
//
// The twelve tools, in ToolSet() order (symmetry order n: the face is unchanged by a
// yaw of 2*pi/n; 0 = continuous, yaw unobservable; 1 = asymmetric):
//   name        n  face
//   lines2_30   2  two ridges crossing at the origin, 30 deg included angle
//   lines2_60   2  two ridges crossing at the origin, 60 deg
//   lines2_90   4  two ridges crossing at the origin, 90 deg
//   lines3_20   1  three ridges fanning from a vertex at (-7 mm, 0), 20 deg apart
//   lines3_40   1  three ridges fanning from a vertex at (-7 mm, 0), 40 deg apart
//   lines5      2  five parallel ridges along u, 4 mm apart
//   rod         2  a 5 mm cylinder, 24 mm long, lying along u
//   hemisphere  0  a 6 mm radius hemisphere
//   triangle    3  an equilateral prism (9 mm circumradius), filleted top edges
//   square      4  a 14 mm square flat punch, filleted top edges
//   l_shape     1  an L-shaped prism (16 x 12 mm, 5 mm arms), origin at its centroid
//   half_disc   1  a half-disc prism (9 mm radius), origin at its centroid
// Ridges are 1.5 mm wide walls, 3 mm high, with a half-cylinder top (0.75 mm radius);
// prisms are 4 mm high with a 1 mm fillet. Exact numbers: models/simulator/tool.cc.
#ifndef TACTFUNC_MODELS_SIMULATOR_TOOL_H_
#define TACTFUNC_MODELS_SIMULATOR_TOOL_H_

#include <functional>
#include <map>
#include <string>
#include <vector>

namespace tactfunc {

class Tool {
 public:
  // height(u, v): the face in metres, >= 0, 0 outside the footprint, at most
  // max_height, and 0 everywhere outside the disc of radius footprint_radius.
  // Throws std::invalid_argument on an empty name, a negative symmetry order or a
  // non-positive max_height / footprint_radius.
  Tool(std::string name, std::string description, int symmetry_order,
       std::function<double(double u, double v)> height, double max_height,
       double footprint_radius);

  // e.g. "rod", "lines2_30": the name used in Contact::tool, labels and folders.
  const std::string& name() const { return name_; }
  // One line of prose, e.g. "two 20 mm ridges crossing at 30 deg".
  const std::string& description() const { return description_; }
  // Order n of the rotational symmetry group C_n: the height field is unchanged by a
  // yaw of 2*pi/n. 1 = asymmetric; 0 = continuous symmetry SO(2) (yaw unobservable).
  int symmetry_order() const { return symmetry_order_; }
  // Height of the tool surface above its base at (u, v) in the tool frame, metres;
  // 0 outside the footprint. Maximum is max_height().
  double Height(double u, double v) const { return height_(u, v); }
  double max_height() const { return max_height_; }
  // Radius (m) of a disc about the tool origin containing the footprint.
  double footprint_radius() const { return footprint_radius_; }

 private:
  std::string name_;
  std::string description_;
  int symmetry_order_;
  std::function<double(double, double)> height_;
  double max_height_;
  double footprint_radius_;
};

// The twelve tools, in the fixed order of the table above.
const std::vector<Tool>& ToolSet();
// The tool called `name`. Throws std::invalid_argument listing the valid names.
const Tool& GetTool(const std::string& name);
// The names of ToolSet(), in order.
std::vector<std::string> ToolNames();
// The symmetry order n of tool `name`; 1 for an unknown or empty name (nothing is
// folded). *known (optional) says whether the name was a known tool.
int SymmetryOrderOfTool(const std::string& name, bool* known = nullptr);
// The same with the orders a dataset declares for tools of its own (tools.csv) looked up
// first: declared, else built in, else 1.
int SymmetryOrderOfTool(const std::string& name, const std::map<std::string, int>& declared,
                        bool* known = nullptr);

// Smallest absolute yaw difference modulo the symmetry, in [0, pi/n] (n >= 1); 0 for
// n == 0. E.g. for the rod (n = 2) yaws 0.1 and 0.1 + pi are 0 apart. Throws
// std::invalid_argument for n < 0.
double YawErrorModuloSymmetry(double yaw_a, double yaw_b, int symmetry_order);

// `yaw` as the representative modulo 2 pi / n nearest `reference_yaw` (a truth compared
// with a folded posterior, or with a prediction); 0 for n = 0 (no observable yaw).
double FoldYawNear(double yaw, double reference_yaw, int symmetry_order);

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_SIMULATOR_TOOL_H_
