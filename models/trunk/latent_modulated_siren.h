// Copyright 2026 The tactfunc Authors.
//
// LatentModulatedSiren: the shared trunk of a tactile functaset (Sec. III-B of
// "Tactile Functasets", after Dupont et al., "From data to functa", 2022).
//
// The trunk maps a pixel coordinate x in R^2 to the pixel's value y in R^C. One short
// latent z in R^d per tactile frame shifts every hidden layer through ONE linear map
// (the paper's gamma_i = W z_i, Eq. 3, plus a bias):
//
//   gamma   = A z + c,                 A: (L*width) x d,   c: L*width
//   gamma_l = gamma[l*width, (l+1)*width)                  (the l-th block of width)
//   h_0     = x                                            (2 values)
//   h_{l+1} = sin(omega_0 * (W_l h_l + b_l + gamma_l)),    l = 0 .. L-1
//   y       = W_out h_L + b_out + R(x) z + m(x)            (C values, linear)
//
// with L = num_hidden_layers, W_0: width x 2, W_l: width x width for l >= 1,
// W_out: C x width. R(x) z + m(x) is the optional LINEAR READOUT BRANCH (absent, i.e.
// zero, unless Options::readout_rows/cols are set): a per-pixel basis R (C x d per grid
// node) and mean m (C per node) stored on a readout_rows x readout_cols grid and
// interpolated bilinearly at x (nodes placed as the pixels of a grid of that size in the
// trunk's coordinate convention, so at the working resolution every pixel sits on its
// own node). With the SIREN's output at zero and R, m = a PCA basis and mean the trunk
// IS that PCA, so a trunk with the branch contains PCA at the same d as a special case;
// the SIREN then models what a linear basis cannot (docs/REPRESENTATION.md). theta = {W_l, b_l, A, c, W_out, b_out} is shared across the
// dataset and meta-learned; z starts at zero for every new frame and a few gradient
// steps fit it (Eq. 6). At z = 0 the trunk computes the "initial image" of Fig. 3.
//
// SPATIAL LATENTS (optional; after "Spatial Functa", Bauer et al. 2023). With
// Options::spatial_rows/cols/channels = G_h, G_w, c_s (all >= 1) part of z is a grid of
// local latents and gamma becomes a per-pixel shift:
//
//   z       = [z_g (d_g values), Z (G c_s values)],   G = G_h G_w,  d = d_g + G c_s
//   z_s(x)  = sum_k w_k(x) Z_k                         (c_s values: the bilinear mix of
//                                                       the grid's node latents at x)
//   gamma(x) = A_g z_g + A_s z_s(x) + c,   A = [A_g | A_s]: (L*width) x (d_g + c_s)
//
// Z_k, the latent of node k = row * G_w + col (row-major over the grid), is
// z[d_g + k c_s .. d_g + (k+1) c_s); the nodes sit where the pixels of a G_h x G_w image
// sit in the trunk's coordinate convention, and coordinates between the outer nodes and
// the image's edge take the edge nodes' latents (LocateSpatial; the same placement and
// clamping as the readout grid). d_g = 0 is a purely spatial latent. Without the option
// (all three 0, the default) d_g = d, A is (L*width) x d and the trunk is exactly the
// global-latent one above. The passes precompute P = A_s [Z_0 .. Z_{G-1}] (one column
// of L*width shifts per node) once per call and blend 4 of its columns per pixel; the
// reverse passes scatter each pixel's dL/dgamma onto the nodes with the same weights
// (dP) and finish with dL/dZ = A_s^T dP, dL/dA_s = dP Z^T. The readout branch, if
// present, still reads the whole z.
//
// Parameters. All of theta lives in ONE flat vector (double precision master copy,
// mirrored in float for the fast paths), so that Adam, SGLD and model files see one
// array. Its layout, in this order, every matrix column-major:
//   for l = 0 .. L-1:  W_l (width x fan_in_l), b_l (width)
//   A ((L*width) x d; with spatial latents (L*width) x (d_g + c_s), the columns of A_g
//      then those of A_s), c (L*width), W_out (C x width), b_out (C)
//   and, with the readout branch, R (d x (G*C)) and m (G*C), G = readout_rows *
//   readout_cols, column / entry g*C + c for node g (row-major over the grid), channel c
//   (so a trunk without the branch has exactly the layout it always had)
// parameter_blocks() lists (group, layer, offset, rows, cols) for each block, and
// View() maps a block of any flat vector (parameters or a gradient) as a matrix.
//
// Initialisation (deterministic from a seed; Boost.Random mt19937_64, never the
// clock), following SIREN (Sitzmann et al. 2020, Sec. 3.2) and functa:
//   W_0, b_0            ~ U(-1/fan_in, 1/fan_in)           (fan_in = 2)
//   W_l, b_l (l >= 1)   ~ U(-sqrt(6/width)/omega_0, +...)
//   W_out, b_out        ~ U(-sqrt(6/width)/omega_0, +...)
//   A                   ~ U(-sqrt(6/n)/omega_0, +...)      (n = A's columns: d, or
//                                                           d_g + c_s with spatial
//                                                           latents; a unit change of one
//                                                           z_k moves phases by O(1) rad)
//   c = 0, R = 0, m = 0 (the trainer may start R, m from a PCA), latents start at zero.
// Biases take the range of their layer's weights: the first layer's then spreads the
// phases of the first sines over +-omega_0/2 rad, as PyTorch SIREN's default bias does.
//
// Coordinates (CoordinateConvention). Pixel (r, c) of a rows x cols grid, pixel index
// j = r * cols + c (row-major, as Image stores pixels), maps to x = (x0, x1) with x0
// following the column (right) and x1 the row (down):
//   kPixelCenters (default): x0 = 2 (c + 0.5) / cols - 1,  x1 = 2 (r + 0.5) / rows - 1
//                            (pixel centres strictly inside (-1, 1); the grid's outer
//                            edges at exactly -1 and +1, so any resolution of the same
//                            sensor covers the same square);
//   kPixelCorners:           x0 = 2 c / (cols - 1) - 1,    x1 = 2 r / (rows - 1) - 1
//                            (first and last pixel at exactly -1 and +1; a single row
//                            or column maps to 0), as linspace(-1, 1, n) does.
//
// Batched buffers (documented once): coords N x 2 (one pixel per row, x0 then x1),
// outputs and dL/dY N x C (one pixel per row), weights N (per-pixel validity weight
// >= 0; an empty vector means all ones), latent z of size d, flat theta of size
// NumParameters(). Every batched method exists in float and double (Scalar).
//
// Blocking. Every batched pass runs over the N pixels in blocks of a few hundred (the
// .cc's kPixelBlock) so that one layer's activations (width x block) stay in L2; the
// buffers are allocated once per call at block size and reused by every block. Sums
// over pixels (gradients, Hessian-vector products) are accumulated across blocks and
// the loss is normalised once over all pixels, so the results are the unblocked ones up
// to float summation order. Callers pass whole frames; they need not block themselves.
//
// Loss. Loss() and friends use the weighted mean squared error over valid pixels
//   L(theta, z) = sum_j w_j sum_c (y_jc - t_jc)^2 / (C * sum_j w_j)
// (0 when sum_j w_j = 0). A pixel with w_j = 0 contributes nothing, even if its
// target is NaN (a dropped-out depth pixel). The mean, as functa uses, keeps learning
// rates independent of the image size.
//
// Errors: a bad Options throws std::invalid_argument from the constructor (with the
// IsValid message); buffers of the wrong shape throw std::invalid_argument quoting the
// expected and found shapes. Non-finite inputs give non-finite outputs, never a throw.
//
// Thread safety: all const methods are safe to call concurrently (no mutable state).
#ifndef TACTFUNC_MODELS_TRUNK_LATENT_MODULATED_SIREN_H_
#define TACTFUNC_MODELS_TRUNK_LATENT_MODULATED_SIREN_H_

