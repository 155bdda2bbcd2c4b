// Copyright 2026 The tactfunc Authors.
#include "models/latent_modulated_siren.h"

#include <cmath>
#include <memory>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "Eigen/Core"
#include "boost/random/mersenne_twister.hpp"
#include "boost/random/uniform_real_distribution.hpp"
#include "models/internal/fast_sincos.h"

namespace tactfunc {
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

// Maps of theta's blocks in one scalar type.
template <typename S>
struct Net {
  std::vector<ConstMap<S>> W, b;  // per hidden layer
  ConstMap<S> A, c, W_out, b_out;
  Net(const S* theta, const std::vector<ParameterBlock>& blocks, int num_layers)
      : A(At(theta, blocks[2 * num_layers])),
        c(At(theta, blocks[2 * num_layers + 1])),
        W_out(At(theta, blocks[2 * num_layers + 2])),
        b_out(At(theta, blocks[2 * num_layers + 3])) {
    for (int l = 0; l < num_layers; ++l) {
      W.push_back(At(theta, blocks[2 * l]));
      b.push_back(At(theta, blocks[2 * l + 1]));
    }
  }
  static ConstMap<S> At(const S* theta, const ParameterBlock& block) {
    return ConstMap<S>(theta + block.offset, block.rows, block.cols);
  }
};

// What the forward pass keeps for the reverse passes. Every matrix holds one pixel
// per column (features x N), so each layer is one GEMM and sin/cos run over one
// contiguous buffer.
template <typename S>
struct Trace {
  std::vector<MatrixX<S>> h;       // h[0] = coords^T (2 x N), h[l+1] width x N
  std::vector<MatrixX<S>> cosine;  // cos(omega_0 pre_l), width x N
  MatrixX<S> y;                    // C x N
};

template <typename S>
void RunForward(const Net<S>& net, double omega_0, const MatrixX<S>& coords,
                const VectorX<S>& z, bool keep_cosine, Trace<S>* trace) {
  const int num_layers = static_cast<int>(net.W.size());
  const long n = coords.rows();
  const long width = net.b[0].rows();
  const VectorX<S> gamma = net.A * z + net.c;
  trace->h.resize(num_layers + 1);
  trace->cosine.resize(keep_cosine ? num_layers : 0);
  trace->h[0] = coords.transpose();
  for (int l = 0; l < num_layers; ++l) {
    MatrixX<S>& pre = trace->h[l + 1];
    pre.resize(width, n);
    pre.noalias() = net.W[l] * trace->h[l];
    const VectorX<S> shift = net.b[l].col(0) + gamma.segment(l * width, width);
    pre.colwise() += shift;
    S* cosine = nullptr;
    if (keep_cosine) {
      trace->cosine[l].resize(width, n);
      cosine = trace->cosine[l].data();
    }
    internal::ScaledSinCos(width * n, static_cast<S>(omega_0), pre.data(), pre.data(),
                           cosine);
  }
  trace->y.resize(net.W_out.rows(), n);
  trace->y.noalias() = net.W_out * trace->h[num_layers];
  trace->y.colwise() += net.b_out.col(0);
}

// Reverse pass from G = dL/dY^T (C x N). The trace must hold the cosines.
template <typename S>
void RunBackward(const Net<S>& net, const std::vector<ParameterBlock>& blocks,
                 double omega_0, const Trace<S>& trace, const VectorX<S>& z,
                 const MatrixX<S>& G, VectorX<S>* dL_dz, VectorX<S>* dL_dtheta) {
  const int num_layers = static_cast<int>(net.W.size());
  const long width = net.b[0].rows();
  const S omega = static_cast<S>(omega_0);
  auto block = [&](int index) {
    return LatentModulatedSiren::View(dL_dtheta, blocks[index]);
  };
  if (dL_dtheta != nullptr) {
    block(2 * num_layers + 2).noalias() = G * trace.h[num_layers].transpose();
    block(2 * num_layers + 3) = G.rowwise().sum();
  }
  VectorX<S> dgamma(num_layers * width);
  MatrixX<S> g = net.W_out.transpose() * G;
  MatrixX<S> g_below;
  for (int l = num_layers - 1; l >= 0; --l) {
    g.array() *= omega * trace.cosine[l].array();  // now dL/dpre_l
    dgamma.segment(l * width, width) = g.rowwise().sum();
    if (dL_dtheta != nullptr) {
      block(2 * l).noalias() = g * trace.h[l].transpose();
      block(2 * l + 1) = dgamma.segment(l * width, width);
    }
    if (l > 0) {
      g_below.resize(width, g.cols());
      g_below.noalias() = net.W[l].transpose() * g;
      g.swap(g_below);
    }
  }
  if (dL_dtheta != nullptr) {
    block(2 * num_layers).noalias() = dgamma * z.transpose();
    block(2 * num_layers + 1) = dgamma;
  }
  if (dL_dz != nullptr) *dL_dz = net.A.transpose() * dgamma;
}

// dL/dY^T (C x N) of the weighted MSE, and the loss. w_j = 0 pixels get exactly 0,
// whatever their target (NaN included). *scale receives 2 / (C sum w) (0 if none).
template <typename S>
S MseAndResidualGradient(const MatrixX<S>& y, const MatrixX<S>& targets,
                         const VectorX<S>& weights, MatrixX<S>* G, S* scale) {
  const long n = y.cols();
  const long channels = y.rows();
  G->resize(channels, n);
  double weight_sum = 0.0;
  double loss = 0.0;
  for (long j = 0; j < n; ++j) {
    const S w = weights.size() == 0 ? S(1) : weights[j];
    if (w == S(0)) {
      G->col(j).setZero();
      continue;
    }
    weight_sum += w;
    for (long ch = 0; ch < channels; ++ch) {
      const S r = y(ch, j) - targets(j, ch);
      (*G)(ch, j) = w * r;
      loss += static_cast<double>(w * r * r);
    }
  }
  if (weight_sum <= 0.0) {
    G->setZero();
    *scale = S(0);
    return S(0);
  }
  const double normaliser = static_cast<double>(channels) * weight_sum;
  *scale = static_cast<S>(2.0 / normaliser);
  *G *= *scale;
  return static_cast<S>(loss / normaliser);
}

}  // namespace

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
  add(ParameterGroup::kModulationMatrix, 0, num_layers * width, options_.latent_dim);
  add(ParameterGroup::kModulationBias, 0, num_layers * width, 1);
  add(ParameterGroup::kOutputWeight, 0, options_.output_channels, width);
  add(ParameterGroup::kOutputBias, 0, options_.output_channels, 1);
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
        bound = std::sqrt(6.0 / options_.latent_dim) / omega;
        break;
      case ParameterGroup::kModulationBias:
        bound = 0.0;  // c = 0: at z = 0 the trunk is a plain SIREN
        break;
      case ParameterGroup::kOutputWeight:
      case ParameterGroup::kOutputBias:
        bound = hidden_bound;
        break;
    }
    if (bound == 0.0) continue;
    boost::random::uniform_real_distribution<double> uniform(-bound, bound);
    for (int i = 0; i < block.size(); ++i) parameters_[block.offset + i] = uniform(rng);
  }
  parameters_float_ = parameters_.cast<float>();
}

