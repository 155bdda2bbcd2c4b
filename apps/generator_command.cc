// Copyright 2026 The tactfunc Authors.
//
// The generator path of the pose posteriors (docs/POSES.md, "The generator path"):
//
//   tactfunc train-generator --model M.tfm --functaset F.tfs --data D --out G.tpg
//       [--mode latents|pixels] [--epochs 300] [--pixel-epochs 4] [--pixel-frames 200]
//       [--calibration-frames 120] [--temperature-frames 600] [--final-pixels 0]
//       [--recalibrate G0.tpg] [--seed 0] [--resume] [--json]
//     trains h(tool, T, depth) -> z on the functaset's labelled train-split entries: by
//     regressing their latents (--mode latents), then (--mode pixels) on --pixel-frames
//     frames per tool through the frozen trunk for --pixel-epochs more epochs; reports the
//     mean rendering PSNR on the test split, calibrates the posterior's sigma inflation
//     on --calibration-frames test-split frames and its mode weights' temperature on
//     --temperature-frames (CalibrateWeightTemperature), both with the posterior's final
//     stage on --final-pixels pixels (recorded in G: the posterior's default), and writes G
//     atomically; --recalibrate G0 skips the training and calibrates G0. Each stage shows
//     its epochs and checkpoints to G.regression.ckpt / G.pixels.ckpt (every 10 epochs and
//     on Ctrl-C, which exits 130); --resume continues from them to the same G.
//
//   tactfunc eval-generator --model M.tfm --generator G.tpg [--functaset F.tfs]
//       [--pose-model P.tpm] [--contacts-per-tool 20] [--tools LIST] [--seed 1592590336]
//       [--unknown-tool]
//       [--diagnose [--diagnose-picture FILE]] [--information [--picture FILE]]
//       [search knobs: --max-pixels, --contact-share,
//       --refined-starts, --iterations, --knn-k, --yaw-grid, --position-grid,
//       --position-rings, --coarse-pixels, --coarse-starts, --coarse-iterations,
//       --final-pixels]
//       [--contacts-csv FILE] [--json]
//       [--data D [--split test|train|all] [--allow-other-frames] [dataset flags]]
//     fresh Soft Bubble contacts (ContactSimulator, seeded; contact k uses DeriveSeed(seed,
//     k)) of every tool the generator knows (--tools: of those, the same contacts), or
//     with --data the labelled bubble frames of a dataset's split (each label the truth;
//     --contacts-per-tool then caps each tool's frames, default all; --information, which
//     needs the simulator's contacts, is refused), through
//     GeneratorPosterior (one thread): the
//     posterior mode's position RMSE (mm) and yaw RMSE (deg, modulo symmetry, hemisphere
//     left out), the coverage of the 50% and 90% highest-density regions, the time per
//     frame (fit + Laplace; wall clock and the thread's CPU time), and with --unknown-tool
//     the tool identification rate; and how often the heaviest mode holds the truth
//     (within 10 deg and 1 mm) against its weight, over the contacts with two or more
//     modes (MixtureWeightReliability). --diagnose: for every contact whose mode is > 5
//     deg or > 1 mm off, the objective at the mode, the truth and the truth refined (a lower
//     refined truth = a search failure, else a model failure), and over the whole frame
//     at the mode, the truth and the trunk's own best latent (Ceres to convergence: how
//     well any generator could render the frame through this trunk); --diagnose-picture:
//     the first 6 wrong modes drawn (WrongModePicture). --information: every
//     contact's Cramer-Rao bound from the simulator's own frames and noise
//     (SoftBubblePoseInformation) on the trunk's working frames and on the sensor's own,
//     printed beside the mode's errors by contact depth: the floor under any unbiased
//     estimator's error on those frames; and for every wrong mode (as --diagnose counts them)
//     whether the frame itself prefers the truth's basin (JudgeWrongMode), and whether the
//     trunk keeps that preference (TrunkLogLikelihoodRatio). --contacts-csv: one row
//     per usable contact (truth, mode, posterior mean, errors, the mode's Laplace standard
//     deviations, the mode's weight among the true tool's modes, with --information the
//     bound's, the frame's and the trunk's verdict, with --diagnose a wrong mode's
//     whole-frame objectives), written atomically; --picture FILE
//     (with --information): each contact's error against its bound.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <iostream>
#include <limits>
#include <map>
#include <memory>
#include <numeric>
#include <optional>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>
#include <sstream>

#include "CLI/CLI.hpp"
#include "apps/command.h"
#include "apps/dataset_flags.h"
#include "apps/interrupt.h"
#include "apps/model_inputs.h"
#include "apps/output_paths.h"
#include "apps/pictures.h"
#include "apps/progress_bar.h"
#include "estimation/data/dataset.h"
#include "estimation/data/image_io.h"
#include "estimation/data/trunk_targets.h"
#include "estimation/evaluation/reconstruction.h"
#include "estimation/fitting/latent_fitter.h"
#include "estimation/functaset/functaset.h"
#include "estimation/pose/pose_distribution.h"
#include "estimation/synthesis/generator_posterior.h"
#include "estimation/synthesis/generator_training.h"
#include "models/core/atomic_file.h"
#include "models/core/seed.h"
#include "models/pose/pose_generator.h"
#include "models/pose/pose_mlp.h"
#include "models/simulator/contact_simulator.h"
#include "models/simulator/pose_information.h"
#include "models/simulator/tool.h"
#include "models/trunk/functa_model.h"

