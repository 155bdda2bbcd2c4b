// Copyright 2026 The tactfunc Authors.
#include "samplers/laplace.h"

#include <chrono>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <string>
#include <utility>

#include <Eigen/Cholesky>
#include <boost/random/mersenne_twister.hpp>
#include <boost/random/normal_distribution.hpp>

#include "models/core/internal/elapsed.h"

namespace tactfunc {
namespace {

using internal::MsSince;

}  // namespace

const char* ToString(LaplaceTermination termination) {
  switch (termination) {
    case LaplaceTermination::kSuccess:
      return "SUCCESS";
    case LaplaceTermination::kIllConditioned:
      return "ILL_CONDITIONED";
    case LaplaceTermination::kNotPositiveDefinite:
      return "NOT_POSITIVE_DEFINITE";
    case LaplaceTermination::kFitFailed:
      return "FIT_FAILED";
  }
  return "UNKNOWN";
}

bool LaplaceSampler::Options::IsValid(std::string* error) const {
  std::ostringstream m;
  if (num_samples < 1) {
    m << "LaplaceSampler::Options::num_samples must be >= 1, got " << num_samples;
  } else if (!(min_relative_pivot > 0 && min_relative_pivot < 1)) {
    m << "LaplaceSampler::Options::min_relative_pivot must be in (0, 1), got "
      << min_relative_pivot;
  } else {
    return true;
  }
  if (error != nullptr) *error = m.str();
  return false;
}

LaplaceSampler::LaplaceSampler(const Options& options) : options_(options) {
  std::string error;
  if (!options_.IsValid(&error)) throw std::invalid_argument(error);
}

std::string LaplaceSampler::Summary::BriefReport() const {
  std::ostringstream s;
  s << "Laplace: " << ToString(termination_type) << ", " << num_samples
    << " samples (d = " << dim << "), U(mode) " << potential_at_mode << ", log det Sigma "
    << log_det_covariance << ", pivot ratio " << min_relative_pivot << ", " << total_time_ms
    << " ms";
  return s.str();
}

std::string LaplaceSampler::Summary::FullReport() const {
  std::ostringstream s;
  s << BriefReport() << "\n";
  if (!message.empty()) s << "  " << message << "\n";
  if (fit_ran) s << "  fit: " << fit_summary.BriefReport() << "\n";
  s << "  time: fit " << fit_time_ms << " ms, Hessian " << hessian_time_ms << " ms, factor "
    << factor_time_ms << " ms, samples " << sample_time_ms << " ms\n";
  return s.str();
}

namespace {

void CheckSampleArguments(int d, const Eigen::VectorXd& mode, const Eigen::MatrixXd* samples,
                          const char* where) {
  if (samples == nullptr) {
    throw std::invalid_argument(std::string("LaplaceSampler::") + where +
                                ": samples must not be null");
  }
  if (mode.size() != d || !mode.allFinite()) {
    throw std::invalid_argument(std::string("LaplaceSampler::") + where +
                                ": expected a finite mode of size " + std::to_string(d) +
                                ", got size " + std::to_string(mode.size()) +
                                (mode.allFinite() ? "" : " with non-finite entries"));
  }
}

}  // namespace

LaplaceSampler::Summary LaplaceSampler::Sample(const LatentPotential& potential,
                                               const Eigen::VectorXd& mode,
                                               Eigen::MatrixXd* samples) const {
  const auto start = std::chrono::steady_clock::now();
  const int d = potential.dim();
  CheckSampleArguments(d, mode, samples, "Sample");
  Summary summary;
  summary.dim = d;
  summary.mode = mode;
  samples->resize(0, d);
  const auto t = std::chrono::steady_clock::now();
  Eigen::MatrixXd hessian;
  const bool have_hessian =
      potential.PotentialAndGaussNewtonHessian(mode, &summary.potential_at_mode, &hessian);
  summary.hessian_time_ms = MsSince(t);
  if (!have_hessian) {
    summary.termination_type = LaplaceTermination::kNotPositiveDefinite;
    summary.message = "the potential provides no Gauss-Newton Hessian";
    summary.total_time_ms = MsSince(start);
    return summary;
  }
  return FromHessian(start, hessian, std::move(summary), samples);
}

LaplaceSampler::Summary LaplaceSampler::SampleWithHessian(const Eigen::VectorXd& mode,
                                                          double potential_at_mode,
                                                          const Eigen::MatrixXd& hessian,
                                                          Eigen::MatrixXd* samples) const {
  const auto start = std::chrono::steady_clock::now();
  const int d = static_cast<int>(hessian.rows());
  if (hessian.cols() != d || d == 0) {
    throw std::invalid_argument("LaplaceSampler::SampleWithHessian: expected a square, non-empty "
                                "Hessian, got " + std::to_string(hessian.rows()) + " x " +
                                std::to_string(hessian.cols()));
  }
  CheckSampleArguments(d, mode, samples, "SampleWithHessian");
  Summary summary;
  summary.dim = d;
  summary.mode = mode;
  summary.potential_at_mode = potential_at_mode;
  samples->resize(0, d);
  return FromHessian(start, hessian, std::move(summary), samples);
}

LaplaceSampler::Summary LaplaceSampler::SampleAtFit(const LatentPotential& potential,
                                                    const LatentFitter::Summary& fit,
                                                    const Eigen::VectorXd& mode,
                                                    Eigen::MatrixXd* samples) const {
  return fit.gauss_newton_hessian.size() > 0
             ? SampleWithHessian(mode, fit.final_cost, fit.gauss_newton_hessian, samples)
             : Sample(potential, mode, samples);
}

LaplaceSampler::Summary LaplaceSampler::FromHessian(
    std::chrono::steady_clock::time_point start, const Eigen::MatrixXd& hessian,
    Summary summary, Eigen::MatrixXd* samples) const {
  const int d = summary.dim;
  const Eigen::VectorXd& mode = summary.mode;
  auto t = std::chrono::steady_clock::now();
  if (!hessian.allFinite()) {
    summary.termination_type = LaplaceTermination::kNotPositiveDefinite;
    summary.message = "the Gauss-Newton Hessian at the mode has non-finite entries";
    summary.total_time_ms = MsSince(start);
    return summary;
  }

  t = std::chrono::steady_clock::now();
  const Eigen::LDLT<Eigen::MatrixXd> ldlt(hessian);
  const Eigen::VectorXd pivots = ldlt.vectorD();
  const double max_pivot = pivots.maxCoeff();
  const double min_pivot = pivots.minCoeff();
  summary.min_relative_pivot = max_pivot > 0 ? min_pivot / max_pivot : 0.0;
  std::ostringstream m;
  if (ldlt.info() != Eigen::Success || !(min_pivot > 0) || !std::isfinite(max_pivot)) {
    summary.termination_type = LaplaceTermination::kNotPositiveDefinite;
    m << "the Gauss-Newton Hessian is not positive definite (LDLT pivots in [" << min_pivot
      << ", " << max_pivot << "])";
  } else if (summary.min_relative_pivot < options_.min_relative_pivot) {
    summary.termination_type = LaplaceTermination::kIllConditioned;
    m << "the Gauss-Newton Hessian is numerically singular: smallest / largest LDLT pivot "
      << summary.min_relative_pivot << " < min_relative_pivot " << options_.min_relative_pivot
      << " (a larger prior precision 1 / sigma_z^2 regularises it)";
  }
  if (!m.str().empty()) {
    summary.message = m.str();
    summary.factor_time_ms = MsSince(t);
    summary.total_time_ms = MsSince(start);
    return summary;
  }
  summary.covariance = ldlt.solve(Eigen::MatrixXd::Identity(d, d));
  summary.covariance = 0.5 * (summary.covariance + summary.covariance.transpose()).eval();
  summary.log_det_covariance = -pivots.array().log().sum();
  summary.factor_time_ms = MsSince(t);

  // z = mode + P^T L^-T D^-1/2 xi has covariance P^T L^-T D^-1 L^-1 P = H^-1.
  t = std::chrono::steady_clock::now();
  const int n = options_.num_samples;
  boost::random::mt19937_64 rng(options_.seed);
  boost::random::normal_distribution<double> normal(0.0, 1.0);
  Eigen::MatrixXd xi(d, n);
  for (int i = 0; i < n; ++i) {
    for (int k = 0; k < d; ++k) xi(k, i) = normal(rng);
  }
  xi = pivots.cwiseSqrt().cwiseInverse().asDiagonal() * xi;
  ldlt.matrixU().solveInPlace(xi);
  xi = ldlt.transpositionsP().transpose() * xi;
  *samples = (xi.colwise() + mode).transpose();
  summary.sample_time_ms = MsSince(t);
  summary.num_samples = n;
  summary.termination_type = LaplaceTermination::kSuccess;
  summary.message = "drew " + std::to_string(n) + " samples from N(mode, H^-1)";
  summary.total_time_ms = MsSince(start);
  return summary;
}

LaplaceSampler::Summary LaplaceSampler::Sample(const LatentProblem& problem,
                                               const LatentFitter& fitter,
                                               Eigen::MatrixXd* samples) const {
  const auto start = std::chrono::steady_clock::now();
  const TrunkPotential potential(problem);
  Eigen::VectorXd mode;
  LatentFitter::Summary fit = fitter.Fit(problem, &mode);
  const double fit_ms = MsSince(start);
  if (!fit.IsSolutionUsable()) {
    Summary summary;
    summary.dim = potential.dim();
    summary.fit_ran = true;
    summary.fit_summary = fit;
    summary.fit_time_ms = fit_ms;
    summary.termination_type = LaplaceTermination::kFitFailed;
    summary.message = "the latent fit gave no usable mode: " + fit.message;
    if (samples != nullptr) samples->resize(0, potential.dim());
    summary.total_time_ms = MsSince(start);
    return summary;
  }
  Summary summary = SampleAtFit(potential, fit, mode, samples);
  summary.fit_ran = true;
  summary.fit_summary = std::move(fit);
  summary.fit_time_ms = fit_ms;
  summary.total_time_ms = MsSince(start);
  return summary;
}

}  // namespace tactfunc
