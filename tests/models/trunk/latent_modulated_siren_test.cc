// Copyright 2026 The tactfunc Authors.
//
// Every analytic derivative of the SIREN (w.r.t. z and each parameter group, the
// latent Jacobian, the Hessian-vector product) is checked against central finite
// differences and against ceres::Jet autodiff, at zero latent, at tiny inputs and at
// random ones, in double precision. Nets are tiny (width 8-12, 2-3 layers). Products
// from a Tape must equal the untaped ones bit for bit, in float and double.
//
// The float sine-and-cosine kernel (internal/fast_sincos.h) is checked against double
// std::sin / std::cos and against libmvec over the arguments the trunk meets.
//
// Tolerances: analytic vs Jet and vs 4th-order central differences must agree to a
// relative error of 1e-6 per parameter block (max-norm of the difference over the
// max-norm of the reference), with an absolute floor of 1e-10 (finite differences)
// or 1e-13 (Jet) for blocks whose exact derivative is 0 (dL/dA at z = 0).
#include "models/trunk/latent_modulated_siren.h"

#include <algorithm>
#include <cmath>
#include <functional>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <type_traits>
#include <vector>

#include "ceres/jet.h"
#include "gtest/gtest.h"
#include "models/trunk/internal/fast_sincos.h"
#include "tests/support/derivative_checks.h"
#include "tests/support/uniform_numbers.h"

