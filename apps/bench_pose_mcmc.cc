// Copyright 2026 The tactfunc Authors.
//
// tactfunc bench pose-mcmc: which Metropolis kernel mixes better over the generator path's
// pose posterior (estimation/synthesis/pose_sampler.h)?
//
//   tactfunc bench pose-mcmc --model M.tfm --generator G.tpg [--pose-model P.tpm]
//       [--contacts 20] [--kernels mala,rwm] [--evaluations 1600] [--chains 4]
//       [--seed 0] [--json]
//
// N fresh simulated Soft Bubble contacts (seeds DeriveSeed(seed, k); the tools with an
// observable yaw in turn, the tool given), the generator posterior of each (the pose MLP's
// start if given, a yaw grid otherwise), and from its heaviest Laplace component every
// kernel runs `chains` chains with the same budget of trunk evaluations per frame:
// evaluations / chains iterations per chain, the first 40% burn-in (step size adapted),
// the rest kept (proposals outside the depth bounds cost no evaluation, so a kernel may
// use fewer). Per kernel: the median over frames of ESS per second of sampling and per
// 1000 trunk evaluations for x, y, yaw and depth, the median and largest per-frame
// max split R-hat, the frames with every R-hat < 1.1, the mean acceptance and the median
// ms of sampling per frame. One thread, the kernels one after another on each frame.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <iostream>
#include <memory>

#include "CLI/CLI.hpp"
#include "apps/bench.h"
#include "apps/bench/fit_common.h"
#include "apps/command.h"
#include "apps/model_inputs.h"
#include "apps/progress_bar.h"
#include "estimation/data/image_io.h"
#include "estimation/data/trunk_targets.h"
#include "estimation/synthesis/generator_posterior.h"
#include "estimation/synthesis/pose_sampler.h"
#include "models/core/seed.h"
#include "models/pose/pose_generator.h"
#include "models/simulator/contact_simulator.h"
#include "models/trunk/functa_model.h"

