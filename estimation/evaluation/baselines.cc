// Copyright 2026 The tactfunc Authors.
#include "estimation/evaluation/baselines.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <limits>
#include <map>
#include <memory>
#include <numeric>
#include <random>
#include <sstream>
#include <stdexcept>

#include <Eigen/Eigenvalues>
#include <opencv2/core.hpp>

#include "estimation/data/codecs.h"
#include "estimation/knn/knn_index.h"
#include "models/simulator/tool.h"

namespace tactfunc {
namespace {

using Clock = std::chrono::steady_clock;

double SecondsSince(Clock::time_point start) {
  return std::chrono::duration<double>(Clock::now() - start).count();
}

std::string ShapeOf(Eigen::Index rows, Eigen::Index cols) {
  return std::to_string(rows) + " x " + std::to_string(cols);
}

void CheckOrders(const Eigen::VectorXi& orders, Eigen::Index rows, const char* what) {
  if (orders.size() != 0 && orders.size() != rows) {
    throw std::invalid_argument(std::string(what) + ": expected " + std::to_string(rows) +
                                " symmetry orders (or none), got " +
                                std::to_string(orders.size()));
  }
  for (Eigen::Index i = 0; i < orders.size(); ++i) {
    if (orders[i] < 0) {
      throw std::invalid_argument(std::string(what) + ": symmetry order " + std::to_string(i) +
                                  " is " + std::to_string(orders[i]) + ", expected >= 0");
    }
  }
}

int OrderAt(const Eigen::VectorXi& orders, Eigen::Index i) {
  return orders.size() == 0 ? 1 : orders[i];
}

// The pose of outputs (x/s, y/s, cos n yaw, sin n yaw) for symmetry order n.
Eigen::Vector3d PoseOfOutputs(const Eigen::Ref<const Eigen::RowVectorXd>& o, int n, double s) {
  const double yaw = n == 0 ? 0.0 : std::atan2(o[3], o[2]) / n;
  return Eigen::Vector3d(s * o[0], s * o[1], yaw);
}

}  // namespace

// ---- Frames as vectors -----------------------------------------------------------------

Eigen::RowVectorXf FlattenFrame(const TrunkTargets& frame) {
  const Eigen::Index n = frame.values.rows(), c = frame.values.cols();
  Eigen::RowVectorXf row(n * c);
  for (Eigen::Index j = 0; j < n; ++j) {
    for (Eigen::Index k = 0; k < c; ++k) row[j * c + k] = frame.values(j, k);
  }
  return row;
}

Eigen::MatrixXf UnflattenFrame(const Eigen::Ref<const Eigen::RowVectorXf>& row, int channels) {
  if (channels < 1 || row.size() % channels != 0) {
    throw std::invalid_argument("UnflattenFrame: " + std::to_string(row.size()) +
                                " values are not a whole number of pixels of " +
                                std::to_string(channels) + " channels");
  }
  const Eigen::Index n = row.size() / channels;
  Eigen::MatrixXf values(n, channels);
  for (Eigen::Index j = 0; j < n; ++j) {
    for (int k = 0; k < channels; ++k) values(j, k) = row[j * channels + k];
  }
  return values;
}

Eigen::MatrixXf StackFrames(const std::vector<const TrunkTargets*>& frames) {
  if (frames.empty()) throw std::invalid_argument("StackFrames: no frames");
  const TrunkTargets& first = *frames[0];
  Eigen::MatrixXf out(static_cast<Eigen::Index>(frames.size()), first.values.size());
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const TrunkTargets& f = *frames[i];
    if (f.values.rows() != first.values.rows() || f.values.cols() != first.values.cols()) {
      throw std::invalid_argument("StackFrames: frame " + std::to_string(i) + " has values " +
                                  ShapeOf(f.values.rows(), f.values.cols()) + ", expected " +
                                  ShapeOf(first.values.rows(), first.values.cols()) +
                                  " as frame 0");
    }
    out.row(static_cast<Eigen::Index>(i)) = FlattenFrame(f);
  }
  return out;
}

Eigen::RowVectorXf DownsamplePixels(const TrunkTargets& frame, int factor) {
  if (factor < 1) {
    throw std::invalid_argument("DownsamplePixels: factor must be >= 1, got " +
                                std::to_string(factor));
  }
  const int rows = frame.rows, cols = frame.cols, c = static_cast<int>(frame.values.cols());
  if (static_cast<Eigen::Index>(rows) * cols != frame.values.rows()) {
    throw std::invalid_argument("DownsamplePixels: values have " +
                                std::to_string(frame.values.rows()) + " pixels, expected " +
                                std::to_string(rows) + " x " + std::to_string(cols));
  }
  const int out_rows = (rows + factor - 1) / factor, out_cols = (cols + factor - 1) / factor;
  Eigen::RowVectorXf out = Eigen::RowVectorXf::Zero(static_cast<Eigen::Index>(out_rows) * out_cols * c);
  for (int r = 0; r < out_rows; ++r) {
    for (int q = 0; q < out_cols; ++q) {
      const int r1 = std::min(rows, (r + 1) * factor), q1 = std::min(cols, (q + 1) * factor);
      const int count = (r1 - r * factor) * (q1 - q * factor);
      for (int k = 0; k < c; ++k) {
        double sum = 0;
        for (int rr = r * factor; rr < r1; ++rr) {
          for (int qq = q * factor; qq < q1; ++qq) sum += frame.values(rr * cols + qq, k);
        }
        out[(static_cast<Eigen::Index>(r) * out_cols + q) * c + k] = static_cast<float>(sum / count);
      }
    }
  }
  return out;
}

// ---- PCA -------------------------------------------------------------------------------

bool PcaCodec::Options::IsValid(std::string* error) const {
  if (components < 1) {
    if (error) *error = "PcaCodec::Options::components must be >= 1, got " + std::to_string(components);
    return false;
  }
  return true;
}

