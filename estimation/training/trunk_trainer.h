// Copyright 2026 The tactfunc Authors.
//
// TrunkTrainer: meta-learns one sensor's latent-modulated SIREN trunk (Sec. III-B of
// "Tactile Functasets"; functa, Dupont et al. 2022, Sec. 3; Meta-SGD, Li et al. 2017).
//
// The objective. For a training frame T_i (pixel coordinates x_j, targets y_ij, validity
// weights w_ij) the inner loop fits the frame's latent from zero with K steps of
// per-dimension gradient descent (models/trunk/meta_sgd.h, the paper's Eq. 6 with learned
// rates alpha):
//
//   z_0 = 0,   z_{k+1} = z_k - alpha (*) d/dz [ L(theta, z_k; T_i) + lambda ||z_k||^2 ]
//
// and the outer (meta) loss is the trunk's weighted per-pixel MSE after those K steps,
// averaged over a batch B of frames (the paper's Eq. 5):
//
//   J(theta, alpha) = (1/|B|) sum_{i in B} L(theta, z_K(theta, alpha; T_i); T_i).
//
// Each outer step draws a batch, computes every frame's exact meta-gradient (second
// order through the K inner steps; first order with Options::meta_sgd.first_order),
// averages them and applies one Adam step (Kingma & Ba 2015) to theta and alpha, then
// clips alpha to [0, 1] (as functa clips its meta-SGD rates). After training, the
// trunk's residual_sigma is the RMS per-pixel residual of the K-step fits on up to
// Options::residual_frames training frames.
//
// Precision. theta, alpha and the Adam moments are kept in double (master copies);
// the per-frame meta-gradients are computed in float (LatentModulatedSiren's float
// mirror) and accumulated in double. Measured on the small trunk: float is 2.0x (256
// px) to 3.6x (6160 px) faster than double per frame, and its meta-gradient differs
// from double's by at most 7e-6 relative (2-norm), so float is used throughout.
//
// Determinism. Every random choice is a pure function of (Options::seed, what it is
// for, step or index) through DeriveSeed (models/core/seed.h): the trunk's initial theta and
// alpha, the order in which frames are visited (one seeded permutation of the training
// frames per epoch; a step takes the next batch_size positions), each batch slot's
// random pixel subset, the monitor and residual subsets. The frames of a batch are
// processed by Options::threads workers, each writing its own slot (with
// Options::processes, by several processes, which exchange the slots); the slots are
// summed in slot order. So a run is bit-identical for any thread and process count, and
// a run that is stopped, checkpointed and resumed is bit-identical to one that never
// stopped.
//
// Checkpoints. With Options::checkpoint_path set, a TensorFile (models/core/tensor_file.h)
// of kind "checkpoint" is written atomically every checkpoint_every steps, when the
// callback stops the run, and at the end. It holds theta and alpha (float64), the Adam
// moments, the step, the loss/PSNR history, the seconds spent, the training set's
// fingerprint and every option that shapes the trajectory (see TrajectoryOptionsJson).
// With Options::resume, Train() continues from the checkpoint if one exists (else it
// starts at step 0); it refuses, naming the field, a checkpoint written with different
// trajectory options, for another sensor or for other training frames. Options that do
// not change the result (steps, threads, the checkpoint and monitor settings) may
// differ: resuming with a larger `steps` extends a finished run.
//
// Errors follow the three tiers of docs/STYLE: invalid Options throw
// std::invalid_argument (from the constructor) naming the field; algorithmic outcomes
// (a non-finite loss, a stop request) are reported in the Summary; bad input (no
// training frames, a corrupt or mismatched checkpoint) throws std::runtime_error
// (TensorFileError for an unreadable checkpoint) quoting what was expected and found.
#ifndef TACTFUNC_ESTIMATION_TRAINING_TRUNK_TRAINER_H_
#define TACTFUNC_ESTIMATION_TRAINING_TRUNK_TRAINER_H_

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "estimation/data/contact.h"
#include "estimation/data/trunk_targets.h"
#include "models/trunk/functa_model.h"
#include "models/trunk/latent_modulated_siren.h"
#include "models/trunk/meta_sgd.h"
#include "models/core/process_group.h"
#include "models/core/sensor.h"

