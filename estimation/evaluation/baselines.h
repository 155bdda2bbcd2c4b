// Copyright 2026 The tactfunc Authors.
//
// Baselines for the paper's Table I ("Tactile Functasets", Tab. I): what a functaset is
// compared with, in representation size, reconstruction PSNR and pose error. Everything
// here works on the SAME frames the trunk fits -- a model's FrameFormat turned into
// TrunkTargets (estimation/data/trunk_targets.h: working resolution, grayscale, fixed-scale
// normalisation, validity mask) -- and every reconstruction is scored with THE PSNR of
// estimation/data/trunk_targets.h (Psnr), so the columns compare like with like.
//
// Frames as vectors (documented once). A frame's targets hold values N x C (N = rows x
// cols pixels, pixel j = row * cols + col; C channels). FlattenFrame lays them out as one
// row of P = N C floats, pixel-major: entry j C + c = values(j, c). A set of M frames is
// M x P, one frame per row (StackFrames). Invalid pixels hold 0 (as TrunkTargets does)
// and are left out of every PSNR.
//
// Reconstruction baselines
//   PcaCodec   principal components fitted on the train split (PcaCodec::Fit: exact
//              for small sets, randomised block Krylov iteration for large ones):
//                code  = B (x - mu)          n floats   (B: n x P orthonormal rows)
//                x_hat = mu + B^T code
//              bytes per frame = 4 n (float32 codes); model bytes = 4 (P + n P) (mean and
//              basis as float32). With n = the latent's float count, a PCA code costs
//              exactly what a functaset latent costs.
//   JpegCodec  OpenCV cv::imencode / cv::imdecode of the frame quantised to 8 bits:
//                q = clamp(round(255 (v - lo) / (hi - lo)), 0, 255),  v_hat = lo + q (hi - lo) / 255
//              with ONE fixed range [lo, hi] per sensor (JpegRangeOfFrames: the min and
//              max over the train split's valid pixels), so the 8-bit quantisation error
//              is part of the reconstruction error. One channel -> grayscale JPEG; three
//              -> a three-channel JPEG (OpenCV's YCbCr with 4:2:0 chroma). Bytes per
//              frame (Options::tables_in_model, default true): the JPEG stream without its
//              quantisation-table (DQT), Huffman-table (DHT) and APPn segments. Those are
//              identical for every frame at one quality (OpenCV writes the standard
//              tables), so they are counted once, as model bytes -- what JPEG's
//              "abbreviated format" (ITU T.81 Annex B.4/B.5) does when a stream of images
//              shares its tables. This favours JPEG: at a few hundred bytes per frame the
//              ~600 bytes of tables would otherwise dominate.
//              FindJpegQuality chooses the quality whose mean bytes per frame over given
//              (train) frames matches a target (TactFunc's latent bytes) by binary search
//              over 1..100.
//
// Pose baselines (the paper's pose MLP on latents is models/pose/pose_mlp.h)
//   - the same PoseMlp on PCA codes (the caller trains it with TrainPoseMlp);
//   - RidgePoseRegressor: closed-form ridge regression on raw downsampled pixels
//     (DownsamplePixels: factor x factor block means of the working-resolution frame),
//     standing in for the paper's ResNet-18 on raw images. It predicts the PoseMlp's
//     outputs (x/s, y/s, cos(n yaw), sin(n yaw)), s = 5 mm; lambda is chosen on a
//     held-out part of the training samples and the model refitted on all of them;
//   - KnnPoseRegressor: the k nearest training frames in the same pixel space.
// Poses are scored by ScorePoses exactly as `tactfunc train-pose` scores the MLP:
// position RMSE in mm (root of the mean squared Euclidean error), yaw RMSE in degrees
// modulo the tool's symmetry (YawErrorModuloSymmetry; n = 0 samples left out), and the
// paper's pose error, pose_mse = mean over frames of (dx^2 + dy^2 + dyaw^2) / 3 in m
// and rad (dyaw modulo symmetry, 0 for n = 0).
//
// Errors (STYLE, three tiers): bad Options throw std::invalid_argument with the IsValid
// message; buffers of the wrong shape (quoted: expected and found), empty training sets
// and non-finite inputs throw std::invalid_argument. Nothing here has an algorithmic
// outcome to report (no iteration that may fail to converge), so the Summaries hold
// figures and timings but no termination type, as ReconstructionEvaluator's.
// Thread safety: const methods are safe to call concurrently.
#ifndef TACTFUNC_ESTIMATION_EVALUATION_BASELINES_H_
#define TACTFUNC_ESTIMATION_EVALUATION_BASELINES_H_

