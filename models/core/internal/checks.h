// Copyright 2026 The tactfunc Authors.
//
// What the library's argument checks share: pi, a number as the short text their
// messages quote, and the check that throws std::invalid_argument with its message.
#ifndef TACTFUNC_MODELS_CORE_INTERNAL_CHECKS_H_
#define TACTFUNC_MODELS_CORE_INTERNAL_CHECKS_H_

#include <cstdio>
#include <stdexcept>
#include <string>

namespace tactfunc::internal {

inline constexpr double kPi = 3.14159265358979323846;

// Six significant digits ("%.6g"): 0.001, 1e-08, 3.14159, inf, nan.
inline std::string Num(double value) {
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.6g", value);
  return buffer;
}

inline void Check(bool ok, const std::string& message) {
  if (!ok) throw std::invalid_argument(message);
}

}  // namespace tactfunc::internal

#endif  // TACTFUNC_MODELS_CORE_INTERNAL_CHECKS_H_