std::string PcaCodec::Summary::BriefReport() const {
  char buffer[200];
  std::snprintf(buffer, sizeof(buffer),
                "PCA: %d components of %d floats from %d frames, %.1f%% of the variance, %.2f s",
                components, dim, frames, 100 * explained_variance, seconds);
  return method.empty() ? std::string(buffer) : std::string(buffer) + " (" + method + ")";
}

namespace {

// The top n eigenpairs (descending) of the symmetric positive semi-definite matrix A
// (K x K, only its lower triangle is read). `method` says how they were found.
//
// K <= kDenseLimit or n > K / 4: Eigen's SelfAdjointEigenSolver on A (exact).
// Else block subspace iteration with Rayleigh-Ritz (k = n + max(16, n / 2) vectors,
// a fixed deterministic start): each step Z = A Q, T = Q^T Z, T = W Theta W^T,
// Q <- orth(Z W), until (a) every kept Ritz pair has ||A v - theta v|| <= 1e-9 theta_1
// (an exact eigenpair of a matrix within 1e-9 ||A|| of A, the backward error of a dense
// solver) and (b) the variance the n pairs keep, sum theta_i (which rises to its exact
// value from below), rose in the last step by at most 1e-6 of the variance they leave
// out (trace A - sum theta_i): so the reconstruction error, and PSNR, are the exact
// fit's (b matters where the spectrum is flat around n, e.g. a sensor-noise floor).
// Not converged after kMaxIterations steps: the dense solver after all.
constexpr int kDenseLimit = 600;
constexpr int kMaxIterations = 300;
constexpr double kResidualTolerance = 1e-9;
constexpr double kKeptTolerance = 1e-6;

// The thin Q (rows x cols, orthonormal columns) of y's Householder QR.
Eigen::MatrixXd ThinQ(const Eigen::MatrixXd& y) {
  const Eigen::HouseholderQR<Eigen::MatrixXd> qr(y);
  return qr.householderQ() * Eigen::MatrixXd::Identity(y.rows(), y.cols());
}

void TopEigenpairs(const Eigen::MatrixXd& a_lower, int n, Eigen::VectorXd* values,
                   Eigen::MatrixXd* vectors, std::string* method) {
  const Eigen::Index K = a_lower.rows();
  auto dense = [&](const std::string& why) {
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> solver(a_lower);  // lower triangle
    // Ascending: the last n columns, reversed.
    *values = solver.eigenvalues().tail(n).reverse();
    *vectors = solver.eigenvectors().rightCols(n).rowwise().reverse();
    *method = "dense eigensolver on " + std::to_string(K) + " x " + std::to_string(K) + why;
  };
  if (K <= kDenseLimit || n > K / 4) {
    dense("");
    return;
  }
  const Eigen::MatrixXd a = a_lower.selfadjointView<Eigen::Lower>();
  const Eigen::Index k = std::min<Eigen::Index>(K, n + std::max(16, n / 2));
  // Deterministic start: std::mt19937's sequence is fixed by the standard.
  std::mt19937 rng(20260101u);
  Eigen::MatrixXd q(K, k);
  for (Eigen::Index i = 0; i < q.size(); ++i) q.data()[i] = rng() / 4294967296.0 - 0.5;
  q = ThinQ(q);
  const double trace = a.trace();
  double previous_sum = -1;
  for (int iteration = 1; iteration <= kMaxIterations; ++iteration) {
    const Eigen::MatrixXd z = a * q;
    const Eigen::MatrixXd t = q.transpose() * z;
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> small(0.5 * (t + t.transpose()));
    const Eigen::MatrixXd w = small.eigenvectors().rowwise().reverse();  // descending
    const Eigen::VectorXd theta = small.eigenvalues().reverse();
    const Eigen::MatrixXd v = q * w.leftCols(n);
    const Eigen::MatrixXd zw = z * w;
    const double scale = std::max(theta[0], 0.0);
    const Eigen::VectorXd residual =
        (zw.leftCols(n) - v * theta.head(n).asDiagonal()).colwise().norm();
    // The variance the n pairs keep, sum theta_i, rises to its exact value from below;
    // its last rise must be a negligible part of the variance they leave out.
    const double kept = theta.head(n).sum();
    const double left_out = std::max(trace - kept, 0.0);
    const bool kept_converged =
        previous_sum >= 0 && kept - previous_sum <= kKeptTolerance * left_out;
    previous_sum = kept;
    if ((residual.maxCoeff() <= kResidualTolerance * scale && kept_converged) || scale == 0) {
      *values = theta.head(n);
      *vectors = v;
      *method = "subspace iteration on " + std::to_string(K) + " x " + std::to_string(K) +
                " (" + std::to_string(iteration) + " steps)";
      return;
    }
    q = ThinQ(zw);
  }
  dense(" (subspace iteration did not converge)");
}

// Randomised block Krylov iteration on the centred frames themselves (Musco and Musco
// 2015, "Randomized block Krylov methods for stronger and faster approximate singular
// value decomposition"; Halko, Martinsson and Tropp 2011), for K = min(M, P) >
// kDenseLimit and n <= K / 4: no K x K matrix is formed. From a fixed deterministic
// start Omega (P x b), the range of
//   [Xc Omega, (Xc Xc^T) Xc Omega, ..., (Xc Xc^T)^(q-1) Xc Omega]     (M x b q)
// is built block by block with float products (the range needs directions, not
// digits), each block orthogonalised in double against those before it (twice:
// classical Gram-Schmidt loses orthogonality once). Then Rayleigh-Ritz on that range
// Q: B = Q^T Xc, B B^T = U Theta U^T (double), basis rows U_n^T B (norms sqrt(theta_i)),
// values theta_n (the squared singular values of Xc). b = max(16, n / 4) and q =
// max(ceil(3 n / b), 6) blocks (3n columns or more, 2 q - 1 products of M x P x b). A
// Krylov range holds the top directions far better than a subspace iteration's range
// after as many products; where the spectrum is flat around n (a sensor-noise floor) the n kept
// directions are still not exactly the top ones: on `tactfunc bench pca`'s 3,991 x
// 8,560 frames (256 components, 192 of them in the noise floor) the reconstructions
// leave out 0.27% more variance than the exact fit (0.01 dB of PSNR), in 3.5 s against
// 22.7 s for the exact Gram-matrix fit (docs/BENCHMARKS.md).
constexpr Eigen::Index kMinKrylovBlocks = 6;

void RandomizedTopComponents(const Eigen::MatrixXf& frames, const Eigen::RowVectorXd& mean,
                             int n, Eigen::VectorXd* values, Eigen::MatrixXd* basis,
                             std::string* method) {
  const Eigen::Index m = frames.rows(), p = frames.cols();
  const Eigen::Index b = std::max(16, n / 4);
  // At least kMinKrylovBlocks products deep: a few components would otherwise get one
  // block, a range finder without a single power step.
  const Eigen::Index blocks = std::min<Eigen::Index>(
      std::max<Eigen::Index>((3 * n + b - 1) / b, kMinKrylovBlocks), std::min(m, p) / b);
  const Eigen::MatrixXf centred = frames.rowwise() - mean.cast<float>();
  std::mt19937 rng(20260101u);
  Eigen::MatrixXf omega(p, b);
  for (Eigen::Index i = 0; i < omega.size(); ++i) {
    omega.data()[i] = static_cast<float>(rng() / 4294967296.0 - 0.5);
  }
  Eigen::MatrixXd q(m, b * blocks);
  Eigen::MatrixXd block = (centred * omega).cast<double>();
  for (Eigen::Index k = 0; k < blocks; ++k) {
    if (k > 0) {
      const Eigen::MatrixXf previous = q.middleCols((k - 1) * b, b).cast<float>();
      block = (centred * (centred.transpose() * previous)).cast<double>();
      for (int pass = 0; pass < 2; ++pass) {
        const auto before = q.leftCols(k * b);
        block -= before * (before.transpose() * block);
      }
    }
    q.middleCols(k * b, b) = ThinQ(block);
  }
  // Rayleigh-Ritz on the range: B = Q^T Xc (a float product; its rounding moves the
  // basis by about 1e-6, the variance it keeps by the square of that).
  const Eigen::MatrixXd projected = (q.cast<float>().transpose() * centred).cast<double>();
  Eigen::MatrixXd gram = Eigen::MatrixXd::Zero(q.cols(), q.cols());
  gram.selfadjointView<Eigen::Lower>().rankUpdate(projected);
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> small(gram);  // lower triangle
  const Eigen::VectorXd theta = small.eigenvalues().reverse();
  const Eigen::MatrixXd u = small.eigenvectors().rowwise().reverse();
  *values = theta.head(n);
  *basis = u.leftCols(n).transpose() * projected;  // rows of norm sqrt(theta_i)
  *method = "randomized block Krylov on " + std::to_string(m) + " x " + std::to_string(p) +
            " (" + std::to_string(blocks) + " blocks of " + std::to_string(b) + ")";
}

// Orthonormal rows: a thin QR of basis^T (rows with s ~ 0 have no direction of their
// own; QR completes them), signs kept from the rows given (R's diagonal positive).
void OrthonormaliseRows(Eigen::MatrixXd* basis) {
  const Eigen::Index n = basis->rows(), p = basis->cols();
  Eigen::HouseholderQR<Eigen::MatrixXd> qr(basis->transpose());
  Eigen::MatrixXd q = qr.householderQ() * Eigen::MatrixXd::Identity(p, n);
  const Eigen::MatrixXd r = qr.matrixQR().topLeftCorner(n, n);
  for (Eigen::Index i = 0; i < n; ++i) {
    if (r(i, i) < 0) q.col(i) *= -1;
  }
  *basis = q.transpose();
}

// A fixed sign per basis vector: its entry of largest magnitude is positive.
void FixSigns(Eigen::MatrixXd* basis_rows) {
  for (Eigen::Index i = 0; i < basis_rows->rows(); ++i) {
    Eigen::Index j = 0;
    basis_rows->row(i).cwiseAbs().maxCoeff(&j);
    if ((*basis_rows)(i, j) < 0) basis_rows->row(i) *= -1;
  }
}

}  // namespace