#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "estimation/data/trunk_targets.h"
#include "models/pose/pose_mlp.h"

namespace tactfunc {

// ---- Frames as vectors -----------------------------------------------------------------

// One frame's values (N x C) as a row of N C floats, pixel-major (header comment).
Eigen::RowVectorXf FlattenFrame(const TrunkTargets& frame);
// The inverse: a row of N C floats back to N x C. Throws std::invalid_argument if the
// size is not a multiple of `channels` (>= 1).
Eigen::MatrixXf UnflattenFrame(const Eigen::Ref<const Eigen::RowVectorXf>& row, int channels);
// Frames M x P (one FlattenFrame per row). Throws std::invalid_argument if the frames
// differ in size or channels (naming the first that differs) or the list is empty.
Eigen::MatrixXf StackFrames(const std::vector<const TrunkTargets*>& frames);

// Block means of a frame: each channel averaged over factor x factor pixel blocks
// (partial blocks at the right and bottom edges averaged over the pixels they have;
// invalid pixels count as their stored 0), laid out pixel-major as FlattenFrame:
// ceil(rows / factor) x ceil(cols / factor) x C floats. factor 1 = FlattenFrame.
// Throws std::invalid_argument for factor < 1.
Eigen::RowVectorXf DownsamplePixels(const TrunkTargets& frame, int factor);

// ---- PCA -------------------------------------------------------------------------------

class PcaCodec {
 public:
  struct Options {
    // Components kept, >= 1. Capped at min(M, P) for M training frames of P floats
    // (there are no more). Table I uses the latent's float count (64 by default).
    int components = 64;
    // false (default): for large frame sets the randomised block Krylov fit (Fit's
    // comment), within a fraction of a per cent of the exact fit's variance; true: the
    // exact fit always (a Gram or covariance matrix in double and its eigenpairs).
    bool exact = false;
    bool IsValid(std::string* error) const;
  };

  struct Summary {
    int frames = 0;      // M training frames
    int dim = 0;         // P floats per frame
    int components = 0;  // n kept
    // Fraction of the training frames' total variance the kept components explain.
    double explained_variance = 0;
    double seconds = 0;  // wall time of the fit
    std::string method;  // how the eigenpairs were found (Fit's comment)
    std::string BriefReport() const;
  };

  PcaCodec() = default;
  // Fits on `frames` (M x P, one frame per row; M >= 1, all finite), deterministic.
  // With K = min(M, P) > 600 and n <= K / 4 (and not Options::exact): randomised block
  // Krylov iteration on the centred frames Xc themselves (3n Krylov directions in float
  // products, Rayleigh-Ritz on them; baselines.cc says how and what it costs in
  // accuracy). Otherwise exact, with mean and products in double: for M <= P the M x M
  // Gram matrix G = Xc Xc^T (basis rows Xc^T u / |Xc^T u| for G's top eigenvectors u),
  // else the P x P covariance Xc^T Xc (basis rows its top eigenvectors). The top n
  // eigenpairs of that K x K matrix: Eigen's SelfAdjointEigenSolver for K <= 600 or n >
  // K / 4, else block subspace iteration with Rayleigh-Ritz until every kept pair's
  // residual |G v - s v| <= 1e-9 s_1 (the backward error of a dense solver) and the
  // variance the n components keep has stopped rising (its last rise <= 1e-6 of the
  // variance left out), so reconstructions match the exact fit's; the dense solver if
  // that has not happened after 300 steps. Each basis row's largest-magnitude entry is
  // positive. eigenvalues() are those of the covariance Xc^T Xc / M (descending).
  // 3,991 frames of 8,560 floats: docs/BENCHMARKS.md (`tactfunc bench pca`).
  // Throws std::invalid_argument for bad options or frames.
  static PcaCodec Fit(const Eigen::MatrixXf& frames, const Options& options,
                      Summary* summary = nullptr);

