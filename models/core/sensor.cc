// Copyright 2026 The tactfunc Authors.
#include "models/core/sensor.h"

namespace tactfunc {

const char* ToString(SensorKind kind) {
  switch (kind) {
    case SensorKind::kSoftBubble:
      return "bubble";
    case SensorKind::kGelSlim:
      return "gelslim";
  }
  return "unknown";
}

bool SensorKindFromString(const std::string& name, SensorKind* kind) {
  if (name == "bubble" || name == "soft_bubble") {
    *kind = SensorKind::kSoftBubble;
    return true;
  }
  if (name == "gelslim" || name == "gel_slim") {
    *kind = SensorKind::kGelSlim;
    return true;
  }
  return false;
}

int SensorChannels(SensorKind kind) {
  return kind == SensorKind::kSoftBubble ? 1 : 3;
}

}  // namespace tactfunc