PcaCodec PcaCodec::Fit(const Eigen::MatrixXf& frames, const Options& options, Summary* summary) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  if (frames.rows() < 1 || frames.cols() < 1) {
    throw std::invalid_argument("PcaCodec::Fit: expected at least one frame of at least one "
                                "float, got " + ShapeOf(frames.rows(), frames.cols()));
  }
  if (!frames.allFinite()) throw std::invalid_argument("PcaCodec::Fit: non-finite frame values");
  const auto start = Clock::now();
  const Eigen::Index m = frames.rows(), p = frames.cols();
  const int n = static_cast<int>(std::min<Eigen::Index>({options.components, m, p}));
  const Eigen::RowVectorXd mean = frames.cast<double>().colwise().mean();
  // Centred frames in double, a block at a time (the whole of them would double the
  // memory of `frames` four times over).
  constexpr Eigen::Index kBlock = 256;
  Eigen::MatrixXd basis;  // n x P
  Eigen::VectorXd values;
  std::string method;
  const Eigen::Index small_side = std::min(m, p);
  if (!options.exact && small_side > kDenseLimit && n <= small_side / 4) {
    RandomizedTopComponents(frames, mean, n, &values, &basis, &method);
    OrthonormaliseRows(&basis);
  } else if (m <= p) {
    // Gram matrix G = Xc Xc^T (M x M): G u = s u gives the basis row Xc^T u / sqrt(s).
    Eigen::MatrixXd gram = Eigen::MatrixXd::Zero(m, m);
    for (Eigen::Index c = 0; c < p; c += kBlock) {
      const Eigen::Index w = std::min(kBlock, p - c);
      const Eigen::MatrixXd block =
          frames.middleCols(c, w).cast<double>().rowwise() - mean.segment(c, w);
      gram.triangularView<Eigen::Lower>() += block * block.transpose();
    }
    Eigen::MatrixXd u;
    TopEigenpairs(gram, n, &values, &u, &method);
    basis.resize(n, p);
    for (Eigen::Index c = 0; c < p; c += kBlock) {
      const Eigen::Index w = std::min(kBlock, p - c);
      const Eigen::MatrixXd block =
          frames.middleCols(c, w).cast<double>().rowwise() - mean.segment(c, w);
      basis.middleCols(c, w) = u.transpose() * block;
    }
    OrthonormaliseRows(&basis);
  } else {
    // Covariance C = Xc^T Xc (P x P): its eigenvectors are the basis rows.
    Eigen::MatrixXd covariance = Eigen::MatrixXd::Zero(p, p);
    for (Eigen::Index r = 0; r < m; r += kBlock) {
      const Eigen::Index h = std::min(kBlock, m - r);
      const Eigen::MatrixXd block = frames.middleRows(r, h).cast<double>().rowwise() - mean;
      covariance.triangularView<Eigen::Lower>() += block.transpose() * block;
    }
    Eigen::MatrixXd vectors;
    TopEigenpairs(covariance, n, &values, &vectors, &method);
    basis = vectors.transpose();
  }
  FixSigns(&basis);
  PcaCodec codec;
  codec.mean_ = mean.cast<float>();
  codec.basis_ = basis.cast<float>();
  // Eigenvalues of the covariance Xc^T Xc / M (cv::PCA's scaling), never negative.
  codec.eigenvalues_ = (values.cwiseMax(0.0) / static_cast<double>(m)).cast<float>();
  if (summary) {
    const double total = (frames.cast<double>().rowwise() - mean).squaredNorm() / m;
    summary->frames = static_cast<int>(m);
    summary->dim = static_cast<int>(p);
    summary->components = n;
    summary->explained_variance =
        total > 0 ? std::min(1.0, codec.eigenvalues_.cast<double>().sum() / total) : 1.0;
    summary->method = method;
    summary->seconds = SecondsSince(start);
  }
  return codec;
}