#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <type_traits>
#include <vector>

#include "Eigen/Core"

namespace tactfunc {

namespace internal {
struct Bfloat16Weights;  // latent_modulated_siren.cc
}  // namespace internal

// How pixel indices map to trunk coordinates; see the header comment for formulas.
enum class CoordinateConvention {
  kPixelCenters,
  kPixelCorners,
};
// "pixel_centers" / "pixel_corners".
const char* ToString(CoordinateConvention convention);
bool CoordinateConventionFromString(const std::string& name,
                                    CoordinateConvention* convention);

// How a latent Jacobian is laid out: one row per output (N*C) x d, pixel-major with the
// channels interleaved, or its transpose, one column per output, d x (N*C): the layout
// a reader that scales or sums whole outputs (a Gauss-Newton Hessian, Ceres' row-major
// Jacobian blocks) takes without a strided copy.
enum class JacobianLayout {
  kOutputRows,
  kOutputColumns,
};

// The six kinds of parameter block in theta.
enum class ParameterGroup {
  kHiddenWeight,      // W_l, width x fan_in_l (one block per hidden layer)
  kHiddenBias,        // b_l, width x 1        (one block per hidden layer)
  kModulationMatrix,  // A, (L*width) x d   ((L*width) x (d_g + c_s) = [A_g | A_s] with
                      // spatial latents)
  kModulationBias,    // c, (L*width) x 1
  kOutputWeight,      // W_out, C x width
  kOutputBias,        // b_out, C x 1
  kReadoutBasis,      // R, d x (G*C)   (only with the readout branch)
  kReadoutMean,       // m, (G*C) x 1   (only with the readout branch)
};
// "hidden_weight", "hidden_bias", "modulation_matrix", "modulation_bias",
// "output_weight", "output_bias", "readout_basis", "readout_mean".
const char* ToString(ParameterGroup group);

// One block of the flat parameter vector: flat[offset .. offset + rows * cols),
// a rows x cols column-major matrix.
struct ParameterBlock {
  ParameterGroup group = ParameterGroup::kHiddenWeight;
  int layer = 0;  // hidden layer index for kHidden*, 0 otherwise
  int offset = 0;
  int rows = 0;
  int cols = 0;
  int size() const { return rows * cols; }
  // "hidden_weight[1]", "modulation_matrix", ... for messages and files.
  std::string Name() const;
};

class LatentModulatedSiren {
 public:
  template <typename Scalar>
  using MatrixX = Eigen::Matrix<Scalar, Eigen::Dynamic, Eigen::Dynamic>;
  template <typename Scalar>
  using VectorX = Eigen::Matrix<Scalar, Eigen::Dynamic, 1>;

