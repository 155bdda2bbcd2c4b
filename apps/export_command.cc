// Copyright 2026 The tactfunc Authors.
//
// tactfunc export: a dataset's trunk targets under a model -- the frames exactly as the
// model's trunks fit them (working resolution, grayscale, normalisation: the model's
// FrameFormat, LoadTrunkTargets) -- as NumPy .npy files, with their validity weights,
// optionally the noise-free frames and a functaset's reconstructions of them, each
// sensor's reference in the same units, and an export.json describing every array and
// frame (docs/CLI.md, "export").
//
// Every frame is loaded, checked and converted before anything is written; the arrays
// are then written atomically one by one and export.json last, so a folder whose
// export.json exists holds a complete export. A failure while writing removes what this
// run wrote.
#include <algorithm>
#include <chrono>
#include <filesystem>
#include <iostream>
#include <optional>
#include <set>
#include <stdexcept>
#include <string>
#include <vector>

#include "CLI/CLI.hpp"
#include "apps/command.h"
#include "apps/dataset_flags.h"
#include "apps/model_inputs.h"
#include "apps/output_paths.h"
#include "apps/progress_bar.h"
#include "estimation/data/dataset.h"
#include "estimation/data/npy_writer.h"
#include "estimation/data/photometric_markers.h"
#include "estimation/data/preprocess.h"
#include "estimation/data/trunk_targets.h"
#include "estimation/evaluation/reconstruction.h"
#include "estimation/functaset/functaset.h"
#include "models/core/atomic_file.h"
#include "models/trunk/functa_model.h"