PcaCodec PcaCodec::Truncated(int n) const {
  if (n < 1 || n > components()) {
    throw std::invalid_argument("PcaCodec::Truncated: expected 1.." + std::to_string(components()) +
                                " components, got " + std::to_string(n));
  }
  PcaCodec codec;
  codec.mean_ = mean_;
  codec.basis_ = basis_.topRows(n);
  codec.eigenvalues_ = eigenvalues_.head(n);
  return codec;
}

Eigen::MatrixXf PcaCodec::Encode(const Eigen::MatrixXf& frames) const {
  if (frames.cols() != dim()) {
    throw std::invalid_argument("PcaCodec::Encode: frames are " +
                                ShapeOf(frames.rows(), frames.cols()) + ", expected M x " +
                                std::to_string(dim()));
  }
  return (frames.rowwise() - mean_) * basis_.transpose();
}

Eigen::MatrixXf PcaCodec::Decode(const Eigen::MatrixXf& codes) const {
  if (codes.cols() != components()) {
    throw std::invalid_argument("PcaCodec::Decode: codes are " +
                                ShapeOf(codes.rows(), codes.cols()) + ", expected M x " +
                                std::to_string(components()));
  }
  return (codes * basis_).rowwise() + mean_;
}

// ---- JPEG ------------------------------------------------------------------------------

bool JpegCodec::Options::IsValid(std::string* error) const {
  std::string message;
  if (quality < 1 || quality > 100) {
    message = "JpegCodec::Options::quality must be in 1..100, got " + std::to_string(quality);
  } else if (!std::isfinite(lo) || !std::isfinite(hi) || !(hi > lo)) {
    message = "JpegCodec::Options: the range [lo, hi] must be finite with hi > lo, got [" +
              std::to_string(lo) + ", " + std::to_string(hi) + "]";
  }
  if (message.empty()) return true;
  if (error) *error = message;
  return false;
}

JpegCodec::JpegCodec(const Options& options) : options_(options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
}

namespace {

// Bytes of the DQT, DHT and APPn segments of a JPEG stream (the tables shared by every
// frame at one quality), scanning the marker segments up to the start of scan.
std::uint64_t SharedSegmentBytes(const std::vector<uchar>& jpeg) {
  std::uint64_t shared = 0;
  std::size_t i = 2;  // after SOI
  while (i + 4 <= jpeg.size()) {
    if (jpeg[i] != 0xFF) break;
    const uchar marker = jpeg[i + 1];
    if (marker == 0xFF) {  // fill byte
      ++i;
      continue;
    }
    const std::size_t length = (static_cast<std::size_t>(jpeg[i + 2]) << 8) | jpeg[i + 3];
    if (marker == 0xDB || marker == 0xC4 || (marker >= 0xE0 && marker <= 0xEF)) {
      shared += 2 + length;
    }
    if (marker == 0xDA) break;  // start of scan: entropy-coded data follows
    i += 2 + length;
  }
  return shared;
}

}  // namespace

namespace {

std::vector<uchar> EncodeJpeg(const JpegCodec::Options& o, const Eigen::MatrixXf& values, int rows,
                              int cols) {
  const int c = static_cast<int>(values.cols());
  if ((c != 1 && c != 3) || values.rows() != static_cast<Eigen::Index>(rows) * cols) {
    throw std::invalid_argument("JpegCodec: values are " + ShapeOf(values.rows(), values.cols()) +
                                ", expected " + std::to_string(rows * cols) + " x 1 or x 3 (" +
                                std::to_string(rows) + " x " + std::to_string(cols) + " pixels)");
  }
  cv::Mat image(rows, cols, CV_8UC(c));
  const double gain = 255.0 / (o.hi - o.lo);
  for (int r = 0; r < rows; ++r) {
    uchar* line = image.ptr<uchar>(r);
    for (int q = 0; q < cols; ++q) {
      for (int k = 0; k < c; ++k) {
        const double v = std::round((values(r * cols + q, k) - o.lo) * gain);
        // OpenCV takes three channels as BGR: store RGB reversed so that its YCbCr
        // conversion weighs the channels as intended.
        line[q * c + (c == 3 ? 2 - k : 0)] = static_cast<uchar>(std::clamp(v, 0.0, 255.0));
      }
    }
  }
  std::vector<uchar> jpeg;
  if (!codecs::Encode(".jpg", image, {codecs::kJpegQuality, o.quality}, &jpeg)) {
    throw std::runtime_error("JpegCodec: cv::imencode failed");
  }
  return jpeg;
}

}  // namespace

