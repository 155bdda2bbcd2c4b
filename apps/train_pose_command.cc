// Copyright 2026 The tactfunc Authors.
//
// tactfunc train-pose: the downstream pose regressor g_phi of "Tactile Functasets"
// (Sec. III-D, IV-C; models/pose/pose_mlp.h) trained on a functaset's latents:
//
//   tactfunc train-pose --functaset F.tfs --out P.tpm [--sensor bubble] [--hidden 512,512,512]
//       [--epochs 100] [--batch 256] [--lr 1e-3] [--seed 0] [--json]
//
// Inputs: the labelled TRAIN-split entries of one sensor (latent -> x, y, yaw); each
// sample's symmetry order n is its tool's (models/simulator/tool.h; an unknown tool name gets
// n = 1, i.e. its yaw is taken as is, with a warning). Reports position RMSE (mm, the
// root of the mean squared Euclidean error) and yaw RMSE (deg, modulo the tool's
// symmetry, YawErrorModuloSymmetry; hemisphere samples, n = 0, have no observable yaw and
// are left out of the yaw figures) on the train and test splits, overall and per tool,
// as a table. Writes P atomically (PoseMlp::Save) with its PoseModelProvenance as the
// info (models/pose/pose_model_provenance.h): the sensor, the functaset, its model
// checksum, the latent map and the figures, so that `tactfunc pose` can check it is
// given a matching model.
//
// --refit STRATEGY --model M --data D (decision): the functaset stores meta-SGD latents
// z_K, but the sgld / laplace posteriors are centred on the MAP fit z* (ceres:10); a
// g_phi trained on z_K is ~6 mm off at z* on the 12-tool bubble data (docs/CLI.md,
// "Latent maps"). --refit re-fits every labelled latent (train and test) with the
// posteriors' fit settings and trains and evaluates on those (RefitLatents,
// estimation/functaset/latent_refit.h; a progress bar, or progress lines where none is
// drawn). Ctrl-C stops the refit after the block in hand, keeps what it fitted in
// OUT.refit.ckpt and exits 130; --resume continues from it. Ctrl-C during the MLP's
// epochs exits 130 too, the complete refit kept; the MLP then trains again from its
// first epoch (deterministic: the same model). The checkpoint is removed once OUT is
// written.
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <numeric>
#include <random>
#include <set>

#include "CLI/CLI.hpp"
#include "apps/command.h"
#include "apps/dataset_flags.h"
#include "apps/interrupt.h"
#include "apps/model_inputs.h"
#include "apps/output_paths.h"
#include "apps/progress_bar.h"
#include "estimation/evaluation/baselines.h"
#include "estimation/data/dataset.h"
#include "estimation/functaset/functaset.h"
#include "estimation/functaset/latent_refit.h"
#include "estimation/fitting/latent_fitter.h"
#include "models/trunk/functa_model.h"
#include "estimation/posterior/pose_posterior.h"
#include "models/pose/pose_mlp.h"
#include "models/pose/pose_model_provenance.h"
#include "models/simulator/tool.h"