namespace tactfunc {

class Dataset;

class TrunkTrainer {
 public:
  struct Options {
    // ---- Trunk (models/trunk/latent_modulated_siren.h) --------------------------------------
    // width, num_hidden_layers, latent_dim, omega_0 (SIREN's 30) and the spatial latent
    // grid (spatial_rows/cols/channels; its values count towards latent_dim) are used as
    // given; output_channels is ignored and set from the frame format (1 for the bubble
    // or grayscale, 3 for RGB GelSlim), readout_rows/cols from `readout` below.
    // Defaults: the "default" preset (see Preset()).
    LatentModulatedSiren::Options siren = DefaultSirenOptions();
    // The linear readout branch (models/trunk/latent_modulated_siren.h): a per-pixel
    // basis and mean at the working resolution, added to the SIREN's output. When set,
    // siren.readout_rows/cols are taken from the frame format, the branch starts as the
    // PCA of the training frames (d components, scaled so that one full-frame meta-SGD
    // step at alpha = 1 from z = 0 lands on the PCA code) and the SIREN's output layer
    // starts at zero, so training starts from exactly that PCA and the SIREN learns
    // what a linear basis cannot. Default false (the trunk of the paper).
    bool readout = false;
    // Training frames the readout's PCA start is computed from (evenly spaced over the
    // split; fewer if it is smaller). >= 1. The PCA is one eigendecomposition of the
    // smaller of the frames' Gram matrix and their values' scatter matrix: 1500 frames
    // of 6160 pixels take about a second, 16,200 about two minutes on one core, and the
    // frames are held in double twice (noisy and noise-free): 16 bytes per value.
    int readout_pca_frames = 1500;
    // The readout branch's Adam step size as a fraction of the trunk's (the schedule
    // applies to both). In [0, 1]; 0 keeps the branch at its PCA start (the SIREN then
    // learns the PCA's residual).
    double readout_learning_rate_scale = 0.0;

    // ---- Training frames ----------------------------------------------------------------
    // The outer loss against each training frame's noise-free copy (a dataset with
    // them: `synth --clean`) while the inner fit sees the noisy frame, as a fit does at
    // test time: the trunk and the rates learn fits that land on the frame without its
    // noise (meta-learned denoising). With `readout` the branch then starts as the PCA
    // of the noise-free copies (the basis of what the outer loss asks for, not of the
    // sensor's noise) and every fit from its projection shrunk by the components'
    // Wiener gains (StartReadoutFromPca). Simulated data only: a recording has no
    // noise-free copy. Default false: the outer loss on the noisy frame, as the paper
    // trains. Measured on the Soft Bubble in docs/REPRESENTATION.md ("Training against the
    // noise-free copies").
    bool outer_loss_on_clean = false;
    // Leave the train split's frames at rest (no contact by DetectContact with `contact`,
    // estimation/data/contact.h) out of training: the trunk's capacity goes to contacts,
    // not to the sensor's noise. At least one contact frame must remain.
    bool skip_frames_at_rest = false;
    ContactOptions contact;

    // ---- Frame format (models/trunk/functa_model.h FrameFormat) -----------------------------
    // Working resolution in pixels (area interpolation). 0 x 0 (default) = the sensor's
    // default: bubble 70 x 88 (half of the 140 x 175 ToF frame), GelSlim 80 x 107 (a
    // quarter of 320 x 427). Both 0 or both > 0.
    int rows = 0;
    int cols = 0;
    // GelSlim RGB -> luma before fitting (one output channel). Default true: the
    // contact is in the shading, and one channel costs a third of three.
    bool grayscale = true;
    // Fixed-scale normalisation: the physical difference (metres of depth, intensity)
    // that maps to 1.0. 0 (default) = the dataset's SensorInfo::normalization_scale
    // (DefaultNormalizationScale if it records none). >= 0.
    double normalization_scale = 0;

