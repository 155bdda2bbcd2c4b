// Copyright 2026 The tactfunc Authors.
#include "samplers/step_size_schedule.h"

#include <cmath>
#include <stdexcept>

namespace tactfunc {

bool StepSizeSchedule::Options::IsValid(std::string* error) const {
  if (!(initial > 0.0) || !std::isfinite(initial)) {
    *error = "StepSizeSchedule::Options::initial must be > 0 and finite, got " +
             std::to_string(initial);
    return false;
  }
  if (type == Type::kPolynomial) {
    if (!(decay_steps > 0.0) || !std::isfinite(decay_steps)) {
      *error = "StepSizeSchedule::Options::decay_steps must be > 0, got " +
               std::to_string(decay_steps);
      return false;
    }
    if (!(gamma > 0.5 && gamma <= 1.0)) {
      *error = "StepSizeSchedule::Options::gamma must be in (0.5, 1], got " +
               std::to_string(gamma);
      return false;
    }
  }
  return true;
}

StepSizeSchedule::StepSizeSchedule(const Options& options) : options_(options) {
  std::string error;
  if (!options_.IsValid(&error)) throw std::invalid_argument(error);
}

double StepSizeSchedule::operator()(long t) const {
  if (t < 0) t = 0;
  switch (options_.type) {
    case Type::kConstant:
      return options_.initial;
    case Type::kPolynomial:
      return options_.initial *
             std::pow(1.0 + static_cast<double>(t) / options_.decay_steps,
                      -options_.gamma);
  }
  return options_.initial;
}

const char* ToString(StepSizeSchedule::Type type) {
  switch (type) {
    case StepSizeSchedule::Type::kConstant:
      return "constant";
    case StepSizeSchedule::Type::kPolynomial:
      return "polynomial";
  }
  return "unknown";
}

}  // namespace tactfunc
