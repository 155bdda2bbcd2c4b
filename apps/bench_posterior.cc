// Copyright 2026 The tactfunc Authors.
//
// tactfunc bench posterior: are the pose posteriors calibrated, how accurate are their
// means, and how long does one take?
//
//   tactfunc bench posterior --model M.tfm --pose-model P.tpm --functaset F.tfs --data D
//       [--sensor bubble] [--frames 60] [--samplers sgld,laplace,knn] [--json]
//
// Over the first N labelled test-split frames of the dataset (one sensor), for each
// sampler: the fraction of frames whose true pose lies in the posterior's nominal 50%
// and 90% credible regions (PoseDistribution::Region, sample-quantile method; the true
// yaw taken modulo 2 pi / n to the representative nearest the posterior mean, since the
// posterior is folded by the tool's symmetry; n = 0: yaw set to 0, the yaw direction of
// the region is degenerate and ignored), the RMSE of the posterior mean (position mm,
// yaw deg modulo symmetry, hemisphere left out of yaw), and the median / p90 wall time
// of one posterior (fit + sampling + pose MLP, what PosePosterior::Summary::total_time_ms
// measures). The pose MLP's point estimate g_phi(z*) at the latent fit z* (ceres:10, the
// posterior's own fit settings) is reported beside, as the baseline the posterior mean
// should not be worse than. A photometric trunk's frames are fitted as encode fits
// them (LatentEncoder, the latents train-pose saw); that one fit is the point estimate's
// latent and every sampler's start, and its time counts in each posterior's.
//
// Coverage bounds (decision): "coverage_bounds_99" is the central 99% interval of the
// coverage a CALIBRATED sampler would show on N frames, [q_0.005, q_0.995] of
// Binomial(N, p) / N. An observed coverage outside it rejects calibration at the 1%
// level (frames are independent contacts). With N = 60 the 90% band is about
// [0.78, 0.98]: wide, so say "not rejected" rather than "calibrated".
//
// The knn sampler searches the functaset's TRAIN-split latents only (the test frames'
// own entries would otherwise be found at distance ~0 and make the coverage trivial).
// Timing is serial on one thread, one measurement per frame (as bench fit).
//
// Under mpirun (docs/SCALING.md) the frames are shared out over the processes and their
// per-frame records gathered: the figures are those of one process, the times each
// frame's own (still one thread per process), and rank 0 alone prints.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <optional>
#include <utility>

#include "CLI/CLI.hpp"
#include "apps/bench.h"
#include "apps/bench/fit_common.h"
#include "apps/command.h"
#include "apps/dataset_flags.h"
#include "apps/distributed.h"
#include "apps/model_inputs.h"
#include "apps/progress_bar.h"
#include "estimation/data/dataset.h"
#include "estimation/data/photometric_markers.h"
#include "estimation/functaset/functaset.h"
#include "estimation/functaset/latent_encoder.h"
#include "estimation/fitting/latent_fitter.h"
#include "estimation/data/trunk_targets.h"
#include "models/trunk/functa_model.h"
#include "models/simulator/tool.h"
#include "estimation/posterior/pose_posterior.h"
#include "estimation/synthesis/generator_posterior.h"
#include "models/pose/pose_generator.h"

