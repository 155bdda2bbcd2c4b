// Copyright 2026 The tactfunc Authors.
#include "models/trunk/photometric_trunk.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <mutex>
#include <sstream>
#include <stdexcept>
#include <type_traits>
#include <utility>

#include "boost/random/mersenne_twister.hpp"
#include "boost/random/uniform_real_distribution.hpp"
#include "models/core/seed.h"
#include "models/trunk/internal/small_gemm.h"

namespace tactfunc {
namespace {

// The five coordinate sets of one pass: the pixel, then one pixel either side along
// x_0, then along x_1 (the central differences of the slope).
constexpr int kSets = 5;

LatentModulatedSiren::Options SirenOptions(const PhotometricTrunk::Options& o) {
  LatentModulatedSiren::Options s;
  s.width = o.width;
  s.num_hidden_layers = o.num_hidden_layers;
  s.omega_0 = o.omega_0;
  s.latent_dim = o.latent_dim - PhotometricTrunk::kPoseValues - o.lighting_components;
  s.output_channels = 1 + o.channels;
  return s;
}

// Offsets of the head's blocks in its flat vector, in the header comment's order: W_1
// (H x 5), b_1, W_2 (H x H), b_2, W_3 (C x H), b_3, then m.
struct HeadLayout {
  HeadLayout(int h, int c)
      : w1(0), b1(w1 + h * 5), w2(b1 + h), b2(w2 + h * h), w3(b2 + h), b3(w3 + c * h),
        m(b3 + c), size(m + 1) {}
  int w1, b1, w2, b2, w3, b3, m, size;
};

// SiLU a / (1 + e^-a) and its slope sigma (1 + a (1 - sigma)), sigma = 1 / (1 + e^-a),
// elementwise: Eigen's packet exp vectorises them (a scalar std::exp per element took
// about a tenth of an encode).
template <typename S>
Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic> Silu(
    const Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>& a) {
  return (a.array() / (S(1) + (-a.array()).exp())).matrix();
}
template <typename S>
Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic> SiluSlope(
    const Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>& a) {
  const Eigen::Array<S, Eigen::Dynamic, Eigen::Dynamic> sigma =
      (S(1) + (-a.array()).exp()).inverse();
  return (sigma * (S(1) + a.array() * (S(1) - sigma))).matrix();
}

// The shading network (header comment) on inputs `in` (5 x N), keeping its
// pre-activations and activations (each may be null) for the reverse pass: C x N.
template <typename S>
Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic> ShadingNetwork(
    const Eigen::Matrix<S, Eigen::Dynamic, 1>& head, int h, int c,
    const Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>& in,
    Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>* a1,
    Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>* h1,
    Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>* a2,
    Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>* h2) {
  using Matrix = Eigen::Matrix<S, Eigen::Dynamic, Eigen::Dynamic>;
  using Vector = Eigen::Matrix<S, Eigen::Dynamic, 1>;
  const HeadLayout layout(h, c);
  const Eigen::Map<const Matrix> W1(head.data() + layout.w1, h, 5);
  const Eigen::Map<const Vector> b1(head.data() + layout.b1, h);
  const Eigen::Map<const Matrix> W2(head.data() + layout.w2, h, h);
  const Eigen::Map<const Vector> b2(head.data() + layout.b2, h);
  const Eigen::Map<const Matrix> W3(head.data() + layout.w3, c, h);
  const Eigen::Map<const Vector> b3(head.data() + layout.b3, c);
  Matrix a1_local, h1_local, a2_local, h2_local;
  if (a1 == nullptr) a1 = &a1_local;
  if (h1 == nullptr) h1 = &h1_local;
  if (a2 == nullptr) a2 = &a2_local;
  if (h2 == nullptr) h2 = &h2_local;
  // Each layer's products start their sums from the biases (internal::ProductPlusOffset;
  // no pass setting them first).
  a1->resize(h, in.cols());
  internal::ProductPlusOffset(W1, in, b1, *a1);
  *h1 = Silu(*a1);
  a2->resize(h, in.cols());
  internal::ProductPlusOffset(W2, *h1, b2, *a2);
  *h2 = Silu(*a2);
  Matrix out(c, in.cols());
  internal::ProductPlusOffset(W3, *h2, b3, out);
  return out;
}

}  // namespace

// The shading network's output for the flat input (no slope, no depth) at every pixel
// of the grid, C x rows cols: constant for a given head. Computed on the first
// whole-grid pass (once per scalar type, thread-safely) and shared by copies of the
// trunk; SetHeadParameters starts a new one.
struct PhotometricTrunk::AtRestShading {
  std::once_flag once_float, once_double;
  Eigen::MatrixXf shading_float;
  Eigen::MatrixXd shading_double;
};

template <typename Scalar>
const PhotometricTrunk::MatrixX<Scalar>& PhotometricTrunk::AtRestShadingOf() const {
  AtRestShading& cache = *at_rest_shading_;
  auto compute = [this](MatrixX<Scalar>* out) {
    const int n = options_.rows * options_.cols;
    MatrixX<Scalar> input = MatrixX<Scalar>::Zero(5, n);
    for (int j = 0; j < n; ++j) {
      const Eigen::Vector2d p = PixelCoordinate(j);
      input(3, j) = static_cast<Scalar>(p[0]);
      input(4, j) = static_cast<Scalar>(p[1]);
    }
    *out = ShadingNetwork<Scalar>(head_.cast<Scalar>(), options_.shading_width,
                                  options_.channels, input, nullptr, nullptr, nullptr, nullptr);
  };
  if constexpr (std::is_same<Scalar, float>::value) {
    std::call_once(cache.once_float, compute, &cache.shading_float);
    return cache.shading_float;
  } else {
    std::call_once(cache.once_double, compute, &cache.shading_double);
    return cache.shading_double;
  }
}

bool PhotometricTrunk::Options::IsValid(std::string* error) const {
  std::ostringstream message;
  if (rows < 3 || cols < 3) {
    message << "rows and cols must be >= 3, found " << rows << " x " << cols;
  } else if (channels < 1 || channels > 4) {
    message << "channels must be in [1, 4], found " << channels;
  } else if (width < 1 || num_hidden_layers < 1) {
    message << "width and num_hidden_layers must be >= 1, found " << width << " and "
            << num_hidden_layers;
  } else if (!(std::isfinite(omega_0) && omega_0 > 0)) {
    message << "omega_0 must be finite and > 0, found " << omega_0;
  } else if (lighting_components < 0 || lighting_components > 64) {
    message << "lighting_components must be in [0, 64], found " << lighting_components;
  } else if (latent_dim <= kPoseValues + lighting_components) {
    message << "latent_dim must be > " << kPoseValues + lighting_components
            << " (the pose values and " << lighting_components
            << " lighting values; the SIREN needs a code value), found " << latent_dim;
  } else if (shading_width < 1 || shading_width > 4096) {
    message << "shading_width must be in [1, 4096], found " << shading_width;
  } else if (supersample < 1 || supersample > 32) {
    message << "supersample must be in [1, 32], found " << supersample;
  } else if (rows > 4096 || cols > 4096) {
    message << "rows and cols must be <= 4096, found " << rows << " x " << cols;
  }
  const std::string text = message.str();
  if (error != nullptr) *error = text;
  return text.empty();
}

template <typename Scalar>
struct PhotometricTrunkPass {
  using Matrix = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;
  // The SIREN's coordinates: kSets N rows, or one row per distinct grid position
  // when the sets share positions (then `slot` names each set row's coordinate row).
  Matrix coords;
  std::vector<int> slot;  // kSets N, or empty when coords has a row per set row
  Matrix siren_out;       // kSets N x (1 + C)
  // With PassUse::jacobian: d s / d code at each coordinate row, one column per output
  // (JacobianLayout::kOutputColumns), and d s / d q, one row per output.
  Matrix siren_J_code, siren_J_q;
  Matrix input, input0;   // 5 x N: (g_0, g_1, w, x_0, x_1) and the flat (0, 0, 0, x)
  Matrix a1, a2, h1, h2;  // H x N pre-activations and activations (contact)
  Matrix a1f, a2f, h1f, h2f;  // the same for the flat input
  Eigen::MatrixXd marker_d_row, marker_d_col;  // C x N
  // With PassUse::reverse (and no Jacobian): the SIREN's forward pass over `coords`,
  // kept for the reverse pass so that it does not run again.
  LatentModulatedSiren::ForwardRecord<Scalar> siren_record;
};

struct PhotometricTrunk::Pass {
  PhotometricTrunkPass<float> f;
  PhotometricTrunkPass<double> d;
  template <typename Scalar>
  PhotometricTrunkPass<Scalar>& get() {
    if constexpr (std::is_same_v<Scalar, float>) {
      return f;
    } else {
      return d;
    }
  }
  template <typename Scalar>
  const PhotometricTrunkPass<Scalar>& get() const {
    return const_cast<Pass*>(this)->get<Scalar>();
  }
};

namespace {

LatentModulatedSiren::Options ValidatedSirenOptions(const PhotometricTrunk::Options& options) {
  std::string error;
  if (!options.IsValid(&error)) {
    throw std::invalid_argument("PhotometricTrunk::Options: " + error);
  }
  return SirenOptions(options);
}

}  // namespace

PhotometricTrunk::PhotometricTrunk(const Options& options, const Image& reference,
                                   std::uint64_t seed)
    : options_(options),
      siren_(ValidatedSirenOptions(options), DeriveSeed(seed, 0)),
      markers_(nullptr) {
  const int c = options.channels;
  num_head_parameters_ = HeadParameterCount(options.shading_width, c);
  InitializeHead(DeriveSeed(seed, 1));
  if (options.wide_biases) {
    boost::random::mt19937_64 rng(DeriveSeed(seed, 2));
    Eigen::VectorXd theta = siren_.parameters();
    for (const ParameterBlock& block : siren_.parameter_blocks()) {
      double bound = 0;
      if (block.group == ParameterGroup::kHiddenBias) {
        bound = 1.0 / std::sqrt(block.layer == 0 ? 2.0 : static_cast<double>(options.width));
      } else if (block.group == ParameterGroup::kOutputBias) {
        bound = 1.0 / std::sqrt(static_cast<double>(options.width));
      } else if (block.group == ParameterGroup::kModulationMatrix) {
        bound = 0.1 / std::sqrt(static_cast<double>(CodeValues()));
      } else {
        continue;
      }
      boost::random::uniform_real_distribution<double> uniform(-bound, bound);
      for (int i = 0; i < block.size(); ++i) theta[block.offset + i] = uniform(rng);
    }
    siren_.SetParameters(theta);
  }
  lighting_ = Eigen::MatrixXf::Zero(
      static_cast<Eigen::Index>(options.rows) * options.cols * options.channels,
      options.lighting_components);
  markers_ = MakeMarkers(reference);
}

std::shared_ptr<const PhotometricTrunk::Markers> PhotometricTrunk::MakeMarkers(
    const Image& reference) const {
  const int c = options_.channels;
  if (reference.empty() || reference.channels != c) {
    throw std::invalid_argument(
        "PhotometricTrunk: the reference must be a non-empty image with " +
        std::to_string(c) + " channel(s), found " + reference.ShapeString());
  }
  auto markers = std::make_shared<Markers>();
  markers->reference = reference;
  const int k = options_.supersample;
  if (reference.rows % options_.rows == 0 && (reference.rows / options_.rows) % k == 0) {
    const int step = reference.rows / options_.rows / k;
    markers->row_sums = Image(reference.rows - (k - 1) * step, reference.cols, c);
    for (int y = 0; y < markers->row_sums.rows; ++y) {
      for (int x = 0; x < reference.cols; ++x) {
        for (int ch = 0; ch < c; ++ch) {
          double sum = 0;
          for (int a = 0; a < k; ++a) sum += reference.at(y + a * step, x, ch);
          markers->row_sums.at(y, x, ch) = static_cast<float>(sum);
        }
      }
    }
  }
  // The at-rest markers: the K x K average of the reference at zero shift.
  markers->at_rest = Image(options_.rows, options_.cols, c);
  std::vector<double> value(c);
  for (int r = 0; r < options_.rows; ++r) {
    for (int col = 0; col < options_.cols; ++col) {
      SampleMarkers(*markers, MarkerSampling::kSensorResolution, r, col, value.data(), nullptr,
                    nullptr);
      for (int ch = 0; ch < c; ++ch) {
        markers->at_rest.at(r, col, ch) = static_cast<float>(value[ch]);
      }
    }
  }
  return markers;
}

int PhotometricTrunk::HeadParameterCount(int shading_width, int channels) {
  return HeadLayout(shading_width, channels).size;
}

void PhotometricTrunk::InitializeHead(std::uint64_t seed) {
  boost::random::mt19937_64 rng(seed);
  const int h = options_.shading_width;
  const HeadLayout layout(h, options_.channels);
  head_.setZero(num_head_parameters_);
  // Each block of W_1, b_1, W_2, b_2, W_3, b_3 with its fan-in, as nn.Linear draws them.
  const int fan_in[6] = {5, 5, h, h, h, h};
  const int starts[7] = {layout.w1, layout.b1, layout.w2, layout.b2, layout.w3, layout.b3,
                         layout.m};
  for (int block = 0; block < 6; ++block) {
    const double bound = 1.0 / std::sqrt(static_cast<double>(fan_in[block]));
    boost::random::uniform_real_distribution<double> uniform(-bound, bound);
    for (int i = starts[block]; i < starts[block + 1]; ++i) head_[i] = uniform(rng);
  }
  head_[layout.m] = 0.0;  // m: the markers start at rest
  at_rest_shading_ = std::make_shared<AtRestShading>();
}

void PhotometricTrunk::SetHeadParameters(const Eigen::VectorXd& head) {
  if (head.size() != num_head_parameters_) {
    throw std::invalid_argument("PhotometricTrunk::SetHeadParameters: expected " +
                                std::to_string(num_head_parameters_) + " values, found " +
                                std::to_string(head.size()));
  }
  head_ = head;
  at_rest_shading_ = std::make_shared<AtRestShading>();
}

void PhotometricTrunk::SetBackground(const Image& background) {
  if (background.empty()) {
    background_ = Image();
    return;
  }
  if (background.rows != options_.rows || background.cols != options_.cols ||
      background.channels != options_.channels) {
    throw std::invalid_argument("PhotometricTrunk::SetBackground: expected " +
                                std::to_string(options_.rows) + "x" +
                                std::to_string(options_.cols) + "x" +
                                std::to_string(options_.channels) + ", found " +
                                background.ShapeString());
  }
  for (float v : background.data) {
    if (!std::isfinite(v)) {
      throw std::invalid_argument("PhotometricTrunk::SetBackground: a value is not finite");
    }
  }
  background_ = background;
}

void PhotometricTrunk::SetLighting(const Eigen::MatrixXf& lighting) {
  if (lighting.rows() != lighting_.rows() || lighting.cols() != lighting_.cols()) {
    throw std::invalid_argument(
        "PhotometricTrunk::SetLighting: expected " + std::to_string(lighting_.rows()) + " x " +
        std::to_string(lighting_.cols()) + " values (rows cols channels x lighting "
        "components), found " + std::to_string(lighting.rows()) + " x " +
        std::to_string(lighting.cols()));
  }
  if (!lighting.allFinite()) {
    throw std::invalid_argument("PhotometricTrunk::SetLighting: the lighting images hold a "
                                "non-finite value");
  }
  lighting_ = lighting;
}

double PhotometricTrunk::LightingRms() const {
  if (lighting_.size() == 0) return 0;
  return std::sqrt(lighting_.cast<double>().squaredNorm() / static_cast<double>(lighting_.size()));
}

double PhotometricTrunk::BackgroundRms() const {
  if (background_.empty()) return 0;
  double sum = 0;
  for (float v : background_.data) sum += static_cast<double>(v) * v;
  return std::sqrt(sum / static_cast<double>(background_.size()));
}

Eigen::Vector2d PhotometricTrunk::PixelCoordinate(int pixel) const {
  const int r = pixel / options_.cols;
  const int c = pixel % options_.cols;
  const double rows = options_.rows;
  return {(2.0 * c + 1.0 - options_.cols) / rows, (2.0 * r + 1.0) / rows - 1.0};
}

std::vector<int> PhotometricTrunk::AllPixels() const {
  std::vector<int> pixels(static_cast<std::size_t>(options_.rows) * options_.cols);
  for (std::size_t j = 0; j < pixels.size(); ++j) pixels[j] = static_cast<int>(j);
  return pixels;
}

void PhotometricTrunk::SampleMarkers(const Markers& markers, MarkerSampling sampling,
                                     double row, double col, double* value, double* d_row,
                                     double* d_col) const {
  const int c = options_.channels;
  std::fill(value, value + c, 0.0);
  if (d_row != nullptr) std::fill(d_row, d_row + c, 0.0);
  if (d_col != nullptr) std::fill(d_col, d_col + c, 0.0);
  // One bilinear sample of `image` at (y, x) in its pixel indices, border-clamped (no
  // slope along a clamped axis), scaled by `weight`; dy_scale / dx_scale turn the
  // image's slopes into slopes per working pixel.
  auto sample = [&](const Image& image, double y, double x, double weight, double dy_scale,
                    double dx_scale) {
    const double y_max = image.rows - 1, x_max = image.cols - 1;
    const bool y_in = y > 0 && y < y_max, x_in = x > 0 && x < x_max;
    y = std::clamp(y, 0.0, y_max);
    x = std::clamp(x, 0.0, x_max);
    const int y0 = static_cast<int>(std::floor(y)), x0 = static_cast<int>(std::floor(x));
    const int y1 = std::min(y0 + 1, image.rows - 1), x1 = std::min(x0 + 1, image.cols - 1);
    const double fy = y - y0, fx = x - x0;
    for (int ch = 0; ch < c; ++ch) {
      const double i00 = image.at(y0, x0, ch), i01 = image.at(y0, x1, ch);
      const double i10 = image.at(y1, x0, ch), i11 = image.at(y1, x1, ch);
      value[ch] += weight * ((1 - fy) * ((1 - fx) * i00 + fx * i01) +
                             fy * ((1 - fx) * i10 + fx * i11));
      if (d_row != nullptr && y_in) {
        d_row[ch] += weight * dy_scale * ((1 - fx) * (i10 - i00) + fx * (i11 - i01));
      }
      if (d_col != nullptr && x_in) {
        d_col[ch] += weight * dx_scale * ((1 - fy) * (i01 - i00) + fy * (i11 - i10));
      }
    }
  };
  if (sampling == MarkerSampling::kWorkingResolution) {
    sample(markers.at_rest, row, col, 1.0, 1.0, 1.0);
    return;
  }
  const Image& reference = markers.reference;
  const int k = options_.supersample;
  const double sr = static_cast<double>(reference.rows) / options_.rows;
  const double sc = static_cast<double>(reference.cols) / options_.cols;
  const double weight = 1.0 / (k * k);
  // Every sample row strictly inside the reference (no clamp, each with its row slope):
  // one sample of the row sums per column of samples (Markers::row_sums).
  const double y_first = (row + 0.5 / k) * sr - 0.5;
  if (!markers.row_sums.empty() && y_first > 0 &&
      y_first < markers.row_sums.rows - 1) {
    for (int b = 0; b < k; ++b) {
      sample(markers.row_sums, y_first, (col + (b + 0.5) / k) * sc - 0.5, weight, sr, sc);
    }
    return;
  }
  for (int a = 0; a < k; ++a) {
    const double y = (row + (a + 0.5) / k) * sr - 0.5;
    for (int b = 0; b < k; ++b) {
      sample(reference, y, (col + (b + 0.5) / k) * sc - 0.5, weight, sr, sc);
    }
  }
}

template <typename Scalar>
void PhotometricTrunk::RunForward(const std::vector<int>& pixels, const VectorX<Scalar>& z,
                                  Pass* pass_holder, MatrixX<Scalar>* outputs,
                                  const PassUse& use, const Markers* markers_given) const {
  const Markers& markers = markers_given != nullptr ? *markers_given : *markers_;
  if (markers.at_rest.rows != options_.rows || markers.at_rest.cols != options_.cols ||
      markers.at_rest.channels != options_.channels ||
      markers.reference.channels != options_.channels) {
    throw std::invalid_argument("PhotometricTrunk: markers of a " +
                                markers.at_rest.ShapeString() + " grid given to a trunk of " +
                                std::to_string(options_.rows) + "x" +
                                std::to_string(options_.cols) + "x" +
                                std::to_string(options_.channels) + " (MakeMarkers makes them)");
  }
  PhotometricTrunkPass<Scalar>& pass = pass_holder->get<Scalar>();
  if (z.size() != options_.latent_dim) {
    throw std::invalid_argument("PhotometricTrunk: expected a latent of " +
                                std::to_string(options_.latent_dim) + " values, found " +
                                std::to_string(z.size()));
  }
  const int n = static_cast<int>(pixels.size());
  const int num_pixels = options_.rows * options_.cols;
  for (int j : pixels) {
    if (j < 0 || j >= num_pixels) {
      throw std::invalid_argument("PhotometricTrunk: pixel index " + std::to_string(j) +
                                  " is outside the " + std::to_string(options_.rows) + " x " +
                                  std::to_string(options_.cols) + " grid");
    }
  }
  const int c = options_.channels;
  const double t0 = static_cast<double>(z[0]), t1 = static_cast<double>(z[1]);
  const double cs = std::cos(static_cast<double>(z[2]));
  const double sn = std::sin(static_cast<double>(z[2]));
  const double step = 2.0 / options_.rows;  // one pixel in coordinates
  const double offsets[kSets][2] = {{0, 0}, {step, 0}, {-step, 0}, {0, step}, {0, -step}};
  std::vector<Eigen::Vector2d> p(n);
  for (int i = 0; i < n; ++i) p[i] = PixelCoordinate(pixels[i]);
  const VectorX<Scalar> code = z.segment(kPoseValues, CodeValues());
  const int lighting_components = options_.lighting_components;
  const VectorX<Scalar> lighting_values = z.tail(lighting_components);
  // The whole grid in order, with no reverse pass to follow: the four neighbours of a
  // pixel are pixels too, so the SIREN runs once per pixel of the grid and its one-pixel
  // border ((rows + 2) x (cols + 2) coordinates instead of 5 rows cols) and the five
  // sets are gathered from it. A neighbour's coordinate is then computed from its own
  // index rather than as p + e, which can differ in the last bit of a double.
  bool whole_grid = !use.reverse && n == num_pixels;
  for (int i = 0; whole_grid && i < n; ++i) whole_grid = pixels[i] == i;
  if (whole_grid) {
    const int rows = options_.rows, cols = options_.cols;
    const int er = rows + 2, ec = cols + 2;
    MatrixX<Scalar> grid(er * ec, 2);
    for (int r = -1; r <= rows; ++r) {
      for (int col = -1; col <= cols; ++col) {
        const double d0 = (2.0 * col + 1.0 - cols) / rows - t0;
        const double d1 = (2.0 * r + 1.0) / rows - 1.0 - t1;
        const int e = (r + 1) * ec + (col + 1);
        grid(e, 0) = static_cast<Scalar>(cs * d0 + sn * d1);
        grid(e, 1) = static_cast<Scalar>(-sn * d0 + cs * d1);
      }
    }
    const MatrixX<Scalar> extended = siren_.Forward<Scalar>(grid, code);
    pass.siren_out.resize(kSets * n, extended.cols());
    // Set k's neighbour (offsets above): +-one column for sets 1 and 2, +-one row for 3, 4.
    const int shift[kSets][2] = {{0, 0}, {0, 1}, {0, -1}, {1, 0}, {-1, 0}};
    for (int k = 0; k < kSets; ++k) {
      for (int i = 0; i < n; ++i) {
        const int r = i / cols + 1 + shift[k][0], col = i % cols + 1 + shift[k][1];
        pass.siren_out.row(k * n + i) = extended.row(r * ec + col);
      }
    }
    pass.coords.resize(0, 2);  // no reverse pass reads them
    pass.slot.clear();
  } else {
    // Any other pixel set: the SIREN runs once per distinct grid position its five sets
    // name. Where pixels are neighbours (blocks of pixels, repeats) they share
    // evaluations, and the reverse pass sums the shared rows' gradients, as the five
    // separate rows would have contributed; with no position shared the pass is the
    // plain one, row for row. A shared position takes the coordinate of its first use.
    const int cols = options_.cols, ec = cols + 2;
    // The slot of each extended-grid position, -1 where none: kept per thread and reset
    // where this pass wrote, not allocated and filled for each pass (a fit's step of 64
    // pixels touches about 300 of the GelSlim's 8,938 positions). It holds (rows + 2) x
    // (cols + 2) ints of the largest grid the thread has met (36 kB for the GelSlim).
    thread_local std::vector<int> slot_of;
    const std::size_t positions = static_cast<std::size_t>(options_.rows + 2) * ec;
    if (slot_of.size() < positions) slot_of.assign(positions, -1);
    pass.slot.resize(static_cast<std::size_t>(kSets) * n);
    std::vector<int> first_use;  // the set row of each slot's first use
    const int shift[kSets][2] = {{0, 0}, {0, 1}, {0, -1}, {1, 0}, {-1, 0}};
    for (int k = 0; k < kSets; ++k) {
      for (int i = 0; i < n; ++i) {
        const int e = (pixels[i] / cols + 1 + shift[k][0]) * ec + pixels[i] % cols + 1 +
                      shift[k][1];
        if (slot_of[e] < 0) {
          slot_of[e] = static_cast<int>(first_use.size());
          first_use.push_back(k * n + i);
        }
        pass.slot[k * n + i] = slot_of[e];
      }
    }
    const int distinct = static_cast<int>(first_use.size());
    for (int u = 0; u < distinct; ++u) {
      const int k = first_use[u] / n, i = first_use[u] % n;
      slot_of[(pixels[i] / cols + 1 + shift[k][0]) * ec + pixels[i] % cols + 1 + shift[k][1]] =
          -1;
    }
    if (distinct == kSets * n) pass.slot.clear();
    pass.coords.resize(distinct, 2);
    for (int u = 0; u < distinct; ++u) {
      const int k = first_use[u] / n, i = first_use[u] % n;
      const double d0 = p[i][0] + offsets[k][0] - t0, d1 = p[i][1] + offsets[k][1] - t1;
      pass.coords(u, 0) = static_cast<Scalar>(cs * d0 + sn * d1);
      pass.coords(u, 1) = static_cast<Scalar>(-sn * d0 + cs * d1);
    }
    MatrixX<Scalar> shared;
    if (use.jacobian) {
      siren_.ForwardAndLatentJacobian<Scalar>(pass.coords, code, &shared, &pass.siren_J_code,
                                              &pass.siren_J_q, JacobianLayout::kOutputColumns);
    } else if (use.reverse) {
      shared = siren_.Forward<Scalar>(pass.coords, code, &pass.siren_record);
    } else {
      shared = siren_.Forward<Scalar>(pass.coords, code);
    }
    if (pass.slot.empty()) {
      pass.siren_out = std::move(shared);
    } else {
      pass.siren_out.resize(kSets * n, shared.cols());
      for (int row = 0; row < kSets * n; ++row) {
        pass.siren_out.row(row) = shared.row(pass.slot[row]);
      }
    }
  }
  const MatrixX<Scalar>& s = pass.siren_out;

  pass.input.resize(5, n);
  pass.input0.setZero(5, n);
  for (int i = 0; i < n; ++i) {
    pass.input(0, i) = (s(n + i, 0) - s(2 * n + i, 0)) / Scalar(2);
    pass.input(1, i) = (s(3 * n + i, 0) - s(4 * n + i, 0)) / Scalar(2);
    pass.input(2, i) = s(i, 0);
    pass.input(3, i) = pass.input0(3, i) = static_cast<Scalar>(p[i][0]);
    pass.input(4, i) = pass.input0(4, i) = static_cast<Scalar>(p[i][1]);
  }
  // The shading network on the contact's and the flat input (the latter cached over
  // the whole grid: it depends on the head alone).
  const int h = options_.shading_width;
  const VectorX<Scalar> head = head_.cast<Scalar>();
  const MatrixX<Scalar> shade =
      ShadingNetwork<Scalar>(head, h, c, pass.input, &pass.a1, &pass.h1, &pass.a2, &pass.h2);
  // Without the head's gradient to follow, the flat input's shading of any pixel set
  // is read from the whole grid's cache.
  MatrixX<Scalar> gathered;
  const MatrixX<Scalar>* shade0 = &gathered;
  if (whole_grid) {
    shade0 = &AtRestShadingOf<Scalar>();
  } else if (!use.head_gradient) {
    const MatrixX<Scalar>& cache = AtRestShadingOf<Scalar>();
    gathered.resize(c, n);
    for (int i = 0; i < n; ++i) gathered.col(i) = cache.col(pixels[i]);
  } else {
    gathered = ShadingNetwork<Scalar>(head, h, c, pass.input0, &pass.a1f, &pass.h1f,
                                      &pass.a2f, &pass.h2f);
  }

  // The markers moved by u = m g.
  const double m = marker_scale();
  pass.marker_d_row.resize(c, n);
  pass.marker_d_col.resize(c, n);
  std::vector<double> value(c);
  if (outputs != nullptr) outputs->resize(n, c);
  for (int i = 0; i < n; ++i) {
    const int r = pixels[i] / options_.cols, col = pixels[i] % options_.cols;
    const double u0 = m * static_cast<double>(pass.input(0, i));
    const double u1 = m * static_cast<double>(pass.input(1, i));
    // The markers' slopes only serve a reverse pass or a Jacobian.
    SampleMarkers(markers, marker_sampling_, r - u1, col - u0, value.data(),
                  use.reverse ? pass.marker_d_row.col(i).data() : nullptr,
                  use.reverse ? pass.marker_d_col.col(i).data() : nullptr);
    if (outputs == nullptr) continue;
    for (int ch = 0; ch < c; ++ch) {
      (*outputs)(i, ch) = shade(ch, i) - (*shade0)(ch, i) +
                          static_cast<Scalar>(value[ch] - markers.at_rest.at(r, col, ch)) +
                          s(i, 1 + ch);
    }
    if (!background_.empty()) {
      for (int ch = 0; ch < c; ++ch) {
        (*outputs)(i, ch) += static_cast<Scalar>(background_.at(r, col, ch));
      }
    }
    if (lighting_components > 0) {
      for (int ch = 0; ch < c; ++ch) {
        (*outputs)(i, ch) +=
            lighting_.row(static_cast<Eigen::Index>(pixels[i]) * c + ch).cast<Scalar>().dot(
                lighting_values);
      }
    }
  }
}

template <typename Scalar>
void PhotometricTrunk::RunBackward(const Pass& pass_holder, const std::vector<int>& pixels,
                                   const VectorX<Scalar>& z, const MatrixX<Scalar>& dL_dY,
                                   VectorX<Scalar>* dL_dz, VectorX<Scalar>* dL_dsiren,
                                   VectorX<Scalar>* dL_dhead) const {
  const PhotometricTrunkPass<Scalar>& pass = pass_holder.get<Scalar>();
  const int n = static_cast<int>(pixels.size());
  const int c = options_.channels;
  const int h = options_.shading_width;
  if (dL_dY.rows() != n || dL_dY.cols() != c) {
    throw std::invalid_argument("PhotometricTrunk::Backward: dL/dY must be " +
                                std::to_string(n) + " x " + std::to_string(c));
  }
  const HeadLayout layout(h, c);
  const VectorX<Scalar> head = head_.cast<Scalar>();
  const Eigen::Map<const MatrixX<Scalar>> W1(head.data() + layout.w1, h, 5);
  const Eigen::Map<const MatrixX<Scalar>> W2(head.data() + layout.w2, h, h);
  const Eigen::Map<const MatrixX<Scalar>> W3(head.data() + layout.w3, c, h);
  VectorX<Scalar> dhead = VectorX<Scalar>::Zero(num_head_parameters_);
  const MatrixX<Scalar> dshade = dL_dY.transpose();  // C x N
  // Reverse through the network; adds its parameter gradients to dhead (scaled by
  // sign) and returns dL/d(input) (5 x N).
  auto network_back = [&](const MatrixX<Scalar>& in, const MatrixX<Scalar>& a1,
                          const MatrixX<Scalar>& h1, const MatrixX<Scalar>& a2,
                          const MatrixX<Scalar>& h2, const MatrixX<Scalar>& dout) {
    const MatrixX<Scalar> dh2 = W3.transpose() * dout;
    const MatrixX<Scalar> da2 = dh2.cwiseProduct(SiluSlope(a2));
    MatrixX<Scalar> dh1(h, da2.cols());
    internal::Product(W2.transpose(), da2, dh1, /*accumulate=*/false);
    const MatrixX<Scalar> da1 = dh1.cwiseProduct(SiluSlope(a1));
    if (dL_dhead != nullptr) {
      Eigen::Map<MatrixX<Scalar>>(dhead.data() + layout.w1, h, 5) += da1 * in.transpose();
      Eigen::Map<VectorX<Scalar>>(dhead.data() + layout.b1, h) += da1.rowwise().sum();
      internal::Product(da2, h1.transpose(),
                        Eigen::Map<MatrixX<Scalar>>(dhead.data() + layout.w2, h, h),
                        /*accumulate=*/true);
      Eigen::Map<VectorX<Scalar>>(dhead.data() + layout.b2, h) += da2.rowwise().sum();
      Eigen::Map<MatrixX<Scalar>>(dhead.data() + layout.w3, c, h) += dout * h2.transpose();
      Eigen::Map<VectorX<Scalar>>(dhead.data() + layout.b3, c) += dout.rowwise().sum();
    }
    return MatrixX<Scalar>(W1.transpose() * da1);
  };
  MatrixX<Scalar> dinput = network_back(pass.input, pass.a1, pass.h1, pass.a2, pass.h2, dshade);
  // The flat input does not depend on z or the SIREN: its pass only has head gradients.
  if (dL_dhead != nullptr) {
    network_back(pass.input0, pass.a1f, pass.h1f, pass.a2f, pass.h2f, -dshade);
  }

  // The markers: sampled at (r - m g_1, c - m g_0).
  const double m = marker_scale();
  double dm = 0.0;
  for (int i = 0; i < n; ++i) {
    double dg0 = 0.0, dg1 = 0.0;
    for (int ch = 0; ch < c; ++ch) {
      const double dy = static_cast<double>(dL_dY(i, ch));
      dg0 -= dy * pass.marker_d_col(ch, i);
      dg1 -= dy * pass.marker_d_row(ch, i);
    }
    dm += dg0 * static_cast<double>(pass.input(0, i)) +
          dg1 * static_cast<double>(pass.input(1, i));
    dinput(0, i) += static_cast<Scalar>(m * dg0);
    dinput(1, i) += static_cast<Scalar>(m * dg1);
  }
  dhead[layout.m] = static_cast<Scalar>(dm);
  if (dL_dhead != nullptr) *dL_dhead = dhead;
  if (dL_dz == nullptr && dL_dsiren == nullptr) return;

  // Into the SIREN's five coordinate sets.
  MatrixX<Scalar> ds = MatrixX<Scalar>::Zero(kSets * n, 1 + c);
  for (int i = 0; i < n; ++i) {
    ds(i, 0) = dinput(2, i);
    for (int ch = 0; ch < c; ++ch) ds(i, 1 + ch) = dL_dY(i, ch);
    ds(n + i, 0) = dinput(0, i) / Scalar(2);
    ds(2 * n + i, 0) = -dinput(0, i) / Scalar(2);
    ds(3 * n + i, 0) = dinput(1, i) / Scalar(2);
    ds(4 * n + i, 0) = -dinput(1, i) / Scalar(2);
  }
  if (!pass.slot.empty()) {
    // Shared positions (RunForward): each coordinate row gets the sum of its uses.
    MatrixX<Scalar> shared = MatrixX<Scalar>::Zero(pass.coords.rows(), 1 + c);
    for (int row = 0; row < kSets * n; ++row) shared.row(pass.slot[row]) += ds.row(row);
    ds = std::move(shared);
  }
  VectorX<Scalar> dcode, dtheta;
  // Without dL/dsiren (a fit) the pose needs only the first layer's weight gradients.
  // The SIREN's forward pass is the one RunForward recorded.
  siren_.Backward<Scalar>(pass.siren_record, ds, dL_dz != nullptr ? &dcode : nullptr, &dtheta,
                          dL_dsiren != nullptr
                              ? LatentModulatedSiren::WeightGradients::kAll
                              : LatentModulatedSiren::WeightGradients::kFirstLayer);
  if (dL_dz != nullptr) {
    // The pose from the first layer's gradients (header comment).
    const ParameterBlock& wblock = siren_.Block(ParameterGroup::kHiddenWeight, 0);
    const ParameterBlock& bblock = siren_.Block(ParameterGroup::kHiddenBias, 0);
    const Eigen::MatrixXd W0 =
        LatentModulatedSiren::View<double>(siren_.parameters(), wblock);
    const Eigen::MatrixXd dW0 =
        LatentModulatedSiren::View<Scalar>(dtheta, wblock).template cast<double>();
    const Eigen::VectorXd db0 =
        LatentModulatedSiren::View<Scalar>(dtheta, bblock).template cast<double>();
    const double cs = std::cos(static_cast<double>(z[2]));
    const double sn = std::sin(static_cast<double>(z[2]));
    Eigen::Matrix2d R;
    R << cs, -sn, sn, cs;
    const Eigen::Vector2d dt = -R * (W0.transpose() * db0);
    const double dphi = (-W0.col(1).cwiseProduct(dW0.col(0)) +
                         W0.col(0).cwiseProduct(dW0.col(1))).sum();
    dL_dz->resize(options_.latent_dim);
    (*dL_dz)[0] = static_cast<Scalar>(dt[0]);
    (*dL_dz)[1] = static_cast<Scalar>(dt[1]);
    (*dL_dz)[2] = static_cast<Scalar>(dphi);
    dL_dz->segment(kPoseValues, CodeValues()) = dcode;
    // The lighting values: the outputs are linear in them.
    const int k_light = options_.lighting_components;
    dL_dz->tail(k_light).setZero();
    for (int i = 0; i < n && k_light > 0; ++i) {
      for (int ch = 0; ch < c; ++ch) {
        const auto row = static_cast<Eigen::Index>(pixels[i]) * c + ch;
        dL_dz->tail(k_light) += dL_dY(i, ch) * lighting_.row(row).cast<Scalar>().transpose();
      }
    }
  }
  if (dL_dsiren != nullptr) *dL_dsiren = std::move(dtheta);
}

template <typename Scalar>
PhotometricTrunk::MatrixX<Scalar> PhotometricTrunk::Forward(const std::vector<int>& pixels,
                                                            const VectorX<Scalar>& z,
                                                            const Markers* markers) const {
  Pass pass;
  MatrixX<Scalar> outputs;
  RunForward<Scalar>(pixels, z, &pass, &outputs,
                     PassUse{/*reverse=*/false, /*head_gradient=*/false, /*jacobian=*/false},
                     markers);
  return outputs;
}

template <typename Scalar>
void PhotometricTrunk::Backward(const std::vector<int>& pixels, const VectorX<Scalar>& z,
                                const MatrixX<Scalar>& dL_dY, VectorX<Scalar>* dL_dz,
                                VectorX<Scalar>* dL_dsiren, VectorX<Scalar>* dL_dhead,
                                const Markers* markers) const {
  Pass pass;
  RunForward<Scalar>(pixels, z, &pass, nullptr,
                     PassUse{/*reverse=*/true, /*head_gradient=*/dL_dhead != nullptr,
                             /*jacobian=*/false},
                     markers);
  RunBackward<Scalar>(pass, pixels, z, dL_dY, dL_dz, dL_dsiren, dL_dhead);
}

template <typename Scalar>
void PhotometricTrunk::ForwardAndLatentJacobian(const std::vector<int>& pixels,
                                                const VectorX<Scalar>& z,
                                                MatrixX<Scalar>* outputs,
                                                MatrixX<Scalar>* J,
                                                const Markers* markers,
                                                JacobianLayout jacobian_layout) const {
  Pass pass_holder;
  // The pass keeps the distinct positions, their slots and the SIREN's Jacobians there.
  RunForward<Scalar>(pixels, z, &pass_holder, outputs,
                     PassUse{/*reverse=*/J != nullptr, /*head_gradient=*/false,
                             /*jacobian=*/J != nullptr},
                     markers);
  if (J == nullptr) return;
  const PhotometricTrunkPass<Scalar>& pass = pass_holder.get<Scalar>();
  const int n = static_cast<int>(pixels.size());
  const int c = options_.channels;
  const int h = options_.shading_width;
  const int d = options_.latent_dim;
  const int outs = 1 + c;  // the SIREN's outputs: w, then s_1 .. s_C

  // The SIREN's derivatives at every position: d s_k / d code (one column per output)
  // and d s_k / d q (one row per output).
  const MatrixX<Scalar>& J_code = pass.siren_J_code;
  const MatrixX<Scalar>& J_q = pass.siren_J_q;
  const long positions = pass.coords.rows();
  const double cs = std::cos(static_cast<double>(z[2]));
  const double sn = std::sin(static_cast<double>(z[2]));
  // Transposed, so that each position's row is a contiguous column: d x (positions outs).
  MatrixX<Scalar> J_posT(d, positions * outs);
  J_posT.middleRows(kPoseValues, CodeValues()) = J_code;
  J_posT.bottomRows(options_.lighting_components).setZero();
  for (long u = 0; u < positions; ++u) {
    const double q0 = static_cast<double>(pass.coords(u, 0));
    const double q1 = static_cast<double>(pass.coords(u, 1));
    for (int k = 0; k < outs; ++k) {
      const long col = u * outs + k;
      const double a = static_cast<double>(J_q(col, 0)), b = static_cast<double>(J_q(col, 1));
      // d s / d t = d s / d q (-R^T), R^T = [[cs, sn], [-sn, cs]]; d q / d phi = (q1, -q0).
      J_posT(0, col) = static_cast<Scalar>(-(a * cs - b * sn));
      J_posT(1, col) = static_cast<Scalar>(-(a * sn + b * cs));
      J_posT(2, col) = static_cast<Scalar>(a * q1 - b * q0);
    }
  }
  auto position = [&](int set_row, int k) {
    const long u = pass.slot.empty()
                       ? static_cast<long>(set_row)
                       : static_cast<long>(pass.slot[static_cast<std::size_t>(set_row)]);
    return J_posT.col(u * outs + k);
  };

  // The head's derivatives w.r.t. (g_0, g_1, w) for each channel: the shading network's
  // reverse pass seeded with one channel, plus the moved markers' slope.
  const HeadLayout layout(h, c);
  const VectorX<Scalar> head = head_.cast<Scalar>();
  const Eigen::Map<const MatrixX<Scalar>> W1(head.data() + layout.w1, h, 5);
  const Eigen::Map<const MatrixX<Scalar>> W2(head.data() + layout.w2, h, h);
  const Eigen::Map<const MatrixX<Scalar>> W3(head.data() + layout.w3, c, h);
  const MatrixX<Scalar> slope1 = SiluSlope(pass.a1);
  const MatrixX<Scalar> slope2 = SiluSlope(pass.a2);
  const double m = marker_scale();
  MatrixX<Scalar> JT(d, static_cast<Eigen::Index>(n) * c);
  for (int ch = 0; ch < c; ++ch) {
    const MatrixX<Scalar> da2 = slope2.array().colwise() * W3.row(ch).transpose().array();
    MatrixX<Scalar> da1(h, da2.cols());
    internal::Product(W2.transpose(), da2, da1, /*accumulate=*/false);
    da1.array() *= slope1.array();
    const MatrixX<Scalar> dinput = W1.transpose() * da1;  // 5 x N
    for (int i = 0; i < n; ++i) {
      const Scalar dg0 = dinput(0, i) - static_cast<Scalar>(m * pass.marker_d_col(ch, i));
      const Scalar dg1 = dinput(1, i) - static_cast<Scalar>(m * pass.marker_d_row(ch, i));
      auto col = JT.col(static_cast<Eigen::Index>(i) * c + ch);
      col = dinput(2, i) * position(i, 0) + position(i, 1 + ch) +
            (dg0 / Scalar(2)) * (position(n + i, 0) - position(2 * n + i, 0)) +
            (dg1 / Scalar(2)) * (position(3 * n + i, 0) - position(4 * n + i, 0));
      // The lighting values' columns: the lighting images at the pixel (zero above).
      if (options_.lighting_components > 0) {
        const auto row = static_cast<Eigen::Index>(pixels[i]) * c + ch;
        col.tail(options_.lighting_components) = lighting_.row(row).cast<Scalar>().transpose();
      }
    }
  }
  if (jacobian_layout == JacobianLayout::kOutputColumns) {
    *J = std::move(JT);
  } else {
    *J = JT.transpose();
  }
}

template <typename Scalar>
Scalar PhotometricTrunk::LossAndGradient(const std::vector<int>& pixels,
                                         const VectorX<Scalar>& z,
                                         const MatrixX<Scalar>& targets,
                                         const VectorX<Scalar>& weights,
                                         VectorX<Scalar>* dL_dz, VectorX<Scalar>* dL_dsiren,
                                         VectorX<Scalar>* dL_dhead,
                                         MatrixX<Scalar>* outputs,
                                         const Markers* markers,
                                         MatrixX<Scalar>* dL_dY) const {
  const int n = static_cast<int>(pixels.size());
  const int c = options_.channels;
  if (targets.rows() != n || targets.cols() != c ||
      (weights.size() != 0 && weights.size() != n)) {
    throw std::invalid_argument("PhotometricTrunk::LossAndGradient: expected targets of " +
                                std::to_string(n) + " x " + std::to_string(c) +
                                " and weights of " + std::to_string(n) + " (or none)");
  }
  Pass pass;
  MatrixX<Scalar> y;
  const bool backward = dL_dz != nullptr || dL_dsiren != nullptr || dL_dhead != nullptr;
  RunForward<Scalar>(pixels, z, &pass, &y,
                     PassUse{/*reverse=*/backward, /*head_gradient=*/dL_dhead != nullptr,
                             /*jacobian=*/false},
                     markers);
  // Normalised as the SIREN's own weighted MSE.
  Scalar gradient_scale = 0;
  const double norm = LatentModulatedSiren::MseNormaliser<Scalar>(weights, n, c, &gradient_scale);
  MatrixX<Scalar> dY = MatrixX<Scalar>::Zero(n, c);
  double loss = 0.0;
  if (norm > 0) {
    for (int i = 0; i < n; ++i) {
      const double w = weights.size() == 0 ? 1.0 : static_cast<double>(weights[i]);
      if (w == 0.0) continue;
      for (int ch = 0; ch < c; ++ch) {
        const double e = static_cast<double>(y(i, ch)) - static_cast<double>(targets(i, ch));
        loss += w * e * e * norm;
        dY(i, ch) = static_cast<Scalar>(2.0 * w * e * norm);
      }
    }
  }
  if (backward) {
    RunBackward<Scalar>(pass, pixels, z, dY, dL_dz, dL_dsiren, dL_dhead);
  }
  if (outputs != nullptr) *outputs = std::move(y);
  if (dL_dY != nullptr) *dL_dY = std::move(dY);
  return static_cast<Scalar>(loss);
}

#define TACTFUNC_INSTANTIATE(S)                                                           \
  template PhotometricTrunk::MatrixX<S> PhotometricTrunk::Forward<S>(                     \
      const std::vector<int>&, const VectorX<S>&, const Markers*) const;                  \
  template void PhotometricTrunk::Backward<S>(const std::vector<int>&, const VectorX<S>&, \
                                              const MatrixX<S>&, VectorX<S>*,             \
                                              VectorX<S>*, VectorX<S>*,                   \
                                              const Markers*) const;                      \
  template void PhotometricTrunk::ForwardAndLatentJacobian<S>(                            \
      const std::vector<int>&, const VectorX<S>&, MatrixX<S>*, MatrixX<S>*,               \
      const Markers*, JacobianLayout) const;                                              \
  template S PhotometricTrunk::LossAndGradient<S>(                                        \
      const std::vector<int>&, const VectorX<S>&, const MatrixX<S>&, const VectorX<S>&,   \
      VectorX<S>*, VectorX<S>*, VectorX<S>*, MatrixX<S>*, const Markers*, MatrixX<S>*) const;
TACTFUNC_INSTANTIATE(float)
TACTFUNC_INSTANTIATE(double)
#undef TACTFUNC_INSTANTIATE

}  // namespace tactfunc