    // ---- Inner loop (models/trunk/meta_sgd.h) ---------------------------------------------
    // K = 3 inner steps (paper Sec. IV-A, functa); latent L2 weight lambda = 1e-5 as in
    // the paper's released code (measured: 30.49 dB with and without it, so it does not
    // hurt); exact second-order meta-gradients (first order is ~2.2x cheaper per step
    // and reached about the same PSNR per second; docs/TRAINING.md).
    MetaSgd::Options meta_sgd = DefaultMetaSgdOptions();

    // ---- Outer optimiser: Adam ------------------------------------------------------
    // Step size of theta, in parameter units per step. > 0. functa uses 3e-6 (with a
    // per-pixel mean loss, as ours) for a 15-layer, 512-wide trunk trained 500k steps;
    // Adam's step does not depend on the gradient's scale, so the rate follows the
    // parameters' scale (SIREN's init shrinks as 1 / sqrt(width)) and the run length,
    // and was measured here: 3e-4 best of {3e-5, 1e-4, 3e-4, 1e-3} after 600 steps of
    // the small preset on synthetic bubble data (27.1, 30.5, 32.3, 31.7 dB;
    // docs/TRAINING.md).
    double learning_rate = 3e-4;
    // Cosine decay of the trunk's step size over the run: at step t (1-based) of
    // `steps`, rate = learning_rate (f + (1 - f) (1 + cos(pi (t - 1) / steps)) / 2),
    // f = this fraction, from learning_rate at the first step down towards
    // f learning_rate at the last. In (0, 1]; 1 = constant, as in the paper (the tiny
    // and small presets); default 0.1, the default preset's (measured over three
    // Bubble seeds: +0.28 dB on average and a third of the seed-to-seed spread).
    // With f < 1 the schedule depends on `steps`, which then belongs to the trajectory
    // (a resume must keep it). The rates alpha keep alpha_learning_rate.
    double learning_rate_final_fraction = 0.1;
    // Step size of the meta-SGD rates alpha, per step. > 0. Measured: 1e-3 and 1e-2 give
    // the same PSNR (30.47 vs 30.49 dB), since alpha stays at its upper clip bound 1.
    double alpha_learning_rate = 1e-3;
    // Adam's moment decays, in [0, 1), and epsilon (> 0): Kingma & Ba's defaults.
    double adam_beta1 = 0.9;
    double adam_beta2 = 0.999;
    double adam_epsilon = 1e-8;
    // Initial meta-SGD rates: each alpha_k ~ U(alpha_init_min, alpha_init_max), with
    // 0 <= min <= max <= alpha_max. Default both 1.0, the top of the clip range: with our
    // small trunk the latent gradient is small and the learned rates stay at 1 anyway;
    // functa's U(0.005, 0.1) (chosen for its 15 x 512 trunk) gave 28.1 dB where 1.0
    // gave 30.5 dB after 600 steps (docs/TRAINING.md).
    double alpha_init_min = 1.0;
    double alpha_init_max = 1.0;
    // Upper clip bound of the meta-SGD rates: after each Adam step alpha is clipped to
    // [0, alpha_max]. > 0, and >= alpha_init_max. Default 1: the [0, 1] of functa. The
    // rates sit at 1 in every run, so the bound binds; lifting it (with alpha_init
    // above 1) measured +0.4 dB on the GelSlim at 2000 steps
    // (docs/RESULTS_RECONSTRUCTION.md), an experiment knob, not the default.
    double alpha_max = 1.0;