  struct Options {
    // Number of units per hidden layer. >= 1. 128 is the trunk docs/BUILD.md times for
    // 32x32 frames; larger frames may need more.
    int width = 128;
    // Number of sine layers L (each one shifted by its block of gamma). >= 1.
    int num_hidden_layers = 4;
    // SIREN frequency omega_0, rad per unit of coordinate. > 0, finite. 30 is SIREN's
    // value (Sitzmann et al. 2020, Sec. 3.2) and functa's.
    double omega_0 = 30.0;
    // Latent dimension d. >= 1. The paper uses 512 (Sec. IV-A).
    int latent_dim = 64;
    // Output channels C: 1 for Soft Bubble depth, 3 for GelSlim RGB. >= 1.
    int output_channels = 1;
    // Pixel-to-coordinate mapping used by Grid().
    CoordinateConvention coordinates = CoordinateConvention::kPixelCenters;
    // The linear readout branch's grid (header comment): both 0 (default: no branch)
    // or both >= 1; the trainer sets them to the working resolution.
    int readout_rows = 0;
    int readout_cols = 0;
    bool has_readout() const { return readout_rows > 0 && readout_cols > 0; }
    // Spatial latents (header comment): a spatial_rows x spatial_cols grid of
    // spatial_channels-vectors, the last G c_s values of z (they count towards
    // latent_dim, which must be >= G c_s). All three 0 (default: one global latent) or
    // all three >= 1.
    int spatial_rows = 0;
    int spatial_cols = 0;
    int spatial_channels = 0;
    bool has_spatial() const {
      return spatial_rows > 0 && spatial_cols > 0 && spatial_channels > 0;
    }
    // G c_s, the grid's share of z (0 without spatial latents).
    int spatial_size() const {
      return has_spatial() ? spatial_rows * spatial_cols * spatial_channels : 0;
    }
    // d_g = latent_dim - G c_s, the global part of z (z's first d_g values).
    int global_latent_dim() const { return latent_dim - spatial_size(); }
    // Columns of A: d_g + c_s (d without spatial latents).
    int modulation_inputs() const {
      return global_latent_dim() + (has_spatial() ? spatial_channels : 0);
    }

    // True if every field is in range; otherwise false and *error (if not null)
    // names the bad field and its value.
    bool IsValid(std::string* error) const;
  };

  // A trunk with SIREN-initialised theta drawn from `seed` (see header comment).
  // Throws std::invalid_argument if !options.IsValid().
  explicit LatentModulatedSiren(const Options& options, std::uint64_t seed = 0);

  const Options& options() const { return options_; }
  int width() const { return options_.width; }
  int num_hidden_layers() const { return options_.num_hidden_layers; }
  int latent_dim() const { return options_.latent_dim; }
  int output_channels() const { return options_.output_channels; }

  // ---- Parameters ---------------------------------------------------------------
  int NumParameters() const { return num_parameters_; }
  // theta, in the layout of the header comment (double master copy).
  const Eigen::VectorXd& parameters() const { return parameters_; }
  // Replaces theta (also refreshes the float mirror). Throws std::invalid_argument
  // if the size is not NumParameters().
  void SetParameters(const Eigen::VectorXd& parameters);
  // Re-draws theta from `seed` as the constructor does.
  void Initialize(std::uint64_t seed);

