// Copyright 2026 The tactfunc Authors.
//
// SGLD against Gaussians with known moments. Tolerances come from the Monte Carlo
// standard error of each estimate, SE = sd / sqrt(ESS) with the ESS of the very series
// averaged (z_k for means, (z_i - m_i)(z_j - m_j) for covariances), at 4.5 SE (two-sided
// p ~ 7e-6 per check). With a constant step the chain's stationary law is not the
// target: for U = (z - m)^T Lambda (z - m) / 2 its mean is m and its covariance S solves
// the discrete Lyapunov equation S = M S M^T + 2 eta P, M = I - eta P Lambda, which the
// tests solve exactly (the discretisation bias is accounted for, not tolerated).
#include "samplers/sgld.h"

#include <cmath>
#include <string>
#include <vector>

#include <Eigen/Dense>
#include <boost/random/mersenne_twister.hpp>
#include <boost/random/normal_distribution.hpp>
#include <gtest/gtest.h>

#include "tests/support/sampler_test_util.h"

namespace tactfunc {
namespace {

using testing_util::kSigmas;

Eigen::MatrixXd Precision3() {
  Eigen::MatrixXd cov(3, 3);
  cov << 2.0, 0.6, -0.3,  //
      0.6, 1.0, 0.2,      //
      -0.3, 0.2, 0.5;
  return cov.inverse();
}

// S = M S M^T + Q by vectorisation: (I - M (x) M) vec(S) = vec(Q).
Eigen::MatrixXd SolveDiscreteLyapunov(const Eigen::MatrixXd& M, const Eigen::MatrixXd& Q) {
  const int d = static_cast<int>(M.rows());
  Eigen::MatrixXd K(d * d, d * d);
  for (int i = 0; i < d; ++i) {
    for (int j = 0; j < d; ++j) K.block(i * d, j * d, d, d) = M(i, j) * M;
  }
  const Eigen::MatrixXd A = Eigen::MatrixXd::Identity(d * d, d * d) - K;
  const Eigen::VectorXd vec_q = Eigen::Map<const Eigen::VectorXd>(Q.data(), d * d);
  const Eigen::VectorXd vec_s = A.fullPivLu().solve(vec_q);
  return Eigen::Map<const Eigen::MatrixXd>(vec_s.data(), d, d);
}

// The chains of column k (series for the diagnostics) of chain-major samples.
std::vector<Eigen::VectorXd> ChainsOf(const Eigen::VectorXd& series, int num_chains) {
  const int n = static_cast<int>(series.size()) / num_chains;
  std::vector<Eigen::VectorXd> chains;
  for (int c = 0; c < num_chains; ++c) chains.push_back(series.segment(c * n, n));
  return chains;
}

// Checks mean and covariance of the samples against (mean, S) within kSigmas MC SE.
void ExpectMoments(const Eigen::MatrixXd& samples, int num_chains, const Eigen::VectorXd& mean,
                   const Eigen::MatrixXd& S) {
  const int d = static_cast<int>(mean.size());
  for (int i = 0; i < d; ++i) {
    const Eigen::VectorXd x = samples.col(i);
    const double ess = EffectiveSampleSize(ChainsOf(x, num_chains));
    const double se = std::sqrt(S(i, i) / ess);
    EXPECT_NEAR(x.mean(), mean[i], kSigmas * se) << "mean " << i << ", ESS " << ess;
    for (int j = 0; j <= i; ++j) {
      const Eigen::VectorXd p =
          (samples.col(i).array() - mean[i]) * (samples.col(j).array() - mean[j]);
      const double ess_p = EffectiveSampleSize(ChainsOf(p, num_chains));
      const double sd_p = std::sqrt((p.array() - p.mean()).square().sum() / (p.size() - 1));
      EXPECT_NEAR(p.mean(), S(i, j), kSigmas * sd_p / std::sqrt(ess_p))
          << "covariance (" << i << ", " << j << "), ESS " << ess_p;
    }
  }
}

Sgld::Options GaussianOptions(Sgld::Preconditioner preconditioner, double eta) {
  Sgld::Options options;
  options.preconditioner = preconditioner;
  options.step_size.initial = eta;
  options.num_chains = 4;
  options.num_samples_per_chain = 5000;
  options.burn_in = 200;
  options.seed = 42;
  options.num_threads = 2;
  return options;
}

TEST(Sgld, DefaultOptionsAreValid) {
  std::string error;
  EXPECT_TRUE(Sgld::Options().IsValid(&error)) << error;
}

TEST(Sgld, BadOptionsNameTheField) {
  std::string error;
  Sgld::Options options;
  options.num_chains = 0;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("num_chains"), std::string::npos) << error;
  options = Sgld::Options();
  options.thinning = 0;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("thinning"), std::string::npos) << error;
  options = Sgld::Options();
  options.step_size.initial = -1;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("step_size"), std::string::npos) << error;
  options = Sgld::Options();
  options.initial_jitter = -1;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("initial_jitter"), std::string::npos) << error;
  options = Sgld::Options();
  options.divergence_potential_increase = 0;
  EXPECT_FALSE(options.IsValid(&error));
  EXPECT_NE(error.find("divergence_potential_increase"), std::string::npos) << error;
  EXPECT_THROW(Sgld{options}, std::invalid_argument);
}