namespace tactfunc::apps {
namespace {

struct TrainGeneratorFlags {
  std::string model, functaset, data, out;
  DatasetFlags dataset;  // data without metadata (a video, a user's folder)
  std::string mode = "pixels";
  std::string hidden = "256,256";
  int harmonics = 4;
  int epochs = 300;
  int pixel_epochs = 4;
  int pixel_frames = 200;
  int pixels = 256;
  int calibration_frames = 120;
  int temperature_frames = 600;
  int final_pixels = 0;     // the posterior's final stage during calibration (recorded)
  std::string recalibrate;  // a trained generator: calibrate it only
  double tune_trunk = 0;    // the trunk's step as a fraction of the pixel stage's (0: frozen)
  std::string out_model;    // with --tune-trunk: the generator's own trunk, written here
  double lr = 1e-3;
  std::uint64_t seed = 0;
  bool json = false;
  bool resume = false;
};

// The checkpoints of train-generator's two stages, beside the output.
std::string StageCheckpoint(const std::string& out, const char* stage) {
  return CheckpointBeside(out, stage);
}

// One training stage's epochs: a progress bar with the loss (progress lines where no bar
// is drawn), and Ctrl-C stops the stage after its current epoch (a checkpoint is written).
// A resumed stage's first call moves the bar to the epochs already done.
GeneratorProgressCallback StageProgress(ProgressBar* bar) {
  return [bar](int epoch, double loss) {
    char status[40];
    std::snprintf(status, sizeof(status), "loss %.4g", loss);
    bar->SetStatus(status);
    bar->Tick(epoch + 1 - bar->done());
    return !InterruptScope::Requested();
  };
}

// After a stage: if Ctrl-C stopped it, say where its checkpoint is and exit 130.
void ExitIfInterrupted(const GeneratorTrainingSummary& stage, int epochs,
                       const std::string& checkpoint) {
  if (!InterruptScope::Requested()) return;
  std::cerr << "train-generator: interrupted after " << stage.epochs_completed << " of " << epochs
            << " epochs; checkpoint " << checkpoint
            << ".\ntrain-generator: to continue, run the same command with --resume\n";
  ExitInterrupted();
}

struct Labelled {
  std::vector<GeneratorSample> samples;
  std::vector<std::size_t> frames;  // dataset frame indices
  Eigen::MatrixXd latents;
};

Labelled Collect(const PoseGenerator& g, const Functaset& f, const Dataset& dataset, Split split,
                 int per_tool_limit) {
  Labelled out;
  std::map<std::string, int> counts;
  std::vector<Eigen::VectorXd> z;
  for (const FunctasetEntry& e : f.entries(SensorKind::kSoftBubble)) {
    if (e.split != split || !e.label.has_value()) continue;
    const int tool = g.ToolIndex(e.label->tool);
    if (tool < 0) continue;
    if (per_tool_limit > 0 && counts[e.label->tool]++ >= per_tool_limit) continue;
    const std::optional<std::size_t> index = dataset.FindFrame(e.id, SensorKind::kSoftBubble);
    if (!index) throw DatasetError("frame '" + e.id + "' of the functaset is not in the dataset");
    out.samples.push_back({tool, e.label->sensor_T_object, e.label->depth_m});
    out.frames.push_back(*index);
    z.push_back(e.latent.cast<double>());
  }
  out.latents.resize(z.size(), f.latent_dim(SensorKind::kSoftBubble));
  for (std::size_t i = 0; i < z.size(); ++i) out.latents.row(i) = z[i].transpose();
  return out;
}

void RunTrainGenerator(const TrainGeneratorFlags& flags) {
  if (flags.mode != "latents" && flags.mode != "pixels") {
    throw UsageError("--mode: expected latents or pixels, got '" + flags.mode + "'");
  }
  const bool tune = flags.tune_trunk > 0;
  if (tune && (flags.mode != "pixels" || !flags.recalibrate.empty())) {
    throw UsageError("--tune-trunk trains the trunk in the pixel stage: it needs --mode pixels "
                     "and no --recalibrate");
  }
  if (tune != !flags.out_model.empty()) {
    throw UsageError("--tune-trunk and --out-model go together (the tuned trunk is written to "
                     "--out-model)");
  }
  const FunctaModel model = FunctaModel::Load(flags.model);
  const SensorTrunk& trunk = model.Trunk(SensorKind::kSoftBubble);
  const Functaset functaset = Functaset::Load(flags.functaset);
  functaset.CheckModel(model, flags.model, flags.functaset);
  const Dataset dataset = OpenDataset(flags.data, flags.dataset);
  // The trunk the generator renders through: --model's, or its copy tuned along with the
  // generator (--tune-trunk), which calibration and the record then name.
  std::optional<FunctaModel> tuned_model;
  const SensorTrunk* render_trunk = &trunk;
  std::string render_model = flags.model;
  std::uint32_t render_checksum = model.checksum();
  PoseGenerator::Options options;
  for (const Tool& t : ToolSet()) {
    options.tools.push_back(t.name());
    options.symmetry_orders.push_back(t.symmetry_order());
  }
  options.latent_dim = trunk.siren.latent_dim();
  options.hidden_sizes = ParsePositiveIntList(flags.hidden, "--hidden", "widths");
  options.yaw_harmonics = flags.harmonics;
  const bool train_it = flags.recalibrate.empty();
  PoseGenerator generator = train_it ? PoseGenerator(options, DeriveSeed(flags.seed, 0))
                                     : PoseGenerator::Load(flags.recalibrate);
  if (!train_it) {
    if (generator.options().latent_dim != options.latent_dim) {
      throw UsageError("--recalibrate '" + flags.recalibrate + "': the generator's latent_dim is " +
                       std::to_string(generator.options().latent_dim) + ", the trunk of --model '" +
                       flags.model + "' has " + std::to_string(options.latent_dim));
    }
  }

  const InterruptScope interrupt_scope;
  GeneratorTrainingOptions to;
  to.epochs = flags.epochs;
  to.learning_rate = flags.lr;
  to.seed = DeriveSeed(flags.seed, 1);
  to.checkpoint_path = StageCheckpoint(flags.out, "regression");
  to.resume = flags.resume;
  GeneratorTrainingSummary reg;
  std::size_t train_contacts = 0;
  if (train_it) {
    const Labelled train = Collect(generator, functaset, dataset, Split::kTrain, 0);
    if (train.samples.empty()) {
      throw DatasetError("--functaset '" + flags.functaset +
                         "' has no labelled bubble train entries");
    }
    ProgressBar bar("train-generator regression", to.epochs, "epochs",
                    ProgressBar::Lines::kWhenNotDrawn);
    reg = TrainGeneratorOnLatents(&generator, train.samples, train.latents, to,
                                  StageProgress(&bar));
    bar.Tick(reg.epochs_completed - bar.done());  // a stage its checkpoint had finished
    bar.Finish();
    ExitIfInterrupted(reg, to.epochs, to.checkpoint_path);
    train_contacts = train.samples.size();
    std::cout << "train-generator: latent regression on " << train.samples.size()
              << " contacts: " << reg.BriefReport()
              << (reg.epochs_resumed > 0
                      ? " (resumed after " + std::to_string(reg.epochs_resumed) + " epochs)"
                      : std::string())
              << "\n";
  }
  // Test-split frames for PSNR and calibration.
  const Labelled test = Collect(generator, functaset, dataset, Split::kTest, 0);
  std::vector<TrunkTargets> test_frames;
  const std::size_t psnr_count = std::min<std::size_t>(test.frames.size(), 240);
  std::vector<GeneratorSample> psnr_samples;
  for (std::size_t i = 0; i < psnr_count; ++i) {
    const std::size_t k = i * test.frames.size() / psnr_count;
    test_frames.push_back(LoadTrunkTargets(dataset, test.frames[k], trunk.format));
    psnr_samples.push_back(test.samples[k]);
  }
  const double psnr_latents = MeanGeneratorPsnr(generator, trunk, psnr_samples, test_frames);
  std::cout << "train-generator: test rendering PSNR "
            << (train_it ? "after regression " : "of " + flags.recalibrate + " ") << psnr_latents
            << " dB\n";
  double psnr_pixels = std::nan("");
  GeneratorTrainingSummary pix;
  if (train_it && flags.mode == "pixels") {
    const Labelled sub = Collect(generator, functaset, dataset, Split::kTrain, flags.pixel_frames);
    std::vector<TrunkTargets> frames;
    for (std::size_t index : sub.frames) frames.push_back(LoadTrunkTargets(dataset, index, trunk.format));
    GeneratorTrainingOptions po = to;
    po.epochs = flags.pixel_epochs;
    po.learning_rate = flags.lr * 0.3;
    po.batch_size = 32;
    po.pixels_per_frame = flags.pixels;
    po.standardize_outputs = false;
    po.seed = DeriveSeed(flags.seed, 2);
    po.checkpoint_path = StageCheckpoint(flags.out, "pixels");
    po.resume = flags.resume;
    po.trunk_step_fraction = flags.tune_trunk;
    if (tune) tuned_model.emplace(model);
    LatentModulatedSiren* tuned =
        tune ? &tuned_model->MutableTrunk(SensorKind::kSoftBubble).siren : nullptr;
    {
      ProgressBar bar("train-generator pixels", po.epochs, "epochs",
                      ProgressBar::Lines::kWhenNotDrawn);
      pix = TrainGeneratorOnPixels(&generator, trunk, sub.samples, frames, po,
                                   StageProgress(&bar), tuned);
      bar.Tick(pix.epochs_completed - bar.done());
      bar.Finish();
    }
    ExitIfInterrupted(pix, po.epochs, po.checkpoint_path);
    if (tune) {
      nlohmann::json record = model.info_json().empty() ? nlohmann::json::object()
                                                        : nlohmann::json::parse(model.info_json());
      record["tuned_with_generator"] = {{"generator", flags.out},
                                        {"from_model", flags.model},
                                        {"from_model_checksum", model.checksum()},
                                        {"trunk_step_fraction", flags.tune_trunk},
                                        {"pixel_epochs", pix.epochs_completed}};
      tuned_model->set_info_json(record.dump());
      tuned_model->Save(flags.out_model);
      // Calibrate through the trunk as the file holds it (float32 parameters, the checksum
      // the generator records), which is what `pose` and `eval-generator` will load.
      *tuned_model = FunctaModel::Load(flags.out_model);
      render_checksum = tuned_model->checksum();
      render_model = flags.out_model;
      render_trunk = &tuned_model->Trunk(SensorKind::kSoftBubble);
      std::cout << "train-generator: wrote the generator's own trunk to " << flags.out_model
                << "\n";
    }
    psnr_pixels = MeanGeneratorPsnr(generator, *render_trunk, psnr_samples, test_frames);
    std::cout << "train-generator: through the trunk on " << sub.samples.size()
              << " frames: " << pix.BriefReport() << "; test rendering PSNR " << psnr_pixels
              << " dB\n";
  }
  // Calibrate the sigma inflation on test-split frames (tool known).
  // The k-NN starts read --functaset's latents: the frame's query under --model's trunk
  // (the generator may render through a tuned one).
  std::unique_ptr<KnnPoseStarts> knn =
      std::make_unique<KnnPoseStarts>(functaset, SensorKind::kSoftBubble, &trunk);
  GeneratorPosterior::Options po;
  po.sigma_inflation = 1;
  po.final_pixels = flags.final_pixels;
  const GeneratorPosterior posterior(*render_trunk, generator, po, knn.get());
  // `count` test-split frames spread evenly over the split, with their labels.
  auto calibration_set = [&](int count, std::vector<TrunkTargets>* frames,
                             std::vector<PoseLabel>* labels) {
    const std::size_t n = std::min<std::size_t>(test.frames.size(), count);
    for (std::size_t i = 0; i < n; ++i) {
      const std::size_t k = (2 * i + 1) * test.frames.size() / (2 * n);
      frames->push_back(LoadTrunkTargets(dataset, test.frames[k], trunk.format));
      PoseLabel l;
      l.tool = generator.options().tools[test.samples[k].tool];
      l.sensor_T_object = test.samples[k].sensor_T_object;
      l.depth_m = test.samples[k].depth_m;
      labels->push_back(l);
    }
    return n;
  };
  std::vector<TrunkTargets> cal_frames;
  std::vector<PoseLabel> cal_labels;
  const std::size_t cal_count = calibration_set(flags.calibration_frames, &cal_frames, &cal_labels);
  const double kappa = CalibrateSigmaInflation(posterior, cal_frames, cal_labels);
  generator.set_sigma_inflation(kappa);
  std::cout << "train-generator: sigma inflation " << kappa << " (from " << cal_count
            << " test-split frames)\n";
  // The mode weights' temperature, at that kappa, on more frames: only those whose
  // posterior has two or more modes inform it.
  double tau = 1;
  if (kappa > 0) {
    GeneratorPosterior::Options to_options;
    to_options.sigma_inflation = kappa;
    to_options.weight_temperature = 1;
    to_options.final_pixels = flags.final_pixels;
    const GeneratorPosterior at_kappa(*render_trunk, generator, to_options, knn.get());
    std::vector<TrunkTargets> t_frames;
    std::vector<PoseLabel> t_labels;
    const std::size_t t_count = calibration_set(flags.temperature_frames, &t_frames, &t_labels);
    int informative = 0, wrong = 0;
    tau = CalibrateWeightTemperature(at_kappa, t_frames, t_labels, 0.05, &informative, &wrong);
    generator.set_weight_temperature(tau);
    std::cout << "train-generator: mode weight temperature " << tau << " (from " << t_count
              << " test-split frames, " << informative << " with two or more modes, " << wrong
              << " of them with the truth outside the heaviest)\n";
  } else {
    std::cout << "train-generator: mode weight temperature not calibrated (no sigma inflation: "
                 "no usable test-split frame); the posterior uses 1\n";
  }
  generator.set_final_pixels(flags.final_pixels);
  if (flags.final_pixels > 0) {
    std::cout << "train-generator: calibrated with the posterior's final stage on "
              << flags.final_pixels << " pixels (its default from now on)\n";
  }
  nlohmann::json info;
  if (train_it) {
    info = {{"model", render_model},
            {"model_checksum", render_checksum},
            {"functaset", flags.functaset},
            {"mode", flags.mode},
            {"train_contacts", train_contacts},
            {"regression_epochs", reg.epochs_completed},
            {"pixel_epochs", pix.epochs_completed},
            {"test_psnr_latents", NumberOrNull(psnr_latents)},
            {"test_psnr_pixels", NumberOrNull(psnr_pixels)},
            {"seed", flags.seed}};
  } else {  // the training's record stays; the calibration's source is added
    info = nlohmann::json::parse(generator.info_json());
    info["recalibrated_from"] = flags.recalibrate;
    info["calibration_functaset"] = flags.functaset;
    info["test_psnr"] = NumberOrNull(psnr_latents);
  }
  generator.set_info_json(info.dump());
  generator.Save(flags.out);
  std::cout << "train-generator: wrote " << flags.out << "\n";
  for (const char* stage : {"regression", "pixels"}) {
    std::error_code ignored;  // the generator is written; a checkpoint left behind is harmless
    std::filesystem::remove(StageCheckpoint(flags.out, stage), ignored);
  }
  if (flags.json) {
    info["sigma_inflation"] = kappa;
    info["weight_temperature"] = tau;
    info["out"] = flags.out;
    EmitJson(info);
  }
}

struct EvalGeneratorFlags {
  std::string model, generator, functaset, pose_model;
  // --data: a labelled dataset's bubble frames instead of fresh simulated contacts.
  std::string data;
  DatasetFlags dataset;
  std::string split = "test";  // with --data: train, test or all
  bool allow_other_frames = false;
  int contacts_per_tool = 20;
  bool contacts_per_tool_given = false;
  std::string tools;  // comma-separated subset of the generator's tools; empty = all
  std::uint64_t seed = 0x5eed0000u;
  bool unknown_tool = false;
  double sigma_inflation = 0;
  double weight_temperature = 0;
  // The search knobs' defaults are GeneratorPosterior's and PoseFitOptions'.
  int max_pixels = GeneratorPosterior::Options().problem.max_pixels;
  double contact_share = GeneratorPosterior::Options().problem.contact_share;
  int refined_starts = PoseFitOptions().max_refined_starts;
  int iterations = PoseFitOptions().max_iterations;
  int knn_k = GeneratorPosterior::Options().knn_k;
  int yaw_grid = GeneratorPosterior::Options().yaw_grid;
  int coarse_pixels = GeneratorPosterior::Options().coarse_pixels;
  double tool_prune_ratio = GeneratorPosterior::Options().tool_prune_ratio;
  bool tool_screen = GeneratorPosterior::Options().tool_screen;
  int final_pixels = GeneratorPosterior::Options().final_pixels;
  double position_grid_mm = 1e3 * GeneratorPosterior::Options().position_grid_m;
  int position_rings = GeneratorPosterior::Options().position_grid_rings;
  int coarse_starts = PoseFitOptions().coarse_refined_starts;
  int coarse_iterations = PoseFitOptions().coarse_iterations;
  bool diagnose = false;
  std::string diagnose_picture;  // with --diagnose: the wrong modes' renderings
  bool information = false;
  std::string picture;  // with --information: each contact's error against its bound
  bool json = false;
  std::string contacts_csv;  // one row per contact, written atomically at the end
};

Image AsStored(const Image& depth) {
  return DecodeImage(EncodePng(depth, PixelEncoding::kDepthU16Micrometres),
                     PixelEncoding::kDepthU16Micrometres, "fresh contact");
}

// What a frame says about a wrong mode: the simulator's own models fitted to it from the
// truth and from the mode (FitSoftBubbleContact). kInTruthBasin: the fit from the mode
// came back to the truth's basin (within 0.3 mm and 2 degrees of the truth's fit);
// otherwise the truth's basin explains the frame better by more than kClearNats, about as
// well, or worse by more than kClearNats.
enum FrameVerdict { kInTruthBasin, kPrefersTruth, kAmbiguous, kPrefersMode, kVerdicts };
constexpr double kClearNats = 3;

struct WrongModeJudgement {
  FrameVerdict verdict = kAmbiguous;
  double log_likelihood_ratio = 0;  // the truth's fit over the mode's, nats
  Contact truth_fit, mode_fit;      // the simulator's fits from the truth and the mode
};

WrongModeJudgement JudgeWrongMode(const ContactSimulator& simulator, const Image& frame,
                                  const Contact& truth, const SE2d& mode, double mode_depth_m,
                                  int symmetry_order) {
  Contact from_mode = truth;
  from_mode.sensor_T_object = mode;
  from_mode.depth_m = mode_depth_m;
  const ContactFit at_truth = FitSoftBubbleContact(simulator, frame, truth);
  const ContactFit at_mode = FitSoftBubbleContact(simulator, frame, from_mode);
  WrongModeJudgement j;
  j.log_likelihood_ratio = at_truth.log_likelihood - at_mode.log_likelihood;
  j.truth_fit = at_truth.contact;
  j.mode_fit = at_mode.contact;
  const SE2d& a = at_truth.contact.sensor_T_object;
  const SE2d& b = at_mode.contact.sensor_T_object;
  const bool same_basin =
      std::hypot(a.x() - b.x(), a.y() - b.y()) < 0.3e-3 &&
      (symmetry_order == 0 || kDeg * YawErrorModuloSymmetry(a.yaw(), b.yaw(), symmetry_order) < 2);
  j.verdict = same_basin                             ? kInTruthBasin
              : j.log_likelihood_ratio > kClearNats  ? kPrefersTruth
              : j.log_likelihood_ratio < -kClearNats ? kPrefersMode
                                                     : kAmbiguous;
  return j;
}

// --diagnose's and --information's whole-frame judgements: the problem over every valid
// pixel of the frame (no thinning, no draw towards the contact), Ceres to convergence on
// it, and an objective there (half the squared whitened residuals; NaN if not finite).
LatentProblem::Options EveryValidPixel(LatentProblem::Options options) {
  options.max_pixels = 0;
  options.contact_share = 0;
  return options;
}

Eigen::VectorXd ConvergedLatent(const SensorTrunk& trunk, const LatentProblem& problem,
                                const Eigen::VectorXd& start) {
  LatentFitter::Options fit;
  fit.strategy = FitStrategy::FromString("ceres:30");
  Eigen::VectorXd z;
  LatentFitter(trunk, fit).Fit(problem, start, &z);
  return z;
}

double Objective(const LatentProblem& problem, const Eigen::VectorXd& z) {
  Eigen::VectorXd r(problem.num_residuals());
  return problem.ResidualsAndJacobian(z.data(), r.data(), nullptr) ? 0.5 * r.squaredNorm()
                                                                   : std::nan("");
}

// What the best generator possible through this trunk would say about a wrong mode: at
// each of the judgement's two simulator fits, the trunk's own latent for the simulator's
// noise-free frame there (Ceres to convergence from the generator's latent, every valid
// pixel), scored on the frame over every valid pixel; the mode's objective minus the
// truth's, in nats (> 0: the trunk keeps what tells the truth from the mode, and a
// generator that rendered every pose as the trunk fits it would rank the truth first).
double TrunkLogLikelihoodRatio(const ContactSimulator& simulator, const Image& reference,
                               const SensorTrunk& trunk, const TrunkTargets& targets,
                               LatentProblem::Options problem_options,
                               const PoseGenerator& generator, int tool_index,
                               const WrongModeJudgement& judgement, std::uint64_t seed) {
  problem_options = EveryValidPixel(problem_options);
  const LatentProblem frame(trunk, targets, problem_options);
  auto objective_at = [&](const Contact& at) {
    const Image clean = simulator.Render(SensorKind::kSoftBubble, at, seed).clean;
    const TrunkTargets noise_free =
        MakeTrunkTargets(AsStored(clean), reference, SensorKind::kSoftBubble, trunk.format);
    const LatentProblem at_pose(trunk, noise_free, problem_options);
    return Objective(frame, ConvergedLatent(trunk, at_pose,
                                            generator.Generate(tool_index, at.sensor_T_object,
                                                               at.depth_m)));
  };
  return objective_at(judgement.mode_fit) - objective_at(judgement.truth_fit);
}

// --diagnose's whole-frame objectives of a wrong mode: the generator's rendering at the
// mode and at the truth, and the trunk's own best latent (Ceres from the truth's
// generated latent to convergence), the floor any generator could reach through this
// trunk. The excess of the truth's rendering over that floor is the generator's
// shortfall at the truth; a floor far above the sensor noise would be the trunk's. (Not
// PSNR: its peak is the frame's own range, so a shallow contact at the noise floor reads
// a low PSNR.)
struct TrunkWholeFrame {
  double mode_cost = 0, truth_cost = 0, trunk_cost = 0;
  Eigen::VectorXd trunk_latent;  // the trunk's own best latent
  double TruthExcess() const { return truth_cost / trunk_cost - 1; }
  double ModeExcess() const { return mode_cost / trunk_cost - 1; }
};

TrunkWholeFrame JudgeAgainstTheTrunk(const SensorTrunk& trunk, const TrunkTargets& targets,
                                     LatentProblem::Options problem_options,
                                     const PoseGenerator& generator, int tool_index,
                                     const SE2d& mode, double mode_depth_m, const SE2d& truth,
                                     double truth_depth_m) {
  const LatentProblem whole(trunk, targets, EveryValidPixel(problem_options));
  TrunkWholeFrame out;
  out.mode_cost = PoseCost(whole, generator, tool_index, mode, mode_depth_m);
  out.truth_cost = PoseCost(whole, generator, tool_index, truth, truth_depth_m);
  out.trunk_latent =
      ConvergedLatent(trunk, whole, generator.Generate(tool_index, truth, truth_depth_m));
  out.trunk_cost = Objective(whole, out.trunk_latent);
  return out;
}

// How well the mixture's weights say which mode holds the truth: over the contacts whose
// true tool has two or more modes, the heaviest mode's weight among them, binned (below
// 0.5, then 0.5-0.6, ..., 0.9-1), against how often that mode holds the truth (its
// position within 1 mm, its yaw within 10 deg modulo the tool's symmetry). A calibrated
// mixture's heaviest mode holds the truth about as often as its weight says; region
// coverage cannot show this, since a region takes most of its mass from the heaviest mode.
class MixtureWeightReliability {
 public:
  static constexpr int kBins = 6;
  static constexpr double kHeldYawDeg = 10, kHeldPositionMm = 1;
  void Add(double weight, bool held) {
    const int b = Bin(weight);
    ++contacts_[b];
    held_[b] += held;
    weight_sum_[b] += weight;
  }
  // [lower, upper) of bin b (the last one closed).
  static double Lower(int b) { return b == 0 ? 0 : 0.4 + 0.1 * b; }
  static double Upper(int b) { return b == kBins - 1 ? 1 : 0.5 + 0.1 * b; }
  std::string Text() const {
    std::ostringstream out;
    for (int b = 0; b < kBins; ++b) {
      if (contacts_[b] == 0) continue;
      out << (out.tellp() > 0 ? ", " : "") << (b == 0 ? std::string("below 0.5") : Range(b))
          << ": " << held_[b] << " of " << contacts_[b];
    }
    return out.tellp() > 0 ? out.str() : std::string("no contact with two or more modes");
  }
  nlohmann::json Json() const {
    nlohmann::json bins = nlohmann::json::array();
    for (int b = 0; b < kBins; ++b) {
      if (contacts_[b] == 0) continue;
      bins.push_back({{"from", Lower(b)},
                      {"to", Upper(b)},
                      {"contacts", contacts_[b]},
                      {"held_truth", held_[b]},
                      {"mean_weight", weight_sum_[b] / contacts_[b]}});
    }
    return bins;
  }