    // ---- Batches --------------------------------------------------------------------
    // Frames per outer step. >= 1. Cost is linear in it. Default: the default preset's.
    int batch_size = 32;
    // Random pixels per frame per step (the inner fit and the outer loss both see only
    // them; a fresh subset each step). 0 = every pixel. >= 0. Cost is linear in it
    // (small trunk, float: 1.4 ms per frame at 256 px, 5.9 at 1024, 38.7 at all 6160,
    // one core), while PSNR per step drops only a little, so at equal compute fewer
    // pixels and more steps won: 256 px x 2400 steps 33.6 dB, 1024 x 600 32.3 dB, all
    // 6160 x 100 25.9 dB (small trunk, bubble; docs/TRAINING.md).
    int pixels_per_frame = 512;
    // Outer steps to run (in total, counting steps done before a resume). >= 0.
    // Default: the default preset's (about 10 minutes for a Bubble trunk on 2 cores).
    int steps = 16000;
    // Seed of every random choice (see Determinism above).
    std::uint64_t seed = 0;
    // Worker threads for per-frame gradients, loading and evaluation. In [1, 256].
    // Does not change the result.
    int threads = 1;

    // ---- Checkpoints ----------------------------------------------------------------
    // TensorFile written atomically; "" = none. The folder must exist.
    std::string checkpoint_path;
    // Write a checkpoint every N steps (and always at the end or on a stop). >= 0;
    // 0 = only at the end or on a stop.
    int checkpoint_every = 500;
    // Continue from checkpoint_path if it exists (see Checkpoints above).
    bool resume = false;

    // ---- Processes (data parallelism; docs/SCALING.md) -------------------------------
    // The processes sharing this run (models/core/process_group.h); null = this process
    // alone. Every process calls Train with the same frames and options; each computes
    // a contiguous share of every batch's slots (ProcessGroup::Share), the slots' float
    // results are gathered to every process, and each sums them in slot order as one
    // process does: the trajectory and the model are bit-identical for any process and
    // thread count (on processors that compute floats alike). Only rank 0 writes
    // checkpoints; with resume every process reads the one at checkpoint_path, which
    // must therefore be on a file system they share. Does not change the result.
    const ProcessGroup* processes = nullptr;

    // ---- Monitoring -----------------------------------------------------------------
    // Evaluate the monitor subset every N steps (and at the start and end): mean PSNR
    // (estimation/data/trunk_targets.h) after the K-step fit and at z = 0, over full frames.
    // >= 1.
    int monitor_every = 250;
    // Training frames in the fixed monitor subset (fewer if the split is smaller). >= 1.
    int monitor_frames = 16;
    // Training frames used for residual_sigma at the end (fewer if the split is
    // smaller). >= 1.
    int residual_frames = 200;
    // Stop as diverged (TerminationType::kDiverged) when a monitor point's PSNR after
    // K steps falls this many dB below the best point of the history so far; 0 =
    // never. A SIREN trunk whose learning rate is too high for its size does not come
    // back: width 256 at the presets' 3e-4 went 24.7 -> 12.1 -> 9.3 dB over 700 steps,
    // 6 layers 23.4 -> 14.5 dB (docs/TRAINING.md), while a healthy run's monitor PSNR
    // wavers by tenths of a dB. Finite and >= 0; like the monitor settings it does
    // not change a run that does not diverge.
    double divergence_drop_db = 6.0;

    // True if every field is in range; otherwise false and *error names the field.
    bool IsValid(std::string* error) const;

    static LatentModulatedSiren::Options DefaultSirenOptions();
    static MetaSgd::Options DefaultMetaSgdOptions();
  };

