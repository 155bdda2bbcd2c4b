// Copyright 2026 The tactfunc Authors.
#include "models/trunk/functa_model.h"

#include <cmath>
#include <filesystem>
#include <functional>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "models/core/tensor_file.h"
#include "nlohmann/json.hpp"

namespace tactfunc {
namespace {

using ::testing::HasSubstr;
using ::testing::Not;

SensorTrunk SmallTrunk(SensorKind sensor, std::uint64_t seed) {
  LatentModulatedSiren::Options options;
  options.width = 8;
  options.num_hidden_layers = 2;
  options.latent_dim = 4;
  SensorTrunk trunk;
  trunk.sensor = sensor;
  trunk.siren = LatentModulatedSiren(options, seed);
  trunk.alpha = Eigen::VectorXd::Constant(4, 0.25);
  trunk.format.rows = 10;
  trunk.format.cols = 12;
  trunk.format.scale = 0.015;
  trunk.format.grayscale = sensor == SensorKind::kGelSlim;
  trunk.residual_sigma = 0.02;
  return trunk;
}

FunctaModel TwoSensorModel() {
  FunctaModel model;
  model.SetTrunk(SmallTrunk(SensorKind::kGelSlim, 2));
  model.SetTrunk(SmallTrunk(SensorKind::kSoftBubble, 1));
  model.set_info_json(R"({"preset": "test"})");
  return model;
}

TEST(FunctaModel, RoundTripsEveryTrunkThroughItsFile) {
  const FunctaModel model = TwoSensorModel();
  const std::string path = (std::filesystem::path(testing::TempDir()) / "m.tfm").string();
  model.Save(path);
  const FunctaModel read = FunctaModel::Load(path);
  EXPECT_EQ(read.checksum(), model.checksum());
  ASSERT_EQ(read.sensors().size(), 2u);
  for (SensorKind sensor : {SensorKind::kSoftBubble, SensorKind::kGelSlim}) {
    const SensorTrunk& a = model.Trunk(sensor);
    const SensorTrunk& b = read.Trunk(sensor);
    // The file stores float32: parameters agree to float precision.
    EXPECT_TRUE(a.siren.parameters().cast<float>().cast<double>().isApprox(
        b.siren.parameters(), 0.0));
    EXPECT_EQ(b.alpha, a.alpha);
    EXPECT_EQ(b.format.rows, 10);
    EXPECT_EQ(b.format.grayscale, sensor == SensorKind::kGelSlim);
    EXPECT_EQ(b.residual_sigma, 0.02);
    EXPECT_EQ(b.meta_sgd.inner_steps, a.meta_sgd.inner_steps);
  }
  EXPECT_THAT(read.info_json(), HasSubstr("test"));
  EXPECT_EQ(read.ParameterBytes(), model.ParameterBytes());
}

TEST(FunctaModel, RoundTripsAReadoutTrunksStartGains) {
  SensorTrunk trunk = SmallTrunk(SensorKind::kSoftBubble, 3);
  LatentModulatedSiren::Options options = trunk.siren.options();
  options.readout_rows = trunk.format.rows;
  options.readout_cols = trunk.format.cols;
  trunk.siren = LatentModulatedSiren(options, 3);
  FunctaModel without;
  without.SetTrunk(trunk);
  const Eigen::VectorXd gains = (Eigen::VectorXd(4) << 1.0, 0.75, 0.5, 0.125).finished();
  trunk.siren.set_start_gains(gains);
  FunctaModel with;
  with.SetTrunk(trunk);
  const FunctaModel read = FunctaModel::Parse(with.Serialize(), "gains.tfm");
  EXPECT_EQ(read.Trunk(SensorKind::kSoftBubble).siren.start_gains(), gains);
  // A trunk without gains reads back without them, its file as before.
  const FunctaModel read_without = FunctaModel::Parse(without.Serialize(), "plain.tfm");
  EXPECT_EQ(read_without.Trunk(SensorKind::kSoftBubble).siren.start_gains().size(), 0);
  EXPECT_THAT(without.Serialize(), Not(HasSubstr("start_gains")));
}

// A readout trunk with a basis of varied values (the initial basis is zero).
SensorTrunk ReadoutTrunk() {
  SensorTrunk trunk = SmallTrunk(SensorKind::kSoftBubble, 3);
  LatentModulatedSiren::Options options = trunk.siren.options();
  options.readout_rows = trunk.format.rows;
  options.readout_cols = trunk.format.cols;
  trunk.siren = LatentModulatedSiren(options, 3);
  Eigen::VectorXd theta = trunk.siren.parameters();
  const ParameterBlock& basis = trunk.siren.Block(ParameterGroup::kReadoutBasis);
  for (int i = 0; i < basis.size(); ++i) theta[basis.offset + i] = 0.1 * std::sin(0.37 * i + 1);
  trunk.siren.SetParameters(theta);
  return trunk;
}

TEST(FunctaModel, AReadoutTrunksBasisIsStoredInFloat16AndOlderFilesStillLoad) {
  const SensorTrunk trunk = ReadoutTrunk();
  FunctaModel model;
  model.SetTrunk(trunk);
  const TensorFile file = TensorFile::Parse(model.Serialize(), "r.tfm", "model");
  const ParameterBlock& basis = trunk.siren.Block(ParameterGroup::kReadoutBasis);
  const int n = trunk.siren.NumParameters();
  EXPECT_EQ(file.Get("bubble/readout_basis", {basis.size()}).dtype,
            TensorFile::DType::kFloat16);
  EXPECT_EQ(file.Get("bubble/theta", {n - basis.size()}).dtype, TensorFile::DType::kFloat32);
  EXPECT_THAT(file.meta_json(), HasSubstr("\"basis\":\"float16\""));
  // The bytes as stored: the basis at 2 bytes a value, the rest at 4.
  EXPECT_EQ(TrunkParameterBytes(trunk),
            4u * static_cast<std::uint64_t>(n - basis.size() + trunk.alpha.size()) +
                2u * static_cast<std::uint64_t>(basis.size()));
  const Eigen::VectorXd& a = trunk.siren.parameters();
  const FunctaModel read = FunctaModel::Parse(file.Serialize(), "r.tfm");
  const Eigen::VectorXd& b = read.Trunk(SensorKind::kSoftBubble).siren.parameters();
  ASSERT_EQ(b.size(), n);
  for (int i = 0; i < n; ++i) {
    if (i >= basis.offset && i < basis.offset + basis.size()) {
      // float16: half a unit in the last of 11 bits, 2^-25 among its subnormals.
      EXPECT_NEAR(b[i], a[i], std::abs(a[i]) * std::pow(2.0, -11) + std::pow(2.0, -25)) << i;
    } else {
      EXPECT_EQ(b[i], static_cast<float>(a[i])) << i;  // float32, in place
    }
  }
  // The layout before: the whole flat vector in theta, no "basis" key.
  nlohmann::json meta = nlohmann::json::parse(file.meta_json());
  meta["trunks"][0]["siren"]["readout"].erase("basis");
  TensorFile older("model");
  older.set_meta_json(meta.dump());
  for (const TensorFile::Tensor& t : file.tensors()) {
    if (t.name == "bubble/theta") {
      older.Add(t.name, t.dtype, {n}, std::vector<double>(a.data(), a.data() + n));
    } else if (t.name != "bubble/readout_basis") {
      older.Add(t.name, t.dtype, t.shape, t.values);
    }
  }
  const FunctaModel read_older = FunctaModel::Parse(older.Serialize(), "old.tfm");
  const Eigen::VectorXd& c = read_older.Trunk(SensorKind::kSoftBubble).siren.parameters();
  for (int i = 0; i < n; ++i) EXPECT_EQ(c[i], static_cast<float>(a[i])) << i;
  // Another storage is refused, naming the field.
  meta["trunks"][0]["siren"]["readout"]["basis"] = "int8";
  TensorFile other("model");
  other.set_meta_json(meta.dump());
  for (const TensorFile::Tensor& t : file.tensors()) other.Add(t.name, t.dtype, t.shape, t.values);
  try {
    FunctaModel::Parse(other.Serialize(), "int8.tfm");
    ADD_FAILURE() << "expected TensorFileError";
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("int8.tfm"));
    EXPECT_THAT(e.what(), HasSubstr("readout.basis"));
  }
}

TEST(FunctaModel, RoundTripsASpatialLatentTrunkAndRecordsItsGrid) {
  SensorTrunk trunk = SmallTrunk(SensorKind::kSoftBubble, 3);
  LatentModulatedSiren::Options options = trunk.siren.options();
  options.spatial_rows = 2;
  options.spatial_cols = 3;
  options.spatial_channels = 2;
  options.latent_dim = 4 + 12;
  trunk.siren = LatentModulatedSiren(options, 3);
  trunk.alpha = Eigen::VectorXd::Constant(16, 0.5);
  FunctaModel model;
  model.SetTrunk(trunk);
  const std::string bytes = model.Serialize();
  const TensorFile file = TensorFile::Parse(bytes, "m.tfm", "model");
  EXPECT_THAT(file.meta_json(), HasSubstr("\"spatial\""));
  EXPECT_THAT(file.meta_json(), HasSubstr("\"global_latent_dim\":4"));
  const FunctaModel read = FunctaModel::Parse(bytes, "m.tfm");
  const LatentModulatedSiren::Options& o = read.Trunk(SensorKind::kSoftBubble).siren.options();
  EXPECT_EQ(o.spatial_rows, 2);
  EXPECT_EQ(o.spatial_cols, 3);
  EXPECT_EQ(o.spatial_channels, 2);
  EXPECT_EQ(o.latent_dim, 16);
  EXPECT_TRUE(trunk.siren.parameters().cast<float>().cast<double>().isApprox(
      read.Trunk(SensorKind::kSoftBubble).siren.parameters(), 0.0));
  // A trunk without spatial latents writes no key (older files load as before).
  EXPECT_THAT(TensorFile::Parse(TwoSensorModel().Serialize(), "m.tfm", "model").meta_json(),
              ::testing::Not(HasSubstr("spatial")));
  // Another layout, or a global part that does not add up, is refused naming the field.
  for (const auto& [from, to] :
       std::vector<std::pair<std::string, std::string>>{{"A=[A_g|A_s]", "A=[A_s|A_g]"},
                                                        {"\"global_latent_dim\":4",
                                                         "\"global_latent_dim\":5"}}) {
    std::string meta = file.meta_json();
    ASSERT_NE(meta.find(from), std::string::npos) << from;
    meta.replace(meta.find(from), from.size(), to);
    TensorFile edited("model");
    edited.set_meta_json(meta);
    for (const char* name : {"bubble/theta", "bubble/alpha"}) {
      const auto& tensor = file.Get(name);
      edited.Add(name, TensorFile::DType::kFloat32, tensor.shape, tensor.values);
    }
    try {
      FunctaModel::Parse(edited.Serialize(), "edited.tfm");
      FAIL() << to;
    } catch (const TensorFileError& e) {
      EXPECT_THAT(e.what(), HasSubstr("bubble.siren.spatial")) << e.what();
    }
  }
}

// The model file `bytes` with each tensor's values passed through edit(name, &values),
// which returns false to leave the tensor out; the meta JSON unchanged.
std::string WithTensorsEdited(
    const std::string& bytes,
    const std::function<bool(const std::string&, std::vector<double>*)>& edit) {
  const TensorFile file = TensorFile::Parse(bytes, "m.tfm", "model");
  TensorFile edited("model");
  edited.set_meta_json(file.meta_json());
  for (const TensorFile::Tensor& t : file.tensors()) {
    std::vector<double> values = t.values;
    if (edit(t.name, &values)) edited.Add(t.name, t.dtype, t.shape, values);
  }
  return edited.Serialize();
}

// The model file `bytes` with the first `from` of its meta JSON replaced by `to`, its
// tensors unchanged ("" if the meta has no `from`).
std::string WithMetaEdited(const std::string& bytes, const std::string& from,
                           const std::string& to) {
  const TensorFile file = TensorFile::Parse(bytes, "m.tfm", "model");
  std::string meta = file.meta_json();
  if (meta.find(from) == std::string::npos) return "";
  meta.replace(meta.find(from), from.size(), to);
  TensorFile edited("model");
  edited.set_meta_json(meta);
  for (const TensorFile::Tensor& t : file.tensors()) edited.Add(t.name, t.dtype, t.shape, t.values);
  return edited.Serialize();
}

// A GelSlim trunk with the photometric head: 10 x 12 working frames, a 20 x 24 reference.
SensorTrunk PhotometricSensorTrunk(int lighting_components = 0) {
  PhotometricTrunk::Options o;
  o.lighting_components = lighting_components;
  o.rows = 10;
  o.cols = 12;
  o.width = 8;
  o.num_hidden_layers = 2;
  o.latent_dim = 7;
  o.shading_width = 5;
  o.supersample = 2;
  Image reference(20, 24, 1);
  for (std::size_t i = 0; i < reference.size(); ++i) reference.data[i] = 0.01f * (i % 37);
  auto photometric = std::make_shared<PhotometricTrunk>(o, reference, 9);
  Eigen::VectorXd head = photometric->head_parameters();
  head[head.size() - 1] = 0.7;
  photometric->SetHeadParameters(head);
  SensorTrunk trunk = SmallTrunk(SensorKind::kGelSlim, 2);
  trunk.siren = photometric->siren();
  trunk.alpha = Eigen::VectorXd::Zero(trunk.siren.latent_dim());  // as `train` writes it
  trunk.photometric = photometric;
  return trunk;
}

TEST(FunctaModel, RoundTripsAPhotometricTrunkWithItsHeadAndReference) {
  FunctaModel model;
  model.SetTrunk(PhotometricSensorTrunk());
  const std::string bytes = model.Serialize();
  const FunctaModel read = FunctaModel::Parse(bytes, "m.tfm");
  const SensorTrunk& a = model.Trunk(SensorKind::kGelSlim);
  const SensorTrunk& b = read.Trunk(SensorKind::kGelSlim);
  ASSERT_NE(b.photometric, nullptr);
  EXPECT_EQ(TrunkLatentDim(b), 7);
  EXPECT_EQ(b.photometric->reference().data, a.photometric->reference().data);
  EXPECT_TRUE(a.photometric->head_parameters().cast<float>().cast<double>().isApprox(
      b.photometric->head_parameters(), 0.0));
  EXPECT_FLOAT_EQ(b.photometric->marker_scale(), 0.7);
  // The loaded trunk draws what the saved one draws, to float32 rounding of its parameters.
  Eigen::VectorXf z = Eigen::VectorXf::LinSpaced(7, -0.3f, 0.4f);
  const Eigen::MatrixXf ya = a.photometric->Forward<float>(a.photometric->AllPixels(), z);
  const Eigen::MatrixXf yb = b.photometric->Forward<float>(b.photometric->AllPixels(), z);
  EXPECT_LT((ya - yb).cwiseAbs().maxCoeff(), 1e-4);
  // A direct trunk writes no key; its latent size is the SIREN's.
  EXPECT_THAT(TensorFile::Parse(TwoSensorModel().Serialize(), "m.tfm", "model").meta_json(),
              ::testing::Not(HasSubstr("photometric")));
  EXPECT_EQ(TrunkLatentDim(TwoSensorModel().Trunk(SensorKind::kGelSlim)), 4);
  // A head whose latent size does not match its SIREN is refused naming the field.
  const std::string edited = WithMetaEdited(bytes, "\"latent_dim\":7", "\"latent_dim\":9");
  ASSERT_FALSE(edited.empty());
  try {
    FunctaModel::Parse(edited, "edited.tfm");
    FAIL() << "a mismatched head accepted";
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("gelslim.photometric")) << e.what();
    EXPECT_THAT(e.what(), HasSubstr("edited.tfm")) << e.what();
  }
}