TEST(Sgld, DensePreconditionedChainRecoversGaussianMoments) {
  const Eigen::Vector3d mean(1.0, -2.0, 0.5);
  const Eigen::MatrixXd precision = Precision3();
  const GaussianPotential potential(mean, precision);
  const double eta = 0.3;
  const Sgld sgld(GaussianOptions(Sgld::Preconditioner::kDense, eta));
  Eigen::MatrixXd samples;
  Eigen::VectorXd u;
  const Sgld::Summary summary = sgld.Sample(potential, Eigen::Vector3d::Zero(), &samples, &u);
  ASSERT_EQ(summary.termination_type, SgldTermination::kCompleted) << summary.FullReport();
  EXPECT_EQ(summary.preconditioner, Sgld::Preconditioner::kDense);
  ASSERT_EQ(samples.rows(), 4 * 5000);
  ASSERT_EQ(u.size(), samples.rows());
  // P = Lambda^-1: S = Lambda^-1 / (1 - eta / 2).
  const Eigen::MatrixXd P = precision.inverse();
  const Eigen::MatrixXd M = Eigen::MatrixXd::Identity(3, 3) - eta * P * precision;
  const Eigen::MatrixXd S = SolveDiscreteLyapunov(M, 2 * eta * P);
  EXPECT_TRUE(S.isApprox(P / (1 - eta / 2), 1e-9));
  ExpectMoments(samples, 4, mean, S);
  for (int i = 0; i < 5; ++i) {
    EXPECT_NEAR(u[i], potential.Evaluate(samples.row(i).transpose(), nullptr), 1e-9);
  }
  EXPECT_LT(summary.max_split_rhat, 1.01);
}

TEST(Sgld, DiagonalAndNoPreconditioningGiveTheSameMoments) {
  const Eigen::Vector3d mean(1.0, -2.0, 0.5);
  const Eigen::MatrixXd precision = Precision3();
  const GaussianPotential potential(mean, precision);
  for (auto [preconditioner, eta] :
       {std::pair{Sgld::Preconditioner::kDiagonal, 0.2}, std::pair{Sgld::Preconditioner::kNone, 0.1}}) {
    SCOPED_TRACE(ToString(preconditioner));
    Sgld::Options options = GaussianOptions(preconditioner, eta);
    options.num_samples_per_chain = 10000;
    const Sgld sgld(options);
    Eigen::MatrixXd samples;
    const Sgld::Summary summary = sgld.Sample(potential, Eigen::Vector3d::Zero(), &samples);
    ASSERT_EQ(summary.termination_type, SgldTermination::kCompleted) << summary.FullReport();
    EXPECT_EQ(summary.preconditioner, preconditioner);
    const Eigen::MatrixXd P =
        preconditioner == Sgld::Preconditioner::kDiagonal
            ? Eigen::MatrixXd(precision.diagonal().cwiseInverse().asDiagonal())
            : Eigen::MatrixXd::Identity(3, 3);
    const Eigen::MatrixXd M = Eigen::MatrixXd::Identity(3, 3) - eta * P * precision;
    ExpectMoments(samples, 4, mean, SolveDiscreteLyapunov(M, 2 * eta * P));
  }
}

