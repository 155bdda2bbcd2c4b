// Copyright 2026 The tactfunc Authors.
#include "models/trunk/latent_modulated_siren.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <memory>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "Eigen/Core"
#include "boost/random/mersenne_twister.hpp"
#include "boost/random/uniform_real_distribution.hpp"
#include "models/trunk/internal/fast_sincos.h"
#include "models/trunk/internal/small_gemm.h"
#include "models/trunk/product_precision.h"

namespace tactfunc {

template <typename Scalar>
double LatentModulatedSiren::MseNormaliser(const VectorX<Scalar>& weights, long n, long channels,
                                           Scalar* gradient_scale) {
  double weight_sum = 0.0;
  if (weights.size() == 0) {
    weight_sum = static_cast<double>(n);
  } else {
    for (long j = 0; j < n; ++j) {
      if (weights[j] != Scalar(0)) weight_sum += weights[j];
    }
  }
  if (weight_sum <= 0.0) {
    *gradient_scale = Scalar(0);
    return 0.0;
  }
  const double normaliser = static_cast<double>(channels) * weight_sum;
  *gradient_scale = static_cast<Scalar>(2.0 / normaliser);
  return 1.0 / normaliser;
}

namespace {

template <typename S>
using MatrixX = LatentModulatedSiren::MatrixX<S>;
template <typename S>
using VectorX = LatentModulatedSiren::VectorX<S>;
template <typename S>
using ConstMap = Eigen::Map<const MatrixX<S>>;

std::string Shape(long rows, long cols) {
  return std::to_string(rows) + "x" + std::to_string(cols);
}

void CheckShape(const char* what, long rows, long cols, long expected_rows,
                long expected_cols) {
  if (rows != expected_rows || cols != expected_cols) {
    throw std::invalid_argument(std::string("LatentModulatedSiren: ") + what +
                                " must be " + Shape(expected_rows, expected_cols) +
                                ", found " + Shape(rows, cols));
  }
}

}  // namespace

namespace internal {
// A trunk's hidden layers' weights W_l and transposes W_l^T packed for bfloat16
// products, for layers 1 .. L-1 (layer 0's product, of the pixel coordinates, stays
// float: its entries are left empty).
struct Bfloat16Weights {
  std::vector<Bfloat16Pairs> W, W_t;
};
}  // namespace internal

namespace {

// Maps of theta's blocks in one scalar type and the hidden layers' weights transposed
// (W_t[l] = W[l]^T): the products W^T delta then read a column-major matrix, which
// internal::Product would otherwise copy per block. For the trunk's own parameters the
// transposes are the ones the trunk stores beside them (made once per parameter update,
// `stored`); for any other theta (a Hessian-vector product's direction) this Net copies
// them, once per call. Copying them per call cost a meta-training step 4 % of its time at
// width 128 and 7 % at width 256 (`tactfunc bench trunk`).
//
// With the trunk's stored transposes also its bfloat16 packs (`packed`, may be null):
// Packed(l) / PackedT(l) give the products of W[l] and W_t[l] their packed copies.
template <typename S>
struct Net {
  std::vector<ConstMap<S>> W, b;  // per hidden layer
  std::vector<ConstMap<S>> W_t;   // per hidden layer, W[l]^T
  ConstMap<S> A, c, W_out, b_out;
  const internal::Bfloat16Weights* packed;
  Net(const S* theta, const std::vector<ParameterBlock>& blocks, int num_layers,
      const std::vector<MatrixX<S>>* stored, const internal::Bfloat16Weights* packed_weights)
      : A(At(theta, blocks[2 * num_layers])),
        c(At(theta, blocks[2 * num_layers + 1])),
        W_out(At(theta, blocks[2 * num_layers + 2])),
        b_out(At(theta, blocks[2 * num_layers + 3])),
        packed(packed_weights) {
    for (int l = 0; l < num_layers; ++l) {
      W.push_back(At(theta, blocks[2 * l]));
      b.push_back(At(theta, blocks[2 * l + 1]));
    }
    if (stored == nullptr) {
      for (const ConstMap<S>& w : W) copies_.push_back(w.transpose());
      stored = &copies_;
    }
    for (const MatrixX<S>& w_t : *stored) W_t.emplace_back(w_t.data(), w_t.rows(), w_t.cols());
  }
  Net(const Net&) = delete;
  Net& operator=(const Net&) = delete;
  static ConstMap<S> At(const S* theta, const ParameterBlock& block) {
    return ConstMap<S>(theta + block.offset, block.rows, block.cols);
  }
  const internal::Bfloat16Pairs* Packed(int l) const { return PackedAt(l, false); }
  const internal::Bfloat16Pairs* PackedT(int l) const { return PackedAt(l, true); }

 private:
  const internal::Bfloat16Pairs* PackedAt(int l, bool transposed) const {
    if (packed == nullptr) return nullptr;
    const std::vector<internal::Bfloat16Pairs>& v = transposed ? packed->W_t : packed->W;
    return v[l].rows > 0 ? &v[l] : nullptr;
  }
  std::vector<MatrixX<S>> copies_;  // W_t's storage when nothing stored them
};

// Pixels per block of every batched pass. Each pass runs over the pixels in blocks of
// at most kPixelBlock columns so that a layer's activations (width x kPixelBlock: 32 KB
// at width 64, 64 KB at width 128, in float) stay in L2 across the GEMM, the sines and
// the reverse pass; gradients and Hessian-vector products are sums over pixels,
// accumulated block by block, and the loss is normalised once over all pixels.
// Measured with Eigen's products (float, one core, d = 64; LossAndGradient w.r.t. z at
// 70x88, 2026-11): width 64 / 3 layers: unblocked 23.2 ms, blocks of 256: 16.9, 512:
// 18.0, 1024: 18.2, 2048: 19.3 ms; width 128 / 4 layers: 63.4, 46.9, 49.2, 51.5, 52.3 ms.
// With the passes' own kernel (internal::Product) blocks of 128 beat 256, alternating
// the two builds (`tactfunc bench trunk`, medians of 4-5 runs, 2026-11-29): the
// meta-training step 225 -> 219 ms at width 128 and 1447 -> 1389 ms at width 256, the
// fit 19.6 -> 18.7 ms at width 128, the same at width 64 (40.6 / 40.0 ms, 4.8 ms): a
// Hessian-vector product's block keeps a dozen width x block matrices, which at 256
// pixels outgrow L2 at width 128. Blocks of 64, so that more of a layer's matrices fit
// L1 at width 64, were slower there in each of three alternated runs (the fit's steps and
// the meta-training step, AVX-512 AMD EPYC, 2026-12-02).
constexpr long kPixelBlock = 128;

// What the forward pass keeps for the reverse passes, for one block of pixels. Every
// matrix holds one pixel per column (features x capacity, of which the first `cols`
// columns are in use), so each layer is one GEMM and sin/cos run over one contiguous
// buffer. The buffers are allocated once per call at block size and reused by every
// block: allocating them per pass cost page faults (glibc returns blocks above its mmap
// threshold to the OS).
template <typename S>
struct Trace {
  std::vector<MatrixX<S>> h;       // h[0] = coords^T (2 x B), h[l+1] width x B
  std::vector<MatrixX<S>> cosine;  // cos(omega_0 pre_l), width x B
  MatrixX<S> y;                    // C x B
  VectorX<S> shift;                // a layer's b_l + gamma_l (RunForward's)
  long cols = 0;                   // pixels in the current block

  Trace(int num_layers, long width, long channels, long capacity, bool keep_cosine)
      : h(num_layers + 1), cosine(keep_cosine ? num_layers : 0) {
    h[0].resize(2, capacity);
    for (int l = 0; l < num_layers; ++l) h[l + 1].resize(width, capacity);
    for (MatrixX<S>& c : cosine) c.resize(width, capacity);
    y.resize(channels, capacity);
  }
};

// Block size for n pixels: at most kPixelBlock, and no larger than n.
long BlockCapacity(long n) { return std::max<long>(1, std::min(n, kPixelBlock)); }

// ---- Spatial latents (header comment): gamma(x) = A_g z_g + c + P w(x) -------------------
// One call's spatial state: the split of z, P = A_s Z ((L*width) x G, one column of shifts
// per node) and the current block's bilinear corners (4 per pixel).
template <typename S>
struct Spatial {
  long d_global = 0;  // d_g
  long channels = 0;  // c_s
  long nodes = 0;     // G
  MatrixX<S> P;       // (L*width) x G
  std::vector<long> node;  // node[4 j + i]: corner i of the block's pixel j
  std::vector<S> weight;   // its bilinear weight
  long cols = 0;           // pixels in the current block

  Spatial(const LatentModulatedSiren::Options& options, long capacity)
      : d_global(options.global_latent_dim()),
        channels(options.spatial_channels),
        nodes(static_cast<long>(options.spatial_rows) * options.spatial_cols),
        node(4 * capacity),
        weight(4 * capacity) {}

  // Z = the node latents of z as a c_s x G matrix (column k: node k's latent).
  ConstMap<S> Nodes(const VectorX<S>& z) const {
    return ConstMap<S>(z.data() + d_global, channels, nodes);
  }
  // A_g (the first d_g columns of A) and A_s (the last c_s).
  auto Global(const ConstMap<S>& A) const { return A.leftCols(d_global); }
  auto Local(const ConstMap<S>& A) const { return A.rightCols(channels); }

  // The corners of every pixel of `coords` (m x 2, one block). A corner of weight 0
  // (on the grid's last row or column, or a pixel on a node) is pointed at corner 0,
  // whose weight is never 0 for a finite coordinate, so that blending it adds exactly 0
  // (LocateSpatial's NaN weights stay NaN).
  template <typename Coords>
  void Locate(const LatentModulatedSiren& siren, const Eigen::MatrixBase<Coords>& coords) {
    cols = coords.rows();
    for (long j = 0; j < cols; ++j) {
      const auto corners = siren.LocateSpatial(static_cast<double>(coords(j, 0)),
                                               static_cast<double>(coords(j, 1)));
      for (int i = 0; i < 4; ++i) {
        node[4 * j + i] = corners.weight[i] == 0.0 ? corners.node[0] : corners.node[i];
        weight[4 * j + i] = static_cast<S>(corners.weight[i]);
      }
    }
  }

  // out (width x m) += rows [row0, row0 + width) of Q (any (L*width) x G matrix of node
  // columns: P or its tangent) blended per pixel: the four corners summed in one pass
  // over the pixel's column (four read-modify-writes of it cost twice as much).
  template <typename Out>
  void Blend(const MatrixX<S>& Q, long row0, Eigen::MatrixBase<Out>& out) const {
    const long width = out.rows();
    for (long j = 0; j < cols; ++j) {
      const long* n = &node[4 * j];
      const S* w = &weight[4 * j];
      out.col(j) += w[0] * Q.col(n[0]).segment(row0, width) +
                    w[1] * Q.col(n[1]).segment(row0, width) +
                    w[2] * Q.col(n[2]).segment(row0, width) +
                    w[3] * Q.col(n[3]).segment(row0, width);
    }
  }