namespace tactfunc::apps {
namespace {

using bench::Median;
using bench::Quantile;

struct PosteriorBenchFlags {
  std::string model;
  std::string pose_model;
  std::string functaset;
  std::string data;
  DatasetFlags dataset;  // data without metadata (a video, a user's folder)
  std::string sensor;
  int frames = 60;
  std::string samplers = "sgld,laplace,knn";
  int samples = 100;
  std::uint64_t seed = 0;
  int knn_k = 8;
  int sgld_minibatch = PosePosterior::kDefaultSgldMinibatch;
  int max_pixels = 0;  // the latent path's; 0 = every valid pixel
  bool json = false;
  bool no_model_error = false;
  double sigma_z = 0;
  double sigma = 0;
  std::string generator;  // adds the generator path's row (bubble)
  std::string generator_model;      // the generator's trunk, if not --model's
  std::string generator_functaset;  // k-NN starts under --generator-model
};

struct Tally {
  PosteriorSampler sampler;
  std::string name;  // the sampler's name, or "generator"
  std::map<std::string, std::pair<double, int>> tool_position_sq, tool_yaw_sq;
  int frames = 0, failures = 0, covered_50 = 0, covered_90 = 0;
  double position_sq = 0, yaw_sq = 0;
  int yaw_count = 0;
  std::vector<double> ms;
  std::vector<double> ms_after_fit;  // sampler + pose MLP + moments, given the latent fit
};

// A pose in a frame's record (x, y, yaw as doubles, bit for bit).
void PutPose(const SE2d& pose, ByteWriter* out) {
  out->Put(pose.x());
  out->Put(pose.y());
  out->Put(pose.yaw());
}

SE2d GetPose(ByteReader& in) {
  const double x = in.Get<double>();
  const double y = in.Get<double>();
  const double yaw = in.Get<double>();
  return SE2d::FromXYYaw(x, y, yaw);
}

void RunPosteriorBench(const PosteriorBenchFlags& flags) {
  std::vector<Tally> tallies;
  for (const std::string& name : SplitList(flags.samplers)) {
    Tally t;
    if (!PosteriorSamplerFromString(name, &t.sampler)) {
      throw UsageError("--samplers: expected a list of sgld, laplace, knn, got '" + name + "'");
    }
    t.name = ToString(t.sampler);
    tallies.push_back(t);
  }
  if (tallies.empty()) throw UsageError("--samplers: empty list");
  const std::size_t num_latent = tallies.size();
  if (!flags.generator.empty()) {
    Tally t;
    t.name = "generator";
    tallies.push_back(t);
  }

  const FunctaModel model = FunctaModel::Load(flags.model);
  const Functaset functaset = Functaset::Load(flags.functaset);
  functaset.CheckModel(model, flags.model, flags.functaset);
  const Dataset dataset = OpenDataset(flags.data, flags.dataset);
  SensorKind sensor;
  if (!ParseSensorFlag(flags.sensor, &sensor)) {
    sensor = dataset.has_sensor(SensorKind::kSoftBubble) ? SensorKind::kSoftBubble
                                                         : dataset.sensors().at(0);
  }
  if (!dataset.has_sensor(sensor)) {
    throw DatasetError("--data '" + flags.data + "' has no " + ToString(sensor) + " frames");
  }
  if (!model.HasSensor(sensor)) {
    throw DatasetError("--model '" + flags.model + "' has no trunk for sensor " + ToString(sensor));
  }
  const SensorTrunk& trunk = model.Trunk(sensor);
  const PoseMlp pose_model = LoadPoseModelFor(flags.pose_model, model, sensor, flags.model);

  // --frames labelled test frames spread evenly over the split (datasets list frames
  // tool by tool, so the first N would cover only the first tools).
  std::vector<std::size_t> labelled;
  for (std::size_t index : dataset.FrameIndices(sensor, Split::kTest)) {
    if (dataset.frames()[index].label.has_value()) labelled.push_back(index);
  }
  std::vector<std::size_t> frames;
  const std::size_t wanted = std::min<std::size_t>(flags.frames, labelled.size());
  for (std::size_t k = 0; k < wanted; ++k) frames.push_back(labelled[k * labelled.size() / wanted]);
  if (frames.empty()) {
    throw DatasetError("--data '" + flags.data + "' has no labelled test-split " +
                       ToString(sensor) + " frames");
  }
  const int num_frames = static_cast<int>(frames.size());

  PosePosterior::Options options;
  options.num_samples = flags.samples;
  options.seed = flags.seed;
  options.knn.k = flags.knn_k;
  options.sgld.minibatch_size = flags.sgld_minibatch;
  options.problem.max_pixels = flags.max_pixels;
  // Centre on the latent map the pose MLP was trained on (estimation/posterior/pose_posterior.h);
  // a photometric trunk's latent is fitted as encode fits it (LatentEncoder), and every
  // sampler starts from that fit, whose time counts in each posterior's.
  const bool photometric = trunk.photometric != nullptr;
  if (!photometric) options.fit.strategy = LatentMapOfPoseModel(pose_model, trunk);
  options.model_error = !flags.no_model_error;
  options.sgld.num_threads = 1;  // one core, as the header says (chains run serially)
  if (flags.sigma_z > 0) options.problem.sigma_z = flags.sigma_z;
  if (flags.sigma > 0) options.problem.sigma = flags.sigma;
  std::string error;
  if (!options.IsValid(&error)) throw UsageError(error);
  FunctasetKnn knn;
  bool need_knn = false;
  for (const Tally& t : tallies) need_knn |= t.sampler == PosteriorSampler::kKnn;
  if (need_knn) {
    knn = MakeFunctasetKnn(functaset, sensor, /*train_only=*/true, options.knn, flags.functaset);
  }
  GeneratorModel generator_model;
  std::unique_ptr<PoseGenerator> generator;
  std::unique_ptr<KnnPoseStarts> knn_starts;
  std::unique_ptr<GeneratorPosterior> generator_posterior;
  if (!flags.generator.empty()) {
    if (sensor != SensorKind::kSoftBubble || photometric) {
      throw UsageError("--generator: the generator path models Soft Bubble frames, not " +
                       std::string(ToString(sensor)));
    }
    // The generator's trunk: --generator-model's (its k-NN starts from
    // --generator-functaset, if given), else --model's (k-NN starts from --functaset).
    if (flags.generator_model.empty() && !flags.generator_functaset.empty()) {
      throw UsageError(
          "--generator-functaset goes with --generator-model (without it the "
          "generator path's k-NN starts come from --functaset)");
    }
    generator_model = LoadGeneratorModel(flags.generator_model, model, flags.model, sensor);
    const FunctaModel* renderer = generator_model.model;
    const std::string& renderer_path = generator_model.path;
    generator = std::make_unique<PoseGenerator>(
        LoadPoseGeneratorFor(flags.generator, *renderer, sensor, renderer_path));
    if (renderer == &model) {
      knn_starts = std::make_unique<KnnPoseStarts>(functaset, sensor);
    } else if (!flags.generator_functaset.empty()) {
      const Functaset own = Functaset::Load(flags.generator_functaset);
      own.CheckModel(*renderer, renderer_path, flags.generator_functaset);
      knn_starts = std::make_unique<KnnPoseStarts>(own, sensor);
    }
    GeneratorPosterior::Options go;
    go.seed = flags.seed;
    generator_posterior = std::make_unique<GeneratorPosterior>(
        renderer->Trunk(sensor), *generator, go, knn_starts.get(), &pose_model, &trunk);
  }
  std::vector<std::unique_ptr<PosePosterior>> posteriors;
  for (std::size_t s = 0; s < num_latent; ++s) {
    const Tally& t = tallies[s];
    PosePosterior::Options o = options;
    o.sampler = t.sampler;
    posteriors.push_back(std::make_unique<PosePosterior>(trunk, pose_model, o, knn.posterior.get()));
  }
  // The point estimate's fit: the posterior's own fit on its own latent problem (header
  // comment), as the posterior resolved them (its sigma may come from the pose model's
  // calibration).
  const PosePosterior::Options& resolved = posteriors.front()->options();
  const LatentFitter::Options& fit_options = resolved.fit;
  std::optional<LatentFitter> fitter, meta_fitter;
  std::unique_ptr<LatentEncoder> encoder;
  if (photometric) {
    encoder = PhotometricPoseEncoder(model, flags.model, sensor, pose_model, flags.pose_model);
  } else {
    fitter.emplace(trunk, fit_options);
    // ... and at the functaset's own latent map, K meta-SGD steps from 0 (what `encode`
    // stores and train-pose trains on): the gap between the two is the pose MLP's
    // sensitivity to which latent estimate it is given.
    LatentFitter::Options meta_options = fit_options;
    meta_options.strategy =
        FitStrategy::FromString("meta_sgd:" + std::to_string(trunk.meta_sgd.inner_steps));
    meta_fitter.emplace(trunk, meta_options);
  }

  std::cout << "bench posterior: " << num_frames << " labelled " << ToString(sensor)
            << " test frames of " << flags.data << ", " << flags.samples << " samples, samplers "
            << flags.samplers << (need_knn ? ", knn over " + std::to_string(knn.size) +
                                                 " train latents"
                                           : "")
            << "\n";
  // Under mpirun (docs/SCALING.md) each process takes its share of the frames
  // (ProcessGroup::OwnItems) and packs what it measured per frame; every frame's record
  // is gathered (GatherItems) and tallied in frame order, so the figures are those of one
  // process -- but for the times, each measured on the process that ran the frame.
  const ProcessGroup& processes = Processes();
  const std::vector<std::int64_t> own = processes.OwnItems(num_frames);
  ProgressBar bar("posterior", static_cast<std::int64_t>(num_frames) * tallies.size(), "posteriors");
  const std::int64_t ticks_per_frame = static_cast<std::int64_t>(tallies.size());
  std::int64_t ticked = 0;
  // The others advance alike: each own frame stands for size() frames on the bar.
  auto tick_frames = [&](std::int64_t count) {
    const std::int64_t n = std::min(count * ticks_per_frame, num_frames * ticks_per_frame - ticked);
    if (n > 0) {
      bar.Tick(n);
      ticked += n;
    }
  };
  std::optional<DatasetMarkers> frame_markers;
  if (photometric) frame_markers.emplace(dataset, trunk);
  std::vector<Bytes> measured;
  for (const std::int64_t k : own) {
    const std::size_t index = frames[static_cast<std::size_t>(k)];
    const PoseLabel& label = *dataset.frames()[index].label;
    const int n = dataset.ToolSymmetryOrder(label.tool);
    const TrunkTargets targets = LoadTrunkTargets(dataset, index, trunk.format);
    ByteWriter record;
    Eigen::VectorXd latent;
    double fit_ms = 0;  // the photometric fit's, added to each posterior's time
    // A photometric trunk draws each frame against its own reference (its clip's).
    const PhotometricTrunk::Markers* markers =
        frame_markers ? frame_markers->Of(index) : nullptr;
    if (photometric) {
      // encode's fit is both the point estimate's latent and the functaset's map.
      EncodedFrameFit fit = EncodeFrame(*encoder, sensor, targets, markers);
      latent = std::move(fit.latent);
      fit_ms = fit.ms;
      PutPose(pose_model.Predict(latent, n), &record);
      PutPose(pose_model.Predict(latent, n), &record);
    } else {
      const LatentProblem problem(trunk, targets, resolved.problem);
      fitter->Fit(problem, &latent);
      PutPose(pose_model.Predict(latent, n), &record);
      Eigen::VectorXd meta_latent;
      meta_fitter->Fit(problem, &meta_latent);
      PutPose(pose_model.Predict(meta_latent, n), &record);
    }
    if (generator_posterior) {
      const SE2d& label_pose = label.sensor_T_object;
      PoseMixture mixture;
      const bool known = generator->ToolIndex(label.tool) >= 0;
      GeneratorPosterior::Summary gs;
      if (known) gs = generator_posterior->Estimate(targets, label.tool, &mixture);
      const bool usable = known && gs.usable;
      // The generator's times count for usable estimates only.
      record.Put<std::uint8_t>(usable);
      if (usable) {
        record.Put(gs.total_time_ms);
        record.Put(gs.total_time_ms - gs.fit_time_ms);
      }
      if (!usable) {
        record.PutString(known ? gs.message : "the generator does not know tool " + label.tool);
      } else {
        record.Put<std::uint8_t>(mixture.Contains(label_pose, 0.5, 400, flags.seed, label.tool));
        record.Put<std::uint8_t>(mixture.Contains(label_pose, 0.9, 400, flags.seed, label.tool));
        PutPose(gs.mean, &record);
      }
    }
    for (std::size_t s = 0; s < num_latent; ++s) {
      std::optional<PoseDistribution> distribution;
      PosePosterior::Summary summary;
      if (photometric) {
        summary = posteriors[s]->Estimate(targets, latent, n, &distribution, nullptr, markers);
        summary.fit_time_ms = fit_ms;
        summary.total_time_ms += fit_ms;
      } else {
        summary = posteriors[s]->Estimate(targets, n, &distribution);
      }
      record.Put(summary.total_time_ms);
      record.Put(summary.total_time_ms - summary.fit_time_ms);
      const bool usable = summary.IsSolutionUsable() && distribution.has_value();
      record.Put<std::uint8_t>(usable);
      if (!usable) {
        record.PutString(summary.message);
        continue;
      }
      const SE2d& mean = summary.mean;
      const SE2d& label_pose = label.sensor_T_object;
      const SE2d truth = SE2d::FromXYYaw(label_pose.x(), label_pose.y(),
                                         FoldYawNear(label_pose.yaw(), mean.yaw(), n));
      record.Put<std::uint8_t>(distribution->Region(0.5).Contains(truth));
      record.Put<std::uint8_t>(distribution->Region(0.9).Contains(truth));
      PutPose(mean, &record);
    }
    measured.push_back(std::move(record.bytes()));
    tick_frames(processes.size());
  }
  const std::vector<Bytes> records = processes.GatherItems(num_frames, measured);
  tick_frames(num_frames);
  bar.Finish();

  // The tally, in frame order.
  double point_position_sq = 0, point_yaw_sq = 0, meta_position_sq = 0, meta_yaw_sq = 0;
  int point_yaw_count = 0;
  for (int k = 0; k < num_frames; ++k) {
    const std::size_t index = frames[static_cast<std::size_t>(k)];
    const PoseLabel& label = *dataset.frames()[index].label;
    const SE2d& label_pose = label.sensor_T_object;
    const int n = dataset.ToolSymmetryOrder(label.tool);
    ByteReader record(records[static_cast<std::size_t>(k)]);
    const SE2d point = GetPose(record);
    point_position_sq +=
        std::pow(point.x() - label_pose.x(), 2) + std::pow(point.y() - label_pose.y(), 2);
    const SE2d meta_point = GetPose(record);
    meta_position_sq +=
        std::pow(meta_point.x() - label_pose.x(), 2) + std::pow(meta_point.y() - label_pose.y(), 2);
    if (n != 0) {
      point_yaw_sq += std::pow(YawErrorModuloSymmetry(point.yaw(), label_pose.yaw(), n), 2);
      meta_yaw_sq += std::pow(YawErrorModuloSymmetry(meta_point.yaw(), label_pose.yaw(), n), 2);
      ++point_yaw_count;
    }
    auto per_tool = [&](Tally& t, const SE2d& mean) {
      auto& p = t.tool_position_sq[label.tool];
      p.first += std::pow(mean.x() - label_pose.x(), 2) + std::pow(mean.y() - label_pose.y(), 2);
      ++p.second;
      if (n != 0) {
        auto& y = t.tool_yaw_sq[label.tool];
        y.first += std::pow(YawErrorModuloSymmetry(mean.yaw(), label_pose.yaw(), n), 2);
        ++y.second;
      }
    };
    // One sampler's outcome on this frame (after its times) into its tally.
    auto tally = [&](Tally& t, bool usable, const std::string& failed_as) {
      ++t.frames;
      if (!usable) {
        ++t.failures;
        std::cerr << "bench posterior: " << failed_as << " failed on frame "
                  << dataset.frames()[index].id << ": " << record.GetString() << "\n";
        return;
      }
      t.covered_50 += record.Get<std::uint8_t>() != 0;
      t.covered_90 += record.Get<std::uint8_t>() != 0;
      const SE2d mean = GetPose(record);
      t.position_sq +=
          std::pow(mean.x() - label_pose.x(), 2) + std::pow(mean.y() - label_pose.y(), 2);
      if (n != 0) {
        t.yaw_sq += std::pow(YawErrorModuloSymmetry(mean.yaw(), label_pose.yaw(), n), 2);
        ++t.yaw_count;
      }
      per_tool(t, mean);
    };
    if (generator_posterior) {
      Tally& t = tallies.back();
      const bool usable = record.Get<std::uint8_t>() != 0;
      if (usable) {
        t.ms.push_back(record.Get<double>());
        t.ms_after_fit.push_back(record.Get<double>());
      }
      tally(t, usable, "generator");
    }
    for (std::size_t s = 0; s < num_latent; ++s) {
      Tally& t = tallies[s];
      t.ms.push_back(record.Get<double>());
      t.ms_after_fit.push_back(record.Get<double>());
      tally(t, record.Get<std::uint8_t>() != 0, ToString(t.sampler));
    }
  }

  const double point_mm = 1e3 * std::sqrt(point_position_sq / num_frames);
  const double point_deg =
      point_yaw_count ? kDeg * std::sqrt(point_yaw_sq / point_yaw_count) : NAN;
  const double meta_mm = 1e3 * std::sqrt(meta_position_sq / num_frames);
  const double meta_deg = point_yaw_count ? kDeg * std::sqrt(meta_yaw_sq / point_yaw_count) : NAN;
  const auto band50 = BinomialInterval99(num_frames, 0.5), band90 = BinomialInterval99(num_frames, 0.9);
  std::printf("%-8s %6s %4s | %-18s | %-18s | %8s %8s | %8s %8s\n", "sampler", "frames", "fail",
              "cover 50% [99% band]", "cover 90% [99% band]", "mean mm", "mean deg", "ms med",
              "ms p90");
  nlohmann::json list = nlohmann::json::array();
  for (const Tally& t : tallies) {
    const double c50 = static_cast<double>(t.covered_50) / t.frames;
    const double c90 = static_cast<double>(t.covered_90) / t.frames;
    const int ok = t.frames - t.failures;
    const double mm = ok ? 1e3 * std::sqrt(t.position_sq / ok) : NAN;
    const double deg = t.yaw_count ? kDeg * std::sqrt(t.yaw_sq / t.yaw_count) : NAN;
    std::printf("%-8s %6d %4d | %5.3f [%4.2f, %4.2f]%s | %5.3f [%4.2f, %4.2f]%s | %8.3f %8.2f | "
                "%8.1f %8.1f   (%.1f ms after the fit)\n",
                t.name.c_str(), t.frames, t.failures, c50, band50.first, band50.second,
                (c50 < band50.first || c50 > band50.second) ? "!" : " ", c90, band90.first,
                band90.second, (c90 < band90.first || c90 > band90.second) ? "!" : " ", mm, deg,
                Median(t.ms), Quantile(t.ms, 0.9), Median(t.ms_after_fit));
    nlohmann::json tools = nlohmann::json::object();
    for (const auto& [tool, v] : t.tool_position_sq) {
      const auto y = t.tool_yaw_sq.find(tool);
      tools[tool] = {{"rmse_mm", 1e3 * std::sqrt(v.first / v.second)},
                     {"rmse_deg", y == t.tool_yaw_sq.end()
                                      ? nlohmann::json()
                                      : nlohmann::json(kDeg * std::sqrt(y->second.first /
                                                                        y->second.second))},
                     {"frames", v.second}};
    }
    list.push_back({{"name", t.name},
                    {"per_tool", tools},
                    {"coverage", {{"0.5", c50}, {"0.9", c90}}},
                    {"coverage_bounds_99",
                     {{"0.5", {band50.first, band50.second}}, {"0.9", {band90.first, band90.second}}}},
                    {"rmse_mm", NumberOrNull(mm)},
                    {"rmse_deg", NumberOrNull(deg)},
                    {"ms_median", NumberOrNull(Median(t.ms))},
                    {"ms_p90", NumberOrNull(Quantile(t.ms, 0.9))},
                    {"ms_median_after_fit", NumberOrNull(Median(t.ms_after_fit))},
                    {"failures", t.failures},
                    {"point_rmse_mm", NumberOrNull(point_mm)},
                    {"point_rmse_deg", NumberOrNull(point_deg)}});
  }
  // Error per tool and method: RMSE of the posterior mean (mode for the generator).
  std::printf("%-11s", "tool");
  for (const Tally& t : tallies) std::printf(" | %-9s mm   deg", t.name.c_str());
  std::printf("\n");
  std::map<std::string, int> tool_names;
  for (const Tally& t : tallies) {
    for (const auto& [tool, v] : t.tool_position_sq) tool_names[tool] = 0;
  }
  for (const auto& [tool, unused] : tool_names) {
    std::printf("%-11s", tool.c_str());
    for (const Tally& t : tallies) {
      const auto p = t.tool_position_sq.find(tool);
      const auto y = t.tool_yaw_sq.find(tool);
      const double mm = p == t.tool_position_sq.end() ? NAN : 1e3 * std::sqrt(p->second.first / p->second.second);
      const double deg = y == t.tool_yaw_sq.end() ? NAN : kDeg * std::sqrt(y->second.first / y->second.second);
      std::printf(" | %12.3f %6.2f", mm, deg);
    }
    std::printf("\n");
  }
  if (photometric) {
    std::printf("pose MLP point estimate g(z*), z* = encode's %s fit (the functaset's latent "
                "map and every sampler's start): %.3f mm, %.2f deg\n",
                encoder->StrategyOf(sensor).ToString().c_str(), point_mm, point_deg);
  } else {
    std::printf("pose MLP point estimate g(z*), z* = the posterior's fit: %.3f mm, %.2f deg\n",
                point_mm, point_deg);
    std::printf("pose MLP point estimate g(z_K), z_K = %d meta-SGD steps (the functaset's "
                "latent map): %.3f mm, %.2f deg\n",
                trunk.meta_sgd.inner_steps, meta_mm, meta_deg);
  }
  std::printf("(coverage: fraction of frames whose true pose lies in the nominal region; "
              "[band] = central 99%% range for a calibrated sampler on %d frames, '!' = outside; "
              "RMSE of the posterior mean, yaw modulo symmetry)\n",
              num_frames);
  if (flags.json) {
    EmitJson({{"bench", "posterior"},
              {"sensor", ToString(sensor)},
              {"samplers", list},
              {"frames", num_frames},
              {"point_meta_sgd_rmse_mm", NumberOrNull(meta_mm)},
              {"point_meta_sgd_rmse_deg", NumberOrNull(meta_deg)},
              {"samples", flags.samples},
              {"machine", MachineDescription()}});
  }
}

}  // namespace

void RegisterPosteriorBenchmark(CLI::App* bench, CommandBody* selected) {
  auto flags = std::make_shared<PosteriorBenchFlags>();
  CLI::App* sub = bench->add_subcommand(
      "posterior",
      "Pose posteriors on a dataset's test frames: 50%/90% region coverage with 99% binomial "
      "bands, RMSE of the mean and of the MLP point estimate, median ms per posterior.");
  sub->add_option("--model", flags->model, "Model file (.tfm)")->required();
  sub->add_option("--pose-model", flags->pose_model, "Pose model from `tactfunc train-pose`")
      ->required();
  sub->add_option("--functaset", flags->functaset,
                  "Functaset (.tfs) of the model (knn sampler: its train latents)")
      ->required();
  sub->add_option("--data", flags->data, "Dataset folder with labelled test frames")->required();
  AddDatasetFlags(sub, &flags->dataset, {"--sensor"});
  sub->add_option("--sensor", flags->sensor, "bubble or gelslim (default bubble if present)");
  sub->add_option("--frames", flags->frames, "First N labelled test frames (default 60)")
      ->check(CLI::Range(1, 1000000));
  sub->add_option("--samplers", flags->samplers, "Comma-separated (default sgld,laplace,knn)");
  sub->add_option("--generator", flags->generator,
                  "Generator (.tpg): adds the generator path's row (Laplace mixture over the "
                  "pose modes, k-NN starts from --functaset, the label's tool; bubble only)");
  sub->add_option("--generator-model", flags->generator_model,
                  "Model whose trunk --generator renders through, if not --model's (same frame "
                  "format; the pose model's start still reads --model's latents)");
  sub->add_option("--generator-functaset", flags->generator_functaset,
                  "With --generator-model: a functaset of that model for the generator path's "
                  "k-NN starts (without it, none)");
  sub->add_option("--samples", flags->samples, "Pose samples per posterior (default 100)")
      ->check(CLI::Range(1, 1000000));
  sub->add_option("--seed", flags->seed, "Sampler seed (default 0)");
  sub->add_option("--knn-k", flags->knn_k, "Neighbours of the knn sampler (default 8)")
      ->check(CLI::Range(1, 100000));
  sub->add_option("--sgld-minibatch", flags->sgld_minibatch,
                  "Pixels per SGLD gradient, with the control variate at the fitted latent; 0 = "
                  "every pixel (default " +
                      std::to_string(PosePosterior::kDefaultSgldMinibatch) + ")")
      ->check(CLI::Range(0, 100000000));
  sub->add_option("--max-pixels", flags->max_pixels,
                  "Latent path: fit and sample at most N of each frame's valid pixels, evenly "
                  "spaced; 0 = every one (default 0)")
      ->check(CLI::Range(0, 100000000));
  sub->add_option("--sigma-z", flags->sigma_z,
                  "Latent prior standard deviation sigma_z (default: PosePosterior's)")
      ->check(CLI::PositiveNumber);
  sub->add_option("--sigma", flags->sigma,
                  "Pixel noise sigma, normalised units (default: the trunk's residual_sigma)")
      ->check(CLI::PositiveNumber);
  sub->add_flag("--no-model-error", flags->no_model_error,
                "Leave the pose MLP's calibrated error out of the sgld/laplace samples (the "
                "latent posterior alone; docs/POSES.md, Calibration)");
  sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
  sub->callback([flags, selected]() { *selected = [flags]() { RunPosteriorBench(*flags); }; });
}

}  // namespace tactfunc::apps