// The background is written only when the trunk has one, read back exactly (float32), and
// drawn by the loaded trunk; a file that claims one without its tensor is refused.
TEST(FunctaModel, RoundTripsAPhotometricBackgroundOnlyWhenThereIsOne) {
  FunctaModel without;
  without.SetTrunk(PhotometricSensorTrunk());
  EXPECT_THAT(TensorFile::Parse(without.Serialize(), "m.tfm", "model").meta_json(),
              ::testing::Not(HasSubstr("background")));
  EXPECT_TRUE(FunctaModel::Parse(without.Serialize(), "m.tfm")
                  .Trunk(SensorKind::kGelSlim)
                  .photometric->background()
                  .empty());
  SensorTrunk trunk = PhotometricSensorTrunk();
  auto photometric = std::make_shared<PhotometricTrunk>(*trunk.photometric);
  Image background(10, 12, 1);
  for (std::size_t i = 0; i < background.size(); ++i) background.data[i] = 0.001f * (i % 11);
  photometric->SetBackground(background);
  trunk.photometric = photometric;
  FunctaModel model;
  model.SetTrunk(trunk);
  const std::string bytes = model.Serialize();
  const FunctaModel read = FunctaModel::Parse(bytes, "m.tfm");
  const PhotometricTrunk& b = *read.Trunk(SensorKind::kGelSlim).photometric;
  EXPECT_EQ(b.background().data, background.data);
  EXPECT_EQ(TrunkParameterBytes(read.Trunk(SensorKind::kGelSlim)),
            TrunkParameterBytes(without.Trunk(SensorKind::kGelSlim)) + 4 * background.size());
  const Eigen::VectorXf z = Eigen::VectorXf::LinSpaced(7, -0.3f, 0.4f);
  const Eigen::MatrixXf y = b.Forward<float>(b.AllPixels(), z);
  const PhotometricTrunk& plain = *without.Trunk(SensorKind::kGelSlim).photometric;
  const Eigen::MatrixXf y0 = plain.Forward<float>(plain.AllPixels(), z);
  EXPECT_NEAR(y(13, 0) - y0(13, 0), background.data[13], 1e-4);
  // A file that claims a background it does not hold.
  const std::string claimed = WithMetaEdited(without.Serialize(), "\"latent_dim\":7",
                                             "\"background\":true,\"latent_dim\":7");
  ASSERT_FALSE(claimed.empty());
  try {
    FunctaModel::Parse(claimed, "claimed.tfm");
    FAIL() << "a missing background accepted";
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("background")) << e.what();
    EXPECT_THAT(e.what(), HasSubstr("claimed.tfm")) << e.what();
  }
  // A background value that is not finite is refused naming the file and the tensor.
  const std::string poisoned =
      WithTensorsEdited(bytes, [](const std::string& name, std::vector<double>* values) {
        if (name == "gelslim/background") (*values)[7] = std::nan("");
        return true;
      });
  try {
    FunctaModel::Parse(poisoned, "poisoned.tfm");
    FAIL() << "a non-finite background accepted";
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("poisoned.tfm")) << e.what();
    EXPECT_THAT(e.what(), HasSubstr("gelslim/background")) << e.what();
    EXPECT_THAT(e.what(), HasSubstr("not finite")) << e.what();
  }
}

