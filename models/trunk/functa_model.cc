// Copyright 2026 The tactfunc Authors.
#include "models/trunk/functa_model.h"

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "models/core/atomic_file.h"
#include "models/core/tensor_file.h"
#include "nlohmann/json.hpp"

namespace tactfunc {
namespace {

constexpr const char* kFormat = "tactfunc-model";
constexpr int kVersion = 1;
// How z and A split with spatial latents (models/trunk/latent_modulated_siren.h): z = [z_g,
// the grid's node latents node-major], A = [A_g | A_s]. Recorded with the grid; a file
// naming another layout is refused.
constexpr const char* kSpatialLayout = "z=[global,grid node-major row-major]; A=[A_g|A_s]";

// A matrix's values row after row (a warm-start table: one training frame after another),
// and back.
using RowMajorMatrixXd = Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;
std::vector<double> RowMajorValues(const Eigen::MatrixXf& m) {
  const RowMajorMatrixXd rows = m.cast<double>();
  return std::vector<double>(rows.data(), rows.data() + rows.size());
}
Eigen::MatrixXf FromRowMajorValues(const std::vector<double>& values, std::int64_t rows,
                                   std::int64_t cols) {
  return Eigen::Map<const RowMajorMatrixXd>(values.data(), rows, cols).cast<float>();
}

std::vector<double> ToVector(const Eigen::VectorXd& v) {
  return std::vector<double>(v.data(), v.data() + v.size());
}

}  // namespace

bool FrameFormat::IsValid(std::string* error) const {
  if (rows <= 0 || cols <= 0) {
    *error = "FrameFormat::rows and cols must be > 0, got " + std::to_string(rows) + "x" +
             std::to_string(cols);
    return false;
  }
  if (!per_image_min_max && !(scale > 0 && std::isfinite(scale))) {
    *error = "FrameFormat::scale must be > 0 and finite for fixed-scale normalisation, got " +
             std::to_string(scale);
    return false;
  }
  return true;
}

void FunctaModel::SetTrunk(SensorTrunk trunk) {
  std::string error;
  if (!trunk.format.IsValid(&error)) throw std::invalid_argument(error);
  if (trunk.alpha.size() != trunk.siren.latent_dim()) {
    throw std::invalid_argument("FunctaModel: alpha has " + std::to_string(trunk.alpha.size()) +
                                " entries, expected latent_dim = " +
                                std::to_string(trunk.siren.latent_dim()));
  }
  if (!trunk.meta_sgd.IsValid(&error)) throw std::invalid_argument(error);
  if (trunk.photometric != nullptr &&
      trunk.photometric->siren().parameters() != trunk.siren.parameters()) {
    throw std::invalid_argument("FunctaModel: the photometric head's SIREN is not the trunk's");
  }
  for (SensorTrunk& existing : trunks_) {
    if (existing.sensor == trunk.sensor) {
      existing = std::move(trunk);
      return;
    }
  }
  trunks_.push_back(std::move(trunk));
  std::sort(trunks_.begin(), trunks_.end(),
            [](const SensorTrunk& a, const SensorTrunk& b) { return a.sensor < b.sensor; });
}

int TrunkLatentDim(const SensorTrunk& trunk) {
  return trunk.photometric != nullptr ? trunk.photometric->latent_dim()
                                      : trunk.siren.latent_dim();
}

int TrunkOutputChannels(const SensorTrunk& trunk) {
  return trunk.photometric != nullptr ? trunk.photometric->channels()
                                      : trunk.siren.output_channels();
}

Eigen::MatrixXf TrunkDecode(const SensorTrunk& trunk, const Eigen::VectorXf& latent,
                            const PhotometricTrunk::Markers* markers) {
  if (latent.size() != TrunkLatentDim(trunk)) {
    throw std::invalid_argument("TrunkDecode: expected a latent of " +
                                std::to_string(TrunkLatentDim(trunk)) + " values, found " +
                                std::to_string(latent.size()));
  }
  if (trunk.photometric != nullptr) {
    return trunk.photometric->Forward<float>(trunk.photometric->AllPixels(), latent, markers);
  }
  return trunk.siren.Forward<float>(trunk.siren.Grid<float>(trunk.format.rows, trunk.format.cols),
                                    latent);
}

std::uint64_t TrunkParameterBytes(const SensorTrunk& trunk) {
  std::uint64_t values = static_cast<std::uint64_t>(trunk.siren.NumParameters()) +
                         static_cast<std::uint64_t>(trunk.alpha.size());
  if (trunk.photometric != nullptr) {
    values += static_cast<std::uint64_t>(trunk.photometric->NumHeadParameters()) +
              trunk.photometric->reference().size() + trunk.photometric->background().size() +
              static_cast<std::uint64_t>(trunk.photometric->lighting().size());
  }
  std::uint64_t bytes = 4ull * values;
  if (trunk.siren.has_readout()) {  // the readout basis is stored in float16
    bytes -= 2ull * static_cast<std::uint64_t>(
                        trunk.siren.Block(ParameterGroup::kReadoutBasis).size());
  }
  if (trunk.warm_start != nullptr) {  // float16
    bytes += 2ull * static_cast<std::uint64_t>(trunk.warm_start->descriptors.size() +
                                               trunk.warm_start->latents.size());
  }
  return bytes;
}

SensorDescription TrunkSensorDescription(const SensorTrunk& trunk) {
  if (trunk.description) return *trunk.description;
  SensorDescription d = BuiltInSensorDescription(trunk.sensor);
  d.working_rows = trunk.format.rows;
  d.working_cols = trunk.format.cols;
  d.aspect = SensorDescription::Aspect::kStretch;
  // Without grayscale the trunk outputs the frames' channels; with it they are unknown
  // and the kind's are assumed.
  if (!trunk.format.grayscale) d.channels = trunk.siren.options().output_channels;
  // A fixed-scale trunk normalised by its format's scale, the data's unless a preset
  // overrode it: the best statement of the scale the model has.
  if (!trunk.format.per_image_min_max && trunk.format.scale > 0) {
    d.normalization_scale = trunk.format.scale;
  }
  return d;
}

bool FunctaModel::HasSensor(SensorKind sensor) const {
  return std::any_of(trunks_.begin(), trunks_.end(),
                     [&](const SensorTrunk& t) { return t.sensor == sensor; });
}

const SensorTrunk& FunctaModel::Trunk(SensorKind sensor) const {
  for (const SensorTrunk& t : trunks_) {
    if (t.sensor == sensor) return t;
  }
  throw std::invalid_argument(std::string("the model has no trunk for sensor '") +
                              ToString(sensor) + "'");
}

SensorTrunk& FunctaModel::MutableTrunk(SensorKind sensor) {
  return const_cast<SensorTrunk&>(static_cast<const FunctaModel*>(this)->Trunk(sensor));
}

std::vector<SensorKind> FunctaModel::sensors() const {
  std::vector<SensorKind> out;
  for (const SensorTrunk& t : trunks_) out.push_back(t.sensor);
  return out;
}

void FunctaModel::set_info_json(const std::string& json) {
  const nlohmann::json parsed = nlohmann::json::parse(json);
  if (!parsed.is_object()) throw std::invalid_argument("FunctaModel info must be a JSON object");
  info_json_ = parsed.dump();
}

std::string FunctaModel::Serialize() const {
  TensorFile file("model");
  nlohmann::json meta;
  meta["format"] = kFormat;
  meta["version"] = kVersion;
  meta["trunks"] = nlohmann::json::array();
  for (const SensorTrunk& t : trunks_) {
    const auto& o = t.siren.options();
    const std::string name = ToString(t.sensor);
    nlohmann::json siren = {{"width", o.width},
                            {"num_hidden_layers", o.num_hidden_layers},
                            {"omega_0", o.omega_0},
                            {"latent_dim", o.latent_dim},
                            {"output_channels", o.output_channels},
                            {"coordinates", ToString(o.coordinates)}};
    // Written only when present, so a trunk without the branch keeps the bytes it had.
    // The readout basis is stored apart, in float16 ("basis": "float16"; theta then holds
    // every other parameter): a PCA-like basis of unit-norm columns keeps 11 significant
    // bits, and a d = 256 trunk's file halves (its basis is 96% of the parameters).
    if (o.has_readout()) {
      siren["readout"] = {{"rows", o.readout_rows}, {"cols", o.readout_cols}, {"basis", "float16"}};
    }
    if (o.has_spatial()) {
      siren["spatial"] = {{"rows", o.spatial_rows},
                          {"cols", o.spatial_cols},
                          {"channels", o.spatial_channels},
                          {"global_latent_dim", o.global_latent_dim()},
                          {"layout", kSpatialLayout}};
    }
    meta["trunks"].push_back(
        {{"sensor", name},
         {"siren", siren},
         {"frame_format",
          {{"rows", t.format.rows},
           {"cols", t.format.cols},
           {"grayscale", t.format.grayscale},
           {"normalization", t.format.per_image_min_max ? "per_image_min_max" : "fixed_scale"},
           {"scale", t.format.scale}}},
         {"meta_sgd",
          {{"inner_steps", t.meta_sgd.inner_steps},
           {"latent_l2_weight", t.meta_sgd.latent_l2_weight},
           {"first_order", t.meta_sgd.first_order}}},
         {"residual_sigma", t.residual_sigma}});
    // Written only when present, so a trunk without one keeps the bytes it had.
    if (!t.default_fit.empty()) meta["trunks"].back()["default_fit"] = t.default_fit;
    if (t.description) {
      meta["trunks"].back()["sensor_description"] =
          nlohmann::json::parse(SensorDescriptionToJson(*t.description));
    }
    if (t.photometric != nullptr) {
      const PhotometricTrunk& p = *t.photometric;
      const Image& ref = p.reference();
      meta["trunks"].back()["photometric"] = {
          {"latent_dim", p.latent_dim()},
          {"shading_width", p.options().shading_width},
          {"supersample", p.options().supersample},
          {"reference", {{"rows", ref.rows}, {"cols", ref.cols}, {"channels", ref.channels}}}};
      file.Add(name + "/head", TensorFile::DType::kFloat32, {p.NumHeadParameters()},
               ToVector(p.head_parameters()));
      file.Add(name + "/reference", TensorFile::DType::kFloat32,
               {static_cast<std::int64_t>(ref.size())},
               std::vector<double>(ref.data.begin(), ref.data.end()));
      // Written only when present, so a trunk without one keeps the bytes it had.
      if (!p.background().empty()) {
        const Image& b = p.background();
        meta["trunks"].back()["photometric"]["background"] = true;
        file.Add(name + "/background", TensorFile::DType::kFloat32,
                 {static_cast<std::int64_t>(b.size())},
                 std::vector<double>(b.data.begin(), b.data.end()));
      }
      // Likewise the lighting images: their count, then (rows cols C) x K values.
      if (p.lighting_components() > 0) {
        const Eigen::MatrixXf& l = p.lighting();
        meta["trunks"].back()["photometric"]["lighting_components"] = p.lighting_components();
        file.Add(name + "/lighting", TensorFile::DType::kFloat32,
                 {static_cast<std::int64_t>(l.cols()), static_cast<std::int64_t>(l.rows())},
                 std::vector<double>(l.data(), l.data() + l.size()));
      }
      if (t.warm_start != nullptr) {
        const WarmStartTable& w = *t.warm_start;
        meta["trunks"].back()["photometric"]["warm_start"] = {{"rows", w.descriptors.rows()},
                                                              {"grid", w.grid},
                                                              {"extent", w.extent},
                                                              {"supersample", w.supersample}};
        file.Add(name + "/warm_start/descriptors", TensorFile::DType::kFloat16,
                 {w.descriptors.rows(), w.descriptors.cols()}, RowMajorValues(w.descriptors));
        file.Add(name + "/warm_start/latents", TensorFile::DType::kFloat16,
                 {w.latents.rows(), w.latents.cols()}, RowMajorValues(w.latents));
      }
    }
    if (o.has_readout()) {
      const ParameterBlock& basis = t.siren.Block(ParameterGroup::kReadoutBasis);
      const std::vector<double> all = ToVector(t.siren.parameters());
      std::vector<double> rest(all.begin(), all.begin() + basis.offset);
      rest.insert(rest.end(), all.begin() + basis.offset + basis.size(), all.end());
      const auto rest_size = static_cast<std::int64_t>(rest.size());
      file.Add(name + "/theta", TensorFile::DType::kFloat32, {rest_size}, std::move(rest));
      file.Add(name + "/readout_basis", TensorFile::DType::kFloat16, {basis.size()},
               std::vector<double>(all.begin() + basis.offset,
                                   all.begin() + basis.offset + basis.size()));
    } else {
      file.Add(name + "/theta", TensorFile::DType::kFloat32, {t.siren.NumParameters()},
               ToVector(t.siren.parameters()));
    }
    file.Add(name + "/alpha", TensorFile::DType::kFloat32, {t.alpha.size()}, ToVector(t.alpha));
    if (t.siren.start_gains().size() != 0) {
      file.Add(name + "/start_gains", TensorFile::DType::kFloat32, {t.siren.start_gains().size()},
               ToVector(t.siren.start_gains()));
    }
  }
  meta["info"] = nlohmann::json::parse(info_json_);
  file.set_meta_json(meta.dump());
  std::string bytes = file.Serialize();
  checksum_ = file.checksum();
  return bytes;
}

void FunctaModel::Save(const std::string& path) const {
  WriteFileAtomically(path, Serialize());
}

FunctaModel FunctaModel::Parse(const std::string& bytes, const std::string& source) {
  return FromTensorFile(TensorFile::Parse(bytes, source, "model"), source);
}

FunctaModel FunctaModel::FromTensorFile(const TensorFile& file, const std::string& source) {
  FunctaModel model;
  file.CheckFormat(kFormat, kVersion);
  std::string field = "meta";
  try {
    const nlohmann::json meta = nlohmann::json::parse(file.meta_json());
    for (const auto& entry : meta.at("trunks")) {
      SensorTrunk trunk;
      field = "trunks[].sensor";
      const std::string name = entry.at("sensor").get<std::string>();
      if (!SensorKindFromString(name, &trunk.sensor)) {
        throw TensorFileError(source + ": field 'trunks[].sensor': unknown sensor '" + name + "'");
      }
      field = name + ".siren";
      const auto& s = entry.at("siren");
      LatentModulatedSiren::Options options;
      bool basis_apart = false;  // the readout basis in its own float16 tensor
      options.width = s.at("width").get<int>();
      options.num_hidden_layers = s.at("num_hidden_layers").get<int>();
      options.omega_0 = s.at("omega_0").get<double>();
      options.latent_dim = s.at("latent_dim").get<int>();
      options.output_channels = s.at("output_channels").get<int>();
      if (!CoordinateConventionFromString(s.at("coordinates").get<std::string>(),
                                          &options.coordinates)) {
        throw TensorFileError(source + ": field '" + field + ".coordinates': unknown convention");
      }
      if (s.contains("readout")) {  // absent in files written before the readout branch
        field = name + ".siren.readout";
        options.readout_rows = s.at("readout").at("rows").get<int>();
        options.readout_cols = s.at("readout").at("cols").get<int>();
        if (s.at("readout").contains("basis")) {  // absent: the basis is in theta, float32
          field = name + ".siren.readout.basis";
          const std::string basis = s.at("readout").at("basis").get<std::string>();
          if (basis != "float16") {
            throw TensorFileError(source + ": field '" + field + "': expected \"float16\", got \"" +
                                  basis + "\"");
          }
          basis_apart = true;
        }
        field = name + ".siren";
      }
      if (s.contains("spatial")) {  // absent in files written before spatial latents
        field = name + ".siren.spatial";
        const auto& grid = s.at("spatial");
        options.spatial_rows = grid.at("rows").get<int>();
        options.spatial_cols = grid.at("cols").get<int>();
        options.spatial_channels = grid.at("channels").get<int>();
        const std::string layout = grid.at("layout").get<std::string>();
        if (layout != kSpatialLayout) {
          throw TensorFileError(source + ": field '" + field + ".layout': unknown layout '" +
                                layout + "', expected '" + kSpatialLayout + "'");
        }
        std::string error;
        if (!options.IsValid(&error)) throw TensorFileError(source + ": " + field + ": " + error);
        const int global = grid.at("global_latent_dim").get<int>();
        if (global != options.global_latent_dim()) {
          throw TensorFileError(source + ": field '" + field + ".global_latent_dim': " +
                                std::to_string(global) + " does not match latent_dim - rows * "
                                "cols * channels = " +
                                std::to_string(options.global_latent_dim()));
        }
        field = name + ".siren";
      }
      std::string error;
      if (!options.IsValid(&error)) throw TensorFileError(source + ": " + field + ": " + error);
      trunk.siren = LatentModulatedSiren(options);
      field = name + ".frame_format";
      const auto& f = entry.at("frame_format");
      trunk.format.rows = f.at("rows").get<int>();
      trunk.format.cols = f.at("cols").get<int>();
      trunk.format.grayscale = f.at("grayscale").get<bool>();
      const std::string normalization = f.at("normalization").get<std::string>();
      if (normalization != "fixed_scale" && normalization != "per_image_min_max") {
        throw TensorFileError(source + ": field '" + field +
                              ".normalization': expected fixed_scale or per_image_min_max, got '" +
                              normalization + "'");
      }
      trunk.format.per_image_min_max = normalization == "per_image_min_max";
      trunk.format.scale = f.at("scale").get<double>();
      if (!trunk.format.IsValid(&error)) throw TensorFileError(source + ": " + field + ": " + error);
      field = name + ".meta_sgd";
      const auto& m = entry.at("meta_sgd");
      trunk.meta_sgd.inner_steps = m.at("inner_steps").get<int>();
      trunk.meta_sgd.latent_l2_weight = m.at("latent_l2_weight").get<double>();
      trunk.meta_sgd.first_order = m.at("first_order").get<bool>();
      if (!trunk.meta_sgd.IsValid(&error)) throw TensorFileError(source + ": " + field + ": " + error);
      field = name + ".residual_sigma";
      trunk.residual_sigma = entry.at("residual_sigma").get<double>();
      if (entry.contains("default_fit")) {  // absent: the encoder's rule
        field = name + ".default_fit";
        trunk.default_fit = entry.at("default_fit").get<std::string>();
        // Its meaning is the fitting layer's (checked where a fit is built); here only
        // that it can be a strategy's name.
        const bool name_like =
            !trunk.default_fit.empty() && trunk.default_fit.size() <= 64 &&
            std::all_of(trunk.default_fit.begin(), trunk.default_fit.end(), [](char c) {
              return (c >= 'a' && c <= 'z') || (c >= '0' && c <= '9') || c == '+' || c == ':' ||
                     c == '_';
            });
        if (!name_like) {
          throw TensorFileError(source + ": field '" + field + "': expected a fitting "
                                "strategy's name such as knn+adam:400, got '" +
                                trunk.default_fit + "'");
        }
      }
      if (entry.contains("sensor_description")) {  // absent in files written before
        field = name + ".sensor_description";
        try {
          trunk.description = ParseSensorDescription(entry.at("sensor_description").dump(),
                                                     source + " (" + field + ")",
                                                     /*allow_unknown_pitch=*/true);
        } catch (const SensorDescriptionError& e) {
          throw TensorFileError(e.what());
        }
        if (trunk.description->kind != trunk.sensor) {
          throw TensorFileError(source + ": field '" + field + ".kind': expected " +
                                SensorKindDescriptionName(trunk.sensor) + " for the " + name +
                                " trunk, got " + SensorKindDescriptionName(trunk.description->kind));
        }
      }
      if (basis_apart) {
        // theta without the basis block, and the basis from its own tensor.
        const ParameterBlock& block = trunk.siren.Block(ParameterGroup::kReadoutBasis);
        const auto& rest = file.Get(name + "/theta", {trunk.siren.NumParameters() - block.size()});
        const auto& basis = file.Get(name + "/readout_basis", {block.size()});
        if (basis.dtype != TensorFile::DType::kFloat16) {
          throw TensorFileError(source + ": tensor '" + name +
                                "/readout_basis': expected float16, got " + ToString(basis.dtype));
        }
        Eigen::VectorXd theta(trunk.siren.NumParameters());
        const auto offset = static_cast<std::ptrdiff_t>(block.offset);
        std::copy(rest.values.begin(), rest.values.begin() + offset, theta.data());
        std::copy(basis.values.begin(), basis.values.end(), theta.data() + offset);
        std::copy(rest.values.begin() + offset, rest.values.end(),
                  theta.data() + offset + block.size());
        trunk.siren.SetParameters(theta);
      } else {
        const auto& theta = file.Get(name + "/theta", {trunk.siren.NumParameters()});
        trunk.siren.SetParameters(Eigen::Map<const Eigen::VectorXd>(theta.values.data(),
                                                                    theta.values.size()));
      }
      const auto& alpha = file.Get(name + "/alpha", {options.latent_dim});
      trunk.alpha = Eigen::Map<const Eigen::VectorXd>(alpha.values.data(), alpha.values.size());
      if (file.Has(name + "/start_gains")) {  // absent: no gains (files before them)
        field = name + "/start_gains";
        if (!trunk.siren.has_readout()) {
          throw TensorFileError(source + ": tensor '" + field +
                                "': start gains belong to a trunk with the readout branch");
        }
        const auto& gains = file.Get(field, {options.latent_dim});
        trunk.siren.set_start_gains(
            Eigen::Map<const Eigen::VectorXd>(gains.values.data(), gains.values.size()));
      }
      if (entry.contains("photometric")) {  // absent for direct trunks
        field = name + ".photometric";
        const auto& p = entry.at("photometric");
        PhotometricTrunk::Options po;
        po.rows = trunk.format.rows;
        po.cols = trunk.format.cols;
        po.channels = options.output_channels - 1;
        po.width = options.width;
        po.num_hidden_layers = options.num_hidden_layers;
        po.omega_0 = options.omega_0;
        po.latent_dim = p.at("latent_dim").get<int>();
        po.shading_width = p.at("shading_width").get<int>();
        po.supersample = p.at("supersample").get<int>();
        if (p.contains("lighting_components")) {
          field = name + ".photometric.lighting_components";
          if (!p.at("lighting_components").is_number_integer()) {
            throw TensorFileError(source + ": field '" + field + "': expected an integer");
          }
          po.lighting_components = p.at("lighting_components").get<int>();
          field = name + ".photometric";
        }
        if (!po.IsValid(&error) || po.latent_dim - PhotometricTrunk::kPoseValues -
                                           po.lighting_components !=
                                       options.latent_dim) {
          throw TensorFileError(
              source + ": " + field + ": " +
              (error.empty() ? "latent_dim must be the SIREN's + " +
                                   std::to_string(PhotometricTrunk::kPoseValues) +
                                   " + lighting_components"
                             : error));
        }
        field = name + ".photometric.reference";
        const auto& r = p.at("reference");
        const int rows = r.at("rows").get<int>(), cols = r.at("cols").get<int>();
        const int channels = r.at("channels").get<int>();
        if (rows < 1 || cols < 1 || rows > 100000 || cols > 100000 || channels != po.channels) {
          throw TensorFileError(source + ": field '" + field + "': expected a reference of at "
                                "least 1 x 1 with " + std::to_string(po.channels) +
                                " channel(s), found " + std::to_string(rows) + " x " +
                                std::to_string(cols) + " x " + std::to_string(channels));
        }
        // The tensors' shapes are checked before anything of their size is allocated:
        // a file holds the values it claims, so no field can ask for more memory.
        const auto& values = file.Get(
            name + "/reference", {static_cast<std::int64_t>(rows) * cols * channels});
        const auto& head = file.Get(
            name + "/head", {PhotometricTrunk::HeadParameterCount(po.shading_width, po.channels)});
        Image reference(rows, cols, channels);
        for (std::size_t i = 0; i < reference.size(); ++i) {
          reference.data[i] = static_cast<float>(values.values[i]);
        }
        auto photometric = std::make_shared<PhotometricTrunk>(po, reference);
        photometric->mutable_siren().SetParameters(trunk.siren.parameters());
        photometric->SetHeadParameters(
            Eigen::Map<const Eigen::VectorXd>(head.values.data(), head.values.size()));
        // The trunk's own checks of a table (finite values), their errors named after the
        // file and the tensor.
        const auto set_table = [&](const std::string& tensor, const auto& set) {
          try {
            set();
          } catch (const std::invalid_argument& e) {
            throw TensorFileError(source + ": tensor '" + name + "/" + tensor + "': " +
                                  e.what());
          }
        };
        if (p.contains("background")) {
          field = name + ".photometric.background";
          if (!p.at("background").is_boolean()) {
            throw TensorFileError(source + ": field '" + field + "': expected true or false");
          }
          if (p.at("background").get<bool>()) {
            const auto& b = file.Get(name + "/background",
                                     {static_cast<std::int64_t>(po.rows) * po.cols * po.channels});
            Image background(po.rows, po.cols, po.channels);
            for (std::size_t i = 0; i < background.size(); ++i) {
              background.data[i] = static_cast<float>(b.values[i]);
            }
            set_table("background", [&] { photometric->SetBackground(background); });
          }
        }
        if (po.lighting_components > 0) {
          const auto& l = file.Get(name + "/lighting",
                                   {static_cast<std::int64_t>(po.lighting_components),
                                    static_cast<std::int64_t>(po.rows) * po.cols * po.channels});
          Eigen::MatrixXf lighting(static_cast<Eigen::Index>(po.rows) * po.cols * po.channels,
                                   po.lighting_components);
          for (Eigen::Index i = 0; i < lighting.size(); ++i) {
            lighting.data()[i] = static_cast<float>(l.values[static_cast<std::size_t>(i)]);
          }
          set_table("lighting", [&] { photometric->SetLighting(lighting); });
        }
        if (p.contains("warm_start")) {
          field = name + ".photometric.warm_start";
          const auto& w = p.at("warm_start");
          auto table = std::make_shared<WarmStartTable>();
          const std::int64_t rows = w.at("rows").get<std::int64_t>();
          table->grid = w.at("grid").get<int>();
          table->extent = w.at("extent").get<double>();
          table->supersample = w.at("supersample").get<int>();
          if (rows < 1 || rows > 10000000 || table->grid < 1 || table->grid > 64 ||
              !(table->extent > 0) || !std::isfinite(table->extent) || table->supersample < 1 ||
              table->supersample > 8) {
            throw TensorFileError(source + ": field '" + field + "': expected rows in [1, 1e7], "
                                  "grid in [1, 64], extent > 0 and supersample in [1, 8]");
          }
          const std::int64_t columns =
              static_cast<std::int64_t>(table->grid) * table->grid * po.channels;
          const auto& descriptors = file.Get(name + "/warm_start/descriptors", {rows, columns});
          const auto& latents = file.Get(name + "/warm_start/latents", {rows, po.latent_dim});
          table->descriptors = FromRowMajorValues(descriptors.values, rows, columns);
          table->latents = FromRowMajorValues(latents.values, rows, po.latent_dim);
          trunk.warm_start = std::move(table);
        }
        trunk.photometric = std::move(photometric);
      }
      model.SetTrunk(std::move(trunk));
    }
    field = "info";
    model.info_json_ = meta.at("info").dump();
  } catch (const nlohmann::json::exception& e) {
    throw TensorFileError(source + ": field '" + field + "' is missing or has the wrong type (" +
                          e.what() + ")");
  }
  model.checksum_ = file.checksum();
  return model;
}

FunctaModel FunctaModel::Load(const std::string& path) {
  return FromTensorFile(TensorFile::Read(path, "model"), path);
}

std::uint64_t FunctaModel::ParameterBytes() const {
  std::uint64_t bytes = 0;
  for (const SensorTrunk& t : trunks_) bytes += TrunkParameterBytes(t);
  return bytes;
}

}  // namespace tactfunc