std::uint64_t JpegCodec::EncodeDecode(const Eigen::MatrixXf& values, int rows, int cols,
                                      Eigen::MatrixXf* reconstruction) const {
  const std::vector<uchar> jpeg = EncodeJpeg(options_, values, rows, cols);
  const int c = static_cast<int>(values.cols());
  if (reconstruction) {
    const cv::Mat decoded =
        codecs::Decode(jpeg.data(), jpeg.size(),
                       c == 3 ? codecs::DecodeMode::kColor : codecs::DecodeMode::kGrayscale);
    if (decoded.empty() || decoded.rows != rows || decoded.cols != cols ||
        decoded.channels() != c) {
      throw std::runtime_error("JpegCodec: cv::imdecode failed");
    }
    reconstruction->resize(values.rows(), c);
    const double step = (options_.hi - options_.lo) / 255.0;
    for (int r = 0; r < rows; ++r) {
      const uchar* line = decoded.ptr<uchar>(r);
      for (int q = 0; q < cols; ++q) {
        for (int k = 0; k < c; ++k) {
          (*reconstruction)(r * cols + q, k) =
              static_cast<float>(options_.lo + step * line[q * c + (c == 3 ? 2 - k : 0)]);
        }
      }
    }
  }
  return jpeg.size() - (options_.tables_in_model ? SharedSegmentBytes(jpeg) : 0);
}

std::uint64_t JpegCodec::TableBytes(const Eigen::MatrixXf& values, int rows, int cols) const {
  return options_.tables_in_model ? SharedSegmentBytes(EncodeJpeg(options_, values, rows, cols))
                                  : 0;
}

void JpegRangeOfFrames(const std::vector<const TrunkTargets*>& frames, double* lo, double* hi) {
  double a = std::numeric_limits<double>::infinity(), b = -a;
  for (const TrunkTargets* f : frames) {
    for (Eigen::Index j = 0; j < f->values.rows(); ++j) {
      if (!(f->weights[j] > 0)) continue;
      a = std::min(a, static_cast<double>(f->values.row(j).minCoeff()));
      b = std::max(b, static_cast<double>(f->values.row(j).maxCoeff()));
    }
  }
  if (!std::isfinite(a)) throw std::invalid_argument("JpegRangeOfFrames: no valid pixel");
  if (b - a < 1e-9) b = a + 1;
  *lo = a;
  *hi = b;
}

std::string JpegQualitySearchSummary::BriefReport() const {
  char buffer[240];
  std::snprintf(buffer, sizeof(buffer),
                "JPEG: quality %d, %.1f bytes/frame for a target of %.1f (bracket q%d..q%d: "
                "%.1f..%.1f)%s, %d probes, %.2f s",
                quality, mean_bytes, target_bytes, below, below + 1, below_bytes, above_bytes,
                target_reachable ? "" : ", target below quality 1", probes, seconds);
  return buffer;
}

JpegQualitySearchSummary FindJpegQuality(const std::vector<const TrunkTargets*>& frames,
                                         const JpegCodec::Options& options, double target_bytes) {
  if (frames.empty()) throw std::invalid_argument("FindJpegQuality: no frames");
  if (!(target_bytes > 0)) {
    throw std::invalid_argument("FindJpegQuality: target bytes must be > 0, got " +
                                std::to_string(target_bytes));
  }
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  const auto start = Clock::now();
  JpegQualitySearchSummary s;
  s.target_bytes = target_bytes;
  std::map<int, double> memo;
  auto mean_bytes = [&](int quality) {
    const auto it = memo.find(quality);
    if (it != memo.end()) return it->second;
    JpegCodec::Options o = options;
    o.quality = quality;
    const JpegCodec codec(o);
    double sum = 0;
    for (const TrunkTargets* f : frames) {
      sum += static_cast<double>(codec.EncodeDecode(f->values, f->rows, f->cols));
    }
    ++s.probes;
    return memo[quality] = sum / frames.size();
  };
  const double nan = std::numeric_limits<double>::quiet_NaN();
  if (mean_bytes(1) > target_bytes) {
    s.below = 0;
    s.below_bytes = nan;
    s.above_bytes = mean_bytes(1);
    s.quality = 1;
    s.target_reachable = false;
  } else if (mean_bytes(100) <= target_bytes) {
    s.below = 100;
    s.below_bytes = mean_bytes(100);
    s.above_bytes = nan;
    s.quality = 100;
  } else {
    int lo = 1, hi = 100;  // mean(lo) <= target < mean(hi)
    while (hi - lo > 1) {
      const int mid = (lo + hi) / 2;
      (mean_bytes(mid) <= target_bytes ? lo : hi) = mid;
    }
    s.below = lo;
    s.below_bytes = mean_bytes(lo);
    s.above_bytes = mean_bytes(hi);
    s.quality = target_bytes - s.below_bytes <= s.above_bytes - target_bytes ? lo : hi;
  }
  s.mean_bytes = mean_bytes(s.quality);
  s.seconds = SecondsSince(start);
  return s;
}

// ---- Scoring poses ---------------------------------------------------------------------