  bool has_readout() const { return options_.has_readout(); }
  // A frozen readout branch still adds to every output and to dL/dz, Jacobians and
  // latent Hessian products, but the passes skip its parameter gradients and report
  // them as 0 (they cost as much as the rest of a small trunk's gradient). For training
  // with the branch fixed; default false.
  void set_readout_frozen(bool frozen) { readout_frozen_ = frozen; }
  bool readout_frozen() const { return readout_frozen_; }

  // Per-dimension gains of the readout branch's projection in StartLatent (empty, the
  // default: none, i.e. all 1): z_0 = g (*) projection. The trainer sets them to the
  // Wiener gains lambda_k / (lambda_k + sigma_k^2) of the branch's components when it has
  // noise-free copies of its frames (lambda_k the copies' variance along component k,
  // sigma_k^2 the noise's: estimation/training/trunk_trainer.h), so that a fit starts
  // from the code of the frame without its noise rather than the noisy frame's. Not
  // part of theta (no gradient). Throws std::invalid_argument unless the trunk has the
  // readout branch and `gains` is empty or has latent_dim finite entries.
  void set_start_gains(const Eigen::VectorXd& gains);
  const Eigen::VectorXd& start_gains() const { return start_gains_; }

  // Bilinear weights of coordinate (x0, x1) on the readout grid: node[i] (row-major
  // grid index) with weight[i], i < 4, weights summing to 1 (coordinates outside the
  // grid are clamped to its edge nodes). Requires has_readout().
  struct ReadoutCorners {
    long node[4];
    double weight[4];
  };
  ReadoutCorners LocateReadout(double x0, double x1) const;
  // The same on the spatial latent grid (node = row * spatial_cols + col). Requires
  // has_spatial().
  bool has_spatial() const { return options_.has_spatial(); }
  ReadoutCorners LocateSpatial(double x0, double x1) const;

  // All blocks, in flat order (2 L + 4 of them, 2 L + 6 with the readout branch).
  const std::vector<ParameterBlock>& parameter_blocks() const { return blocks_; }
  // The block of `group` (and hidden layer `layer` for kHidden*). Throws
  // std::out_of_range for a layer outside [0, L).
  const ParameterBlock& Block(ParameterGroup group, int layer = 0) const;
  // Block `block` of any flat vector (theta or a gradient) as a rows x cols matrix.
  template <typename Scalar>
  static Eigen::Map<const MatrixX<Scalar>> View(const VectorX<Scalar>& flat,
                                                const ParameterBlock& block) {
    return Eigen::Map<const MatrixX<Scalar>>(flat.data() + block.offset, block.rows,
                                             block.cols);
  }
  template <typename Scalar>
  static Eigen::Map<MatrixX<Scalar>> View(VectorX<Scalar>* flat,
                                          const ParameterBlock& block) {
    return Eigen::Map<MatrixX<Scalar>>(flat->data() + block.offset, block.rows,
                                       block.cols);
  }

  // ---- Coordinates ----------------------------------------------------------------
  // rows*cols x 2 coordinates of a rows x cols grid, pixel j = r * cols + c in row j.
  // Throws std::invalid_argument for rows or cols < 1.
  static Eigen::MatrixXf GridCoordinates(
      int rows, int cols,
      CoordinateConvention convention = CoordinateConvention::kPixelCenters);
  static Eigen::MatrixXd GridCoordinatesD(
      int rows, int cols,
      CoordinateConvention convention = CoordinateConvention::kPixelCenters);
  // The grid in this trunk's convention.
  template <typename Scalar>
  MatrixX<Scalar> Grid(int rows, int cols) const;

  // ---- Batched passes (Scalar = float or double) ------------------------------------
  // Outputs, N x C.
  template <typename Scalar>
  MatrixX<Scalar> Forward(const MatrixX<Scalar>& coords, const VectorX<Scalar>& z) const;

  // Which weight matrices a reverse pass differentiates. kFirstLayer leaves W_1 ..
  // W_{L-1} and W_out's blocks of dL/dtheta at zero (their GEMMs are skipped; every other
  // block, dL/dz and W_0's are as with kAll): for a caller that needs the latent's and the
  // first layer's gradients only, as the photometric head's contact frame in a fit
  // (models/trunk/photometric_trunk.h).
  enum class WeightGradients { kAll, kFirstLayer };

