// Copyright 2026 The tactfunc Authors.
//
// Step-size schedules for Langevin samplers.
//
// Stochastic Gradient Langevin Dynamics (Welling & Teh, 2011) takes steps
//   z <- z - eta_t grad U(z) + sqrt(2 eta_t) xi,   xi ~ N(0, I).
// With a constant eta_t the chain samples a slightly biased stationary distribution
// (bias O(eta)); the polynomially decaying schedule
//   eta_t = a (b + t)^(-gamma),   gamma in (0.5, 1],
// satisfies sum eta_t = inf and sum eta_t^2 < inf, so the bias vanishes as t grows.
// Welling & Teh use gamma = 0.55.
#ifndef TACTFUNC_SAMPLERS_STEP_SIZE_SCHEDULE_H_
#define TACTFUNC_SAMPLERS_STEP_SIZE_SCHEDULE_H_

#include <string>

namespace tactfunc {

class StepSizeSchedule {
 public:
  enum class Type {
    kConstant,    // eta_t = initial
    kPolynomial,  // eta_t = initial * (1 + t / decay_steps)^(-gamma)
  };
  struct Options {
    Type type = Type::kConstant;
    // eta_0, in units of latent^2 per unit of U. Must be > 0 and finite.
    double initial = 1e-4;
    // Steps over which the polynomial schedule has decayed by 2^-gamma; it is
    // b = decay_steps in a (b + t)^-gamma written as eta_0 (1 + t/b)^-gamma. Must be > 0.
    double decay_steps = 100.0;
    // Decay exponent, in (0.5, 1] for the Robbins-Monro conditions (Welling & Teh use
    // 0.55).
    double gamma = 0.55;
    bool IsValid(std::string* error) const;
  };

  // Throws std::invalid_argument (with Options::IsValid's message) on bad options.
  explicit StepSizeSchedule(const Options& options);

  // The step size at step t >= 0.
  double operator()(long t) const;

  const Options& options() const { return options_; }

 private:
  Options options_;
};

const char* ToString(StepSizeSchedule::Type type);

}  // namespace tactfunc

#endif  // TACTFUNC_SAMPLERS_STEP_SIZE_SCHEDULE_H_
