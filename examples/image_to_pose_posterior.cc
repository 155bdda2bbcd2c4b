// Copyright 2026 The tactfunc Authors.
//
// From one image file to a pose posterior, in library calls (docs/ARCHITECTURE.md, "From
// an image file to a pose posterior"): a Soft Bubble depth frame and its no-contact
// reference are read from PNG files, turned into trunk targets with the pretrained
// model's frame format, and the frame's latent problem is fitted and sampled (Laplace,
// 100 samples) and pushed through the pose model into a distribution over
// sensor_T_object.
//
// So that it needs no data, the example first writes the two files itself: one contact
// of the `triangle` tool rendered by the simulator (its pose is the truth printed at the end).
// Arguments (optional): the model file and the pose model file; by default the
// committed pretrained ones.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <optional>
#include <string>

#include "estimation/data/image_io.h"
#include "estimation/data/trunk_targets.h"
#include "estimation/posterior/pose_posterior.h"
#include "models/pose/pose_mlp.h"
#include "models/simulator/contact_simulator.h"
#include "models/simulator/tool.h"
#include "models/trunk/functa_model.h"

int main(int argc, char** argv) {
  using namespace tactfunc;
  const std::string model_path =
      argc > 1 ? argv[1] : TACTFUNC_SOURCE_DIR "/models/pretrained/default.tfm";
  const std::string pose_model_path =
      argc > 2 ? argv[2] : TACTFUNC_SOURCE_DIR "/models/pretrained/pose_bubble.tpm";
  constexpr double kDeg = 3.14159265358979323846 / 180.0;

  // 1. The files a user would bring: a depth frame and the sensor's reference.
  const ContactSimulator simulator;
  const Contact contact = simulator.SamplePairedContact("triangle", 7).bubble;
  const std::string dir =
      (std::filesystem::temp_directory_path() / "tactfunc_example_image_to_pose").string();
  std::filesystem::create_directories(dir);
  const std::string frame_path = dir + "/frame.png", reference_path = dir + "/reference.png";
  WritePngAtomically(frame_path, simulator.Render(SensorKind::kSoftBubble, contact, 1).frame,
                     PixelEncoding::kDepthU16Micrometres);
  WritePngAtomically(reference_path, simulator.Reference(SensorKind::kSoftBubble),
                     PixelEncoding::kDepthU16Micrometres);

  // 2. Read them back and make the trunk's targets (difference from the reference,
  //    normalised and resized to the trunk's working format).
  const Image frame = ReadImage(frame_path, PixelEncoding::kDepthU16Micrometres);
  const Image reference = ReadImage(reference_path, PixelEncoding::kDepthU16Micrometres);
  const FunctaModel model = FunctaModel::Load(model_path);
  const SensorTrunk& trunk = model.Trunk(SensorKind::kSoftBubble);
  const TrunkTargets targets = MakeTrunkTargets(frame, reference, SensorKind::kSoftBubble,
                                                trunk.format);

  // 3. The pose posterior: fit the frame's latent problem on the latent map the pose
  //    model was trained on, sample it (Laplace), map every sample to a pose.
  const PoseMlp pose_model = PoseMlp::Load(pose_model_path);
  PosePosterior::Options options;
  options.sampler = PosteriorSampler::kLaplace;
  options.num_samples = 100;
  options.seed = 1;
  options.fit.strategy = LatentMapOfPoseModel(pose_model, trunk);
  const int symmetry_order = GetTool(contact.tool).symmetry_order();
  std::optional<PoseDistribution> posterior;
  const PosePosterior::Summary summary =
      PosePosterior(trunk, pose_model, options).Estimate(targets, symmetry_order, &posterior);
  std::printf("%s\n", summary.BriefReport().c_str());
  if (!summary.IsSolutionUsable()) return 1;

  // 4. What a filter consumes: the mean sensor_T_object and the 3x3 covariance in the
  //    tangent space at the mean (x m, y m, yaw rad; right perturbations).
  const SE2d& mean = summary.mean;
  std::printf("fit: %s\n", summary.fit_summary.BriefReport().c_str());
  std::printf("mean   x %.2f mm, y %.2f mm, yaw %.1f deg\n", 1e3 * mean.x(), 1e3 * mean.y(),
              mean.yaw() / kDeg);
  std::printf("stddev x %.2f mm, y %.2f mm, yaw %.1f deg\n",
              1e3 * std::sqrt(summary.covariance(0, 0)), 1e3 * std::sqrt(summary.covariance(1, 1)),
              std::sqrt(summary.covariance(2, 2)) / kDeg);
  const SE2d& truth = contact.sensor_T_object;
  std::printf("truth  x %.2f mm, y %.2f mm, yaw %.1f deg (%.1f modulo the %s's symmetry order %d)\n",
              1e3 * truth.x(), 1e3 * truth.y(), truth.yaw() / kDeg,
              FoldYawNear(truth.yaw(), mean.yaw(), symmetry_order) / kDeg,
              contact.tool.c_str(), symmetry_order);
  std::printf("%zu pose samples from %s\n", posterior->samples().size(), frame_path.c_str());
  return 0;
}
