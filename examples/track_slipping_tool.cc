// Copyright 2026 The tactfunc Authors.
//
// Track a tool slipping in the grasp with a particle filter over per-frame pose
// posteriors (estimation/pose/pose_filter.h, docs/FILTERING.md).
//
// The chain, per frame t = 0 .. T-1:
//   1. ContactSimulator renders a Soft Bubble frame of the tool at the true pose
//      sensor_T_object(t), which drifts smoothly -- s(t) = (1 - cos(pi t / (T - 1))) / 2 --
//      from (x, y, yaw) = (-1.5 mm, 1 mm, 10 deg) to (1.5 mm, -1 mm, 30 deg): 3.6 mm and
//      20 deg in total, starting and stopping gently as a slip does. The frame is stored
//      and read back in the dataset's 16-bit micrometre encoding, as training frames are.
//   2. A per-frame posterior turns the frame into a PoseDistribution. laplace (default)
//      and sgld: PosePosterior (estimation/posterior/pose_posterior.h), a Ceres fit of the
//      latent z*, N(z*, H^-1) or SGLD latents, pushed through the pose MLP. generator:
//      GeneratorPosterior (estimation/synthesis/generator_posterior.h), the pose itself
//      fitted through the pose generator and the trunk on SE(2), draws from the Laplace
//      mixture over its modes for the scene's tool. Folded by the tool's symmetry order.
//   3. SE2ParticleFilter: x_i <- x_i Exp(w_i), w_i ~ N(0, Q) (a slip of ~0.2 mm and ~1 deg
//      per frame), then w_i <- w_i * sum_j w_j N(Log(s_j^-1 x_i); 0, h^2 Sigma_z + K_floor).
// It prints, per frame, the error of the per-frame posterior mean and of the filtered
// mean (position in mm, yaw in deg modulo the tool's symmetry), then both RMSEs: the
// before -> after line.
//
// Flags (the defaults run as is from a build tree):
//   --model M.tfm          trunk (default: models/pretrained/default.tfm in the sources)
//   --pose-model P.tpm     pose MLP trained by `tactfunc train-pose` on that trunk's
//                          Soft Bubble latents (default: TACTFUNC_EXAMPLE_POSE_MODEL,
//                          models/pretrained/pose_bubble.tpm in the sources)
//   --tool NAME            default l_shape (asymmetric); any name of `tactfunc info --tools`
//   --frames N             default 30
//   --sampler laplace|sgld|generator  default laplace (fast: ~10-50 ms per frame);
//                          generator fits the pose through the trunk (slower, sharper)
//   --generator G.tpg      pose generator for --sampler generator (default:
//                          models/pretrained/pose_generator_bubble.tpg in the sources)
//   --generator-model M.tfm  the trunk the generator renders through (default:
//                          models/pretrained/bubble.tfm in the sources); the pose MLP's
//                          start still reads --model's latents
//   --samples N            pose samples per frame, default 100
//   --particles N          default 1000
//   --seed S               default 1 (frames' noise, posteriors and the filter)
//   --constant-velocity    the filter's constant-velocity motion model (default: random
//                          walk; pose_filter.h)
//   --skip-if-no-pose-model  exit 77 (ctest's SKIP) with a message when the pose model
//                          file does not exist, instead of failing
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include "estimation/data/image_io.h"
#include "estimation/pose/pose_distribution.h"
#include "estimation/pose/pose_filter.h"
#include "estimation/data/trunk_targets.h"
#include "models/simulator/contact_simulator.h"
#include "models/trunk/functa_model.h"
#include "models/pose/pose_mlp.h"
#include "models/core/seed.h"
#include "models/simulator/tool.h"
#include "estimation/posterior/pose_posterior.h"
#include "estimation/synthesis/generator_posterior.h"
#include "models/pose/pose_generator.h"

#ifndef TACTFUNC_SOURCE_DIR
#define TACTFUNC_SOURCE_DIR "."
#endif
#ifndef TACTFUNC_EXAMPLE_POSE_MODEL
#define TACTFUNC_EXAMPLE_POSE_MODEL TACTFUNC_SOURCE_DIR "/models/pretrained/pose_bubble.tpm"
#endif