// Lighting images: their count and values round-trip (float32) and the loaded trunk
// draws them; a trunk without them writes neither; a count without its tensor, or with
// a non-finite value, is refused naming the file.
TEST(FunctaModel, RoundTripsPhotometricLightingImages) {
  EXPECT_THAT(TensorFile::Parse([] {
                FunctaModel m;
                m.SetTrunk(PhotometricSensorTrunk());
                return m.Serialize();
              }(), "m.tfm", "model").meta_json(),
              ::testing::Not(HasSubstr("lighting")));
  SensorTrunk trunk = PhotometricSensorTrunk(2);
  auto photometric = std::make_shared<PhotometricTrunk>(*trunk.photometric);
  Eigen::MatrixXf lighting(10 * 12, 2);
  for (Eigen::Index i = 0; i < lighting.size(); ++i) {
    lighting.data()[i] = 0.002f * static_cast<float>(i % 13) - 0.01f;
  }
  photometric->SetLighting(lighting);
  trunk.photometric = photometric;
  FunctaModel model;
  model.SetTrunk(trunk);
  const std::string bytes = model.Serialize();
  const FunctaModel read = FunctaModel::Parse(bytes, "m.tfm");
  const SensorTrunk& loaded = read.Trunk(SensorKind::kGelSlim);
  const PhotometricTrunk& b = *loaded.photometric;
  EXPECT_EQ(TrunkLatentDim(loaded), 7);
  EXPECT_EQ(b.lighting_components(), 2);
  EXPECT_EQ(b.siren().options().latent_dim, 2);  // 7 = pose 3 + code 2 + lighting 2
  EXPECT_EQ(b.lighting(), lighting);
  // float32 each: the SIREN, alpha, the head, the reference and the lighting images.
  EXPECT_EQ(TrunkParameterBytes(loaded),
            4u * static_cast<std::uint64_t>(loaded.siren.NumParameters() + loaded.alpha.size() +
                                            b.NumHeadParameters() + b.reference().size() +
                                            lighting.size()));
  const Eigen::VectorXf z = Eigen::VectorXf::LinSpaced(7, -0.3f, 0.4f);
  EXPECT_LT((b.Forward<float>(b.AllPixels(), z) -
             photometric->Forward<float>(photometric->AllPixels(), z))
                .cwiseAbs()
                .maxCoeff(),
            1e-4);
  // A count without its tensor (a trunk of 2 lighting images written without them).
  FunctaModel unlit;
  unlit.SetTrunk(PhotometricSensorTrunk(2));
  const std::string dropped = WithTensorsEdited(
      unlit.Serialize(),
      [](const std::string& name, std::vector<double>*) { return name != "gelslim/lighting"; });
  try {
    FunctaModel::Parse(dropped, "dropped.tfm");
    FAIL() << "missing lighting images accepted";
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("lighting")) << e.what();
    EXPECT_THAT(e.what(), HasSubstr("dropped.tfm")) << e.what();
  }
  const std::string poisoned =
      WithTensorsEdited(bytes, [](const std::string& name, std::vector<double>* values) {
        if (name == "gelslim/lighting") (*values)[3] = std::nan("");
        return true;
      });
  try {
    FunctaModel::Parse(poisoned, "poisoned.tfm");
    FAIL() << "a non-finite lighting image accepted";
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("poisoned.tfm")) << e.what();
    EXPECT_THAT(e.what(), HasSubstr("gelslim/lighting")) << e.what();
  }
}