double PoseErrors::RmseMm() const {
  return count ? 1e3 * std::sqrt(position_sq / count) : std::numeric_limits<double>::quiet_NaN();
}
double PoseErrors::RmseDeg() const {
  return yaw_count ? std::sqrt(yaw_sq / yaw_count) * 180.0 / M_PI
                   : std::numeric_limits<double>::quiet_NaN();
}
double PoseErrors::PoseMse() const {
  return count ? pose_sq / count : std::numeric_limits<double>::quiet_NaN();
}

PoseErrors ScorePoses(const Eigen::MatrixXd& predicted, const Eigen::MatrixXd& truth,
                      const Eigen::VectorXi& symmetry_orders) {
  if (predicted.cols() != 3 || truth.cols() != 3 || predicted.rows() != truth.rows()) {
    throw std::invalid_argument("ScorePoses: predicted is " +
                                ShapeOf(predicted.rows(), predicted.cols()) + " and truth " +
                                ShapeOf(truth.rows(), truth.cols()) + ", expected both M x 3");
  }
  CheckOrders(symmetry_orders, truth.rows(), "ScorePoses");
  PoseErrors e;
  for (Eigen::Index i = 0; i < truth.rows(); ++i) {
    const int n = OrderAt(symmetry_orders, i);
    const double dx = predicted(i, 0) - truth(i, 0), dy = predicted(i, 1) - truth(i, 1);
    const double dyaw = YawErrorModuloSymmetry(predicted(i, 2), truth(i, 2), n);  // 0 for n = 0
    ++e.count;
    e.position_sq += dx * dx + dy * dy;
    if (n != 0) {
      ++e.yaw_count;
      e.yaw_sq += dyaw * dyaw;
    }
    e.pose_sq += (dx * dx + dy * dy + dyaw * dyaw) / 3.0;
  }
  return e;
}

Eigen::MatrixXd PredictPoses(const PoseMlp& model, const Eigen::MatrixXf& inputs,
                             const Eigen::VectorXi& symmetry_orders) {
  CheckOrders(symmetry_orders, inputs.rows(), "PredictPoses");
  Eigen::MatrixXd poses(inputs.rows(), 3);
  std::map<int, std::vector<Eigen::Index>> by_order;
  for (Eigen::Index i = 0; i < inputs.rows(); ++i) by_order[OrderAt(symmetry_orders, i)].push_back(i);
  for (const auto& [n, rows] : by_order) {
    Eigen::MatrixXf batch(static_cast<Eigen::Index>(rows.size()), inputs.cols());
    for (std::size_t k = 0; k < rows.size(); ++k) batch.row(k) = inputs.row(rows[k]);
    const std::vector<SE2d> predicted = model.PredictBatch(batch, n);
    for (std::size_t k = 0; k < rows.size(); ++k) {
      poses.row(rows[k]) << predicted[k].x(), predicted[k].y(), predicted[k].yaw();
    }
  }
  return poses;
}

// ---- Ridge regression ------------------------------------------------------------------

RidgeRegression::RidgeRegression(const Eigen::MatrixXd& inputs, const Eigen::MatrixXd& outputs) {
  if (inputs.rows() < 1 || inputs.rows() != outputs.rows() || inputs.cols() < 1) {
    throw std::invalid_argument("RidgeRegression: inputs are " +
                                ShapeOf(inputs.rows(), inputs.cols()) + " and outputs " +
                                ShapeOf(outputs.rows(), outputs.cols()) +
                                ", expected M x P and M x K with M, P >= 1");
  }
  if (!inputs.allFinite() || !outputs.allFinite()) {
    throw std::invalid_argument("RidgeRegression: non-finite inputs or outputs");
  }
  input_mean_ = inputs.colwise().mean();
  output_mean_ = outputs.colwise().mean();
  const Eigen::MatrixXd x = inputs.rowwise() - input_mean_;
  const Eigen::MatrixXd y = outputs.rowwise() - output_mean_;
  primal_ = x.cols() <= x.rows();
  Eigen::MatrixXd gram;
  if (primal_) {
    gram.noalias() = x.transpose() * x;
  } else {
    gram.noalias() = x * x.transpose();
  }
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> solver(gram);
  const Eigen::VectorXd& all = solver.eigenvalues();  // ascending
  const double largest = all.size() ? std::max(0.0, all[all.size() - 1]) : 0.0;
  Eigen::Index first = 0;
  while (first < all.size() && !(all[first] > 1e-12 * largest && all[first] > 0)) ++first;
  const Eigen::Index r = all.size() - first;
  values_ = all.tail(r);
  vectors_ = solver.eigenvectors().rightCols(r);
  if (primal_) {
    projected_ = vectors_.transpose() * (x.transpose() * y);
  } else {
    projected_ = vectors_.transpose() * y;
    inputs_ = x;
  }
}

void RidgeRegression::Solve(double lambda, Eigen::MatrixXd* weights,
                            Eigen::VectorXd* intercept) const {
  if (!(lambda >= 0)) {
    throw std::invalid_argument("RidgeRegression::Solve: lambda must be >= 0, got " +
                                std::to_string(lambda));
  }
  const Eigen::VectorXd inverse = (values_.array() + lambda).inverse().matrix();
  const Eigen::MatrixXd scaled = inverse.asDiagonal() * projected_;
  if (primal_) {
    *weights = vectors_ * scaled;
  } else {
    *weights = inputs_.transpose() * (vectors_ * scaled);
  }
  *intercept = (output_mean_ - input_mean_ * *weights).transpose();
}

double RidgeRegression::MeanEigenvalue() const {
  const Eigen::Index n = primal_ ? input_mean_.size() : (inputs_.rows());
  return n > 0 ? values_.sum() / n : 0.0;
}