void LatentModulatedSiren::SetParameters(const Eigen::VectorXd& parameters) {
  if (parameters.size() != num_parameters_) {
    throw std::invalid_argument("LatentModulatedSiren::SetParameters: expected " +
                                std::to_string(num_parameters_) + " parameters, found " +
                                std::to_string(parameters.size()));
  }
  parameters_ = parameters;
  parameters_float_ = parameters_.cast<float>();
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
  CheckShape("coords", coords.rows(), coords.cols(), coords.rows(), 2);
  CheckShape("z", z.rows(), 1, options_.latent_dim, 1);
  const Net<Scalar> net(ParameterData<Scalar>(), blocks_, options_.num_hidden_layers);
  Trace<Scalar> trace;
  RunForward(net, options_.omega_0, coords, z, /*keep_cosine=*/false, &trace);
  return trace.y.transpose();
}

template <typename Scalar>
void LatentModulatedSiren::Backward(const MatrixX<Scalar>& coords,
                                    const VectorX<Scalar>& z,
                                    const MatrixX<Scalar>& dL_dY, VectorX<Scalar>* dL_dz,
                                    VectorX<Scalar>* dL_dtheta) const {
  CheckShape("coords", coords.rows(), coords.cols(), coords.rows(), 2);
  CheckShape("z", z.rows(), 1, options_.latent_dim, 1);
  CheckShape("dL_dY", dL_dY.rows(), dL_dY.cols(), coords.rows(),
             options_.output_channels);
  const Net<Scalar> net(ParameterData<Scalar>(), blocks_, options_.num_hidden_layers);
  Trace<Scalar> trace;
  RunForward(net, options_.omega_0, coords, z, /*keep_cosine=*/true, &trace);
  if (dL_dtheta != nullptr) dL_dtheta->resize(num_parameters_);
  const MatrixX<Scalar> G = dL_dY.transpose();
  RunBackward(net, blocks_, options_.omega_0, trace, z, G, dL_dz, dL_dtheta);
}