  // Exact reverse pass: given dL/dY (N x C) returns dL/dz (size d) and dL/dtheta
  // (size NumParameters(), flat layout; use View() for W_l, b_l, A, c, W_out, b_out).
  // Either output may be null. One GEMM per layer and gradient per block of pixels.
  // It runs the forward pass again, block by block, keeping only one block's values.
  template <typename Scalar>
  void Backward(const MatrixX<Scalar>& coords, const VectorX<Scalar>& z,
                const MatrixX<Scalar>& dL_dY, VectorX<Scalar>* dL_dz,
                VectorX<Scalar>* dL_dtheta,
                WeightGradients weights = WeightGradients::kAll) const;

  // A movable owner of what a pass recorded for a later pass at the same point (a
  // ForwardRecord or a Tape, below): opaque, its content defined in the .cc per kind;
  // empty until recorded.
  struct ForwardKind;  // tags naming the kinds
  struct TapeKind;
  template <typename Scalar, typename Kind>
  class Recording {
   public:
    Recording();
    ~Recording();
    Recording(Recording&& other) noexcept;
    Recording& operator=(Recording&& other) noexcept;
    bool empty() const { return record_ == nullptr; }

   private:
    friend class LatentModulatedSiren;
    struct Record;  // defined in the .cc
    std::unique_ptr<Record> record_;
  };

  // What a forward pass keeps for a reverse pass at the same coords and z, so that the
  // reverse pass need not run it again: every block's activations and cosines, about
  // (2 L + 1) x width x N values for N pixels, and copies of coords and z. For callers
  // that need the outputs before they know dL/dY (a head on the trunk's outputs, as the
  // photometric trunk's). Opaque; recorded by the Forward overload below, read by the
  // Backward overload below; valid until the parameters change, as a Tape. Movable.
  template <typename Scalar>
  using ForwardRecord = Recording<Scalar, ForwardKind>;

  // Forward that also records *record (not null; its previous content is replaced).
  // The outputs are those of the forward pass the Backward above runs, bit for bit;
  // they differ from Forward's without a record by float rounding at most (that pass
  // keeps no cosines and takes its sines from the sine-alone kernel, fast_sincos.h).
  template <typename Scalar>
  MatrixX<Scalar> Forward(const MatrixX<Scalar>& coords, const VectorX<Scalar>& z,
                          ForwardRecord<Scalar>* record) const;
  // Backward at the record's coords and z, bit-identical to Backward(coords, z, ...)
  // there, without its forward pass. Throws std::invalid_argument for an empty record,
  // one of other parameters, or dL/dY of the wrong shape.
  template <typename Scalar>
  void Backward(const ForwardRecord<Scalar>& record, const MatrixX<Scalar>& dL_dY,
                VectorX<Scalar>* dL_dz, VectorX<Scalar>* dL_dtheta,
                WeightGradients weights = WeightGradients::kAll) const;

  // Outputs (N x C, may be null) and the Jacobian of every output w.r.t. z,
  // J_y_z: (N*C) x d with row j*C + c holding d y_jc / d z (pixel-major, channels
  // interleaved as in Image). Computed as one batched reverse pass per output
  // channel w.r.t. the shifts gamma, then times A. J_y_x (may be null) receives the
  // Jacobian w.r.t. each pixel's own coordinates, (N*C) x 2 in the same row order, from
  // the same passes (d y / d x_j = W_0^T d y / d pre_0(j)); it needs a trunk without the
  // readout branch and spatial latents (std::invalid_argument otherwise), whose
  // coordinates also move their interpolation. `layout` kOutputColumns gives J_y_z
  // transposed, d x (N*C) (the same values), for a trunk without the readout branch and
  // spatial latents (std::invalid_argument otherwise); J_y_x keeps its rows.
  // With `directions` D (d x k, may be null) J_y_z receives J_y_z D instead, (N*C) x k
  // (k x (N*C) for kOutputColumns): the Jacobian along k directions of latent space,
  // e.g. a generator's d z / d pose. Without spatial latents the reverse passes are
  // taken times A D (width x k per layer) instead of A (width x d), so a few directions
  // cost far less than the whole Jacobian; with them the whole Jacobian is formed and
  // multiplied. Throws std::invalid_argument for D of another row count.
  template <typename Scalar>
  void ForwardAndLatentJacobian(const MatrixX<Scalar>& coords, const VectorX<Scalar>& z,
                                MatrixX<Scalar>* outputs, MatrixX<Scalar>* J_y_z,
                                MatrixX<Scalar>* J_y_x = nullptr,
                                JacobianLayout layout = JacobianLayout::kOutputRows,
                                const MatrixX<Scalar>* directions = nullptr) const;