Eigen::MatrixXd EncodePoseOutputs(const PoseTargets& targets, double position_scale) {
  if (targets.poses.cols() != 3) {
    throw std::invalid_argument("EncodePoseOutputs: poses are " +
                                ShapeOf(targets.poses.rows(), targets.poses.cols()) +
                                ", expected M x 3");
  }
  CheckOrders(targets.symmetry_orders, targets.poses.rows(), "EncodePoseOutputs");
  Eigen::MatrixXd out(targets.poses.rows(), 4);
  for (Eigen::Index i = 0; i < out.rows(); ++i) {
    const int n = OrderAt(targets.symmetry_orders, i);
    out(i, 0) = targets.poses(i, 0) / position_scale;
    out(i, 1) = targets.poses(i, 1) / position_scale;
    out(i, 2) = n == 0 ? 0.0 : std::cos(n * targets.poses(i, 2));
    out(i, 3) = n == 0 ? 0.0 : std::sin(n * targets.poses(i, 2));
  }
  return out;
}

bool RidgePoseRegressor::Options::IsValid(std::string* error) const {
  std::string message;
  if (relative_lambdas.empty()) message = "RidgePoseRegressor::Options::relative_lambdas is empty";
  for (double l : relative_lambdas) {
    if (!(l >= 0) || !std::isfinite(l)) {
      message = "RidgePoseRegressor::Options::relative_lambdas: " + std::to_string(l) +
                " is not a finite value >= 0";
    }
  }
  if (!(validation_fraction > 0 && validation_fraction < 1)) {
    message = "RidgePoseRegressor::Options::validation_fraction must be in (0, 1), got " +
              std::to_string(validation_fraction);
  }
  if (!(position_scale > 0) || !std::isfinite(position_scale)) {
    message = "RidgePoseRegressor::Options::position_scale must be finite and > 0, got " +
              std::to_string(position_scale);
  }
  if (message.empty()) return true;
  if (error) *error = message;
  return false;
}

std::string RidgePoseRegressor::Summary::BriefReport() const {
  char buffer[200];
  std::snprintf(buffer, sizeof(buffer),
                "ridge: %d samples of %d floats, lambda %.3g (%.0e x mean eigenvalue; %d held "
                "out), %.2f s",
                samples, dim, lambda, relative_lambda, validation, seconds);
  return buffer;
}

namespace {

// Ridge on a subset of samples: x, y outputs on all of them, the yaw outputs on those
// with an observable yaw (n != 0).
class PoseRidge {
 public:
  PoseRidge(const Eigen::MatrixXd& x, const Eigen::MatrixXd& y, const Eigen::VectorXi& orders,
            const std::vector<Eigen::Index>& rows) {
    std::vector<Eigen::Index> yaw_rows;
    for (Eigen::Index i : rows) {
      if (OrderAt(orders, i) != 0) yaw_rows.push_back(i);
    }
    const bool same = yaw_rows.size() == rows.size();
    position_ = std::make_unique<RidgeRegression>(
        x(rows, Eigen::all), same ? Eigen::MatrixXd(y(rows, Eigen::all))
                                  : Eigen::MatrixXd(y(rows, Eigen::seqN(0, 2))));
    all_columns_ = same;
    if (!same && !yaw_rows.empty()) {
      yaw_ = std::make_unique<RidgeRegression>(x(yaw_rows, Eigen::all),
                                               y(yaw_rows, Eigen::seqN(2, 2)));
    }
  }
  double MeanEigenvalue() const { return position_->MeanEigenvalue(); }
  void Solve(double lambda, Eigen::MatrixXd* w, Eigen::VectorXd* b) const {
    Eigen::MatrixXd wp;
    Eigen::VectorXd bp;
    position_->Solve(lambda, &wp, &bp);
    if (all_columns_) {
      *w = wp;
      *b = bp;
      return;
    }
    w->setZero(wp.rows(), 4);
    b->setZero(4);
    w->leftCols(2) = wp;
    b->head(2) = bp;
    if (yaw_) {
      Eigen::MatrixXd wy;
      Eigen::VectorXd by;
      yaw_->Solve(lambda, &wy, &by);
      w->rightCols(2) = wy;
      b->tail(2) = by;
    } else {
      (*b)[2] = 1;  // no observable yaw anywhere: predict yaw 0
    }
  }

 private:
  std::unique_ptr<RidgeRegression> position_, yaw_;
  bool all_columns_ = false;
};

// The PoseMlp's loss (mean over samples; yaw terms only for n != 0).
double PoseLoss(const Eigen::MatrixXd& outputs, const Eigen::MatrixXd& targets,
                const Eigen::VectorXi& orders, const std::vector<Eigen::Index>& rows) {
  double sum = 0;
  for (std::size_t k = 0; k < rows.size(); ++k) {
    const Eigen::Index i = rows[k];
    const Eigen::RowVectorXd d = outputs.row(static_cast<Eigen::Index>(k)) - targets.row(i);
    sum += d[0] * d[0] + d[1] * d[1] + (OrderAt(orders, i) != 0 ? d[2] * d[2] + d[3] * d[3] : 0.0);
  }
  return rows.empty() ? 0.0 : sum / rows.size();
}

}  // namespace

