// Copyright 2026 The tactfunc Authors.
//
// SGLD on a real latent posterior: the committed Soft Bubble trunk
// (models/pretrained/default.tfm) and a fresh simulated contact (a seed no training run
// used). Minibatch chains with the control variate at the mode (samplers/sgld.h, "Control
// variate") must sample the law the full-batch chains sample; plain minibatches of the
// same size must not (the check can tell them apart). The laws are compared in the
// whitened coordinates u = L^T (z - z*), H_GN(z*) = L L^T, where every direction has
// about unit variance, by the variance of u averaged over the d directions and the mean
// of u: with 4 chains x 150 kept steps at eta = 0.3 (lag-1 autocorrelation ~0.7, ESS
// ~100 per direction) the averaged variance has a Monte Carlo error of a few per cent.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <memory>
#include <string>

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include "estimation/data/image_io.h"
#include "estimation/data/trunk_targets.h"
#include "estimation/fitting/latent_fitter.h"
#include "estimation/fitting/latent_problem.h"
#include "models/simulator/contact_simulator.h"
#include "models/trunk/functa_model.h"
#include "samplers/sgld.h"
#include "tests/support/stored_frame_util.h"

namespace tactfunc {
namespace {

using testing_util::AsStoredDepth;

const std::string kModel = std::string(TACTFUNC_SOURCE_DIR) + "/models/pretrained/default.tfm";

struct Moments {
  double mean_variance = 0;  // variance of u_k averaged over k
  double mean_offset = 0;    // |mean of u| / sqrt(d)
};

Moments Whitened(const Eigen::MatrixXd& samples, const Eigen::VectorXd& mode,
                 const Eigen::MatrixXd& hessian) {
  const Eigen::LLT<Eigen::MatrixXd> llt(hessian);
  const Eigen::MatrixXd u =
      (llt.matrixU() * (samples.rowwise() - mode.transpose()).transpose()).transpose();
  const Eigen::RowVectorXd mean = u.colwise().mean();
  const Eigen::MatrixXd centred = u.rowwise() - mean;
  Moments m;
  m.mean_variance =
      centred.array().square().colwise().sum().mean() / static_cast<double>(u.rows() - 1);
  m.mean_offset = mean.norm() / std::sqrt(static_cast<double>(u.cols()));
  return m;
}

class SgldOnTheTrunk : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(std::filesystem::is_regular_file(kModel)) << kModel;
    model_ = FunctaModel::Load(kModel);
    const SensorTrunk& trunk = model_.Trunk(SensorKind::kSoftBubble);
    const ContactSimulator simulator;
    const std::uint64_t seed = 0x5c0de001u;
    const Contact contact = simulator.SamplePairedContact("rod", seed).bubble;
    const Image frame = AsStoredDepth(simulator.Render(SensorKind::kSoftBubble, contact, seed).frame);
    const Image reference = AsStoredDepth(simulator.Reference(SensorKind::kSoftBubble));
    targets_ = MakeTrunkTargets(frame, reference, SensorKind::kSoftBubble, trunk.format);
    problem_ = std::make_unique<LatentProblem>(trunk, targets_, LatentProblem::Options{});
    LatentFitter::Options fit;
    std::string error;
    ASSERT_TRUE(FitStrategy::Parse("ceres:20", &fit.strategy, &error)) << error;
    const LatentFitter::Summary summary = LatentFitter(trunk, fit).Fit(*problem_, &mode_);
    ASSERT_TRUE(summary.IsSolutionUsable()) << summary.FullReport();
    problem_->GaussNewtonHessian(mode_, &hessian_);
  }

  Moments Run(int minibatch_size, bool control_variate, Sgld::Summary* summary) const {
    Sgld::Options options;
    options.num_chains = 4;
    options.num_samples_per_chain = 150;
    options.minibatch_size = minibatch_size;
    options.control_variate = control_variate;
    options.seed = 7;
    options.num_threads = 2;
    const TrunkPotential potential(*problem_);
    Eigen::MatrixXd samples;
    *summary = Sgld(options).Sample(potential, mode_, &samples);
    EXPECT_TRUE(summary->IsSolutionUsable()) << summary->FullReport();
    return Whitened(samples, mode_, hessian_);
  }

  FunctaModel model_;
  TrunkTargets targets_;
  std::unique_ptr<LatentProblem> problem_;
  Eigen::VectorXd mode_;
  Eigen::MatrixXd hessian_;
};

TEST_F(SgldOnTheTrunk, ControlVariateMinibatchesSampleTheFullBatchLaw) {
  Sgld::Summary full_summary, cv_summary, plain_summary;
  const Moments full = Run(0, true, &full_summary);
  const Moments cv = Run(1024, true, &cv_summary);
  const Moments plain = Run(1024, false, &plain_summary);
  std::printf("whitened variance (mean over d) / offset: full batch %.3f / %.3f (%.0f ms), "
              "control variate n = 1024 %.3f / %.3f (%.0f ms), plain n = 1024 %.3f / %.3f\n",
              full.mean_variance, full.mean_offset, full_summary.sampling_time_ms,
              cv.mean_variance, cv.mean_offset, cv_summary.sampling_time_ms,
              plain.mean_variance, plain.mean_offset);
  EXPECT_FALSE(full_summary.minibatched);
  EXPECT_TRUE(cv_summary.control_variate);
  EXPECT_FALSE(plain_summary.control_variate);
  // The full-batch chain's own law: about the discretised Gaussian's 1 / (1 - eta / 2).
  EXPECT_NEAR(full.mean_variance, 1.0 / (1.0 - 0.15), 0.25);
  EXPECT_NEAR(cv.mean_variance / full.mean_variance, 1.0, 0.1);
  EXPECT_LT(cv.mean_offset, 0.25);
  // Plain minibatches of the same size widen it far beyond that.
  EXPECT_GT(plain.mean_variance / full.mean_variance, 1.5);
}

}  // namespace
}  // namespace tactfunc