template <typename Scalar>
void LatentModulatedSiren::ForwardAndLatentJacobian(const MatrixX<Scalar>& coords,
                                                    const VectorX<Scalar>& z,
                                                    MatrixX<Scalar>* outputs,
                                                    MatrixX<Scalar>* J_y_z) const {
  CheckShape("coords", coords.rows(), coords.cols(), coords.rows(), 2);
  CheckShape("z", z.rows(), 1, options_.latent_dim, 1);
  const int num_layers = options_.num_hidden_layers;
  const long width = options_.width;
  const long n = coords.rows();
  const int channels = options_.output_channels;
  const Net<Scalar> net(ParameterData<Scalar>(), blocks_, num_layers);
  Trace<Scalar> trace;
  RunForward(net, options_.omega_0, coords, z, /*keep_cosine=*/J_y_z != nullptr, &trace);
  if (outputs != nullptr) *outputs = trace.y.transpose();
  if (J_y_z == nullptr) return;
  const Scalar omega = static_cast<Scalar>(options_.omega_0);
  J_y_z->resize(n * channels, options_.latent_dim);
  MatrixX<Scalar> g(width, n), g_below(width, n);
  MatrixX<Scalar> J_channel(options_.latent_dim, n);  // d x N: d y_c / d z per pixel
  for (int ch = 0; ch < channels; ++ch) {
    // Seeding dL/dy = 1 for channel ch at every pixel: since pixels are independent,
    // column j of each delta is then d y_{j,ch} / d pre_l(j) = d y_{j,ch} / d gamma_l.
    g = net.W_out.row(ch).transpose().replicate(1, n);
    J_channel.setZero();
    for (int l = num_layers - 1; l >= 0; --l) {
      g.array() *= omega * trace.cosine[l].array();
      J_channel.noalias() += net.A.middleRows(l * width, width).transpose() * g;
      if (l > 0) {
        g_below.noalias() = net.W[l].transpose() * g;
        g.swap(g_below);
      }
    }
    if (channels == 1) {
      *J_y_z = J_channel.transpose();
    } else {
      J_y_z->operator()(Eigen::seqN(ch, n, channels), Eigen::all) = J_channel.transpose();
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
  const long n = coords.rows();
  CheckShape("coords", n, coords.cols(), n, 2);
  CheckShape("z", z.rows(), 1, options_.latent_dim, 1);
  CheckShape("targets", targets.rows(), targets.cols(), n, options_.output_channels);
  if (weights.size() != 0) CheckShape("weights", weights.rows(), 1, n, 1);
  const bool backward = dL_dz != nullptr || dL_dtheta != nullptr;
  const Net<Scalar> net(ParameterData<Scalar>(), blocks_, options_.num_hidden_layers);
  Trace<Scalar> trace;
  RunForward(net, options_.omega_0, coords, z, backward, &trace);
  MatrixX<Scalar> G;
  Scalar scale;
  const Scalar loss = MseAndResidualGradient(trace.y, targets, weights, &G, &scale);
  if (backward) {
    if (dL_dtheta != nullptr) dL_dtheta->resize(num_parameters_);
    RunBackward(net, blocks_, options_.omega_0, trace, z, G, dL_dz, dL_dtheta);
  }
  return loss;
}

template <typename Scalar>
Scalar LatentModulatedSiren::LossGradientAndHessianProduct(
    const MatrixX<Scalar>& coords, const VectorX<Scalar>& z,
    const MatrixX<Scalar>& targets, const VectorX<Scalar>& weights,
    const VectorX<Scalar>* v_theta, const VectorX<Scalar>& v_z, VectorX<Scalar>* dL_dz,
    VectorX<Scalar>* dL_dtheta, VectorX<Scalar>* Hv_z, VectorX<Scalar>* Hv_theta) const {
  const long n = coords.rows();
  const int num_layers = options_.num_hidden_layers;
  const long width = options_.width;
  CheckShape("coords", n, coords.cols(), n, 2);
  CheckShape("z", z.rows(), 1, options_.latent_dim, 1);
  CheckShape("v_z", v_z.rows(), 1, options_.latent_dim, 1);
  CheckShape("targets", targets.rows(), targets.cols(), n, options_.output_channels);
  if (weights.size() != 0) CheckShape("weights", weights.rows(), 1, n, 1);
  if (v_theta != nullptr) CheckShape("v_theta", v_theta->rows(), 1, num_parameters_, 1);
  const Scalar omega = static_cast<Scalar>(options_.omega_0);
  const Net<Scalar> net(ParameterData<Scalar>(), blocks_, num_layers);
  Trace<Scalar> trace;
  RunForward(net, options_.omega_0, coords, z, /*keep_cosine=*/true, &trace);
  MatrixX<Scalar> G;
  Scalar scale;
  const Scalar loss = MseAndResidualGradient(trace.y, targets, weights, &G, &scale);
  if (dL_dz != nullptr || dL_dtheta != nullptr) {
    if (dL_dtheta != nullptr) dL_dtheta->resize(num_parameters_);
    RunBackward(net, blocks_, options_.omega_0, trace, z, G, dL_dz, dL_dtheta);
  }
  if (Hv_z == nullptr && Hv_theta == nullptr) return loss;

  // Tangents (the R-operator, written with dots): theta' = v_theta, z' = v_z.
  std::unique_ptr<Net<Scalar>> dnet;
  if (v_theta != nullptr) {
    dnet = std::make_unique<Net<Scalar>>(v_theta->data(), blocks_, num_layers);
  }
  VectorX<Scalar> dgamma_dot = net.A * v_z;
  if (dnet) dgamma_dot += dnet->A * z + dnet->c;
  // h_dot[l]: tangent of h_l (h_dot[0] = 0); s_dot[l] = omega_0 * pre_l'.
  std::vector<MatrixX<Scalar>> h_dot(num_layers + 1), s_dot(num_layers);
  for (int l = 0; l < num_layers; ++l) {
    MatrixX<Scalar>& s = s_dot[l];
    if (l > 0) {
      s.noalias() = net.W[l] * h_dot[l];
    } else {
      s.setZero(width, n);
    }
    if (dnet) {
      s.noalias() += dnet->W[l] * trace.h[l];
      s.colwise() += dnet->b[l].col(0) + dgamma_dot.segment(l * width, width);
    } else {
      s.colwise() += dgamma_dot.segment(l * width, width);
    }
    s *= omega;
    h_dot[l + 1] = trace.cosine[l].cwiseProduct(s);
  }
  MatrixX<Scalar> y_dot = net.W_out * h_dot[num_layers];
  if (dnet) {
    y_dot.noalias() += dnet->W_out * trace.h[num_layers];
    y_dot.colwise() += dnet->b_out.col(0);
  }
  // G' = scale * w * y' (zero where w = 0).
  MatrixX<Scalar> G_dot = scale * y_dot;
  if (weights.size() != 0) G_dot *= weights.asDiagonal();

  VectorX<Scalar> hv_theta_storage;
  VectorX<Scalar>* hv = Hv_theta;
  if (hv == nullptr) hv = &hv_theta_storage;  // the theta blocks are cheap by-products
  hv->resize(num_parameters_);
  auto block = [&](int index) { return View(hv, blocks_[index]); };
  block(2 * num_layers + 2).noalias() = G_dot * trace.h[num_layers].transpose();
  block(2 * num_layers + 2).noalias() += G * h_dot[num_layers].transpose();
  block(2 * num_layers + 3) = G_dot.rowwise().sum();

  MatrixX<Scalar> g = net.W_out.transpose() * G;  // dL/dh_{l+1}
  MatrixX<Scalar> g_dot = net.W_out.transpose() * G_dot;
  if (dnet) g_dot.noalias() += dnet->W_out.transpose() * G;
  VectorX<Scalar> dgamma(num_layers * width), ddgamma(num_layers * width);
  MatrixX<Scalar> delta, delta_dot;
  for (int l = num_layers - 1; l >= 0; --l) {
    const auto cosine = trace.cosine[l].array();
    const auto sine = trace.h[l + 1].array();
    delta = omega * g.array() * cosine;
    // d/dpre cos(omega pre) = -omega sin(omega pre); s_dot already holds omega pre'.
    delta_dot = omega * (g_dot.array() * cosine - g.array() * sine * s_dot[l].array());
    dgamma.segment(l * width, width) = delta.rowwise().sum();
    ddgamma.segment(l * width, width) = delta_dot.rowwise().sum();
    block(2 * l).noalias() = delta_dot * trace.h[l].transpose();
    if (l > 0) block(2 * l).noalias() += delta * h_dot[l].transpose();
    block(2 * l + 1) = ddgamma.segment(l * width, width);
    if (l > 0) {
      g.noalias() = net.W[l].transpose() * delta;
      g_dot.noalias() = net.W[l].transpose() * delta_dot;
      if (dnet) g_dot.noalias() += dnet->W[l].transpose() * delta;
    }
  }
  block(2 * num_layers).noalias() = ddgamma * z.transpose() + dgamma * v_z.transpose();
  block(2 * num_layers + 1) = ddgamma;
  if (Hv_z != nullptr) {
    *Hv_z = net.A.transpose() * ddgamma;
    if (dnet) Hv_z->noalias() += dnet->A.transpose() * dgamma;
  }
  return loss;
}

// ---- Explicit instantiations -------------------------------------------------------

#define TACTFUNC_INSTANTIATE_SIREN(S)                                                    \
  template LatentModulatedSiren::MatrixX<S> LatentModulatedSiren::Grid<S>(int, int)      \
      const;                                                                             \
  template LatentModulatedSiren::MatrixX<S> LatentModulatedSiren::Forward<S>(            \
      const MatrixX<S>&, const VectorX<S>&) const;                                       \
  template void LatentModulatedSiren::Backward<S>(                                       \
      const MatrixX<S>&, const VectorX<S>&, const MatrixX<S>&, VectorX<S>*, VectorX<S>*) \
      const;                                                                             \
  template void LatentModulatedSiren::ForwardAndLatentJacobian<S>(                       \
      const MatrixX<S>&, const VectorX<S>&, MatrixX<S>*, MatrixX<S>*) const;             \
  template S LatentModulatedSiren::Loss<S>(const MatrixX<S>&, const VectorX<S>&,         \
                                           const MatrixX<S>&, const VectorX<S>&) const;  \
  template S LatentModulatedSiren::LossAndGradient<S>(                                   \
      const MatrixX<S>&, const VectorX<S>&, const MatrixX<S>&, const VectorX<S>&,        \
      VectorX<S>*, VectorX<S>*) const;                                                   \
  template S LatentModulatedSiren::LossGradientAndHessianProduct<S>(                     \
      const MatrixX<S>&, const VectorX<S>&, const MatrixX<S>&, const VectorX<S>&,        \
      const VectorX<S>*, const VectorX<S>&, VectorX<S>*, VectorX<S>*, VectorX<S>*,       \
      VectorX<S>*) const;

TACTFUNC_INSTANTIATE_SIREN(float)
TACTFUNC_INSTANTIATE_SIREN(double)
#undef TACTFUNC_INSTANTIATE_SIREN

}  // namespace tactfunc