namespace tactfunc {
namespace {

using Siren = LatentModulatedSiren;
using Eigen::MatrixXd;
using Eigen::MatrixXf;
using Eigen::VectorXd;
using Eigen::VectorXf;

constexpr int kChunk = 8;
using Jet = ceres::Jet<double, kChunk>;

Siren::Options SmallOptions(int channels = 2) {
  Siren::Options options;
  options.width = 8;
  options.num_hidden_layers = 2;
  options.latent_dim = 4;
  options.output_channels = channels;
  return options;
}

Siren::Options DeeperOptions() {
  Siren::Options options;
  options.width = 12;
  options.num_hidden_layers = 3;
  options.latent_dim = 6;
  options.output_channels = 1;
  return options;
}

// SmallOptions with the linear readout branch on a 3 x 4 grid: the frames' random
// coordinates fall between nodes, so the bilinear weights are generic.
Siren::Options ReadoutOptions(int channels = 2) {
  Siren::Options options = SmallOptions(channels);
  options.readout_rows = 3;
  options.readout_cols = 4;
  return options;
}

// SmallOptions with spatial latents: a 2 x 3 grid of 2-vectors (12 values) after a
// global part of `global` values (0: spatial alone), with or without the readout branch.
// Random coordinates fall between the nodes and beyond the outer ones (clamped).
Siren::Options SpatialOptions(int global, bool readout, int channels = 2) {
  Siren::Options options = readout ? ReadoutOptions(channels) : SmallOptions(channels);
  options.spatial_rows = 2;
  options.spatial_cols = 3;
  options.spatial_channels = 2;
  options.latent_dim = global + 12;
  return options;
}

// Every spatial combination: with and without the global part and the readout branch,
// and a deeper trunk with a 3 x 2 grid of 3-vectors after 2 global values.
std::vector<Siren::Options> SpatialVariants(int channels = 2) {
  Siren::Options deeper = DeeperOptions();
  deeper.output_channels = channels;
  deeper.spatial_rows = 3;
  deeper.spatial_cols = 2;
  deeper.spatial_channels = 3;
  deeper.latent_dim = 2 + 18;
  return {SpatialOptions(3, false, channels), SpatialOptions(0, false, channels),
          SpatialOptions(3, true, channels), SpatialOptions(0, true, channels), deeper};
}

std::string Describe(const Siren::Options& o) {
  return "trunk " + std::to_string(o.width) + "x" + std::to_string(o.num_hidden_layers) +
         " d=" + std::to_string(o.latent_dim) + " spatial " + std::to_string(o.spatial_rows) +
         "x" + std::to_string(o.spatial_cols) + "x" + std::to_string(o.spatial_channels) +
         (o.has_readout() ? " readout" : "");
}

using testing_util::Uniform;  // deterministic numbers in [-1, 1)

// A trunk whose c and every other block are generic (c = 0 at initialisation would
// hide mistakes in dL/dc-dependent terms).
Siren PerturbedSiren(const Siren::Options& options, unsigned seed) {
  Siren siren(options, seed);
  siren.SetParameters(siren.parameters() +
                      0.05 * Uniform(siren.NumParameters(), 1, seed + 7));
  return siren;
}

struct Frame {
  std::string name;
  MatrixXd coords;
  VectorXd z;
  MatrixXd targets;
  VectorXd weights;
};

// Zero latent, tiny inputs, random inputs; some pixels masked out.
// Spatial trunks get 16 pixels, so that every node of their grids sees some.
std::vector<Frame> Frames(const Siren& siren) {
  const int n = siren.has_spatial() ? 16 : 7;
  const int d = siren.latent_dim();
  const int c = siren.output_channels();
  VectorXd weights = 0.5 * (Uniform(n, 1, 3).array() + 1.0);
  weights[2] = 0.0;
  MatrixXd targets = 0.3 * Uniform(n, c, 4);
  targets(2, 0) = std::numeric_limits<double>::quiet_NaN();  // masked: must not leak
  return {
      {"zero_latent", Uniform(n, 2, 1), VectorXd::Zero(d), targets, weights},
      {"tiny_inputs", 1e-4 * Uniform(n, 2, 5), 1e-5 * Uniform(d, 1, 6), targets, weights},
      {"random_inputs", Uniform(n, 2, 8), Uniform(d, 1, 9), targets, weights},
  };
}

using testing_util::ExpectClose;

void ExpectBlocksClose(const Siren& siren, const VectorXd& actual,
                       const VectorXd& expected, double rel, double floor,
                       const std::string& what) {
  for (const ParameterBlock& block : siren.parameter_blocks()) {
    ExpectClose(actual.segment(block.offset, block.size()),
                expected.segment(block.offset, block.size()), rel, floor,
                what + " " + block.Name());
  }
}

using testing_util::Derivative;

VectorXd NumericGradientTheta(const Siren& siren, const Frame& frame) {
  VectorXd gradient(siren.NumParameters());
  Siren probe = siren;
  for (int i = 0; i < siren.NumParameters(); ++i) {
    gradient[i] = Derivative(
        [&](double delta) {
          VectorXd theta = siren.parameters();
          theta[i] += delta;
          probe.SetParameters(theta);
          return probe.Loss<double>(frame.coords, frame.z, frame.targets, frame.weights);
        },
        1e-4);
  }
  return gradient;
}

VectorXd NumericGradientZ(const Siren& siren, const Frame& frame) {
  VectorXd gradient(siren.latent_dim());
  for (int k = 0; k < siren.latent_dim(); ++k) {
    gradient[k] = Derivative(
        [&](double delta) {
          VectorXd z = frame.z;
          z[k] += delta;
          return siren.Loss<double>(frame.coords, z, frame.targets, frame.weights);
        },
        1e-4);
  }
  return gradient;
}

// The weighted MSE from the one-pixel template path, in any scalar type.
template <typename T>
T TemplateLoss(const Siren& siren, const T* theta, const T* z, const Frame& frame) {
  const int channels = siren.output_channels();
  T loss(0.0);
  double weight_sum = 0.0;
  std::vector<T> out(channels);
  for (int j = 0; j < frame.coords.rows(); ++j) {
    if (frame.weights[j] == 0.0) continue;
    weight_sum += frame.weights[j];
    const T x[2] = {T(frame.coords(j, 0)), T(frame.coords(j, 1))};
    siren.EvaluateWithParameters(theta, x, z, out.data());
    for (int c = 0; c < channels; ++c) {
      const T r = out[c] - frame.targets(j, c);
      loss += frame.weights[j] * r * r;
    }
  }
  return loss / (channels * weight_sum);
}

// dL/dtheta and dL/dz by forward-mode autodiff, kChunk directions at a time.
void JetGradient(const Siren& siren, const Frame& frame, VectorXd* dtheta, VectorXd* dz) {
  const int p = siren.NumParameters();
  const int d = siren.latent_dim();
  dtheta->resize(p);
  dz->resize(d);
  const int total = p + d;
  for (int start = 0; start < total; start += kChunk) {
    std::vector<Jet> theta(p), z(d);
    for (int i = 0; i < p; ++i) theta[i] = Jet(siren.parameters()[i]);
    for (int k = 0; k < d; ++k) z[k] = Jet(frame.z[k]);
    for (int i = start; i < std::min(total, start + kChunk); ++i) {
      Jet& seed = i < p ? theta[i] : z[i - p];
      seed.v[i - start] = 1.0;
    }
    const Jet loss = TemplateLoss(siren, theta.data(), z.data(), frame);
    for (int i = start; i < std::min(total, start + kChunk); ++i) {
      (i < p ? (*dtheta)[i] : (*dz)[i - p]) = loss.v[i - start];
    }
  }
}

// ---- Options and construction ------------------------------------------------------

TEST(LatentModulatedSirenOptions, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(Siren::Options().IsValid(&error)) << error;
  EXPECT_TRUE(Siren::Options().IsValid(nullptr));
}

TEST(LatentModulatedSirenOptions, BadOptionsNameTheField) {
  const std::vector<std::pair<std::string, std::function<void(Siren::Options*)>>> cases =
      {
          {"width", [](Siren::Options* o) { o->width = 0; }},
          {"num_hidden_layers", [](Siren::Options* o) { o->num_hidden_layers = 0; }},
          {"omega_0", [](Siren::Options* o) { o->omega_0 = -1.0; }},
          {"omega_0", [](Siren::Options* o) { o->omega_0 = std::nan(""); }},
          {"latent_dim", [](Siren::Options* o) { o->latent_dim = 0; }},
          {"output_channels", [](Siren::Options* o) { o->output_channels = -2; }},
          {"coordinates",
           [](Siren::Options* o) {
             o->coordinates = static_cast<CoordinateConvention>(7);
           }},
      };
  for (const auto& [field, spoil] : cases) {
    Siren::Options options;
    spoil(&options);
    std::string error;
    EXPECT_FALSE(options.IsValid(&error)) << field;
    EXPECT_NE(error.find(field), std::string::npos) << error;
    EXPECT_THROW(Siren(options, 1), std::invalid_argument) << field;
  }
}

TEST(LatentModulatedSiren, ParameterBlocksTileTheFlatVectorInTheDocumentedOrder) {
  const Siren siren(SmallOptions(), 1);
  const std::vector<ParameterBlock>& blocks = siren.parameter_blocks();
  ASSERT_EQ(blocks.size(), 2u * 2 + 4);
  int offset = 0;
  for (const ParameterBlock& block : blocks) {
    EXPECT_EQ(block.offset, offset) << block.Name();
    offset += block.size();
  }
  EXPECT_EQ(offset, siren.NumParameters());
  EXPECT_EQ(siren.NumParameters(), (16 + 8) + (64 + 8) + 16 * 4 + 16 + 2 * 8 + 2);
  const ParameterBlock& w0 = siren.Block(ParameterGroup::kHiddenWeight, 0);
  EXPECT_EQ(w0.rows, 8);
  EXPECT_EQ(w0.cols, 2);
  EXPECT_EQ(siren.Block(ParameterGroup::kHiddenBias, 1).Name(), "hidden_bias[1]");
  EXPECT_EQ(siren.Block(ParameterGroup::kModulationMatrix).rows, 16);
  EXPECT_EQ(siren.Block(ParameterGroup::kModulationMatrix).cols, 4);
  EXPECT_EQ(siren.Block(ParameterGroup::kOutputWeight).rows, 2);
  EXPECT_THROW(siren.Block(ParameterGroup::kHiddenWeight, 2), std::out_of_range);
  VectorXd theta = siren.parameters();
  EXPECT_EQ(Siren::View(&theta, siren.Block(ParameterGroup::kOutputBias))(1, 0),
            theta[siren.NumParameters() - 1]);
}

TEST(LatentModulatedSiren, InitialisationStaysInTheDocumentedRanges) {
  Siren::Options options;  // default size: enough draws to see the bounds
  options.width = 64;
  options.num_hidden_layers = 3;
  options.latent_dim = 32;
  const Siren siren(options, 42);
  const double omega = options.omega_0;
  for (const ParameterBlock& block : siren.parameter_blocks()) {
    double bound = std::sqrt(6.0 / 64) / omega;
    if (block.group == ParameterGroup::kHiddenWeight ||
        block.group == ParameterGroup::kHiddenBias) {
      if (block.layer == 0) bound = 0.5;
    } else if (block.group == ParameterGroup::kModulationMatrix) {
      bound = std::sqrt(6.0 / 32) / omega;
    } else if (block.group == ParameterGroup::kModulationBias) {
      bound = 0.0;
    }
    const double largest = Siren::View(siren.parameters(), block).cwiseAbs().maxCoeff();
    EXPECT_LE(largest, bound) << block.Name();
    if (block.size() >= 64) {
      EXPECT_GE(largest, 0.9 * bound) << block.Name() << " uses too little of its range";
    }
  }
}

TEST(LatentModulatedSiren, SameSeedGivesSameParametersAndOtherSeedsDiffer) {
  const Siren a(SmallOptions(), 5), b(SmallOptions(), 5), c(SmallOptions(), 6);
  EXPECT_EQ(a.parameters(), b.parameters());
  EXPECT_NE(a.parameters(), c.parameters());
  Siren d(SmallOptions(), 6);
  d.Initialize(5);
  EXPECT_EQ(a.parameters(), d.parameters());
}

TEST(LatentModulatedSiren, SetParametersRejectsTheWrongSize) {
  Siren siren(SmallOptions(), 1);
  EXPECT_THROW(siren.SetParameters(VectorXd::Zero(3)), std::invalid_argument);
}

// ---- Coordinates ---------------------------------------------------------------------

TEST(LatentModulatedSiren, PixelCentersFollowTheDocumentedFormula) {
  const MatrixXd grid = Siren::GridCoordinatesD(2, 4);
  ASSERT_EQ(grid.rows(), 8);
  // pixel (r, c) = (1, 3) is row 1 * 4 + 3 = 7.
  EXPECT_DOUBLE_EQ(grid(7, 0), 2.0 * 3.5 / 4 - 1.0);
  EXPECT_DOUBLE_EQ(grid(7, 1), 2.0 * 1.5 / 2 - 1.0);
  EXPECT_DOUBLE_EQ(grid(0, 0), -0.75);
  EXPECT_DOUBLE_EQ(grid(0, 1), -0.5);
  const MatrixXf gridf = Siren::GridCoordinates(2, 4);
  EXPECT_TRUE(gridf.cast<double>().isApprox(grid));
}

TEST(LatentModulatedSiren, PixelCornersReachMinusOneAndOne) {
  const MatrixXd grid =
      Siren::GridCoordinatesD(3, 5, CoordinateConvention::kPixelCorners);
  EXPECT_DOUBLE_EQ(grid(0, 0), -1.0);
  EXPECT_DOUBLE_EQ(grid(0, 1), -1.0);
  EXPECT_DOUBLE_EQ(grid(14, 0), 1.0);
  EXPECT_DOUBLE_EQ(grid(14, 1), 1.0);
  EXPECT_DOUBLE_EQ(grid(7, 0), 0.0);  // (1, 2): the centre
  const MatrixXd line =
      Siren::GridCoordinatesD(1, 1, CoordinateConvention::kPixelCorners);
  EXPECT_DOUBLE_EQ(line(0, 0), 0.0);
  EXPECT_THROW(Siren::GridCoordinatesD(0, 3), std::invalid_argument);
  CoordinateConvention parsed;
  ASSERT_TRUE(CoordinateConventionFromString("pixel_corners", &parsed));
  EXPECT_EQ(parsed, CoordinateConvention::kPixelCorners);
}

// ---- Forward -----------------------------------------------------------------------

std::vector<Siren::Options> With(std::vector<Siren::Options> options,
                                 const std::vector<Siren::Options>& more) {
  options.insert(options.end(), more.begin(), more.end());
  return options;
}

TEST(LatentModulatedSiren, BatchedForwardMatchesTheOnePixelTemplate) {
  for (const Siren::Options& options :
       With({SmallOptions(), ReadoutOptions()}, SpatialVariants())) {
    SCOPED_TRACE(Describe(options));
  const Siren siren = PerturbedSiren(options, 11);
  for (const Frame& frame : Frames(siren)) {
    const MatrixXd y = siren.Forward<double>(frame.coords, frame.z);
    ASSERT_EQ(y.rows(), frame.coords.rows());
    ASSERT_EQ(y.cols(), 2);
    for (int j = 0; j < y.rows(); ++j) {
      double out[2];
      const double x[2] = {frame.coords(j, 0), frame.coords(j, 1)};
      siren.Evaluate(x, frame.z.data(), out);
      EXPECT_NEAR(y(j, 0), out[0], 1e-13) << frame.name;
      EXPECT_NEAR(y(j, 1), out[1], 1e-13) << frame.name;
    }
  }
  }
}

TEST(LatentModulatedSiren, ReadoutNodesSitOnThePixelsOfTheirGrid) {
  for (CoordinateConvention convention :
       {CoordinateConvention::kPixelCenters, CoordinateConvention::kPixelCorners}) {
    Siren::Options options = ReadoutOptions(1);
    options.coordinates = convention;
    const Siren siren(options, 1);
    const MatrixXd grid = Siren::GridCoordinatesD(3, 4, convention);
    for (int j = 0; j < grid.rows(); ++j) {
      const Siren::ReadoutCorners corners = siren.LocateReadout(grid(j, 0), grid(j, 1));
      double on_node = 0, sum = 0;
      for (int i = 0; i < 4; ++i) {
        sum += corners.weight[i];
        if (corners.node[i] == j) on_node += corners.weight[i];
      }
      EXPECT_NEAR(sum, 1.0, 1e-12);
      EXPECT_NEAR(on_node, 1.0, 1e-12) << "pixel " << j << " " << ToString(convention);
    }
    // Outside the grid: clamped to the edge nodes; a NaN coordinate gives NaN weights.
    const Siren::ReadoutCorners outside = siren.LocateReadout(-5.0, 5.0);
    double weight_on_corner = 0;
    for (int i = 0; i < 4; ++i) weight_on_corner += outside.node[i] == 8 ? outside.weight[i] : 0;
    EXPECT_NEAR(weight_on_corner, 1.0, 1e-12);  // bottom-left node (row 2, col 0)
    EXPECT_TRUE(std::isnan(siren.LocateReadout(std::nan(""), 0.0).weight[0]));
  }
}

TEST(LatentModulatedSiren, ReadoutAloneIsTheLinearMapOfItsBasis) {
  // SIREN output layer at zero: y = R(x) z + m(x) exactly, linear in z.
  Siren siren = PerturbedSiren(ReadoutOptions(1), 12);
  VectorXd theta = siren.parameters();
  Siren::View(&theta, siren.Block(ParameterGroup::kOutputWeight)).setZero();
  Siren::View(&theta, siren.Block(ParameterGroup::kOutputBias)).setZero();
  siren.SetParameters(theta);
  const MatrixXd grid = Siren::GridCoordinatesD(3, 4);
  const VectorXd z = Uniform(4, 1, 13);
  const MatrixXd y = siren.Forward<double>(grid, z);
  const auto R = Siren::View(theta, siren.Block(ParameterGroup::kReadoutBasis));
  const auto m = Siren::View(theta, siren.Block(ParameterGroup::kReadoutMean));
  for (int j = 0; j < 12; ++j) {
    EXPECT_NEAR(y(j, 0), R.col(j).dot(z) + m(j, 0), 1e-12) << "pixel " << j;
  }
  EXPECT_THROW(Siren(SmallOptions(), 1).Block(ParameterGroup::kReadoutBasis),
               std::out_of_range);
  Siren::Options bad = SmallOptions();
  bad.readout_rows = 3;
  std::string error;
  EXPECT_FALSE(bad.IsValid(&error));
  EXPECT_NE(error.find("readout_rows"), std::string::npos) << error;
}

TEST(LatentModulatedSiren, StartGainsScaleTheReadoutProjectionPerDimension) {
  Siren siren = PerturbedSiren(ReadoutOptions(1), 14);
  const MatrixXd grid = Siren::GridCoordinatesD(3, 4);
  const MatrixXd targets = Uniform(12, 1, 15);
  const VectorXd weights = 0.5 * (Uniform(12, 1, 16).array() + 1.0);
  const VectorXd plain = siren.StartLatent<double>(grid, targets, weights);
  ASSERT_GT(plain.cwiseAbs().minCoeff(), 0.0);
  const VectorXd gains = (VectorXd(4) << 1.0, 0.5, 0.25, 0.0).finished();
  siren.set_start_gains(gains);
  EXPECT_EQ(siren.start_gains(), gains);
  const VectorXd shrunk = siren.StartLatent<double>(grid, targets, weights);
  for (int k = 0; k < 4; ++k) EXPECT_NEAR(shrunk[k], gains[k] * plain[k], 1e-15) << k;
  // Copies keep them; empty gains are none.
  const Siren copy = siren;
  EXPECT_EQ(copy.start_gains(), gains);
  siren.set_start_gains(VectorXd());
  EXPECT_EQ(siren.StartLatent<double>(grid, targets, weights), plain);
  // Refused: another size, a non-finite gain, a trunk without the branch.
  EXPECT_THROW(siren.set_start_gains(VectorXd::Ones(3)), std::invalid_argument);
  EXPECT_THROW(siren.set_start_gains(VectorXd::Constant(4, std::nan(""))), std::invalid_argument);
  Siren plain_trunk(SmallOptions(), 1);
  EXPECT_THROW(plain_trunk.set_start_gains(VectorXd::Ones(4)), std::invalid_argument);
}

TEST(LatentModulatedSiren, AtZeroLatentWithZeroModulationBiasTheTrunkIgnoresA) {
  Siren siren(SmallOptions(), 3);
  const MatrixXd coords = Uniform(5, 2, 2);
  const MatrixXd before = siren.Forward<double>(coords, VectorXd::Zero(4));
  VectorXd theta = siren.parameters();
  Siren::View(&theta, siren.Block(ParameterGroup::kModulationMatrix)).setRandom();
  siren.SetParameters(theta);
  EXPECT_EQ(before, siren.Forward<double>(coords, VectorXd::Zero(4)));
}

// float runs sin(omega_0 * pre) with |pre| ~ 1 in single precision; a phase error of
// ~30 * 6e-8 per layer gives output errors ~1e-6. 2e-5 leaves a margin, ten times
// below the output's own spread (~0.1).
TEST(LatentModulatedSiren, FloatAndDoubleForwardAgreeTo2em5) {
  const Siren siren = PerturbedSiren(DeeperOptions(), 12);
  const MatrixXd coords = siren.Grid<double>(9, 11);
  const VectorXd z = Uniform(6, 1, 13);
  const MatrixXd y = siren.Forward<double>(coords, z);
  const MatrixXf yf = siren.Forward<float>(coords.cast<float>(), z.cast<float>());
  EXPECT_LE((yf.cast<double>() - y).cwiseAbs().maxCoeff(), 2e-5);
  EXPECT_GE(y.cwiseAbs().maxCoeff(), 1e-2);  // not comparing zeros
  // Gradients too, relative to their size.
  const MatrixXd targets = 0.2 * Uniform(99, 1, 14);
  VectorXd dz, dtheta;
  VectorXf dzf, dthetaf;
  siren.LossAndGradient<double>(coords, z, targets, VectorXd(), &dz, &dtheta);
  siren.LossAndGradient<float>(coords.cast<float>(), z.cast<float>(),
                               targets.cast<float>(), VectorXf(), &dzf, &dthetaf);
  ExpectClose(dzf.cast<double>(), dz, 1e-4, 0.0, "float dL/dz");
  ExpectClose(dthetaf.cast<double>(), dtheta, 1e-4, 0.0, "float dL/dtheta");
}

TEST(LatentModulatedSiren, CoordinateJacobianMatchesCentralDifferences) {
  // d y / d x_j from the latent Jacobian's reverse passes, against central differences
  // of Forward moving each pixel's coordinates, for two channels and a deeper trunk.
  for (const Siren::Options& options : {SmallOptions(2), DeeperOptions()}) {
    const Siren siren = PerturbedSiren(options, 3);
    const MatrixXd coords = Uniform(7, 2, 21);
    const VectorXd z = Uniform(options.latent_dim, 1, 22);
    MatrixXd J_z, J_x, J_z_alone;
    siren.ForwardAndLatentJacobian<double>(coords, z, nullptr, &J_z, &J_x);
    siren.ForwardAndLatentJacobian<double>(coords, z, nullptr, &J_z_alone);
    EXPECT_EQ(J_z, J_z_alone) << Describe(options);
    const int channels = options.output_channels;
    ASSERT_EQ(J_x.rows(), coords.rows() * channels);
    ASSERT_EQ(J_x.cols(), 2);
    const double eps = 1e-6;
    for (int k = 0; k < 2; ++k) {
      MatrixXd up = coords, down = coords;
      up.col(k).array() += eps;
      down.col(k).array() -= eps;
      const MatrixXd numeric = (siren.Forward<double>(up, z) - siren.Forward<double>(down, z)) /
                               (2 * eps);
      for (int j = 0; j < coords.rows(); ++j) {
        for (int ch = 0; ch < channels; ++ch) {
          EXPECT_NEAR(J_x(j * channels + ch, k), numeric(j, ch),
                      1e-6 * (1 + std::abs(numeric(j, ch))))
              << Describe(options) << " pixel " << j << " channel " << ch << " x_" << k;
        }
      }
    }
    // Asked for alone, without J_y_z.
    MatrixXd J_x_alone;
    siren.ForwardAndLatentJacobian<double>(coords, z, nullptr, nullptr, &J_x_alone);
    EXPECT_EQ(J_x, J_x_alone) << Describe(options);
    // One column per output: the same values, transposed; J_y_x keeps its rows.
    MatrixXd J_z_columns, J_x_columns;
    siren.ForwardAndLatentJacobian<double>(coords, z, nullptr, &J_z_columns, &J_x_columns,
                                           JacobianLayout::kOutputColumns);
    EXPECT_EQ(J_z_columns, J_z.transpose()) << Describe(options);
    EXPECT_EQ(J_x_columns, J_x) << Describe(options);
  }
  // The readout branch and spatial latents move with the coordinates too: refused, and
  // the output-column layout is refused with them.
  const Siren readout(ReadoutOptions(), 1);
  MatrixXd J_x, J_z;
  EXPECT_THROW(readout.ForwardAndLatentJacobian<double>(
                   Uniform(3, 2, 1), VectorXd::Zero(4), nullptr, nullptr, &J_x),
               std::invalid_argument);
  EXPECT_THROW(readout.ForwardAndLatentJacobian<double>(Uniform(3, 2, 1), VectorXd::Zero(4),
                                                        nullptr, &J_z, nullptr,
                                                        JacobianLayout::kOutputColumns),
               std::invalid_argument);
}

TEST(LatentModulatedSiren, ExtremeInputsGiveFiniteOutputs) {
  const Siren siren(SmallOptions(), 4);
  MatrixXd coords(4, 2);
  coords << 1e6, -1e6, 1e12, 3.0, -50.0, 1e9, 0.0, 0.0;
  for (double scale : {1e3, 1e6, 1e12}) {
    const VectorXd z = scale * Uniform(4, 1, 15);
    const MatrixXd y = siren.Forward<double>(coords, z);
    EXPECT_TRUE(y.allFinite()) << scale;
    const MatrixXf yf = siren.Forward<float>(coords.cast<float>(), z.cast<float>());
    EXPECT_TRUE(yf.allFinite()) << scale;
    MatrixXd values, J;
    siren.ForwardAndLatentJacobian<double>(coords, z, &values, &J);
    EXPECT_TRUE(J.allFinite()) << scale;
    VectorXd dz, dtheta;
    siren.LossAndGradient<double>(coords, z, MatrixXd::Zero(4, 2), VectorXd(), &dz,
                                  &dtheta);
    EXPECT_TRUE(dz.allFinite() && dtheta.allFinite()) << scale;
    // sin is bounded, so the output is bounded by |W_out|_1 + |b_out|.
    EXPECT_LE(y.cwiseAbs().maxCoeff(), 1.0) << scale;
  }
}

TEST(LatentModulatedSiren, WrongShapesThrowAndQuoteTheShapes) {
  const Siren siren(SmallOptions(), 1);
  try {
    siren.Forward<double>(MatrixXd::Zero(3, 3), VectorXd::Zero(4));
    FAIL() << "expected std::invalid_argument";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("3x2"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("3x3"), std::string::npos) << e.what();
  }
  EXPECT_THROW(siren.Forward<double>(MatrixXd::Zero(3, 2), VectorXd::Zero(5)),
               std::invalid_argument);
  VectorXd dz;
  EXPECT_THROW(siren.Backward<double>(MatrixXd::Zero(3, 2), VectorXd::Zero(4),
                                      MatrixXd::Zero(3, 1), &dz, nullptr),
               std::invalid_argument);
  EXPECT_THROW(siren.Loss<double>(MatrixXd::Zero(3, 2), VectorXd::Zero(4),
                                  MatrixXd::Zero(3, 2), VectorXd::Zero(2)),
               std::invalid_argument);
}

// ---- Gradients -----------------------------------------------------------------------

TEST(LatentModulatedSiren, LossGradientMatchesFiniteDifferencesForEveryGroup) {
  for (const Siren::Options& options :
       With({SmallOptions(), DeeperOptions(), ReadoutOptions()}, SpatialVariants())) {
    SCOPED_TRACE(Describe(options));
    const Siren siren = PerturbedSiren(options, 21);
    for (const Frame& frame : Frames(siren)) {
      VectorXd dz, dtheta;
      siren.LossAndGradient<double>(frame.coords, frame.z, frame.targets, frame.weights,
                                    &dz, &dtheta);
      ExpectBlocksClose(siren, dtheta, NumericGradientTheta(siren, frame), 1e-6, 1e-10,
                        frame.name + " numeric");
      ExpectClose(dz, NumericGradientZ(siren, frame), 1e-6, 1e-10,
                  frame.name + " numeric dL/dz");
    }
  }
}

TEST(LatentModulatedSiren, LossGradientMatchesJetAutodiffForEveryGroup) {
  for (const Siren::Options& options :
       With({SmallOptions(), DeeperOptions(), ReadoutOptions()}, SpatialVariants())) {
    SCOPED_TRACE(Describe(options));
    const Siren siren = PerturbedSiren(options, 22);
    for (const Frame& frame : Frames(siren)) {
      VectorXd dz, dtheta, jet_dz, jet_dtheta;
      siren.LossAndGradient<double>(frame.coords, frame.z, frame.targets, frame.weights,
                                    &dz, &dtheta);
      JetGradient(siren, frame, &jet_dtheta, &jet_dz);
      ExpectBlocksClose(siren, dtheta, jet_dtheta, 1e-6, 1e-13, frame.name + " jet");
      ExpectClose(dz, jet_dz, 1e-6, 1e-13, frame.name + " jet dL/dz");
    }
  }
}

TEST(LatentModulatedSiren, BackwardOfAnyOutputGradientMatchesJetAutodiff) {
  for (const Siren::Options& options :
       With({SmallOptions(), ReadoutOptions()}, SpatialVariants())) {
    SCOPED_TRACE(Describe(options));
  const Siren siren = PerturbedSiren(options, 23);
  const Frame frame = Frames(siren)[2];
  const MatrixXd dL_dY = Uniform(frame.coords.rows(), 2, 24);
  VectorXd dz, dtheta;
  siren.Backward<double>(frame.coords, frame.z, dL_dY, &dz, &dtheta);
  // The same as the gradient of sum(dL_dY .* Y): a weighted MSE against targets
  // Y - dL_dY/2 (all weights 1) has gradient 2/(C N) (Y - targets) = dL_dY / (C N).
  Frame mse = frame;
  mse.weights = VectorXd::Ones(frame.coords.rows());
  mse.targets = siren.Forward<double>(frame.coords, frame.z) - 0.5 * dL_dY;
  VectorXd jet_dz, jet_dtheta;
  JetGradient(siren, mse, &jet_dtheta, &jet_dz);
  const double scale = 2.0 * frame.coords.rows();
  ExpectBlocksClose(siren, dtheta, scale * jet_dtheta, 1e-6, 1e-13, "backward");
  ExpectClose(dz, scale * jet_dz, 1e-6, 1e-13, "backward dL/dz");
  VectorXd dz_only;
  siren.Backward<double>(frame.coords, frame.z, dL_dY, &dz_only, nullptr);
  EXPECT_EQ(dz_only, dz);
  // The first layer's weights only: the other weight matrices' blocks stay zero, every
  // other block and dL/dz are those of the full pass, to the bit.
  VectorXd dz_first, dtheta_first;
  siren.Backward<double>(frame.coords, frame.z, dL_dY, &dz_first, &dtheta_first,
                         Siren::WeightGradients::kFirstLayer);
  EXPECT_EQ(dz_first, dz);
  ASSERT_EQ(dtheta_first.size(), dtheta.size());
  for (const ParameterBlock& block : siren.parameter_blocks()) {
    const bool skipped = (block.group == ParameterGroup::kHiddenWeight && block.layer > 0) ||
                         block.group == ParameterGroup::kOutputWeight;
    const VectorXd first = dtheta_first.segment(block.offset, block.size());
    if (skipped) {
      EXPECT_EQ(first.cwiseAbs().maxCoeff(), 0.0) << block.Name();
    } else {
      EXPECT_EQ(first, dtheta.segment(block.offset, block.size())) << block.Name();
    }
  }
  }
}

TEST(LatentModulatedSiren, MaskedPixelsContributeNothingEvenWithNanTargets) {
  const Siren siren = PerturbedSiren(SmallOptions(), 25);
  const Frame frame = Frames(siren)[2];  // pixel 2 has weight 0 and a NaN target
  std::vector<int> kept;
  for (int j = 0; j < frame.coords.rows(); ++j) {
    if (frame.weights[j] != 0.0) kept.push_back(j);
  }
  const MatrixXd coords = frame.coords(kept, Eigen::all);
  const MatrixXd targets = frame.targets(kept, Eigen::all);
  const VectorXd weights = frame.weights(kept);
  VectorXd dz, dtheta, kept_dz, kept_dtheta;
  const double loss = siren.LossAndGradient<double>(frame.coords, frame.z, frame.targets,
                                                    frame.weights, &dz, &dtheta);
  const double kept_loss = siren.LossAndGradient<double>(coords, frame.z, targets,
                                                         weights, &kept_dz, &kept_dtheta);
  EXPECT_TRUE(std::isfinite(loss));
  EXPECT_NEAR(loss, kept_loss, 1e-15);
  ExpectClose(dz, kept_dz, 1e-12, 0.0, "dz");
  ExpectClose(dtheta, kept_dtheta, 1e-12, 0.0, "dtheta");
  // All pixels masked: zero loss and gradient.
  const double none =
      siren.LossAndGradient<double>(frame.coords, frame.z, frame.targets,
                                    VectorXd::Zero(frame.coords.rows()), &dz, &dtheta);
  EXPECT_EQ(none, 0.0);
  EXPECT_EQ(dz.cwiseAbs().maxCoeff(), 0.0);
  EXPECT_EQ(dtheta.cwiseAbs().maxCoeff(), 0.0);
}

// ---- Latent Jacobian
// -------------------------------------------------------------------

TEST(LatentModulatedSiren, LatentJacobianEqualsTheBackwardPassPerOutput) {
  for (const Siren::Options& options :
       With({SmallOptions(3), DeeperOptions(), ReadoutOptions(3)}, SpatialVariants(3))) {
    SCOPED_TRACE(Describe(options));
    const Siren siren = PerturbedSiren(options, 31);
    const int channels = options.output_channels;
    for (const Frame& frame : Frames(siren)) {
      const int n = frame.coords.rows();
      MatrixXd y, J;
      siren.ForwardAndLatentJacobian<double>(frame.coords, frame.z, &y, &J);
      ASSERT_EQ(J.rows(), n * channels);
      ASSERT_EQ(J.cols(), options.latent_dim);
      EXPECT_EQ(y, siren.Forward<double>(frame.coords, frame.z));
      for (int j = 0; j < n; ++j) {
        for (int c = 0; c < channels; ++c) {
          MatrixXd seed = MatrixXd::Zero(n, channels);
          seed(j, c) = 1.0;
          VectorXd dz;
          siren.Backward<double>(frame.coords, frame.z, seed, &dz, nullptr);
          ExpectClose(J.row(j * channels + c).transpose(), dz, 1e-12, 1e-15,
                      frame.name + " pixel " + std::to_string(j));
        }
      }
    }
  }
}

TEST(LatentModulatedSiren, TheJacobianAlongDirectionsIsTheJacobianTimesThem) {
  for (const Siren::Options& options :
       With({SmallOptions(3), DeeperOptions(), ReadoutOptions(3)}, SpatialVariants(3))) {
    SCOPED_TRACE(Describe(options));
    const Siren siren = PerturbedSiren(options, 37);
    std::mt19937_64 rng(5);
    std::normal_distribution<double> normal;
    MatrixXd D(options.latent_dim, 4);
    for (int i = 0; i < D.size(); ++i) D.data()[i] = normal(rng);
    for (const Frame& frame : Frames(siren)) {
      MatrixXd y, J, y_along, J_along;
      siren.ForwardAndLatentJacobian<double>(frame.coords, frame.z, &y, &J);
      siren.ForwardAndLatentJacobian<double>(frame.coords, frame.z, &y_along, &J_along, nullptr,
                                             JacobianLayout::kOutputRows, &D);
      EXPECT_EQ(y_along, y);
      ASSERT_EQ(J_along.rows(), J.rows());
      ASSERT_EQ(J_along.cols(), 4);
      const MatrixXd expected = J * D;
      for (int r = 0; r < J.rows(); ++r) {
        ExpectClose(J_along.row(r).transpose(), expected.row(r).transpose(), 1e-11, 1e-14,
                    frame.name + " row " + std::to_string(r));
      }
      if (!options.has_readout() && !options.has_spatial()) {
        MatrixXd J_columns;
        siren.ForwardAndLatentJacobian<double>(frame.coords, frame.z, nullptr, &J_columns,
                                               nullptr, JacobianLayout::kOutputColumns, &D);
        EXPECT_EQ(J_columns, J_along.transpose());
      }
    }
    const MatrixXd wrong = MatrixXd::Zero(options.latent_dim + 1, 2);
    MatrixXd J;
    EXPECT_THROW(siren.ForwardAndLatentJacobian<double>(Frames(siren).front().coords,
                                                        Frames(siren).front().z, nullptr, &J,
                                                        nullptr, JacobianLayout::kOutputRows,
                                                        &wrong),
                 std::invalid_argument);
  }
}

TEST(LatentModulatedSiren, LatentJacobianMatchesJetAutodiff) {
  for (const Siren::Options& options : {SmallOptions(), ReadoutOptions()}) {
  const Siren siren = PerturbedSiren(options, 32);
  for (const Frame& frame : Frames(siren)) {
    MatrixXd J;
    siren.ForwardAndLatentJacobian<double>(frame.coords, frame.z, nullptr, &J);
    for (int j = 0; j < frame.coords.rows(); ++j) {
      const Jet x[2] = {Jet(frame.coords(j, 0)), Jet(frame.coords(j, 1))};
      Jet z[4], out[2];
      for (int k = 0; k < 4; ++k) z[k] = Jet(frame.z[k], k);
      siren.Evaluate(x, z, out);
      for (int c = 0; c < 2; ++c) {
        ExpectClose(J.row(j * 2 + c).transpose(), out[c].v.head(4), 1e-6, 1e-13,
                    frame.name);
      }
    }
  }
  }
}

// ---- Hessian-vector products
// -------------------------------------------------------------

void CheckHessianProduct(const Siren& siren, const Frame& frame, bool with_theta) {
  // Small enough that 4th-order differences resolve 1e-6 (a unit step in W_0 moves
  // phases by omega_0 = 30 rad).
  const VectorXd v_theta = 0.1 * Uniform(siren.NumParameters(), 1, 41);
  const VectorXd v_z = Uniform(siren.latent_dim(), 1, 42);
  VectorXd dz, dtheta, Hv_z, Hv_theta;
  const double loss = siren.LossGradientAndHessianProduct<double>(
      frame.coords, frame.z, frame.targets, frame.weights,
      with_theta ? &v_theta : nullptr, v_z, &dz, &dtheta, &Hv_z, &Hv_theta);
  // Value and gradients equal LossAndGradient's.
  VectorXd ref_dz, ref_dtheta;
  EXPECT_EQ(loss, siren.LossAndGradient<double>(frame.coords, frame.z, frame.targets,
                                                frame.weights, &ref_dz, &ref_dtheta));
  EXPECT_EQ(dz, ref_dz);
  EXPECT_EQ(dtheta, ref_dtheta);
  // Central differences of the exact gradient along (v_theta, v_z).
  Siren probe = siren;
  auto gradient_at = [&](double t, VectorXd* g_theta, VectorXd* g_z) {
    VectorXd theta = siren.parameters();
    if (with_theta) theta += t * v_theta;
    probe.SetParameters(theta);
    probe.LossAndGradient<double>(frame.coords, frame.z + t * v_z, frame.targets,
                                  frame.weights, g_z, g_theta);
  };
  const double h = 1e-4;
  VectorXd numeric_theta = VectorXd::Zero(siren.NumParameters());
  VectorXd numeric_z = VectorXd::Zero(siren.latent_dim());
  const double coefficients[4] = {-1, 8, -8, 1};
  const double steps[4] = {2 * h, h, -h, -2 * h};
  for (int i = 0; i < 4; ++i) {
    VectorXd g_theta, g_z;
    gradient_at(steps[i], &g_theta, &g_z);
    numeric_theta += coefficients[i] / (12 * h) * g_theta;
    numeric_z += coefficients[i] / (12 * h) * g_z;
  }
  const std::string what = frame.name + (with_theta ? " (theta, z)" : " (0, z)");
  ExpectBlocksClose(siren, Hv_theta, numeric_theta, 1e-6, 1e-9, what);
  ExpectClose(Hv_z, numeric_z, 1e-6, 1e-9, what + " Hv_z");
}

TEST(LatentModulatedSiren, HessianProductAlongTheLatentMatchesFiniteDifferences) {
  for (const Siren::Options& options :
       With({SmallOptions(), DeeperOptions(), ReadoutOptions()}, SpatialVariants())) {
    SCOPED_TRACE(Describe(options));
    const Siren siren = PerturbedSiren(options, 43);
    for (const Frame& frame : Frames(siren)) CheckHessianProduct(siren, frame, false);
  }
}

TEST(LatentModulatedSiren, HessianProductAlongThetaAndLatentMatchesFiniteDifferences) {
  for (const Siren::Options& options :
       With({SmallOptions(), DeeperOptions(), ReadoutOptions()}, SpatialVariants())) {
    SCOPED_TRACE(Describe(options));
    const Siren siren = PerturbedSiren(options, 44);
    for (const Frame& frame : Frames(siren)) CheckHessianProduct(siren, frame, true);
  }
}

TEST(LatentModulatedSiren, FloatHessianProductAgreesWithDouble) {
  const Siren siren = PerturbedSiren(DeeperOptions(), 45);
  const Frame frame = Frames(siren)[2];
  const VectorXd v_z = Uniform(siren.latent_dim(), 1, 46);
  VectorXd Hv_z, Hv_theta;
  VectorXf Hv_zf, Hv_thetaf;
  siren.LossGradientAndHessianProduct<double>(frame.coords, frame.z, frame.targets,
                                              frame.weights, nullptr, v_z, nullptr,
                                              nullptr, &Hv_z, &Hv_theta);
  MatrixXf targets = frame.targets.cast<float>();
  targets(2, 0) = 0.0f;
  siren.LossGradientAndHessianProduct<float>(
      frame.coords.cast<float>(), frame.z.cast<float>(), targets,
      frame.weights.cast<float>(), nullptr, v_z.cast<float>(), nullptr, nullptr, &Hv_zf,
      &Hv_thetaf);
  ExpectClose(Hv_zf.cast<double>(), Hv_z, 1e-4, 0.0, "float Hv_z");
  ExpectClose(Hv_thetaf.cast<double>(), Hv_theta, 1e-4, 0.0, "float Hv_theta");
}

// ---- Tapes -------------------------------------------------------------------------

// LossAndGradient with a tape against LossGradientAndHessianProduct without one, in
// scalar S on `coords`: the same loss and gradients, and HessianProduct from the tape
// the same Hv_z and Hv_theta, bit for bit (the same arithmetic on the same values), with
// and without v_theta. The tape is recorded as MetaSgd records it (dL/dz alone).
template <typename S>
void ExpectTapedPassesBitIdentical(const Siren& siren, const MatrixXd& coords_d,
                                   unsigned seed) {
  using MatrixS = Siren::MatrixX<S>;
  using VectorS = Siren::VectorX<S>;
  const long n = coords_d.rows();
  const int d = siren.latent_dim();
  const MatrixS coords = coords_d.cast<S>();
  const VectorS z = (0.5 * Uniform(d, 1, seed)).cast<S>();
  const MatrixS targets = (0.3 * Uniform(n, siren.output_channels(), seed + 1)).cast<S>();
  VectorS weights = (0.5 * (Uniform(n, 1, seed + 2).array() + 1.0)).matrix().cast<S>();
  weights[n / 2] = S(0);
  const VectorS v_theta = (0.1 * Uniform(siren.NumParameters(), 1, seed + 3)).cast<S>();
  const VectorS v_z = Uniform(d, 1, seed + 4).cast<S>();

  Siren::Tape<S> tape;
  EXPECT_TRUE(tape.empty());
  VectorS dz;
  const S loss = siren.LossAndGradient<S>(coords, z, targets, weights, &dz, nullptr, &tape);
  EXPECT_FALSE(tape.empty());
  VectorS full_dz, dtheta, ref_dz, ref_dtheta;
  siren.LossAndGradient<S>(coords, z, targets, weights, &full_dz, &dtheta, &tape);
  for (const VectorS* direction : {static_cast<const VectorS*>(nullptr), &v_theta}) {
    const std::string what = direction == nullptr ? "v = (0, v_z)" : "v = (v_theta, v_z)";
    VectorS hz, htheta, ref_hz, ref_htheta, alone_hz, alone_htheta;
    const S ref_loss = siren.LossGradientAndHessianProduct<S>(
        coords, z, targets, weights, direction, v_z, &ref_dz, &ref_dtheta, &ref_hz,
        &ref_htheta);
    // The products alone, as MetaSgd asked for them before tapes.
    siren.LossGradientAndHessianProduct<S>(coords, z, targets, weights, direction, v_z,
                                           nullptr, nullptr, &alone_hz, &alone_htheta);
    siren.HessianProduct<S>(tape, direction, v_z, &hz, &htheta);
    EXPECT_EQ(loss, ref_loss) << what;
    EXPECT_EQ(dz, ref_dz) << what;
    EXPECT_EQ(full_dz, ref_dz) << what;
    EXPECT_EQ(dtheta, ref_dtheta) << what;
    EXPECT_EQ(hz, ref_hz) << what << ", max difference " << (hz - ref_hz).cwiseAbs().maxCoeff();
    EXPECT_EQ(htheta, ref_htheta)
        << what << ", max difference " << (htheta - ref_htheta).cwiseAbs().maxCoeff();
    EXPECT_EQ(alone_hz, ref_hz) << what;
    EXPECT_EQ(alone_htheta, ref_htheta) << what;
    EXPECT_GT(hz.norm(), S(0)) << what;
    EXPECT_GT(htheta.norm(), S(0)) << what;
  }
}

// check(siren, coords) for global, deeper, readout (also frozen) and every spatial
// variant of the trunk (seeded from `seed`), each on 7 random pixels (one block) and on
// a 20 x 30 grid (600 pixels: blocks of 256, 256 and 88, and runs of pixels sharing
// their spatial corners).
template <typename Check>
void ForEachTrunkAndPixelSet(unsigned seed, const Check& check) {
  const std::vector<Siren::Options> variants =
      With({SmallOptions(), DeeperOptions(), ReadoutOptions()}, SpatialVariants());
  for (std::size_t i = 0; i <= variants.size(); ++i) {
    const bool frozen = i == variants.size();  // the readout branch once more, frozen
    Siren siren = PerturbedSiren(frozen ? ReadoutOptions() : variants[i],
                                 seed + static_cast<unsigned>(i));
    siren.set_readout_frozen(frozen);
    SCOPED_TRACE(Describe(siren.options()) + (frozen ? " (frozen)" : ""));
    for (const MatrixXd& coords : {Uniform(7, 2, seed + 10), siren.Grid<double>(20, 30)}) {
      SCOPED_TRACE(std::to_string(coords.rows()) + " pixels");
      check(siren, coords);
    }
  }
}

// Float and double, on every trunk and pixel set of ForEachTrunkAndPixelSet.
TEST(LatentModulatedSirenTape, HessianProductFromATapeIsBitIdenticalToTheUntapedOne) {
  ForEachTrunkAndPixelSet(70, [](const Siren& siren, const MatrixXd& coords) {
    ExpectTapedPassesBitIdentical<double>(siren, coords, 81);
    ExpectTapedPassesBitIdentical<float>(siren, coords, 82);
  });
}

TEST(LatentModulatedSirenTape, RefusesAnEmptyTapeAndOneOfOtherParameters) {
  Siren siren = PerturbedSiren(SmallOptions(), 90);
  const Frame frame = Frames(siren)[2];
  VectorXd hz, expected;
  Siren::Tape<double> tape;
  auto product = [&](const Siren& trunk) {
    trunk.HessianProduct<double>(tape, nullptr, frame.z, &hz, nullptr);
  };
  EXPECT_THROW(product(siren), std::invalid_argument);
  EXPECT_THROW(siren.LossAndGradient<double>(frame.coords, frame.z, frame.targets,
                                             frame.weights, nullptr, nullptr, nullptr),
               std::invalid_argument);
  siren.LossAndGradient<double>(frame.coords, frame.z, frame.targets, frame.weights,
                                nullptr, nullptr, &tape);
  product(siren);
  expected = hz;
  const Siren copy = siren;  // the same parameters: the tape holds for it
  product(copy);
  EXPECT_EQ(hz, expected);
  VectorXd wrong_size = VectorXd::Zero(siren.latent_dim() + 1);
  EXPECT_THROW(siren.HessianProduct<double>(tape, nullptr, wrong_size, &hz, nullptr),
               std::invalid_argument);
  EXPECT_THROW(product(PerturbedSiren(SmallOptions(), 91)), std::invalid_argument);
  siren.SetParameters(siren.parameters());  // any change of theta invalidates it
  EXPECT_THROW(product(siren), std::invalid_argument);
  EXPECT_NO_THROW(product(copy));
  Siren::Tape<double> moved = std::move(tape);
  EXPECT_FALSE(moved.empty());
  siren.Initialize(3);
  EXPECT_THROW(siren.HessianProduct<double>(moved, nullptr, frame.z, &hz, nullptr),
               std::invalid_argument);
}


// ---- Forward records -------------------------------------------------------------------

// Forward with a record, then Backward from it, against Backward(coords, z, ...), in
// scalar S: the same dL/dz and dL/dtheta bit for bit, for every weight selection; the
// recorded outputs within float rounding of Forward's without a record (bit for bit in
// double, where both passes take the same sines).
template <typename S>
void ExpectRecordedBackwardBitIdentical(const Siren& siren, const MatrixXd& coords_d,
                                        unsigned seed) {
  using MatrixS = Siren::MatrixX<S>;
  using VectorS = Siren::VectorX<S>;
  const MatrixS coords = coords_d.cast<S>();
  const VectorS z = (0.5 * Uniform(siren.latent_dim(), 1, seed)).cast<S>();
  const MatrixS dY =
      Uniform(static_cast<int>(coords.rows()), siren.output_channels(), seed + 1).cast<S>();
  Siren::ForwardRecord<S> record;
  EXPECT_TRUE(record.empty());
  const MatrixS recorded = siren.Forward<S>(coords, z, &record);
  EXPECT_FALSE(record.empty());
  const MatrixS plain = siren.Forward<S>(coords, z);
  if constexpr (std::is_same_v<S, double>) {
    EXPECT_EQ(recorded, plain);
  } else {
    EXPECT_LE((recorded - plain).cwiseAbs().maxCoeff(), 1e-5f);
  }
  for (auto weights : {Siren::WeightGradients::kAll, Siren::WeightGradients::kFirstLayer}) {
    VectorS dz, dtheta, ref_dz, ref_dtheta;
    siren.Backward<S>(record, dY, &dz, &dtheta, weights);
    siren.Backward<S>(coords, z, dY, &ref_dz, &ref_dtheta, weights);
    EXPECT_EQ(dz, ref_dz);
    EXPECT_EQ(dtheta, ref_dtheta);
    EXPECT_GT(dz.norm(), S(0));
  }
}

// Float and double, on every trunk and pixel set of ForEachTrunkAndPixelSet.
TEST(LatentModulatedSirenForwardRecord, BackwardFromARecordIsBitIdenticalToTheOneThatReruns) {
  ForEachTrunkAndPixelSet(170, [](const Siren& siren, const MatrixXd& coords) {
    ExpectRecordedBackwardBitIdentical<double>(siren, coords, 181);
    ExpectRecordedBackwardBitIdentical<float>(siren, coords, 182);
  });
}

TEST(LatentModulatedSirenForwardRecord, RefusesAnEmptyRecordOneOfOtherParametersAndBadShapes) {
  Siren siren = PerturbedSiren(SmallOptions(), 190);
  const Frame frame = Frames(siren)[1];
  const MatrixXd dY = Uniform(static_cast<int>(frame.coords.rows()), siren.output_channels(), 191);
  VectorXd dz;
  Siren::ForwardRecord<double> record;
  EXPECT_THROW(siren.Backward<double>(record, dY, &dz, nullptr), std::invalid_argument);
  EXPECT_THROW(siren.Forward<double>(frame.coords, frame.z, nullptr), std::invalid_argument);
  siren.Forward<double>(frame.coords, frame.z, &record);
  EXPECT_NO_THROW(siren.Backward<double>(record, dY, &dz, nullptr));
  EXPECT_THROW(siren.Backward<double>(record, dY.topRows(dY.rows() - 1), &dz, nullptr),
               std::invalid_argument);
  const Siren copy = siren;  // the same parameters: the record holds for it
  EXPECT_NO_THROW(copy.Backward<double>(record, dY, &dz, nullptr));
  siren.SetParameters(siren.parameters());  // any change of theta invalidates it
  EXPECT_THROW(siren.Backward<double>(record, dY, &dz, nullptr), std::invalid_argument);
  Siren::ForwardRecord<double> moved = std::move(record);
  EXPECT_FALSE(moved.empty());
  EXPECT_NO_THROW(copy.Backward<double>(moved, dY, &dz, nullptr));
}


// ---- Spatial latents -------------------------------------------------------------------

TEST(LatentModulatedSirenSpatial, OptionsAreValidatedAndNameTheField) {
  std::string error;
  EXPECT_TRUE(SpatialOptions(3, false).IsValid(&error)) << error;
  EXPECT_TRUE(SpatialOptions(0, true).IsValid(&error)) << error;
  Siren::Options partial = SmallOptions();
  partial.spatial_rows = 2;
  partial.spatial_cols = 2;
  EXPECT_FALSE(partial.IsValid(&error));
  EXPECT_NE(error.find("spatial_channels"), std::string::npos) << error;
  Siren::Options negative = SpatialOptions(3, false);
  negative.spatial_cols = -3;
  EXPECT_FALSE(negative.IsValid(&error));
  Siren::Options too_short = SpatialOptions(0, false);
  too_short.latent_dim = 11;  // the grid alone has 12 values
  EXPECT_FALSE(too_short.IsValid(&error));
  EXPECT_NE(error.find("latent_dim"), std::string::npos) << error;
  EXPECT_THROW(Siren(too_short, 1), std::invalid_argument);
  EXPECT_EQ(SpatialOptions(3, false).global_latent_dim(), 3);
  EXPECT_EQ(SpatialOptions(3, false).modulation_inputs(), 5);
  EXPECT_EQ(SmallOptions().global_latent_dim(), 4);
  EXPECT_EQ(SmallOptions().modulation_inputs(), 4);
}

TEST(LatentModulatedSirenSpatial, ModulationMatrixHoldsTheGlobalThenTheLocalColumns) {
  const Siren siren(SpatialOptions(3, false), 1);
  const ParameterBlock& A = siren.Block(ParameterGroup::kModulationMatrix);
  EXPECT_EQ(A.rows, 16);
  EXPECT_EQ(A.cols, 3 + 2);
  EXPECT_EQ(siren.parameter_blocks().size(), 2u * 2 + 4);
  EXPECT_EQ(siren.NumParameters(), (16 + 8) + (64 + 8) + 16 * 5 + 16 + 2 * 8 + 2);
  // Initialised with the fan-in of gamma(x): d_g + c_s values.
  const double bound = std::sqrt(6.0 / 5) / 30.0;
  EXPECT_LE(Siren::View(siren.parameters(), A).cwiseAbs().maxCoeff(), bound);
  EXPECT_GE(Siren::View(siren.parameters(), A).cwiseAbs().maxCoeff(), 0.5 * bound);
}

TEST(LatentModulatedSirenSpatial, AOneNodeGridIsTheGlobalLatentTrunk) {
  // On a 1 x 1 grid z_s(x) = Z_0 everywhere: the trunk is the global-latent trunk with
  // d = d_g + c_s and the same flat parameters (the layouts coincide).
  Siren::Options one_node = SmallOptions();
  one_node.spatial_rows = one_node.spatial_cols = 1;
  one_node.spatial_channels = 2;
  one_node.latent_dim = 3 + 2;
  Siren::Options global = SmallOptions();
  global.latent_dim = 5;
  const Siren spatial = PerturbedSiren(one_node, 51);
  Siren plain(global, 1);
  ASSERT_EQ(plain.NumParameters(), spatial.NumParameters());
  plain.SetParameters(spatial.parameters());
  for (const Frame& frame : Frames(spatial)) {
    SCOPED_TRACE(frame.name);
    EXPECT_LE((spatial.Forward<double>(frame.coords, frame.z) -
               plain.Forward<double>(frame.coords, frame.z))
                  .cwiseAbs()
                  .maxCoeff(),
              1e-14);
    const VectorXd v_z = Uniform(5, 1, 52);
    const VectorXd v_theta = 0.1 * Uniform(spatial.NumParameters(), 1, 53);
    VectorXd dz[2], dtheta[2], hz[2], htheta[2];
    MatrixXd J[2];
    const Siren* trunks[2] = {&spatial, &plain};
    for (int t = 0; t < 2; ++t) {
      trunks[t]->LossGradientAndHessianProduct<double>(frame.coords, frame.z, frame.targets,
                                                       frame.weights, &v_theta, v_z, &dz[t],
                                                       &dtheta[t], &hz[t], &htheta[t]);
      trunks[t]->ForwardAndLatentJacobian<double>(frame.coords, frame.z, nullptr, &J[t]);
    }
    ExpectClose(dz[0], dz[1], 1e-12, 1e-15, "dL/dz");
    ExpectClose(dtheta[0], dtheta[1], 1e-12, 1e-15, "dL/dtheta");
    ExpectClose(hz[0], hz[1], 1e-12, 1e-15, "Hv_z");
    ExpectClose(htheta[0], htheta[1], 1e-12, 1e-15, "Hv_theta");
    EXPECT_LE((J[0] - J[1]).cwiseAbs().maxCoeff(), 1e-14);
  }
}

TEST(LatentModulatedSirenSpatial, NodesSitOnThePixelsOfTheirGridAndActLocally) {
  for (CoordinateConvention convention :
       {CoordinateConvention::kPixelCenters, CoordinateConvention::kPixelCorners}) {
    SCOPED_TRACE(ToString(convention));
    Siren::Options options = SpatialOptions(3, false);
    options.coordinates = convention;
    const Siren siren = PerturbedSiren(options, 54);
    const MatrixXd nodes = Siren::GridCoordinatesD(2, 3, convention);
    for (int j = 0; j < nodes.rows(); ++j) {
      const Siren::ReadoutCorners corners = siren.LocateSpatial(nodes(j, 0), nodes(j, 1));
      double on_node = 0;
      for (int i = 0; i < 4; ++i) on_node += corners.node[i] == j ? corners.weight[i] : 0.0;
      EXPECT_NEAR(on_node, 1.0, 1e-12) << "node " << j;
    }
    // Moving node 5's latent (bottom right) changes only the pixels it is a corner of.
    const MatrixXd pixels = Siren::GridCoordinatesD(8, 9, convention);
    const VectorXd z = Uniform(15, 1, 55);
    VectorXd moved = z;
    moved.tail(2) += VectorXd::Constant(2, 0.7);
    const MatrixXd before = siren.Forward<double>(pixels, z);
    const MatrixXd after = siren.Forward<double>(pixels, moved);
    int changed = 0;
    for (int j = 0; j < pixels.rows(); ++j) {
      const Siren::ReadoutCorners corners = siren.LocateSpatial(pixels(j, 0), pixels(j, 1));
      double weight = 0;
      for (int i = 0; i < 4; ++i) weight += corners.node[i] == 5 ? corners.weight[i] : 0.0;
      const double change = (after.row(j) - before.row(j)).cwiseAbs().maxCoeff();
      if (weight == 0.0) {
        EXPECT_EQ(change, 0.0) << "pixel " << j;
      } else {
        EXPECT_GT(change, 0.0) << "pixel " << j;
        ++changed;
      }
    }
    EXPECT_GT(changed, 0);
    EXPECT_LT(changed, pixels.rows());
  }
}

TEST(LatentModulatedSirenSpatial, LatentJacobianMatchesJetAutodiff) {
  for (const Siren::Options& options : SpatialVariants()) {
    SCOPED_TRACE(Describe(options));
    const Siren siren = PerturbedSiren(options, 56);
    const int d = options.latent_dim;
    for (const Frame& frame : Frames(siren)) {
      MatrixXd values, J;
      siren.ForwardAndLatentJacobian<double>(frame.coords, frame.z, &values, &J);
      EXPECT_EQ(values, siren.Forward<double>(frame.coords, frame.z));
      for (int j = 0; j < frame.coords.rows(); ++j) {
        const Jet x[2] = {Jet(frame.coords(j, 0)), Jet(frame.coords(j, 1))};
        for (int start = 0; start < d; start += kChunk) {
          std::vector<Jet> z(d), out(2);
          for (int k = 0; k < d; ++k) z[k] = Jet(frame.z[k]);
          for (int k = start; k < std::min(d, start + kChunk); ++k) z[k].v[k - start] = 1.0;
          siren.Evaluate(x, z.data(), out.data());
          const int count = std::min(d, start + kChunk) - start;
          for (int c = 0; c < 2; ++c) {
            ExpectClose(J.row(j * 2 + c).segment(start, count).transpose(),
                        out[c].v.head(count), 1e-6, 1e-13,
                        frame.name + " pixel " + std::to_string(j));
          }
        }
      }
    }
  }
}

// More pixels than one block of the batched passes (kPixelBlock = 256): the corners are
// located per block, the node sums run across blocks.
TEST(LatentModulatedSirenSpatial, PassesOverSeveralPixelBlocksMatchTheTemplate) {
  for (bool readout : {false, true}) {
    const Siren siren = PerturbedSiren(SpatialOptions(3, readout, 1), 57);
    SCOPED_TRACE(Describe(siren.options()));
    Frame frame;
    frame.name = "600 pixels";
    frame.coords = siren.Grid<double>(20, 30);
    frame.z = Uniform(15, 1, 58);
    frame.targets = 0.3 * Uniform(600, 1, 59);
    frame.weights = 0.5 * (Uniform(600, 1, 60).array() + 1.0);
    frame.weights[300] = 0.0;
    const MatrixXd y = siren.Forward<double>(frame.coords, frame.z);
    for (int j = 0; j < 600; j += 7) {
      double out;
      const double x[2] = {frame.coords(j, 0), frame.coords(j, 1)};
      siren.Evaluate(x, frame.z.data(), &out);
      EXPECT_NEAR(y(j, 0), out, 1e-13) << "pixel " << j;
    }
    VectorXd dz, dtheta, jet_dz, jet_dtheta;
    siren.LossAndGradient<double>(frame.coords, frame.z, frame.targets, frame.weights, &dz,
                                  &dtheta);
    JetGradient(siren, frame, &jet_dtheta, &jet_dz);
    ExpectBlocksClose(siren, dtheta, jet_dtheta, 1e-6, 1e-13, "jet");
    ExpectClose(dz, jet_dz, 1e-6, 1e-13, "jet dL/dz");
    CheckHessianProduct(siren, frame, true);
    MatrixXd J;
    siren.ForwardAndLatentJacobian<double>(frame.coords, frame.z, nullptr, &J);
    for (int j : {0, 255, 256, 599}) {
      MatrixXd seed = MatrixXd::Zero(600, 1);
      seed(j, 0) = 1.0;
      VectorXd row;
      siren.Backward<double>(frame.coords, frame.z, seed, &row, nullptr);
      ExpectClose(J.row(j).transpose(), row, 1e-12, 1e-15, "J row " + std::to_string(j));
    }
  }
}

TEST(LatentModulatedSirenSpatial, FloatPassesAgreeWithDouble) {
  Siren::Options options = SpatialVariants(1).back();  // 12 x 3, a 3 x 2 x 3 grid
  const Siren siren = PerturbedSiren(options, 61);
  const MatrixXd coords = siren.Grid<double>(9, 11);
  const VectorXd z = Uniform(options.latent_dim, 1, 62);
  const MatrixXd y = siren.Forward<double>(coords, z);
  const MatrixXf yf = siren.Forward<float>(coords.cast<float>(), z.cast<float>());
  EXPECT_LE((yf.cast<double>() - y).cwiseAbs().maxCoeff(), 2e-5);
  const MatrixXd targets = 0.2 * Uniform(99, 1, 63);
  const VectorXd v_z = Uniform(options.latent_dim, 1, 64);
  VectorXd dz, dtheta, hz, htheta;
  VectorXf dzf, dthetaf, hzf, hthetaf;
  siren.LossGradientAndHessianProduct<double>(coords, z, targets, VectorXd(), nullptr, v_z,
                                              &dz, &dtheta, &hz, &htheta);
  siren.LossGradientAndHessianProduct<float>(coords.cast<float>(), z.cast<float>(),
                                             targets.cast<float>(), VectorXf(), nullptr,
                                             v_z.cast<float>(), &dzf, &dthetaf, &hzf, &hthetaf);
  ExpectClose(dzf.cast<double>(), dz, 1e-4, 0.0, "float dL/dz");
  ExpectClose(dthetaf.cast<double>(), dtheta, 1e-4, 0.0, "float dL/dtheta");
  ExpectClose(hzf.cast<double>(), hz, 1e-4, 0.0, "float Hv_z");
  ExpectClose(hthetaf.cast<double>(), htheta, 1e-4, 0.0, "float Hv_theta");
  MatrixXd J;
  MatrixXf Jf;
  siren.ForwardAndLatentJacobian<double>(coords, z, nullptr, &J);
  siren.ForwardAndLatentJacobian<float>(coords.cast<float>(), z.cast<float>(), nullptr, &Jf);
  EXPECT_LE((Jf.cast<double>() - J).cwiseAbs().maxCoeff(), 1e-4 * J.cwiseAbs().maxCoeff());
}

TEST(LatentModulatedSirenSpatial, StartLatentIsZeroWithoutTheReadoutBranch) {
  const Siren siren = PerturbedSiren(SpatialOptions(3, false), 65);
  const Frame frame = Frames(siren)[2];
  EXPECT_EQ(siren.StartLatent<double>(frame.coords, frame.targets, frame.weights),
            VectorXd::Zero(15));
}

// ---- The float sine-and-cosine kernel (models/trunk/internal/fast_sincos.h) ----

// Arguments spread over |scale * x| <= 7,500 (a trained trunk's omega_0 pre-activations
// stay far inside), an odd count so that the vector loops' remainders run too.
std::vector<float> SinCosArguments(int n, float limit, unsigned seed) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> u(-limit, limit);
  std::vector<float> x(n);
  for (float& v : x) v = u(rng);
  return x;
}

TEST(FastSinCos, SineAndCosineAreWithinTwoUlpOfOneOfTheExactValues) {
  const float scale = 30.0f;
  const std::vector<float> x = SinCosArguments(4099, 250.0f, 3);
  std::vector<float> s(x.size()), c(x.size()), ls(x.size()), lc(x.size());
  internal::ScaledSinCos(static_cast<long>(x.size()), scale, x.data(), s.data(), c.data());
  internal::LibmvecScaledSinCos(static_cast<long>(x.size()), scale, x.data(), ls.data(),
                                lc.data());
  double worst = 0, worst_libmvec = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double y = static_cast<double>(scale * x[i]);  // the float product, as the kernel
    worst = std::max({worst, std::abs(s[i] - std::sin(y)), std::abs(c[i] - std::cos(y))});
    worst_libmvec = std::max(
        {worst_libmvec, std::abs(ls[i] - std::sin(y)), std::abs(lc[i] - std::cos(y))});
  }
  EXPECT_LE(worst, 2.4e-7);  // two float ulps of 1
  EXPECT_LE(worst_libmvec, 2.4e-7);
}