RidgePoseRegressor RidgePoseRegressor::Fit(const Eigen::MatrixXf& inputs,
                                           const PoseTargets& targets, const Options& options,
                                           Summary* summary) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  if (inputs.rows() < 1 || targets.poses.rows() != inputs.rows()) {
    throw std::invalid_argument("RidgePoseRegressor::Fit: inputs are " +
                                ShapeOf(inputs.rows(), inputs.cols()) + " and poses " +
                                ShapeOf(targets.poses.rows(), targets.poses.cols()) +
                                ", expected M x P and M x 3 with M >= 1");
  }
  const auto start = Clock::now();
  const Eigen::MatrixXd x = inputs.cast<double>();
  const Eigen::MatrixXd y = EncodePoseOutputs(targets, options.position_scale);
  const Eigen::VectorXi& orders = targets.symmetry_orders;
  const Eigen::Index m = x.rows();
  std::vector<Eigen::Index> all(m);
  std::iota(all.begin(), all.end(), 0);

  Summary s;
  s.samples = static_cast<int>(m);
  s.dim = static_cast<int>(x.cols());
  const std::vector<double>& candidates = options.relative_lambdas;
  s.relative_lambda = candidates[candidates.size() / 2];
  const int held_out = static_cast<int>(std::lround(options.validation_fraction * m));
  if (m >= 5 && held_out >= 1 && held_out < m) {
    std::vector<Eigen::Index> shuffled = all;
    std::mt19937_64 rng(options.seed);
    std::shuffle(shuffled.begin(), shuffled.end(), rng);
    std::vector<Eigen::Index> validation(shuffled.begin(), shuffled.begin() + held_out);
    std::vector<Eigen::Index> train(shuffled.begin() + held_out, shuffled.end());
    std::sort(validation.begin(), validation.end());
    std::sort(train.begin(), train.end());
    const PoseRidge ridge(x, y, orders, train);
    const Eigen::MatrixXd xv = x(validation, Eigen::all);
    double best = std::numeric_limits<double>::infinity();
    for (double relative : candidates) {
      Eigen::MatrixXd w;
      Eigen::VectorXd b;
      ridge.Solve(relative * ridge.MeanEigenvalue(), &w, &b);
      const Eigen::MatrixXd out = (xv * w).rowwise() + b.transpose();
      const double loss = PoseLoss(out, y, orders, validation);
      s.validation_losses.push_back(loss);
      if (loss < best) {
        best = loss;
        s.relative_lambda = relative;
      }
    }
    s.validation = held_out;
  }
  const PoseRidge ridge(x, y, orders, all);
  RidgePoseRegressor model;
  model.position_scale_ = options.position_scale;
  s.lambda = s.relative_lambda * ridge.MeanEigenvalue();
  ridge.Solve(s.lambda, &model.weights_, &model.intercept_);
  s.seconds = SecondsSince(start);
  if (summary) *summary = s;
  return model;
}

Eigen::MatrixXd RidgePoseRegressor::Outputs(const Eigen::MatrixXf& inputs) const {
  if (inputs.cols() != weights_.rows()) {
    throw std::invalid_argument("RidgePoseRegressor: inputs are " +
                                ShapeOf(inputs.rows(), inputs.cols()) + ", expected N x " +
                                std::to_string(weights_.rows()));
  }
  return (inputs.cast<double>() * weights_).rowwise() + intercept_.transpose();
}

Eigen::MatrixXd RidgePoseRegressor::Predict(const Eigen::MatrixXf& inputs,
                                            const Eigen::VectorXi& symmetry_orders) const {
  CheckOrders(symmetry_orders, inputs.rows(), "RidgePoseRegressor::Predict");
  const Eigen::MatrixXd outputs = Outputs(inputs);
  Eigen::MatrixXd poses(inputs.rows(), 3);
  for (Eigen::Index i = 0; i < inputs.rows(); ++i) {
    poses.row(i) = PoseOfOutputs(outputs.row(i), OrderAt(symmetry_orders, i), position_scale_)
                       .transpose();
  }
  return poses;
}

// ---- k-NN ------------------------------------------------------------------------------

bool KnnPoseRegressor::Options::IsValid(std::string* error) const {
  if (k >= 1) return true;
  if (error) *error = "KnnPoseRegressor::Options::k must be >= 1, got " + std::to_string(k);
  return false;
}

KnnPoseRegressor::KnnPoseRegressor(const Eigen::MatrixXf& inputs, const PoseTargets& targets,
                                   const Options& options)
    : options_(options), inputs_(inputs), poses_(targets.poses) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  if (inputs.rows() < 1 || inputs.cols() < 1 || targets.poses.rows() != inputs.rows() ||
      targets.poses.cols() != 3) {
    throw std::invalid_argument("KnnPoseRegressor: inputs are " +
                                ShapeOf(inputs.rows(), inputs.cols()) + " and poses " +
                                ShapeOf(targets.poses.rows(), targets.poses.cols()) +
                                ", expected M x P and M x 3 with M, P >= 1");
  }
}

Eigen::MatrixXd KnnPoseRegressor::Predict(const Eigen::MatrixXf& queries,
                                          const Eigen::VectorXi& symmetry_orders) const {
  if (queries.cols() != inputs_.cols()) {
    throw std::invalid_argument("KnnPoseRegressor::Predict: queries are " +
                                ShapeOf(queries.rows(), queries.cols()) + ", expected N x " +
                                std::to_string(inputs_.cols()));
  }
  CheckOrders(symmetry_orders, queries.rows(), "KnnPoseRegressor::Predict");
  const std::unique_ptr<KnnIndex> index = BuildKnnIndex(inputs_, KnnIndexOptions());  // exact
  const int k = static_cast<int>(std::min<Eigen::Index>(options_.k, inputs_.rows()));
  const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> q = queries;
  std::vector<float> distances(static_cast<std::size_t>(q.rows()) * k);
  std::vector<std::int64_t> labels(distances.size());
  index->Search(q.data(), q.rows(), k, distances.data(), labels.data());
  Eigen::MatrixXd poses(q.rows(), 3);
  for (Eigen::Index i = 0; i < q.rows(); ++i) {
    const int n = OrderAt(symmetry_orders, i);
    double x = 0, y = 0, c = 0, s = 0;
    int found = 0;
    for (int j = 0; j < k; ++j) {
      const std::int64_t label = labels[static_cast<std::size_t>(i) * k + j];
      if (label < 0) continue;
      ++found;
      x += poses_(label, 0);
      y += poses_(label, 1);
      c += std::cos(n * poses_(label, 2));
      s += std::sin(n * poses_(label, 2));
    }
    if (found == 0) {  // a NaN query: nothing is near it
      poses.row(i).setConstant(std::numeric_limits<double>::quiet_NaN());
      continue;
    }
    poses.row(i) << x / found, y / found, n == 0 ? 0.0 : std::atan2(s, c) / n;
  }
  return poses;
}

}  // namespace tactfunc
