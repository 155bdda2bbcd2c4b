// Copyright 2026 The tactfunc Authors.
#include "models/pose/pose_model_provenance.h"

#include <cmath>
#include <stdexcept>

#include "nlohmann/json.hpp"

namespace tactfunc {
namespace {

using Json = nlohmann::json;

Json NumberOrNull(double value) { return std::isfinite(value) ? Json(value) : Json(nullptr); }

// Reads the fields of one info object, throwing on a field of the wrong type.
class FieldReader {
 public:
  FieldReader(const Json& object, const std::string& source)
      : object_(object), source_(source) {}

  const Json* Find(const std::string& name) const {
    const auto it = object_.find(name);
    return it == object_.end() ? nullptr : &*it;
  }

  [[noreturn]] void Fail(const std::string& name, const std::string& expected,
                         const Json& got) const {
    throw std::invalid_argument("pose model '" + source_ + "': info field '" + name +
                                "': expected " + expected + ", got " + got.type_name() + " " +
                                got.dump());
  }

  void String(const std::string& name, std::string* out) const {
    const Json* v = Find(name);
    if (v == nullptr) return;
    if (!v->is_string()) Fail(name, "a string", *v);
    *out = v->get<std::string>();
  }
  // null reads as NaN (a non-finite figure is written as null).
  void Double(const std::string& name, double* out) const {
    const Json* v = Find(name);
    if (v == nullptr) return;
    if (v->is_null()) {
      *out = std::numeric_limits<double>::quiet_NaN();
      return;
    }
    if (!v->is_number()) Fail(name, "a number", *v);
    *out = v->get<double>();
  }
  void Int64(const std::string& name, std::int64_t* out) const {
    const Json* v = Find(name);
    if (v == nullptr) return;
    if (!v->is_number_integer()) Fail(name, "an integer", *v);
    *out = v->get<std::int64_t>();
  }
  template <typename T>
  void Optional(const std::string& name, std::optional<T>* out) const {
    const Json* v = Find(name);
    if (v == nullptr) return;
    if constexpr (std::is_floating_point_v<T>) {
      if (!v->is_number()) Fail(name, "a number", *v);
    } else if constexpr (std::is_unsigned_v<T>) {
      if (!v->is_number_unsigned() ||
          v->get<std::uint64_t>() > std::numeric_limits<T>::max()) {
        Fail(name, "an unsigned integer of at most " +
                       std::to_string(std::numeric_limits<T>::max()), *v);
      }
    } else {
      if (!v->is_number_integer()) Fail(name, "an integer", *v);
    }
    *out = v->get<T>();
  }
  void TrainTest(const std::string& name, PoseModelProvenance::TrainTest* out) const {
    const Json* v = Find(name);
    if (v == nullptr) return;
    if (!v->is_object()) Fail(name, "an object {train, test}", *v);
    const FieldReader inner(*v, source_);
    try {
      inner.Double("train", &out->train);
      inner.Double("test", &out->test);
    } catch (const std::invalid_argument&) {
      Fail(name, "an object {train, test} of numbers or null", *v);
    }
  }

 private:
  const Json& object_;
  const std::string& source_;
};

}  // namespace

std::string PoseModelProvenance::ToJson() const {
  Json info = {{"provenance_version", version},
               {"sensor", sensor},
               {"functaset", functaset},
               {"train_samples", train_samples},
               {"latents", latents},
               {"latent_map", latent_map},
               {"calibration_samples", calibration_samples},
               {"posterior_sigma", posterior_sigma},
               {"calibration_tools", calibration_tools},
               {"excluded_tools", excluded_tools},
               {"final_loss", NumberOrNull(final_loss)},
               {"termination", termination},
               {"rmse_mm", {{"train", NumberOrNull(rmse_mm.train)}, {"test", NumberOrNull(rmse_mm.test)}}},
               {"rmse_deg",
                {{"train", NumberOrNull(rmse_deg.train)}, {"test", NumberOrNull(rmse_deg.test)}}}};
  if (model_checksum) info["model_checksum"] = *model_checksum;
  if (epochs) info["epochs"] = *epochs;
  if (batch) info["batch"] = *batch;
  if (learning_rate) info["learning_rate"] = *learning_rate;
  if (seed) info["seed"] = *seed;
  if (refit_sigma > 0) info["refit_sigma"] = refit_sigma;
  return info.dump();
}

PoseModelProvenance PoseModelProvenance::FromJson(const std::string& json,
                                                  const std::string& source) {
  const Json info = Json::parse(json, nullptr, false);
  if (!info.is_object()) {
    throw std::invalid_argument("pose model '" + source +
                                "': info: expected a JSON object, got '" +
                                json.substr(0, 80) + "'");
  }
  const FieldReader read(info, source);
  PoseModelProvenance p;
  p.version = 0;
  if (const Json* v = read.Find("provenance_version")) {
    if (!v->is_number_integer()) read.Fail("provenance_version", "an integer", *v);
    p.version = v->get<int>();
    if (p.version < 0 || p.version > kVersion) {
      read.Fail("provenance_version", "0 to " + std::to_string(kVersion), *v);
    }
  }
  read.String("sensor", &p.sensor);
  read.String("functaset", &p.functaset);
  read.Optional("model_checksum", &p.model_checksum);
  read.String("latents", &p.latents);
  if (read.Find("latent_map") != nullptr) {
    read.String("latent_map", &p.latent_map);
  } else if (p.latents.rfind("refit ", 0) == 0) {
    p.latent_map = p.latents.substr(6);  // an info of before "latent_map"
  }
  read.Double("posterior_sigma", &p.posterior_sigma);
  if (!(std::isfinite(p.posterior_sigma) && p.posterior_sigma > 0)) p.posterior_sigma = 0;
  read.Double("refit_sigma", &p.refit_sigma);
  if (!(std::isfinite(p.refit_sigma) && p.refit_sigma > 0)) p.refit_sigma = 0;
  read.Int64("train_samples", &p.train_samples);
  read.Int64("calibration_samples", &p.calibration_samples);
  read.String("calibration_tools", &p.calibration_tools);
  read.String("excluded_tools", &p.excluded_tools);
  read.Optional("epochs", &p.epochs);
  read.Optional("batch", &p.batch);
  read.Optional("learning_rate", &p.learning_rate);
  read.Optional("seed", &p.seed);
  read.Double("final_loss", &p.final_loss);
  read.String("termination", &p.termination);
  read.TrainTest("rmse_mm", &p.rmse_mm);
  read.TrainTest("rmse_deg", &p.rmse_deg);
  return p;
}

}  // namespace tactfunc