  // Rows [row0, row0 + width) of *dQ ((L*width) x G) += the per-pixel columns of
  // `delta` (width x m) scattered onto the nodes with the same weights. Consecutive
  // pixels with the same four corners (a run along an image row between two grid
  // columns) are summed as one product delta_run (width x len) * W_run (len x 4, their
  // weights) before the four node columns are touched: four read-modify-writes of the
  // node columns per pixel cost about as much as the layer's own reverse GEMM. Runs
  // shorter than kMinRun (a training step's random pixels) are scattered pixel by
  // pixel, where a product per run would cost more than it saves. Measured (`bench
  // trunk --spatial 4x4x4`, width 64, 3 layers, d = 64, one thread, 2026-11): the
  // meta_sgd:3 steps of a whole 70 x 88 frame 13.0 ms pixel by pixel, 12.4 ms by runs
  // (10.5 ms without the grid); a meta-training step of 8 frames x 2048 random pixels
  // 140 ms either way (116 ms without the grid).
  static constexpr long kMinRun = 8;
  template <typename Delta>
  void Scatter(const Eigen::MatrixBase<Delta>& delta, long row0, MatrixX<S>* dQ) const {
    using RunWeights = Eigen::Matrix<S, Eigen::Dynamic, 4, Eigen::RowMajor>;
    const long width = delta.rows();
    MatrixX<S>& sums = run_sums;
    sums.resize(width, 4);
    for (long begin = 0; begin < cols;) {
      const long* n = &node[4 * begin];
      long end = begin + 1;
      while (end < cols && std::equal(n, n + 4, &node[4 * end])) ++end;
      if (end - begin < kMinRun) {  // random pixel subsets: runs of one, no product
        for (long j = begin; j < end; ++j) {
          for (int i = 0; i < 4; ++i) {
            dQ->col(n[i]).segment(row0, width) += weight[4 * j + i] * delta.col(j);
          }
        }
      } else {
        const Eigen::Map<const RunWeights> w(&weight[4 * begin], end - begin, 4);
        sums.noalias() = delta.middleCols(begin, end - begin) * w;
        for (int i = 0; i < 4; ++i) dQ->col(n[i]).segment(row0, width) += sums.col(i);
      }
      begin = end;
    }
  }
  mutable MatrixX<S> run_sums;  // Scatter's width x 4 buffer (one per call's Spatial)
};

// Forward pass over `coords` (m x 2, one block of pixels) with shifts gamma = A z + c.
// With spatial latents (spatial not null, its corners located for this block) gamma
// is A_g z_g + c and each pixel adds its blend of the columns of spatial->P.
template <typename S, typename Coords>
void RunForward(const Net<S>& net, double omega_0, const Eigen::MatrixBase<Coords>& coords,
                const VectorX<S>& gamma, const Spatial<S>* spatial, Trace<S>* trace) {
  const int num_layers = static_cast<int>(net.W.size());
  const long m = coords.rows();
  const long width = net.b[0].rows();
  const bool keep_cosine = !trace->cosine.empty();
  trace->cols = m;
  trace->h[0].leftCols(m) = coords.transpose();
  for (int l = 0; l < num_layers; ++l) {
    auto pre = trace->h[l + 1].leftCols(m);
    // The product's sums start from the shifts (no pass over `pre` to set them first).
    trace->shift = net.b[l].col(0) + gamma.segment(l * width, width);
    internal::ProductPlusOffset(net.W[l], trace->h[l].leftCols(m), trace->shift, pre,
                                net.Packed(l));
    if (spatial != nullptr) spatial->Blend(spatial->P, l * width, pre);
    S* cosine = keep_cosine ? trace->cosine[l].data() : nullptr;
    internal::ScaledSinCos(width * m, static_cast<S>(omega_0), pre.data(), pre.data(),
                           cosine);
  }
  auto y = trace->y.leftCols(m);
  y.noalias() = net.W_out * trace->h[num_layers].leftCols(m);
  y.colwise() += net.b_out.col(0);
}

// dL/dpre_l = dL/dh_{l+1} (*) omega_0 cos(omega_0 pre_l) (element-wise) into *out: the one
// expression of it, so that the reverse pass and the Hessian-vector product, which
// recomputes it from a kept dL/dh_{l+1}, round alike.
template <typename S, typename GradH, typename Cosine, typename Out>
void PreActivationGradient(const Eigen::MatrixBase<GradH>& g,
                           const Eigen::MatrixBase<Cosine>& cosine, S omega,
                           Eigen::MatrixBase<Out>* out) {
  out->array() = g.array() * (omega * cosine.array());
}

// The element-wise passes below each go once over a block's values, column by column
// (the blocks are column-major, one pixel per column), where Eigen expressions would
// take two passes: a Hessian-vector product's block keeps a dozen width x block
// matrices, and these passes are bound by moving them, not by arithmetic.
//
// Each works on one column of `rows` values. GCC vectorises these loops only with
// their pointers __restrict parameters of a function (as locals in the callers' loops
// it kept them scalar, and the meta-training step took 8-22 % longer). Where a pass keeps
// no per-row sum, one call over a block's columns (contiguous) was no faster than one
// call per column (ColumnScaleAndModulate in the tangent pass, width 64, 2026-12-02); and
// keeping the row sums of 64 rows in registers across a block's columns, instead of
// loading and storing them per column, took about a tenth off these passes' share of a
// width-64 meta-training step's samples, too little to time on this machine, so the
// simpler form stays.
template <typename S>
void ColumnPreActivationGradientAndSum(long rows, S omega, const S* __restrict g,
                                       const S* __restrict cosine, S* __restrict delta,
                                       S* __restrict sum) {
  for (long i = 0; i < rows; ++i) {
    const S d = g[i] * (omega * cosine[i]);
    delta[i] = d;
    sum[i] += d;
  }
}
// s <- omega s; h' = cos .* s.
template <typename S>
void ColumnScaleAndModulate(long rows, S omega, S* __restrict s, const S* __restrict cosine,
                            S* __restrict h_dot) {
  for (long i = 0; i < rows; ++i) {
    const S v = s[i] * omega;
    s[i] = v;
    h_dot[i] = cosine[i] * v;
  }
}
// dd = omega (g' .* cos - g .* sin .* s'); sum += dd.
template <typename S>
void ColumnTangentPreActivationGradientAndSum(long rows, S omega, const S* __restrict g_dot,
                                              const S* __restrict g, const S* __restrict cosine,
                                              const S* __restrict sine, const S* __restrict s_dot,
                                              S* __restrict dd, S* __restrict sum) {
  for (long i = 0; i < rows; ++i) {
    const S v = omega * (g_dot[i] * cosine[i] - g[i] * sine[i] * s_dot[i]);
    dd[i] = v;
    sum[i] += v;
  }
}

// delta = g .* (omega cos), as PreActivationGradient, and row_sum[i] += sum_j delta(i, j)
// (the block's share of dL/dgamma) in the same pass.
template <typename S, typename GradH, typename Cosine, typename Out>
void PreActivationGradientAndRowSum(const Eigen::MatrixBase<GradH>& g,
                                    const Eigen::MatrixBase<Cosine>& cosine, S omega,
                                    Eigen::MatrixBase<Out>* out, S* row_sum) {
  const long rows = g.rows();
  for (long j = 0; j < g.cols(); ++j) {
    ColumnPreActivationGradientAndSum(rows, omega, g.derived().data() + j * g.outerStride(),
                                      cosine.derived().data() + j * cosine.outerStride(),
                                      out->derived().data() + j * out->outerStride(), row_sum);
  }
}

// Reverse pass of one block from G = dL/dY^T (C x m). The trace must hold the cosines.
// (*g)[l] receives dL/dh_{l+1} (width x >= m) for every layer l, or, if g holds one
// matrix, that one serves every layer in turn; *delta (width x >= m) is a work buffer.
// Adds the block's dL/dgamma to *dgamma and, if dL_dtheta is not null, its share of
// dL/dW_l, dL/dW_out and dL/db_out to those blocks of *dL_dtheta; the blocks that
// depend on pixels only through dgamma (b_l, A, c) are left to FinishGradient. With
// spatial latents (spatial not null) it also scatters each pixel's dL/dgamma onto the
// grid's nodes, *dP ((L*width) x G) += sum_j dL/dgamma(x_j) w(x_j)^T.
template <typename S, typename GradY>
void RunBackwardBlock(const Net<S>& net, const std::vector<ParameterBlock>& blocks,
                      double omega_0, const Trace<S>& trace,
                      const Eigen::MatrixBase<GradY>& G, std::vector<MatrixX<S>>* g,
                      MatrixX<S>* delta_buffer, const Spatial<S>* spatial,
                      VectorX<S>* dgamma, MatrixX<S>* dP, VectorX<S>* dL_dtheta,
                      bool first_layer_weights_only = false) {
  const int num_layers = static_cast<int>(net.W.size());
  const long width = net.b[0].rows();
  const long m = trace.cols;
  const S omega = static_cast<S>(omega_0);
  auto block = [&](int index) {
    return LatentModulatedSiren::View(dL_dtheta, blocks[index]);
  };
  auto layer_g = [&](int l) { return (*g)[g->size() == 1 ? 0 : l].leftCols(m); };
  if (dL_dtheta != nullptr) {
    if (!first_layer_weights_only) {
      block(2 * num_layers + 2).noalias() += G * trace.h[num_layers].leftCols(m).transpose();
    }
    block(2 * num_layers + 3) += G.rowwise().sum();
  }
  internal::Product(net.W_out.transpose(), G, layer_g(num_layers - 1), /*accumulate=*/false);
  auto delta = delta_buffer->leftCols(m);
  for (int l = num_layers - 1; l >= 0; --l) {
    PreActivationGradientAndRowSum(layer_g(l), trace.cosine[l].leftCols(m), omega, &delta,
                                   dgamma->data() + l * width);
    if (spatial != nullptr) spatial->Scatter(delta, l * width, dP);
    if (dL_dtheta != nullptr && (l == 0 || !first_layer_weights_only)) {
      internal::Product(delta, trace.h[l].leftCols(m).transpose(), block(2 * l),
                        /*accumulate=*/true);
    }
    if (l > 0) internal::Product(net.W_t[l], delta, layer_g(l - 1), false, net.PackedT(l));
  }
}

// The gradient's pixel-independent parts from the accumulated dL/dgamma:
// dL/db_l = dgamma_l, dL/dA = dgamma z^T, dL/dc = dgamma, dL/dz = A^T dgamma; with
// spatial latents (spatial not null, dP the scattered dL/dgamma) dL/dA = [dgamma z_g^T |
// dP Z^T], dL/dz_g = A_g^T dgamma, dL/dZ = A_s^T dP.
template <typename S>
void FinishGradient(const Net<S>& net, const std::vector<ParameterBlock>& blocks,
                    const VectorX<S>& dgamma, const VectorX<S>& z,
                    const Spatial<S>* spatial, const MatrixX<S>* dP, VectorX<S>* dL_dz,
                    VectorX<S>* dL_dtheta) {
  const int num_layers = static_cast<int>(net.W.size());
  const long width = net.b[0].rows();
  if (dL_dtheta != nullptr) {
    auto block = [&](int index) {
      return LatentModulatedSiren::View(dL_dtheta, blocks[index]);
    };
    for (int l = 0; l < num_layers; ++l) {
      block(2 * l + 1) = dgamma.segment(l * width, width);
    }
    if (spatial == nullptr) {
      block(2 * num_layers).noalias() = dgamma * z.transpose();
    } else {
      auto dA = block(2 * num_layers);
      dA.leftCols(spatial->d_global).noalias() =
          dgamma * z.head(spatial->d_global).transpose();
      dA.rightCols(spatial->channels).noalias() = *dP * spatial->Nodes(z).transpose();
    }
    block(2 * num_layers + 1) = dgamma;
  }
  if (dL_dz == nullptr) return;
  if (spatial == nullptr) {
    *dL_dz = net.A.transpose() * dgamma;
    return;
  }
  dL_dz->resize(z.size());
  dL_dz->head(spatial->d_global).noalias() = spatial->Global(net.A).transpose() * dgamma;
  Eigen::Map<MatrixX<S>>(dL_dz->data() + spatial->d_global, spatial->channels,
                         spatial->nodes)
      .noalias() = spatial->Local(net.A).transpose() * *dP;
}

// The shifts every pixel shares: gamma = A z + c, or A_g z_g + c with spatial latents,
// whose *spatial then gets P = A_s Z.
template <typename S>
VectorX<S> SharedShifts(const Net<S>& net, const VectorX<S>& z, Spatial<S>* spatial) {
  if (spatial == nullptr) return net.A * z + net.c;
  spatial->P.noalias() = spatial->Local(net.A) * spatial->Nodes(z);
  return spatial->Global(net.A) * z.head(spatial->d_global) + net.c;
}

// ---- The linear readout branch (header comment): y += R(x) z + m(x) ------------------
// Every batched pass computes the per-node values u = R^T z + m once (G C numbers),
// interpolates them per pixel, and scatters a block's dL/dY back onto the nodes
// (s = sum over pixels of the bilinear weight times dL/dy); the pixel-independent parts
// follow from s: dL/dz += R s, dL/dR = z s^T, dL/dm = s.
template <typename S>
struct ReadoutMaps {
  ConstMap<S> R;  // d x (G C)
  ConstMap<S> m;  // (G C) x 1
  ReadoutMaps(const S* theta, const std::vector<ParameterBlock>& blocks, int num_layers)
      : R(Net<S>::At(theta, blocks[2 * num_layers + 4])),
        m(Net<S>::At(theta, blocks[2 * num_layers + 5])) {}
};

// Calls visit(j, ch, k, w) for every pixel j of `coords` (m x 2), every channel ch < channels
// and every grid corner of the pixel with a non-zero bilinear weight w, k = node * C + ch
// the corner's entry in a node-major (G C) vector.
template <typename S, typename Coords, typename Visit>
void ForEachReadoutCorner(const LatentModulatedSiren& siren, const Eigen::MatrixBase<Coords>& coords,
                          long channels, Visit&& visit) {
  for (long j = 0; j < coords.rows(); ++j) {
    const auto corners = siren.LocateReadout(static_cast<double>(coords(j, 0)),
                                             static_cast<double>(coords(j, 1)));
    for (int i = 0; i < 4; ++i) {
      const S w = static_cast<S>(corners.weight[i]);
      if (w == S(0)) continue;
      for (long ch = 0; ch < channels; ++ch) visit(j, ch, corners.node[i] * channels + ch, w);
    }
  }
}

// Adds the interpolated node values u (G C) to Y (C x m, one pixel per column) for the
// pixels `coords` (m x 2).
template <typename S, typename Coords, typename Out>
void AddReadout(const LatentModulatedSiren& siren, const Eigen::MatrixBase<Coords>& coords,
                const VectorX<S>& u, Eigen::MatrixBase<Out>& Y) {
  ForEachReadoutCorner<S>(siren, coords, Y.rows(),
                          [&](long j, long ch, long k, S w) { Y(ch, j) += w * u[k]; });
}

// s (G C) += the bilinear scatter of G (C x m) for the pixels `coords` (m x 2).
template <typename S, typename Coords, typename Grad>
void ScatterReadout(const LatentModulatedSiren& siren, const Eigen::MatrixBase<Coords>& coords,
                    const Eigen::MatrixBase<Grad>& G, VectorX<S>* s) {
  ForEachReadoutCorner<S>(siren, coords, G.rows(),
                          [&](long j, long ch, long k, S w) { (*s)[k] += w * G(ch, j); });
}

// The readout's share of the gradient from the scattered s: dL/dz += R s, and the
// blocks dL/dR = z s^T, dL/dm = s of *dL_dtheta (if not null).
template <typename S>
void FinishReadoutGradient(const ReadoutMaps<S>& readout,
                           const std::vector<ParameterBlock>& blocks, int num_layers,
                           const VectorX<S>& s, const VectorX<S>& z, VectorX<S>* dL_dz,
                           VectorX<S>* dL_dtheta) {
  if (dL_dtheta != nullptr) {
    LatentModulatedSiren::View(dL_dtheta, blocks[2 * num_layers + 4]).noalias() =
        z * s.transpose();
    LatentModulatedSiren::View(dL_dtheta, blocks[2 * num_layers + 5]) = s;
  }
  if (dL_dz != nullptr) dL_dz->noalias() += readout.R * s;
}

// One block's dL/dY^T (C x m) of the weighted MSE into G's first m columns, given the
// global *scale of LatentModulatedSiren::MseNormaliser; returns the block's
// sum_j w_j ||r_j||^2 (unnormalised).
// w_j = 0 pixels get exactly 0, whatever their target (NaN included); so does every
// pixel when scale = 0 (no valid pixel at all).
template <typename S>
double BlockResidualGradient(const Trace<S>& trace, const MatrixX<S>& targets,
                             const VectorX<S>& weights, long begin, S scale,
                             MatrixX<S>* G) {
  const long m = trace.cols;
  const long channels = trace.y.rows();
  if (scale == S(0)) {
    G->leftCols(m).setZero();
    return 0.0;
  }
  double loss = 0.0;
  for (long j = 0; j < m; ++j) {
    const S w = weights.size() == 0 ? S(1) : weights[begin + j];
    if (w == S(0)) {
      G->col(j).setZero();
      continue;
    }
    for (long ch = 0; ch < channels; ++ch) {
      const S r = trace.y(ch, j) - targets(begin + j, ch);
      (*G)(ch, j) = scale * (w * r);
      loss += static_cast<double>(w * r * r);
    }
  }
  return loss;
}

// ---- The loss passes: LossGradientAndHessianProduct, a Tape's recording and reading --

// Shapes of a loss pass's inputs (coords N x 2, z d, targets N x C, weights N or empty)
// and of a Hessian-vector product's direction (v_theta may be null).
template <typename S>
void CheckLossInputs(const LatentModulatedSiren& siren, const MatrixX<S>& coords,
                     const VectorX<S>& z, const MatrixX<S>& targets,
                     const VectorX<S>& weights) {
  const long n = coords.rows();
  CheckShape("coords", n, coords.cols(), n, 2);
  CheckShape("z", z.rows(), 1, siren.latent_dim(), 1);
  CheckShape("targets", targets.rows(), targets.cols(), n, siren.output_channels());
  if (weights.size() != 0) CheckShape("weights", weights.rows(), 1, n, 1);
}
template <typename S>
void CheckDirection(const LatentModulatedSiren& siren, const VectorX<S>* v_theta,
                    const VectorX<S>& v_z) {
  CheckShape("v_z", v_z.rows(), 1, siren.latent_dim(), 1);
  if (v_theta != nullptr) CheckShape("v_theta", v_theta->rows(), 1, siren.NumParameters(), 1);
}

// What the passes of one call share: theta's maps, the spatial latents' state (corners
// located per block) and the readout branch's maps.
template <typename S>
struct PassContext {
  const LatentModulatedSiren& siren;
  const std::vector<ParameterBlock>& blocks;
  const int num_layers;
  const long width, channels;
  const double omega_0;
  const Net<S> net;
  std::unique_ptr<Spatial<S>> spatial;      // with spatial latents
  std::unique_ptr<ReadoutMaps<S>> readout;  // with the readout branch