  // The weighted MSE's normaliser over n pixels of C channels: returns 1 / (C sum_j w_j)
  // (w_j = 1 for every pixel when weights is empty) and sets *gradient_scale to
  // 2 / (C sum_j w_j), so that dL / dy_{j,c} = *gradient_scale w_j (y_{j,c} - t_{j,c});
  // both 0 when sum_j w_j <= 0. Every loss pass of the trunk normalises with it.
  template <typename Scalar>
  static double MseNormaliser(const VectorX<Scalar>& weights, long n, long channels,
                              Scalar* gradient_scale);

  // The weighted MSE of the header comment; targets N x C, weights N or empty.
  template <typename Scalar>
  Scalar Loss(const MatrixX<Scalar>& coords, const VectorX<Scalar>& z,
              const MatrixX<Scalar>& targets, const VectorX<Scalar>& weights) const;
  // The loss and its gradients w.r.t. z and theta (either may be null).
  template <typename Scalar>
  Scalar LossAndGradient(const MatrixX<Scalar>& coords, const VectorX<Scalar>& z,
                         const MatrixX<Scalar>& targets, const VectorX<Scalar>& weights,
                         VectorX<Scalar>* dL_dz, VectorX<Scalar>* dL_dtheta) const;
  // The same, also returning the forward pass's outputs Y (N x C) in *outputs (not
  // null), bit-identical to the loss pass's own: a caller that needs the trunk's values
  // at z as well as the gradient (the cost at a fit's start) pays no extra pass.
  template <typename Scalar>
  Scalar LossGradientAndOutputs(const MatrixX<Scalar>& coords, const VectorX<Scalar>& z,
                                const MatrixX<Scalar>& targets, const VectorX<Scalar>& weights,
                                VectorX<Scalar>* dL_dz, VectorX<Scalar>* dL_dtheta,
                                MatrixX<Scalar>* outputs) const;

  // Hessian-vector product of the loss (exact; Pearlmutter's R-operator, i.e.
  // forward-mode differentiation of the reverse pass). With H the Hessian of
  // L(theta, z) over the stacked (theta, z) and direction v = (v_theta, v_z):
  //   Hv_theta = d/dtheta (grad L . v),   Hv_z = d/dz (grad L . v).
  // v_theta == nullptr means v_theta = 0 and skips its terms; this is the case meta-
  // learning needs: with g = dL/dz, Hv_theta = d/dtheta (g . v_z) (mixed Hessian)
  // and Hv_z = d/dz (g . v_z) (latent Hessian). Returns the loss; fills the gradients
  // too when dL_dz / dL_dtheta are not null (they come at no extra cost). Hv_theta
  // and Hv_z may be null. Cost about 2.5 forward+backward passes.
  template <typename Scalar>
  Scalar LossGradientAndHessianProduct(
      const MatrixX<Scalar>& coords, const VectorX<Scalar>& z,
      const MatrixX<Scalar>& targets, const VectorX<Scalar>& weights,
      const VectorX<Scalar>* v_theta, const VectorX<Scalar>& v_z, VectorX<Scalar>* dL_dz,
      VectorX<Scalar>* dL_dtheta, VectorX<Scalar>* Hv_z, VectorX<Scalar>* Hv_theta) const;

  // What a gradient pass keeps for Hessian-vector products at the same point, so that
  // they need not repeat it: per block of pixels the activations h_l and cosines of the
  // forward pass, dL/dY and the reverse pass's dL/dh_l, about (3 L + 1) x width x N
  // values for N pixels, and copies of coords, weights and z. Opaque; recorded by the
  // LossAndGradient overload below, read by HessianProduct. A tape is valid for trunks
  // with the parameters (and options) of the one that recorded it, until they change:
  // SetParameters and Initialize invalidate it (HessianProduct then throws). Movable.
  template <typename Scalar>
  using Tape = Recording<Scalar, TapeKind>;

  // LossAndGradient that also records *tape (not null; its previous content is
  // replaced). Loss and gradients are bit-identical to the overload without a tape.
  template <typename Scalar>
  Scalar LossAndGradient(const MatrixX<Scalar>& coords, const VectorX<Scalar>& z,
                         const MatrixX<Scalar>& targets, const VectorX<Scalar>& weights,
                         VectorX<Scalar>* dL_dz, VectorX<Scalar>* dL_dtheta,
                         Tape<Scalar>* tape) const;
  // The Hessian-vector products of LossGradientAndHessianProduct at the tape's coords,
  // z, targets and weights, bit-identical to its Hv_z and Hv_theta, without repeating
  // the forward and reverse passes the tape holds: with v_theta = nullptr, 4 instead of
  // 6 matrix products per hidden layer and block. Throws std::invalid_argument for an
  // empty tape, a tape of other parameters (see Tape) or v of the wrong size.
  template <typename Scalar>
  void HessianProduct(const Tape<Scalar>& tape, const VectorX<Scalar>* v_theta,
                      const VectorX<Scalar>& v_z, VectorX<Scalar>* Hv_z,
                      VectorX<Scalar>* Hv_theta) const;

