// Copyright 2026 The tactfunc Authors.
//
// Writes the fuzz targets' seed corpora with tactfunc's own writers:
//   make_seed_corpora OUT_DIR
// creates OUT_DIR/<target>/seed_* for tensor_file, model, functaset, pose_model,
// knn_index, labels_csv, dataset and image (scripts/fuzz.sh calls it).
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <sstream>
#include <string>
#include <vector>

#include "estimation/data/dataset.h"
#include "estimation/data/image_io.h"
#include "estimation/data/internal/labels_csv.h"
#include "estimation/functaset/functaset.h"
#include "estimation/knn/knn_index.h"
#include "models/core/tensor_file.h"
#include "models/pose/pose_mlp.h"
#include "models/pose/pose_model_provenance.h"
#include "models/trunk/functa_model.h"
#include "tests/support/functa_test_util.h"

namespace fs = std::filesystem;
using namespace tactfunc;

namespace {

std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

void Put(const fs::path& dir, const std::string& name, const std::string& bytes) {
  fs::create_directories(dir);
  std::ofstream(dir / name, std::ios::binary) << bytes;
}

// A small two-sensor model (keeps the seeds a few kB, so mutations are fast).
FunctaModel SmallModel() {
  using testing_util::MakeTrunk;
  FunctaModel model;
  model.SetTrunk(MakeTrunk(SensorKind::kSoftBubble, 6, 5, 0.01, false, 8, 1, 4, 0.5, 3, 1));
  model.SetTrunk(MakeTrunk(SensorKind::kGelSlim, 4, 5, 0.5, true, 8, 1, 3, 0.5, 2, 2));
  return model;
}

Functaset SmallFunctaset(Functaset::LatentPrecision precision) {
  Functaset functaset;
  functaset.set_model_checksum(1234567);
  functaset.set_dataset("/data/sim");
  functaset.set_latent_precision(precision);
  functaset.AddSensor(SensorKind::kSoftBubble, 4);
  functaset.set_fit_strategy(SensorKind::kSoftBubble, "meta_sgd:3");
  for (int i = 0; i < 4; ++i) {
    FunctasetEntry entry;
    entry.id = testing_util::FrameId(i);
    entry.split = i == 3 ? Split::kTest : Split::kTrain;
    if (i != 2) entry.label = PoseLabel{"pen", SE2d::FromXYYaw(0.001 * i, -0.001, 0.3 * i), 0.002};
    entry.latent = Eigen::VectorXf::LinSpaced(4, -1.0f + i, 1.0f + 0.5f * i);
    entry.psnr = 30.0f + i;
    functaset.Add(SensorKind::kSoftBubble, entry);
  }
  functaset.set_complete(precision != Functaset::LatentPrecision::kFloat16);
  return functaset;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::cerr << "usage: make_seed_corpora OUT_DIR\n";
    return 2;
  }
  const fs::path out = argv[1];
  const fs::path scratch = out / "scratch";
  fs::remove_all(scratch);
  fs::create_directories(scratch);

  // TensorFile: a file of every dtype.
  TensorFile file("model");
  file.set_meta_json(R"({"format": "tactfunc-model", "version": 1, "note": [1, {"a": null}]})");
  file.Add("w", TensorFile::DType::kFloat32, {2, 3}, {1, 2, 3, 4, 5, 6});
  file.Add("h", TensorFile::DType::kFloat16, {2}, {0.5, -2});
  file.Add("d", TensorFile::DType::kFloat64, {1}, {1e-300});
  file.Add("q", TensorFile::DType::kUint8, {3}, {0, 7, 255});
  Put(out / "tensor_file", "seed_all_dtypes", file.Serialize());

  // Model, also a tensor file.
  SmallModel().Save((scratch / "m.tfm").string());
  Put(out / "model", "seed_two_trunks", Slurp((scratch / "m.tfm").string()));
  Put(out / "tensor_file", "seed_model", Slurp((scratch / "m.tfm").string()));

  // Functasets in each latent precision.
  const std::pair<const char*, Functaset::LatentPrecision> precisions[] = {
      {"float32", Functaset::LatentPrecision::kFloat32},
      {"float16", Functaset::LatentPrecision::kFloat16},
      {"uint8", Functaset::LatentPrecision::kUint8},
      {"uint4", Functaset::LatentPrecision::kUint4}};
  for (const auto& [name, precision] : precisions) {
    Put(out / "functaset", std::string("seed_") + name, SmallFunctaset(precision).Serialize());
  }

  // Pose model with its provenance.
  PoseMlp::Options pose_options;
  pose_options.input_dim = 4;
  pose_options.hidden_sizes = {6};
  PoseMlp pose(pose_options, 3);
  PoseModelProvenance provenance;
  provenance.sensor = "bubble";
  provenance.functaset = "f.tfs";
  provenance.model_checksum = 1234567;
  provenance.epochs = 5;
  provenance.seed = 1;
  pose.set_info_json(provenance.ToJson());
  Put(out / "pose_model", "seed_small", pose.Serialize());

  // k-NN indexes: brute force and a FLANN kd-forest, over 12 latents of 4 values.
  Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> latents(12, 4);
  for (int i = 0; i < latents.size(); ++i) latents.data()[i] = static_cast<float>((i * 37) % 11);
  for (const char* type : {"brute_force", "kd_forest", "kmeans"}) {
    KnnIndexOptions options;
    options.type = type;
    const std::string path = (scratch / (std::string(type) + ".knn")).string();
    BuildKnnIndex(latents, options)->Save(path);
    Put(out / "knn_index", std::string("seed_") + type, Slurp(path));
  }

  // A dataset as DatasetWriter writes it (the dataset target's base dataset is the same
  // WriteTinyDataset(dir, 3, clean)): dataset.json, NUL, labels.csv.
  const std::string data = (scratch / "d").string();
  testing_util::WriteTinyDataset(data, 3, /*clean=*/true);
  const std::string json = Slurp(data + "/dataset.json"), labels = Slurp(data + "/labels.csv");
  Put(out / "dataset", "seed_with_labels", json + std::string(1, '\0') + labels);
  Put(out / "dataset", "seed_without_labels", json);
  Put(out / "labels_csv", "seed_dataset", labels);
  std::vector<internal::LabelRow> rows(2);
  rows[0].frame = "a";
  rows[0].label = PoseLabel{"hex_key", SE2d::FromXYYaw(0.001, 0.002, -3.14159), 0.01};
  rows[1].frame = "b";
  rows[1].sensor = SensorKind::kGelSlim;
  rows[1].split = Split::kTest;
  Put(out / "labels_csv", "seed_rows", internal::FormatLabelsCsv(rows));

  // Images: depth and rgb PNGs (first byte: 0 = depth, 1 = rgb8; image_fuzzer.cc).
  Put(out / "image", "seed_depth", std::string(1, '\0') +
                                       EncodePng(testing_util::BubbleFrame(1),
                                                 PixelEncoding::kDepthU16Micrometres));
  Put(out / "image", "seed_rgb",
      std::string(1, '\1') + EncodePng(testing_util::GelFrame(1), PixelEncoding::kRgb8));
  Put(out / "image", "seed_gray",
      std::string(1, '\1') + EncodePng(Image(3, 4, 1, 0.25f), PixelEncoding::kRgb8));

  fs::remove_all(scratch);
  std::cout << "make_seed_corpora: wrote the seed corpora to " << out.string() << "\n";
  return 0;
}