TEST(FunctaModel, RoundTripsAWarmStartTableInFloat16AndRefusesABadOne) {
  FunctaModel model;
  SensorTrunk trunk = PhotometricSensorTrunk();
  const std::uint64_t bytes_without = TrunkParameterBytes(trunk);
  auto table = std::make_shared<WarmStartTable>();
  table->grid = 3;
  table->extent = 0.75;
  table->supersample = 2;
  table->descriptors = Eigen::MatrixXf::Random(4, 9);  // 3 x 3 cells, one channel
  table->latents = Eigen::MatrixXf::Random(4, 7);
  table->latents(2, 5) = 1.0f / 3.0f;  // not a float16 value
  trunk.warm_start = table;
  model.SetTrunk(trunk);
  EXPECT_EQ(TrunkParameterBytes(trunk), bytes_without + 2 * (36 + 28));
  const std::string bytes = model.Serialize();
  const SensorTrunk read = FunctaModel::Parse(bytes, "m.tfm").Trunk(SensorKind::kGelSlim);
  ASSERT_NE(read.warm_start, nullptr);
  EXPECT_EQ(read.warm_start->grid, 3);
  EXPECT_EQ(read.warm_start->extent, 0.75);
  EXPECT_EQ(read.warm_start->supersample, 2);
  ASSERT_EQ(read.warm_start->descriptors.rows(), 4);
  EXPECT_LT((read.warm_start->descriptors - table->descriptors).cwiseAbs().maxCoeff(), 1e-3);
  EXPECT_LT((read.warm_start->latents - table->latents).cwiseAbs().maxCoeff(), 1e-3);
  EXPECT_NE(read.warm_start->latents(2, 5), 1.0f / 3.0f);  // stored as float16
  // A trunk without a table writes none and reads back without one.
  EXPECT_EQ(FunctaModel::Parse(
                [] {
                  FunctaModel m;
                  m.SetTrunk(PhotometricSensorTrunk());
                  return m.Serialize();
                }(),
                "n.tfm")
                .Trunk(SensorKind::kGelSlim)
                .warm_start,
            nullptr);
  // A grid that does not match the descriptors' shape is refused naming the tensor.
  const std::string edited = WithMetaEdited(bytes, "\"grid\":3", "\"grid\":4");
  ASSERT_FALSE(edited.empty());
  try {
    FunctaModel::Parse(edited, "edited.tfm");
    FAIL() << "a table of another grid accepted";
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("warm_start")) << e.what();
    EXPECT_THAT(e.what(), HasSubstr("edited.tfm")) << e.what();
  }
}

