// Copyright 2026 The tactfunc Authors.
#include "estimation/functaset/functaset.h"

#include <cmath>
#include <filesystem>
#include <fstream>
#include <functional>
#include <initializer_list>
#include <limits>
#include <numeric>
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
// The file of `f` rewritten: its meta through `edit_meta`, each tensor's values through
// `edit_values` (given the tensor's name).
std::string Rewritten(
    const Functaset& f, const std::function<void(nlohmann::json&)>& edit_meta,
    const std::function<void(const std::string&, std::vector<double>&)>& edit_values) {
  const TensorFile file = TensorFile::Parse(f.Serialize(), "original", "functaset");
  nlohmann::json meta = nlohmann::json::parse(file.meta_json());
  edit_meta(meta);
  TensorFile edited("functaset");
  edited.set_meta_json(meta.dump());
  for (const TensorFile::Tensor& t : file.tensors()) {
    std::vector<double> values = t.values;
    edit_values(t.name, values);
    edited.Add(t.name, t.dtype, t.shape, std::move(values));
  }
  return edited.Serialize();
}

std::string WithMeta(const Functaset& f, const std::function<void(nlohmann::json&)>& edit) {
  return Rewritten(f, edit, [](const std::string&, std::vector<double>&) {});
}

// The file of `f` with tensor `name`'s values edited.
std::string WithTensor(const Functaset& f, const std::string& name,
                       const std::function<void(std::vector<double>&)>& edit) {
  return Rewritten(f, [](nlohmann::json&) {},
                   [&](const std::string& tensor, std::vector<double>& values) {
                     if (tensor == name) edit(values);
                   });
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

// ---- b-bit latents -----------------------------------------------------------------------

constexpr Functaset::LatentPrecision kCodePrecisions[] = {Functaset::LatentPrecision::kUint8,
                                                          Functaset::LatentPrecision::kUint6,
                                                          Functaset::LatentPrecision::kUint4};

// M = 40 bubble entries of d = 7 (codes of 7 x 6 and 7 x 4 bits straddle bytes), whose
// dimension 2 is constant and dimension 0 spans [-3, 5] exactly.
Functaset MakeCodeFunctaset(Functaset::LatentPrecision precision) {
  Functaset f(7, "/data");
  f.set_latent_precision(precision);
  f.AddSensor(SensorKind::kSoftBubble, 7);
  for (int i = 0; i < 40; ++i) {
    FunctasetEntry e;
    e.id = std::to_string(i);
    e.latent = Latent(7, i) * (1.0f + 0.1f * i);
    e.latent[2] = 0.375f;
    e.latent[0] = i == 0 ? -3.0f : (i == 1 ? 5.0f : 1.0f + 3.99f * std::sin(0.9f * i));
    e.psnr = 20.0f + 0.25f * i;
    f.Add(SensorKind::kSoftBubble, e);
  }
  return f;
}

TEST(Functaset, CodeLatentsRoundTripWithinHalfAStepAndReproduceExactly) {
  for (Functaset::LatentPrecision precision : kCodePrecisions) {
    SCOPED_TRACE(ToString(precision));
    const int bits = LatentBits(precision);
    const Functaset original = MakeCodeFunctaset(precision);
    const Functaset loaded = Functaset::Parse(original.Serialize(), "codes.tfs");
    EXPECT_EQ(loaded.latent_precision(), precision);
    const auto& a = original.entries(SensorKind::kSoftBubble);
    const auto& b = loaded.entries(SensorKind::kSoftBubble);
    ASSERT_EQ(a.size(), b.size());
    const Functaset::LatentMatrix z = original.Latents(SensorKind::kSoftBubble);
    for (int k = 0; k < 7; ++k) {
      const double step = (z.col(k).maxCoeff() - z.col(k).minCoeff()) / ((1 << bits) - 1.0);
      for (std::size_t i = 0; i < a.size(); ++i) {
        // Half a step, plus the float32 rounding of the step and of the result.
        EXPECT_NEAR(b[i].latent[k], a[i].latent[k], step / 2 * (1 + 1e-5) + 1e-6)
            << "entry " << i << " dimension " << k;
      }
    }
    // The stored PSNR is the unrounded fit's, untouched.
    for (std::size_t i = 0; i < a.size(); ++i) EXPECT_EQ(a[i].psnr, b[i].psnr);
    // A second save writes the same codes: the latents come back bit for bit.
    const std::string again = loaded.Serialize();
    ExpectIdentical(loaded, Functaset::Parse(again, "again.tfs"));
  }
}

TEST(Functaset, CodesReachBothEndsOfTheRangeAndAConstantDimensionIsExact) {
  for (Functaset::LatentPrecision precision : kCodePrecisions) {
    SCOPED_TRACE(ToString(precision));
    const int bits = LatentBits(precision);
    const Functaset original = MakeCodeFunctaset(precision);
    const TensorFile file = TensorFile::Parse(original.Serialize(), "mem", "functaset");
    const std::vector<double>& offset = file.Get("bubble/latent_offset", {7}).values;
    const std::vector<double>& step = file.Get("bubble/latent_step", {7}).values;
    EXPECT_EQ(offset[0], -3.0);
    EXPECT_FLOAT_EQ(step[0], 8.0 / ((1 << bits) - 1));
    EXPECT_EQ(offset[2], 0.375);
    EXPECT_EQ(step[2], 0.0);
    // Dimension 0 of entries 0 and 1: codes 0 and 2^b - 1, read back as the min and max.
    const std::vector<double>& codes = file.Get("bubble/latent_codes").values;
    const std::int64_t row = (7 * bits + 7) / 8;
    EXPECT_EQ(static_cast<int>(codes[0]) & ((1 << bits) - 1), 0);
    EXPECT_EQ(static_cast<int>(codes[row]) & ((1 << bits) - 1), (1 << bits) - 1);
    const Functaset loaded = Functaset::Parse(file.Serialize(), "mem");
    const auto& entries = loaded.entries(SensorKind::kSoftBubble);
    EXPECT_EQ(entries[0].latent[0], -3.0f);
    EXPECT_FLOAT_EQ(entries[1].latent[0], 5.0f);
    for (const FunctasetEntry& e : entries) EXPECT_EQ(e.latent[2], 0.375f);
  }
}

TEST(Functaset, CodeLatentsTakeCeilOfDTimesBitsOverEightBytesPerFrame) {
  for (Functaset::LatentPrecision precision : kCodePrecisions) {
    SCOPED_TRACE(ToString(precision));
    const int bits = LatentBits(precision);
    const Functaset f = MakeCodeFunctaset(precision);
    const std::int64_t row = (7 * bits + 7) / 8;  // 7, 6, 4 bytes
    EXPECT_EQ(f.BytesPerFrame(SensorKind::kSoftBubble), static_cast<double>(row));
    EXPECT_EQ(f.SharedLatentBytes(SensorKind::kSoftBubble), 2u * 7 * 4);
    const std::string bytes = f.Serialize();
    const TensorFile file = TensorFile::Parse(bytes, "mem", "functaset");
    EXPECT_FALSE(file.Has("bubble/latents"));
    const TensorFile::Tensor& codes = file.Get("bubble/latent_codes", {40, row});
    EXPECT_EQ(codes.dtype, TensorFile::DType::kUint8);
    // The payload bytes of the codes tensor, as the container's header states them.
    const nlohmann::json meta = nlohmann::json::parse(file.meta_json());
    EXPECT_EQ(meta["sensors"][0]["latent_bits"], bits);
    const std::uint64_t header_length = *reinterpret_cast<const std::uint64_t*>(bytes.data() + 16);
    const nlohmann::json header = nlohmann::json::parse(bytes.substr(24, header_length));
    for (const nlohmann::json& t : header["tensors"]) {
      if (t["name"] == "bubble/latent_codes") {
        EXPECT_EQ(t["bytes"], 40 * row);
      }
    }
  }
  // The float precisions: 4 d and 2 d bytes per frame, no shared tables.
  Functaset f = MakeCodeFunctaset(Functaset::LatentPrecision::kFloat32);
  EXPECT_EQ(f.BytesPerFrame(SensorKind::kSoftBubble), 28.0);
  EXPECT_EQ(f.SharedLatentBytes(SensorKind::kSoftBubble), 0u);
  f.set_latent_precision(Functaset::LatentPrecision::kFloat16);
  EXPECT_EQ(f.BytesPerFrame(SensorKind::kSoftBubble), 14.0);
}

TEST(Functaset, FloatLatentFilesStillParse) {
  for (Functaset::LatentPrecision precision :
       {Functaset::LatentPrecision::kFloat32, Functaset::LatentPrecision::kFloat16}) {
    Functaset f = MakeFunctaset();
    f.set_latent_precision(precision);
    const TensorFile file = TensorFile::Parse(f.Serialize(), "mem", "functaset");
    EXPECT_EQ(file.Get("bubble/latents").dtype, precision == Functaset::LatentPrecision::kFloat16
                                                     ? TensorFile::DType::kFloat16
                                                     : TensorFile::DType::kFloat32);
    EXPECT_FALSE(file.Has("bubble/latent_codes"));
    const nlohmann::json meta = nlohmann::json::parse(file.meta_json());
    EXPECT_FALSE(meta["sensors"][0].contains("latent_bits"));
    const Functaset loaded = Functaset::Parse(file.Serialize(), "mem");
    EXPECT_EQ(loaded.latent_precision(), precision);
    if (precision == Functaset::LatentPrecision::kFloat32) ExpectIdentical(f, loaded);
  }
}

// Sum over entries and dimensions of the squared difference of two functasets' latents.
double SquaredDifference(const Functaset& a, const Functaset& b) {
  return (a.Latents(SensorKind::kSoftBubble) - b.Latents(SensorKind::kSoftBubble))
      .cast<double>()
      .squaredNorm();
}

TEST(Functaset, AllocatedCodesShareTheBytesAmongTheDimensionsAndReproduceExactly) {
  Functaset f = MakeCodeFunctaset(Functaset::LatentPrecision::kAllocated);
  f.set_latent_bytes(4);  // as many bytes as 4-bit codes of the 7 values take
  EXPECT_EQ(f.BytesPerFrame(SensorKind::kSoftBubble), 4.0);
  EXPECT_EQ(f.SharedLatentBytes(SensorKind::kSoftBubble), 9u * 7);
  const TensorFile file = TensorFile::Parse(f.Serialize(), "mem", "functaset");
  const nlohmann::json meta = nlohmann::json::parse(file.meta_json());
  EXPECT_EQ(meta["sensors"][0]["latent_bytes"], 4);
  EXPECT_FALSE(meta["sensors"][0].contains("latent_bits"));
  const TensorFile::Tensor& bits = file.Get("bubble/latent_bits", {7});
  EXPECT_EQ(bits.dtype, TensorFile::DType::kUint8);
  EXPECT_EQ(bits.values[2], 0);  // the constant dimension needs no bit
  EXPECT_LE(std::accumulate(bits.values.begin(), bits.values.end(), 0.0), 32);
  EXPECT_EQ(file.Get("bubble/latent_codes", {40, 4}).dtype, TensorFile::DType::kUint8);

  const Functaset loaded = Functaset::Parse(file.Serialize(), "codes.tfs");
  EXPECT_EQ(loaded.latent_precision(), Functaset::LatentPrecision::kAllocated);
  EXPECT_EQ(loaded.latent_bytes(), 4);
  EXPECT_EQ(loaded.code_bits(SensorKind::kSoftBubble),
            std::vector<int>(bits.values.begin(), bits.values.end()));
  for (const FunctasetEntry& e : loaded.entries(SensorKind::kSoftBubble)) {
    EXPECT_EQ(e.latent[2], 0.375f);
  }
  // Less squared error than 4-bit codes in the same bytes per frame.
  const Functaset uint4 = Functaset::Parse(
      MakeCodeFunctaset(Functaset::LatentPrecision::kUint4).Serialize(), "uint4.tfs");
  EXPECT_EQ(uint4.BytesPerFrame(SensorKind::kSoftBubble), 4.0);
  EXPECT_LT(SquaredDifference(f, loaded), SquaredDifference(f, uint4));
  // A second save writes the same codes and bits.
  const std::string again = loaded.Serialize();
  ExpectIdentical(loaded, Functaset::Parse(again, "again.tfs"));
  EXPECT_EQ(Functaset::Parse(again, "again.tfs").Serialize(), again);
  // A budget outside 1 .. 2 d bytes (16 bits per value) is refused.
  for (int bytes : {0, 15}) {
    f.set_latent_bytes(bytes);
    EXPECT_THROW(f.Serialize(), std::invalid_argument) << bytes;
  }
}

TEST(Functaset, BadAllocatedCodeFieldsAreRejectedNamingThem) {
  Functaset f = MakeCodeFunctaset(Functaset::LatentPrecision::kAllocated);
  f.set_latent_bytes(4);
  ExpectFileError([&] { Functaset::Parse(WithMeta(f, [](nlohmann::json& m) {
                                           m["sensors"][0]["latent_bytes"] = 15;
                                         }), "bad.tfs"); },
                  {"bad.tfs", "sensors[0].latent_bytes", "expected 1..14"});
  ExpectFileError([&] { Functaset::Parse(WithMeta(f, [](nlohmann::json& m) {
                                           m["sensors"][0]["latent_bytes"] = 3;
                                         }), "bad.tfs"); },
                  {"bad.tfs", "bubble/latent_"});
  ExpectFileError([&] { Functaset::Parse(WithTensor(f, "bubble/latent_bits", [](auto& v) {
                                           v[0] = 17;
                                         }), "bad.tfs"); },
                  {"bad.tfs", "bubble/latent_bits", "expected bits in [0, 16]"});
  ExpectFileError([&] { Functaset::Parse(WithTensor(f, "bubble/latent_bits", [](auto& v) {
                                           for (double& b : v) b = 16;
                                         }), "bad.tfs"); },
                  {"bad.tfs", "bubble/latent_bits", "more than latent_bytes = 4"});
}

TEST(Functaset, BadCodeFieldsAreRejectedNamingThem) {
  const Functaset f = MakeCodeFunctaset(Functaset::LatentPrecision::kUint6);
  ExpectFileError([&] { Functaset::Parse(WithMeta(f, [](nlohmann::json& m) {
                                           m["sensors"][0]["latent_bits"] = 5;
                                         }), "bad.tfs"); },
                  {"bad.tfs", "sensors[0].latent_bits", "expected 8, 6 or 4, got 5"});
  ExpectFileError([&] { Functaset::Parse(WithMeta(f, [](nlohmann::json& m) {
                                           m["sensors"][0]["latent_bits"] = 8;
                                         }), "bad.tfs"); },
                  {"bad.tfs", "bubble/latent_codes", "shape [40, 6], expected [40, 7]"});
}

// Frames at rest share the sensor's rest latent, stored once: the file holds a latent row
// only for the others, at every precision, and reads back what was written.
TEST(Functaset, FramesAtRestShareOneStoredLatentAtEveryPrecision) {
  for (Functaset::LatentPrecision precision :
       {Functaset::LatentPrecision::kFloat32, Functaset::LatentPrecision::kFloat16,
        Functaset::LatentPrecision::kUint8, Functaset::LatentPrecision::kUint4,
        Functaset::LatentPrecision::kAllocated}) {
    SCOPED_TRACE(ToString(precision));
    Functaset all = MakeCodeFunctaset(precision);
    Functaset shared = MakeCodeFunctaset(precision);
    all.set_latent_bytes(5);
    shared.set_latent_bytes(5);
    const Eigen::VectorXf rest = Latent(7, 99) * 10.0f;  // outside the others' code range
    shared.set_rest_latent(SensorKind::kSoftBubble, rest);
    FunctasetEntry e;
    for (int i = 0; i < 10; ++i) {
      e.id = "rest_" + std::to_string(i);
      e.at_rest = true;
      e.psnr = 12.5f;
      shared.Add(SensorKind::kSoftBubble, e);
    }
    EXPECT_EQ(shared.NumStoredLatents(SensorKind::kSoftBubble), 40);
    EXPECT_EQ(shared.SharedLatentBytes(SensorKind::kSoftBubble),
              all.SharedLatentBytes(SensorKind::kSoftBubble) + 4 * 7);
    const Functaset loaded = Functaset::Parse(shared.Serialize(), "mem");
    const Functaset reference = Functaset::Parse(all.Serialize(), "mem");
    ASSERT_EQ(loaded.entries(SensorKind::kSoftBubble).size(), 50u);
    ASSERT_NE(loaded.rest_latent(SensorKind::kSoftBubble), nullptr);
    EXPECT_EQ(*loaded.rest_latent(SensorKind::kSoftBubble), rest);
    for (std::size_t i = 0; i < 50; ++i) {
      const FunctasetEntry& got = loaded.entries(SensorKind::kSoftBubble)[i];
      EXPECT_EQ(got.at_rest, i >= 40) << i;
      // The others read back exactly as without frames at rest (same codes' grid).
      EXPECT_EQ(got.latent, i < 40 ? reference.entries(SensorKind::kSoftBubble)[i].latent : rest)
          << i;
    }
    // Frames at rest cost d float32 once (a tensor with its header) and an index each
    // (at most 5 characters here), not a latent each.
    Functaset fitted = all;
    for (int i = 0; i < 10; ++i) {
      e.id = "rest_" + std::to_string(i);
      e.at_rest = false;
      e.latent = rest;
      fitted.Add(SensorKind::kSoftBubble, e);
    }
    const double saved = 10 * (all.BytesPerFrame(SensorKind::kSoftBubble) - 5) - 4 * 7 - 160;
    EXPECT_LE(static_cast<double>(shared.Serialize().size()),
              static_cast<double>(fitted.Serialize().size()) - saved);
  }
  // An entry at rest needs the rest latent first; a bad at_rest array names the field.
  Functaset f(1, "d");
  f.AddSensor(SensorKind::kGelSlim, 3);
  FunctasetEntry e;
  e.id = "a";
  e.at_rest = true;
  EXPECT_THROW(f.Add(SensorKind::kGelSlim, e), std::invalid_argument);
  f.set_rest_latent(SensorKind::kGelSlim, Latent(3, 1));
  f.Add(SensorKind::kGelSlim, e);
  EXPECT_THROW(f.set_rest_latent(SensorKind::kGelSlim, Latent(4, 1)), std::invalid_argument);
  const std::string bytes =
      WithMeta(f, [](nlohmann::json& m) { m["sensors"][0]["at_rest"][0] = 1; });
  ExpectFileError([&] { Functaset::Parse(bytes, "edited.tfs"); },
                  {"edited.tfs", "sensors[0].at_rest[0]"});
}

// The dataset's declared tool symmetries travel with the functaset.
TEST(Functaset, DeclaredToolSymmetriesRoundTripAndComeBeforeTheBuiltInOnes) {
  Functaset f = MakeFunctaset();
  EXPECT_EQ(f.ToolSymmetryOrder("edge"), 1);
  f.set_tool_symmetries({{"edge", 2}, {"ball", 0}});
  const Functaset loaded = Functaset::Parse(f.Serialize(), "mem");
  EXPECT_EQ(loaded.tool_symmetries(), f.tool_symmetries());
  bool known = false;
  EXPECT_EQ(loaded.ToolSymmetryOrder("edge", &known), 2);
  EXPECT_TRUE(known);
  EXPECT_EQ(loaded.ToolSymmetryOrder("ball"), 0);
  EXPECT_EQ(loaded.ToolSymmetryOrder("rod"), 2);  // built in
  EXPECT_EQ(loaded.ToolSymmetryOrder("mystery", &known), 1);
  EXPECT_FALSE(known);
  const std::string bytes =
      WithMeta(f, [](nlohmann::json& m) { m["tool_symmetry"]["edge"] = -2; });
  ExpectFileError([&] { Functaset::Parse(bytes, "edited.tfs"); },
                  {"edited.tfs", "tool_symmetry.edge"});
}

TEST(Functaset, LatentPrecisionNamesRoundTrip) {
  for (const char* name : {"float32", "float16", "uint8", "uint6", "uint4", "allocated"}) {
    Functaset::LatentPrecision p;
    ASSERT_TRUE(LatentPrecisionFromString(name, &p)) << name;
    EXPECT_STREQ(ToString(p), name);
  }
  Functaset::LatentPrecision p;
  EXPECT_FALSE(LatentPrecisionFromString("uint16", &p));
}

}  // namespace
}  // namespace tactfunc