TEST(FastSinCos, QuadrantsAndTheirBoundariesHaveTheRightSigns) {
  // Arguments just either side of k pi/2, k in [-40, 40]: every quadrant's swap and sign.
  std::vector<float> x;
  for (int k = -40; k <= 40; ++k) {
    for (double offset : {-1e-3, -1e-6, 0.0, 1e-6, 1e-3, 0.3, 0.7}) {
      x.push_back(static_cast<float>(k * M_PI / 2 + offset));
    }
  }
  std::vector<float> s(x.size()), c(x.size());
  internal::ScaledSinCos(static_cast<long>(x.size()), 1.0f, x.data(), s.data(), c.data());
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double y = x[i];
    EXPECT_NEAR(s[i], std::sin(y), 2.4e-7) << "sin(" << y << ")";
    EXPECT_NEAR(c[i], std::cos(y), 2.4e-7) << "cos(" << y << ")";
  }
}

TEST(FastSinCos, EverySixteenthOfPiAndEveryBoundaryBetweenThemIsRight) {
  // The table's 32 entries (k pi/16) and the points half-way between them, where the
  // reduction's rounding switches entry, each just either side, over several periods
  // (k in [-200, 200]) and at large arguments (k near 40,000, |y| near 7,850).
  std::vector<float> x;
  for (int base : {0, 40000, -40000}) {
    for (int k = base - 200; k <= base + 200; ++k) {
      for (double half : {0.0, 0.5}) {
        float y = static_cast<float>((k + half) * M_PI / 16);
        for (int step = 0; step < 2; ++step) y = std::nextafter(y, -1e9f);
        for (int step = 0; step < 5; ++step, y = std::nextafter(y, 1e9f)) x.push_back(y);
      }
    }
  }
  std::vector<float> s(x.size()), c(x.size());
  internal::ScaledSinCos(static_cast<long>(x.size()), 1.0f, x.data(), s.data(), c.data());
  double worst = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    const double y = x[i];
    worst = std::max({worst, std::abs(s[i] - std::sin(y)), std::abs(c[i] - std::cos(y))});
  }
  EXPECT_LE(worst, 1.5e-7);  // 1.25 float ulps of 1 (the table's path reads 8.8e-8)
}