TEST(FunctaModel, DifferentParametersGiveDifferentChecksums) {
  FunctaModel a = TwoSensorModel();
  FunctaModel b = TwoSensorModel();
  b.SetTrunk(SmallTrunk(SensorKind::kSoftBubble, 99));
  a.Serialize();
  b.Serialize();
  EXPECT_NE(a.checksum(), b.checksum());
}

TEST(FunctaModel, RejectsCorruptFilesAndOtherKindsNamingTheFile) {
  std::string bytes = TwoSensorModel().Serialize();
  bytes[bytes.size() / 2] ^= 0x11;
  EXPECT_THROW(FunctaModel::Parse(bytes, "bad.tfm"), TensorFileError);
  TensorFile other("functaset");
  try {
    FunctaModel::Parse(other.Serialize(), "f.tfs");
    FAIL();
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("f.tfs"));
    EXPECT_THAT(e.what(), HasSubstr("'model'"));
  }
}

TEST(FunctaModel, RejectsAModelFileWithAMissingField) {
  TensorFile file("model");
  file.set_meta_json(R"({"format": "tactfunc-model", "version": 1,
                         "trunks": [{"sensor": "bubble"}], "info": {}})");
  try {
    FunctaModel::Parse(file.Serialize(), "m.tfm");
    FAIL();
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("m.tfm"));
    EXPECT_THAT(e.what(), HasSubstr("bubble.siren"));
  }
  file.set_meta_json(R"({"format": "tactfunc-model", "version": 7, "trunks": [], "info": {}})");
  EXPECT_THROW(FunctaModel::Parse(file.Serialize(), "m.tfm"), TensorFileError);
}