TEST(Sgld, SplitRhatIsNearOneForConvergedChains) {
  const GaussianPotential potential(Eigen::Vector3d(1.0, -2.0, 0.5), Precision3());
  const Sgld sgld(GaussianOptions(Sgld::Preconditioner::kDense, 0.3));
  Eigen::MatrixXd samples;
  const Sgld::Summary summary = sgld.Sample(potential, Eigen::Vector3d::Zero(), &samples);
  // Converged: R^2 ~ 1 - 1/N + X M' / ESS with X ~ chi2(M' - 1) / (M' - 1) over M' = 8
  // half chains of N draws; bound X by 1 + kSigmas sqrt(2 / (M' - 1)).
  const double m = 8, n = 2500;
  for (int k = 0; k < 3; ++k) {
    const double ess = summary.effective_sample_size[k];
    const double bound = std::sqrt(1 + (1 + kSigmas * std::sqrt(2 / (m - 1))) * m / ess);
    EXPECT_LT(summary.split_rhat[k], bound) << "dimension " << k << ", ESS " << ess;
    EXPECT_GT(summary.split_rhat[k], std::sqrt(1 - 1 / n) - 1e-12);
  }
}

TEST(Sgld, SplitRhatFlagsChainsStartedFarApartWithTooFewSteps) {
  const GaussianPotential potential(Eigen::Vector3d(1.0, -2.0, 0.5), Precision3());
  Sgld::Options options = GaussianOptions(Sgld::Preconditioner::kDense, 0.01);
  options.num_samples_per_chain = 20;
  options.burn_in = 0;
  options.initial_jitter = 50;  // starts 50 posterior standard deviations apart
  options.min_diffusion = 0;
  const Sgld sgld(options);
  Eigen::MatrixXd samples;
  const Sgld::Summary summary = sgld.Sample(potential, Eigen::Vector3d::Zero(), &samples);
  EXPECT_GT(summary.max_split_rhat, 1.1) << summary.FullReport();
}

TEST(Sgld, EffectiveSampleSizeOfIndependentDrawsIsTheirNumber) {
  boost::random::mt19937_64 rng(7);
  boost::random::normal_distribution<double> normal;
  std::vector<Eigen::VectorXd> chains(4, Eigen::VectorXd(5000));
  for (auto& c : chains) {
    for (Eigen::Index i = 0; i < c.size(); ++i) c[i] = normal(rng);
  }
  int max_lag = 0;
  const double n = 20000;
  const double ess = EffectiveSampleSize(chains, &max_lag);
  // Sokal: var(tau_hat) ~ 2 (2 K + 1) / n tau^2 with K the last lag summed.
  const double relative_se = std::sqrt(2.0 * (2 * max_lag + 1) / n);
  EXPECT_NEAR(ess / n, 1.0, kSigmas * relative_se) << "max lag " << max_lag;
}

TEST(Sgld, EffectiveSampleSizeOfAnAr1ChainMatchesTheory) {
  const double phi = 0.6;
  boost::random::mt19937_64 rng(11);
  boost::random::normal_distribution<double> normal;
  std::vector<Eigen::VectorXd> chains(4, Eigen::VectorXd(20000));
  for (auto& c : chains) {
    double x = normal(rng);  // stationary start
    for (Eigen::Index i = 0; i < c.size(); ++i) {
      c[i] = x;
      x = phi * x + std::sqrt(1 - phi * phi) * normal(rng);
    }
  }
  int max_lag = 0;
  const double n = 80000;
  const double tau = (1 + phi) / (1 - phi);  // integrated autocorrelation time
  const double ess = EffectiveSampleSize(chains, &max_lag);
  const double relative_se = std::sqrt(2.0 * (2 * max_lag + 1) / n);
  EXPECT_NEAR(ess / (n / tau), 1.0, kSigmas * relative_se) << "max lag " << max_lag;
}

TEST(Sgld, DiagnosticsOfDegenerateInputs) {
  EXPECT_TRUE(std::isnan(EffectiveSampleSize({Eigen::VectorXd::Zero(3)})));
  EXPECT_TRUE(std::isnan(SplitRhat({Eigen::VectorXd::Zero(8), Eigen::VectorXd::Zero(9)})));
  EXPECT_EQ(EffectiveSampleSize({Eigen::VectorXd::Ones(8), Eigen::VectorXd::Ones(8)}), 16);
  EXPECT_EQ(SplitRhat({Eigen::VectorXd::Ones(8)}), 1.0);
}

