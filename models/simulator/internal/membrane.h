// Copyright 2026 The tactfunc Authors.
//
// The elastic surface of both sensors as an obstacle problem (private helper).
//
// A Soft Bubble membrane (tension T over a gas spring k) and a GelSlim gel layer
// bonded to acrylic (a Pasternak foundation: shear coupling over a Winkler spring) both
// obey, for a small normal displacement w(x, y) towards the camera,
//   -T lap(w) + k w = p,        p >= 0 the contact pressure,
// whose point-load Green's function is K0(r / l) / (2 pi T), l = sqrt(T / k) the decay
// length. Pressed by a rigid tool whose interference (how far the undeformed surface
// would sit inside the tool) is s(x, y), the surface takes the shape of least energy
//   E(w) = integral |grad w|^2 / 2 + w^2 / (2 l^2)   subject to  w >= s,
// with p > 0 only where w == s (the complementarity conditions of the obstacle problem).
// It wraps convex features, bridges between close ones, and relaxes away over ~l.
//
// Discretised on the pixel grid (5-point Laplacian, w = 0 outside the grid, a
// clamped rim) and solved by cascadic multigrid: a pyramid of obstacles built by 2x2
// max pooling (so coarse solutions stay on or above the fine one), projected damped
// Jacobi sweeps on each level from coarse to fine, bilinear prolongation in between.
// Jacobi is order-independent, so the solver commutes exactly with the symmetries of
// the grid (flips, 90-degree turns) and is deterministic.
#ifndef TACTFUNC_MODELS_SIMULATOR_INTERNAL_MEMBRANE_H_
#define TACTFUNC_MODELS_SIMULATOR_INTERNAL_MEMBRANE_H_

#include <vector>

namespace tactfunc::internal {

struct MembraneSchedule {
  int coarsest_sweeps = 80;   // on the coarsest grid (a few hundred cells)
  int coarse_sweeps = 48;     // on each intermediate level
  int finest_sweeps = 4;      // on the full-resolution grid
  int min_coarse_size = 6;    // stop coarsening before a side drops below this
  double damping = 0.8;       // Jacobi weight; 0.8 damps the checkerboard mode
};

// obstacle, *w: rows x cols, row-major. decay_length_px: l in pixels (> 0).
// *w is resized; on return w >= obstacle everywhere.
void SolveMembraneObstacle(const std::vector<float>& obstacle, int rows, int cols,
                           double decay_length_px, const MembraneSchedule& schedule,
                           std::vector<float>* w);

}  // namespace tactfunc::internal

#endif  // TACTFUNC_MODELS_SIMULATOR_INTERNAL_MEMBRANE_H_