  // The latent every fit of a frame starts from: z = 0 without the readout branch (the
  // paper's start); with it, the branch's projection of the targets,
  //   z_0 = 2 / (C sum_j w_j) sum_j w_j sum_c R_c(x_j) (t_jc - m_c(x_j)),
  // one full-frame gradient step of the branch's own weighted MSE at rate 1 from z = 0,
  // which is exactly the PCA code when the branch holds a PCA basis scaled as the
  // trainer scales it (estimation/training/trunk_trainer.h, Options::readout) and every
  // pixel is valid, times start_gains() if set. Pixels with w_j = 0 are skipped (their
  // targets may be NaN).
  template <typename Scalar>
  VectorX<Scalar> StartLatent(const MatrixX<Scalar>& coords, const MatrixX<Scalar>& targets,
                              const VectorX<Scalar>& weights) const;

  // ---- One pixel, any scalar type (ceres::Jet) -------------------------------------
  // out[0 .. C) = f_theta(coord2; z) with theta = parameters(). T must support
  // +, *, and sin found by argument-dependent lookup or std:: (double, float,
  // ceres::Jet). O(L width^2) per pixel: for checks and AutoDiff cost functions, not
  // for training.
  template <typename T>
  void Evaluate(const T* coord2, const T* z, T* out) const {
    EvaluateImpl(parameters_.data(), coord2, z, out);
  }
  // The same with theta given (NumParameters() values, flat layout) in the same
  // scalar type, to differentiate w.r.t. theta.
  template <typename T>
  void EvaluateWithParameters(const T* theta, const T* coord2, const T* z, T* out) const {
    EvaluateImpl(theta, coord2, z, out);
  }

 private:
  // The value of a scalar, of a ceres::Jet (its .a) or of a Jet of Jets.
  template <typename T>
  static double PlainValue(const T& value) {
    if constexpr (std::is_arithmetic_v<T>) {
      return static_cast<double>(value);
    } else {
      return PlainValue(value.a);
    }
  }
  template <typename P, typename T>
  void EvaluateImpl(const P* theta, const T* coord2, const T* z, T* out) const;
  // Forward's passes; with record not null every block's trace is kept in it.
  template <typename Scalar>
  MatrixX<Scalar> ForwardPasses(const MatrixX<Scalar>& coords, const VectorX<Scalar>& z,
                                typename ForwardRecord<Scalar>::Record* record) const;
  // Backward's passes; with record not null its traces stand in for the forward pass.
  template <typename Scalar>
  void BackwardPasses(const MatrixX<Scalar>& coords, const VectorX<Scalar>& z,
                      const MatrixX<Scalar>& dL_dY, VectorX<Scalar>* dL_dz,
                      VectorX<Scalar>* dL_dtheta, WeightGradients weights,
                      const typename ForwardRecord<Scalar>::Record* record) const;
  // LossGradientAndHessianProduct's passes; outputs (may be null) receives Y.
  template <typename Scalar>
  Scalar LossPasses(const MatrixX<Scalar>& coords, const VectorX<Scalar>& z,
                    const MatrixX<Scalar>& targets, const VectorX<Scalar>& weights,
                    const VectorX<Scalar>* v_theta, const VectorX<Scalar>& v_z,
                    VectorX<Scalar>* dL_dz, VectorX<Scalar>* dL_dtheta, VectorX<Scalar>* Hv_z,
                    VectorX<Scalar>* Hv_theta, MatrixX<Scalar>* outputs) const;
  template <typename Scalar>
  const Scalar* ParameterData() const;
  // The hidden layers' weights transposed, W_l^T, in the scalar type: made by
  // ParametersChanged for the reverse passes' products W_l^T delta.
  template <typename Scalar>
  const std::vector<MatrixX<Scalar>>& HiddenWeightsTransposed() const;
  // The hidden layers' weights and their transposes packed for bfloat16 products, made by
  // ParametersChanged when the process's product precision is bfloat16 then; null for
  // double and otherwise (products then pack them per call, to the same bits).
  template <typename Scalar>
  const internal::Bfloat16Weights* PackedWeights() const;
  // Derives what depends on parameters_ (the float copy, the transposes, the bfloat16
  // packs) and draws a new parameters generation; called wherever parameters_ changes.
  void ParametersChanged();
  void BuildLayout();