TEST(FastSinCos, InPlaceEqualsOutOfPlace) {
  const std::vector<float> x = SinCosArguments(1027, 3.0f, 5);
  std::vector<float> s(x.size()), c(x.size()), inplace = x, c2(x.size());
  const long n = static_cast<long>(x.size());
  internal::ScaledSinCos(n, 30.0f, x.data(), s.data(), c.data());
  internal::ScaledSinCos(n, 30.0f, inplace.data(), inplace.data(), c2.data());
  EXPECT_EQ(s, inplace);
  EXPECT_EQ(c, c2);
  std::vector<float> alone(x.size()), alone_inplace = x;
  internal::ScaledSinCos(n, 30.0f, x.data(), alone.data(), nullptr);
  internal::ScaledSinCos(n, 30.0f, alone_inplace.data(), alone_inplace.data(), nullptr);
  EXPECT_EQ(alone, alone_inplace);
}

// The sine alone (reduced by pi, one polynomial): within 1.5e-7 (1.25 float ulps of 1)
// of the exact sine over |scale * x| <= 7,500, and at arguments just either side of
// k pi (k up to 2,000), where the reduced argument is smallest and the sign flips.
TEST(FastSin, TheSineAloneIsWithinAFloatUlpOfOneOfTheExactSine) {
  std::vector<float> x = SinCosArguments(40001, 250.0f, 11);
  const float scale = 30.0f;
  std::vector<float> s(x.size());
  internal::ScaledSinCos(static_cast<long>(x.size()), scale, x.data(), s.data(), nullptr);
  double worst = 0;
  for (std::size_t i = 0; i < x.size(); ++i) {
    worst = std::max(worst, std::abs(s[i] - std::sin(static_cast<double>(scale * x[i]))));
  }
  EXPECT_LE(worst, 1.5e-7);

  std::vector<float> near;
  for (int k = -2000; k <= 2000; k += 7) {
    float y = static_cast<float>(k * M_PI);
    for (int step = 0; step < 3; ++step) y = std::nextafter(y, -1e9f);
    for (int step = 0; step < 7; ++step, y = std::nextafter(y, 1e9f)) near.push_back(y);
    for (double offset : {-0.3, 0.3, M_PI / 2 - 1e-4}) {
      near.push_back(static_cast<float>(k * M_PI + offset));
    }
  }
  std::vector<float> sn(near.size());
  internal::ScaledSinCos(static_cast<long>(near.size()), 1.0f, near.data(), sn.data(), nullptr);
  for (std::size_t i = 0; i < near.size(); ++i) {
    EXPECT_NEAR(sn[i], std::sin(static_cast<double>(near[i])), 1.5e-7)
        << "sin(" << near[i] << ")";
  }
}