  // theta and its hidden layers' weights transposed and packed (the trunk's, as it
  // stores them).
  PassContext(const LatentModulatedSiren& trunk, const S* theta,
              const std::vector<MatrixX<S>>& transposed,
              const internal::Bfloat16Weights* packed, long capacity)
      : siren(trunk),
        blocks(trunk.parameter_blocks()),
        num_layers(trunk.num_hidden_layers()),
        width(trunk.width()),
        channels(trunk.output_channels()),
        omega_0(trunk.options().omega_0),
        net(theta, blocks, num_layers, &transposed, packed) {
    if (trunk.has_spatial()) spatial = std::make_unique<Spatial<S>>(trunk.options(), capacity);
    if (trunk.has_readout()) readout = std::make_unique<ReadoutMaps<S>>(theta, blocks, num_layers);
  }
};

// One block's primal values as the Hessian-vector product reads them: the forward
// trace (with the cosines), G = dL/dY^T (C x m) and the reverse pass's dL/dh_{l+1} per
// layer l (g; one matrix serving every layer in turn when they are not kept).
template <typename S>
struct BlockRecord {
  Trace<S> trace;
  MatrixX<S> G;
  std::vector<MatrixX<S>> g;
  BlockRecord(int num_layers, long width, long channels, long capacity, bool reverse,
              bool keep_layers)
      : trace(num_layers, width, channels, capacity, /*keep_cosine=*/reverse),
        G(channels, capacity),
        g(reverse ? (keep_layers ? num_layers : 1) : 0) {
    // Each resized, not copied from a prototype: copying one matrix's uninitialised
    // values into each cost 1 % of a meta-training step.
    for (MatrixX<S>& layer : g) layer.resize(width, capacity);
  }
};

// The loss over blocks of pixels and, if `reverse`, the reverse pass: dL/dgamma summed
// over blocks (dgamma), its scatter onto the spatial nodes (dP), the readout branch's
// scattered dL/dY (scatter), and dL/dtheta's pixel-dependent blocks.
template <typename S>
struct LossPass {
  const PassContext<S>& context;
  const bool reverse;
  VectorX<S>* const dL_dtheta;
  VectorX<S> gamma;  // the shifts every pixel shares (SharedShifts)
  VectorX<S> u;      // the readout's node values R^T z + m
  S scale = 0;       // LatentModulatedSiren::MseNormaliser's
  double inverse_normaliser = 0;
  double loss = 0;   // sum_j w_j ||r_j||^2 so far
  VectorX<S> dgamma, scatter;
  MatrixX<S> dP, delta;  // delta: RunBackwardBlock's work buffer

  LossPass(PassContext<S>& c, const VectorX<S>& z, const VectorX<S>& weights, long n,
           long capacity, bool reverse_pass, VectorX<S>* theta_gradient)
      : context(c), reverse(reverse_pass), dL_dtheta(theta_gradient) {
    gamma = SharedShifts(c.net, z, c.spatial.get());
    if (c.readout) u = c.readout->R.transpose() * z + c.readout->m;
    inverse_normaliser = LatentModulatedSiren::MseNormaliser(weights, n, c.channels, &scale);
    if (dL_dtheta != nullptr) dL_dtheta->setZero(c.siren.NumParameters());
    if (!reverse) return;
    dgamma.setZero(c.num_layers * c.width);
    if (c.spatial) dP.setZero(c.num_layers * c.width, c.spatial->nodes);
    if (c.readout) scatter.setZero(u.size());
    delta.resize(c.width, capacity);
  }

  // Pixels [begin, begin + m) into *record (the spatial corners are located for them).
  void Block(const MatrixX<S>& coords, const MatrixX<S>& targets, const VectorX<S>& weights,
             long begin, long m, BlockRecord<S>* record) {
    const PassContext<S>& c = context;
    const auto block_coords = coords.middleRows(begin, m);
    if (c.spatial) c.spatial->Locate(c.siren, block_coords);
    RunForward(c.net, c.omega_0, block_coords, gamma, c.spatial.get(), &record->trace);
    if (c.readout) {
      auto y = record->trace.y.leftCols(m);
      AddReadout(c.siren, block_coords, u, y);
    }
    loss += BlockResidualGradient(record->trace, targets, weights, begin, scale, &record->G);
    if (!reverse) return;
    const auto Gm = record->G.leftCols(m);
    if (c.readout) ScatterReadout(c.siren, block_coords, Gm, &scatter);
    RunBackwardBlock(c.net, c.blocks, c.omega_0, record->trace, Gm, &record->g, &delta,
                     c.spatial.get(), &dgamma, &dP, dL_dtheta);
  }

  // dL/dz (may be null) and the rest of dL/dtheta from the sums.
  void Finish(const VectorX<S>& z, VectorX<S>* dL_dz) const {
    const PassContext<S>& c = context;
    FinishGradient(c.net, c.blocks, dgamma, z, c.spatial.get(), &dP, dL_dz, dL_dtheta);
    if (c.readout) {
      FinishReadoutGradient(*c.readout, c.blocks, c.num_layers, scatter, z, dL_dz,
                            c.siren.readout_frozen() ? nullptr : dL_dtheta);
    }
  }

  S Loss() const { return static_cast<S>(loss * inverse_normaliser); }
};

// The Hessian-vector product (Pearlmutter's R-operator, written with dots: theta' =
// v_theta, z' = v_z): the tangent of the forward pass, then of the reverse pass, block
// by block from the blocks' primal values (BlockRecord, with every layer's dL/dh kept),
// and finally from the reverse pass's sums (LossPass's dgamma, dP, scatter).
template <typename S>
struct TangentPass {
  const PassContext<S>& context;
  std::unique_ptr<Net<S>> dnet;              // theta' (v_theta not null)
  std::unique_ptr<ReadoutMaps<S>> dreadout;  // R', m' (v_theta not null, branch not frozen)
  VectorX<S> dgamma_dot;                     // gamma', the shared part
  VectorX<S> shift_dot;                      // one layer's b_l' + gamma_l' (Block's)
  MatrixX<S> P_dot;                          // P' (spatial latents)
  VectorX<S> u_dot;                          // the readout's node values' tangent
  // h_dot[l]: tangent of h_l (h_dot[0] = 0); s_dot[l] = omega_0 * pre_l'.
  std::vector<MatrixX<S>> h_dot, s_dot;
  MatrixX<S> y_dot, G_dot, g_dot, dm, ddm;
  // Summed over blocks: the tangents of dgamma, dP and scatter.
  VectorX<S> ddgamma, scatter_dot;
  MatrixX<S> ddP;
  VectorX<S> hv_storage;
  VectorX<S>* hv;  // Hv_theta, or hv_storage (the theta blocks are cheap by-products)