namespace tactfunc::apps {
namespace {

using bench::Median;

struct PoseMcmcFlags {
  std::string model;
  std::string generator;
  std::string pose_model;
  int contacts = 20;
  std::string kernels = "mala,rwm";
  int evaluations = 1600;
  int chains = 4;
  std::uint64_t seed = 0;
  double jump_probability = PoseSamplerOptions().jump_probability;
  bool json = false;
};

struct KernelTally {
  MetropolisKernel kernel;
  std::vector<double> ess_per_s[4], ess_per_k[4];
  std::vector<double> max_rhat, acceptance, ms, evaluations;
  int mixed = 0;
  long jumps_proposed = 0, jumps_accepted = 0;
  std::vector<std::string> unmixed;  // one line per frame with a split R-hat >= 1.1
};

void RunPoseMcmcBench(const PoseMcmcFlags& flags) {
  std::vector<KernelTally> tallies;
  for (const std::string& name : SplitList(flags.kernels)) {
    KernelTally t;
    if (!ParseMetropolisKernel(name, &t.kernel)) {
      throw UsageError("--kernels: unknown kernel '" + name + "' (expected mala or rwm)");
    }
    tallies.push_back(t);
  }
  if (tallies.empty()) throw UsageError("--kernels: expected a list of mala, rwm");
  if (flags.evaluations / flags.chains < 20) {
    throw UsageError("--evaluations: expected >= 20 per chain (" + std::to_string(20 * flags.chains) +
                     " with " + std::to_string(flags.chains) + " chains)");
  }
  const FunctaModel model = FunctaModel::Load(flags.model);
  const SensorTrunk& trunk = model.Trunk(SensorKind::kSoftBubble);
  const PoseGenerator generator =
      LoadPoseGeneratorFor(flags.generator, model, SensorKind::kSoftBubble, flags.model);
  std::unique_ptr<PoseMlp> mlp;
  if (!flags.pose_model.empty()) {
    mlp = std::make_unique<PoseMlp>(
        LoadPoseModelFor(flags.pose_model, model, SensorKind::kSoftBubble, flags.model));
  }
  const GeneratorPosterior posterior(trunk, generator, GeneratorPosterior::Options(), nullptr,
                                     mlp.get());
  const ContactSimulator simulator;
  auto as_stored = [](const Image& depth) {
    return DecodeImage(EncodePng(depth, PixelEncoding::kDepthU16Micrometres),
                       PixelEncoding::kDepthU16Micrometres, "fresh contact");
  };
  const Image reference = as_stored(simulator.Reference(SensorKind::kSoftBubble));
  std::vector<int> tools;
  for (int t = 0; t < generator.num_tools(); ++t) {
    if (generator.SymmetryOrder(t) != 0) tools.push_back(t);
  }
  if (tools.empty()) throw UsageError("--generator: no tool with an observable yaw");
  const int per_chain = flags.evaluations / flags.chains;
  PoseSamplerOptions options;
  options.chain.num_chains = flags.chains;
  options.chain.burn_in = per_chain * 2 / 5;
  options.chain.num_samples_per_chain = per_chain - options.chain.burn_in;
  options.depth_min_m = posterior.options().fit.depth_min_m;
  options.depth_max_m = posterior.options().fit.depth_max_m;
  options.jump_probability = flags.jump_probability;
  int failures = 0;
  int multimodal = 0;  // frames whose tool has two or more modes
  ProgressBar bar("pose-mcmc", flags.contacts, "frames");
  for (int k = 0; k < flags.contacts; ++k) {
    const int tool = tools[k % tools.size()];
    const std::string& name = generator.options().tools[tool];
    const std::uint64_t seed = DeriveSeed(flags.seed, k);
    const Contact contact = simulator.SamplePairedContact(name, seed).bubble;
    const TrunkTargets targets =
        MakeTrunkTargets(as_stored(simulator.Render(SensorKind::kSoftBubble, contact, seed).frame),
                         reference, SensorKind::kSoftBubble, trunk.format);
    PoseMixture mixture;
    const GeneratorPosterior::Summary s = posterior.Estimate(targets, name, &mixture);
    if (!s.usable) {
      ++failures;
      std::cerr << "bench pose-mcmc: the posterior failed on contact " << k << ": " << s.message
                << "\n";
      bar.Tick();
      continue;
    }
    const LatentProblem problem(trunk, targets, posterior.options().problem);
    std::vector<LaplaceComponent> modes;  // the tool's modes, heaviest first
    for (const LaplaceComponent& c : mixture.components()) {
      if (c.tool == name) modes.push_back(c);
    }
    if (modes.empty()) modes.push_back(mixture.components().front());
    multimodal += modes.size() > 1;
    for (KernelTally& t : tallies) {
      options.chain.kernel = t.kernel;
      options.chain.seed = seed;
      const PoseSamples p = SamplePosePosterior(problem, generator, tool, s.sigma, modes, options);
      const MetropolisResult& r = p.chains;
      for (int c = 0; c < 4; ++c) {
        t.ess_per_s[c].push_back(r.effective_sample_size[c] / (1e-3 * r.time_ms));
        t.ess_per_k[c].push_back(1e3 * r.effective_sample_size[c] / std::max(1L, p.trunk_evaluations));
      }
      t.max_rhat.push_back(r.MaxSplitRhat());
      t.mixed += r.MaxSplitRhat() < 1.1;
      if (!(r.MaxSplitRhat() < 1.1)) {
        char line[256];
        std::snprintf(line, sizeof line,
                      "contact %d (%s, %zu mode%s): split R-hat x %.3f y %.3f yaw %.3f depth %.3f",
                      k, name.c_str(), modes.size(), modes.size() == 1 ? "" : "s", r.split_rhat[0],
                      r.split_rhat[1], r.split_rhat[2], r.split_rhat[3]);
        t.unmixed.push_back(line);
      }
      t.acceptance.push_back(r.MeanAcceptance());
      t.ms.push_back(r.time_ms);
      t.evaluations.push_back(static_cast<double>(p.trunk_evaluations));
      for (std::size_t c = 0; c < r.jumps_proposed.size(); ++c) {
        t.jumps_proposed += r.jumps_proposed[c];
        t.jumps_accepted += r.jumps_accepted[c];
      }
    }
    bar.Tick();
  }
  bar.Finish();
  const int frames = flags.contacts - failures;
  std::printf("%d fresh contacts (%d failed), %d chains x %d iterations (%d burn-in), budget %d "
              "trunk evaluations per frame; %d frames with several modes of the tool (mode "
              "jumps %s)\n",
              flags.contacts, failures, flags.chains, per_chain, options.chain.burn_in,
              flags.chains * per_chain, multimodal,
              options.jump_probability > 0 ? "on" : "off");
  std::printf("%-6s | %-31s | %-31s | %-13s | %7s | %6s | %8s | %6s\n", "kernel",
              "ESS/s x, y, yaw, depth", "ESS/1000 evals x, y, yaw, depth", "R-hat med max",
              "<1.1", "accept", "ms/frame", "evals");
  static const char* kNames[4] = {"x", "y", "yaw", "depth"};
  nlohmann::json list = nlohmann::json::array();
  for (const KernelTally& t : tallies) {
    double s[4], e[4];
    for (int c = 0; c < 4; ++c) {
      s[c] = Median(t.ess_per_s[c]);
      e[c] = Median(t.ess_per_k[c]);
    }
    const double rhat_max =
        t.max_rhat.empty() ? std::nan("") : *std::max_element(t.max_rhat.begin(), t.max_rhat.end());
    double acceptance = 0;
    for (double a : t.acceptance) acceptance += a;
    acceptance /= std::max<std::size_t>(1, t.acceptance.size());
    std::printf("%-6s | %7.0f %7.0f %7.0f %7.0f | %7.1f %7.1f %7.1f %7.1f | %6.3f %6.3f | %3d/%-3d "
                "| %6.3f | %8.0f | %6.0f\n",
                ToString(t.kernel), s[0], s[1], s[2], s[3], e[0], e[1], e[2], e[3],
                Median(t.max_rhat), rhat_max, t.mixed, frames, acceptance, Median(t.ms),
                Median(t.evaluations));
    nlohmann::json per_coordinate = nlohmann::json::object();
    for (int c = 0; c < 4; ++c) {
      per_coordinate[kNames[c]] = {{"ess_per_s_median", NumberOrNull(s[c])},
                                   {"ess_per_1000_evaluations_median", NumberOrNull(e[c])}};
    }
    list.push_back({{"kernel", ToString(t.kernel)},
                    {"coordinates", per_coordinate},
                    {"max_split_rhat_median", NumberOrNull(Median(t.max_rhat))},
                    {"max_split_rhat_max", NumberOrNull(rhat_max)},
                    {"frames_rhat_below_1_1", t.mixed},
                    {"acceptance_mean", acceptance},
                    {"ms_per_frame_median", NumberOrNull(Median(t.ms))},
                    {"evaluations_median", NumberOrNull(Median(t.evaluations))},
                    {"jumps_proposed", t.jumps_proposed},
                    {"jumps_accepted", t.jumps_accepted}});
    for (const std::string& line : t.unmixed) {
      std::printf("%-6s   not mixed: %s\n", ToString(t.kernel), line.c_str());
    }
    if (t.jumps_proposed > 0) {
      std::printf("%-6s   mode jumps: %ld proposed, %ld accepted (kept iterations)\n",
                  ToString(t.kernel), t.jumps_proposed, t.jumps_accepted);
    }
  }
  if (flags.json) {
    EmitJson({{"bench", "pose-mcmc"},
              {"contacts", flags.contacts},
              {"failures", failures},
              {"chains", flags.chains},
              {"evaluations_budget", flags.chains * per_chain},
              {"kernels", list},
              {"machine", MachineDescription()}});
  }
}

}  // namespace

void RegisterPoseMcmcBenchmark(CLI::App* bench, CommandBody* selected) {
  auto flags = std::make_shared<PoseMcmcFlags>();
  CLI::App* sub = bench->add_subcommand(
      "pose-mcmc",
      "MCMC over the generator path's pose on fresh simulated contacts: per kernel, ESS per "
      "second and per 1000 trunk evaluations (x, y, yaw, depth), split R-hat, acceptance and "
      "ms per frame at the same evaluation budget.");
  sub->add_option("--model", flags->model, "Model file (.tfm)")->required();
  sub->add_option("--generator", flags->generator, "Pose generator (.tpg)")->required();
  sub->add_option("--pose-model", flags->pose_model,
                  "Pose model (.tpm): its prediction is one start of the posterior's search");
  sub->add_option("--contacts", flags->contacts, "Fresh contacts (default 20)")
      ->check(CLI::Range(1, 100000));
  sub->add_option("--kernels", flags->kernels, "Comma-separated mala, rwm (default mala,rwm)");
  sub->add_option("--evaluations", flags->evaluations,
                  "Trunk evaluations per frame and kernel (default 1600)")
      ->check(CLI::Range(1, 10000000));
  sub->add_option("--chains", flags->chains, "Chains per frame (default 4)")
      ->check(CLI::Range(2, 1000));
  sub->add_option("--seed", flags->seed, "Seed of the contacts and the chains (default 0)");
  sub->add_option("--jump-probability", flags->jump_probability,
                  "Probability of a mode-jump proposal per iteration when the tool has several "
                  "modes (default 0.1; 0 = local moves only)")
      ->check(CLI::Range(0.0, 0.99));
  sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
  sub->callback([flags, selected]() { *selected = [flags]() { RunPoseMcmcBench(*flags); }; });
}

}  // namespace tactfunc::apps