  Options options_;
  int num_parameters_ = 0;
  std::vector<ParameterBlock> blocks_;
  Eigen::VectorXd parameters_;
  Eigen::VectorXf parameters_float_;
  std::vector<Eigen::MatrixXd> hidden_weights_t_;
  std::vector<Eigen::MatrixXf> hidden_weights_t_float_;
  std::shared_ptr<const internal::Bfloat16Weights> packed_weights_;  // immutable, shared by copies
  // Drawn anew from a process-wide counter whenever theta changes (copies share it):
  // a Tape records it to know the parameters it was recorded with.
  std::uint64_t parameters_generation_ = 0;
  bool readout_frozen_ = false;
  Eigen::VectorXd start_gains_;  // empty: none
};

// ---- Implementation of the one-pixel template ------------------------------------
template <typename P, typename T>
void LatentModulatedSiren::EvaluateImpl(const P* theta, const T* coord2, const T* z,
                                        T* out) const {
  using std::sin;
  const int width = options_.width;
  const int num_layers = options_.num_hidden_layers;
  const int d = options_.latent_dim;
  const int d_global = options_.global_latent_dim();
  const int channels = options_.output_channels;
  const int num_shifts = num_layers * width;
  const P* A = theta + blocks_[2 * num_layers].offset;
  const P* c = theta + blocks_[2 * num_layers + 1].offset;
  const P* W_out = theta + blocks_[2 * num_layers + 2].offset;
  const P* b_out = theta + blocks_[2 * num_layers + 3].offset;
  const T omega(options_.omega_0);

  // Spatial latents: z_s(x), the bilinear mix of the grid's node latents (the weights
  // depend on the coordinate's value only).
  const int spatial_channels = has_spatial() ? options_.spatial_channels : 0;
  std::vector<T> z_s(spatial_channels, T(0.0));
  if (has_spatial()) {
    const ReadoutCorners corners =
        LocateSpatial(PlainValue(coord2[0]), PlainValue(coord2[1]));
    for (int i = 0; i < 4; ++i) {
      if (corners.weight[i] == 0.0) continue;
      const T w(corners.weight[i]);
      for (int ch = 0; ch < spatial_channels; ++ch) {
        z_s[ch] += w * z[d_global + corners.node[i] * spatial_channels + ch];
      }
    }
  }
  std::vector<T> h(coord2, coord2 + 2);
  std::vector<T> next(width);
  for (int l = 0; l < num_layers; ++l) {
    const P* W = theta + blocks_[2 * l].offset;
    const P* b = theta + blocks_[2 * l + 1].offset;
    const int fan_in = static_cast<int>(h.size());
    for (int i = 0; i < width; ++i) {
      const int row = l * width + i;
      T pre = T(b[i]) + T(c[row]);
      for (int k = 0; k < d_global; ++k) pre += A[row + k * num_shifts] * z[k];
      for (int k = 0; k < spatial_channels; ++k) {
        pre += A[row + (d_global + k) * num_shifts] * z_s[k];
      }
      for (int j = 0; j < fan_in; ++j) pre += W[i + j * width] * h[j];
      next[i] = sin(omega * pre);
    }
    h.swap(next);
    next.resize(width);
  }
  for (int ch = 0; ch < channels; ++ch) {
    T y = T(b_out[ch]);
    for (int i = 0; i < width; ++i) y += W_out[ch + i * channels] * h[i];
    out[ch] = y;
  }
  if (!has_readout()) return;
  // The readout branch: the grid position depends on the coordinate's value only (a
  // coordinate is data, never differentiated).
  const P* R = theta + blocks_[2 * num_layers + 4].offset;
  const P* m = theta + blocks_[2 * num_layers + 5].offset;
  const ReadoutCorners corners = LocateReadout(PlainValue(coord2[0]), PlainValue(coord2[1]));
  for (int i = 0; i < 4; ++i) {
    if (corners.weight[i] == 0.0) continue;
    const T w(corners.weight[i]);
    for (int ch = 0; ch < channels; ++ch) {
      const long column = corners.node[i] * channels + ch;
      T value = T(m[column]);
      for (int k = 0; k < d; ++k) value += R[k + column * d] * z[k];
      out[ch] += w * value;
    }
  }
}

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_TRUNK_LATENT_MODULATED_SIREN_H_