  TangentPass(const PassContext<S>& c, const VectorX<S>& z, const VectorX<S>* v_theta,
              const VectorX<S>& v_z, long capacity, VectorX<S>* Hv_theta)
      : context(c), hv(Hv_theta != nullptr ? Hv_theta : &hv_storage) {
    const int num_layers = c.num_layers;
    const long width = c.width;
    if (v_theta != nullptr) {
      dnet = std::make_unique<Net<S>>(v_theta->data(), c.blocks, num_layers, nullptr, nullptr);
    }
    if (c.spatial) {
      // gamma' = A_g v_zg + A_g' z_g + c' shared, P' = A_s V + A_s' Z per node.
      const long dg = c.spatial->d_global;
      dgamma_dot = c.spatial->Global(c.net.A) * v_z.head(dg);
      P_dot.noalias() = c.spatial->Local(c.net.A) * c.spatial->Nodes(v_z);
      if (dnet) {
        dgamma_dot += c.spatial->Global(dnet->A) * z.head(dg) + dnet->c;
        P_dot.noalias() += c.spatial->Local(dnet->A) * c.spatial->Nodes(z);
      }
      ddP.setZero(num_layers * width, c.spatial->nodes);
    } else {
      dgamma_dot = c.net.A * v_z;
      if (dnet) dgamma_dot += dnet->A * z + dnet->c;
    }
    ddgamma.setZero(num_layers * width);
    hv->setZero(c.siren.NumParameters());
    h_dot.resize(num_layers + 1);
    s_dot.resize(num_layers);
    for (int l = 0; l < num_layers; ++l) {
      h_dot[l + 1].resize(width, capacity);
      s_dot[l].resize(width, capacity);
    }
    y_dot.resize(c.channels, capacity);
    G_dot.resize(c.channels, capacity);
    for (MatrixX<S>* buffer : {&g_dot, &dm, &ddm}) buffer->resize(width, capacity);
    if (c.readout) {
      u_dot = c.readout->R.transpose() * v_z;
      if (v_theta != nullptr && !c.siren.readout_frozen()) {
        dreadout = std::make_unique<ReadoutMaps<S>>(v_theta->data(), c.blocks, num_layers);
        u_dot += dreadout->R.transpose() * z + dreadout->m;
      }
      scatter_dot.setZero(u_dot.size());
    }
  }

  // Pixels [begin, begin + m) of coords and weights, whose primal values `record` holds
  // (the spatial corners located for them); scale as LossPass's.
  void Block(const BlockRecord<S>& record, const MatrixX<S>& coords,
             const VectorX<S>& weights, long begin, long m, S scale) {
    const PassContext<S>& c = context;
    const Net<S>& net = c.net;
    const int num_layers = c.num_layers;
    const long width = c.width;
    const S omega = static_cast<S>(c.omega_0);
    const Trace<S>& trace = record.trace;
    const auto block_coords = coords.middleRows(begin, m);
    auto hv_block = [&](int index) { return LatentModulatedSiren::View(hv, c.blocks[index]); };
    // Tangent forward pass.
    for (int l = 0; l < num_layers; ++l) {
      auto s = s_dot[l].leftCols(m);
      // pre_l' = W_l h_l' + W_l' h_l + b_l' + gamma_l', the products' sums started from
      // the shifts' tangent (no pass over s to add it afterwards).
      shift_dot = dgamma_dot.segment(l * width, width);
      if (dnet) shift_dot += dnet->b[l].col(0);
      if (l > 0) {
        internal::ProductPlusOffset(net.W[l], h_dot[l].leftCols(m), shift_dot, s, net.Packed(l));
        if (dnet) internal::Product(dnet->W[l], trace.h[l].leftCols(m), s, /*accumulate=*/true);
      } else if (dnet) {
        internal::ProductPlusOffset(dnet->W[l], trace.h[l].leftCols(m), shift_dot, s);
      } else {  // h_0' = 0
        s.colwise() = shift_dot;
      }
      if (c.spatial) c.spatial->Blend(P_dot, l * width, s);
      // s *= omega, h_dot_{l+1} = cos .* s, in one pass.
      for (long j = 0; j < m; ++j) {
        ColumnScaleAndModulate(width, omega, s_dot[l].col(j).data(), trace.cosine[l].col(j).data(),
                               h_dot[l + 1].col(j).data());
      }
    }
    auto yd = y_dot.leftCols(m);
    yd.noalias() = net.W_out * h_dot[num_layers].leftCols(m);
    if (dnet) {
      yd.noalias() += dnet->W_out * trace.h[num_layers].leftCols(m);
      yd.colwise() += dnet->b_out.col(0);
    }
    if (c.readout) AddReadout(c.siren, block_coords, u_dot, yd);
    // G' = scale * w * y' (zero where w = 0).
    auto Gd = G_dot.leftCols(m);
    Gd = scale * yd;
    if (weights.size() != 0) Gd *= weights.segment(begin, m).asDiagonal();
    if (c.readout) ScatterReadout(c.siren, block_coords, Gd, &scatter_dot);

    // The reverse pass's tangent, from the reverse pass's dL/dh_{l+1} (gm) kept in the
    // record; dm = dL/dpre_l is recomputed from it as the reverse pass computed it.
    const auto Gm = record.G.leftCols(m);
    const auto h_top = trace.h[num_layers].leftCols(m);
    hv_block(2 * num_layers + 2).noalias() += Gd * h_top.transpose();
    hv_block(2 * num_layers + 2).noalias() += Gm * h_dot[num_layers].leftCols(m).transpose();
    hv_block(2 * num_layers + 3) += Gd.rowwise().sum();
    auto gdm = g_dot.leftCols(m);
    auto dmm = dm.leftCols(m);
    auto ddmm = ddm.leftCols(m);
    internal::Product(net.W_out.transpose(), Gd, gdm, /*accumulate=*/false);
    if (dnet) internal::Product(dnet->W_out.transpose(), Gm, gdm, /*accumulate=*/true);
    for (int l = num_layers - 1; l >= 0; --l) {
      const auto gm = record.g[l].leftCols(m);
      const auto cosine = trace.cosine[l].leftCols(m);
      // d/dpre cos(omega pre) = -omega sin(omega pre); s_dot already holds omega pre'.
      // ddm = omega (g' .* cos - g .* sin .* s'), its row sums added to ddgamma_l, in one
      // pass.
      for (long j = 0; j < m; ++j) {
        ColumnTangentPreActivationGradientAndSum(width, omega, gdm.col(j).data(), gm.col(j).data(),
                                                 cosine.col(j).data(), trace.h[l + 1].col(j).data(),
                                                 s_dot[l].col(j).data(), ddmm.col(j).data(),
                                                 ddgamma.data() + l * width);
      }
      if (c.spatial) c.spatial->Scatter(ddmm, l * width, &ddP);
      const auto h_below = trace.h[l].leftCols(m);
      internal::Product(ddmm, h_below.transpose(), hv_block(2 * l), /*accumulate=*/true);
      if (l == 0) break;  // h_dot[0] = 0, and nothing lies below
      PreActivationGradient(gm, cosine, omega, &dmm);
      internal::Product(dmm, h_dot[l].leftCols(m).transpose(), hv_block(2 * l),
                        /*accumulate=*/true);
      internal::Product(net.W_t[l], ddmm, gdm, /*accumulate=*/false, net.PackedT(l));
      if (dnet) internal::Product(dnet->W_t[l], dmm, gdm, /*accumulate=*/true);
    }
  }