 private:
  static int Bin(double weight) {
    if (!(weight >= 0.5)) return 0;
    return std::min(kBins - 1, 1 + static_cast<int>((weight - 0.5) * 10));
  }
  static std::string Range(int b) {
    char text[32];
    std::snprintf(text, sizeof(text), "%.1f-%.1f", Lower(b), Upper(b));
    return text;
  }
  int contacts_[kBins] = {};
  int held_[kBins] = {};
  double weight_sum_[kBins] = {};
};

// One wrong mode on --diagnose-picture.
struct WrongModeView {
  int contact = 0;
  std::string tool;
  double depth_m = 0;
  TrunkTargets targets;
  SE2d truth, mode;
  Eigen::VectorXf truth_latent, mode_latent;
  TrunkWholeFrame whole;
};

// --diagnose-picture: one row per wrong mode, left to right the frame (contact number and
// depth; the truth's pose as a green arrow, the mode's red), the trunk's own best latent
// (the tool), the generator's rendering at the truth and at the mode (each with its
// whole-frame objective's excess over the trunk's best; the same colour scale as the
// frame), and the two renderings' errors against the frame (one diverging scale for the
// row). pitch_m: metres per pixel of the trunk's working frame.
cv::Mat WrongModePicture(const std::vector<WrongModeView>& views, const SensorTrunk& trunk,
                         double pitch_m, int tile_height) {
  const int rows = trunk.format.rows, cols = trunk.format.cols;
  const cv::Scalar kTruth(80, 200, 80), kMode(60, 60, 230);
  std::vector<std::vector<cv::Mat>> grid;
  for (const WrongModeView& v : views) {
    const std::pair<double, double> range = ValidValueRange(v.targets);  // the row's colours
    const double lo = range.first, hi = range.second;
    const Eigen::MatrixXf trunk_best = Reconstruct(trunk, v.whole.trunk_latent.cast<float>());
    const Eigen::MatrixXf at_truth = Reconstruct(trunk, v.truth_latent);
    const Eigen::MatrixXf at_mode = Reconstruct(trunk, v.mode_latent);
    double scale = 1e-6;
    for (const Eigen::MatrixXf* m : {&at_truth, &at_mode}) {
      for (int j = 0; j < m->rows(); ++j) {
        if (v.targets.weights[j] > 0) {
          scale = std::max<double>(scale, std::abs((m->row(j) - v.targets.values.row(j)).mean()));
        }
      }
    }
    auto value = [&](const Eigen::MatrixXf& values) {
      return ValueTile(values, v.targets.weights, rows, cols, lo, hi);
    };
    auto fit = [&](const cv::Mat& tile) { return FitHeight(tile, tile_height); };
    cv::Mat frame = fit(value(v.targets.values));
    const double tile_pitch_m = pitch_m * rows / frame.rows;  // metres per tile pixel
    DrawPoseArrow(frame, frame.rows, frame.cols, tile_pitch_m, v.truth.x(), v.truth.y(),
                  v.truth.yaw(), kTruth);
    DrawPoseArrow(frame, frame.rows, frame.cols, tile_pitch_m, v.mode.x(), v.mode.y(),
                  v.mode.yaw(), kMode);
    char label[96];
    std::snprintf(label, sizeof(label), "#%d %.1f mm", v.contact, 1e3 * v.depth_m);
    PutLabel(frame, label, {4, 14}, 0.4);
    cv::Mat best_tile = fit(value(trunk_best));
    PutLabel(best_tile, v.tool, {4, 14}, 0.4);
    cv::Mat truth_tile = fit(value(at_truth)), mode_tile = fit(value(at_mode));
    std::snprintf(label, sizeof(label), "%+.1f %%", 100 * v.whole.TruthExcess());
    PutLabel(truth_tile, label, {4, 14}, 0.4);
    std::snprintf(label, sizeof(label), "%+.1f %%", 100 * v.whole.ModeExcess());
    PutLabel(mode_tile, label, {4, 14}, 0.4);
    grid.push_back({frame, best_tile, truth_tile, mode_tile,
                    fit(ErrorTile(at_truth, v.targets, scale)),
                    fit(ErrorTile(at_mode, v.targets, scale))});
  }
  if (grid.empty()) return cv::Mat();
  const char* titles[6] = {"frame", "trunk's best", "h(truth)", "h(mode)", "h(truth)-frame",
                           "h(mode)-frame"};
  std::vector<cv::Mat> header;
  for (int c = 0; c < 6; ++c) header.push_back(Caption(grid.front()[c].cols, titles[c]));
  grid.insert(grid.begin(), header);
  return TileGrid(grid);
}

// One contact on --information's picture: the mode's error and the bound's standard
// deviation, position (mm) and yaw (deg; NaN for a tool without an observable yaw), and
// its true depth's band (0: below 6 mm, 1: 6-10 mm, 2: from 10 mm).
struct BoundPoint {
  double bound_mm, error_mm, bound_deg, error_deg;
  int band;
};

// Each contact's error against its bound, one panel for the position and one for the
// yaw, both axes logarithmic over the same range: the line error = bound is the diagonal,
// a point's height above it the factor by which the estimator misses what the frame
// allows. Errors below the smallest bound sit on the bottom edge as triangles. The
// dashed line is the product's aim (0.3 mm, 3 deg).
cv::Mat BoundPicture(const std::vector<BoundPoint>& points, const std::string& subtitle) {
  const cv::Scalar band_colour[3] = {cv::Scalar(60, 60, 220), cv::Scalar(40, 160, 240),
                                     cv::Scalar(200, 120, 40)};
  const char* band_name[3] = {"below 6 mm deep", "6-10 mm deep", "from 10 mm deep"};
  std::vector<cv::Mat> panels;
  for (int panel = 0; panel < 2; ++panel) {
    const bool yaw = panel == 1;
    const double aim = yaw ? 3.0 : 0.3;
    double lo = std::numeric_limits<double>::infinity(), hi = aim;
    for (const BoundPoint& p : points) {
      const double b = yaw ? p.bound_deg : p.bound_mm, e = yaw ? p.error_deg : p.error_mm;
      if (!(b > 0) || !std::isfinite(b)) continue;
      lo = std::min(lo, b);
      hi = std::max(hi, b);
      if (std::isfinite(e)) hi = std::max(hi, e);
    }
    if (!std::isfinite(lo)) continue;
    LogXPlot::Layout layout;
    layout.height = 620;
    layout.width = 1100;
    layout.log_y = true;
    LogXPlot plot(layout, lo, hi, lo, hi);
    plot.DrawFrame(yaw ? "Cramer-Rao bound on the yaw, sd (deg)"
                       : "Cramer-Rao bound on the position, RMSE (mm)",
                   yaw ? "mode's yaw error (deg)" : "mode's position error (mm)",
                   yaw ? "Yaw: the estimator against what the frames allow"
                       : "Position: the estimator against what the frames allow",
                   subtitle);
    cv::Mat& canvas = plot.canvas();
    const cv::Rect& area = plot.area();
    const int bottom = area.y + area.height;
    // The diagonal error = bound, clipped to the plot area.
    std::vector<cv::Point> diagonal;
    for (int k = 0; k <= 200; ++k) {
      const double b =
          std::pow(10.0, std::log10(lo) - 1 + k * (std::log10(hi) - std::log10(lo) + 2) / 200);
      const cv::Point at(plot.X(b), plot.Y(b));
      if (area.contains(at)) diagonal.push_back(at);
    }
    if (diagonal.size() > 1) {
      cv::polylines(canvas, diagonal, false, cv::Scalar(130, 130, 130), 1, cv::LINE_AA);
    }
    DrawDashedLine(canvas, {area.x, plot.Y(aim)}, {area.x + area.width, plot.Y(aim)},
                   cv::Scalar(0, 0, 0));
    for (const BoundPoint& p : points) {
      const double b = yaw ? p.bound_deg : p.bound_mm, e = yaw ? p.error_deg : p.error_mm;
      if (!(b > 0) || !std::isfinite(b) || !std::isfinite(e)) continue;
      const int x = plot.X(b);
      if (e > 0 && plot.Y(e) < bottom) {
        cv::circle(canvas, {x, plot.Y(e)}, 3, band_colour[p.band], cv::FILLED, cv::LINE_AA);
      } else {
        const std::vector<cv::Point> tip = {{x, bottom}, {x - 4, bottom - 7}, {x + 4, bottom - 7}};
        cv::fillConvexPoly(canvas, tip, band_colour[p.band], cv::LINE_AA);
      }
    }
    const int lx = area.x + area.width + 22, ly = area.y + 14;
    for (int b = 0; b < 3; ++b) {
      cv::circle(canvas, {lx + 7, ly + 20 * b}, 4, band_colour[b], cv::FILLED, cv::LINE_AA);
      PlainText(canvas, band_name[b], {lx + 20, ly + 20 * b + 5}, 0.42);
    }
    cv::line(canvas, {lx, ly + 60}, {lx + 14, ly + 60}, cv::Scalar(130, 130, 130), 1);
    PlainText(canvas, "error = bound", {lx + 20, ly + 65}, 0.42);
    DrawDashedLine(canvas, {lx, ly + 80}, {lx + 14, ly + 80}, cv::Scalar(0, 0, 0));
    PlainText(canvas, yaw ? "aim: 3 deg RMSE" : "aim: 0.3 mm RMSE", {lx + 20, ly + 85}, 0.42);
    PlainText(canvas, "triangles: error below", {lx, ly + 110}, 0.38);
    PlainText(canvas, "the axis", {lx, ly + 126}, 0.38);
    panels.push_back(canvas);
  }
  cv::Mat picture;
  if (!panels.empty()) cv::vconcat(panels, picture);
  return picture;
}

void RunEvalGenerator(const EvalGeneratorFlags& flags) {
  if (!flags.data.empty() && flags.information) {
    throw UsageError("--information needs the simulator's own contacts: it cannot score "
                     "--data's frames (leave out --data or --information)");
  }
  if (flags.split != "train" && flags.split != "test" && flags.split != "all") {
    throw UsageError("--split: expected train, test or all, got '" + flags.split + "'");
  }
  const FunctaModel model = FunctaModel::Load(flags.model);
  const SensorTrunk& trunk = model.Trunk(SensorKind::kSoftBubble);
  const PoseGenerator generator =
      LoadPoseGeneratorFor(flags.generator, model, SensorKind::kSoftBubble, flags.model);
  std::unique_ptr<KnnPoseStarts> knn;
  if (!flags.functaset.empty()) {
    const Functaset functaset = Functaset::Load(flags.functaset);
    functaset.CheckModel(model, flags.model, flags.functaset);
    knn = std::make_unique<KnnPoseStarts>(functaset, SensorKind::kSoftBubble);
  }
  std::unique_ptr<PoseMlp> mlp;
  if (!flags.pose_model.empty()) mlp = std::make_unique<PoseMlp>(PoseMlp::Load(flags.pose_model));
  GeneratorPosterior::Options options;
  options.sigma_inflation = flags.sigma_inflation;
  options.weight_temperature = flags.weight_temperature;
  options.problem.max_pixels = flags.max_pixels;
  options.problem.contact_share = flags.contact_share;
  options.fit.max_refined_starts = flags.refined_starts;
  options.fit.max_iterations = flags.iterations;
  options.knn_k = flags.knn_k;
  options.yaw_grid = flags.yaw_grid;
  options.coarse_pixels = flags.coarse_pixels;
  options.tool_prune_ratio = flags.tool_prune_ratio;
  options.tool_screen = flags.tool_screen;
  options.final_pixels = flags.final_pixels;
  options.position_grid_m = 1e-3 * flags.position_grid_mm;
  options.position_grid_rings = flags.position_rings;
  options.fit.coarse_refined_starts = flags.coarse_starts;
  options.fit.coarse_iterations = flags.coarse_iterations;
  const GeneratorPosterior posterior(trunk, generator, options, knn.get(), mlp.get());
  const ContactSimulator simulator;
  const Image reference = AsStored(simulator.Reference(SensorKind::kSoftBubble));
  std::unique_ptr<Dataset> dataset;
  if (!flags.data.empty()) {
    dataset = std::make_unique<Dataset>(OpenDataset(flags.data, flags.dataset));
    if (!dataset->has_sensor(SensorKind::kSoftBubble)) {
      throw DatasetError("--data '" + flags.data + "': no bubble frames (the generator " +
                         "renders Soft Bubble frames)");
    }
    CheckModelMatchesData(model, flags.model, *dataset, flags.data, SensorKind::kSoftBubble,
                          "eval-generator", "--allow-other-frames", flags.allow_other_frames);
  }
  int contacts = 0, failures = 0, c50 = 0, c90 = 0, yaw_count = 0, identified = 0;
  long tools_refined = 0, tools_screened_in = 0;
  double pos_sq = 0, yaw_sq = 0;
  double mean_pos_sq = 0, mean_yaw_sq = 0;  // of the posterior mean
  std::vector<double> mean_yaw_errors;
  int wrong = 0, search_failures = 0, model_failures = 0;
  MixtureWeightReliability weight_reliability;
  // --diagnose-picture: the first kPictureRows wrong modes.
  constexpr std::size_t kPictureRows = 6;
  std::vector<WrongModeView> wrong_views;
  // --diagnose: per wrong mode, the truth's and the mode's whole-frame excess over the
  // trunk's own best latent.
  std::vector<double> truth_excess, mode_excess;
  std::vector<double> yaw_errors;
  std::vector<double> position_errors;  // of the mode, metres
  std::ostringstream csv;
  csv << "contact,tool,symmetry_order,truth_x_mm,truth_y_mm,truth_yaw_deg,truth_depth_mm,"
         "mode_x_mm,mode_y_mm,mode_yaw_deg,mode_depth_mm,mean_x_mm,mean_y_mm,mean_yaw_deg,"
         "position_error_mm,yaw_error_deg,modes,tool_probability,mode_sd_x_mm,mode_sd_y_mm,"
         "mode_sd_yaw_deg,bound_sd_along_mm,bound_sd_across_mm,bound_sd_yaw_deg,"
         "bound_sd_depth_mm,frame_llr_truth_over_mode,trunk_llr_truth_over_mode,"
         "whole_frame_truth_cost,whole_frame_mode_cost,whole_frame_trunk_best_cost,mode_weight\n";
  std::vector<double> times, cpu_times;
  std::map<std::string, std::pair<double, int>> per_tool_pos;
  // --information, by true depth (below 6 mm, 6-10 mm, from 10 mm): the mode's summed
  // squared position error, the bound's summed trace (m^2) and the count; and the yaw's
  // summed squared error and bound (rad^2) over tools with an observable yaw.
  const double kDepthEdges[2] = {6e-3, 10e-3};
  // The bound on the trunk's working frames and, beside it, on the sensor's own.
  double band_error[3] = {0, 0, 0}, band_bound[3] = {0, 0, 0};
  int band_count[3] = {0, 0, 0};
  double bound_yaw_sq = 0, sensor_bound_sq = 0, sensor_bound_yaw_sq = 0;
  // Wrong modes by what the frame says (JudgeWrongMode), counted by verdict.
  int frame_verdicts[kVerdicts] = {0, 0, 0, 0};
  std::vector<double> frame_llrs;
  std::vector<double> trunk_llrs;  // the same wrong modes through the trunk
  std::vector<BoundPoint> bound_points;
  PoseInformationOptions working_size;
  working_size.rows = trunk.format.rows;
  working_size.cols = trunk.format.cols;
  const std::vector<std::string>& tools = generator.options().tools;
  // --tools: a subset, each contact seeded as in the run over every tool.
  std::vector<bool> evaluated(tools.size(), flags.tools.empty());
  for (const std::string& name : SplitList(flags.tools)) {
    const int index = generator.ToolIndex(name);
    if (index < 0) {
      throw UsageError("--tools: '" + name + "' is not a tool of --generator '" +
                       flags.generator + "'");
    }
    evaluated[index] = true;
  }
  // What is scored: contact k of tool t, seeded as in the run over every tool; with --data
  // the split's labelled frames of each evaluated tool in the dataset's order (k: the
  // frame's index in the dataset), at most --contacts-per-tool of each when given.
  struct EvalCase {
    int tool = 0;
    int contact = 0;  // k; with --data the frame's index into dataset->frames()
  };
  std::vector<EvalCase> cases;
  if (dataset) {
    std::vector<int> taken(tools.size(), 0);
    const std::vector<FrameRecord>& records = dataset->frames();
    for (std::size_t i = 0; i < records.size(); ++i) {
      const FrameRecord& r = records[i];
      if (r.sensor != SensorKind::kSoftBubble || !r.label.has_value()) continue;
      if (flags.split != "all" && ToString(r.split) != flags.split) continue;
      const int t = generator.ToolIndex(r.label->tool);
      if (t < 0 || !evaluated[t]) continue;
      if (flags.contacts_per_tool_given && taken[t] >= flags.contacts_per_tool) continue;
      ++taken[t];
      cases.push_back({t, static_cast<int>(i)});
    }
    if (cases.empty()) {
      throw DatasetError("--data '" + flags.data + "': no labelled bubble frames of the " +
                         (flags.split == "all" ? std::string("dataset") : flags.split + " split") +
                         " whose tool the generator knows");
    }
  } else {
    for (std::size_t t = 0; t < tools.size(); ++t) {
      if (!evaluated[t]) continue;
      for (int j = 0; j < flags.contacts_per_tool; ++j) {
        const int k = static_cast<int>(t) * flags.contacts_per_tool + j;
        cases.push_back({static_cast<int>(t), k});
      }
    }
  }
  ProgressBar bar("eval-generator", static_cast<std::int64_t>(cases.size()), "contacts",
                  ProgressBar::Lines::kWhenNotDrawn);
  for (const EvalCase& c : cases) {
    const std::size_t t = static_cast<std::size_t>(c.tool);
    const int k = c.contact;
    const std::uint64_t seed = DeriveSeed(flags.seed, k);
    // A fresh contact, or a labelled frame of --data (its label the truth).
    const Contact contact = dataset ? *dataset->frames()[k].label
                                    : simulator.SamplePairedContact(tools[t], seed).bubble;
    const Image frame =
        dataset ? Image()
                : AsStored(simulator.Render(SensorKind::kSoftBubble, contact, seed).frame);
    const TrunkTargets targets =
        dataset ? LoadTrunkTargets(*dataset, k, trunk.format)
                : MakeTrunkTargets(frame, reference, SensorKind::kSoftBubble, trunk.format);
    PoseMixture mixture;
    const GeneratorPosterior::Summary s =
        posterior.Estimate(targets, flags.unknown_tool ? "" : tools[t], &mixture);
    ++contacts;
    bar.Tick();
    if (!s.usable) {
      ++failures;
      continue;
    }
    times.push_back(s.total_time_ms);
    cpu_times.push_back(s.cpu_time_ms);
    identified += s.tool == tools[t];
    tools_refined += s.tools_refined;
    tools_screened_in += s.tools_screened_in;
    const int n = generator.SymmetryOrder(static_cast<int>(t));
    const SE2d& truth = contact.sensor_T_object;
    // Score the mode of the true tool's components (the tool-conditional posterior):
    // its heaviest component, the first of that tool; the overall mode if it has none.
    const LaplaceComponent* true_mode = nullptr;
    for (const LaplaceComponent& c : mixture.components()) {
      if (c.tool == tools[t]) {
        true_mode = &c;
        break;
      }
    }
    const SE2d mode = true_mode != nullptr ? true_mode->mean : s.mean;
    // The mode's yaw error (radians, modulo symmetry; n = 0: none).
    const double mode_yaw_error =
        n != 0 ? YawErrorModuloSymmetry(mode.yaw(), truth.yaw(), n) : std::nan("");
    const double dp = std::pow(mode.x() - truth.x(), 2) + std::pow(mode.y() - truth.y(), 2);
    pos_sq += dp;
    position_errors.push_back(std::sqrt(dp));
    // And the posterior mean of the true tool's components (PoseMixture::Mean); that of
    // the most probable tool if the true one has none (its fits failed, or the tool
    // unknown, it was screened out or pruned), as the mode above.
    const SE2d mean = true_mode != nullptr ? mixture.Mean(tools[t]) : mixture.Mean();
    mean_pos_sq += std::pow(mean.x() - truth.x(), 2) + std::pow(mean.y() - truth.y(), 2);
    if (n != 0) {
      const double e = YawErrorModuloSymmetry(mean.yaw(), truth.yaw(), n);
      mean_yaw_sq += e * e;
      mean_yaw_errors.push_back(e);
    }
    // The true tool's modes, and the heaviest one's weight among them.
    int modes = 0;
    double tool_weight = 0;
    for (const LaplaceComponent& c : mixture.components()) {
      if (c.tool != tools[t]) continue;
      ++modes;
      tool_weight += c.weight;
    }
    const double mode_weight =
        true_mode != nullptr && tool_weight > 0 ? true_mode->weight / tool_weight : std::nan("");
    if (modes >= 2 && std::isfinite(mode_weight)) {
      weight_reliability.Add(
          mode_weight,
          (n == 0 || kDeg * mode_yaw_error <= MixtureWeightReliability::kHeldYawDeg) &&
              1e3 * std::sqrt(dp) <= MixtureWeightReliability::kHeldPositionMm);
    }
    // Wrong: the mode's yaw more than 5 degrees or its position more than 1 mm off.
    const bool wrong_mode = (n != 0 && kDeg * mode_yaw_error > 5) || std::sqrt(dp) > 1e-3;
    PoseInformation information;
    double frame_llr = std::nan("");
    double trunk_llr = std::nan("");
    if (flags.information) {
      information = SoftBubblePoseInformation(simulator, contact, working_size);
      const PoseInformation sensor = SoftBubblePoseInformation(simulator, contact);
      sensor_bound_sq += sensor.bound(0, 0) + sensor.bound(1, 1);
      if (n != 0) sensor_bound_yaw_sq += sensor.bound(2, 2);
      const int band = (contact.depth_m >= kDepthEdges[0]) + (contact.depth_m >= kDepthEdges[1]);
      band_error[band] += dp;
      band_bound[band] += information.bound(0, 0) + information.bound(1, 1);
      ++band_count[band];
      if (n != 0) bound_yaw_sq += information.bound(2, 2);
      bound_points.push_back({1e3 * information.PositionRmse(), 1e3 * std::sqrt(dp),
                              n != 0 ? kDeg * information.YawSd() : std::nan(""),
                              n != 0 ? kDeg * mode_yaw_error : std::nan(""), band});
      // A wrong mode: does the frame itself prefer the truth's basin?
      if (wrong_mode) {
        const WrongModeJudgement j =
            JudgeWrongMode(simulator, frame, contact, mode,
                           true_mode != nullptr ? true_mode->depth_m : contact.depth_m, n);
        ++frame_verdicts[j.verdict];
        frame_llr = j.log_likelihood_ratio;
        frame_llrs.push_back(frame_llr);
        trunk_llr = TrunkLogLikelihoodRatio(simulator, reference, trunk, targets,
                                            options.problem, generator, static_cast<int>(t),
                                            j, seed);
        trunk_llrs.push_back(trunk_llr);
      }
    }
    // --diagnose, a wrong mode: the whole-frame objectives (NaN otherwise).
    TrunkWholeFrame whole;
    whole.mode_cost = whole.truth_cost = whole.trunk_cost = std::nan("");
    if (flags.diagnose) {
      // Is the truth's objective lower than the chosen mode's (a search failure) or
      // higher (the generator and trunk prefer the wrong pose: a model failure)? The
      // truth is also refined (from the true pose and depth) to its local minimum.
      const double e = n != 0 ? kDeg * mode_yaw_error : 0;
      if (wrong_mode) {
        ++wrong;
        // The problem the posterior ranked its modes on (the final stage's when it
        // runs), so that the costs compare what chose the mode.
        const LatentProblem problem(trunk, targets, posterior.options().RankingProblem());
        const int ti = static_cast<int>(t);
        const double mode_depth = true_mode != nullptr ? true_mode->depth_m : 0;
        const double c_mode = PoseCost(problem, generator, ti, mode, mode_depth);
        const double c_truth = PoseCost(problem, generator, ti, truth, contact.depth_m);
        const std::vector<PoseFit> refined = FitPoseModes(
            problem, generator, ti, {{truth, contact.depth_m, "truth"}}, options.fit);
        const double c_refined = refined.empty() ? std::nan("") : refined.front().cost;
        // Lower by more than 1% of the mode's cost (not the same minimum re-found).
        const bool search = c_refined < c_mode - 0.01 * std::abs(c_mode);
        search_failures += search;
        model_failures += !search;
        std::printf("  contact %d %-11s yaw err %6.1f deg pos err %.2f mm | cost: mode %.1f, "
                    "truth %.1f, truth refined %.1f -> %s failure\n",
                    k, tools[t].c_str(), e, 1e3 * std::sqrt(dp), c_mode, c_truth, c_refined,
                    search ? "search" : "model");
        // Which part of the renderer: over the whole frame (so that a free latent cannot
        // fit the few pixels of a pass), the generator at the mode and at the truth
        // against the trunk's own best latent (Ceres to convergence from the truth's
        // generated latent), the best any generator could render through this trunk.
        whole = JudgeAgainstTheTrunk(trunk, targets, options.problem, generator, ti, mode,
                                     mode_depth, truth, contact.depth_m);
        truth_excess.push_back(whole.TruthExcess());
        mode_excess.push_back(whole.ModeExcess());
        if (!flags.diagnose_picture.empty() && wrong_views.size() < kPictureRows) {
          wrong_views.push_back({k, tools[t], contact.depth_m, targets, truth, mode,
                                 generator.Generate(ti, truth, contact.depth_m).cast<float>(),
                                 generator.Generate(ti, mode, mode_depth).cast<float>(),
                                 whole});
        }
        std::printf("    whole frame: mode %.1f, truth %.1f, the trunk's own best latent %.1f "
                    "(truth %+.1f %%, mode %+.1f %% above it)\n",
                    whole.mode_cost, whole.truth_cost, whole.trunk_cost,
                    100 * whole.TruthExcess(), 100 * whole.ModeExcess());
      }
    }
    if (!flags.contacts_csv.empty()) {
      const double mode_depth = true_mode != nullptr ? true_mode->depth_m : std::nan("");
      // The mode's Laplace standard deviations in its tangent space: x and y along and
      // across the object's own axes (right perturbation), and the yaw.
      Eigen::Vector3d sd = Eigen::Vector3d::Constant(std::nan(""));
      if (true_mode != nullptr) sd = true_mode->covariance.diagonal().head<3>().cwiseSqrt();
      if (n == 0) sd[2] = std::nan("");  // the yaw of a C_inf tool is not estimated
      // The bound's standard deviations along and across the true object's axes.
      Eigen::Vector4d bound_sd = Eigen::Vector4d::Constant(std::nan(""));
      if (flags.information) {
        const Eigen::Matrix2d r = truth.Rotation();
        const Eigen::Matrix2d object_block =
            r.transpose() * information.bound.topLeftCorner<2, 2>() * r;
        bound_sd << std::sqrt(object_block(0, 0)), std::sqrt(object_block(1, 1)),
            std::sqrt(information.bound(2, 2)), std::sqrt(information.bound(3, 3));
      }
      char row[768];
      std::snprintf(
          row, sizeof(row),
          "%d,%s,%d,%.4f,%.4f,%.3f,%.4f,%.4f,%.4f,%.3f,%.4f,%.4f,%.4f,%.3f,%.4f,%.3f,%d,"
          "%.4f,%.4f,%.4f,%.3f,%.4f,%.4f,%.3f,%.4f,%.2f,%.2f,%.2f,%.2f,%.2f,%.4f\n",
          k, tools[t].c_str(), n, 1e3 * truth.x(), 1e3 * truth.y(), kDeg * truth.yaw(),
          1e3 * contact.depth_m, 1e3 * mode.x(), 1e3 * mode.y(), kDeg * mode.yaw(),
          1e3 * mode_depth, 1e3 * mean.x(), 1e3 * mean.y(), kDeg * mean.yaw(),
          1e3 * std::sqrt(dp), kDeg * mode_yaw_error, modes,
          s.tool_probabilities.count(tools[t]) ? s.tool_probabilities.at(tools[t]) : 0.0,
          1e3 * sd[0], 1e3 * sd[1], kDeg * sd[2], 1e3 * bound_sd[0], 1e3 * bound_sd[1],
          kDeg * bound_sd[2], 1e3 * bound_sd[3], frame_llr, trunk_llr, whole.truth_cost,
          whole.mode_cost, whole.trunk_cost, mode_weight);
      csv << row;
    }
    per_tool_pos[tools[t]].first += dp;
    per_tool_pos[tools[t]].second += 1;
    if (n != 0) {
      yaw_sq += mode_yaw_error * mode_yaw_error;
      yaw_errors.push_back(mode_yaw_error);
      ++yaw_count;
    }
    if (true_mode != nullptr) {
      c50 += mixture.Contains(truth, 0.5, options.num_region_samples, seed, tools[t]);
      c90 += mixture.Contains(truth, 0.9, options.num_region_samples, seed, tools[t]);
    }
  }
  bar.Finish();
  if (!flags.contacts_csv.empty()) {
    WriteFileAtomically(flags.contacts_csv, csv.str());
    std::cout << "eval-generator: wrote one row per contact to " << flags.contacts_csv << "\n";
  }
  const int ok = contacts - failures;
  std::sort(times.begin(), times.end());
  const double median = times.empty() ? 0 : times[times.size() / 2];
  const double mean_ms = times.empty() ? 0 : std::accumulate(times.begin(), times.end(), 0.0) / times.size();
  const double rmse_mm = 1e3 * std::sqrt(pos_sq / std::max(1, ok));
  const double rmse_deg = kDeg * std::sqrt(yaw_sq / std::max(1, yaw_count));
  const std::string scored =
      dataset ? "labelled frames of " + flags.data + " (" + flags.split + ")" : "fresh contacts";
  std::printf("eval-generator: %d %s (%d failed), tool %s\n", contacts, scored.c_str(), failures,
              flags.unknown_tool ? "unknown (every tool fitted)" : "given");
  std::printf("  position RMSE %.3f mm, yaw RMSE %.2f deg (modulo symmetry, hemisphere left out)\n",
              rmse_mm, rmse_deg);
  std::sort(position_errors.begin(), position_errors.end());
  const double position_median_mm =
      position_errors.empty() ? 0 : 1e3 * position_errors[position_errors.size() / 2];
  const double position_p90_mm =
      position_errors.empty() ? 0 : 1e3 * position_errors[position_errors.size() * 9 / 10];
  std::printf("  position error median %.3f mm, 90th percentile %.3f mm\n", position_median_mm,
              position_p90_mm);
  std::sort(yaw_errors.begin(), yaw_errors.end());
  const double yaw_median = yaw_errors.empty() ? 0 : kDeg * yaw_errors[yaw_errors.size() / 2];
  const double yaw_within5 =
      yaw_errors.empty() ? 0
                         : static_cast<double>(std::lower_bound(yaw_errors.begin(), yaw_errors.end(),
                                                                5 / kDeg) -
                                               yaw_errors.begin()) / yaw_errors.size();
  std::printf("  yaw error median %.2f deg, within 5 deg: %.3f\n", yaw_median, yaw_within5);
  std::sort(mean_yaw_errors.begin(), mean_yaw_errors.end());
  const double mean_rmse_mm = 1e3 * std::sqrt(mean_pos_sq / std::max(1, ok));
  const double mean_rmse_deg = kDeg * std::sqrt(mean_yaw_sq / std::max(1, yaw_count));
  const double mean_yaw_median =
      mean_yaw_errors.empty() ? 0 : kDeg * mean_yaw_errors[mean_yaw_errors.size() / 2];
  std::printf("  posterior mean: position RMSE %.3f mm, yaw RMSE %.2f deg, yaw median %.2f deg\n",
              mean_rmse_mm, mean_rmse_deg, mean_yaw_median);
  std::printf("  coverage 50%%: %.3f, 90%%: %.3f\n", static_cast<double>(c50) / std::max(1, ok),
              static_cast<double>(c90) / std::max(1, ok));
  std::printf("  the heaviest of two or more modes holds the truth (within %.0f deg and %.0f mm), "
              "by its weight: %s\n",
              MixtureWeightReliability::kHeldYawDeg, MixtureWeightReliability::kHeldPositionMm,
              weight_reliability.Text().c_str());
  std::sort(cpu_times.begin(), cpu_times.end());
  const double cpu_median = cpu_times.empty() ? 0 : cpu_times[cpu_times.size() / 2];
  std::printf("  time per frame (fit + Laplace, one thread): median %.1f ms, mean %.1f ms; "
              "CPU time median %.1f ms\n",
              median, mean_ms, cpu_median);
  if (flags.diagnose) {
    std::printf("  wrong (yaw > 5 deg or position > 1 mm): %d; truth's refined cost lower "
                "(search failure): %d, higher (model failure): %d\n",
                wrong, search_failures, model_failures);
    if (!truth_excess.empty()) {
      std::sort(truth_excess.begin(), truth_excess.end());
      std::sort(mode_excess.begin(), mode_excess.end());
      const std::size_t half = truth_excess.size() / 2;
      std::printf(
          "  over the whole frame, above the trunk's own best latent: the truth's rendering "
          "median %+.1f %% (%+.1f to %+.1f), the mode's %+.1f %% (%+.1f to %+.1f)\n",
          100 * truth_excess[half], 100 * truth_excess.front(), 100 * truth_excess.back(),
          100 * mode_excess[half], 100 * mode_excess.front(), 100 * mode_excess.back());
    }
  }
  nlohmann::json information_json;
  if (flags.information) {
    // sqrt(mean bound) over a band: the floor on that band's RMSE for unbiased estimators.
    const auto floor_mm = [](double sum, int count) {
      return count > 0 ? 1e3 * std::sqrt(sum / count) : std::nan("");
    };
    const int all = band_count[0] + band_count[1] + band_count[2];
    const double bound_mm = floor_mm(band_bound[0] + band_bound[1] + band_bound[2], all);
    const double bound_deg = kDeg * std::sqrt(bound_yaw_sq / std::max(1, yaw_count));
    const double sensor_mm = floor_mm(sensor_bound_sq, all);
    const double sensor_deg = kDeg * std::sqrt(sensor_bound_yaw_sq / std::max(1, yaw_count));
    std::printf(
        "  Cramer-Rao bound (the simulator's frames and noise, any unbiased estimator) "
        "on the trunk's %dx%d frames: position RMSE %.3f mm (mode %.3f), yaw RMSE %.2f "
        "deg (mode %.2f); on the sensor's own: %.3f mm, %.2f deg\n",
        trunk.format.rows, trunk.format.cols, bound_mm, rmse_mm, bound_deg, rmse_deg, sensor_mm,
        sensor_deg);
    const char* band_names[3] = {"below 6 mm deep", "6-10 mm deep", "from 10 mm deep"};
    information_json = {{"bound_rmse_mm", NumberOrNull(bound_mm)},
                        {"bound_rmse_deg", NumberOrNull(bound_deg)},
                        {"sensor_bound_rmse_mm", NumberOrNull(sensor_mm)},
                        {"sensor_bound_rmse_deg", NumberOrNull(sensor_deg)}};
    for (int b = 0; b < 3; ++b) {
      const double bound_b = floor_mm(band_bound[b], band_count[b]);
      const double mode_b = floor_mm(band_error[b], band_count[b]);
      std::printf("    %-15s %4d contacts: position RMSE bound %.3f mm, mode %.3f mm\n",
                  band_names[b], band_count[b], bound_b, mode_b);
      information_json["by_depth"].push_back({{"band", band_names[b]},
                                              {"contacts", band_count[b]},
                                              {"bound_rmse_mm", NumberOrNull(bound_b)},
                                              {"mode_rmse_mm", NumberOrNull(mode_b)}});
    }
    std::sort(frame_llrs.begin(), frame_llrs.end());
    const double llr_median = frame_llrs.empty() ? std::nan("") : frame_llrs[frame_llrs.size() / 2];
    std::printf(
        "  wrong modes (yaw > 5 deg or position > 1 mm): %zu; by the simulator's own fit "
        "from the truth and from the mode, the frame puts the mode in the truth's basin: "
        "%d; prefers the truth's basin by > %.0f nats: %d; about as likely (within %.0f): "
        "%d; prefers the mode's basin: %d; log-likelihood ratio median %.1f nats\n",
        frame_llrs.size(), frame_verdicts[kInTruthBasin], kClearNats, frame_verdicts[kPrefersTruth],
        kClearNats, frame_verdicts[kAmbiguous], frame_verdicts[kPrefersMode], llr_median);
    information_json["wrong_modes"] = {{"count", frame_llrs.size()},
                                       {"mode_in_truth_basin", frame_verdicts[kInTruthBasin]},
                                       {"frame_prefers_truth", frame_verdicts[kPrefersTruth]},
                                       {"frame_ambiguous", frame_verdicts[kAmbiguous]},
                                       {"frame_prefers_mode", frame_verdicts[kPrefersMode]},
                                       {"log_likelihood_ratio_median", NumberOrNull(llr_median)}};
    // The same wrong modes through the trunk (TrunkLogLikelihoodRatio).
    const auto trunk_prefers_truth = std::count_if(
        trunk_llrs.begin(), trunk_llrs.end(), [](double v) { return v > kClearNats; });
    const auto trunk_prefers_mode = std::count_if(
        trunk_llrs.begin(), trunk_llrs.end(), [](double v) { return v < -kClearNats; });
    std::sort(trunk_llrs.begin(), trunk_llrs.end());
    const double trunk_median =
        trunk_llrs.empty() ? std::nan("") : trunk_llrs[trunk_llrs.size() / 2];
    std::printf(
        "  through the trunk (its own latent for the simulator's noise-free frame at each "
        "of those fits, scored on the frame): prefers the truth by > %.0f nats: %ld; the "
        "mode: %ld; log-likelihood ratio median %.1f nats\n",
        kClearNats, static_cast<long>(trunk_prefers_truth), static_cast<long>(trunk_prefers_mode),
        trunk_median);
    information_json["wrong_modes"]["trunk_prefers_truth"] = trunk_prefers_truth;
    information_json["wrong_modes"]["trunk_prefers_mode"] = trunk_prefers_mode;
    information_json["wrong_modes"]["trunk_log_likelihood_ratio_median"] =
        NumberOrNull(trunk_median);
  }
  if (!flags.diagnose_picture.empty()) {
    const SoftBubbleOptions& bubble = simulator.options().bubble;  // the frames' pitch
    const double pitch_m = bubble.pixel_pitch_m * bubble.rows / trunk.format.rows;
    const cv::Mat picture = WrongModePicture(wrong_views, trunk, pitch_m, 100);
    if (picture.empty()) {
      std::cout << "eval-generator: no wrong mode, " << flags.diagnose_picture
                << " not written\n";
    } else {
      WritePicture(flags.diagnose_picture, picture);
      std::cout << "eval-generator: wrote " << flags.diagnose_picture << " ("
                << wrong_views.size() << " wrong modes)\n";
    }
  }
  if (!flags.picture.empty()) {
    char subtitle[256];
    std::snprintf(subtitle, sizeof(subtitle),
                  "%d fresh Soft Bubble contacts (seed %llu); bound from the simulator's own "
                  "frames and noise on the trunk's %dx%d frames",
                  ok, static_cast<unsigned long long>(flags.seed), trunk.format.rows,
                  trunk.format.cols);
    const cv::Mat picture = BoundPicture(bound_points, subtitle);
    if (!picture.empty()) {
      WritePicture(flags.picture, picture);
      std::cout << "eval-generator: wrote " << flags.picture << "\n";
    }
  }
  if (flags.unknown_tool) {
    std::printf(
        "  tool identified: %.3f; tools per frame: %.2f past the screening, %.2f refined past "
        "the coarse stage\n",
        static_cast<double>(identified) / std::max(1, ok),
        static_cast<double>(tools_screened_in) / std::max(1, ok),
        static_cast<double>(tools_refined) / std::max(1, ok));
  }
  for (const auto& [tool, v] : per_tool_pos) {
    std::printf("  %-11s position RMSE %.3f mm\n", tool.c_str(), 1e3 * std::sqrt(v.first / v.second));
  }
  if (flags.json) {
    EmitJson({{"contacts", contacts},
              {"failures", failures},
              {"rmse_mm", rmse_mm},
              {"rmse_deg", rmse_deg},
              {"mean_rmse_mm", mean_rmse_mm},
              {"mean_rmse_deg", mean_rmse_deg},
              {"mean_yaw_median_deg", mean_yaw_median},
              {"yaw_median_deg", yaw_median},
              {"position_median_mm", position_median_mm},
              {"position_p90_mm", position_p90_mm},
              {"yaw_within_5deg", yaw_within5},
              {"coverage_50", static_cast<double>(c50) / std::max(1, ok)},
              {"coverage_90", static_cast<double>(c90) / std::max(1, ok)},
              {"mode_weight_reliability", weight_reliability.Json()},
              {"median_ms", median},
              {"mean_ms", mean_ms},
              {"cpu_median_ms", cpu_median},
              {"information", information_json},
              {"tool_identified",
               flags.unknown_tool ? NumberOrNull(static_cast<double>(identified) / std::max(1, ok))
                                  : nlohmann::json()},
              {"tools_screened_in_per_frame",
               flags.unknown_tool
                   ? NumberOrNull(static_cast<double>(tools_screened_in) / std::max(1, ok))
                   : nlohmann::json()},
              {"tools_refined_per_frame",
               flags.unknown_tool
                   ? NumberOrNull(static_cast<double>(tools_refined) / std::max(1, ok))
                   : nlohmann::json()}});
  }
}

}  // namespace

void RegisterTrainGenerator(CLI::App& app, CommandBody* selected) {
  auto flags = std::make_shared<TrainGeneratorFlags>();
  CLI::App* sub = app.add_subcommand(
      "train-generator",
      "Train the pose-conditioned generator h(tool, pose, depth) -> latent on a functaset's "
      "labelled bubble train entries (regression, then optionally through the frozen trunk on "
      "pixels), calibrate its posterior sigma and write it (docs/POSES.md, The generator path).");
  sub->add_option("--model", flags->model, "Model file (.tfm) of the functaset")->required();
  sub->add_option("--functaset", flags->functaset, "Labelled functaset (.tfs)")->required();
  sub->add_option("--data", flags->data, "The functaset's dataset (frames)")->required();
  AddDatasetFlags(sub, &flags->dataset);
  sub->add_option("--out", flags->out, "Generator file to write (atomically)")->required();
  sub->add_option("--mode", flags->mode,
                  "latents (regress the functaset's latents) or pixels (then fine-tune through "
                  "the trunk on pixels; default)");
  sub->add_option("--hidden", flags->hidden, "tanh hidden widths (default 256,256)");
  sub->add_option("--harmonics", flags->harmonics, "Yaw harmonics K (default 4)")
      ->check(CLI::Range(1, 64));
  sub->add_option("--epochs", flags->epochs, "Regression epochs (default 300)")
      ->check(CLI::Range(1, 1000000));
  sub->add_option("--pixel-epochs", flags->pixel_epochs, "Epochs through the trunk (default 4)")
      ->check(CLI::Range(1, 100000));
  sub->add_option("--pixel-frames", flags->pixel_frames,
                  "Train frames per tool for the pixel epochs (default 200)")
      ->check(CLI::Range(1, 1000000));
  sub->add_option("--pixels", flags->pixels, "Pixels per frame and step (default 256)")
      ->check(CLI::Range(1, 1 << 20));
  sub->add_option("--calibration-frames", flags->calibration_frames,
                  "Test-split frames for the sigma inflation (default 120)")
      ->check(CLI::Range(1, 1000000));
  sub->add_option("--temperature-frames", flags->temperature_frames,
                  "Test-split frames for the temperature of the posterior's mode weights "
                  "(default 600)")
      ->check(CLI::Range(1, 1000000));
  sub->add_option("--final-pixels", flags->final_pixels,
                  "Calibrate with the posterior's final stage on N pixels (eval-generator "
                  "--final-pixels) and record it, so that the posterior runs that stage by "
                  "default (default 0 = none)")
      ->check(CLI::Range(0, 1 << 20));
  sub->add_option("--recalibrate", flags->recalibrate,
                  "A trained generator (.tpg) to calibrate again (kappa, tau, --final-pixels) "
                  "on --functaset's test split instead of training one; written to --out with "
                  "its training record; the training flags are ignored");
  sub->add_option("--tune-trunk", flags->tune_trunk,
                  "Train the trunk too in the pixel stage, its Adam step this fraction of the "
                  "generator's (default 0: frozen); needs --out-model")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--out-model", flags->out_model,
                  "With --tune-trunk: the generator's own trunk (.tfm) to write (atomically); "
                  "the generator renders through it (`pose --generator-model`)");
  sub->add_option("--lr", flags->lr, "Adam step (default 1e-3; pixels use 0.3x)")
      ->check(CLI::PositiveNumber);
  sub->add_option("--seed", flags->seed, "Seed (default 0)");
  sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
  sub->add_flag("--resume", flags->resume,
                "Continue from the checkpoints OUT.regression.ckpt / OUT.pixels.ckpt that an "
                "interrupted run (Ctrl-C) left; the same flags give the same generator");
  sub->callback([flags, selected]() { *selected = [flags]() { RunTrainGenerator(*flags); }; });
}