  int components() const { return static_cast<int>(basis_.rows()); }
  int dim() const { return static_cast<int>(mean_.size()); }
  const Eigen::RowVectorXf& mean() const { return mean_; }
  const Eigen::MatrixXf& basis() const { return basis_; }          // n x P, orthonormal rows
  const Eigen::VectorXf& eigenvalues() const { return eigenvalues_; }  // n, descending

  // The first n components (1 <= n <= components(), else std::invalid_argument): the
  // fit with n components, as PCA's components are nested.
  PcaCodec Truncated(int n) const;

  // codes M x n for frames M x P; frames back from codes. Throw std::invalid_argument
  // for a wrong column count.
  Eigen::MatrixXf Encode(const Eigen::MatrixXf& frames) const;
  Eigen::MatrixXf Decode(const Eigen::MatrixXf& codes) const;

  std::uint64_t BytesPerFrame() const { return 4ull * components(); }
  std::uint64_t ModelBytes() const { return 4ull * (dim() + 1ull * components() * dim()); }

 private:
  Eigen::RowVectorXf mean_;
  Eigen::MatrixXf basis_;
  Eigen::VectorXf eigenvalues_;
};

// ---- JPEG ------------------------------------------------------------------------------

class JpegCodec {
 public:
  struct Options {
    // JPEG quality (cv::IMWRITE_JPEG_QUALITY), 1..100.
    int quality = 75;
    // The fixed quantisation range (normalised units, header comment): lo maps to 0,
    // hi to 255; finite, hi > lo. Values outside are clamped (and so count as error).
    double lo = -1;
    double hi = 1;
    // true: bytes per frame leave out the DQT, DHT and APPn segments, counted once as
    // TableBytes() (header comment); false: the whole file counts per frame.
    bool tables_in_model = true;
    bool IsValid(std::string* error) const;
  };

  // Throws std::invalid_argument with the IsValid message.
  explicit JpegCodec(const Options& options);
  const Options& options() const { return options_; }

  // Encodes one frame's values (N x C of a rows x cols frame, C = 1 or 3) and decodes
  // it again: returns the bytes per frame (as Options::tables_in_model says) and,
  // if `reconstruction` is not null, the decoded values N x C (normalised units).
  // Throws std::invalid_argument for a shape that is not rows*cols x 1 or x 3, and
  // std::runtime_error if OpenCV fails to encode or decode.
  std::uint64_t EncodeDecode(const Eigen::MatrixXf& values, int rows, int cols,
                             Eigen::MatrixXf* reconstruction = nullptr) const;
  // Bytes of the segments left out of the per-frame count for this frame's encoding
  // (0 unless tables_in_model): the model bytes of a JPEG representation.
  std::uint64_t TableBytes(const Eigen::MatrixXf& values, int rows, int cols) const;

