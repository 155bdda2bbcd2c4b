// Copyright 2026 The tactfunc Authors.
#include "models/trunk/meta_sgd.h"

#include <cmath>
#include <sstream>
#include <stdexcept>
#include <vector>

namespace tactfunc {

bool MetaSgd::Options::IsValid(std::string* error) const {
  std::ostringstream message;
  if (inner_steps < 0) {
    message << "inner_steps must be >= 0, found " << inner_steps;
  } else if (!(latent_l2_weight >= 0.0) || !std::isfinite(latent_l2_weight)) {
    message << "latent_l2_weight must be finite and >= 0, found " << latent_l2_weight;
  } else {
    return true;
  }
  if (error != nullptr) *error = "MetaSgd::Options::" + message.str();
  return false;
}

MetaSgd::MetaSgd(const Options& options) : options_(options) {
  std::string error;
  if (!options_.IsValid(&error)) throw std::invalid_argument(error);
}

namespace {

template <typename Scalar>
void CheckAlpha(const LatentModulatedSiren& siren,
                const LatentModulatedSiren::VectorX<Scalar>& alpha) {
  if (alpha.size() != siren.latent_dim()) {
    throw std::invalid_argument(
        "MetaSgd: alpha must have latent_dim = " + std::to_string(siren.latent_dim()) +
        " entries, found " + std::to_string(alpha.size()));
  }
}

}  // namespace

template <typename Scalar>
MetaSgd::VectorX<Scalar> MetaSgd::FitLatent(const LatentModulatedSiren& siren,
                                            const MatrixX<Scalar>& coords,
                                            const MatrixX<Scalar>& targets,
                                            const VectorX<Scalar>& weights,
                                            const VectorX<Scalar>& alpha,
                                            Scalar* loss) const {
  const VectorX<Scalar> z = InnerLoop<Scalar>(siren, coords, targets, weights, alpha,
                                              siren.StartLatent<Scalar>(coords, targets, weights),
                                              options_.inner_steps);
  if (loss != nullptr) *loss = siren.Loss<Scalar>(coords, z, targets, weights);
  return z;
}

template <typename Scalar>
MetaSgd::VectorX<Scalar> MetaSgd::InnerLoop(const LatentModulatedSiren& siren,
                                            const MatrixX<Scalar>& coords,
                                            const MatrixX<Scalar>& targets,
                                            const VectorX<Scalar>& weights,
                                            const VectorX<Scalar>& alpha,
                                            const VectorX<Scalar>& z0, int steps,
                                            MatrixX<Scalar>* outputs_at_start) const {
  CheckAlpha(siren, alpha);
  if (z0.size() != siren.latent_dim() || steps < 0) {
    throw std::invalid_argument("MetaSgd::InnerLoop: expected a start of latent_dim = " +
                                std::to_string(siren.latent_dim()) +
                                " entries and steps >= 0, found " + std::to_string(z0.size()) +
                                " entries and " + std::to_string(steps) + " steps");
  }
  const Scalar two_lambda = static_cast<Scalar>(2.0 * options_.latent_l2_weight);
  VectorX<Scalar> z = z0;
  VectorX<Scalar> g;
  if (outputs_at_start != nullptr && steps == 0) *outputs_at_start = siren.Forward<Scalar>(coords, z);
  for (int k = 0; k < steps; ++k) {
    if (k == 0 && outputs_at_start != nullptr) {
      siren.LossGradientAndOutputs<Scalar>(coords, z, targets, weights, &g, nullptr,
                                           outputs_at_start);
    } else {
      siren.LossAndGradient<Scalar>(coords, z, targets, weights, &g, nullptr);
    }
    g += two_lambda * z;
    z -= alpha.cwiseProduct(g);
  }
  return z;
}

template <typename Scalar>
MetaSgd::Result<Scalar> MetaSgd::OuterLossAndGradient(
    const LatentModulatedSiren& siren, const MatrixX<Scalar>& coords,
    const MatrixX<Scalar>& targets, const VectorX<Scalar>& weights,
    const VectorX<Scalar>& alpha, const MatrixX<Scalar>* outer_targets) const {
  CheckAlpha(siren, alpha);
  if (outer_targets != nullptr && (outer_targets->rows() != targets.rows() ||
                                   outer_targets->cols() != targets.cols())) {
    throw std::invalid_argument(
        "MetaSgd::OuterLossAndGradient: outer_targets must be " +
        std::to_string(targets.rows()) + " x " + std::to_string(targets.cols()) +
        " like targets, found " + std::to_string(outer_targets->rows()) + " x " +
        std::to_string(outer_targets->cols()));
  }
  const int steps = options_.inner_steps;
  const Scalar two_lambda = static_cast<Scalar>(2.0 * options_.latent_l2_weight);
  Result<Scalar> result;

  // Inner loop, keeping every z_k and g_k for the reverse pass, and (for the exact
  // gradient) the passes at z_k on tapes, which its Hessian-vector products read
  // instead of repeating them.
  std::vector<VectorX<Scalar>> z(steps + 1), g(steps);
  std::vector<LatentModulatedSiren::Tape<Scalar>> tapes(options_.first_order ? 0 : steps);
  // The start (zero, or the readout branch's projection; a frozen branch makes it
  // independent of the trained parameters, else its dependence is not differentiated).
  z[0] = siren.StartLatent<Scalar>(coords, targets, weights);
  for (int k = 0; k < steps; ++k) {
    const Scalar loss =
        options_.first_order
            ? siren.LossAndGradient<Scalar>(coords, z[k], targets, weights, &g[k], nullptr)
            : siren.LossAndGradient<Scalar>(coords, z[k], targets, weights, &g[k], nullptr,
                                            &tapes[k]);
    if (k == 0) result.loss_at_zero = loss;
    g[k] += two_lambda * z[k];
    z[k + 1] = z[k] - alpha.cwiseProduct(g[k]);
  }

  // Outer loss and its partial derivatives at z_K.
  VectorX<Scalar> v;  // dL_out / dz_k, running backwards
  result.loss = siren.LossAndGradient<Scalar>(
      coords, z[steps], outer_targets != nullptr ? *outer_targets : targets, weights, &v,
      &result.dL_dtheta);
  if (steps == 0) result.loss_at_zero = result.loss;
  result.latent = z[steps];
  result.dL_dalpha = VectorX<Scalar>::Zero(siren.latent_dim());

  VectorX<Scalar> Hv_z, Hv_theta;
  for (int k = steps - 1; k >= 0; --k) {
    result.dL_dalpha -= v.cwiseProduct(g[k]);
    if (options_.first_order) continue;
    const VectorX<Scalar> u = alpha.cwiseProduct(v);
    siren.HessianProduct<Scalar>(tapes[k], nullptr, u, &Hv_z, &Hv_theta);
    result.dL_dtheta -= Hv_theta;
    if (k > 0) v -= Hv_z + two_lambda * u;  // z_0 = 0 is a constant
  }
  return result;
}

#define TACTFUNC_INSTANTIATE_META_SGD(S)                                 \
  template MetaSgd::Result<S> MetaSgd::OuterLossAndGradient<S>(          \
      const LatentModulatedSiren&, const MatrixX<S>&, const MatrixX<S>&, \
      const VectorX<S>&, const VectorX<S>&, const MatrixX<S>*) const;    \
  template MetaSgd::VectorX<S> MetaSgd::FitLatent<S>(                    \
      const LatentModulatedSiren&, const MatrixX<S>&, const MatrixX<S>&, \
      const VectorX<S>&, const VectorX<S>&, S*) const;                  \
  template MetaSgd::VectorX<S> MetaSgd::InnerLoop<S>(                    \
      const LatentModulatedSiren&, const MatrixX<S>&, const MatrixX<S>&, \
      const VectorX<S>&, const VectorX<S>&, const VectorX<S>&, int, MatrixX<S>*) const;

TACTFUNC_INSTANTIATE_META_SGD(float)
TACTFUNC_INSTANTIATE_META_SGD(double)
#undef TACTFUNC_INSTANTIATE_META_SGD

}  // namespace tactfunc