void RegisterEvalGenerator(CLI::App& app, CommandBody* selected) {
  auto flags = std::make_shared<EvalGeneratorFlags>();
  CLI::App* sub = app.add_subcommand(
      "eval-generator",
      "Score the generator pose posterior on fresh simulated bubble contacts of every tool it "
      "knows, or on a labelled dataset's frames (--data): position / yaw RMSE of the mode and "
      "of the posterior mean, 50%/90% region coverage, time per frame, and "
      "tool identification with --unknown-tool.");
  sub->add_option("--model", flags->model, "Model file (.tfm)")->required();
  sub->add_option("--generator", flags->generator, "Generator from `tactfunc train-generator`")
      ->required();
  sub->add_option("--functaset", flags->functaset, "Labelled functaset for the k-NN starts");
  sub->add_option("--pose-model", flags->pose_model, "Pose MLP for an extra start");
  sub->add_option("--tools", flags->tools,
                  "Only these of the generator's tools (comma-separated; default all); each "
                  "contact is the one the run over every tool draws");
  CLI::Option* per_tool =
      sub->add_option("--contacts-per-tool", flags->contacts_per_tool,
                      "Default 20; with --data at most this many frames of each tool (default "
                      "all)")
          ->check(CLI::Range(1, 100000));
  sub->add_option("--data", flags->data,
                  "Score the labelled bubble frames of this dataset (ours or your own) instead "
                  "of fresh simulated contacts: the frames of --split whose tool the generator "
                  "knows, each label the truth");
  sub->add_option("--split", flags->split, "With --data: train, test (default) or all");
  sub->add_flag("--allow-other-frames", flags->allow_other_frames,
                "With --data: run even when its frames (size, channels, sensor description) "
                "are not those the model's trunk was trained on (a warning instead of an error)");
  AddDatasetFlags(sub, &flags->dataset);
  sub->add_option("--seed", flags->seed,
                  "Contact seed (default 0x5eed0000, which no training data uses)");
  sub->add_option("--sigma-inflation", flags->sigma_inflation,
                  "Override the generator's calibrated sigma inflation (0 = stored)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--weight-temperature", flags->weight_temperature,
                  "Override the generator's calibrated temperature of the mode weights "
                  "(0 = stored; 1 = the Laplace evidences as they are)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--max-pixels", flags->max_pixels,
                  "Pixels per trunk pass (default " + std::to_string(flags->max_pixels) + ")")
      ->check(CLI::Range(0, 1 << 20));
  sub->add_option("--contact-share", flags->contact_share,
                  "Share of each pass's pixels drawn towards the contact, importance-weighted "
                  "(default " + FormatFixed(GeneratorPosterior::Options().problem.contact_share, 2) +
                      "; 0 = evenly spaced)")
      ->check(CLI::Range(0.0, 1.0));
  sub->add_option("--refined-starts", flags->refined_starts,
                  "Best distinct starts refined per tool (default " +
                      std::to_string(PoseFitOptions().max_refined_starts) + ")")
      ->check(CLI::Range(1, 100));
  sub->add_option("--iterations", flags->iterations,
                  "Levenberg-Marquardt iterations per start (default " +
                      std::to_string(PoseFitOptions().max_iterations) + ")")
      ->check(CLI::Range(1, 1000));
  sub->add_option("--knn-k", flags->knn_k,
                  "k-NN starts per tool (default " + std::to_string(flags->knn_k) + ")")
      ->check(CLI::Range(0, 1000));
  sub->add_option("--yaw-grid", flags->yaw_grid,
                  "Yaws per start position over the full turn (default " +
                      std::to_string(flags->yaw_grid) + "; 1 = none)")
      ->check(CLI::Range(1, 360));
  sub->add_option("--coarse-pixels", flags->coarse_pixels,
                  "Pixels of the coarse stage (start scoring and first refinement; default " +
                      std::to_string(flags->coarse_pixels) + ", 0 = none)")
      ->check(CLI::Range(0, 1 << 20));
  sub->add_option("--tool-screen", flags->tool_screen,
                  "With --unknown-tool and pruning: screen the tools first by a coarse stage "
                  "without the position and yaw grids, pruned by the same ratio (default " +
                      std::string(flags->tool_screen ? "true" : "false") + ")");
  sub->add_option("--tool-prune-ratio", flags->tool_prune_ratio,
                  "With --unknown-tool: tools whose best cost after the coarse stage exceeds R "
                  "times the best tool's are not refined further (default " +
                      FormatFixed(flags->tool_prune_ratio, 1) +
                      "; 0 = every tool refined, else >= 1)")
      ->check(CLI::Range(0.0, 1e12))
      ->check([](const std::string& v) {
        char* end = nullptr;
        const double r = std::strtod(v.c_str(), &end);
        const bool ok = end != v.c_str() && (r == 0 || r >= 1);
        return ok ? std::string() : "the ratio must be 0 (off) or >= 1, got " + v;
      });
  sub->add_option("--final-pixels", flags->final_pixels,
                  "Pixels of a final stage that refines every distinct mode again and takes its "
                  "Laplace approximation there (all valid pixels when the frame has fewer; 0 = "
                  "none; default: the stage the generator was calibrated with, as `info` shows)")
      ->check(CLI::Range(0, 1 << 20));
  sub->add_option("--position-grid", flags->position_grid_mm,
                  "Spacing (mm) of the shifted copies of the first start (default " +
                      FormatFixed(flags->position_grid_mm, 1) + ", 0 = none)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--position-rings", flags->position_rings,
                  "Rings of shifted copies of the first start (default " +
                      std::to_string(flags->position_rings) + ": a " +
                      std::to_string(2 * flags->position_rings + 1) + " x " +
                      std::to_string(2 * flags->position_rings + 1) + " grid)")
      ->check(CLI::Range(0, 10));
  sub->add_option("--coarse-starts", flags->coarse_starts,
                  "Starts refined in the coarse stage per tool (default " +
                      std::to_string(PoseFitOptions().coarse_refined_starts) + ")")
      ->check(CLI::Range(1, 1000));
  sub->add_option("--coarse-iterations", flags->coarse_iterations,
                  "Levenberg-Marquardt iterations in the coarse stage (default " +
                      std::to_string(PoseFitOptions().coarse_iterations) + ")")
      ->check(CLI::Range(1, 1000));
  sub->add_flag("--unknown-tool", flags->unknown_tool, "Fit every tool and identify it");
  sub->add_flag(
      "--information", flags->information,
      "Also each contact's Cramer-Rao bound on its pose and depth from the simulator's "
      "frames and noise (the floor under any unbiased estimator's error), and for every "
      "wrong mode whether the frame itself prefers the truth's basin (about 10 ms more per "
      "contact)");
  sub->add_option("--picture", flags->picture,
                  "With --information: a PNG of each contact's mode error against its bound "
                  "(position and yaw), written atomically")
      ->needs("--information");
  sub->add_flag("--diagnose", flags->diagnose,
                "For every contact whose mode is > 5 deg or > 1 mm off: the objective at the "
                "mode, at the truth and at the truth refined (search or model failure), and "
                "over the whole frame at the mode, at the truth and at the trunk's own best "
                "latent (what the generator falls short of the trunk by)");
  sub->add_option("--diagnose-picture", flags->diagnose_picture,
                  "With --diagnose: a PNG of the first 6 wrong modes, each frame beside the "
                  "trunk's own best latent, the generator's renderings at the truth and at "
                  "the mode and their errors, written atomically")
      ->needs("--diagnose");
  sub->add_option("--contacts-csv", flags->contacts_csv,
                  "Write one CSV row per contact (truth, mode, posterior mean, errors, the "
                  "mode's weight; mm and degrees) to this file (atomically)");
  sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
  sub->callback([flags, selected, per_tool]() {
    flags->contacts_per_tool_given = per_tool->count() > 0;
    *selected = [flags]() { RunEvalGenerator(*flags); };
  });
}

}  // namespace tactfunc::apps
