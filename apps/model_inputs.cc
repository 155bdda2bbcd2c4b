// Copyright 2026 The tactfunc Authors.
#include "apps/model_inputs.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <stdexcept>

#include "apps/command.h"
#include "estimation/data/image_io.h"
#include "models/core/internal/elapsed.h"
#include "models/simulator/tool.h"
#include "estimation/posterior/pose_posterior.h"
#include "models/pose/pose_model_provenance.h"

namespace tactfunc::apps {

namespace fs = std::filesystem;

SensorKind InferSensor(const std::string& path, const std::string& flag) {
  if (!fs::is_regular_file(path)) {
    throw DatasetError(flag + " '" + path + "': no such file");
  }
  // From the header alone (no pixel decoded): a frame too large is refused here.
  ImageHeader header;
  try {
    header = ReadImageHeader(path);
  } catch (const DatasetError& e) {
    throw DatasetError(flag + ": " + e.what());
  }
  const bool png = header.format == ImageHeader::Format::kPng;
  if (png && header.bit_depth == 16 && header.channels == 1) return SensorKind::kSoftBubble;
  if (!png || header.bit_depth <= 8) return SensorKind::kGelSlim;
  throw DatasetError(flag + " '" + path +
                     "': cannot infer the sensor: expected a 16-bit 1-channel image (bubble "
                     "depth) or an 8-bit one (gelslim rgb), got " +
                     std::to_string(header.bit_depth) + "-bit with " +
                     std::to_string(header.channels) + " channel(s); give --sensor");
}

Image ReadInput(const std::string& path, SensorKind sensor, const std::string& flag) {
  if (!fs::is_regular_file(path)) throw DatasetError(flag + " '" + path + "': no such file");
  try {
    return ReadImage(path, SensorEncoding(sensor));
  } catch (const DatasetError& e) {
    throw DatasetError(flag + " (" + ToString(sensor) + "): " + e.what());
  }
}

std::string Shape(const Image& image) {
  return std::to_string(image.rows) + "x" + std::to_string(image.cols) + "x" +
         std::to_string(image.channels);
}

bool ParseSensorFlag(const std::string& text, SensorKind* sensor) {
  if (text.empty()) return false;
  if (!SensorKindFromString(text, sensor)) {
    throw UsageError("--sensor: expected bubble or gelslim, got '" + text + "'");
  }
  return true;
}

std::vector<SensorKind> ParseSensorsFlag(const std::string& list) {
  std::vector<SensorKind> sensors;
  for (const std::string& name : SplitList(list)) {
    SensorKind kind;
    if (!SensorKindFromString(name, &kind)) {
      throw UsageError("--sensors: unknown sensor '" + name + "', expected bubble or gelslim");
    }
    if (std::find(sensors.begin(), sensors.end(), kind) == sensors.end()) sensors.push_back(kind);
  }
  return sensors;
}

FramePair ReadFramePair(const std::string& frame_path, const std::string& reference_path,
                        const std::string& sensor_flag, const std::string& sensor_file) {
  FramePair pair;
  if (!sensor_file.empty()) {
    try {
      pair.description = ReadSensorDescriptionFile(sensor_file);
    } catch (const SensorDescriptionError& e) {
      throw DatasetError(std::string("--sensor-file: ") + e.what());
    }
  }
  if (!ParseSensorFlag(sensor_flag, &pair.sensor)) {
    pair.sensor = pair.description ? pair.description->kind : InferSensor(frame_path, "--frame");
  } else if (pair.description && pair.description->kind != pair.sensor) {
    throw UsageError("--sensor " + sensor_flag + ": --sensor-file '" + sensor_file +
                     "' describes a " + SensorKindDescriptionName(pair.description->kind) +
                     " sensor");
  }
  pair.frame = ReadInput(frame_path, pair.sensor, "--frame");
  pair.reference = ReadInput(reference_path, pair.sensor, "--reference");
  if (pair.description) {
    try {
      pair.frame = ApplySensorGeometry(pair.frame, *pair.description, sensor_file);
      pair.reference = ApplySensorGeometry(pair.reference, *pair.description, sensor_file);
    } catch (const SensorDescriptionError& e) {
      throw DatasetError("--frame '" + frame_path + "': " + e.what());
    }
  }
  if (!pair.frame.SameShape(pair.reference)) {
    throw DatasetError("--reference '" + reference_path + "' is " + Shape(pair.reference) +
                       " (rows x cols x channels) but --frame '" + frame_path + "' is " +
                       Shape(pair.frame) + "; they must be of the same sensor and size");
  }
  return pair;
}

double DatasetPixelPitch(const std::string& frame_path, SensorKind sensor) {
  std::error_code ec;
  const fs::path root = fs::absolute(frame_path, ec).parent_path().parent_path();
  if (ec || !fs::is_regular_file(root / "dataset.json")) return 0;
  try {
    const Dataset dataset = Dataset::Open(root.string());
    return dataset.has_sensor(sensor) ? dataset.sensor_info(sensor).pixel_pitch_m : 0;
  } catch (const std::exception&) {
    return 0;  // not a dataset we can read: the pitch stays unknown
  }
}

EncodedFrameFit EncodeFrame(const LatentEncoder& encoder, SensorKind sensor,
                            const TrunkTargets& targets,
                            const PhotometricTrunk::Markers* markers) {
  const auto start = std::chrono::steady_clock::now();
  const LatentEncoder::EncodedFrame fitted = encoder.EncodeTargets(sensor, targets, markers);
  EncodedFrameFit out;
  out.ms = internal::MsSince(start);
  out.latent = fitted.latent.cast<double>();
  out.psnr = fitted.psnr;
  return out;
}

std::unique_ptr<LatentEncoder> PhotometricPoseEncoder(const FunctaModel& model,
                                                      const std::string& model_path,
                                                      SensorKind sensor,
                                                      const PoseMlp& pose_model,
                                                      const std::string& pose_model_path) {
  LatentEncoder::Options options;
  options.sensors = {sensor};
  options.strategy = PhotometricLatentMapOfPoseModel(pose_model);
  options.score_targets = false;  // the posterior needs the latent alone
  try {
    return std::make_unique<LatentEncoder>(model, options);
  } catch (const std::invalid_argument& e) {
    throw DatasetError("--pose-model '" + pose_model_path + "' was trained on " +
                       options.strategy + " latents, which the photometric " +
                       ToString(sensor) + " trunk of '" + model_path +
                       "' does not fit (" + e.what() + ")");
  }
}

FunctasetKnn MakeFunctasetKnn(const Functaset& functaset, SensorKind sensor, bool train_only,
                              const KnnPosterior::Options& options,
                              const std::string& functaset_name) {
  if (!functaset.has_sensor(sensor)) {
    throw DatasetError("--functaset '" + functaset_name + "' has no " + ToString(sensor) +
                       " latents (the knn sampler searches them)");
  }
  const std::optional<Split> split =
      train_only ? std::optional<Split>(Split::kTrain) : std::nullopt;
  const Functaset::LatentMatrix latents = functaset.Latents(sensor, split);
  std::vector<std::optional<SE2d>> poses = KnnPosterior::PosesOf(functaset, sensor, split);
  int labelled = 0;
  for (const auto& pose : poses) labelled += pose.has_value();
  if (labelled == 0) {
    throw DatasetError("--functaset '" + functaset_name + "' has no labelled " +
                       std::string(train_only ? "train-split " : "") + ToString(sensor) +
                       " entries: the knn sampler needs labelled poses");
  }
  // Unlabelled neighbours are skipped, not replaced (estimation/posterior/knn_posterior.h): ask the
  // index for k plus the number of unlabelled entries, so k labelled ones always come back.
  KnnPosterior::Options knn_options = options;
  const int unlabelled = static_cast<int>(poses.size()) - labelled;
  knn_options.search_k =
      std::min<int>(static_cast<int>(poses.size()), std::max(options.k, options.search_k) + unlabelled);
  knn_options.search_k = std::max(knn_options.search_k, knn_options.k);
  FunctasetKnn knn;
  knn.index = BuildKnnIndex(latents, KnnIndexOptions());  // exact
  knn.posterior = std::make_unique<KnnPosterior>(*knn.index, std::move(poses), knn_options);
  knn.size = static_cast<int>(latents.rows());
  return knn;
}

PoseMlp LoadPoseModelFor(const std::string& path, const FunctaModel& model, SensorKind sensor,
                         const std::string& model_path) {
  if (!fs::is_regular_file(path)) throw DatasetError("--pose-model '" + path + "': no such file");
  PoseMlp pose = PoseMlp::Load(path);
  const int latent_dim = TrunkLatentDim(model.Trunk(sensor));
  if (pose.input_dim() != latent_dim) {
    throw DatasetError("--pose-model '" + path + "' takes " + std::to_string(pose.input_dim()) +
                       "-dimensional latents but the " + ToString(sensor) + " trunk of --model '" +
                       model_path + "' has latent dimension " + std::to_string(latent_dim));
  }
  PoseModelProvenance provenance;
  try {
    provenance = PoseModelProvenance::FromJson(pose.info_json(), path);
  } catch (const std::invalid_argument& e) {
    throw DatasetError(std::string("--pose-model: ") + e.what());
  }
  if (!provenance.sensor.empty() && provenance.sensor != ToString(sensor)) {
    throw DatasetError("--pose-model '" + path + "' was trained on " + provenance.sensor +
                       " latents, but the frame is " + ToString(sensor) +
                       " (give --sensor or the matching pose model)");
  }
  if (provenance.model_checksum && *provenance.model_checksum != model.checksum()) {
    char buffer[128];
    std::snprintf(buffer, sizeof(buffer), "0x%08x, but --model has 0x%08x",
                  *provenance.model_checksum, model.checksum());
    throw DatasetError("--pose-model '" + path + "' was trained on latents of model checksum " +
                       buffer + " ('" + model_path + "'): its latent space is another");
  }
  return pose;
}

PoseGenerator LoadPoseGeneratorFor(const std::string& path, const FunctaModel& model,
                                   SensorKind sensor, const std::string& model_path) {
  if (!fs::is_regular_file(path)) throw DatasetError("--generator '" + path + "': no such file");
  PoseGenerator generator = PoseGenerator::Load(path);
  const int latent_dim = TrunkLatentDim(model.Trunk(sensor));
  if (generator.latent_dim() != latent_dim) {
    throw DatasetError("--generator '" + path + "' renders " +
                       std::to_string(generator.latent_dim()) + "-dimensional latents but the " +
                       ToString(sensor) + " trunk of --model '" + model_path +
                       "' has latent dimension " + std::to_string(latent_dim));
  }
  const nlohmann::json info = nlohmann::json::parse(generator.info_json());
  const auto recorded = info.find("model_checksum");
  if (recorded != info.end()) {
    if (!recorded->is_number_unsigned()) {
      throw DatasetError("--generator '" + path +
                         "': field 'info.model_checksum' must be an unsigned integer");
    }
    const std::uint64_t checksum = recorded->get<std::uint64_t>();
    if (checksum != model.checksum()) {
      char buffer[128];
      std::snprintf(buffer, sizeof(buffer), "0x%08llx, but --model has 0x%08x",
                    static_cast<unsigned long long>(checksum), model.checksum());
      throw DatasetError("--generator '" + path + "' was trained through the trunk of model " +
                         "checksum " + buffer + " ('" + model_path +
                         "'): it renders through that trunk only");
    }
  }
  return generator;
}

GeneratorModel LoadGeneratorModel(const std::string& path, const FunctaModel& model,
                                  const std::string& model_path, SensorKind sensor) {
  GeneratorModel g;
  g.model = &model;
  g.path = model_path;
  if (path.empty()) return g;
  g.owned = std::make_unique<FunctaModel>(FunctaModel::Load(path));
  g.model = g.owned.get();
  g.path = path;
  if (!g.owned->HasSensor(sensor)) {
    throw DatasetError("--generator-model '" + path + "' has no trunk for sensor " +
                       ToString(sensor));
  }
  const FrameFormat& a = g.owned->Trunk(sensor).format;
  const FrameFormat& b = model.Trunk(sensor).format;
  if (!a.SameAs(b)) {
    throw DatasetError("--generator-model '" + path + "' works at " + std::to_string(a.rows) + "x" +
                       std::to_string(a.cols) + ", scale " + FormatFixed(a.scale, 4) +
                       ", --model '" + model_path + "' at " + std::to_string(b.rows) + "x" +
                       std::to_string(b.cols) + ", scale " + FormatFixed(b.scale, 4) +
                       ": both must see the frame alike");
  }
  return g;
}

nlohmann::json DataFramesJson(const SensorInfo& info) {
  return {{"rows", info.rows},
          {"cols", info.cols},
          {"channels", info.channels},
          {"pixel_pitch_m", info.pixel_pitch_m}};
}

std::string DataDescriptionWhere(const Dataset& dataset, const std::string& data_path,
                                 SensorKind sensor) {
  const SensorInfo& info = dataset.sensor_info(sensor);
  return "--data '" + data_path + "' (" +
         (info.description ? info.description_path
                           : std::string("built-in ") + ToString(sensor) + " description") +
         ")";
}

void CheckModelDescription(const FunctaModel& model, const std::string& model_path,
                           const SensorDescription& data, const std::string& data_where,
                           SensorKind sensor, const std::string& command,
                           const std::string& override_flag, bool override_given,
                           bool data_described) {
  if (!model.HasSensor(sensor)) return;
  const SensorTrunk& trunk = model.Trunk(sensor);
  const SensorDescription trained = TrunkSensorDescription(trunk);
  SensorDescription compared = data;
  if (compared.working_rows <= 0) {
    compared.working_rows = trained.working_rows;
    compared.working_cols = trained.working_cols;
    compared.aspect = trained.aspect;
  }
  if (compared.pixel_pitch_m <= 0 || trained.pixel_pitch_m <= 0 || !trunk.description) {
    compared.pixel_pitch_m = trained.pixel_pitch_m;
  }
  // The preprocessing normalises by the model's own scale; the data's is a statement only
  // when a description file makes it (else it is the kind's default), and a model
  // without a description never recorded one.
  if (!trunk.description || !data_described) {
    compared.normalization_scale = trained.normalization_scale;
  }
  const std::vector<std::string> differences = FrameDifferences(trained, compared);
  if (differences.empty()) return;
  std::string list;
  for (const std::string& d : differences) list += (list.empty() ? "" : "; ") + d;
  const std::string message =
      "model '" + model_path + "' was trained on " + ToString(sensor) + " frames described as \"" +
      trained.name + "\"" + (trunk.description ? "" : " (built in: the model records none)") +
      ", but " + data_where + " describes them as \"" + data.name + "\"; they differ in " + list +
      " (model vs data). Train a model on this data (tactfunc train), or pass " + override_flag +
      " to use this model anyway";
  if (!override_given) throw DatasetError(message);
  std::cerr << command << ": warning (" << override_flag << "): " << message << "\n";
}

namespace {
// The size / channel / pitch check against the model info's data_frames record.
void CheckModelFrames(const FunctaModel& model, const std::string& model_path,
                      const Dataset& dataset, const std::string& data_path, SensorKind sensor,
                      const std::string& command, const std::string& override_flag,
                      bool override_given);
}  // namespace

void CheckModelMatchesData(const FunctaModel& model, const std::string& model_path,
                           const Dataset& dataset, const std::string& data_path,
                           SensorKind sensor, const std::string& command,
                           const std::string& override_flag, bool override_given) {
  if (!dataset.has_sensor(sensor)) return;
  // The description first: its message says what differs (a crop, a pitch), where the
  // sizes below would only say that they do.
  const SensorInfo& data = dataset.sensor_info(sensor);
  CheckModelDescription(model, model_path, DataSensorDescription(data),
                        DataDescriptionWhere(dataset, data_path, sensor), sensor, command,
                        override_flag, override_given, data.description.has_value());
  CheckModelFrames(model, model_path, dataset, data_path, sensor, command, override_flag,
                   override_given);
}

namespace {

void CheckModelFrames(const FunctaModel& model, const std::string& model_path,
                      const Dataset& dataset, const std::string& data_path, SensorKind sensor,
                      const std::string& command, const std::string& override_flag,
                      bool override_given) {
  nlohmann::json info;
  try {
    info = nlohmann::json::parse(model.info_json());
  } catch (const nlohmann::json::exception&) {
    return;  // set_info_json keeps info a JSON object; nothing recorded otherwise
  }
  const std::string name = ToString(sensor);
  if (!info.is_object() || !info.contains("trunks") || !info["trunks"].is_object() ||
      !info["trunks"].contains(name) || !info["trunks"][name].is_object() ||
      !info["trunks"][name].contains("data_frames")) {
    return;
  }
  const nlohmann::json& trained = info["trunks"][name]["data_frames"];
  const SensorInfo& data = dataset.sensor_info(sensor);
  auto number = [&](const char* key) {
    return trained.contains(key) && trained[key].is_number() ? trained[key].get<double>() : 0.0;
  };
  const int rows = static_cast<int>(number("rows")), cols = static_cast<int>(number("cols"));
  const int channels = static_cast<int>(number("channels"));
  const double pitch = number("pixel_pitch_m");
  auto shape = [](int r, int c, int ch) {
    return std::to_string(r) + "x" + std::to_string(c) + "x" + std::to_string(ch);
  };
  if (rows > 0 && cols > 0 && channels > 0 &&
      (rows != data.rows || cols != data.cols || channels != data.channels)) {
    const std::string message =
        "model '" + model_path + "' was trained on " + name + " frames of " +
        shape(rows, cols, channels) + " (rows x cols x channels, its info's trunks." + name +
        ".data_frames), but --data '" + data_path + "' has " + name + " frames of " +
        shape(data.rows, data.cols, data.channels) +
        ": another sensor or resolution. Train a model on this data (tactfunc train), or pass " +
        override_flag + " to use this model anyway";
    if (!override_given) throw DatasetError(message);
    std::cerr << command << ": warning (" << override_flag << "): " << message << "\n";
  }
  // A trunk with a description had its pitch compared above.
  if (!model.Trunk(sensor).description && pitch > 0 && data.pixel_pitch_m > 0 &&
      std::abs(pitch / data.pixel_pitch_m - 1.0) > 0.01) {
    std::cerr << command << ": warning: model '" << model_path << "' was trained on " << name
              << " frames of pixel pitch " << pitch * 1e3 << " mm, --data '" << data_path
              << "' has " << data.pixel_pitch_m * 1e3
              << " mm: contacts appear at another scale than the trunk learned\n";
  }
}

}  // namespace

}  // namespace tactfunc::apps