TEST(FastSinCos, ABlockOutsideTheReducedRangeOrWithANanGoesThroughLibmvecWhole) {
  for (float odd : {1.0e4f, -3.0e5f, std::numeric_limits<float>::quiet_NaN(),
                    std::numeric_limits<float>::infinity()}) {
    std::vector<float> x = SinCosArguments(37, 3.0f, 7);
    x[11] = odd;
    const long n = static_cast<long>(x.size());
    std::vector<float> s(x.size()), c(x.size()), ls(x.size()), lc(x.size());
    internal::ScaledSinCos(n, 1.0f, x.data(), s.data(), c.data());
    internal::LibmvecScaledSinCos(n, 1.0f, x.data(), ls.data(), lc.data());
    std::vector<float> alone(x.size()), libmvec_alone(x.size());
    internal::ScaledSinCos(n, 1.0f, x.data(), alone.data(), nullptr);
    internal::LibmvecScaledSinCos(n, 1.0f, x.data(), libmvec_alone.data(), nullptr);
    for (std::size_t i = 0; i < x.size(); ++i) {
      if (std::isnan(libmvec_alone[i])) {
        EXPECT_TRUE(std::isnan(alone[i])) << "argument " << odd;
      } else {
        EXPECT_EQ(alone[i], libmvec_alone[i]) << "argument " << odd << ", element " << i;
      }
    }
    for (std::size_t i = 0; i < x.size(); ++i) {
      if (std::isnan(ls[i])) {
        EXPECT_TRUE(std::isnan(s[i]) && std::isnan(c[i])) << "argument " << odd;
      } else {
        EXPECT_EQ(s[i], ls[i]) << "argument " << odd << ", element " << i;
        EXPECT_EQ(c[i], lc[i]) << "argument " << odd << ", element " << i;
      }
    }
  }
}

}  // namespace
}  // namespace tactfunc