namespace tactfunc::apps {
namespace {

namespace fs = std::filesystem;

struct ExportFlags {
  std::string data;
  std::string model;
  std::string functaset;  // "": no reconstructions
  std::string out;
  std::string sensors;
  std::string split = "all";
  bool clean = false;
  bool overwrite = false;
  bool allow_other_frames = false;
  bool json = false;
  DatasetFlags dataset;
};

constexpr const char* kDescriptionFile = "export.json";

// One sensor's export: its frames, the arrays (N x rows x cols x C, C order) and what
// export.json says about them.
struct SensorExport {
  SensorKind sensor = SensorKind::kSoftBubble;
  FrameFormat format;
  std::vector<std::size_t> indices;  // into Dataset::frames(), in file order
  int rows = 0, cols = 0, channels = 0;
  std::vector<float> values, weights, clean, recon;
  nlohmann::json frames = nlohmann::json::array();
  std::optional<PreprocessedFrame> reference;
  nlohmann::json reference_json;
  std::string values_file, weights_file, clean_file, recon_file,
      reference_file;  // "" = not written
};

std::string JoinNames(const std::vector<std::string>& names) {
  std::string text;
  for (const std::string& name : names) text += (text.empty() ? "" : ", ") + name;
  return text.empty() ? "none" : text;
}

std::string SensorNames(const std::vector<SensorKind>& sensors) {
  std::vector<std::string> names;
  for (SensorKind sensor : sensors) names.push_back(ToString(sensor));
  return JoinNames(names);
}

// The sensors to export: --sensors (each in the model and the dataset), else every
// sensor in both.
std::vector<SensorKind> SelectSensors(const ExportFlags& flags, const FunctaModel& model,
                                      const Dataset& dataset) {
  std::vector<SensorKind> selected = ParseSensorsFlag(flags.sensors);
  if (!flags.sensors.empty() && selected.empty()) {
    throw UsageError("--sensors: expected a comma-separated list of bubble and/or gelslim, got '" +
                     flags.sensors + "'");
  }
  for (SensorKind kind : selected) {
    const std::string name = ToString(kind);
    if (!model.HasSensor(kind)) {
      throw UsageError("--sensors: the model '" + flags.model + "' has no trunk for " + name +
                       " (its trunks: " + SensorNames(model.sensors()) + ")");
    }
    if (!dataset.has_sensor(kind)) {
      throw UsageError("--sensors: the dataset '" + flags.data + "' has no " + name +
                       " frames (its sensors: " + SensorNames(dataset.sensors()) + ")");
    }
  }
  if (selected.empty()) {
    for (SensorKind sensor : dataset.sensors()) {
      if (model.HasSensor(sensor)) selected.push_back(sensor);
    }
    if (selected.empty()) {
      throw DatasetError("no sensor is in both the dataset '" + flags.data + "' (" +
                         SensorNames(dataset.sensors()) + ") and the model '" + flags.model +
                         "' (" + SensorNames(model.sensors()) + "): nothing to export");
    }
  }
  return selected;
}

nlohmann::json LabelJson(const std::optional<PoseLabel>& label) {
  if (!label) return nullptr;
  return {{"tool", label->tool},
          {"x_m", label->sensor_T_object.x()},
          {"y_m", label->sensor_T_object.y()},
          {"yaw_rad", label->sensor_T_object.yaw()},
          {"depth_m", label->depth_m}};
}

// Copies `targets` (pixel j = row * cols + col, one column per channel) into frame `n` of
// the N x rows x cols x C arrays.
void StoreTargets(const TrunkTargets& targets, std::size_t n, const SensorExport& e,
                  std::vector<float>* values, std::vector<float>* weights) {
  const std::size_t pixels = static_cast<std::size_t>(e.rows) * e.cols;
  float* v = values->data() + n * pixels * e.channels;
  for (std::size_t j = 0; j < pixels; ++j) {
    for (int c = 0; c < e.channels; ++c) {
      v[j * e.channels + c] = targets.values(static_cast<Eigen::Index>(j), c);
    }
  }
  if (weights != nullptr) {
    float* w = weights->data() + n * pixels;
    for (std::size_t j = 0; j < pixels; ++j) w[j] = targets.weights[static_cast<Eigen::Index>(j)];
  }
}

// Throws unless `targets` are rows x cols x C of the export (they are, by the format).
void CheckShape(const TrunkTargets& targets, const SensorExport& e, const Dataset& dataset,
                std::size_t index) {
  if (targets.rows != e.rows || targets.cols != e.cols || targets.values.cols() != e.channels) {
    throw DatasetError("frame '" + dataset.frames()[index].id + "' (" + ToString(e.sensor) +
                       "): expected targets of " + std::to_string(e.rows) + "x" +
                       std::to_string(e.cols) + "x" + std::to_string(e.channels) + ", got " +
                       std::to_string(targets.rows) + "x" + std::to_string(targets.cols) + "x" +
                       std::to_string(targets.values.cols()));
  }
}

// The sensor's reference in the units of its targets (PreprocessImage: the reference
// itself, not a difference), or none for a per-image min-max format; export.json's record
// of it.
void MakeReference(const Dataset& dataset, SensorExport* e) {
  nlohmann::json& j = e->reference_json;
  if (e->format.per_image_min_max) {
    j = {{"file", nullptr},
         {"note", "not written: the model normalises each frame by its own min and max, "
                  "so a reference has no units shared with the frames"}};
    return;
  }
  const std::size_t first = e->indices.front();
  const PreprocessedFrame reference = PreprocessImage(
      dataset.FrameReference(first), ToPreprocessOptions(e->format), e->format.scale);
  if (reference.values.rows != e->rows || reference.values.cols != e->cols ||
      reference.values.channels != e->channels) {
    throw std::logic_error("export: the " + std::string(ToString(e->sensor)) + " reference is " +
                           reference.values.ShapeString() + ", the targets " +
                           std::to_string(e->rows) + "x" + std::to_string(e->cols) + "x" +
                           std::to_string(e->channels));
  }
  e->reference_file = std::string(ToString(e->sensor)) + "_reference.npy";
  j = {{"file", e->reference_file},
       {"valid_pixels", reference.num_valid()},
       {"note", "the reference itself (not a difference): grayscale if the format says so, "
                "resized like the targets, divided by the scale; invalid pixels hold 0"}};
  const int clip = dataset.frames()[first].clip;
  if (clip >= 0) {
    std::set<int> clips;
    for (std::size_t index : e->indices) clips.insert(dataset.frames()[index].clip);
    j["clip"] = dataset.clips()[clip].name;
    j["clips_in_selection"] = clips.size();
    j["note"] = j["note"].get<std::string>() +
                "; the reference of the first frame's clip -- each frame's targets are "
                "differenced against its own clip's reference";
  } else {
    j["clip"] = nullptr;
  }
  e->reference = reference;
}

// Copies a reconstruction (pixel j = row * cols + col, one column per channel) into frame
// `n` of the N x rows x cols x C array.
void StoreReconstruction(const Eigen::MatrixXf& recon, std::size_t n, SensorExport* e) {
  const std::size_t pixels = static_cast<std::size_t>(e->rows) * e->cols;
  float* v = e->recon.data() + n * pixels * e->channels;
  for (std::size_t j = 0; j < pixels; ++j) {
    for (int c = 0; c < e->channels; ++c) v[j * e->channels + c] = recon(j, c);
  }
}

// Loads every selected frame (and its noise-free copy with --clean) as the model's trunk
// targets, one frame decoded at a time; with a functaset, also each frame's
// reconstruction from its stored latent (as `recon` draws it).
void LoadSensor(const Dataset& dataset, bool clean, const SensorTrunk& trunk,
                const Functaset* functaset, ProgressBar* bar, SensorExport* e) {
  const std::size_t n = e->indices.size();
  const std::size_t pixels = static_cast<std::size_t>(e->rows) * e->cols;
  e->values.assign(n * pixels * e->channels, 0.0f);
  e->weights.assign(n * pixels, 0.0f);
  if (clean) e->clean.assign(n * pixels * e->channels, 0.0f);
  if (functaset != nullptr) e->recon.assign(n * pixels * e->channels, 0.0f);
  // A photometric trunk draws each frame against its own reference (its clip's).
  std::optional<DatasetMarkers> markers;
  if (functaset != nullptr && trunk.photometric != nullptr) markers.emplace(dataset, trunk);
  for (std::size_t k = 0; k < n; ++k) {
    const std::size_t index = e->indices[k];
    const FrameRecord& record = dataset.frames()[index];
    const TrunkTargets targets = LoadTrunkTargets(dataset, index, e->format, /*clean=*/false);
    CheckShape(targets, *e, dataset, index);
    StoreTargets(targets, k, *e, &e->values, &e->weights);
    if (functaset != nullptr) {
      // Every frame's entry was checked to exist before anything was loaded.
      const Eigen::VectorXf& latent =
          functaset->entries(e->sensor)[*functaset->Find(e->sensor, record.id)].latent;
      const Eigen::MatrixXf recon =
          Reconstruct(trunk, latent, markers ? markers->Of(index) : nullptr);
      if (recon.rows() != static_cast<Eigen::Index>(pixels) || recon.cols() != e->channels) {
        throw std::logic_error("export: the " + std::string(ToString(e->sensor)) +
                               " trunk drew " + std::to_string(recon.rows()) + "x" +
                               std::to_string(recon.cols()) + " values for frame '" +
                               record.id + "', the targets have " + std::to_string(pixels) +
                               "x" + std::to_string(e->channels));
      }
      StoreReconstruction(recon, k, e);
    }
    nlohmann::json frame = {{"index", index},
                            {"id", record.id},
                            {"split", ToString(record.split)},
                            {"label", LabelJson(record.label)},
                            {"scale", targets.scale},
                            {"offset", targets.offset}};
    if (e->format.per_image_min_max) frame["flat"] = targets.flat;
    if (record.clip >= 0) frame["clip"] = dataset.clips()[record.clip].name;
    if (clean) {
      const TrunkTargets noise_free =
          LoadTrunkTargets(dataset, index, e->format, /*clean=*/true);
      CheckShape(noise_free, *e, dataset, index);
      StoreTargets(noise_free, k, *e, &e->clean, nullptr);
      frame["clean_scale"] = noise_free.scale;
      frame["clean_offset"] = noise_free.offset;
    }
    e->frames.push_back(std::move(frame));
    bar->Tick();
  }
  MakeReference(dataset, e);
}

nlohmann::json InputsJson(const ExportFlags& flags, const FunctaModel& model) {
  nlohmann::json j = {{"data", flags.data},
                      {"model", flags.model},
                      {"model_checksum", model.checksum()},
                      {"functaset", flags.functaset.empty() ? nlohmann::json(nullptr)
                                                            : nlohmann::json(flags.functaset)},
                      {"out", flags.out},
                      {"sensors", flags.sensors.empty() ? nlohmann::json(nullptr)
                                                        : nlohmann::json(flags.sensors)},
                      {"split", flags.split},
                      {"clean", flags.clean},
                      {"allow_other_frames", flags.allow_other_frames}};
  const DatasetFlags& d = flags.dataset;
  if (!d.sensor.empty()) j["sensor"] = d.sensor;
  if (!d.reference.empty()) j["reference"] = d.reference;
  if (d.reference_index != 0) j["reference_index"] = d.reference_index;
  if (d.pixel_pitch_mm != 0) j["pixel_pitch_mm"] = d.pixel_pitch_mm;
  if (!d.labels.empty()) j["labels"] = d.labels;
  if (!d.tools.empty()) j["tool_symmetry"] = d.tools;
  if (!d.sensor_file.empty()) j["sensor_file"] = d.sensor_file;
  return j;
}

nlohmann::json SensorJson(const SensorExport& e) {
  nlohmann::json files = {{"values", e.values_file},
                          {"weights", e.weights_file},
                          {"clean", e.clean_file.empty() ? nlohmann::json(nullptr)
                                                         : nlohmann::json(e.clean_file)},
                          {"recon", e.recon_file.empty() ? nlohmann::json(nullptr)
                                                         : nlohmann::json(e.recon_file)},
                          {"reference", e.reference_file.empty()
                                            ? nlohmann::json(nullptr)
                                            : nlohmann::json(e.reference_file)}};
  return {{"rows", e.rows},
          {"cols", e.cols},
          {"channels", e.channels},
          {"count", e.indices.size()},
          {"grayscale", e.format.grayscale},
          {"normalization", e.format.per_image_min_max ? "per_image_min_max" : "fixed_scale"},
          {"scale", e.format.per_image_min_max ? nlohmann::json(nullptr)
                                               : nlohmann::json(e.format.scale)},
          {"units", e.sensor == SensorKind::kSoftBubble
                        ? "difference = reference - frame in metres of depth"
                        : "difference = frame - reference in intensity (0..1)"},
          {"values_are", "(difference - offset) / scale per frame; invalid pixels hold 0 "
                         "(weight 0)"},
          {"files", files},
          {"reference", e.reference_json},
          {"frames", e.frames}};
}

void RunExport(const ExportFlags& flags) {
  const auto start = std::chrono::steady_clock::now();
  std::optional<Split> split;
  if (flags.split != "all") {
    Split parsed;
    if (!SplitFromString(flags.split, &parsed)) {
      throw UsageError("--split: expected train, test or all, got '" + flags.split + "'");
    }
    split = parsed;
  }
  std::vector<NamedPath> inputs = DatasetPathInputs("--data", flags.data, flags.dataset);
  inputs.push_back({"--model", flags.model});
  if (!flags.functaset.empty()) inputs.push_back({"--functaset", flags.functaset});
  RefuseOutputsThatAreInputs({{"--out", flags.out}}, inputs);
  std::error_code ec;
  if (fs::exists(flags.out, ec) && !fs::is_directory(flags.out, ec)) {
    throw UsageError("--out '" + flags.out + "': expected a folder (new or existing), got a file");
  }
  // The functaset first: its products' precision is set before the model is read, so
  // that the reconstructions are recon's and encode's own.
  std::optional<Functaset> functaset;
  if (!flags.functaset.empty()) {
    functaset.emplace(Functaset::Load(flags.functaset));
    ApplyProductPrecision(ProductPrecisionFor("", *functaset, flags.functaset, "export"));
  }
  const FunctaModel model = FunctaModel::Load(flags.model);
  if (functaset) functaset->CheckModel(model, flags.model, flags.functaset);
  const Dataset dataset = OpenDataset(flags.data, flags.dataset);
  const std::vector<NamedPath> dataset_files = DatasetFileInputs("--data", dataset);
  RefuseOutputsThatAreInputs({{"--out", flags.out}}, dataset_files);

  // What will be exported, checked in full before any frame is loaded.
  std::vector<SensorExport> exports;
  std::vector<std::string> names;
  std::int64_t total = 0;
  for (SensorKind sensor : SelectSensors(flags, model, dataset)) {
    SensorExport e;
    e.sensor = sensor;
    e.format = model.Trunk(sensor).format;
    e.indices = dataset.FrameIndices(sensor, split);
    const std::string name = ToString(sensor);
    if (e.indices.empty()) {
      throw UsageError("--split " + flags.split + ": the dataset '" + flags.data + "' has no " +
                       flags.split + " frames of " + name +
                       "; choose another --split or other --sensors");
    }
    if (flags.clean) {
      if (!dataset.has_clean()) {
        throw UsageError("--clean: the dataset '" + flags.data +
                         "' has no noise-free frames (`tactfunc synth --clean` writes them); "
                         "export without --clean");
      }
      for (std::size_t index : e.indices) {
        if (dataset.frames()[index].clean_path.empty()) {
          throw UsageError("--clean: frame '" + dataset.frames()[index].id + "' (" + name +
                           ") of the dataset '" + flags.data + "' has no noise-free copy");
        }
      }
    }
    if (functaset) {
      for (std::size_t index : e.indices) {
        if (!functaset->Find(sensor, dataset.frames()[index].id)) {
          throw UsageError("--functaset '" + flags.functaset + "' has no " + name +
                           " latent for frame '" + dataset.frames()[index].id +
                           "' of the dataset '" + flags.data +
                           "' (encode it, or choose another --split or --sensors)");
        }
      }
    }
    CheckModelMatchesData(model, flags.model, dataset, flags.data, sensor, "export",
                          "--allow-other-frames", flags.allow_other_frames);
    WarnIfStretched(dataset, flags.data, sensor, e.format.rows, e.format.cols, "export");
    const SensorInfo& info = dataset.sensor_info(sensor);
    e.rows = e.format.rows;
    e.cols = e.format.cols;
    e.channels = e.format.grayscale && info.channels == 3 ? 1 : info.channels;
    e.values_file = name + "_" + flags.split + ".npy";
    e.weights_file = name + "_" + flags.split + "_weights.npy";
    if (flags.clean) e.clean_file = name + "_" + flags.split + "_clean.npy";
    if (functaset) e.recon_file = name + "_" + flags.split + "_recon.npy";
    for (const std::string* file :
         {&e.values_file, &e.weights_file, &e.clean_file, &e.recon_file}) {
      if (!file->empty()) names.push_back(*file);
    }
    if (!e.format.per_image_min_max) names.push_back(name + "_reference.npy");
    total += static_cast<std::int64_t>(e.indices.size());
    exports.push_back(std::move(e));
  }
  names.push_back(kDescriptionFile);
  const std::vector<NamedPath> outputs = FilesIn("--out", flags.out, names);
  inputs.insert(inputs.end(), dataset_files.begin(), dataset_files.end());
  RefuseOutputsThatAreInputs(outputs, inputs);
  std::vector<std::string> existing;
  for (const NamedPath& file : outputs) {
    if (fs::exists(file.path, ec)) existing.push_back(fs::path(file.path).filename().string());
  }
  if (!existing.empty() && !flags.overwrite) {
    throw UsageError("--out '" + flags.out + "' already holds " + JoinNames(existing) +
                     ": pass --overwrite to replace them, or choose another --out");
  }

  ProgressBar bar("export", total, "frames", ProgressBar::Lines::kWhenNotDrawn);
  for (SensorExport& e : exports) {
    LoadSensor(dataset, flags.clean, model.Trunk(e.sensor), functaset ? &*functaset : nullptr,
               &bar, &e);
  }
  bar.Finish();

  nlohmann::json description = {{"format", "tactfunc-export"},
                                {"version", 1},
                                {"inputs", InputsJson(flags, model)},
                                {"sensors", nlohmann::json::object()}};
  for (const SensorExport& e : exports) description["sensors"][ToString(e.sensor)] = SensorJson(e);

  // Write: export.json goes first (an export being replaced never looks complete) and
  // comes back last; a failure removes what this run wrote.
  fs::create_directories(flags.out);
  for (const NamedPath& file : outputs) RemoveStaleTemporaries(file.path);
  const std::string description_path = (fs::path(flags.out) / kDescriptionFile).string();
  fs::remove(description_path);
  std::vector<std::string> written;
  try {
    for (const SensorExport& e : exports) {
      const std::int64_t n = static_cast<std::int64_t>(e.indices.size());
      auto write = [&](const std::string& name, const std::vector<std::int64_t>& shape,
                       const std::vector<float>& data) {
        const std::string path = (fs::path(flags.out) / name).string();
        WriteNpyFloat32(path, shape, data.data(), data.size());
        written.push_back(path);
      };
      write(e.values_file, {n, e.rows, e.cols, e.channels}, e.values);
      write(e.weights_file, {n, e.rows, e.cols}, e.weights);
      if (!e.clean_file.empty()) write(e.clean_file, {n, e.rows, e.cols, e.channels}, e.clean);
      if (!e.recon_file.empty()) write(e.recon_file, {n, e.rows, e.cols, e.channels}, e.recon);
      if (e.reference) {
        write(e.reference_file, {e.rows, e.cols, e.channels}, e.reference->values.data);
      }
    }
    WriteFileAtomically(description_path, description.dump(2) + "\n");
  } catch (const std::exception&) {
    for (const std::string& path : written) fs::remove(path, ec);
    std::cerr << "export: removed the " << written.size() << " file(s) this run had written to "
              << flags.out << "\n";
    throw;
  }

  const double seconds =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  nlohmann::json sensors = nlohmann::json::object();
  for (const SensorExport& e : exports) {
    std::cout << "export: " << ToString(e.sensor) << ": " << e.indices.size() << " "
              << flags.split << " frames of " << e.rows << "x" << e.cols << "x" << e.channels
              << " -> " << e.values_file << ", " << e.weights_file
              << (e.clean_file.empty() ? "" : ", " + e.clean_file)
              << (e.recon_file.empty() ? "" : ", " + e.recon_file)
              << (e.reference_file.empty() ? " (no reference: per-image min-max format)"
                                           : ", " + e.reference_file)
              << "\n";
    sensors[ToString(e.sensor)] = {{"frames", e.indices.size()},
                                   {"rows", e.rows},
                                   {"cols", e.cols},
                                   {"channels", e.channels}};
  }
  std::cout << "export: wrote " << names.size() << " files to " << flags.out << " in "
            << FormatFixed(seconds, 2) << " s (" << kDescriptionFile << " describes them)\n";
  if (flags.json) {
    EmitJson({{"out", flags.out},
              {"split", flags.split},
              {"files", names},
              {"sensors", sensors},
              {"seconds", seconds}});
  }
}

}  // namespace

void RegisterExport(CLI::App& app, CommandBody* selected) {
  auto flags = std::make_shared<ExportFlags>();
  CLI::App* sub = app.add_subcommand(
      "export",
      "Write a dataset's frames as a model's trunks fit them (working resolution, "
      "normalised by the model's frame format) as NumPy .npy files, with weights, "
      "references and an export.json.");
  sub->add_option("--data", flags->data, "Dataset folder or video")->required();
  sub->add_option("--model", flags->model,
                  "Model file (.tfm): its trunks' frame formats define the targets")
      ->required();
  sub->add_option("--functaset", flags->functaset,
                  "Functaset (.tfs) encoded with --model: also write "
                  "<sensor>_<split>_recon.npy, each frame drawn from its stored latent as "
                  "`recon` draws it (every exported frame needs its latent)");
  sub->add_option("--out", flags->out,
                  "Folder to write <sensor>_<split>.npy, <sensor>_<split>_weights.npy, "
                  "<sensor>_reference.npy (and with --clean / --functaset the noise-free "
                  "frames / the reconstructions) and export.json into (created if needed)")
      ->required();
  sub->add_option("--sensors", flags->sensors,
                  "Comma-separated sensors to export (default: every sensor of the dataset "
                  "that the model has a trunk for)");
  sub->add_option("--split", flags->split, "Frames of this split: train, test or all (default)");
  sub->add_flag("--clean", flags->clean,
                "Also write <sensor>_<split>_clean.npy from the noise-free frames (datasets "
                "from `tactfunc synth --clean`)");
  sub->add_flag("--overwrite", flags->overwrite,
                "Replace files of an earlier export in --out (other files are left alone)");
  sub->add_flag("--allow-other-frames", flags->allow_other_frames,
                "Export even when the data's frames (size, channels, sensor description) are "
                "not those the model's trunk was trained on (a warning instead of an error)");
  sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
  AddDatasetFlags(sub, &flags->dataset);
  sub->callback([flags, selected]() { *selected = [flags]() { RunExport(*flags); }; });
}

}  // namespace tactfunc::apps