TEST(FunctaModel, AskingForAMissingSensorNamesIt) {
  FunctaModel model;
  model.SetTrunk(SmallTrunk(SensorKind::kSoftBubble, 1));
  try {
    model.Trunk(SensorKind::kGelSlim);
    FAIL();
  } catch (const std::invalid_argument& e) {
    EXPECT_THAT(e.what(), HasSubstr("gelslim"));
  }
}

TEST(FunctaModel, SetTrunkRejectsInconsistentTrunks) {
  SensorTrunk trunk = SmallTrunk(SensorKind::kSoftBubble, 1);
  trunk.alpha = Eigen::VectorXd::Zero(3);
  FunctaModel model;
  EXPECT_THROW(model.SetTrunk(trunk), std::invalid_argument);
  trunk = SmallTrunk(SensorKind::kSoftBubble, 1);
  trunk.format.scale = 0;
  EXPECT_THROW(model.SetTrunk(trunk), std::invalid_argument);
}

TEST(FunctaModel, RecordsTheSensorDescriptionItWasTrainedOn) {
  FunctaModel model = TwoSensorModel();
  SensorDescription described = ParseSensorDescription(
      R"({"name": "wedge", "kind": "optical", "channels": 3, "perspective":
          {"corners": [[12, 8], [150, 10], [148, 118], [10, 116]], "rows": 90, "cols": 120},
          "working_size": {"rows": 10, "cols": 12}, "pixel_pitch_mm": 0.1245,
          "normalization_scale": 0.4, "markers": false})",
      "sensor.json");
  model.MutableTrunk(SensorKind::kGelSlim).description = described;
  const std::string path = (std::filesystem::path(testing::TempDir()) / "described.tfm").string();
  model.Save(path);
  const FunctaModel read = FunctaModel::Load(path);
  EXPECT_EQ(read.checksum(), model.checksum());
  ASSERT_TRUE(read.Trunk(SensorKind::kGelSlim).description);
  const SensorDescription& back = *read.Trunk(SensorKind::kGelSlim).description;
  EXPECT_TRUE(SameFrames(back, described)) << SensorDescriptionToJson(back);
  EXPECT_EQ(back.name, "wedge");
  EXPECT_TRUE(SameFrames(TrunkSensorDescription(read.Trunk(SensorKind::kGelSlim)), described));
  // The bubble trunk records none: it reads as the built-in of its kind at its format's
  // working size (as do all models written before descriptions).
  EXPECT_FALSE(read.Trunk(SensorKind::kSoftBubble).description);
  const SensorDescription fallback = TrunkSensorDescription(read.Trunk(SensorKind::kSoftBubble));
  EXPECT_EQ(fallback.name, "soft_bubble");
  EXPECT_EQ(fallback.geometry, SensorDescription::Geometry::kNone);
  EXPECT_EQ(fallback.working_rows, 10);
  EXPECT_EQ(fallback.working_cols, 12);
  EXPECT_EQ(fallback.channels, 1);
}