  // Named starting points, sized by measurement ("model only what a scene requires";
  // the sweep and the figures are in docs/RESULTS_RECONSTRUCTION.md). Each preset may
  // size the trunk per sensor, since the scenes differ: a Bubble dent is smooth, a
  // GelSlim frame is thin shading ridges and markers that a wider trunk barely helps.
  //   tiny:    width 32, 2 layers, d = 16, 16 x 20 pixels, batch 4, 300 steps
  //            -- tests and CI, a few seconds.
  //   small:   width 64, 3 layers, d = 64, the sensor's working resolution, batch 32,
  //            512 pixels per frame, 4000 steps -- the committed pretrained trunk
  //            (models/pretrained/default.tfm, scripts/train_pretrained.sh): fast
  //            enough for the pose posteriors' latency targets; 10 minutes for both
  //            sensors on 2 cores.
  //   default: as small but 16000 steps with a cosine decay of the learning rate to
  //            a tenth, d = 128 for the Bubble and d = 32 for the GelSlim -- the smallest
  //            measured trunks that reach the paper's Bubble PSNR (38 dB in the paper's
  //            convention: 38.69 dB on average over three seeds, 38.49-38.83; 8000
  //            steps gave 37.99) while trunks + float16 latents stay 1000x smaller than
  //            the raw frames. The Bubble's dents gain from a longer latent (a wider
  //            trunk gained nothing); the GelSlim's frames barely do, so its latent is
  //            cut to pay for the Bubble's. About 20 minutes for both on 2 cores.
  //   storage: small's SIREN with the readout branch, d = 256, trained on whole frames
  //            (batch 8) for 1000 steps against their noise-free copies, every fit the
  //            frame's projection shrunk by Wiener gains (readout, readout_pca_frames
  //            20000, meta_sgd.inner_steps 0, outer_loss_on_clean) -- the Soft Bubble's
  //            storage trunk (models/pretrained/bubble_readout.tfm): 3 dB above PCA
  //            codes in the same allocated bytes at 128 and 256 B per frame on six
  //            fresh sets (docs/RESULTS_RECONSTRUCTION.md). Needs noise-free copies
  //            (simulated data); about 4 minutes on one core at 16,200 frames.
  // Options() as constructed is the default preset for the Bubble. Throws
  // std::invalid_argument listing the names for an unknown one.
  static Options Preset(const std::string& name, SensorKind sensor = SensorKind::kSoftBubble);
  static std::vector<std::string> PresetNames();

  // The trunk's Adam step size at outer step `step` (1-based), by the schedule of
  // Options::learning_rate_final_fraction.
  static double LearningRateAt(const Options& options, int step);

  enum class TerminationType {
    kCompleted,      // reached Options::steps
    kUserStopped,    // the step callback asked to stop (checkpoint written)
    kNonFinite,      // a loss or gradient was NaN/inf; the last finite state is kept
    kDiverged,       // the monitor PSNR fell Options::divergence_drop_db below its best;
                     // the parameters of the step that showed it are kept
  };

  // One point of the training curve (at the start, every monitor_every steps, the end).
  struct HistoryPoint {
    int step = 0;
    double loss = 0;              // mean outer loss of the steps since the last point
                                  // (at step 0: the monitor subset's loss after K steps)
    double psnr = 0;              // monitor subset, mean PSNR after K steps, dB
    double psnr_at_zero = 0;      // monitor subset, mean PSNR at z = 0 (the trunk alone)
    double seconds = 0;           // training seconds so far (all runs)
  };

  // What the step callback sees after every outer step.
  struct StepReport {
    int step = 0;           // steps completed
    int total_steps = 0;    // Options::steps
    double loss = 0;        // this step's batch mean outer loss
    double loss_at_zero = 0;  // this step's batch mean loss at z = 0
    bool monitored = false;   // `latest` was just appended to the history
    HistoryPoint latest;      // the newest history point
  };
  // Return false to stop after this step (a checkpoint is written if configured).
  using StepCallback = std::function<bool(const StepReport&)>;