namespace {

using tactfunc::SE2d;
constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180;
constexpr int kSkip = 77;  // ctest SKIP_RETURN_CODE

struct Flags {
  std::string model = TACTFUNC_SOURCE_DIR "/models/pretrained/default.tfm";
  std::string pose_model = TACTFUNC_EXAMPLE_POSE_MODEL;
  std::string tool = "l_shape";
  std::string sampler = "laplace";
  std::string generator = TACTFUNC_SOURCE_DIR "/models/pretrained/pose_generator_bubble.tpg";
  std::string generator_model = TACTFUNC_SOURCE_DIR "/models/pretrained/bubble.tfm";
  int frames = 30;
  int samples = 100;
  int particles = 1000;
  std::uint64_t seed = 1;
  bool skip_if_no_pose_model = false;
  bool constant_velocity = false;
};

void Usage(std::FILE* out) {
  std::fprintf(out,
               "usage: example_track_slipping_tool [--model M.tfm] [--pose-model P.tpm] "
               "[--tool NAME] [--frames N]\n"
               "       [--sampler laplace|sgld|generator] [--generator G.tpg] "
               "[--generator-model M.tfm] [--samples N] "
               "[--particles N] [--seed S] [--constant-velocity] [--skip-if-no-pose-model]\n");
}

Flags ParseFlags(int argc, char** argv) {
  Flags f;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto value = [&]() -> std::string {
      if (i + 1 >= argc) throw std::invalid_argument(a + " needs a value");
      return argv[++i];
    };
    auto integer = [&](int min) {
      const std::string v = value();
      char* end = nullptr;
      const long n = std::strtol(v.c_str(), &end, 10);
      if (end == v.c_str() || *end != '\0' || n < min) {
        throw std::invalid_argument(a + " expects an integer >= " + std::to_string(min) +
                                    ", got '" + v + "'");
      }
      return static_cast<int>(n);
    };
    if (a == "--model") {
      f.model = value();
    } else if (a == "--pose-model") {
      f.pose_model = value();
    } else if (a == "--tool") {
      f.tool = value();
    } else if (a == "--sampler") {
      f.sampler = value();
    } else if (a == "--generator") {
      f.generator = value();
    } else if (a == "--generator-model") {
      f.generator_model = value();
    } else if (a == "--frames") {
      f.frames = integer(2);
    } else if (a == "--samples") {
      f.samples = integer(1);
    } else if (a == "--particles") {
      f.particles = integer(1);
    } else if (a == "--seed") {
      f.seed = static_cast<std::uint64_t>(integer(0));
    } else if (a == "--skip-if-no-pose-model") {
      f.skip_if_no_pose_model = true;
    } else if (a == "--constant-velocity") {
      f.constant_velocity = true;
    } else if (a == "--help" || a == "-h") {
      Usage(stdout);
      std::exit(0);
    } else {
      throw std::invalid_argument("unknown flag '" + a + "'");
    }
  }
  return f;
}

// The slip: a smooth start and stop between two poses.
SE2d TrueSlip(int t, int frames) {
  const double s = 0.5 * (1 - std::cos(kPi * t / (frames - 1)));
  return SE2d::FromXYYaw((-1.5 + 3.0 * s) * 1e-3, (1.0 - 2.0 * s) * 1e-3, (10 + 20 * s) * kDeg);
}

// What a dataset file holds: 16-bit micrometres (estimation/data/image_io.h).
tactfunc::Image AsStored(const tactfunc::Image& depth, const std::string& name) {
  using tactfunc::PixelEncoding;
  return tactfunc::DecodeImage(tactfunc::EncodePng(depth, PixelEncoding::kDepthU16Micrometres),
                               PixelEncoding::kDepthU16Micrometres, name);
}

// What the filter takes from either posterior.
struct FrameSummary {
  bool usable = false;
  std::string message;
  SE2d mean;
  Eigen::Matrix3d covariance = Eigen::Matrix3d::Identity();
  double total_time_ms = 0;
};

struct Errors {
  double sq_mm = 0, sq_deg = 0;
  int count = 0;
  void Add(double mm, double deg) {
    sq_mm += mm * mm;
    sq_deg += deg * deg;
    ++count;
  }
  double RmseMm() const { return std::sqrt(sq_mm / count); }
  double RmseDeg() const { return std::sqrt(sq_deg / count); }
};

