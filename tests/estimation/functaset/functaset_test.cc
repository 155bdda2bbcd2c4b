// Copyright 2026 The tactfunc Authors.
#include "estimation/functaset/functaset.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <initializer_list>
#include <limits>
#include <string>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "models/core/tensor_file.h"
#include "nlohmann/json.hpp"
#include "tests/support/functa_test_util.h"
#include "tests/support/test_dir.h"

namespace tactfunc {
namespace {

using ::testing::HasSubstr;
using testing_util::MakeModel;
using testing_util::TestDir;

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();
constexpr float kInf = std::numeric_limits<float>::infinity();

Eigen::VectorXf Latent(int d, int seed) {
  Eigen::VectorXf z(d);
  for (int k = 0; k < d; ++k) z[k] = std::sin(1.7f * (seed + 1) * (k + 1)) * 1.3f + 1e-7f * k;
  return z;
}

// A functaset with both sensors: labelled and unlabelled entries, both splits, and
// the PSNR extremes (NaN: no valid pixel, +inf: exact fit).
Functaset MakeFunctaset() {
  Functaset f(0xdeadbeefu, "/data/tactile set");
  f.AddSensor(SensorKind::kGelSlim, 3);
  f.AddSensor(SensorKind::kSoftBubble, 5);
  for (int i = 0; i < 4; ++i) {
    FunctasetEntry e;
    e.id = "frame_" + std::to_string(i);
    e.split = i == 3 ? Split::kTest : Split::kTrain;
    if (i != 1) e.label = PoseLabel{"pen", SE2d::FromXYYaw(0.001 * i, -0.0005, 0.25 - i), 0.0021};
    e.latent = Latent(5, i);
    e.psnr = i == 0 ? kNaN : (i == 2 ? kInf : 30.125f + i);
    f.Add(SensorKind::kSoftBubble, e);
    e.latent = Latent(3, i + 10);
    e.psnr = 25.5f;
    f.Add(SensorKind::kGelSlim, e);
  }
  return f;
}

bool SameFloat(float a, float b) { return std::isnan(a) ? std::isnan(b) : a == b; }

void ExpectIdentical(const Functaset& a, const Functaset& b) {
  EXPECT_EQ(a.model_checksum(), b.model_checksum());
  EXPECT_EQ(a.dataset(), b.dataset());
  EXPECT_EQ(a.complete(), b.complete());
  ASSERT_EQ(a.sensors(), b.sensors());
  for (SensorKind sensor : a.sensors()) {
    EXPECT_EQ(a.latent_dim(sensor), b.latent_dim(sensor));
    ASSERT_EQ(a.entries(sensor).size(), b.entries(sensor).size());
    for (std::size_t i = 0; i < a.entries(sensor).size(); ++i) {
      const FunctasetEntry& x = a.entries(sensor)[i];
      const FunctasetEntry& y = b.entries(sensor)[i];
      EXPECT_EQ(x.id, y.id);
      EXPECT_EQ(x.split, y.split);
      EXPECT_EQ(x.label.has_value(), y.label.has_value());
      if (x.label && y.label) {
        EXPECT_EQ(*x.label, *y.label);
      }
      EXPECT_TRUE(SameFloat(x.psnr, y.psnr)) << x.psnr << " vs " << y.psnr;
      ASSERT_EQ(x.latent.size(), y.latent.size());
      for (Eigen::Index k = 0; k < x.latent.size(); ++k) EXPECT_EQ(x.latent[k], y.latent[k]);
    }
  }
}

// Runs `body`, expecting a TensorFileError whose message holds every piece.
void ExpectFileError(const std::function<void()>& body, std::initializer_list<std::string> pieces) {
  try {
    body();
    ADD_FAILURE() << "expected a TensorFileError, got none";
  } catch (const TensorFileError& e) {
    for (const std::string& piece : pieces) EXPECT_THAT(e.what(), HasSubstr(piece));
  }
}

// The functaset's file with its meta edited by `edit`, re-containered (valid CRC).
std::string WithMeta(const Functaset& f, const std::function<void(nlohmann::json&)>& edit) {
  const TensorFile file = TensorFile::Parse(f.Serialize(), "original", "functaset");
  nlohmann::json meta = nlohmann::json::parse(file.meta_json());
  edit(meta);
  TensorFile edited("functaset");
  edited.set_meta_json(meta.dump());
  for (const TensorFile::Tensor& t : file.tensors()) edited.Add(t.name, t.dtype, t.shape, t.values);
  return edited.Serialize();
}

TEST(Functaset, FileRoundTripIsExact) {
  TestDir dir;
  const Functaset original = MakeFunctaset();
  original.Save(dir / "set.tfs");
  const Functaset loaded = Functaset::Load(dir / "set.tfs");
  ExpectIdentical(original, loaded);
  EXPECT_EQ(loaded.source(), dir / "set.tfs");
  EXPECT_EQ(loaded.size(), 8u);
  // Unlabelled entries stay unlabelled; sensors come back in SensorKind order.
  EXPECT_FALSE(loaded.entries(SensorKind::kSoftBubble)[1].label.has_value());
  EXPECT_EQ(loaded.sensors().front(), SensorKind::kSoftBubble);
}

TEST(Functaset, PartialFlagRoundTrips) {
  Functaset f = MakeFunctaset();
  f.set_complete(false);
  EXPECT_FALSE(Functaset::Parse(f.Serialize(), "mem").complete());
}

TEST(Functaset, EmptyFunctasetRoundTrips) {
  Functaset f(1, "d");
  f.AddSensor(SensorKind::kGelSlim, 4);
  const Functaset loaded = Functaset::Parse(f.Serialize(), "mem");
  EXPECT_EQ(loaded.latent_dim(SensorKind::kGelSlim), 4);
  EXPECT_TRUE(loaded.entries(SensorKind::kGelSlim).empty());
  EXPECT_EQ(loaded.Latents(SensorKind::kGelSlim).rows(), 0);
}

TEST(Functaset, FileHoldsTheDocumentedLayout) {
  const TensorFile file = TensorFile::Parse(MakeFunctaset().Serialize(), "mem", "functaset");
  const nlohmann::json meta = nlohmann::json::parse(file.meta_json());
  EXPECT_EQ(meta["format"], "tactfunc-functaset");
  EXPECT_EQ(meta["version"], 1);
  EXPECT_EQ(meta["model_checksum"], 0xdeadbeefu);
  EXPECT_EQ(meta["sensors"][0]["sensor"], "bubble");
  EXPECT_EQ(meta["sensors"][0]["tools"][1], nullptr);
  EXPECT_EQ(meta["sensors"][0]["splits"][3], "test");
  EXPECT_EQ(file.Get("bubble/latents").shape, (std::vector<std::int64_t>{4, 5}));
  EXPECT_EQ(file.Get("bubble/latents").dtype, TensorFile::DType::kFloat32);
  EXPECT_EQ(file.Get("gelslim/psnr").shape, (std::vector<std::int64_t>{4}));
  const TensorFile::Tensor& poses = file.Get("bubble/poses");
  EXPECT_EQ(poses.dtype, TensorFile::DType::kFloat64);
  EXPECT_EQ(poses.shape, (std::vector<std::int64_t>{4, 4}));
  EXPECT_TRUE(std::isnan(poses.values[4]));      // entry 1 is unlabelled
  EXPECT_EQ(poses.values[3 * 4 + 2], 0.25 - 3);  // yaw of entry 3
}

TEST(Functaset, LatentsAreRowsInEntryOrderAndFilterBySplit) {
  const Functaset f = MakeFunctaset();
  const Functaset::LatentMatrix all = f.Latents(SensorKind::kSoftBubble);
  ASSERT_EQ(all.rows(), 4);
  ASSERT_EQ(all.cols(), 5);
  EXPECT_EQ(Eigen::VectorXf(all.row(2).transpose()), Latent(5, 2));
  const Functaset::LatentMatrix test = f.Latents(SensorKind::kSoftBubble, Split::kTest);
  ASSERT_EQ(test.rows(), 1);
  EXPECT_EQ(Eigen::VectorXf(test.row(0).transpose()), Latent(5, 3));
  EXPECT_EQ(*f.Find(SensorKind::kGelSlim, "frame_2"), 2u);
  EXPECT_FALSE(f.Find(SensorKind::kGelSlim, "frame_9").has_value());
}

TEST(Functaset, AddRejectsEntriesThatDoNotFit) {
  Functaset f = MakeFunctaset();
  FunctasetEntry e;
  e.id = "new";
  e.latent = Latent(4, 0);
  EXPECT_THROW(f.Add(SensorKind::kSoftBubble, e), std::invalid_argument);  // d = 5
  e.latent = Latent(5, 0);
  e.id = "frame_0";
  EXPECT_THROW(f.Add(SensorKind::kSoftBubble, e), std::invalid_argument);  // duplicate
  Functaset other;
  EXPECT_THROW(other.Add(SensorKind::kSoftBubble, e), std::invalid_argument);  // undeclared
  EXPECT_THROW(f.AddSensor(SensorKind::kSoftBubble, 6), std::invalid_argument);
  EXPECT_NO_THROW(f.AddSensor(SensorKind::kSoftBubble, 5));
}

TEST(Functaset, TruncatedFileIsRejectedNamingTheFile) {
  TestDir dir;
  const std::string bytes = MakeFunctaset().Serialize();
  for (std::size_t keep : {std::size_t(0), std::size_t(10), bytes.size() / 2, bytes.size() - 1}) {
    testing_util::WriteText(dir / "cut.tfs", bytes.substr(0, keep));
    ExpectFileError([&] { Functaset::Load(dir / "cut.tfs"); }, {dir / "cut.tfs"});
  }
}

TEST(Functaset, CorruptFileIsRejectedNamingTheFile) {
  TestDir dir;
  std::string bytes = MakeFunctaset().Serialize();
  bytes[bytes.size() - 40] ^= 0x10;  // a latent or PSNR byte
  testing_util::WriteText(dir / "bad.tfs", bytes);
  ExpectFileError([&] { Functaset::Load(dir / "bad.tfs"); }, {dir / "bad.tfs", "corrupt"});
}

TEST(Functaset, MissingFileIsRejectedNamingTheFile) {
  TestDir dir;
  ExpectFileError([&] { Functaset::Load(dir / "absent.tfs"); }, {dir / "absent.tfs"});
}

TEST(Functaset, ModelFileIsNotAFunctaset) {
  TestDir dir;
  MakeModel().Save(dir / "model.tfm");
  ExpectFileError([&] { Functaset::Load(dir / "model.tfm"); },
                  {dir / "model.tfm", "'model'", "'functaset'"});
}

TEST(Functaset, OtherVersionIsRejected) {
  const std::string bytes =
      WithMeta(MakeFunctaset(), [](nlohmann::json& meta) { meta["version"] = 2; });
  ExpectFileError([&] { Functaset::Parse(bytes, "v2.tfs"); }, {"v2.tfs", "version 2"});
}

TEST(Functaset, BadFieldsAreRejectedNamingTheField) {
  struct Case {
    std::function<void(nlohmann::json&)> edit;
    std::string field;
  };
  const std::vector<Case> cases = {
      {[](nlohmann::json& m) { m["format"] = "tactfunc-model"; }, "format"},
      {[](nlohmann::json& m) { m.erase("model_checksum"); }, "model_checksum"},
      {[](nlohmann::json& m) { m["model_checksum"] = -3; }, "model_checksum"},
      {[](nlohmann::json& m) { m["complete"] = "yes"; }, "complete"},
      {[](nlohmann::json& m) { m["sensors"][0]["sensor"] = "camera"; }, "sensors[0].sensor"},
      {[](nlohmann::json& m) { m["sensors"][1]["sensor"] = "bubble"; }, "sensors[1].sensor"},
      {[](nlohmann::json& m) { m["sensors"][0]["ids"].erase(0); }, "sensors[0].ids"},
      {[](nlohmann::json& m) { m["sensors"][0]["ids"][2] = "frame_0"; }, "sensors[0].ids[2]"},
      {[](nlohmann::json& m) { m["sensors"][0]["splits"][1] = "val"; }, "sensors[0].splits[1]"},
      {[](nlohmann::json& m) { m["sensors"][0].erase("tools"); }, "sensors[0].tools"},
      {[](nlohmann::json& m) { m["sensors"][0]["tools"][1] = "pen"; }, "bubble/poses[1]"},
      {[](nlohmann::json& m) { m["sensors"][0]["latent_dim"] = 0; }, "sensors[0].latent_dim"},
  };
  for (const Case& c : cases) {
    SCOPED_TRACE(c.field);
    const std::string bytes = WithMeta(MakeFunctaset(), c.edit);
    ExpectFileError([&] { Functaset::Parse(bytes, "edited.tfs"); }, {"edited.tfs", c.field});
  }
}

TEST(Functaset, TensorOfTheWrongShapeIsRejectedNamingIt) {
  // latent_dim 4 in the meta, but the latents tensor is 4 x 5.
  const std::string bytes =
      WithMeta(MakeFunctaset(), [](nlohmann::json& m) { m["sensors"][0]["latent_dim"] = 4; });
  ExpectFileError([&] { Functaset::Parse(bytes, "shape.tfs"); }, {"shape.tfs", "bubble/latents"});
}

TEST(Functaset, CheckModelAcceptsTheModelItWasEncodedWith) {
  TestDir dir;
  MakeModel().Save(dir / "model.tfm");
  const FunctaModel model = FunctaModel::Load(dir / "model.tfm");
  Functaset f(model.checksum(), "d");
  f.AddSensor(SensorKind::kSoftBubble, model.Trunk(SensorKind::kSoftBubble).siren.latent_dim());
  EXPECT_NO_THROW(f.CheckModel(model, dir / "model.tfm"));
}

TEST(Functaset, CheckModelRejectsAnotherModelQuotingBothChecksums) {
  TestDir dir;
  MakeModel(3, 0.5, 7).Save(dir / "a.tfm");
  MakeModel(3, 0.5, 8).Save(dir / "b.tfm");
  const FunctaModel a = FunctaModel::Load(dir / "a.tfm");
  const FunctaModel b = FunctaModel::Load(dir / "b.tfm");
  ASSERT_NE(a.checksum(), b.checksum());
  Functaset f(a.checksum(), "d");
  f.Save(dir / "set.tfs");
  const Functaset loaded = Functaset::Load(dir / "set.tfs");
  try {
    loaded.CheckModel(b, dir / "b.tfm");
    ADD_FAILURE() << "expected FunctasetModelMismatch";
  } catch (const FunctasetModelMismatch& e) {
    char a_hex[16], b_hex[16];
    std::snprintf(a_hex, sizeof(a_hex), "0x%08x", a.checksum());
    std::snprintf(b_hex, sizeof(b_hex), "0x%08x", b.checksum());
    EXPECT_THAT(e.what(), HasSubstr("functaset " + dir / "set.tfs" +
                                    " was encoded with model checksum " + a_hex));
    EXPECT_THAT(e.what(), HasSubstr("but model " + dir / "b.tfm" + " has " + b_hex));
  }
}

TEST(Functaset, CheckModelRejectsAnotherLatentDimension) {
  const FunctaModel model = MakeModel();  // never saved: checksum 0
  Functaset f(model.checksum(), "d");
  f.AddSensor(SensorKind::kSoftBubble, 99);
  EXPECT_THROW(f.CheckModel(model), FunctasetModelMismatch);
}

}  // namespace
}  // namespace tactfunc
