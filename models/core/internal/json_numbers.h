// Copyright 2026 The tactfunc Authors.
//
// Numbers from parsed JSON (nlohmann) without undefined behaviour, for the file readers:
// nlohmann's get<int>() of 1e300, or get<float>() of 1e300, is an out-of-range
// conversion. These take a value only if it is a number of the right kind within the
// given bounds, and return false otherwise (the caller names the file and field).
// Private to tactfunc's readers (they link nlohmann_json privately).
#ifndef TACTFUNC_MODELS_CORE_INTERNAL_JSON_NUMBERS_H_
#define TACTFUNC_MODELS_CORE_INTERNAL_JSON_NUMBERS_H_

#include <cmath>
#include <cstdint>
#include <limits>

#include "nlohmann/json.hpp"

namespace tactfunc::internal {

// A JSON integer (not 1.0) in [lo, hi].
inline bool JsonInteger(const nlohmann::json& value, std::int64_t lo, std::int64_t hi,
                        std::int64_t* out) {
  if (value.is_number_unsigned()) {
    const std::uint64_t u = value.get<std::uint64_t>();
    if (u > static_cast<std::uint64_t>(std::numeric_limits<std::int64_t>::max())) return false;
    *out = static_cast<std::int64_t>(u);
  } else if (value.is_number_integer()) {
    *out = value.get<std::int64_t>();
  } else {
    return false;
  }
  return *out >= lo && *out <= hi;
}

// As above, for an int.
inline bool JsonInt(const nlohmann::json& value, int lo, int hi, int* out) {
  std::int64_t v = 0;
  if (!JsonInteger(value, lo, hi, &v)) return false;
  *out = static_cast<int>(v);
  return true;
}

// A finite JSON number in [lo, hi].
inline bool JsonReal(const nlohmann::json& value, double lo, double hi, double* out) {
  if (!value.is_number()) return false;
  *out = value.get<double>();
  return std::isfinite(*out) && *out >= lo && *out <= hi;
}

}  // namespace tactfunc::internal

#endif  // TACTFUNC_MODELS_CORE_INTERNAL_JSON_NUMBERS_H_
