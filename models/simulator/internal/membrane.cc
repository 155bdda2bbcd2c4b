// Copyright 2026 The tactfunc Authors.
#include "models/simulator/internal/membrane.h"

#include <algorithm>
#include <cmath>
#include <utility>

namespace tactfunc::internal {
namespace {

// One level of the pyramid; arrays are padded by one zero cell on every side so the
// sweep needs no branches and the rim is clamped (w = 0 just outside the grid).
struct Level {
  int rows = 0, cols = 0;
  std::vector<float> obstacle, w, scratch;
  int stride() const { return cols + 2; }
  std::size_t Index(int r, int c) const {
    return static_cast<std::size_t>(r + 1) * stride() + (c + 1);
  }
  void Allocate(int r, int c) {
    rows = r;
    cols = c;
    const std::size_t n = static_cast<std::size_t>(r + 2) * (c + 2);
    obstacle.assign(n, 0.0f);
    w.assign(n, 0.0f);
    scratch.assign(n, 0.0f);
  }
};

void Sweep(Level* level, float inv_diag, float damping, int sweeps) {
  const int stride = level->stride();
  for (int it = 0; it < sweeps; ++it) {
    const float* w = level->w.data();
    float* out = level->scratch.data();
    const float* s = level->obstacle.data();
    for (int r = 0; r < level->rows; ++r) {
      const std::size_t row = level->Index(r, 0);
      const float* wc = w + row;
      const float* wn = wc - stride;
      const float* ws = wc + stride;
      const float* sc = s + row;
      float* oc = out + row;
      for (int c = 0; c < level->cols; ++c) {
        const float jacobi = (wn[c] + ws[c] + wc[c - 1] + wc[c + 1]) * inv_diag;
        const float relaxed = wc[c] + damping * (jacobi - wc[c]);
        oc[c] = relaxed > sc[c] ? relaxed : sc[c];
      }
    }
    std::swap(level->w, level->scratch);
  }
}

// Bilinear prolongation of coarse.w onto fine.w (cell centres: fine i sits at coarse
// i / 2 - 1/4), then projection onto the fine obstacle.
void Prolong(const Level& coarse, Level* fine) {
  auto weights = [](int n, std::vector<int>* index, std::vector<float>* frac) {
    index->resize(n);
    frac->resize(n);
    for (int i = 0; i < n; ++i) {
      const double x = 0.5 * i - 0.25;
      const int i0 = static_cast<int>(std::floor(x));
      (*index)[i] = i0;
      (*frac)[i] = static_cast<float>(x - i0);
    }
  };
  std::vector<int> ri, ci;
  std::vector<float> rf, cf;
  weights(fine->rows, &ri, &rf);
  weights(fine->cols, &ci, &cf);
  for (int r = 0; r < fine->rows; ++r) {
    // Padded coarse rows ri and ri + 1 (both within [-1, coarse.rows]).
    const float* a = coarse.w.data() + coarse.Index(ri[r], 0);
    const float* b = a + coarse.stride();
    float* out = fine->w.data() + fine->Index(r, 0);
    const float* s = fine->obstacle.data() + fine->Index(r, 0);
    const float fr = rf[r];
    for (int c = 0; c < fine->cols; ++c) {
      const int j = ci[c];
      const float fc = cf[c];
      const float top = a[j] + fc * (a[j + 1] - a[j]);
      const float bottom = b[j] + fc * (b[j + 1] - b[j]);
      const float value = top + fr * (bottom - top);
      out[c] = std::max(value, s[c]);
    }
  }
}

}  // namespace

void SolveMembraneObstacle(const std::vector<float>& obstacle, int rows, int cols,
                           double decay_length_px, const MembraneSchedule& schedule,
                           std::vector<float>* w) {
  std::vector<Level> levels(1);
  levels[0].Allocate(rows, cols);
  for (int r = 0; r < rows; ++r) {
    std::copy_n(obstacle.data() + static_cast<std::size_t>(r) * cols, cols,
                levels[0].obstacle.data() + levels[0].Index(r, 0));
  }
  while (true) {
    const Level& fine = levels.back();
    const int r2 = (fine.rows + 1) / 2, c2 = (fine.cols + 1) / 2;
    if (std::min(r2, c2) < schedule.min_coarse_size) break;
    Level coarse;
    coarse.Allocate(r2, c2);
    for (int r = 0; r < r2; ++r) {
      for (int c = 0; c < c2; ++c) {
        // Rows/cols past the fine grid read the zero padding, which never wins.
        const float* p = fine.obstacle.data() + fine.Index(2 * r, 2 * c);
        const float* q = p + fine.stride();
        coarse.obstacle[coarse.Index(r, c)] =
            std::max(std::max(p[0], p[1]), std::max(q[0], q[1]));
      }
    }
    levels.push_back(std::move(coarse));
  }

  const float damping = static_cast<float>(schedule.damping);
  for (int k = static_cast<int>(levels.size()) - 1; k >= 0; --k) {
    Level& level = levels[k];
    const double h_over_l = std::ldexp(1.0, k) / decay_length_px;
    const float inv_diag = static_cast<float>(1.0 / (4.0 + h_over_l * h_over_l));
    int sweeps = schedule.coarse_sweeps;
    if (k == static_cast<int>(levels.size()) - 1) {
      level.w = level.obstacle;
      sweeps = schedule.coarsest_sweeps;
    } else {
      Prolong(levels[k + 1], &level);
    }
    if (k == 0 && levels.size() > 1) sweeps = schedule.finest_sweeps;
    Sweep(&level, inv_diag, damping, sweeps);
    if (k > 0) levels[k].scratch.clear();
  }

  w->resize(static_cast<std::size_t>(rows) * cols);
  for (int r = 0; r < rows; ++r) {
    std::copy_n(levels[0].w.data() + levels[0].Index(r, 0), cols,
                w->data() + static_cast<std::size_t>(r) * cols);
  }
}

}  // namespace tactfunc::internal