 private:
  Options options_;
};

// [lo, hi] = the min and max of the frames' values over their valid pixels and
// channels (the fixed range of JpegCodec::Options). A range below 1e-9 is widened to
// lo + 1. Throws std::invalid_argument if no frame has a valid pixel.
void JpegRangeOfFrames(const std::vector<const TrunkTargets*>& frames, double* lo, double* hi);

struct JpegQualitySearchSummary {
  double target_bytes = 0;
  // The quality chosen: of `below` and `below + 1`, the one whose mean bytes per frame
  // is nearer the target (ties: below).
  int quality = 0;
  double mean_bytes = 0;  // at `quality`
  // The bracket: the largest quality whose mean bytes per frame is <= the target, and
  // its mean; `above_bytes` is the mean at below + 1 (NaN if below is 100).
  // below = 0 (and below_bytes NaN) when even quality 1 exceeds the target.
  int below = 0;
  double below_bytes = 0;
  double above_bytes = 0;
  bool target_reachable = true;  // false if quality 1 already exceeds the target
  int probes = 0;                // qualities tried (each encodes every frame once)
  double seconds = 0;
  std::string BriefReport() const;
};

// Binary search over qualities 1..100 (mean bytes per frame grows with quality) for the
// quality matching `target_bytes` (> 0) of mean bytes per frame over `frames`, with the
// other settings of `options`. Throws std::invalid_argument for an empty list, bad
// options or a target <= 0.
JpegQualitySearchSummary FindJpegQuality(const std::vector<const TrunkTargets*>& frames,
                                         const JpegCodec::Options& options, double target_bytes);

// ---- Scoring poses ---------------------------------------------------------------------

// Error sums over a set of frames (header comment; as `tactfunc train-pose` reports).
struct PoseErrors {
  int count = 0;           // frames
  double position_sq = 0;  // sum of squared Euclidean position errors, m^2
  int yaw_count = 0;       // frames with an observable yaw (n != 0)
  double yaw_sq = 0;       // sum of squared yaw errors modulo symmetry, rad^2
  // Sum over frames of (dx^2 + dy^2 + dyaw^2) / 3 (dyaw = 0 for n = 0), m^2 and rad^2.
  double pose_sq = 0;
  double RmseMm() const;     // 1e3 sqrt(position_sq / count); NaN if count = 0
  double RmseDeg() const;    // sqrt(yaw_sq / yaw_count) in degrees; NaN if yaw_count = 0
  double PoseMse() const;    // pose_sq / count: the paper's pose error; NaN if count = 0
};

// predicted and truth: M x 3 (x m, y m, yaw rad); symmetry_orders: M entries >= 0 (empty
// = all 1). Throws std::invalid_argument for mismatched shapes or a negative order.
PoseErrors ScorePoses(const Eigen::MatrixXd& predicted, const Eigen::MatrixXd& truth,
                      const Eigen::VectorXi& symmetry_orders);

// A PoseMlp's poses for inputs M x d whose samples have different symmetry orders
// (PoseMlp::PredictBatch takes one): M x 3. Throws like ScorePoses and PredictBatch.
Eigen::MatrixXd PredictPoses(const PoseMlp& model, const Eigen::MatrixXf& inputs,
                             const Eigen::VectorXi& symmetry_orders);

// ---- Ridge regression ------------------------------------------------------------------

// Multi-output ridge regression with an unpenalised intercept,
//   min_{W, b} || X W + 1 b^T - Y ||_F^2 + lambda || W ||_F^2,
// solved in closed form from ONE eigendecomposition of the centred Gram matrix (X^T X,
// P x P, when P <= M; X X^T, M x M, otherwise), so that every lambda costs only a few
// matrix products: W = V diag(1 / (s_i^2 + lambda)) V^T X^T Y (or its dual form).
// X: M x P inputs, Y: M x K outputs, one sample per row, M >= 1.
class RidgeRegression {
 public:
  // Throws std::invalid_argument for mismatched rows, M = 0 or non-finite entries.
  RidgeRegression(const Eigen::MatrixXd& inputs, const Eigen::MatrixXd& outputs);
  // W (P x K) and b (K) for lambda >= 0 (lambda = 0 with a rank-deficient X gives the
  // minimum-norm solution: eigenvalues below 1e-12 of the largest are dropped).
  void Solve(double lambda, Eigen::MatrixXd* weights, Eigen::VectorXd* intercept) const;
  // The mean eigenvalue of the Gram matrix, trace / min(M, P): the natural unit of lambda.
  double MeanEigenvalue() const;