TEST(FunctaModel, AModelWithoutDescriptionsKeepsItsBytes) {
  // The file of a model without descriptions has no "sensor_description" key, so models
  // written before descriptions load unchanged and re-save to the same checksum.
  const FunctaModel model = TwoSensorModel();
  const std::string bytes = model.Serialize();
  EXPECT_EQ(bytes.find("sensor_description"), std::string::npos);
  const FunctaModel read = FunctaModel::Parse(bytes, "m.tfm");
  EXPECT_EQ(read.Serialize(), bytes);
}

TEST(FunctaModel, ADescriptionOfAnotherKindIsRefusedNamingTheField) {
  FunctaModel model = TwoSensorModel();
  SensorDescription depth = BuiltInSensorDescription(SensorKind::kSoftBubble);
  model.MutableTrunk(SensorKind::kGelSlim).description = depth;
  try {
    FunctaModel::Parse(model.Serialize(), "m.tfm");
    ADD_FAILURE() << "accepted";
  } catch (const TensorFileError& e) {
    EXPECT_THAT(e.what(), HasSubstr("m.tfm: field 'gelslim.sensor_description.kind': expected "
                                    "optical for the gelslim trunk, got depth"));
  }
}

TEST(FunctaModel, RecordsATrunksDefaultFitAndRefusesOneThatIsNoStrategysName) {
  FunctaModel model = TwoSensorModel();
  const std::string without = model.Serialize();
  EXPECT_EQ(without.find("default_fit"), std::string::npos);  // absent: the encoder's rule
  EXPECT_EQ(FunctaModel::Parse(without, "m.tfm").Trunk(SensorKind::kGelSlim).default_fit, "");
  model.MutableTrunk(SensorKind::kGelSlim).default_fit = "knn+adam:400";
  const std::string bytes = model.Serialize();
  const FunctaModel read = FunctaModel::Parse(bytes, "m.tfm");
  EXPECT_EQ(read.Trunk(SensorKind::kGelSlim).default_fit, "knn+adam:400");
  EXPECT_EQ(read.Trunk(SensorKind::kSoftBubble).default_fit, "");
  EXPECT_EQ(read.Serialize(), bytes);
  for (const std::string& bad : {std::string("\"\""), std::string("\"knn adam\""),
                                 std::string("400")}) {
    const std::string edited =
        WithMetaEdited(bytes, "\"default_fit\":\"knn+adam:400\"", "\"default_fit\":" + bad);
    ASSERT_FALSE(edited.empty());
    try {
      FunctaModel::Parse(edited, "m.tfm");
      ADD_FAILURE() << "accepted " << bad;
    } catch (const TensorFileError& e) {
      EXPECT_THAT(e.what(), HasSubstr("m.tfm")) << e.what();
      EXPECT_THAT(e.what(), HasSubstr("gelslim.default_fit")) << e.what();
    }
  }
}

}  // namespace
}  // namespace tactfunc