namespace tactfunc::apps {
namespace {

struct TrainPoseFlags {
  std::string functaset;
  std::string out;
  std::string sensor;
  std::string hidden = "512,512,512";
  int epochs = 100;
  int batch = 256;
  double lr = 1e-3;
  double weight_decay = 0;
  std::uint64_t seed = 0;
  std::string refit;  // "" or a LatentFitter strategy: re-fit every latent from --data
  std::string model;
  std::string data;
  DatasetFlags dataset;  // data without metadata (a video, a user's folder), for --refit
  double calibration_fraction = 0.1;
  std::string exclude_tools;      // left out of training and calibration (held-out tools)
  std::string calibration_tools;  // calibrate on these tools instead of a random fraction
  int threads = 0;
  double posterior_sigma = 0;
  double refit_sigma = 0;  // 0 = the trunk's residual_sigma
  bool resume = false;     // continue the refit from OUT.refit.ckpt
  bool json = false;
};

// The refit's checkpoint, beside the output.
std::string RefitCheckpoint(const std::string& out) { return CheckpointBeside(out, "refit"); }

// Labelled entries of one split as training data.
struct Samples {
  Eigen::MatrixXf inputs;  // M x d
  PoseTargets targets;
  std::vector<std::string> tools;
};

Samples Collect(const Functaset& functaset, SensorKind sensor, Split split,
                std::set<std::string>* unknown_tools) {
  std::vector<const FunctasetEntry*> chosen;
  for (const FunctasetEntry& e : functaset.entries(sensor)) {
    if (e.split == split && e.label.has_value()) chosen.push_back(&e);
  }
  Samples s;
  const int m = static_cast<int>(chosen.size());
  s.inputs.resize(m, functaset.latent_dim(sensor));
  s.targets.poses.resize(m, 3);
  s.targets.symmetry_orders.resize(m);
  for (int i = 0; i < m; ++i) {
    const FunctasetEntry& e = *chosen[i];
    s.inputs.row(i) = e.latent.transpose();
    const SE2d& pose = e.label->sensor_T_object;
    s.targets.poses.row(i) << pose.x(), pose.y(), pose.yaw();
    bool known = false;
    s.targets.symmetry_orders[i] = functaset.ToolSymmetryOrder(e.label->tool, &known);
    if (!known) unknown_tools->insert(e.label->tool);
    s.tools.push_back(e.label->tool);
  }
  return s;
}

using ErrorSums = PoseErrors;  // estimation/evaluation/baselines.h: the one pose scoring of tactfunc

// Per tool ("" = all) errors of the model on `samples` (ScorePoses, as `eval` scores).
std::map<std::string, ErrorSums> Evaluate(const PoseMlp& model, const Samples& samples) {
  std::map<std::string, ErrorSums> sums;
  const Eigen::Index m = samples.inputs.rows();
  if (m == 0) return sums;
  const Eigen::MatrixXd predicted =
      PredictPoses(model, samples.inputs, samples.targets.symmetry_orders);
  std::map<std::string, std::vector<Eigen::Index>> groups;
  for (Eigen::Index i = 0; i < m; ++i) {
    groups[""].push_back(i);
    groups[samples.tools[i]].push_back(i);
  }
  for (const auto& [key, rows] : groups) {
    const Eigen::Index k = static_cast<Eigen::Index>(rows.size());
    Eigen::MatrixXd p(k, 3), t(k, 3);
    Eigen::VectorXi n(k);
    for (Eigen::Index j = 0; j < k; ++j) {
      p.row(j) = predicted.row(rows[j]);
      t.row(j) = samples.targets.poses.row(rows[j]);
      n[j] = samples.targets.symmetry_orders[rows[j]];
    }
    sums[key] = ScorePoses(p, t, n);
  }
  return sums;
}

void CheckToolName(const std::string& tool, const char* flag) {
  bool known = false;
  SymmetryOrderOfTool(tool, &known);
  if (!known) {
    throw UsageError(std::string(flag) + ": unknown tool '" + tool +
                     "' (tactfunc info --tools lists them)");
  }
}

std::string Cell(double v, int width, int digits) {
  char buffer[32];
  if (std::isfinite(v)) {
    std::snprintf(buffer, sizeof(buffer), "%*.*f", width, digits, v);
  } else {
    std::snprintf(buffer, sizeof(buffer), "%*s", width, "-");
  }
  return buffer;
}

void RunTrainPose(const TrainPoseFlags& flags) {
  const std::vector<int> hidden = ParsePositiveIntList(flags.hidden, "--hidden", "layer widths");
  PoseMlpTrainingOptions training;
  training.epochs = flags.epochs;
  training.batch_size = flags.batch;
  training.learning_rate = flags.lr;
  training.weight_decay = flags.weight_decay;
  training.seed = flags.seed;
  std::string error;
  if (!training.IsValid(&error)) throw UsageError(error);

  const std::vector<NamedPath> outputs = {{"--out", flags.out},
                                          {"--out's checkpoint", RefitCheckpoint(flags.out)}};
  std::vector<NamedPath> inputs = {{"--functaset", flags.functaset}, {"--model", flags.model}};
  if (!flags.data.empty()) {
    const std::vector<NamedPath> data = DatasetPathInputs("--data", flags.data, flags.dataset);
    inputs.insert(inputs.end(), data.begin(), data.end());
  }
  RefuseOutputsThatAreInputs(outputs, inputs);
  // Ctrl-C stops the refit after the block of latents in hand (its checkpoint is kept
  // for --resume) or the MLP training after its epoch.
  const InterruptScope interrupt_scope;
  const Functaset functaset = Functaset::Load(flags.functaset);
  SensorKind sensor;
  if (!ParseSensorFlag(flags.sensor, &sensor)) {
    const std::vector<SensorKind> sensors = functaset.sensors();
    if (sensors.empty()) throw DatasetError("--functaset '" + flags.functaset + "' has no sensors");
    // The bubble if present (the paper's headline sensor), else the only one.
    sensor = functaset.has_sensor(SensorKind::kSoftBubble) ? SensorKind::kSoftBubble : sensors[0];
    if (sensors.size() > 1) {
      std::cerr << "train-pose: note: the functaset has several sensors; training on "
                << ToString(sensor) << " (give --sensor to choose)\n";
    }
  } else if (!functaset.has_sensor(sensor)) {
    throw DatasetError("--functaset '" + flags.functaset + "' has no " + ToString(sensor) +
                       " latents (--sensor " + flags.sensor + ")");
  }
  Functaset refitted;
  const Functaset* source = &functaset;
  if (!flags.refit.empty()) {
    // Latents re-fitted with the posterior's fit settings (PosePosterior::Options::fit
    // on its latent problem, Options::problem), so that g_phi is trained on the latent map
    // the sgld / laplace posteriors are centred on (docs/CLI.md, "Latent maps").
    // The fit's sigma is the trunk's residual_sigma (unless --refit-sigma) even when
    // --posterior-sigma gives the posteriors a smaller one: sigma only weighs the pixels
    // against the N(0, sigma_z^2) prior, which thousands of pixels outweigh at either
    // value. Refitting at the posterior sigma (0.002 instead of 0.0088) was measured and
    // not kept: the coverage moved by noise-level amounts and the held-out tools' fell
    // just below its band (docs/POSES.md, "Calibration").
    if (flags.model.empty() || flags.data.empty()) {
      throw UsageError("--refit needs --model and --data (the frames to re-fit)");
    }
    const FunctaModel model = FunctaModel::Load(flags.model);
    functaset.CheckModel(model, flags.model, flags.functaset);
    const Dataset dataset = OpenDataset(flags.data, flags.dataset);
    RefuseOutputsThatAreInputs(outputs, DatasetFileInputs("--data", dataset));
    const PosePosterior::Options posterior_options;
    LatentFitter::Options fit = posterior_options.fit;
    LatentProblem::Options problem_options = posterior_options.problem;
    if (flags.refit_sigma > 0) problem_options.sigma = flags.refit_sigma;
    if (!FitStrategy::Parse(flags.refit, &fit.strategy, &error) || fit.strategy.knn) {
      throw UsageError("--refit: expected meta_sgd:K or ceres:N, got '" + flags.refit + "'");
    }
    const SensorTrunk& trunk = model.Trunk(sensor);
    if (trunk.photometric != nullptr) {
      throw UsageError("--refit: the " + std::string(ToString(sensor)) + " trunk of '" +
                       flags.model + "' is photometric; its latents are encode's fits, which "
                       "the functaset already holds (train without --refit, or encode again "
                       "with another --strategy)");
    }
    RefitOptions refit;
    refit.fit = fit;
    refit.problem = problem_options;
    refit.threads = ResolveThreads(flags.threads);
    refit.model_checksum = model.checksum();
    refit.checkpoint_path = RefitCheckpoint(flags.out);
    refit.resume = flags.resume;
    RefitSummary refit_summary;
    {
      ProgressBar bar("train-pose refit", functaset.entries(sensor).size(), "latents",
                      ProgressBar::Lines::kWhenNotDrawn);
      try {
        refitted = RefitLatents(functaset, sensor, dataset, trunk, refit, &refit_summary,
                                [&](int done, int) {
                                  bar.Tick(done - bar.done());
                                  return !InterruptScope::Requested();
                                });
      } catch (const DatasetError& e) {
        throw DatasetError("--data '" + flags.data + "': " + e.what());
      }
      bar.Finish();
    }
    if (refit_summary.stopped) {
      std::cerr << "train-pose: interrupted after re-fitting " << refit_summary.done << " of "
                << refit_summary.entries << " latents; checkpoint " << refit.checkpoint_path
                << ".\ntrain-pose: to continue, run the same command with --resume\n";
      ExitInterrupted();
    }
    std::cout << "train-pose: re-fitted " << refit_summary.entries << " latents with "
              << flags.refit << " in " << refit_summary.seconds << " s";
    if (refit_summary.resumed > 0) {
      std::cout << " (" << refit_summary.resumed << " taken from " << refit.checkpoint_path
                << ")";
    }
    std::cout << "\n";
    source = &refitted;
  }
  std::set<std::string> unknown_tools;
  Samples train = Collect(*source, sensor, Split::kTrain, &unknown_tools);
  const Samples test = Collect(*source, sensor, Split::kTest, &unknown_tools);
  // Calibration contacts (decision, docs/POSES.md "Calibration"): a seeded random
  // fraction of the train split (or the train contacts of --calibration-tools) is held
  // out of the MLP's training; its residuals, stored in the pose model, are the
  // regressor error the posteriors add to their samples. --exclude-tools drop tools
  // from training and calibration (they stay in the test figures).
  Samples calibration;
  {
    const std::vector<std::string> excluded = SplitList(flags.exclude_tools);
    const std::vector<std::string> calibration_tools = SplitList(flags.calibration_tools);
    for (const std::string& tool : excluded) CheckToolName(tool, "--exclude-tools");
    for (const std::string& tool : calibration_tools) CheckToolName(tool, "--calibration-tools");
    auto in = [](const std::vector<std::string>& list, const std::string& tool) {
      return std::find(list.begin(), list.end(), tool) != list.end();
    };
    auto take = [&](const Samples& from, const std::vector<int>& rows) {
      Samples s;
      const int k = static_cast<int>(rows.size());
      s.inputs.resize(k, from.inputs.cols());
      s.targets.poses.resize(k, 3);
      s.targets.symmetry_orders.resize(k);
      for (int i = 0; i < k; ++i) {
        s.inputs.row(i) = from.inputs.row(rows[i]);
        s.targets.poses.row(i) = from.targets.poses.row(rows[i]);
        s.targets.symmetry_orders[i] = from.targets.symmetry_orders[rows[i]];
        s.tools.push_back(from.tools[rows[i]]);
      }
      return s;
    };
    std::vector<int> fit_rows, calibration_rows;
    for (int i = 0; i < static_cast<int>(train.tools.size()); ++i) {
      if (in(excluded, train.tools[i])) continue;
      (in(calibration_tools, train.tools[i]) ? calibration_rows : fit_rows).push_back(i);
    }
    if (calibration_tools.empty()) {
      // A seeded random fraction of the training contacts.
      std::mt19937_64 engine(flags.seed ^ 0x63616c6962ull);  // "calib"
      std::shuffle(fit_rows.begin(), fit_rows.end(), engine);
      const std::size_t held =
          static_cast<std::size_t>(std::floor(flags.calibration_fraction * fit_rows.size()));
      if (held < fit_rows.size()) {
        calibration_rows.assign(fit_rows.end() - held, fit_rows.end());
        fit_rows.resize(fit_rows.size() - held);
        std::sort(fit_rows.begin(), fit_rows.end());
      }
    }
    calibration = take(train, calibration_rows);
    train = take(train, fit_rows);
    if (!excluded.empty()) {
      std::cout << "train-pose: tools held out of training and calibration: "
                << flags.exclude_tools << "\n";
    }
  }
  if (train.inputs.rows() == 0) {
    throw DatasetError("--functaset '" + flags.functaset + "' has no labelled train-split " +
                       ToString(sensor) + " entries to train on");
  }
  for (const std::string& tool : unknown_tools) {
    std::cerr << "train-pose: warning: unknown tool '" << tool
              << "': symmetry order 1 assumed (yaw regressed as is)\n";
  }

  PoseMlp::Options options;
  options.input_dim = functaset.latent_dim(sensor);
  options.hidden_sizes = hidden;
  if (!options.IsValid(&error)) throw UsageError(error);
  PoseMlp model(options, flags.seed);
  std::cout << "train-pose: " << ToString(sensor) << ", " << train.inputs.rows() << " train / "
            << test.inputs.rows() << " test latents of dimension " << options.input_dim
            << ", hidden " << flags.hidden << ", " << model.NumParameters() << " parameters\n";
  const int report_every = std::max(1, flags.epochs / 10);
  const PoseMlpTrainingSummary summary = TrainPoseMlp(
      &model, train.inputs, train.targets, training, [&](int epoch, double loss) {
        if ((epoch + 1) % report_every == 0 || epoch + 1 == flags.epochs) {
          std::cerr << "train-pose: epoch " << epoch + 1 << "/" << flags.epochs << " loss " << loss
                    << "\n";
        }
        return !InterruptScope::Requested();
      });
  std::cout << summary.BriefReport() << "\n";
  if (summary.termination == PoseMlpTrainingTermination::kUserRequested) {
    std::cerr << "train-pose: interrupted after " << summary.epochs_completed << " of "
              << flags.epochs << " epochs; nothing was written";
    if (!flags.refit.empty()) {
      std::cerr << ". The re-fitted latents are kept in " << RefitCheckpoint(flags.out)
                << ":\ntrain-pose: the same command with --resume takes them and trains the "
                   "MLP again from its first epoch (the same model as a run never stopped)";
    }
    std::cerr << "\n";
    ExitInterrupted();
  }
  if (summary.termination == PoseMlpTrainingTermination::kNonFinite) {
    throw std::runtime_error(
        "training diverged (" + summary.message + "); try a smaller --lr. Nothing was written" +
        (flags.refit.empty() ? std::string(".")
                             : "; the re-fitted latents are kept in " + RefitCheckpoint(flags.out) +
                                   ", which --resume takes."));
  }

  if (calibration.inputs.rows() > 0) {
    model.SetCalibrationResiduals(
        CalibrationResiduals(model, calibration.inputs, calibration.targets));
  }
  const std::map<std::string, ErrorSums> calibration_errors = Evaluate(model, calibration);
  const std::map<std::string, ErrorSums> train_errors = Evaluate(model, train);
  const std::map<std::string, ErrorSums> test_errors = Evaluate(model, test);
  std::set<std::string> tools;
  for (const auto& [tool, sums] : train_errors) tools.insert(tool);
  for (const auto& [tool, sums] : test_errors) tools.insert(tool);
  tools.erase("");
  const ErrorSums none;
  auto get = [&](const std::map<std::string, ErrorSums>& m, const std::string& key) {
    const auto it = m.find(key);
    return it == m.end() ? none : it->second;
  };

  std::printf("%-16s %2s | %6s %8s %8s | %6s %8s %8s\n", "tool", "n", "train", "mm", "deg", "test",
              "mm", "deg");
  nlohmann::json per_tool = nlohmann::json::object();
  auto row = [&](const std::string& name, const std::string& key, const std::string& n) {
    const ErrorSums a = get(train_errors, key), b = get(test_errors, key);
    std::printf("%-16s %2s | %6d %s %s | %6d %s %s\n", name.c_str(), n.c_str(), a.count,
                Cell(a.RmseMm(), 8, 3).c_str(), Cell(a.RmseDeg(), 8, 2).c_str(), b.count,
                Cell(b.RmseMm(), 8, 3).c_str(), Cell(b.RmseDeg(), 8, 2).c_str());
  };
  for (const std::string& tool : tools) {
    bool known = false;
    const int n = source->ToolSymmetryOrder(tool, &known);
    row(tool, tool, known ? std::to_string(n) : "?");
    const ErrorSums a = get(train_errors, tool), b = get(test_errors, tool);
    per_tool[tool] = {
        {"symmetry_order", n},
        {"count", {{"train", a.count}, {"test", b.count}}},
        {"rmse_mm", {{"train", NumberOrNull(a.RmseMm())}, {"test", NumberOrNull(b.RmseMm())}}},
        {"rmse_deg", {{"train", NumberOrNull(a.RmseDeg())}, {"test", NumberOrNull(b.RmseDeg())}}}};
  }
  row(std::string("all (") + ToString(sensor) + ")", "", "");
  if (calibration.inputs.rows() > 0) {
    const ErrorSums c = get(calibration_errors, "");
    std::printf("%-19s | %6d %s %s   (held out of training; their residuals are stored)\n",
                "calibration", c.count, Cell(c.RmseMm(), 8, 3).c_str(),
                Cell(c.RmseDeg(), 8, 2).c_str());
  }
  std::cout << "(position RMSE in mm; yaw RMSE in degrees modulo each tool's symmetry order n, "
               "n = 0 (no observable yaw) left out)\n";
  const ErrorSums all_train = get(train_errors, ""), all_test = get(test_errors, "");

  const nlohmann::json figures = {
      {"rmse_mm",
       {{"train", NumberOrNull(all_train.RmseMm())}, {"test", NumberOrNull(all_test.RmseMm())}}},
      {"rmse_deg",
       {{"train", NumberOrNull(all_train.RmseDeg())}, {"test", NumberOrNull(all_test.RmseDeg())}}}};
  // The latent map the MLP was trained on: what the posteriors must centre on
  // (LatentMapOfPoseModel, estimation/posterior/pose_posterior.h).
  // Without --refit, the functaset's own strategy as encode recorded it ("functaset",
  // the trunk's K meta-SGD steps, for a functaset that records none).
  const std::string latent_map =
      !flags.refit.empty() ? flags.refit
      : functaset.fit_strategy(sensor).empty() ? std::string("functaset")
                                               : functaset.fit_strategy(sensor);
  PoseModelProvenance provenance;
  provenance.sensor = ToString(sensor);
  provenance.functaset = flags.functaset;
  provenance.model_checksum = functaset.model_checksum();
  provenance.train_samples = train.inputs.rows();
  provenance.latents = flags.refit.empty() ? "functaset" : "refit " + flags.refit;
  provenance.latent_map = latent_map;
  provenance.calibration_samples = calibration.inputs.rows();
  provenance.posterior_sigma = flags.posterior_sigma;
  provenance.refit_sigma = flags.refit_sigma;
  provenance.calibration_tools = flags.calibration_tools;
  provenance.excluded_tools = flags.exclude_tools;
  provenance.epochs = summary.epochs_completed;
  provenance.batch = flags.batch;
  provenance.learning_rate = flags.lr;
  provenance.seed = flags.seed;
  provenance.final_loss = summary.final_loss;
  provenance.termination = ToString(summary.termination);
  provenance.rmse_mm = {all_train.RmseMm(), all_test.RmseMm()};
  provenance.rmse_deg = {all_train.RmseDeg(), all_test.RmseDeg()};
  model.set_info_json(provenance.ToJson());
  model.Save(flags.out);  // atomic
  std::cout << "train-pose: wrote " << flags.out << " in "
            << summary.total_time_in_seconds << " s of training\n";
  std::error_code ignored;  // the model is written; a checkpoint left behind is harmless
  std::filesystem::remove(RefitCheckpoint(flags.out), ignored);

  if (flags.json) {
    nlohmann::json j = {{"sensor", ToString(sensor)}};
    j.update(figures);
    j["per_tool"] = per_tool;
    j["out"] = flags.out;
    j["epochs"] = summary.epochs_completed;
    j["final_loss"] = NumberOrNull(summary.final_loss);
    j["seconds"] = summary.total_time_in_seconds;
    EmitJson(j);
  }
}

}  // namespace

void RegisterTrainPose(CLI::App& app, CommandBody* selected) {
  auto flags = std::make_shared<TrainPoseFlags>();
  CLI::App* sub = app.add_subcommand(
      "train-pose",
      "Train the pose MLP (latent -> x, y, yaw) on a functaset's labelled train-split latents "
      "of one sensor; prints train/test RMSE per tool and writes the pose model.");
  sub->add_option("--functaset", flags->functaset, "Functaset (.tfs) from `tactfunc encode`")
      ->required();
  sub->add_option("--out", flags->out, "Pose model file to write (atomically)")->required();
  sub->add_option("--sensor", flags->sensor,
                  "bubble or gelslim; default: bubble if the functaset has it, else its sensor");
  sub->add_option("--hidden", flags->hidden,
                  "Hidden ReLU layer widths, comma-separated (default 512,512,512, the paper's)");
  sub->add_option("--epochs", flags->epochs, "Passes over the training set (default 100)")
      ->check(CLI::Range(1, 1000000));
  sub->add_option("--batch", flags->batch, "Samples per Adam step (default 256)")
      ->check(CLI::Range(1, 1 << 24));
  sub->add_option("--lr", flags->lr, "Adam step size (default 1e-3)")->check(CLI::PositiveNumber);
  sub->add_option("--weight-decay", flags->weight_decay,
                  "Decoupled (AdamW) weight decay per step (default 0)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--seed", flags->seed, "Seed of the initialisation and shuffles (default 0)");
  sub->add_option("--refit", flags->refit,
                  "Train on latents re-fitted from --data with this strategy (e.g. ceres:10, the "
                  "pose posteriors' fit) instead of the functaset's meta-SGD latents");
  sub->add_option("--refit-sigma", flags->refit_sigma,
                  "Pixel sigma of the --refit fits (default: the trunk's residual_sigma; it "
                  "weighs the pixels against the latent prior; docs/POSES.md, Calibration)")
      ->check(CLI::PositiveNumber);
  sub->add_option("--model", flags->model, "Model (.tfm) of the functaset, for --refit");
  sub->add_option("--data", flags->data, "Dataset of the functaset, for --refit");
  AddDatasetFlags(sub, &flags->dataset, {"--sensor"});
  sub->add_option("--calibration-fraction", flags->calibration_fraction,
                  "Fraction of the train split held out of training whose residuals are stored "
                  "as the model's own error for the posteriors (default 0.1; 0 = none)")
      ->check(CLI::Range(0.0, 0.9));
  sub->add_option("--exclude-tools", flags->exclude_tools,
                  "Comma-separated tools left out of training and calibration (held-out tools; "
                  "their test figures measure generalisation to unseen shapes)");
  sub->add_option("--calibration-tools", flags->calibration_tools,
                  "Calibrate on these tools' train contacts (held out of training) instead of a "
                  "random --calibration-fraction: residuals of shapes the MLP has not seen");
  sub->add_option("--posterior-sigma", flags->posterior_sigma,
                  "Pixel sigma of the sgld/laplace latent posterior to store with the model "
                  "(calibrated: docs/POSES.md, Calibration; default 0 = the trunk's "
                  "residual_sigma)")
      ->check(CLI::NonNegativeNumber);
  sub->add_option("--threads", flags->threads, "Threads of --refit (default: all cores)")
      ->check(CLI::Range(0, 256));
  sub->add_flag("--resume", flags->resume,
                "Continue --refit from the checkpoint OUT.refit.ckpt that an interrupted run "
                "(Ctrl-C, exit 130) left; the options must match it. The MLP's epochs start "
                "again (they take a minute or so); the model is the same as a run never stopped");
  sub->add_flag("--json", flags->json,
                "Print {sensor, rmse_mm, rmse_deg, per_tool, out} as one JSON line");
  sub->callback([flags, selected]() { *selected = [flags]() { RunTrainPose(*flags); }; });
}

}  // namespace tactfunc::apps