  // Hv_theta's pixel-independent blocks and Hv_z (may be null) from the reverse pass's
  // sums (dgamma, dP with spatial latents, scatter with the readout branch).
  void Finish(const VectorX<S>& z, const VectorX<S>& v_z, const VectorX<S>& dgamma,
              const MatrixX<S>& dP, const VectorX<S>& scatter, VectorX<S>* Hv_z) {
    const PassContext<S>& c = context;
    const int num_layers = c.num_layers;
    const long width = c.width;
    auto hv_block = [&](int index) { return LatentModulatedSiren::View(hv, c.blocks[index]); };
    for (int l = 0; l < num_layers; ++l) {
      hv_block(2 * l + 1) = ddgamma.segment(l * width, width);
    }
    hv_block(2 * num_layers + 1) = ddgamma;
    if (c.spatial) {
      // g_A = [dgamma z_g^T | dP Z^T] and g_z = [A_g^T dgamma; A_s^T dP] differentiated
      // along (v_theta, v_z).
      const Spatial<S>& spatial = *c.spatial;
      const long dg = spatial.d_global, cs = spatial.channels;
      auto hv_A = hv_block(2 * num_layers);
      hv_A.leftCols(dg).noalias() =
          ddgamma * z.head(dg).transpose() + dgamma * v_z.head(dg).transpose();
      hv_A.rightCols(cs).noalias() =
          ddP * spatial.Nodes(z).transpose() + dP * spatial.Nodes(v_z).transpose();
      if (Hv_z != nullptr) {
        Hv_z->resize(z.size());
        auto hv_nodes = Eigen::Map<MatrixX<S>>(Hv_z->data() + dg, cs, spatial.nodes);
        Hv_z->head(dg).noalias() = spatial.Global(c.net.A).transpose() * ddgamma;
        hv_nodes.noalias() = spatial.Local(c.net.A).transpose() * ddP;
        if (dnet) {
          Hv_z->head(dg).noalias() += spatial.Global(dnet->A).transpose() * dgamma;
          hv_nodes.noalias() += spatial.Local(dnet->A).transpose() * dP;
        }
      }
    } else {
      hv_block(2 * num_layers).noalias() = ddgamma * z.transpose() + dgamma * v_z.transpose();
      if (Hv_z != nullptr) {
        *Hv_z = c.net.A.transpose() * ddgamma;
        if (dnet) Hv_z->noalias() += dnet->A.transpose() * dgamma;
      }
    }
    if (c.readout) {
      // g_z's readout term R s has the tangent R s' + R' s; g_R = z s^T has v_z s^T +
      // z s'^T; g_m = s has s'.
      if (Hv_z != nullptr) {
        Hv_z->noalias() += c.readout->R * scatter_dot;
        if (dreadout) Hv_z->noalias() += dreadout->R * scatter;
      }
      if (!c.siren.readout_frozen()) {
        hv_block(2 * num_layers + 4).noalias() =
            v_z * scatter.transpose() + z * scatter_dot.transpose();
        hv_block(2 * num_layers + 5) = scatter_dot;
      }
    }
  }
};

// A Recording (header) serves `caller` only if it holds a record, made with the
// parameters the trunk has now (`generation`).
void CheckRecording(bool empty, std::uint64_t recorded_generation, std::uint64_t generation,
                    const char* caller, const char* what) {
  if (!empty && recorded_generation == generation) return;
  throw std::invalid_argument(std::string("LatentModulatedSiren::") + caller + ": the " + what +
                              (empty ? " is empty"
                                     : " was recorded with other parameters than this trunk's"));
}

// What each kind of Recording (header) holds.
template <typename Scalar, typename Kind>
struct RecordOf;

// Forward's: the inputs and every block's trace, cosines included.
template <typename Scalar>
struct RecordOf<Scalar, LatentModulatedSiren::ForwardKind> {
  std::uint64_t parameters_generation = 0;
  MatrixX<Scalar> coords;
  VectorX<Scalar> z;
  std::vector<Trace<Scalar>> blocks;  // pixels [b kPixelBlock, ...) in blocks[b]
};

// LossAndGradient's (a Tape): the inputs the tangent pass reads again, every block's
// primal values (every layer's dL/dh kept) and the reverse pass's sums.
template <typename Scalar>
struct RecordOf<Scalar, LatentModulatedSiren::TapeKind> {
  std::uint64_t parameters_generation = 0;
  MatrixX<Scalar> coords;
  VectorX<Scalar> z, weights;
  Scalar scale = 0;
  std::vector<BlockRecord<Scalar>> blocks;  // pixels [b kPixelBlock, ...) in blocks[b]
  VectorX<Scalar> dgamma, scatter;
  MatrixX<Scalar> dP;
};

}  // namespace

template <typename Scalar, typename Kind>
struct LatentModulatedSiren::Recording<Scalar, Kind>::Record : RecordOf<Scalar, Kind> {};

template <typename Scalar, typename Kind>
LatentModulatedSiren::Recording<Scalar, Kind>::Recording() = default;
template <typename Scalar, typename Kind>
LatentModulatedSiren::Recording<Scalar, Kind>::~Recording() = default;
template <typename Scalar, typename Kind>
LatentModulatedSiren::Recording<Scalar, Kind>::Recording(Recording&& other) noexcept = default;
template <typename Scalar, typename Kind>
LatentModulatedSiren::Recording<Scalar, Kind>& LatentModulatedSiren::Recording<Scalar, Kind>::
operator=(Recording&& other) noexcept = default;

// ---- Names -----------------------------------------------------------------------

const char* ToString(CoordinateConvention convention) {
  switch (convention) {
    case CoordinateConvention::kPixelCenters:
      return "pixel_centers";
    case CoordinateConvention::kPixelCorners:
      return "pixel_corners";
  }
  return "unknown";
}

bool CoordinateConventionFromString(const std::string& name,
                                    CoordinateConvention* convention) {
  for (CoordinateConvention c :
       {CoordinateConvention::kPixelCenters, CoordinateConvention::kPixelCorners}) {
    if (name == ToString(c)) {
      *convention = c;
      return true;
    }
  }
  return false;
}

const char* ToString(ParameterGroup group) {
  switch (group) {
    case ParameterGroup::kHiddenWeight:
      return "hidden_weight";
    case ParameterGroup::kHiddenBias:
      return "hidden_bias";
    case ParameterGroup::kModulationMatrix:
      return "modulation_matrix";
    case ParameterGroup::kModulationBias:
      return "modulation_bias";
    case ParameterGroup::kOutputWeight:
      return "output_weight";
    case ParameterGroup::kOutputBias:
      return "output_bias";
    case ParameterGroup::kReadoutBasis:
      return "readout_basis";
    case ParameterGroup::kReadoutMean:
      return "readout_mean";
  }
  return "unknown";
}

std::string ParameterBlock::Name() const {
  std::string name = ToString(group);
  if (group == ParameterGroup::kHiddenWeight || group == ParameterGroup::kHiddenBias) {
    name += "[" + std::to_string(layer) + "]";
  }
  return name;
}

// ---- Options, layout, initialisation ---------------------------------------------

bool LatentModulatedSiren::Options::IsValid(std::string* error) const {
  std::ostringstream message;
  if (width < 1) {
    message << "width must be >= 1, found " << width;
  } else if (num_hidden_layers < 1) {
    message << "num_hidden_layers must be >= 1, found " << num_hidden_layers;
  } else if (!(omega_0 > 0.0) || !std::isfinite(omega_0)) {
    message << "omega_0 must be finite and > 0, found " << omega_0;
  } else if (latent_dim < 1) {
    message << "latent_dim must be >= 1, found " << latent_dim;
  } else if (output_channels < 1) {
    message << "output_channels must be >= 1, found " << output_channels;
  } else if (coordinates != CoordinateConvention::kPixelCenters &&
             coordinates != CoordinateConvention::kPixelCorners) {
    message << "coordinates is not a CoordinateConvention, found "
            << static_cast<int>(coordinates);
  } else if (readout_rows < 0 || readout_cols < 0 ||
             (readout_rows == 0) != (readout_cols == 0)) {
    message << "readout_rows and readout_cols must be both 0 (no readout branch) or both "
               ">= 1, found "
            << readout_rows << " x " << readout_cols;
  } else if (spatial_rows < 0 || spatial_cols < 0 || spatial_channels < 0 ||
             ((spatial_rows == 0) != (spatial_cols == 0)) ||
             ((spatial_rows == 0) != (spatial_channels == 0))) {
    message << "spatial_rows, spatial_cols and spatial_channels must be all 0 (no spatial "
               "latents) or all >= 1, found "
            << spatial_rows << " x " << spatial_cols << " x " << spatial_channels;
  } else if (static_cast<double>(spatial_rows) * spatial_cols * spatial_channels >
             latent_dim) {
    message << "latent_dim must be >= spatial_rows * spatial_cols * spatial_channels (the "
               "grid's values are part of the latent), found latent_dim "
            << latent_dim << " for a " << spatial_rows << " x " << spatial_cols << " x "
            << spatial_channels << " grid";
  } else if (static_cast<double>(readout_rows) * readout_cols * output_channels *
                 (latent_dim + 1) >
             1.0e9) {
    message << "the readout branch would have more than 1e9 parameters (" << readout_rows
            << " x " << readout_cols << " nodes, " << output_channels << " channels, latent_dim "
            << latent_dim << ")";
  } else if (static_cast<double>(width) * (width + latent_dim) * num_hidden_layers >
             2.0e9) {
    message << "width, num_hidden_layers and latent_dim give more than 2e9 "
               "parameters (width "
            << width << ", num_hidden_layers " << num_hidden_layers << ", latent_dim "
            << latent_dim << ")";
  } else {
    return true;
  }
  if (error != nullptr) *error = "LatentModulatedSiren::Options::" + message.str();
  return false;
}

namespace {
// A new value for every change of any trunk's parameters in this process.
std::uint64_t NextParametersGeneration() {
  static std::atomic<std::uint64_t> next{1};
  return next.fetch_add(1, std::memory_order_relaxed);
}
}  // namespace

LatentModulatedSiren::LatentModulatedSiren(const Options& options, std::uint64_t seed)
    : options_(options) {
  std::string error;
  if (!options_.IsValid(&error)) throw std::invalid_argument(error);
  BuildLayout();
  Initialize(seed);
}

void LatentModulatedSiren::BuildLayout() {
  const int width = options_.width;
  const int num_layers = options_.num_hidden_layers;
  blocks_.clear();
  int offset = 0;
  auto add = [&](ParameterGroup group, int layer, int rows, int cols) {
    blocks_.push_back(ParameterBlock{group, layer, offset, rows, cols});
    offset += rows * cols;
  };
  for (int l = 0; l < num_layers; ++l) {
    add(ParameterGroup::kHiddenWeight, l, width, l == 0 ? 2 : width);
    add(ParameterGroup::kHiddenBias, l, width, 1);
  }
  add(ParameterGroup::kModulationMatrix, 0, num_layers * width, options_.modulation_inputs());
  add(ParameterGroup::kModulationBias, 0, num_layers * width, 1);
  add(ParameterGroup::kOutputWeight, 0, options_.output_channels, width);
  add(ParameterGroup::kOutputBias, 0, options_.output_channels, 1);
  if (options_.has_readout()) {
    const int nodes = options_.readout_rows * options_.readout_cols * options_.output_channels;
    add(ParameterGroup::kReadoutBasis, 0, options_.latent_dim, nodes);
    add(ParameterGroup::kReadoutMean, 0, nodes, 1);
  }
  num_parameters_ = offset;
}

const ParameterBlock& LatentModulatedSiren::Block(ParameterGroup group, int layer) const {
  const int num_layers = options_.num_hidden_layers;
  switch (group) {
    case ParameterGroup::kHiddenWeight:
    case ParameterGroup::kHiddenBias:
      if (layer < 0 || layer >= num_layers) {
        throw std::out_of_range("LatentModulatedSiren::Block: layer must be in [0, " +
                                std::to_string(num_layers) + "), found " +
                                std::to_string(layer));
      }
      return blocks_[2 * layer + (group == ParameterGroup::kHiddenBias ? 1 : 0)];
    case ParameterGroup::kModulationMatrix:
      return blocks_[2 * num_layers];
    case ParameterGroup::kModulationBias:
      return blocks_[2 * num_layers + 1];
    case ParameterGroup::kOutputWeight:
      return blocks_[2 * num_layers + 2];
    case ParameterGroup::kOutputBias:
      return blocks_[2 * num_layers + 3];
    case ParameterGroup::kReadoutBasis:
    case ParameterGroup::kReadoutMean:
      if (!has_readout()) {
        throw std::out_of_range(
            "LatentModulatedSiren::Block: this trunk has no readout branch");
      }
      return blocks_[2 * num_layers + (group == ParameterGroup::kReadoutMean ? 5 : 4)];
  }
  throw std::out_of_range("LatentModulatedSiren::Block: unknown group");
}

void LatentModulatedSiren::Initialize(std::uint64_t seed) {
  boost::random::mt19937_64 rng(seed);
  const double omega = options_.omega_0;
  const double hidden_bound = std::sqrt(6.0 / options_.width) / omega;
  parameters_.setZero(num_parameters_);
  for (const ParameterBlock& block : blocks_) {
    double bound = 0.0;
    switch (block.group) {
      case ParameterGroup::kHiddenWeight:
      case ParameterGroup::kHiddenBias:
        bound = block.layer == 0 ? 1.0 / 2.0 : hidden_bound;  // first: 1 / fan_in
        break;
      case ParameterGroup::kModulationMatrix:
        bound = std::sqrt(6.0 / options_.modulation_inputs()) / omega;  // d without spatial
        break;
      case ParameterGroup::kModulationBias:
        bound = 0.0;  // c = 0: at z = 0 the trunk is a plain SIREN
        break;
      case ParameterGroup::kOutputWeight:
      case ParameterGroup::kOutputBias:
        bound = hidden_bound;
        break;
      case ParameterGroup::kReadoutBasis:
      case ParameterGroup::kReadoutMean:
        bound = 0.0;  // the branch starts at zero (or from a PCA, set by the trainer)
        break;
    }
    if (bound == 0.0) continue;
    boost::random::uniform_real_distribution<double> uniform(-bound, bound);
    for (int i = 0; i < block.size(); ++i) parameters_[block.offset + i] = uniform(rng);
  }
  ParametersChanged();
}

void LatentModulatedSiren::SetParameters(const Eigen::VectorXd& parameters) {
  if (parameters.size() != num_parameters_) {
    throw std::invalid_argument("LatentModulatedSiren::SetParameters: expected " +
                                std::to_string(num_parameters_) + " parameters, found " +
                                std::to_string(parameters.size()));
  }
  parameters_ = parameters;
  ParametersChanged();
}

namespace {
// Bilinear corners of (x0, x1) on a rows x cols grid of nodes placed as the pixels of a
// rows x cols image in `convention` (LocateReadout, LocateSpatial).
LatentModulatedSiren::ReadoutCorners LocateOnGrid(CoordinateConvention convention, int rows,
                                                  int cols, double x0, double x1) {
  // Grid position of a coordinate along an axis of `count` nodes, the inverse of
  // MakeGrid's mapping, clamped to [0, count - 1].
  auto position = [convention](double x, int count) {
    double p = convention == CoordinateConvention::kPixelCenters
                   ? (x + 1.0) * 0.5 * count - 0.5
                   : (count == 1 ? 0.0 : (x + 1.0) * 0.5 * (count - 1));
    if (!(p >= 0.0)) p = std::isnan(p) ? p : 0.0;  // NaN stays NaN (a NaN output)
    return std::min(p, static_cast<double>(count - 1));
  };
  const double pc = position(x0, cols), pr = position(x1, rows);
  LatentModulatedSiren::ReadoutCorners corners;
  if (std::isnan(pc) || std::isnan(pr)) {
    for (int i = 0; i < 4; ++i) {
      corners.node[i] = 0;
      corners.weight[i] = std::nan("");
    }
    return corners;
  }
  const int c0 = static_cast<int>(pc), r0 = static_cast<int>(pr);
  const int c1 = std::min(c0 + 1, cols - 1), r1 = std::min(r0 + 1, rows - 1);
  const double fc = pc - c0, fr = pr - r0;
  corners.node[0] = static_cast<long>(r0) * cols + c0;
  corners.node[1] = static_cast<long>(r0) * cols + c1;
  corners.node[2] = static_cast<long>(r1) * cols + c0;
  corners.node[3] = static_cast<long>(r1) * cols + c1;
  corners.weight[0] = (1 - fr) * (1 - fc);
  corners.weight[1] = (1 - fr) * fc;
  corners.weight[2] = fr * (1 - fc);
  corners.weight[3] = fr * fc;
  return corners;
}
}  // namespace

LatentModulatedSiren::ReadoutCorners LatentModulatedSiren::LocateReadout(double x0,
                                                                         double x1) const {
  return LocateOnGrid(options_.coordinates, options_.readout_rows, options_.readout_cols, x0,
                      x1);
}

LatentModulatedSiren::ReadoutCorners LatentModulatedSiren::LocateSpatial(double x0,
                                                                         double x1) const {
  return LocateOnGrid(options_.coordinates, options_.spatial_rows, options_.spatial_cols, x0,
                      x1);
}

void LatentModulatedSiren::ParametersChanged() {
  parameters_float_ = parameters_.cast<float>();
  const int num_layers = options_.num_hidden_layers;
  hidden_weights_t_.resize(num_layers);
  hidden_weights_t_float_.resize(num_layers);
  for (int l = 0; l < num_layers; ++l) {
    const ParameterBlock& block = blocks_[2 * l];
    hidden_weights_t_[l] =
        Eigen::Map<const Eigen::MatrixXd>(parameters_.data() + block.offset, block.rows, block.cols)
            .transpose();
    hidden_weights_t_float_[l] = hidden_weights_t_[l].cast<float>();
  }
  packed_weights_.reset();
  if (GetProductPrecision() == ProductPrecision::kBfloat16 &&
      options_.width >= internal::kMinBfloat16Extent) {
    auto packed = std::make_shared<internal::Bfloat16Weights>();
    packed->W.resize(num_layers);
    packed->W_t.resize(num_layers);
    bool ok = true;
    for (int l = 1; l < num_layers && ok; ++l) {
      const ParameterBlock& block = blocks_[2 * l];
      const Eigen::MatrixXf& w_t = hidden_weights_t_float_[l];
      ok = internal::PackBfloat16Pairs(block.rows, block.cols,
                                       parameters_float_.data() + block.offset, 1, block.rows,
                                       &packed->W[l]) &&
           internal::PackBfloat16Pairs(w_t.rows(), w_t.cols(), w_t.data(), 1, w_t.rows(),
                                       &packed->W_t[l]);
    }
    if (ok) packed_weights_ = std::move(packed);
  }
  parameters_generation_ = NextParametersGeneration();
}

template <>
const internal::Bfloat16Weights* LatentModulatedSiren::PackedWeights<double>() const {
  return nullptr;
}
template <>
const internal::Bfloat16Weights* LatentModulatedSiren::PackedWeights<float>() const {
  return packed_weights_.get();
}

template <>
const std::vector<Eigen::MatrixXd>& LatentModulatedSiren::HiddenWeightsTransposed<double>() const {
  return hidden_weights_t_;
}
template <>
const std::vector<Eigen::MatrixXf>& LatentModulatedSiren::HiddenWeightsTransposed<float>() const {
  return hidden_weights_t_float_;
}

template <>
const double* LatentModulatedSiren::ParameterData<double>() const {
  return parameters_.data();
}
template <>
const float* LatentModulatedSiren::ParameterData<float>() const {
  return parameters_float_.data();
}

// ---- Coordinates -----------------------------------------------------------------

namespace {
template <typename S>
MatrixX<S> MakeGrid(int rows, int cols, CoordinateConvention convention) {
  if (rows < 1 || cols < 1) {
    throw std::invalid_argument(
        "LatentModulatedSiren::GridCoordinates: rows and cols "
        "must be >= 1, found " +
        Shape(rows, cols));
  }
  auto coordinate = [convention](int index, int count) -> double {
    if (convention == CoordinateConvention::kPixelCenters) {
      return 2.0 * (index + 0.5) / count - 1.0;
    }
    return count == 1 ? 0.0 : 2.0 * index / (count - 1) - 1.0;
  };
  MatrixX<S> grid(static_cast<long>(rows) * cols, 2);
  for (int r = 0; r < rows; ++r) {
    for (int c = 0; c < cols; ++c) {
      const long j = static_cast<long>(r) * cols + c;
      grid(j, 0) = static_cast<S>(coordinate(c, cols));
      grid(j, 1) = static_cast<S>(coordinate(r, rows));
    }
  }
  return grid;
}
}  // namespace

Eigen::MatrixXf LatentModulatedSiren::GridCoordinates(int rows, int cols,
                                                      CoordinateConvention convention) {
  return MakeGrid<float>(rows, cols, convention);
}

Eigen::MatrixXd LatentModulatedSiren::GridCoordinatesD(int rows, int cols,
                                                       CoordinateConvention convention) {
  return MakeGrid<double>(rows, cols, convention);
}

template <typename Scalar>
LatentModulatedSiren::MatrixX<Scalar> LatentModulatedSiren::Grid(int rows,
                                                                 int cols) const {
  return MakeGrid<Scalar>(rows, cols, options_.coordinates);
}

// ---- Batched passes ----------------------------------------------------------------

template <typename Scalar>
LatentModulatedSiren::MatrixX<Scalar> LatentModulatedSiren::Forward(
    const MatrixX<Scalar>& coords, const VectorX<Scalar>& z) const {
  return ForwardPasses<Scalar>(coords, z, nullptr);
}

template <typename Scalar>
LatentModulatedSiren::MatrixX<Scalar> LatentModulatedSiren::Forward(
    const MatrixX<Scalar>& coords, const VectorX<Scalar>& z,
    ForwardRecord<Scalar>* record) const {
  if (record == nullptr) {
    throw std::invalid_argument("LatentModulatedSiren::Forward: record must not be null");
  }
  auto kept = std::make_unique<typename ForwardRecord<Scalar>::Record>();
  MatrixX<Scalar> outputs = ForwardPasses<Scalar>(coords, z, kept.get());
  kept->parameters_generation = parameters_generation_;
  kept->coords = coords;
  kept->z = z;
  record->record_ = std::move(kept);
  return outputs;
}

template <typename Scalar>
LatentModulatedSiren::MatrixX<Scalar> LatentModulatedSiren::ForwardPasses(
    const MatrixX<Scalar>& coords, const VectorX<Scalar>& z,
    typename ForwardRecord<Scalar>::Record* record) const {
  CheckShape("coords", coords.rows(), coords.cols(), coords.rows(), 2);
  CheckShape("z", z.rows(), 1, options_.latent_dim, 1);
  const long n = coords.rows();
  const Net<Scalar> net(ParameterData<Scalar>(), blocks_, options_.num_hidden_layers,
                        &HiddenWeightsTransposed<Scalar>(), PackedWeights<Scalar>());
  std::unique_ptr<Spatial<Scalar>> spatial;
  if (has_spatial()) spatial = std::make_unique<Spatial<Scalar>>(options_, BlockCapacity(n));
  const VectorX<Scalar> gamma = SharedShifts(net, z, spatial.get());
  // Without a record one trace serves every block; with one, each block keeps its own,
  // with the cosines the reverse pass reads.
  const bool keep = record != nullptr;
  std::optional<Trace<Scalar>> shared;
  if (!keep) {
    shared.emplace(options_.num_hidden_layers, options_.width, options_.output_channels,
                   BlockCapacity(n), /*keep_cosine=*/false);
  } else {
    record->blocks.reserve((n + kPixelBlock - 1) / kPixelBlock);
  }
  MatrixX<Scalar> outputs(n, options_.output_channels);
  VectorX<Scalar> u;
  if (has_readout()) {
    const ReadoutMaps<Scalar> readout(ParameterData<Scalar>(), blocks_,
                                      options_.num_hidden_layers);
    u = readout.R.transpose() * z + readout.m;
  }
  for (long begin = 0; begin < n; begin += kPixelBlock) {
    const long m = std::min(kPixelBlock, n - begin);
    if (keep) {
      record->blocks.emplace_back(options_.num_hidden_layers, options_.width,
                                  options_.output_channels, m, /*keep_cosine=*/true);
    }
    Trace<Scalar>& trace = keep ? record->blocks.back() : *shared;
    if (spatial) spatial->Locate(*this, coords.middleRows(begin, m));
    RunForward(net, options_.omega_0, coords.middleRows(begin, m), gamma, spatial.get(),
               &trace);
    if (has_readout()) {
      auto y = trace.y.leftCols(m);
      AddReadout(*this, coords.middleRows(begin, m), u, y);
    }
    outputs.middleRows(begin, m) = trace.y.leftCols(m).transpose();
  }
  return outputs;
}

template <typename Scalar>
void LatentModulatedSiren::Backward(const MatrixX<Scalar>& coords,
                                    const VectorX<Scalar>& z,
                                    const MatrixX<Scalar>& dL_dY, VectorX<Scalar>* dL_dz,
                                    VectorX<Scalar>* dL_dtheta,
                                    WeightGradients weights) const {
  CheckShape("coords", coords.rows(), coords.cols(), coords.rows(), 2);
  CheckShape("z", z.rows(), 1, options_.latent_dim, 1);
  BackwardPasses<Scalar>(coords, z, dL_dY, dL_dz, dL_dtheta, weights, nullptr);
}

template <typename Scalar>
void LatentModulatedSiren::Backward(const ForwardRecord<Scalar>& record,
                                    const MatrixX<Scalar>& dL_dY, VectorX<Scalar>* dL_dz,
                                    VectorX<Scalar>* dL_dtheta,
                                    WeightGradients weights) const {
  CheckRecording(record.empty(), record.empty() ? 0 : record.record_->parameters_generation,
                 parameters_generation_, "Backward", "forward record");
  const typename ForwardRecord<Scalar>::Record& kept = *record.record_;
  BackwardPasses<Scalar>(kept.coords, kept.z, dL_dY, dL_dz, dL_dtheta, weights, &kept);
}

template <typename Scalar>
void LatentModulatedSiren::BackwardPasses(
    const MatrixX<Scalar>& coords, const VectorX<Scalar>& z, const MatrixX<Scalar>& dL_dY,
    VectorX<Scalar>* dL_dz, VectorX<Scalar>* dL_dtheta, WeightGradients weights,
    const typename ForwardRecord<Scalar>::Record* record) const {
  CheckShape("dL_dY", dL_dY.rows(), dL_dY.cols(), coords.rows(),
             options_.output_channels);
  const long n = coords.rows();
  const long capacity = BlockCapacity(n);
  const Net<Scalar> net(ParameterData<Scalar>(), blocks_, options_.num_hidden_layers,
                        &HiddenWeightsTransposed<Scalar>(), PackedWeights<Scalar>());
  std::unique_ptr<Spatial<Scalar>> spatial;
  MatrixX<Scalar> dP;  // the spatial latents' scattered dL/dgamma
  if (has_spatial()) {
    spatial = std::make_unique<Spatial<Scalar>>(options_, capacity);
    dP.setZero(net.A.rows(), spatial->nodes);
  }
  const VectorX<Scalar> gamma = SharedShifts(net, z, spatial.get());
  // Without a record one trace serves every block, filled by the block's forward pass.
  std::optional<Trace<Scalar>> own;
  if (record == nullptr) {
    own.emplace(options_.num_hidden_layers, options_.width, options_.output_channels,
                capacity, /*keep_cosine=*/true);
  }
  std::vector<MatrixX<Scalar>> g(1, MatrixX<Scalar>(options_.width, capacity));
  MatrixX<Scalar> delta(options_.width, capacity);
  VectorX<Scalar> dgamma = VectorX<Scalar>::Zero(net.A.rows());
  if (dL_dtheta != nullptr) dL_dtheta->setZero(num_parameters_);
  VectorX<Scalar> s;  // the readout's scattered dL/dY
  if (has_readout()) s.setZero(blocks_[2 * options_.num_hidden_layers + 5].rows);
  for (long begin = 0; begin < n; begin += kPixelBlock) {
    const long m = std::min(kPixelBlock, n - begin);
    // The readout adds to y but not to the SIREN's reverse pass (y is linear in both).
    if (spatial) spatial->Locate(*this, coords.middleRows(begin, m));
    if (record == nullptr) {
      RunForward(net, options_.omega_0, coords.middleRows(begin, m), gamma, spatial.get(),
                 &*own);
    }
    const Trace<Scalar>& trace = record == nullptr ? *own : record->blocks[begin / kPixelBlock];
    RunBackwardBlock(net, blocks_, options_.omega_0, trace,
                     dL_dY.middleRows(begin, m).transpose(), &g, &delta, spatial.get(),
                     &dgamma, &dP, dL_dtheta, weights == WeightGradients::kFirstLayer);
    if (has_readout()) {
      ScatterReadout(*this, coords.middleRows(begin, m), dL_dY.middleRows(begin, m).transpose(),
                     &s);
    }
  }
  FinishGradient(net, blocks_, dgamma, z, spatial.get(), &dP, dL_dz, dL_dtheta);
  if (has_readout()) {
    const ReadoutMaps<Scalar> readout(ParameterData<Scalar>(), blocks_,
                                      options_.num_hidden_layers);
    FinishReadoutGradient(readout, blocks_, options_.num_hidden_layers, s, z, dL_dz,
                          readout_frozen_ ? nullptr : dL_dtheta);
  }
}

template <typename Scalar>
void LatentModulatedSiren::ForwardAndLatentJacobian(const MatrixX<Scalar>& coords,
                                                    const VectorX<Scalar>& z,
                                                    MatrixX<Scalar>* outputs,
                                                    MatrixX<Scalar>* J_y_z,
                                                    MatrixX<Scalar>* J_y_x,
                                                    JacobianLayout layout,
                                                    const MatrixX<Scalar>* directions) const {
  CheckShape("coords", coords.rows(), coords.cols(), coords.rows(), 2);
  CheckShape("z", z.rows(), 1, options_.latent_dim, 1);
  if (directions != nullptr) {
    CheckShape("directions", directions->rows(), directions->cols(), options_.latent_dim,
               directions->cols());
  }
  const bool columns = layout == JacobianLayout::kOutputColumns;
  if (directions != nullptr && J_y_z != nullptr && has_spatial()) {
    // Each pixel's row is scattered over the grid's nodes: the whole Jacobian, then D.
    MatrixX<Scalar> whole;
    ForwardAndLatentJacobian<Scalar>(coords, z, outputs, &whole, J_y_x, layout, nullptr);
    *J_y_z = whole * *directions;
    return;
  }
  if ((J_y_x != nullptr || columns) && (has_readout() || has_spatial())) {
    throw std::invalid_argument(
        std::string("LatentModulatedSiren::ForwardAndLatentJacobian: the ") +
        (J_y_x != nullptr ? "coordinate Jacobian" : "output-column layout") +
        " needs a trunk without the readout branch and spatial latents, found " +
        (has_readout() ? "a readout branch" : "spatial latents"));
  }
  // The coordinate Jacobian comes from the latent Jacobian's reverse passes.
  MatrixX<Scalar> J_z_local;
  if (J_y_x != nullptr && J_y_z == nullptr) J_y_z = &J_z_local;
  const int num_layers = options_.num_hidden_layers;
  const long width = options_.width;
  const long n = coords.rows();
  const long capacity = BlockCapacity(n);
  const int channels = options_.output_channels;
  const int d = options_.latent_dim;
  const Net<Scalar> net(ParameterData<Scalar>(), blocks_, num_layers,
                        &HiddenWeightsTransposed<Scalar>(), PackedWeights<Scalar>());
  std::unique_ptr<Spatial<Scalar>> spatial;
  if (has_spatial()) spatial = std::make_unique<Spatial<Scalar>>(options_, capacity);
  const VectorX<Scalar> gamma = SharedShifts(net, z, spatial.get());
  const Scalar omega = static_cast<Scalar>(options_.omega_0);
  Trace<Scalar> trace(num_layers, width, channels, capacity,
                      /*keep_cosine=*/J_y_z != nullptr);
  if (outputs != nullptr) outputs->resize(n, channels);
  // The map from the shifts to what J_y_z holds: A, or A D along `directions`.
  MatrixX<Scalar> A_directions;
  if (directions != nullptr) A_directions = net.A * *directions;
  const ConstMap<Scalar> A_used =
      directions != nullptr
          ? ConstMap<Scalar>(A_directions.data(), A_directions.rows(), A_directions.cols())
          : net.A;
  const long k = A_used.cols();
  // A_used^T (k x (L width)), copied once: its layer blocks multiply every block's deltas.
  MatrixX<Scalar> A_used_t;
  if (J_y_z != nullptr) A_used_t = A_used.transpose();
  // k x B: d y_c / d z (times D) per pixel (k = d without spatial latents; with them
  // d y_c / d [z_g, z_s(x)], scattered onto the nodes below).
  MatrixX<Scalar> g, g_below, J_channel;
  if (J_y_x != nullptr) J_y_x->resize(n * channels, 2);
  if (J_y_z != nullptr) {
    const long cols = directions != nullptr ? directions->cols() : d;
    if (columns) {
      J_y_z->resize(cols, n * channels);
    } else {
      J_y_z->resize(n * channels, cols);
    }
    g.resize(width, capacity);
    g_below.resize(width, capacity);
    J_channel.resize(k, capacity);
  }
  std::unique_ptr<ReadoutMaps<Scalar>> readout;
  VectorX<Scalar> u;
  // The readout's basis columns as J_y_z holds them: R (d x (G C)), or D^T R.
  MatrixX<Scalar> R_directions;
  if (has_readout()) {
    readout = std::make_unique<ReadoutMaps<Scalar>>(ParameterData<Scalar>(), blocks_, num_layers);
    u = readout->R.transpose() * z + readout->m;
    if (directions != nullptr && J_y_z != nullptr) {
      R_directions = directions->transpose() * readout->R;
    }
  }
  for (long begin = 0; begin < n; begin += kPixelBlock) {
    const long m = std::min(kPixelBlock, n - begin);
    if (spatial) spatial->Locate(*this, coords.middleRows(begin, m));
    RunForward(net, options_.omega_0, coords.middleRows(begin, m), gamma, spatial.get(),
               &trace);
    if (outputs != nullptr) {
      auto y = trace.y.leftCols(m);
      if (readout) AddReadout(*this, coords.middleRows(begin, m), u, y);
      outputs->middleRows(begin, m) = y.transpose();
    }
    if (J_y_z == nullptr) continue;
    if (readout) {
      // d y_{j,ch} / d z of the readout: the bilinear mix of the nodes' basis columns.
      for (long j = 0; j < m; ++j) {
        const ReadoutCorners corners = LocateReadout(static_cast<double>(coords(begin + j, 0)),
                                                     static_cast<double>(coords(begin + j, 1)));
        for (int ch = 0; ch < channels; ++ch) {
          auto row = J_y_z->row((begin + j) * channels + ch);
          row.setZero();
          for (int i = 0; i < 4; ++i) {
            if (corners.weight[i] == 0.0) continue;
            const long column = corners.node[i] * channels + ch;
            if (directions != nullptr) {
              row += static_cast<Scalar>(corners.weight[i]) * R_directions.col(column).transpose();
            } else {
              row += static_cast<Scalar>(corners.weight[i]) * readout->R.col(column).transpose();
            }
          }
        }
      }
    }
    for (int ch = 0; ch < channels; ++ch) {
      // Seeding dL/dy = 1 for channel ch at every pixel: since pixels are independent,
      // column j of each delta is then d y_{j,ch} / d pre_l(j) = d y_{j,ch} / d gamma_l.
      MatrixX<Scalar>* delta = &g;
      MatrixX<Scalar>* below = &g_below;
      // (A column broadcast: replicate() would take a modulo per value.)
      delta->leftCols(m).colwise() = net.W_out.row(ch).transpose();
      auto J = J_channel.leftCols(m);
      J.setZero();
      for (int l = num_layers - 1; l >= 0; --l) {
        auto dl = delta->leftCols(m);
        dl.array() *= omega * trace.cosine[l].leftCols(m).array();
        internal::Product(A_used_t.middleCols(l * width, width), dl, J, /*accumulate=*/true);
        if (l > 0) {
          internal::Product(net.W_t[l], dl, below->leftCols(m), false, net.PackedT(l));
          std::swap(delta, below);
        } else if (J_y_x != nullptr) {
          J_y_x->operator()(Eigen::seqN(begin * channels + ch, m, channels), Eigen::all) =
              (net.W[0].transpose() * dl).transpose();
        }
      }
      if (columns) {
        // Column of pixel j, channel ch: J's column j (no readout, no spatial latents),
        // copied column by column (an indexed view of strided columns is copied value by
        // value).
        for (long j = 0; j < m; ++j) J_y_z->col((begin + j) * channels + ch) = J.col(j);
      } else if (spatial) {
        // Row of pixel j, channel ch: the global columns from J's first d_g rows, each
        // corner node's c_s columns from its last c_s rows times the corner's weight.
        const long dg = spatial->d_global, cs = spatial->channels;
        for (long j = 0; j < m; ++j) {
          auto row = J_y_z->row((begin + j) * channels + ch);
          if (!readout) row.setZero();
          row.head(dg) += J.col(j).head(dg).transpose();
          for (int i = 0; i < 4; ++i) {
            const Scalar w = spatial->weight[4 * j + i];
            if (w == Scalar(0)) continue;
            row.segment(dg + spatial->node[4 * j + i] * cs, cs) +=
                w * J.col(j).tail(cs).transpose();
          }
        }
      } else if (channels == 1) {
        if (readout) {
          J_y_z->middleRows(begin, m) += J.transpose();
        } else {
          J_y_z->middleRows(begin, m) = J.transpose();
        }
      } else if (readout) {
        J_y_z->operator()(Eigen::seqN(begin * channels + ch, m, channels), Eigen::all) +=
            J.transpose();
      } else {
        J_y_z->operator()(Eigen::seqN(begin * channels + ch, m, channels), Eigen::all) =
            J.transpose();
      }
    }
  }
}

template <typename Scalar>
Scalar LatentModulatedSiren::Loss(const MatrixX<Scalar>& coords, const VectorX<Scalar>& z,
                                  const MatrixX<Scalar>& targets,
                                  const VectorX<Scalar>& weights) const {
  return LossAndGradient<Scalar>(coords, z, targets, weights, nullptr, nullptr);
}

template <typename Scalar>
Scalar LatentModulatedSiren::LossAndGradient(const MatrixX<Scalar>& coords,
                                             const VectorX<Scalar>& z,
                                             const MatrixX<Scalar>& targets,
                                             const VectorX<Scalar>& weights,
                                             VectorX<Scalar>* dL_dz,
                                             VectorX<Scalar>* dL_dtheta) const {
  // No Hessian-vector product is asked for, so v_z is never read.
  return LossGradientAndHessianProduct<Scalar>(
      coords, z, targets, weights, nullptr, VectorX<Scalar>::Zero(options_.latent_dim),
      dL_dz, dL_dtheta, nullptr, nullptr);
}

template <typename Scalar>
Scalar LatentModulatedSiren::LossGradientAndOutputs(
    const MatrixX<Scalar>& coords, const VectorX<Scalar>& z, const MatrixX<Scalar>& targets,
    const VectorX<Scalar>& weights, VectorX<Scalar>* dL_dz, VectorX<Scalar>* dL_dtheta,
    MatrixX<Scalar>* outputs) const {
  if (outputs == nullptr) {
    throw std::invalid_argument(
        "LatentModulatedSiren::LossGradientAndOutputs: outputs must not be null");
  }
  // No Hessian-vector product is asked for, so v_z is never read.
  return LossPasses<Scalar>(coords, z, targets, weights, nullptr,
                            VectorX<Scalar>::Zero(options_.latent_dim), dL_dz, dL_dtheta,
                            nullptr, nullptr, outputs);
}

template <typename Scalar>
Scalar LatentModulatedSiren::LossGradientAndHessianProduct(
    const MatrixX<Scalar>& coords, const VectorX<Scalar>& z,
    const MatrixX<Scalar>& targets, const VectorX<Scalar>& weights,
    const VectorX<Scalar>* v_theta, const VectorX<Scalar>& v_z, VectorX<Scalar>* dL_dz,
    VectorX<Scalar>* dL_dtheta, VectorX<Scalar>* Hv_z, VectorX<Scalar>* Hv_theta) const {
  return LossPasses<Scalar>(coords, z, targets, weights, v_theta, v_z, dL_dz, dL_dtheta, Hv_z,
                            Hv_theta, nullptr);
}

template <typename Scalar>
Scalar LatentModulatedSiren::LossPasses(
    const MatrixX<Scalar>& coords, const VectorX<Scalar>& z, const MatrixX<Scalar>& targets,
    const VectorX<Scalar>& weights, const VectorX<Scalar>* v_theta, const VectorX<Scalar>& v_z,
    VectorX<Scalar>* dL_dz, VectorX<Scalar>* dL_dtheta, VectorX<Scalar>* Hv_z,
    VectorX<Scalar>* Hv_theta, MatrixX<Scalar>* outputs) const {
  CheckLossInputs(*this, coords, z, targets, weights);
  CheckDirection(*this, v_theta, v_z);
  const long n = coords.rows();
  const bool gradient = dL_dz != nullptr || dL_dtheta != nullptr;
  const bool hvp = Hv_z != nullptr || Hv_theta != nullptr;
  const bool reverse = gradient || hvp;
  const long capacity = BlockCapacity(n);
  PassContext<Scalar> context(*this, ParameterData<Scalar>(), HiddenWeightsTransposed<Scalar>(),
                              PackedWeights<Scalar>(), capacity);
  LossPass<Scalar> pass(context, z, weights, n, capacity, reverse, dL_dtheta);
  std::unique_ptr<TangentPass<Scalar>> tangent;
  if (hvp) {
    tangent = std::make_unique<TangentPass<Scalar>>(context, z, v_theta, v_z, capacity, Hv_theta);
  }
  // One block's primal values, reused by every block; the Hessian-vector product reads
  // every layer's dL/dh.
  BlockRecord<Scalar> record(options_.num_hidden_layers, options_.width,
                             options_.output_channels, capacity, reverse,
                             /*keep_layers=*/hvp);
  if (outputs != nullptr) outputs->resize(n, options_.output_channels);
  for (long begin = 0; begin < n; begin += kPixelBlock) {
    const long m = std::min(kPixelBlock, n - begin);
    pass.Block(coords, targets, weights, begin, m, &record);
    if (outputs != nullptr) {
      outputs->middleRows(begin, m) = record.trace.y.leftCols(m).transpose();
    }
    if (tangent) tangent->Block(record, coords, weights, begin, m, pass.scale);
  }
  if (gradient) pass.Finish(z, dL_dz);
  if (tangent) tangent->Finish(z, v_z, pass.dgamma, pass.dP, pass.scatter, Hv_z);
  return pass.Loss();
}

// ---- Tapes -------------------------------------------------------------------------

template <typename Scalar>
Scalar LatentModulatedSiren::LossAndGradient(const MatrixX<Scalar>& coords,
                                             const VectorX<Scalar>& z,
                                             const MatrixX<Scalar>& targets,
                                             const VectorX<Scalar>& weights,
                                             VectorX<Scalar>* dL_dz,
                                             VectorX<Scalar>* dL_dtheta,
                                             Tape<Scalar>* tape) const {
  if (tape == nullptr) {
    throw std::invalid_argument("LatentModulatedSiren::LossAndGradient: tape must not be null");
  }
  CheckLossInputs(*this, coords, z, targets, weights);
  const long n = coords.rows();
  const long capacity = BlockCapacity(n);
  auto record = std::make_unique<typename Tape<Scalar>::Record>();
  PassContext<Scalar> context(*this, ParameterData<Scalar>(), HiddenWeightsTransposed<Scalar>(),
                              PackedWeights<Scalar>(), capacity);
  LossPass<Scalar> pass(context, z, weights, n, capacity, /*reverse=*/true, dL_dtheta);
  record->blocks.reserve((n + kPixelBlock - 1) / kPixelBlock);
  for (long begin = 0; begin < n; begin += kPixelBlock) {
    const long m = std::min(kPixelBlock, n - begin);
    record->blocks.emplace_back(options_.num_hidden_layers, options_.width,
                                options_.output_channels, m, /*reverse=*/true,
                                /*keep_layers=*/true);
    pass.Block(coords, targets, weights, begin, m, &record->blocks.back());
  }
  pass.Finish(z, dL_dz);
  record->parameters_generation = parameters_generation_;
  record->coords = coords;
  record->z = z;
  record->weights = weights;
  record->scale = pass.scale;
  record->dgamma = std::move(pass.dgamma);
  record->scatter = std::move(pass.scatter);
  record->dP = std::move(pass.dP);
  tape->record_ = std::move(record);
  return pass.Loss();
}

template <typename Scalar>
void LatentModulatedSiren::HessianProduct(const Tape<Scalar>& tape,
                                          const VectorX<Scalar>* v_theta,
                                          const VectorX<Scalar>& v_z, VectorX<Scalar>* Hv_z,
                                          VectorX<Scalar>* Hv_theta) const {
  CheckRecording(tape.empty(), tape.empty() ? 0 : tape.record_->parameters_generation,
                 parameters_generation_, "HessianProduct", "tape");
  CheckDirection(*this, v_theta, v_z);
  if (Hv_z == nullptr && Hv_theta == nullptr) return;
  const typename Tape<Scalar>::Record& record = *tape.record_;
  const long n = record.coords.rows();
  const long capacity = BlockCapacity(n);
  PassContext<Scalar> context(*this, ParameterData<Scalar>(), HiddenWeightsTransposed<Scalar>(),
                              PackedWeights<Scalar>(), capacity);
  TangentPass<Scalar> tangent(context, record.z, v_theta, v_z, capacity, Hv_theta);
  for (std::size_t b = 0; b < record.blocks.size(); ++b) {
    const long begin = static_cast<long>(b) * kPixelBlock;
    const long m = std::min(kPixelBlock, n - begin);
    if (context.spatial) context.spatial->Locate(*this, record.coords.middleRows(begin, m));
    tangent.Block(record.blocks[b], record.coords, record.weights, begin, m, record.scale);
  }
  tangent.Finish(record.z, v_z, record.dgamma, record.dP, record.scatter, Hv_z);
}

template <typename Scalar>
LatentModulatedSiren::VectorX<Scalar> LatentModulatedSiren::StartLatent(
    const MatrixX<Scalar>& coords, const MatrixX<Scalar>& targets,
    const VectorX<Scalar>& weights) const {
  const long n = coords.rows();
  const long channels = options_.output_channels;
  CheckShape("coords", n, coords.cols(), n, 2);
  CheckShape("targets", targets.rows(), targets.cols(), n, channels);
  if (weights.size() != 0) CheckShape("weights", weights.rows(), 1, n, 1);
  VectorX<Scalar> z = VectorX<Scalar>::Zero(options_.latent_dim);
  if (!has_readout()) return z;
  const ReadoutMaps<Scalar> readout(ParameterData<Scalar>(), blocks_,
                                    options_.num_hidden_layers);
  VectorX<Scalar> scatter = VectorX<Scalar>::Zero(readout.m.rows());
  double weight_sum = 0;
  for (long j = 0; j < n; ++j) {
    const Scalar w = weights.size() == 0 ? Scalar(1) : weights[j];
    if (w == Scalar(0)) continue;
    weight_sum += w;
    const ReadoutCorners corners = LocateReadout(static_cast<double>(coords(j, 0)),
                                                 static_cast<double>(coords(j, 1)));
    for (long ch = 0; ch < channels; ++ch) {
      Scalar mean = 0;
      for (int i = 0; i < 4; ++i) {
        if (corners.weight[i] != 0.0) {
          mean += static_cast<Scalar>(corners.weight[i]) * readout.m(corners.node[i] * channels + ch, 0);
        }
      }
      const Scalar r = w * (targets(j, ch) - mean);
      for (int i = 0; i < 4; ++i) {
        if (corners.weight[i] != 0.0) {
          scatter[corners.node[i] * channels + ch] += static_cast<Scalar>(corners.weight[i]) * r;
        }
      }
    }
  }
  if (!(weight_sum > 0)) return z;
  z.noalias() = static_cast<Scalar>(2.0 / (channels * weight_sum)) * (readout.R * scatter);
  if (start_gains_.size() != 0) z.array() *= start_gains_.cast<Scalar>().array();
  return z;
}

void LatentModulatedSiren::set_start_gains(const Eigen::VectorXd& gains) {
  if (gains.size() != 0 && (!has_readout() || gains.size() != options_.latent_dim ||
                            !gains.allFinite())) {
    throw std::invalid_argument(
        "LatentModulatedSiren::set_start_gains: expected no gains or latent_dim = " +
        std::to_string(options_.latent_dim) + " finite ones for a trunk with the readout "
        "branch, got " + std::to_string(gains.size()) +
        (has_readout() ? std::string() : std::string(" for a trunk without the branch")));
  }
  start_gains_ = gains;
}

// ---- Explicit instantiations -------------------------------------------------------

#define TACTFUNC_INSTANTIATE_SIREN(S)                                                    \
  template LatentModulatedSiren::MatrixX<S> LatentModulatedSiren::Grid<S>(int, int)      \
      const;                                                                             \
  template LatentModulatedSiren::MatrixX<S> LatentModulatedSiren::Forward<S>(            \
      const MatrixX<S>&, const VectorX<S>&) const;                                       \
  template void LatentModulatedSiren::Backward<S>(                                       \
      const MatrixX<S>&, const VectorX<S>&, const MatrixX<S>&, VectorX<S>*, VectorX<S>*, \
      WeightGradients) const;                                                            \
  template class LatentModulatedSiren::Recording<S, LatentModulatedSiren::ForwardKind>;  \
  template LatentModulatedSiren::MatrixX<S> LatentModulatedSiren::Forward<S>(            \
      const MatrixX<S>&, const VectorX<S>&, ForwardRecord<S>*) const;                    \
  template void LatentModulatedSiren::Backward<S>(                                       \
      const ForwardRecord<S>&, const MatrixX<S>&, VectorX<S>*, VectorX<S>*,              \
      WeightGradients) const;                                                            \
  template double LatentModulatedSiren::MseNormaliser<S>(const VectorX<S>&, long, long,  \
                                                        S*);                           \
  template void LatentModulatedSiren::ForwardAndLatentJacobian<S>(                       \
      const MatrixX<S>&, const VectorX<S>&, MatrixX<S>*, MatrixX<S>*, MatrixX<S>*,        \
      JacobianLayout, const MatrixX<S>*) const;                                           \
  template LatentModulatedSiren::VectorX<S> LatentModulatedSiren::StartLatent<S>(        \
      const MatrixX<S>&, const MatrixX<S>&, const VectorX<S>&) const;                    \
  template S LatentModulatedSiren::Loss<S>(const MatrixX<S>&, const VectorX<S>&,         \
                                           const MatrixX<S>&, const VectorX<S>&) const;  \
  template S LatentModulatedSiren::LossAndGradient<S>(                                   \
      const MatrixX<S>&, const VectorX<S>&, const MatrixX<S>&, const VectorX<S>&,        \
      VectorX<S>*, VectorX<S>*) const;                                                   \
  template S LatentModulatedSiren::LossGradientAndOutputs<S>(                            \
      const MatrixX<S>&, const VectorX<S>&, const MatrixX<S>&, const VectorX<S>&,        \
      VectorX<S>*, VectorX<S>*, MatrixX<S>*) const;                                      \
  template S LatentModulatedSiren::LossGradientAndHessianProduct<S>(                     \
      const MatrixX<S>&, const VectorX<S>&, const MatrixX<S>&, const VectorX<S>&,        \
      const VectorX<S>*, const VectorX<S>&, VectorX<S>*, VectorX<S>*, VectorX<S>*,       \
      VectorX<S>*) const;                                                                \
  template class LatentModulatedSiren::Recording<S, LatentModulatedSiren::TapeKind>;     \
  template S LatentModulatedSiren::LossAndGradient<S>(                                   \
      const MatrixX<S>&, const VectorX<S>&, const MatrixX<S>&, const VectorX<S>&,        \
      VectorX<S>*, VectorX<S>*, Tape<S>*) const;                                         \
  template void LatentModulatedSiren::HessianProduct<S>(                                 \
      const Tape<S>&, const VectorX<S>*, const VectorX<S>&, VectorX<S>*, VectorX<S>*)    \
      const;

TACTFUNC_INSTANTIATE_SIREN(float)
TACTFUNC_INSTANTIATE_SIREN(double)
#undef TACTFUNC_INSTANTIATE_SIREN

}  // namespace tactfunc