TEST(Sgld, HugeStepSizeIsReportedAsDivergenceWithoutThrowing) {
  const GaussianPotential potential(Eigen::Vector3d(1.0, -2.0, 0.5), Precision3());
  Sgld::Options options = GaussianOptions(Sgld::Preconditioner::kNone, 10.0);
  options.num_samples_per_chain = 100;
  const Sgld sgld(options);
  Eigen::MatrixXd samples;
  Eigen::VectorXd u;
  Sgld::Summary summary;
  ASSERT_NO_THROW(summary = sgld.Sample(potential, Eigen::Vector3d::Zero(), &samples, &u));
  EXPECT_EQ(summary.termination_type, SgldTermination::kDiverged);
  EXPECT_FALSE(summary.IsSolutionUsable());
  EXPECT_NE(summary.message.find("diverged"), std::string::npos) << summary.message;
  EXPECT_EQ(samples.rows(), 0);
  EXPECT_TRUE(samples.allFinite());
  EXPECT_TRUE(u.allFinite());
  for (const auto& chain : summary.chains) EXPECT_TRUE(chain.diverged);
}

TEST(Sgld, TinyStepSizeIsFlagged) {
  const GaussianPotential potential(Eigen::Vector3d(1.0, -2.0, 0.5), Precision3());
  Sgld::Options options = GaussianOptions(Sgld::Preconditioner::kDense, 1e-12);
  options.num_samples_per_chain = 10;
  const Sgld sgld(options);
  Eigen::MatrixXd samples;
  const Sgld::Summary summary = sgld.Sample(potential, Eigen::Vector3d::Zero(), &samples);
  EXPECT_EQ(summary.termination_type, SgldTermination::kStepSizeTooSmall) << summary.message;
  EXPECT_NE(summary.message.find("step size too small"), std::string::npos);
  EXPECT_LT(summary.min_diffusion, 1e-4);
  EXPECT_EQ(samples.rows(), 40);  // returned, but flagged
}

TEST(Sgld, SameSeedSameSamplesWhateverTheThreadCount) {
  const GaussianPotential potential(Eigen::Vector3d(1.0, -2.0, 0.5), Precision3());
  Sgld::Options options = GaussianOptions(Sgld::Preconditioner::kDense, 0.3);
  options.num_samples_per_chain = 50;
  options.num_threads = 1;
  Eigen::MatrixXd a, b, c;
  Sgld(options).Sample(potential, Eigen::Vector3d::Zero(), &a);
  options.num_threads = 3;
  Sgld(options).Sample(potential, Eigen::Vector3d::Zero(), &b);
  EXPECT_EQ(a, b);
  options.seed = 43;
  Sgld(options).Sample(potential, Eigen::Vector3d::Zero(), &c);
  EXPECT_FALSE(a == c);
}

TEST(Sgld, ThrowsForABadInitialLatent) {
  const GaussianPotential potential(Eigen::Vector3d::Zero(), Eigen::Matrix3d::Identity());
  const Sgld sgld{Sgld::Options()};
  Eigen::MatrixXd samples;
  EXPECT_THROW(sgld.Sample(potential, Eigen::Vector2d::Zero(), &samples), std::invalid_argument);
  EXPECT_THROW(sgld.Sample(potential, Eigen::Vector3d(NAN, 0, 0), &samples),
               std::invalid_argument);
}

// ---- TrunkPotential ----------------------------------------------------------------

// U, its gradient, minibatches and H_GN are LatentProblem's, tested in
// tests/estimation/fitting/latent_problem_test.cc; the potential only forwards them.
TEST(TrunkPotential, ForwardsItsLatentProblem) {
  const SensorTrunk trunk = testing_util::MakeTinyTrunk(6, 7, 16, 2, 4, 3);
  const TrunkTargets targets =
      testing_util::MakeTargets(trunk, Eigen::Vector4d(0.3, -0.2, 0.1, 0.4), 0.05, 1);
  const LatentProblem problem(trunk, targets, {});
  const TrunkPotential potential(problem);
  EXPECT_EQ(potential.dim(), 4);
  EXPECT_EQ(potential.NumDataTerms(), 42);
  const Eigen::VectorXd z = Eigen::Vector4d(0.1, 0.2, 0.3, 0.4);
  Eigen::VectorXd g, gp;
  EXPECT_EQ(potential.Evaluate(z, &g), problem.Evaluate(z, &gp));
  EXPECT_EQ(g, gp);
  EXPECT_EQ(potential.EvaluateMinibatch(z, {1, 5}, &g), problem.EvaluateMinibatch(z, {1, 5}, &gp));
  EXPECT_EQ(g, gp);
  Eigen::MatrixXd H, Hp;
  ASSERT_TRUE(potential.GaussNewtonHessian(z, &H));
  problem.GaussNewtonHessian(z, &Hp);
  EXPECT_EQ(H, Hp);
}

