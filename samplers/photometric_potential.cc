// Copyright 2026 The tactfunc Authors.
#include "samplers/photometric_potential.h"

#include <cmath>
#include <stdexcept>
#include <string>

namespace tactfunc {

PhotometricPotential::PhotometricPotential(const PhotometricTrunk& trunk,
                                           const TrunkTargets& targets, double sigma,
                                           double sigma_z,
                                           const PhotometricTrunk::Markers* markers)
    : trunk_(&trunk), markers_(markers), sigma_(sigma), sigma_z_(sigma_z) {
  const int channels = trunk.channels();
  const Eigen::Index n = static_cast<Eigen::Index>(trunk.options().rows) * trunk.options().cols;
  CheckTargetsShape(targets, trunk.options().rows, trunk.options().cols, channels,
                    "PhotometricPotential");
  if (!(sigma > 0) || !std::isfinite(sigma) || !(sigma_z > 0) || !std::isfinite(sigma_z)) {
    throw std::invalid_argument("PhotometricPotential: sigma and sigma_z must be finite and > 0, "
                                "found " + std::to_string(sigma) + " and " +
                                std::to_string(sigma_z));
  }
  for (Eigen::Index j = 0; j < n; ++j) {
    const float w = targets.weights.size() == 0 ? 1.0f : targets.weights[j];
    if (!(w >= 0) || !std::isfinite(w)) {
      throw std::invalid_argument("PhotometricPotential: weight " + std::to_string(j) +
                                  " is " + std::to_string(w) + ", expected finite and >= 0");
    }
    if (w > 0) pixels_.push_back(static_cast<int>(j));
  }
  const Eigen::Index m = static_cast<Eigen::Index>(pixels_.size());
  values_.resize(m, channels);
  weights_.resize(m);
  for (Eigen::Index i = 0; i < m; ++i) {
    values_.row(i) = targets.values.row(pixels_[i]);
    weights_[i] = targets.weights.size() == 0 ? 1.0f : targets.weights[pixels_[i]];
  }
}

double PhotometricPotential::EvaluateOn(const Eigen::VectorXd& z, const std::vector<int>& pixels,
                                        const Eigen::MatrixXf& values,
                                        const Eigen::VectorXf& weights, double scale,
                                        Eigen::VectorXd* gradient) const {
  if (z.size() != dim()) {
    throw std::invalid_argument("PhotometricPotential: expected a latent of " +
                                std::to_string(dim()) + " values, found " +
                                std::to_string(z.size()));
  }
  double u = 0.5 * z.squaredNorm() / (sigma_z_ * sigma_z_);
  if (gradient != nullptr) *gradient = z / (sigma_z_ * sigma_z_);
  if (pixels.empty()) return u;
  double weight_sum = 0;
  for (Eigen::Index i = 0; i < weights.size(); ++i) weight_sum += weights[i];
  // LossAndGradient's loss is sum_j w_j ||y_j - t_j||^2 / (C sum_j w_j).
  const double to_u = scale * values.cols() * weight_sum / (2.0 * sigma_ * sigma_);
  Eigen::VectorXf dz;
  const double loss = trunk_->LossAndGradient<float>(
      pixels, z.cast<float>(), values, weights, gradient != nullptr ? &dz : nullptr, nullptr,
      nullptr, nullptr, markers_);
  u += to_u * loss;
  if (gradient != nullptr) *gradient += to_u * dz.cast<double>();
  return u;
}

double PhotometricPotential::Evaluate(const Eigen::VectorXd& z,
                                      Eigen::VectorXd* gradient) const {
  return EvaluateOn(z, pixels_, values_, weights_, 1.0, gradient);
}

double PhotometricPotential::EvaluateMinibatch(const Eigen::VectorXd& z,
                                               const std::vector<int>& indices,
                                               Eigen::VectorXd* gradient) const {
  const Eigen::Index n = static_cast<Eigen::Index>(indices.size());
  std::vector<int> pixels(indices.size());
  Eigen::MatrixXf values(n, values_.cols());
  Eigen::VectorXf weights(n);
  for (Eigen::Index i = 0; i < n; ++i) {
    const int term = indices[static_cast<std::size_t>(i)];
    if (term < 0 || term >= NumDataTerms()) {
      throw std::invalid_argument("PhotometricPotential: data term " + std::to_string(term) +
                                  " is outside [0, " + std::to_string(NumDataTerms()) + ")");
    }
    pixels[static_cast<std::size_t>(i)] = pixels_[term];
    values.row(i) = values_.row(term);
    weights[i] = weights_[term];
  }
  const double scale = n == 0 ? 0.0 : static_cast<double>(NumDataTerms()) / n;
  return EvaluateOn(z, pixels, values, weights, scale, gradient);
}

bool PhotometricPotential::GaussNewtonHessian(const Eigen::VectorXd& z,
                                              Eigen::MatrixXd* hessian) const {
  return HessianPass(z, nullptr, hessian);
}

bool PhotometricPotential::PotentialAndGaussNewtonHessian(const Eigen::VectorXd& z,
                                                          double* potential,
                                                          Eigen::MatrixXd* hessian) const {
  return HessianPass(z, potential, hessian);
}

bool PhotometricPotential::HessianPass(const Eigen::VectorXd& z, double* potential,
                                       Eigen::MatrixXd* hessian) const {
  if (z.size() != dim()) {
    throw std::invalid_argument("PhotometricPotential: expected a latent of " +
                                std::to_string(dim()) + " values, found " +
                                std::to_string(z.size()));
  }
  // The trunk's exact Jacobian, transposed (pixel-major columns i C + c), each column
  // scaled by sqrt(w_i) / sigma: H = J^T J + I / sigma_z^2.
  Eigen::MatrixXf y, JT;
  trunk_->ForwardAndLatentJacobian<float>(pixels_, z.cast<float>(),
                                          potential != nullptr ? &y : nullptr, &JT, markers_,
                                          JacobianLayout::kOutputColumns);
  const Eigen::Index channels = values_.cols();
  if (potential != nullptr) {
    // U = sum_i w_i ||y_i - t_i||^2 / (2 sigma^2) + ||z||^2 / (2 sigma_z^2), as Evaluate.
    double data = 0;
    for (Eigen::Index i = 0; i < values_.rows(); ++i) {
      double e2 = 0;
      for (Eigen::Index c = 0; c < channels; ++c) {
        const double e = static_cast<double>(y(i, c)) - static_cast<double>(values_(i, c));
        e2 += e * e;
      }
      data += static_cast<double>(weights_[i]) * e2;
    }
    *potential = 0.5 * z.squaredNorm() / (sigma_z_ * sigma_z_) + data / (2.0 * sigma_ * sigma_);
  }
  for (Eigen::Index i = 0; i < values_.rows(); ++i) {
    const float scale = std::sqrt(weights_[i]) / static_cast<float>(sigma_);
    JT.middleCols(i * channels, channels) *= scale;
  }
  if (!JT.allFinite()) return false;
  // Accumulated in double (the sum runs over thousands of outputs), one triangle.
  const Eigen::MatrixXd JTd = JT.cast<double>();
  hessian->setZero(dim(), dim());
  hessian->selfadjointView<Eigen::Lower>().rankUpdate(JTd);
  *hessian = hessian->selfadjointView<Eigen::Lower>();
  hessian->diagonal().array() += 1.0 / (sigma_z_ * sigma_z_);
  return true;
}

}  // namespace tactfunc
