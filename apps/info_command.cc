// Copyright 2026 The tactfunc Authors.
//
// tactfunc info: what a dataset holds -- counts per sensor and split, resolutions,
// tools, bytes on disk; what a tactfunc file holds (any kind: its kind, version, size
// and checksum; for a model, functaset, pose model or checkpoint also the figures of
// its kind); or, with --tools, the simulator's twelve tools.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "CLI/CLI.hpp"
#include "apps/command.h"
#include "apps/dataset_flags.h"
#include "estimation/data/dataset.h"
#include "estimation/data/image_io.h"
#include "estimation/functaset/functaset.h"
#include "estimation/evaluation/reconstruction.h"
#include "models/trunk/functa_model.h"
#include "models/pose/pose_generator.h"
#include "models/pose/pose_mlp.h"
#include "models/core/tensor_file.h"
#include "models/simulator/tool.h"

namespace tactfunc::apps {
namespace {

struct InfoFlags {
  std::string dir;
  DatasetFlags data;
  bool tools = false;
  bool json = false;
};

void PrintTools(bool json) {
  nlohmann::json list = nlohmann::json::array();
  std::printf("%-12s %-9s %-8s %s\n", "tool", "symmetry", "height", "description");
  for (const Tool& tool : ToolSet()) {
    const std::string symmetry = tool.symmetry_order() == 0
                                     ? "SO(2)"
                                     : "C" + std::to_string(tool.symmetry_order());
    std::printf("%-12s %-9s %5.1f mm %s\n", tool.name().c_str(), symmetry.c_str(),
                tool.max_height() * 1e3, tool.description().c_str());
    list.push_back({{"name", tool.name()}, {"symmetry_order", tool.symmetry_order()}});
  }
  if (json) EmitJson({{"tools", list}});
}

// True if `path` is a regular file with a tactfunc extension (.tfm, .tfs, .tpm, .ckpt,
// .knn: TensorFile::Read then says what is wrong with a damaged one) or that starts
// with the TensorFile magic.
bool IsTensorFile(const std::string& path) {
  if (!std::filesystem::is_regular_file(path)) return false;
  const std::string ext = std::filesystem::path(path).extension().string();
  for (const char* known : {".tfm", ".tfs", ".tpm", ".ckpt", ".knn"}) {
    if (ext == known) return true;
  }
  std::ifstream in(path, std::ios::binary);
  char magic[8] = {};
  in.read(magic, sizeof(magic));
  return in.gcount() == 8 && std::string(magic, 8) == "TACTFUNC";
}

// j[key] if j is an object holding a number there, else NaN (files from other versions
// or hand-edited info may lack a field or hold null, e.g. for a NaN PSNR).
double NumberAt(const nlohmann::json& j, const char* key) {
  if (!j.is_object() || !j.contains(key) || !j[key].is_number()) {
    return std::numeric_limits<double>::quiet_NaN();
  }
  return j[key].get<double>();
}

// j[key] if j is an object holding an object there, else {}.
nlohmann::json ObjectAt(const nlohmann::json& j, const char* key) {
  if (!j.is_object() || !j.contains(key) || !j[key].is_object()) return nlohmann::json::object();
  return j[key];
}

std::string StringAt(const nlohmann::json& j, const char* key) {
  if (!j.is_object() || !j.contains(key) || !j[key].is_string()) return "?";
  return j[key].get<std::string>();
}

// An integral count (a step, a version) as a JSON integer; null if not finite.
nlohmann::json CountOrNull(double value) {
  if (!std::isfinite(value)) return nullptr;
  return static_cast<std::int64_t>(std::llround(value));
}

// A trunk model: per sensor the trunk's shape, working format, inner loop and, from the
// model's info, the training run.
nlohmann::json DescribeModel(const std::string& bytes, const std::string& path) {
  const FunctaModel model = FunctaModel::Parse(bytes, path);
  const nlohmann::json info = nlohmann::json::parse(model.info_json());
  const nlohmann::json trunks_info = ObjectAt(info, "trunks");
  const std::string preset = StringAt(info, "preset");
  // Files written before `train --products` existed were trained in float.
  std::string products = StringAt(info, "products");
  if (products == "?") products = "float";
  std::cout << "  preset " << preset
            << (products == "float" ? "" : ", trained with " + products + " products") << "\n";
  nlohmann::json trunks = nlohmann::json::object();
  for (SensorKind sensor : model.sensors()) {
    const SensorTrunk& t = model.Trunk(sensor);
    const LatentModulatedSiren::Options& o = t.siren.options();
    if (t.photometric != nullptr) {
      std::printf("  %-8s SIREN %d x %d (omega_0 %g), d = %d, %d parameters; %dx%d%s, scale %g; "
                  "residual sigma %.4g\n",
                  ToString(sensor), o.width, o.num_hidden_layers, o.omega_0, TrunkLatentDim(t),
                  t.siren.NumParameters(), t.format.rows, t.format.cols,
                  t.format.grayscale ? " grayscale" : "", t.format.scale, t.residual_sigma);
    } else {
      std::printf("  %-8s SIREN %d x %d (omega_0 %g), d = %d, %d parameters; %dx%d%s, scale %g; "
                  "K = %d%s, alpha in [%.3g, %.3g]; residual sigma %.4g\n",
                  ToString(sensor), o.width, o.num_hidden_layers, o.omega_0, o.latent_dim,
                  t.siren.NumParameters(), t.format.rows, t.format.cols,
                  t.format.grayscale ? " grayscale" : "", t.format.scale, t.meta_sgd.inner_steps,
                  t.meta_sgd.first_order ? " (first-order)" : "", t.alpha.minCoeff(),
                  t.alpha.maxCoeff(), t.residual_sigma);
    }
    if (o.has_spatial()) {
      std::printf("           spatial latents: a %d x %d grid of %d values (%d) + %d global\n",
                  o.spatial_rows, o.spatial_cols, o.spatial_channels, o.spatial_size(),
                  o.global_latent_dim());
    }
    if (o.has_readout()) {
      const Eigen::VectorXd& gains = t.siren.start_gains();
      std::printf("           linear readout branch on a %d x %d grid", o.readout_rows,
                  o.readout_cols);
      if (gains.size() != 0) {
        std::printf(", every fit from its projection times gains in [%.3g, %.3g]",
                    gains.minCoeff(), gains.maxCoeff());
      }
      std::printf("\n");
    }
    if (t.photometric != nullptr) {
      const PhotometricTrunk& p = *t.photometric;
      const std::string lighting_values =
          p.lighting_components() > 0
              ? " + lighting " + std::to_string(p.lighting_components())
              : std::string();
      std::printf("           photometric head: latent %d = rigid motion 3 + code %d%s, shading "
                  "network of %d, markers moved at the sensor's %dx%d (%d x %d samples a "
                  "pixel), %.3f px per unit slope; fitted with adam:N, knn+adam:N or "
                  "knn+ceres:N\n",
                  p.latent_dim(), p.CodeValues(), lighting_values.c_str(),
                  p.options().shading_width, p.reference().rows, p.reference().cols,
                  p.options().supersample, p.options().supersample, p.marker_scale());
      if (!p.background().empty()) {
        std::printf("           background: %dx%dx%d values (RMS %.4g) added to every frame "
                    "drawn, no latent bytes\n",
                    p.background().rows, p.background().cols, p.background().channels,
                    p.BackgroundRms());
      }
      if (p.lighting_components() > 0) {
        std::printf("           lighting: %d images of %dx%dx%d values (RMS %.4g), weighed by "
                    "the latent's last %d values\n",
                    p.lighting_components(), p.options().rows, p.options().cols, p.channels(),
                    p.LightingRms(), p.lighting_components());
      }
      if (t.warm_start != nullptr) {
        const WarmStartTable& w = *t.warm_start;
        std::printf("           warm-start table: %lld training latents, descriptors of %d x "
                    "%d cells (%s, float16), for knn+adam:N, knn+ceres:N and knn\n",
                    static_cast<long long>(w.latents.rows()), w.grid, w.grid,
                    FormatBytes(2ull * static_cast<std::uint64_t>(w.descriptors.size() +
                                                                  w.latents.size()))
                        .c_str());
      }
    }
    nlohmann::json trunk = {{"width", o.width},
                            {"layers", o.num_hidden_layers},
                            {"omega_0", o.omega_0},
                            {"latent_dim", TrunkLatentDim(t)},
                            {"output_channels", TrunkOutputChannels(t)},
                            {"parameters", t.siren.NumParameters()},
                            {"rows", t.format.rows},
                            {"cols", t.format.cols},
                            {"grayscale", t.format.grayscale},
                            {"scale", t.format.scale},
                            {"inner_steps", t.meta_sgd.inner_steps},
                            {"first_order", t.meta_sgd.first_order},
                            {"alpha_min", t.alpha.minCoeff()},
                            {"alpha_max", t.alpha.maxCoeff()},
                            {"residual_sigma", t.residual_sigma}};
    if (t.photometric != nullptr) {
      trunk["photometric"] = {{"latent_dim", t.photometric->latent_dim()},
                              {"shading_width", t.photometric->options().shading_width},
                              {"supersample", t.photometric->options().supersample},
                              {"marker_scale", t.photometric->marker_scale()},
                              {"warm_start_rows", t.warm_start != nullptr
                                                      ? t.warm_start->latents.rows()
                                                      : Eigen::Index{0}}};
    }
    if (!t.default_fit.empty()) {
      std::printf("           default fit %s (recorded by train --default-fit; encode "
                  "--strategy S asks for another)\n",
                  t.default_fit.c_str());
      trunk["default_fit"] = t.default_fit;
    }
    if (o.has_spatial()) {
      trunk["spatial"] = {{"rows", o.spatial_rows},
                          {"cols", o.spatial_cols},
                          {"channels", o.spatial_channels},
                          {"global_latent_dim", o.global_latent_dim()}};
    }
    if (o.has_readout()) {
      trunk["readout"] = {{"rows", o.readout_rows}, {"cols", o.readout_cols}};
      const Eigen::VectorXd& gains = t.siren.start_gains();
      if (gains.size() != 0) {
        trunk["readout"]["start_gains"] = std::vector<double>(gains.data(),
                                                              gains.data() + gains.size());
      }
    }
    const SensorDescription described = TrunkSensorDescription(t);
    std::cout << "           sensor " << DescribeSensor(described)
              << (t.description ? "" : " (built in: the model records none)") << "\n";
    trunk["sensor_description"] = nlohmann::json::parse(SensorDescriptionToJson(described));
    trunk["sensor_description_recorded"] = t.description.has_value();
    const nlohmann::json run = ObjectAt(trunks_info, ToString(sensor));
    const double steps = NumberAt(run, "steps"), seconds = NumberAt(run, "train_seconds");
    const double psnr = NumberAt(run, "train_psnr");
    if (std::isfinite(steps)) {
      // Models written before the timing left the file still carry train_seconds.
      std::cout << "           trained " << FormatFixed(steps, 0) << " steps"
                << (std::isfinite(seconds) ? " in " + FormatFixed(seconds, 0) + " s" : "")
                << ", monitor PSNR after K steps "
                << FormatFixed(psnr, 2) << " dB\n";
    }
    trunk["steps"] = CountOrNull(steps);
    trunk["train_seconds"] = NumberOrNull(seconds);
    trunk["train_psnr"] = NumberOrNull(psnr);
    trunks[ToString(sensor)] = trunk;
  }
  return {{"trunks", trunks},
          {"parameter_bytes", model.ParameterBytes()},
          {"preset", preset},
          {"products", products}};
}

// A functaset: per sensor the latent size, the entries per split and their mean PSNR.
nlohmann::json DescribeFunctaset(const std::string& bytes, const std::string& path) {
  const Functaset functaset = Functaset::Parse(bytes, path);
  std::printf("  model checksum %u, dataset %s, latents %s%s\n", functaset.model_checksum(),
              functaset.dataset().c_str(),
              ToString(functaset.latent_precision()),
              functaset.complete() ? "" : ", PARTIAL (encode --resume continues it)");
  nlohmann::json sensors = nlohmann::json::object();
  for (SensorKind sensor : functaset.sensors()) {
    std::map<Split, std::vector<double>> psnrs;
    int labelled = 0;
    for (const FunctasetEntry& e : functaset.entries(sensor)) {
      psnrs[e.split].push_back(e.psnr);
      if (e.label) ++labelled;
    }
    const std::string strategy =
        functaset.fit_strategy(sensor).empty() ? "n/a" : functaset.fit_strategy(sensor);
    const std::string& products = functaset.products(sensor);
    // Allocated codes: how the bytes were shared among the values.
    const std::vector<int> bits = functaset.latent_precision() ==
                                          Functaset::LatentPrecision::kAllocated
                                      ? functaset.code_bits(sensor)
                                      : std::vector<int>();
    std::string shared;
    if (!bits.empty()) {
      const auto [fewest, most] = std::minmax_element(bits.begin(), bits.end());
      shared = " (" + std::to_string(*most) + " to " + std::to_string(*fewest) +
               " bits per value, " + std::to_string(std::count(bits.begin(), bits.end(), 0)) +
               " values not stored)";
    }
    std::printf("  %-8s %zu latents of %d values, %s B each on disk%s (%d labelled), fit %s%s",
                ToString(sensor), functaset.entries(sensor).size(), functaset.latent_dim(sensor),
                FormatFixed(functaset.BytesPerFrame(sensor), 0).c_str(), shared.c_str(), labelled,
                strategy.c_str(),
                products == "float" ? "" : (" with " + products + " products").c_str());
    nlohmann::json splits = nlohmann::json::object();
    for (const auto& [split, values] : psnrs) {
      const PsnrStats stats = ComputePsnrStats(values);
      std::printf(", %s %zu at %s dB", ToString(split), values.size(),
                  FormatFixed(stats.mean, 2).c_str());
      splits[ToString(split)] = {{"count", values.size()}, {"psnr_mean", NumberOrNull(stats.mean)}};
    }
    std::printf("\n");
    sensors[ToString(sensor)] = {{"latent_dim", functaset.latent_dim(sensor)},
                                 {"fit_strategy", functaset.fit_strategy(sensor).empty()
                                                      ? nlohmann::json(nullptr)
                                                      : nlohmann::json(functaset.fit_strategy(sensor))},
                                 {"products", products},
                                 {"count", functaset.entries(sensor).size()},
                                 {"labelled", labelled},
                                 {"splits", splits}};
    if (!bits.empty()) sensors[ToString(sensor)]["latent_bits"] = bits;
  }
  return {{"model_checksum", functaset.model_checksum()},
          {"dataset", functaset.dataset()},
          {"latent_precision", ToString(functaset.latent_precision())},
          {"latent_bytes", functaset.latent_precision() == Functaset::LatentPrecision::kAllocated
                               ? nlohmann::json(functaset.latent_bytes())
                               : nlohmann::json(nullptr)},
          {"complete", functaset.complete()},
          {"sensors", sensors}};
}

// A pose model: the MLP's shape and its calibration set.
nlohmann::json DescribePoseModel(const std::string& bytes, const std::string& path) {
  const PoseMlp pose = PoseMlp::Parse(bytes, path);
  std::printf("  pose MLP: %d inputs (latent floats), %d layers, %d parameters, %lld calibration "
              "residuals\n",
              pose.input_dim(), pose.num_layers(), pose.NumParameters(),
              static_cast<long long>(pose.calibration_residuals().rows()));
  return {{"input_dim", pose.input_dim()},
          {"layers", pose.num_layers()},
          {"parameters", pose.NumParameters()},
          {"calibration_residuals", pose.calibration_residuals().rows()}};
}

// A pose generator: its shape and the posterior's calibration (docs/POSES.md, "The
// generator path").
nlohmann::json DescribePoseGenerator(const std::string& bytes, const std::string& path) {
  const PoseGenerator g = PoseGenerator::Parse(bytes, path);
  std::string hidden;
  for (int h : g.options().hidden_sizes)
    hidden += (hidden.empty() ? "" : " x ") + std::to_string(h);
  std::cout << "  pose generator: " << g.options().tools.size() << " tools, latent "
            << g.options().latent_dim << ", tanh " << hidden << ", " << g.options().yaw_harmonics
            << " yaw harmonics; sigma inflation "
            << (g.sigma_inflation() > 0 ? FormatFixed(g.sigma_inflation(), 3) : "none")
            << ", mode weight temperature "
            << (g.weight_temperature() > 0
                    ? FormatFixed(g.weight_temperature(), 3) +
                          (g.weight_temperature_on_likelihood() ? " on the likelihood"
                                                                : " on the whole evidence")
                    : std::string("none (1)"))
            << ", calibrated with "
            << (g.final_pixels() > 0 ? "a final stage on " + std::to_string(g.final_pixels()) +
                                           " pixels"
                                     : std::string("no final stage"))
            << "\n";
  return {{"tools", g.options().tools},
          {"latent_dim", g.options().latent_dim},
          {"hidden_sizes", g.options().hidden_sizes},
          {"yaw_harmonics", g.options().yaw_harmonics},
          {"sigma_inflation", g.sigma_inflation()},
          {"weight_temperature", g.weight_temperature()},
          {"weight_temperature_on",
           g.weight_temperature_on_likelihood() ? "likelihood" : "evidence"},
          {"final_pixels", g.final_pixels()}};
}

// Any tactfunc file: the container's facts, then those of its kind (parsed from the same
// bytes, read once). The checksum is checked first, so a damaged file fails here with
// the reason.
void DescribeFile(const std::string& path, bool json) {
  const std::string content = ReadFile(path);
  const TensorFile file = TensorFile::Parse(content, path);
  const nlohmann::json meta = nlohmann::json::parse(file.meta_json());
  std::uint64_t tensor_bytes = 0;
  for (const TensorFile::Tensor& t : file.tensors()) {
    tensor_bytes += static_cast<std::uint64_t>(t.numel()) * ElementBytes(t.dtype);
  }
  const std::uint64_t bytes = content.size();
  const double version = NumberAt(meta, "version");
  std::cout << path << ": " << file.kind() << " file, format " << StringAt(meta, "format")
            << " version " << FormatFixed(version, 0) << ", " << FormatBytes(bytes) << " ("
            << file.tensors().size() << " tensors, " << FormatBytes(tensor_bytes)
            << "), checksum " << file.checksum() << " (verified)\n";
  nlohmann::json out = {{"file", path},
                        {"kind", file.kind()},
                        {"format", StringAt(meta, "format")},
                        {"version", CountOrNull(version)},
                        {"bytes", bytes},
                        {"tensors", file.tensors().size()},
                        {"checksum", file.checksum()}};
  if (file.kind() == "model") {
    out["model"] = DescribeModel(content, path);
  } else if (file.kind() == "functaset") {
    out["functaset"] = DescribeFunctaset(content, path);
  } else if (file.kind() == "pose_model") {
    out["pose_model"] = DescribePoseModel(content, path);
  } else if (file.kind() == "pose_generator") {
    out["pose_generator"] = DescribePoseGenerator(content, path);
  } else if (file.kind() == "checkpoint") {
    // A checkpoint of estimation/training/internal/checkpoint.h: the trainers' (trunk,
    // photometric, pose generator) or a latent refit's, told apart by its format.
    const std::string sensor = StringAt(meta, "sensor");
    const std::string format = StringAt(meta, "format");
    const double step = NumberAt(meta, "step"), seconds = NumberAt(meta, "train_seconds");
    std::string stage;
    if (format == "tactfunc-generator-checkpoint") {
      const auto options = meta.find("options");
      if (options != meta.end() && options->is_object()) stage = StringAt(*options, "stage");
      std::cout << "  pose generator, stage " << stage << ", at epoch " << FormatFixed(step, 0)
                << " after " << FormatFixed(seconds, 0)
                << " s of training; the same train-generator command plus --resume continues "
                   "it\n";
    } else if (format == "tactfunc-refit-checkpoint") {
      const auto frames = meta.find("frames");
      const double total = frames != meta.end() && frames->is_object()
                               ? NumberAt(*frames, "count")
                               : std::numeric_limits<double>::quiet_NaN();
      std::cout << "  " << sensor << " latents re-fitted: the first " << FormatFixed(step, 0)
                << " of " << FormatFixed(total, 0) << " entries after " << FormatFixed(seconds, 0)
                << " s; the same train-pose command plus --resume continues it\n";
    } else {
      std::cout << "  " << sensor << " trunk at step " << FormatFixed(step, 0) << " after "
                << FormatFixed(seconds, 0)
                << " s of training; the same train command plus --resume "
                << "continues it (with a larger --steps to extend a finished run)\n";
    }
    out["checkpoint"] = {{"format", format},
                         {"sensor", sensor},
                         {"step", CountOrNull(step)},
                         {"train_seconds", NumberOrNull(seconds)}};
    if (!stage.empty()) out["checkpoint"]["stage"] = stage;
  }
  if (json) EmitJson(out);
}

void RunInfo(const InfoFlags& flags) {
  if (flags.tools) {
    PrintTools(flags.json);
    return;
  }
  if (flags.dir.empty()) {
    throw UsageError("a dataset folder or a tactfunc file is required (or --tools)");
  }
  if (IsTensorFile(flags.dir)) {
    DescribeFile(flags.dir, flags.json);
    return;
  }
  const Dataset dataset = OpenDataset(flags.dir, flags.data);
  nlohmann::json sensors = nlohmann::json::object();
  std::cout << "dataset " << dataset.root() << "\n";
  for (SensorKind sensor : dataset.sensors()) {
    const SensorInfo& info = dataset.sensor_info(sensor);
    const auto all = dataset.FrameIndices(sensor);
    const auto train = dataset.FrameIndices(sensor, Split::kTrain);
    const auto test = dataset.FrameIndices(sensor, Split::kTest);
    std::map<std::string, int> tools;
    int labelled = 0;
    for (std::size_t i : all) {
      const FrameRecord& record = dataset.frames()[i];
      if (record.label) {
        ++labelled;
        ++tools[record.label->tool];
      }
    }
    std::printf("  %-8s %5zu frames (%zu train, %zu test, %d labelled)  %dx%dx%d %s",
                ToString(sensor), all.size(), train.size(), test.size(), labelled,
                info.rows, info.cols, info.channels, ToString(info.encoding));
    if (info.pixel_pitch_m > 0) {
      std::printf("  %.3f mm/px (%.1f x %.1f mm)", info.pixel_pitch_m * 1e3,
                  info.cols * info.pixel_pitch_m * 1e3, info.rows * info.pixel_pitch_m * 1e3);
    }
    std::printf("\n");
    const SensorDescription described = DataSensorDescription(info);
    std::cout << "           sensor " << DescribeSensor(described) << " ("
              << (info.description ? info.description_path : std::string("built in")) << ")\n";
    nlohmann::json tool_counts = nlohmann::json::object();
    for (const auto& [tool, count] : tools) tool_counts[tool] = count;
    sensors[ToString(sensor)] = {{"frames", all.size()},
                                 {"train", train.size()},
                                 {"test", test.size()},
                                 {"labelled", labelled},
                                 {"rows", info.rows},
                                 {"cols", info.cols},
                                 {"channels", info.channels},
                                 {"encoding", ToString(info.encoding)},
                                 {"pixel_pitch_m", info.pixel_pitch_m},
                                 {"sensor_description",
                                  nlohmann::json::parse(SensorDescriptionToJson(described))},
                                 {"sensor_description_file", info.description_path},
                                 {"tools", tool_counts}};
  }
  if (!dataset.clips().empty()) {
    int train = 0, test = 0;
    for (const ClipInfo& clip : dataset.clips()) {
      if (clip.split) ++(*clip.split == Split::kTest ? test : train);
    }
    int videos = 0;
    for (const ClipInfo& clip : dataset.clips()) videos += clip.video ? 1 : 0;
    std::printf("  clips: %zu (%d videos, %zu folders)", dataset.clips().size(), videos,
                dataset.clips().size() - videos);
    if (train + test > 0) std::printf(", clips.csv: %d train, %d test", train, test);
    std::printf("\n");
  }
  const std::uint64_t bytes = dataset.BytesOnDisk();
  std::cout << "  tools: ";
  std::map<std::string, int> all_tools;
  for (const FrameRecord& record : dataset.frames()) {
    if (record.label) all_tools[record.label->tool]++;
  }
  bool first = true;
  for (const auto& [tool, count] : all_tools) {
    std::cout << (first ? "" : ", ") << tool;
    first = false;
  }
  if (all_tools.empty()) std::cout << "(no labels)";
  std::cout << "\n  bytes on disk: " << FormatBytes(bytes) << " (" << bytes << ")"
            << (dataset.has_clean() ? ", including noise-free copies" : "") << "\n";
  if (flags.json) {
    EmitJson({{"dir", dataset.root()},
              {"sensors", sensors},
              {"clips", dataset.clips().size()},
              {"tools", all_tools.size()},
              {"bytes", bytes},
              {"has_clean", dataset.has_clean()}});
  }
}

}  // namespace

void RegisterInfo(CLI::App& app, CommandBody* selected) {
  auto flags = std::make_shared<InfoFlags>();
  CLI::App* sub = app.add_subcommand(
      "info",
      "Summarise a dataset (counts, resolutions, tools, bytes on disk) or a tactfunc file "
      "(model, functaset, pose model, checkpoint: kind, version, size, what it holds).");
  sub->add_option("dir", flags->dir,
                  "Dataset folder (ours or your own, see docs/DATASET_FORMAT.md), or a tactfunc "
                  "file (.tfm, .tfs, .tpm, .ckpt, .knn)");
  AddDatasetFlags(sub, &flags->data);
  sub->add_flag("--tools", flags->tools, "List the simulator's tools and symmetries");
  sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
  sub->callback([flags, selected]() { *selected = [flags]() { RunInfo(*flags); }; });
}

}  // namespace tactfunc::apps