int Run(const Flags& flags) {
  using namespace tactfunc;
  if (!std::filesystem::is_regular_file(flags.pose_model)) {
    const std::string why = "pose model '" + flags.pose_model +
                            "' does not exist; make one with `tactfunc synth`, `tactfunc "
                            "encode` and `tactfunc train-pose` (docs/FILTERING.md) and pass "
                            "--pose-model";
    if (flags.skip_if_no_pose_model) {
      std::printf("SKIP: %s\n", why.c_str());
      return kSkip;
    }
    throw std::invalid_argument(why);
  }
  const bool by_generator = flags.sampler == "generator";
  PosteriorSampler sampler = PosteriorSampler::kLaplace;
  if (!by_generator &&
      (!PosteriorSamplerFromString(flags.sampler, &sampler) || sampler == PosteriorSampler::kKnn)) {
    throw std::invalid_argument("--sampler must be laplace, sgld or generator, got '" +
                                flags.sampler + "'");
  }
  const int n = GetTool(flags.tool).symmetry_order();  // throws for an unknown tool
  const FunctaModel model = FunctaModel::Load(flags.model);
  const SensorKind sensor = SensorKind::kSoftBubble;
  const SensorTrunk& trunk = model.Trunk(sensor);
  const PoseMlp pose_mlp = PoseMlp::Load(flags.pose_model);
  if (pose_mlp.input_dim() != trunk.siren.latent_dim()) {
    throw std::invalid_argument("--pose-model takes " + std::to_string(pose_mlp.input_dim()) +
                                "-d latents, the Soft Bubble trunk of --model has " +
                                std::to_string(trunk.siren.latent_dim()));
  }

  PosePosterior::Options posterior_options;
  posterior_options.sampler = sampler;
  posterior_options.num_samples = flags.samples;
  std::optional<PoseGenerator> generator;
  std::optional<FunctaModel> generator_model;  // the trunk the generator renders through
  if (by_generator) {
    generator_model.emplace(FunctaModel::Load(flags.generator_model));
    generator.emplace(PoseGenerator::Load(flags.generator));
    if (generator->ToolIndex(flags.tool) < 0) {
      throw std::invalid_argument("--tool '" + flags.tool + "': the generator '" +
                                  flags.generator + "' does not know it");
    }
  }

  SE2ParticleFilter::Options filter_options;
  filter_options.num_particles = flags.particles;
  filter_options.symmetry_order = n;
  filter_options.seed = DeriveSeed(flags.seed, 2);
  filter_options.constant_velocity = flags.constant_velocity;
  SE2ParticleFilter filter(filter_options);

  const ContactSimulator simulator;
  const Image reference = AsStored(simulator.Reference(sensor), "reference");
  std::printf(
      "track_slipping_tool: %s (n = %d), %d Soft Bubble frames, %s posteriors of %d "
      "samples, %d particles\n",
      flags.tool.c_str(), n, flags.frames, by_generator ? "generator" : ToString(sampler),
      flags.samples, flags.particles);
  // Per frame: the truth; the per-frame posterior's error and its own standard deviation
  // (sqrt of the x + y variances, and of the yaw variance); the filtered mean's error.
  std::printf("%5s | %7s %7s %6s | %-16s | %-16s | %-16s | %6s  %s\n", "frame", "x mm", "y mm",
              "yaw deg", "per-frame err", "per-frame sd", "filtered err", "ESS", "update");

  Errors per_frame, filtered;
  double posterior_ms = 0, filter_ms = 0;
  for (int t = 0; t < flags.frames; ++t) {
    const SE2d truth = TrueSlip(t, flags.frames);
    Contact contact;
    contact.tool = flags.tool;
    contact.sensor_T_object = truth;
    contact.depth_m = 8e-3;
    const ContactSimulator::Rendering rendering =
        simulator.Render(sensor, contact, DeriveSeed(flags.seed, 3 * t));
    const TrunkTargets targets = MakeTrunkTargets(
        AsStored(rendering.frame, "frame " + std::to_string(t)), reference, sensor, trunk.format);

    // Each frame its own sampler seed: one seed for all would give every frame the same
    // standard-normal draws, i.e. errors the filter cannot average out.
    const std::uint64_t frame_seed = DeriveSeed(flags.seed, 3 * t + 1);
    std::optional<PoseDistribution> distribution;
    FrameSummary summary;
    if (by_generator) {
      // The scene names its tool: only that tool is modelled.
      GeneratorPosterior::Options options;
      options.seed = frame_seed;
      const GeneratorPosterior frame_posterior(generator_model->Trunk(sensor), *generator,
                                               options, nullptr, &pose_mlp, &trunk);
      PoseMixture mixture;
      const GeneratorPosterior::Summary g = frame_posterior.Estimate(targets, flags.tool, &mixture);
      summary = {g.usable, g.message, g.mean, g.covariance, g.total_time_ms};
      if (g.usable) distribution.emplace(mixture.Sample(flags.samples, frame_seed, g.tool));
    } else {
      PosePosterior::Options options = posterior_options;
      options.seed = frame_seed;
      const PosePosterior frame_posterior(trunk, pose_mlp, options);
      const PosePosterior::Summary p = frame_posterior.Estimate(targets, n, &distribution);
      summary = {p.IsSolutionUsable(), p.message, p.mean, p.covariance, p.total_time_ms};
    }
    posterior_ms += summary.total_time_ms;

    filter.Predict();
    std::string update = "no measurement (" + summary.message + ")";
    char frame_text[40], sd_text[40];
    std::snprintf(frame_text, sizeof(frame_text), "%16s", "failed");
    std::snprintf(sd_text, sizeof(sd_text), "%16s", "");
    if (summary.usable && distribution) {
      const SE2ParticleFilter::UpdateSummary u = filter.Update(*distribution);
      filter_ms += u.time_ms;
      update = ToString(u.type);
      const double mm =
          1e3 * std::hypot(summary.mean.x() - truth.x(), summary.mean.y() - truth.y());
      const double deg = YawErrorModuloSymmetry(summary.mean.yaw(), truth.yaw(), n) / kDeg;
      per_frame.Add(mm, deg);
      std::snprintf(frame_text, sizeof(frame_text), "%6.3f mm %5.2f", mm, deg);
      const Eigen::Matrix3d& c = summary.covariance;
      std::snprintf(sd_text, sizeof(sd_text), "%6.3f mm %5.2f", 1e3 * std::sqrt(c(0, 0) + c(1, 1)),
                    std::sqrt(c(2, 2)) / kDeg);
    }
    if (!filter.initialized()) continue;
    const SE2ParticleFilter::Estimate e = filter.CurrentEstimate();
    const double mm = 1e3 * std::hypot(e.mean.x() - truth.x(), e.mean.y() - truth.y());
    const double deg = YawErrorModuloSymmetry(e.mean.yaw(), truth.yaw(), n) / kDeg;
    filtered.Add(mm, deg);
    std::printf("%5d | %7.3f %7.3f %6.2f  | %s | %s | %6.3f mm %5.2f | %6.0f  %s\n", t,
                1e3 * truth.x(), 1e3 * truth.y(), truth.yaw() / kDeg, frame_text, sd_text, mm, deg,
                filter.EffectiveSampleSize(), update.c_str());
  }
  std::printf("%s\n", filter.summary().BriefReport(filter.num_particles()).c_str());
  std::printf("time: %.1f ms per posterior, %.1f ms per filter update\n",
              posterior_ms / flags.frames, per_frame.count > 0 ? filter_ms / per_frame.count : 0.0);
  if (per_frame.count == 0) throw std::runtime_error("every per-frame posterior failed");
  std::printf("RMSE over %d frames: per-frame %.3f mm, %.2f deg; filtered %.3f mm, %.2f deg\n",
              per_frame.count, per_frame.RmseMm(), per_frame.RmseDeg(), filtered.RmseMm(),
              filtered.RmseDeg());
  std::printf("per-frame -> filtered: %.3f -> %.3f mm, %.2f -> %.2f deg\n", per_frame.RmseMm(),
              filtered.RmseMm(), per_frame.RmseDeg(), filtered.RmseDeg());
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  try {
    return Run(ParseFlags(argc, argv));
  } catch (const std::exception& e) {
    std::fprintf(stderr, "track_slipping_tool: error: %s\n", e.what());
    Usage(stderr);
    return 1;
  }
}
