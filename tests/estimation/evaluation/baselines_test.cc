// Copyright 2026 The tactfunc Authors.
//
// The Table I baselines (estimation/evaluation/baselines.h) against exact answers: PCA on data of
// known rank, JPEG's quality search against its own bracket, ridge against a known linear
// map, and pose scoring of symmetric tools.
#include "estimation/evaluation/baselines.h"

#include <cmath>
#include <cstdio>
#include <random>
#include <string>
#include <vector>

#include <Eigen/Dense>

#include "gtest/gtest.h"

namespace tactfunc {
namespace {

// A rows x cols one-channel frame from a flat row of values; all pixels valid.
TrunkTargets FrameOf(const Eigen::RowVectorXf& row, int rows, int cols) {
  TrunkTargets t;
  t.rows = rows;
  t.cols = cols;
  t.values = UnflattenFrame(row, 1);
  t.weights = Eigen::VectorXf::Ones(rows * cols);
  return t;
}

// Smooth contact-like frames: a Gaussian bump whose centre and width vary per frame.
std::vector<TrunkTargets> BumpFrames(int count, int rows, int cols, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(0, 1);
  std::normal_distribution<double> noise(0, 0.01);
  std::vector<TrunkTargets> frames;
  for (int i = 0; i < count; ++i) {
    const double cr = rows * (0.2 + 0.6 * u(rng)), cc = cols * (0.2 + 0.6 * u(rng));
    const double sigma = 2 + 3 * u(rng), height = 0.3 + 0.5 * u(rng);
    Eigen::RowVectorXf row(rows * cols);
    for (int r = 0; r < rows; ++r) {
      for (int c = 0; c < cols; ++c) {
        row[r * cols + c] = static_cast<float>(
            height * std::exp(-((r - cr) * (r - cr) + (c - cc) * (c - cc)) / (2 * sigma * sigma)) +
            noise(rng));
      }
    }
    frames.push_back(FrameOf(row, rows, cols));
  }
  return frames;
}

std::vector<const TrunkTargets*> Pointers(const std::vector<TrunkTargets>& frames) {
  std::vector<const TrunkTargets*> p;
  for (const TrunkTargets& f : frames) p.push_back(&f);
  return p;
}

TEST(Baselines, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(PcaCodec::Options().IsValid(&error)) << error;
  EXPECT_TRUE(JpegCodec::Options().IsValid(&error)) << error;
  EXPECT_TRUE(RidgePoseRegressor::Options().IsValid(&error)) << error;
  EXPECT_TRUE(KnnPoseRegressor::Options().IsValid(&error)) << error;
}

TEST(Baselines, BadOptionsNameTheField) {
  std::string error;
  PcaCodec::Options pca;
  pca.components = 0;
  EXPECT_FALSE(pca.IsValid(&error));
  EXPECT_NE(error.find("components"), std::string::npos) << error;
  JpegCodec::Options jpeg;
  jpeg.quality = 101;
  EXPECT_FALSE(jpeg.IsValid(&error));
  EXPECT_NE(error.find("quality"), std::string::npos) << error;
  EXPECT_THROW(JpegCodec{jpeg}, std::invalid_argument);
}

TEST(Baselines, FlattenAndUnflattenArePixelMajorInverses) {
  TrunkTargets t;
  t.rows = 2;
  t.cols = 3;
  t.values.resize(6, 3);
  for (int j = 0; j < 6; ++j) {
    for (int c = 0; c < 3; ++c) t.values(j, c) = static_cast<float>(10 * j + c);
  }
  const Eigen::RowVectorXf row = FlattenFrame(t);
  EXPECT_EQ(row[3 * 2 + 1], 21.0f);  // pixel 2, channel 1
  EXPECT_EQ(UnflattenFrame(row, 3), t.values);
  EXPECT_THROW(UnflattenFrame(row, 4), std::invalid_argument);
}

TEST(Baselines, DownsamplePixelsAveragesBlocksAndPartialEdges) {
  Eigen::RowVectorXf row(3 * 3);
  row << 1, 2, 3, 4, 5, 6, 7, 8, 9;
  const Eigen::RowVectorXf down = DownsamplePixels(FrameOf(row, 3, 3), 2);
  ASSERT_EQ(down.size(), 4);
  EXPECT_FLOAT_EQ(down[0], 3.0f);  // (1 + 2 + 4 + 5) / 4
  EXPECT_FLOAT_EQ(down[1], 4.5f);  // (3 + 6) / 2
  EXPECT_FLOAT_EQ(down[2], 7.5f);  // (7 + 8) / 2
  EXPECT_FLOAT_EQ(down[3], 9.0f);
  EXPECT_EQ(DownsamplePixels(FrameOf(row, 3, 3), 1), row);
}

TEST(Baselines, PcaReconstructsRankKDataExactlyWithKComponents) {
  const int m = 40, p = 60, k = 5;
  std::mt19937_64 rng(3);
  std::normal_distribution<float> normal(0, 1);
  Eigen::MatrixXf basis(k, p), codes(m, k);
  for (int i = 0; i < basis.size(); ++i) basis.data()[i] = normal(rng);
  for (int i = 0; i < codes.size(); ++i) codes.data()[i] = normal(rng);
  Eigen::RowVectorXf offset(p);
  for (int j = 0; j < p; ++j) offset[j] = normal(rng);
  const Eigen::MatrixXf data = (codes * basis).rowwise() + offset;  // affine rank k
  PcaCodec::Options options;
  options.components = k;
  PcaCodec::Summary summary;
  const PcaCodec pca = PcaCodec::Fit(data, options, &summary);
  EXPECT_EQ(pca.components(), k);
  EXPECT_EQ(pca.BytesPerFrame(), 4u * k);
  EXPECT_EQ(pca.ModelBytes(), 4u * (p + k * p));
  const Eigen::MatrixXf decoded = pca.Decode(pca.Encode(data));
  EXPECT_LT((decoded - data).cwiseAbs().maxCoeff(), 1e-3f * data.cwiseAbs().maxCoeff());
  EXPECT_NEAR(summary.explained_variance, 1.0, 1e-4);
  // Orthonormal basis rows.
  EXPECT_LT((pca.basis() * pca.basis().transpose() - Eigen::MatrixXf::Identity(k, k))
                .cwiseAbs()
                .maxCoeff(),
            1e-4f);
}

// A brute-force reference: the eigen-decomposition of C^T C in double, C the centred
// frames, whatever the shape (its eigenvalues are the squared singular values s^2 of C,
// the PCA's eigenvalues s^2 / M, its eigenvectors the basis rows up to sign); the Gram
// path (M <= P), the covariance path (P < M) and the iterative path (K > 600,
// n <= K / 4) each agree. Not an SVD: Eigen's BDCSVD alone takes about a minute to
// compile, its JacobiSVD 20 s to run on these shapes, and squaring the spectrum in double
// loses nothing at these tolerances (the compared eigenvalues lie within four decades of
// the largest).
void ExpectPcaMatchesSvd(const Eigen::MatrixXf& data, int n) {
  SCOPED_TRACE(std::to_string(data.rows()) + " x " + std::to_string(data.cols()) + ", n " +
               std::to_string(n));
  PcaCodec::Options options;
  options.components = n;
  PcaCodec::Summary summary;
  const PcaCodec pca = PcaCodec::Fit(data, options, &summary);
  ASSERT_EQ(pca.components(), n);
  const Eigen::MatrixXd x = data.cast<double>();
  const Eigen::RowVectorXd mean = x.colwise().mean();
  const Eigen::MatrixXd centred = x.rowwise() - mean;
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> reference(centred.transpose() *
                                                                  centred);
  const Eigen::VectorXd lambda = reference.eigenvalues().reverse();  // descending
  const Eigen::MatrixXd v = reference.eigenvectors().rowwise().reverse();
  const Eigen::VectorXd s = lambda.cwiseMax(0.0).cwiseSqrt();
  EXPECT_LT((pca.mean().cast<double>() - mean).cwiseAbs().maxCoeff(), 1e-5);
  for (int i = 0; i < n; ++i) {
    const double expected = s[i] * s[i] / data.rows();
    EXPECT_NEAR(pca.eigenvalues()[i], expected, 1e-4 * expected + 1e-9) << "eigenvalue " << i;
    // Directions of well-separated eigenvalues are defined up to sign.
    const double gap = std::min(i > 0 ? s[i - 1] - s[i] : 1e9, s[i] - s[i + 1]);
    if (gap > 1e-2 * s[0]) {
      const double cosine = std::abs(pca.basis().row(i).cast<double>().dot(v.col(i)));
      EXPECT_NEAR(cosine, 1.0, 1e-4) << "basis row " << i;
    }
    // The fixed sign: the largest-magnitude entry is positive.
    Eigen::Index j = 0;
    pca.basis().row(i).cwiseAbs().maxCoeff(&j);
    EXPECT_GT(pca.basis()(i, j), 0) << "basis row " << i;
  }
  EXPECT_LT((pca.basis() * pca.basis().transpose() - Eigen::MatrixXf::Identity(n, n))
                .cwiseAbs()
                .maxCoeff(),
            1e-4f);
  // Deterministic: a second fit is the same to the bit.
  const PcaCodec again = PcaCodec::Fit(data, options);
  EXPECT_EQ(again.basis(), pca.basis());
  EXPECT_EQ(again.eigenvalues(), pca.eigenvalues());
}

// Frames with a decaying spectrum: rank-r signal with scales 1 / (1 + i), plus noise.
Eigen::MatrixXf DecayingFrames(int m, int p, int r, unsigned seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<float> normal(0, 1);
  Eigen::MatrixXf basis(r, p), codes(m, r), noise(m, p);
  for (int i = 0; i < basis.size(); ++i) basis.data()[i] = normal(rng);
  for (int k = 0; k < m; ++k) {
    for (int i = 0; i < r; ++i) codes(k, i) = normal(rng) * 10.0f / (1.0f + i);
  }
  for (int i = 0; i < noise.size(); ++i) noise.data()[i] = 0.01f * normal(rng);
  return (codes * basis + noise).array() + 3.0f;
}

TEST(Baselines, PcaMatchesABruteForceSvdOnEveryPath) {
  ExpectPcaMatchesSvd(DecayingFrames(30, 50, 8, 1), 6);     // Gram, dense
  ExpectPcaMatchesSvd(DecayingFrames(60, 20, 8, 2), 6);     // covariance, dense
  ExpectPcaMatchesSvd(DecayingFrames(20, 20, 30, 3), 19);   // every component but the null one
  ExpectPcaMatchesSvd(DecayingFrames(700, 760, 40, 4), 24); // block Krylov
  ExpectPcaMatchesSvd(DecayingFrames(760, 700, 40, 5), 24); // block Krylov, P < M
  ExpectPcaMatchesSvd(DecayingFrames(700, 760, 40, 7), 2);  // block Krylov, few components
  PcaCodec::Options options;
  options.components = 24;
  PcaCodec::Summary summary;
  PcaCodec::Fit(DecayingFrames(700, 760, 40, 4), options, &summary);
  EXPECT_NE(summary.method.find("block Krylov"), std::string::npos) << summary.method;
  options.exact = true;
  PcaCodec::Fit(DecayingFrames(700, 760, 40, 4), options, &summary);
  EXPECT_NE(summary.method.find("subspace iteration"), std::string::npos) << summary.method;
}

// Variance of the frames the codec's reconstructions leave out, over the total.
double LeftOut(const PcaCodec& pca, const Eigen::MatrixXf& data) {
  const Eigen::MatrixXd x = data.cast<double>();
  const Eigen::MatrixXd centred = x.rowwise() - x.colwise().mean();
  const Eigen::MatrixXd error = pca.Decode(pca.Encode(data)).cast<double>() - x;
  return error.squaredNorm() / centred.squaredNorm();
}

TEST(Baselines, FastPcaKeepsNearlyTheExactVarianceWhereManyComponentsLieInTheNoiseFloor) {
  // 40 signal directions and 110 of a flat noise floor among the 150 kept: the fast fit
  // cannot pick the noise floor's top directions exactly, but the variance it leaves out
  // must stay within 1% of the exact fit's (0.04 dB of PSNR; bench pca measures 0.27%
  // at eval's size), and it must beat keeping the signal's directions alone.
  const Eigen::MatrixXf data = DecayingFrames(700, 760, 40, 6);
  PcaCodec::Options options;
  options.components = 150;
  PcaCodec::Summary summary;
  const PcaCodec fast = PcaCodec::Fit(data, options, &summary);
  ASSERT_NE(summary.method.find("block Krylov"), std::string::npos) << summary.method;
  options.exact = true;
  const PcaCodec exact = PcaCodec::Fit(data, options);
  const double fast_left = LeftOut(fast, data), exact_left = LeftOut(exact, data);
  std::printf("left out: fast %.6e, exact %.6e (+%.3f%%), signal only %.6e\n", fast_left,
              exact_left, 100 * (fast_left / exact_left - 1), LeftOut(exact.Truncated(40), data));
  EXPECT_GE(fast_left, exact_left * (1 - 1e-6));
  EXPECT_LE(fast_left, exact_left * 1.01);
  EXPECT_LT(fast_left, LeftOut(exact.Truncated(40), data));
}

TEST(Baselines, PcaErrorFallsAsComponentsGrow) {
  const std::vector<TrunkTargets> frames = BumpFrames(80, 12, 14, 5);
  const Eigen::MatrixXf data = StackFrames(Pointers(frames));
  PcaCodec::Options options;
  options.components = 32;
  const PcaCodec full = PcaCodec::Fit(data, options);
  double previous_psnr = -1e9;
  for (int n : {1, 2, 4, 8, 16, 32}) {
    const PcaCodec pca = full.Truncated(n);
    const Eigen::MatrixXf decoded = pca.Decode(pca.Encode(data));
    double psnr = 0;
    for (int i = 0; i < data.rows(); ++i) {
      psnr += Psnr(UnflattenFrame(decoded.row(i), 1), frames[i]) / data.rows();
    }
    EXPECT_GT(psnr, previous_psnr) << n << " components";
    previous_psnr = psnr;
  }
  EXPECT_THROW(full.Truncated(33), std::invalid_argument);
}

TEST(Baselines, JpegQualitySearchHitsTheTargetBytesWithinOneQualityStep) {
  const std::vector<TrunkTargets> frames = BumpFrames(20, 40, 48, 7);
  const std::vector<const TrunkTargets*> pointers = Pointers(frames);
  JpegCodec::Options options;
  JpegRangeOfFrames(pointers, &options.lo, &options.hi);
  // The target: what quality 40 gives, plus a little, so that it lies strictly inside a
  // bracket.
  options.quality = 40;
  double at40 = 0;
  for (const TrunkTargets* f : pointers) {
    at40 += JpegCodec(options).EncodeDecode(f->values, f->rows, f->cols) / 20.0;
  }
  const double target = at40 + 3;
  const JpegQualitySearchSummary s = FindJpegQuality(pointers, options, target);
  EXPECT_TRUE(s.target_reachable);
  EXPECT_LE(s.below_bytes, target);
  EXPECT_GT(s.above_bytes, target);
  EXPECT_TRUE(s.quality == s.below || s.quality == s.below + 1) << s.BriefReport();
  EXPECT_GE(s.below, 40);
  EXPECT_LE(s.probes, 9);  // a binary search over 100 values, plus the two ends
  // An unreachable target: quality 1 with the flag down.
  const JpegQualitySearchSummary tiny = FindJpegQuality(pointers, options, 1.0);
  EXPECT_FALSE(tiny.target_reachable);
  EXPECT_EQ(tiny.quality, 1);
}

TEST(Baselines, JpegPsnrRisesWithQualityAndIncludesTheQuantisation) {
  const std::vector<TrunkTargets> frames = BumpFrames(6, 40, 48, 9);
  JpegCodec::Options options;
  JpegRangeOfFrames(Pointers(frames), &options.lo, &options.hi);
  double previous = -1e9;
  std::uint64_t previous_bytes = 0;
  for (int quality : {5, 25, 50, 75, 95}) {
    options.quality = quality;
    const JpegCodec codec(options);
    double psnr = 0;
    std::uint64_t bytes = 0;
    for (const TrunkTargets& f : frames) {
      Eigen::MatrixXf decoded;
      bytes += codec.EncodeDecode(f.values, f.rows, f.cols, &decoded);
      psnr += Psnr(decoded, f) / frames.size();
    }
    EXPECT_GT(psnr, previous) << "quality " << quality;
    EXPECT_GT(bytes, previous_bytes) << "quality " << quality;
    previous = psnr;
    previous_bytes = bytes;
  }
  // Even at quality 100 the 8-bit quantisation over the fixed range is an error: a frame
  // spanning a small part of the range cannot be reproduced exactly.
  options.quality = 100;
  Eigen::MatrixXf decoded;
  JpegCodec(options).EncodeDecode(frames[0].values, frames[0].rows, frames[0].cols, &decoded);
  EXPECT_TRUE(std::isfinite(Psnr(decoded, frames[0])));
  // The tables are counted apart: the whole file is larger than the per-frame bytes.
  JpegCodec::Options whole = options;
  whole.tables_in_model = false;
  const std::uint64_t frame_bytes = JpegCodec(options).EncodeDecode(frames[0].values, 40, 48);
  const std::uint64_t table_bytes = JpegCodec(options).TableBytes(frames[0].values, 40, 48);
  EXPECT_GT(table_bytes, 100u);
  EXPECT_EQ(JpegCodec(whole).EncodeDecode(frames[0].values, 40, 48), frame_bytes + table_bytes);
}

TEST(Baselines, RidgeRecoversAKnownLinearMap) {
  const int m = 200, p = 12, k = 3;
  std::mt19937_64 rng(11);
  std::normal_distribution<double> normal(0, 1);
  Eigen::MatrixXd x(m, p), a(p, k);
  for (int i = 0; i < x.size(); ++i) x.data()[i] = normal(rng);
  for (int i = 0; i < a.size(); ++i) a.data()[i] = normal(rng);
  const Eigen::Vector3d b(0.5, -2, 3);
  const Eigen::MatrixXd y = (x * a).rowwise() + b.transpose();
  const RidgeRegression ridge(x, y);
  Eigen::MatrixXd w;
  Eigen::VectorXd intercept;
  ridge.Solve(0, &w, &intercept);
  EXPECT_LT((w - a).cwiseAbs().maxCoeff(), 1e-9);
  EXPECT_LT((intercept - b).cwiseAbs().maxCoeff(), 1e-9);
  // The dual form (more inputs than samples) gives the same as the primal form on the
  // same problem: the minimum-norm interpolant at lambda -> 0, and the same weights at
  // any lambda > 0.
  const Eigen::MatrixXd xs = x.topRows(8), ys = y.topRows(8);
  const RidgeRegression dual(xs, ys);
  Eigen::MatrixXd wd;
  Eigen::VectorXd bd;
  dual.Solve(0.3, &wd, &bd);
  const Eigen::MatrixXd xc = xs.rowwise() - xs.colwise().mean();
  const Eigen::MatrixXd yc = ys.rowwise() - ys.colwise().mean();
  const Eigen::MatrixXd direct =
      (xc.transpose() * xc + 0.3 * Eigen::MatrixXd::Identity(p, p)).ldlt().solve(xc.transpose() * yc);
  EXPECT_LT((wd - direct).cwiseAbs().maxCoeff(), 1e-9);
  // Larger lambda shrinks the weights.
  Eigen::MatrixXd w_big;
  ridge.Solve(1e4 * ridge.MeanEigenvalue(), &w_big, &intercept);
  EXPECT_LT(w_big.norm(), 0.01 * a.norm());
}

// Linear "images" of a pose: inputs = (x, y, cos n yaw, sin n yaw) mixed into 20 pixels.
struct PoseProblem {
  Eigen::MatrixXf inputs;
  PoseTargets targets;
};
PoseProblem MakePoseProblem(int m, int n, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  std::normal_distribution<double> normal(0, 1);
  Eigen::MatrixXd mix(4, 20);
  for (int i = 0; i < mix.size(); ++i) mix.data()[i] = normal(rng);
  PoseProblem problem;
  problem.inputs.resize(m, 20);
  problem.targets.poses.resize(m, 3);
  problem.targets.symmetry_orders = Eigen::VectorXi::Constant(m, n);
  for (int i = 0; i < m; ++i) {
    const double x = 0.004 * u(rng), y = 0.004 * u(rng), yaw = M_PI * u(rng);
    problem.targets.poses.row(i) << x, y, yaw;
    const Eigen::RowVector4d features(x / 0.005, y / 0.005, std::cos(n * yaw), std::sin(n * yaw));
    problem.inputs.row(i) = (features * mix).cast<float>();
  }
  return problem;
}

TEST(Baselines, PoseBaselinesScoreSymmetricToolsModuloSymmetry) {
  // Scoring alone: a rod (n = 2) predicted at yaw + pi is exact; a square (n = 4) at
  // yaw + pi/2 too; an asymmetric tool at yaw + pi is pi off. Hemisphere (n = 0): yaw
  // is not scored.
  Eigen::MatrixXd truth(4, 3), predicted(4, 3);
  truth << 0, 0, 0.3, 0, 0, 0.3, 0, 0, 0.3, 0.001, 0, 0.3;
  predicted << 0, 0, 0.3 + M_PI, 0, 0, 0.3 + M_PI / 2, 0, 0, 0.3 + M_PI, 0.001, 0.002, 2.0;
  const PoseErrors e = ScorePoses(predicted, truth, Eigen::Vector4i(2, 4, 1, 0));
  EXPECT_EQ(e.count, 4);
  EXPECT_EQ(e.yaw_count, 3);
  EXPECT_NEAR(e.yaw_sq, M_PI * M_PI, 1e-9);
  EXPECT_NEAR(e.position_sq, 0.002 * 0.002, 1e-15);
  EXPECT_NEAR(e.PoseMse(), (M_PI * M_PI + 0.002 * 0.002) / 3 / 4, 1e-12);
  EXPECT_NEAR(e.RmseMm(), 1e3 * std::sqrt(0.002 * 0.002 / 4), 1e-9);

  // Ridge and k-NN on a C_2 tool whose images depend only on (cos 2 yaw, sin 2 yaw):
  // yaw is recoverable only modulo pi, and both recover it so.
  const PoseProblem all = MakePoseProblem(450, 2, 1);  // one mixing: 400 train, 50 test
  PoseProblem train;
  train.inputs = all.inputs.topRows(400);
  train.targets.poses = all.targets.poses.topRows(400);
  train.targets.symmetry_orders = all.targets.symmetry_orders.head(400);
  const Eigen::MatrixXf test_inputs = all.inputs.bottomRows(50);
  const Eigen::MatrixXd test_poses = all.targets.poses.bottomRows(50);
  const Eigen::VectorXi orders = Eigen::VectorXi::Constant(50, 2);

  RidgePoseRegressor::Summary summary;
  const RidgePoseRegressor ridge =
      RidgePoseRegressor::Fit(train.inputs, train.targets, RidgePoseRegressor::Options(), &summary);
  EXPECT_EQ(summary.validation, 80);
  const PoseErrors ridge_errors = ScorePoses(ridge.Predict(test_inputs, orders), test_poses, orders);
  EXPECT_LT(ridge_errors.RmseMm(), 0.01) << summary.BriefReport();
  EXPECT_LT(ridge_errors.RmseDeg(), 0.1);
  // Scored without the symmetry (n = 1), about half the yaws would be pi/2 off on average.
  const PoseErrors unfolded = ScorePoses(ridge.Predict(test_inputs, orders), test_poses,
                                         Eigen::VectorXi::Ones(50));
  EXPECT_GT(unfolded.RmseDeg(), 30);

  KnnPoseRegressor::Options knn_options;
  knn_options.k = 3;
  const KnnPoseRegressor knn(train.inputs, train.targets, knn_options);
  const PoseErrors knn_errors = ScorePoses(knn.Predict(test_inputs, orders), test_poses, orders);
  EXPECT_LT(knn_errors.RmseDeg(), 15);  // neighbours at yaw and yaw + pi agree
  EXPECT_LT(knn_errors.RmseMm(), 1.5);
}

TEST(Baselines, RidgeLeavesHemisphereYawOutOfTheFit) {
  // Half the samples have n = 0 and a random (unobservable) yaw in their labels: the
  // yaw outputs are fitted on the n != 0 half only, so the n = 1 yaws stay exact.
  PoseProblem p = MakePoseProblem(200, 1, 4);
  std::mt19937_64 rng(2);
  std::uniform_real_distribution<double> u(-M_PI, M_PI);
  for (int i = 0; i < 200; i += 2) {
    p.targets.symmetry_orders[i] = 0;
  }
  Eigen::MatrixXd noisy_labels = p.targets.poses;
  for (int i = 0; i < 200; i += 2) noisy_labels(i, 2) = u(rng);
  PoseTargets targets{noisy_labels, p.targets.symmetry_orders};
  const RidgePoseRegressor ridge = RidgePoseRegressor::Fit(p.inputs, targets, {});
  const Eigen::MatrixXd predicted = ridge.Predict(p.inputs, p.targets.symmetry_orders);
  const PoseErrors e = ScorePoses(predicted, p.targets.poses, p.targets.symmetry_orders);
  EXPECT_EQ(e.yaw_count, 100);
  EXPECT_LT(e.RmseDeg(), 0.1);
  for (int i = 0; i < 200; i += 2) EXPECT_EQ(predicted(i, 2), 0.0);
}

TEST(Baselines, BadShapesAreRejectedWithTheShapes) {
  EXPECT_THROW(ScorePoses(Eigen::MatrixXd(2, 3), Eigen::MatrixXd(3, 3), {}), std::invalid_argument);
  EXPECT_THROW(PcaCodec::Fit(Eigen::MatrixXf(0, 4), {}), std::invalid_argument);
  PcaCodec::Options options;
  options.components = 2;
  const PcaCodec pca = PcaCodec::Fit(Eigen::MatrixXf::Random(5, 4), options);
  try {
    pca.Encode(Eigen::MatrixXf(3, 5));
    FAIL() << "no throw";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("3 x 5"), std::string::npos) << e.what();
  }
  JpegCodec::Options jpeg;
  EXPECT_THROW(JpegCodec(jpeg).EncodeDecode(Eigen::MatrixXf(6, 2), 2, 3), std::invalid_argument);
}

}  // namespace
}  // namespace tactfunc