 private:
  bool primal_ = true;
  Eigen::MatrixXd inputs_;     // centred X, M x P
  Eigen::RowVectorXd input_mean_;
  Eigen::RowVectorXd output_mean_;
  Eigen::MatrixXd projected_;  // V^T X^T Y (primal) or U^T Y (dual)
  Eigen::MatrixXd vectors_;    // V (P x r) or U (M x r)
  Eigen::VectorXd values_;     // s_i^2, r
};

// The PoseMlp's regression targets for ridge and k-NN: (x/s, y/s, cos(n yaw), sin(n yaw))
// per row of targets.poses, M x 4 (n from targets.symmetry_orders, empty = 1; for n = 0
// the yaw columns hold 0 and are not fitted).
Eigen::MatrixXd EncodePoseOutputs(const PoseTargets& targets, double position_scale);

class RidgePoseRegressor {
 public:
  struct Options {
    // Candidate lambdas in units of RidgeRegression::MeanEigenvalue(), each >= 0,
    // non-empty; the one with the least validation loss (the PoseMlp's loss on the
    // held-out samples) is chosen and the model refitted on all samples with it.
    std::vector<double> relative_lambdas = {1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1, 10};
    // Fraction of the training samples held out to choose lambda, in (0, 1). 0.2: the
    // usual 80/20 split. With fewer than 5 samples no lambda search is made: the
    // middle candidate is used.
    double validation_fraction = 0.2;
    // Which samples are held out (a seeded shuffle).
    std::uint64_t seed = 0;
    // Metres per position output, as PoseMlp::Options::position_scale (5 mm).
    double position_scale = 0.005;
    bool IsValid(std::string* error) const;
  };

  struct Summary {
    int samples = 0;       // M
    int dim = 0;           // P
    int validation = 0;    // held out for the lambda search (0: no search)
    double lambda = 0;     // chosen, absolute
    double relative_lambda = 0;
    std::vector<double> validation_losses;  // per candidate (empty: no search)
    double seconds = 0;
    std::string BriefReport() const;
  };

  RidgePoseRegressor() = default;
  // inputs M x P (float, one sample per row), targets with M rows. Throws
  // std::invalid_argument for bad options, shapes or non-finite values, or M = 0.
  static RidgePoseRegressor Fit(const Eigen::MatrixXf& inputs, const PoseTargets& targets,
                                const Options& options, Summary* summary = nullptr);
  // Outputs N x 4 and poses N x 3 (yaw = atan2(o_3, o_2) / n, 0 for n = 0) for inputs
  // N x P; symmetry_orders: N entries (empty = all 1).
  Eigen::MatrixXd Outputs(const Eigen::MatrixXf& inputs) const;
  Eigen::MatrixXd Predict(const Eigen::MatrixXf& inputs,
                          const Eigen::VectorXi& symmetry_orders) const;

 private:
  double position_scale_ = 0.005;
  Eigen::MatrixXd weights_;    // P x 4
  Eigen::VectorXd intercept_;  // 4
};

// ---- k-NN ------------------------------------------------------------------------------

// Pose of a query = the mean pose of its k nearest training samples (Euclidean, exact
// brute force, estimation/knn/knn_index.h): mean x and y; yaw = atan2(mean sin(n yaw_j),
// mean cos(n yaw_j)) / n with the QUERY's symmetry order n (the caller knows the tool),
// so neighbours at equivalent yaws agree instead of cancelling.
class KnnPoseRegressor {
 public:
  struct Options {
    // Neighbours averaged, >= 1 (capped at the training set's size). 5: a common
    // default; the exact value matters little next to the representation.
    int k = 5;
    bool IsValid(std::string* error) const;
  };

  // inputs M x P (M >= 1), targets.poses M x 3. Throws std::invalid_argument for bad
  // options or shapes.
  KnnPoseRegressor(const Eigen::MatrixXf& inputs, const PoseTargets& targets,
                   const Options& options);
  // Poses N x 3 for queries N x P; symmetry_orders N entries (empty = all 1).
  Eigen::MatrixXd Predict(const Eigen::MatrixXf& queries,
                          const Eigen::VectorXi& symmetry_orders) const;

 private:
  Options options_;
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> inputs_;
  Eigen::MatrixXd poses_;  // M x 3
};

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_EVALUATION_BASELINES_H_