TEST(Sgld, RunsOnATinyTrunkWithMinibatches) {
  const SensorTrunk trunk = testing_util::MakeTinyTrunk(6, 7, 16, 2, 4, 3);
  const Eigen::Vector4d z_true(0.3, -0.2, 0.1, 0.4);
  const TrunkTargets targets = testing_util::MakeTargets(trunk, z_true, 0.05, 1);
  const LatentProblem problem(trunk, targets, {});
  const TrunkPotential potential(problem);
  Sgld::Options options;
  options.minibatch_size = 21;
  options.num_threads = 2;
  const Sgld sgld(options);
  Eigen::MatrixXd samples;
  Eigen::VectorXd u;
  const Sgld::Summary summary = sgld.Sample(potential, z_true, &samples, &u);
  EXPECT_TRUE(summary.IsSolutionUsable()) << summary.FullReport();
  EXPECT_TRUE(summary.minibatched);
  EXPECT_EQ(summary.minibatch_size, 21);
  EXPECT_EQ(samples.rows(), 100);
  EXPECT_TRUE(samples.allFinite());
  EXPECT_TRUE(u.allFinite());
}

// The same potential without DataTerms: the control variate then evaluates each
// minibatch at the anchor too.
class WithoutDataTerms : public LatentPotential {
 public:
  explicit WithoutDataTerms(const LatentPotential& inner) : inner_(&inner) {}
  int dim() const override { return inner_->dim(); }
  double Evaluate(const Eigen::VectorXd& z, Eigen::VectorXd* gradient) const override {
    return inner_->Evaluate(z, gradient);
  }
  int NumDataTerms() const override { return inner_->NumDataTerms(); }
  double EvaluateMinibatch(const Eigen::VectorXd& z, const std::vector<int>& indices,
                           Eigen::VectorXd* gradient) const override {
    return inner_->EvaluateMinibatch(z, indices, gradient);
  }
  bool GaussNewtonHessian(const Eigen::VectorXd& z, Eigen::MatrixXd* hessian) const override {
    return inner_->GaussNewtonHessian(z, hessian);
  }

 private:
  const LatentPotential* inner_;
};

TEST(Sgld, ControlVariateIsTheSameEstimateWithOrWithoutStoredDataTerms) {
  const SensorTrunk trunk = testing_util::MakeTinyTrunk(6, 7, 16, 2, 4, 3);
  const Eigen::Vector4d z_true(0.3, -0.2, 0.1, 0.4);
  const TrunkTargets targets = testing_util::MakeTargets(trunk, z_true, 0.05, 1);
  LatentProblem::Options problem_options;
  problem_options.precision = LatentProblem::Precision::kDouble;
  const LatentProblem problem(trunk, targets, problem_options);
  const TrunkPotential potential(problem);
  const WithoutDataTerms generic(potential);
  Sgld::Options options;
  options.minibatch_size = 10;
  options.num_threads = 1;
  const Sgld sgld(options);
  Eigen::MatrixXd stored, recomputed;
  Eigen::VectorXd u_stored, u_recomputed;
  const Sgld::Summary a = sgld.Sample(potential, z_true, &stored, &u_stored);
  const Sgld::Summary b = sgld.Sample(generic, z_true, &recomputed, &u_recomputed);
  ASSERT_TRUE(a.IsSolutionUsable()) << a.FullReport();
  ASSERT_TRUE(b.IsSolutionUsable()) << b.FullReport();
  EXPECT_TRUE(a.control_variate);
  EXPECT_TRUE(b.control_variate);
  ASSERT_EQ(stored.rows(), recomputed.rows());
  // The same draws and batches; only the rounding of the anchor's terms differs.
  EXPECT_LT((stored - recomputed).cwiseAbs().maxCoeff(), 1e-8);
  EXPECT_LT((u_stored - u_recomputed).cwiseAbs().maxCoeff(), 1e-8 * u_stored.cwiseAbs().maxCoeff());
  // Without the control variate the chains are others.
  options.control_variate = false;
  Eigen::MatrixXd plain;
  const Sgld::Summary c = Sgld(options).Sample(potential, z_true, &plain);
  EXPECT_FALSE(c.control_variate);
  EXPECT_GT((stored - plain).cwiseAbs().maxCoeff(), 1e-6);
}

}  // namespace
}  // namespace tactfunc