  struct Summary {
    TerminationType termination_type = TerminationType::kCompleted;
    std::string message;
    SensorKind sensor = SensorKind::kSoftBubble;
    FrameFormat format;            // as resolved (rows, cols, scale)
    int num_train_frames = 0;
    int num_frames_at_rest_skipped = 0;  // with Options::skip_frames_at_rest
    int num_parameters = 0;        // theta's size (alpha not counted)
    int start_step = 0;            // > 0 when resumed from a checkpoint
    int steps_done = 0;            // total steps completed (all runs)
    double load_seconds = 0;       // loading and preprocessing the frames
    double wall_seconds = 0;       // this run's training loop (without loading)
    double total_train_seconds = 0;  // training loop seconds over all runs
    double seconds_per_step = 0;   // this run's mean
    double final_loss = 0;         // mean outer loss of the last history interval
    double train_psnr = 0;         // final monitor PSNR after K steps, dB
    double train_psnr_at_zero = 0; // final monitor PSNR at z = 0, dB
    double residual_sigma = 0;     // as stored in the trunk
    std::vector<HistoryPoint> history;

    // One line: termination, steps, loss, PSNR, time.
    std::string BriefReport() const;
    // Several lines: the setup, the history table and the outcome.
    std::string FullReport() const;
  };

  // Throws std::invalid_argument (with IsValid's message) for invalid options.
  explicit TrunkTrainer(const Options& options);
  const Options& options() const { return options_; }

  // The frame format this trainer uses for `sensor` given the dataset's scale
  // (`sensor_scale` > 0; used when Options::normalization_scale is 0).
  FrameFormat ResolveFormat(SensorKind sensor, double sensor_scale) const;

  // Trains a trunk for `sensor` on the dataset's train split (loading every frame once,
  // in parallel) and stores it in *trunk (siren, alpha, format, meta_sgd,
  // residual_sigma). Throws std::runtime_error if the sensor has no train frames, plus
  // what Dataset::LoadFrame and the checkpoint reader throw.
  Summary Train(const Dataset& dataset, SensorKind sensor, SensorTrunk* trunk,
                const StepCallback& callback = nullptr) const;

  // The same on frames already preprocessed with `format` (e.g. by LoadTrunkTargets).
  // `fingerprint` identifies the training set in checkpoints (e.g. a hash of frame ids;
  // resuming with a different one is refused). Every frame must have format's size.
  // With Options::outer_loss_on_clean, `clean_frames` holds each frame's noise-free
  // copy (same order and size; required then, ignored otherwise).
  Summary Train(const std::vector<TrunkTargets>& frames, SensorKind sensor,
                const FrameFormat& format, std::uint64_t fingerprint, SensorTrunk* trunk,
                const StepCallback& callback = nullptr,
                const std::vector<TrunkTargets>* clean_frames = nullptr) const;

  // The options that shape the trajectory, with the resolved format, as a flat JSON
  // object {"siren.width": 64, ..., "format.rows": 70, ...}: what a checkpoint must
  // match and what a model's info records.
  std::string TrajectoryOptionsJson(SensorKind sensor, const FrameFormat& format) const;

  // Starts `siren`'s readout branch (it must have one, with rows x cols nodes = the
  // frames' pixels) from the PCA of `frames` as Options::readout describes, and zeroes
  // the SIREN's output layer. Uses at most `max_frames` frames, evenly spaced. With
  // `noisy_frames` (the same frames with the sensor's noise; `frames` then are their
  // noise-free copies) it also sets the trunk's start gains
  // (LatentModulatedSiren::set_start_gains) to each component's Wiener gain
  // lambda_k / (lambda_k + sigma_k^2), lambda_k the copies' variance along the component
  // and sigma_k^2 the noise's, over the same frames; without them the trunk has none.
  // Throws std::invalid_argument if the branch's grid does not match the frames or the
  // noisy frames are not as many.
  static void StartReadoutFromPca(const std::vector<TrunkTargets>& frames, int max_frames,
                                  LatentModulatedSiren* siren,
                                  const std::vector<TrunkTargets>* noisy_frames = nullptr);

 private:
  Options options_;
};

const char* ToString(TrunkTrainer::TerminationType type);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_TRAINING_TRUNK_TRAINER_H_
