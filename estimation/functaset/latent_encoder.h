// Copyright 2026 The tactfunc Authors.
//
// LatentEncoder: turns a tactile dataset into its functaset (estimation/functaset/functaset.h)
// under a trained model (models/trunk/functa_model.h) -- Sec. III-B/C of "Tactile
// Functasets": every frame gets its own latent, fitted with the trunk fixed.
//
// For frame i of sensor s the encoder runs exactly the inner loop the model was
// meta-trained with (models/trunk/meta_sgd.h, the paper's Eq. 6 with meta-SGD rates):
//
//   targets t_i, weights w_i = LoadTrunkTargets(dataset, i, format_s)   (N x C, N)
//   z_0 = 0;   z_{k+1} = z_k - alpha_s (*) d/dz [ L(theta_s, z_k) + lambda ||z_k||^2 ]
//   latent_i = z_K,   psnr_i = Psnr(f_theta_s(grid; z_K), t_i)          (trunk_targets.h)
//
// with K = the trunk's meta_sgd.inner_steps, in float: the default strategy. Using the
// same K and alpha as in training matters: meta-learning shaped theta so that THESE K
// steps land well. Options::strategy chooses another fit per frame: meta_sgd:K (K steps
// of the same loop) or ceres:N (Sec. III-C's "until convergence": at most N
// Levenberg-Marquardt iterations on the frame's LatentProblem, estimation/fitting/
// latent_problem.h, from z = 0, with Options::problem's sigma, sigma_z and robust loss).
// A photometric trunk (models/trunk/photometric_trunk.h) is fitted by FitPhotometricLatent
// instead: knn+adam:N (the default where the model holds a warm-start table, N = 140 per
// 64 latent values: the best of 4 neighbours among the training latents, then N Adam
// steps from 1e-2 on 64 pixels a step, estimation/training/photometric_warm_start.h), knn
// (that neighbour as it is), knn+ceres:N or adam:N (N steps from the moment pose and its
// turn by pi; the default without a table, N = 200). A trunk that records its own default
// fit (SensorTrunk::default_fit, `train --default-fit`) gets that one instead of these
// rules. The functaset records the strategy of each sensor (Functaset::fit_strategy).
//
// Parallelism and determinism. Frames are independent; `threads` workers take them
// from a shared counter. Each frame is computed by one thread with the same code, so
// the functaset is bit-identical whatever the thread count, and entries are stored in
// the dataset's order (grouped by sensor) whatever the completion order.
//
// Several processes (Options::processes; `mpirun ... tactfunc encode`, docs/SCALING.md).
// The pending frames are encoded in rounds of `checkpoint_every` frames (one round
// without checkpoints); in each round process r of n encodes every n-th frame from the
// r-th, and at its end the processes exchange their latents, so that every process
// returns the same functaset, bit-identical to a single process's. Only rank 0 writes
// (the checkpoints and the final file) and reads the checkpoint to resume, sending the
// finished frames to the others. An interrupt or a failure in one process stops all of
// them at the end of the round (a failure is rethrown in every process, naming the one
// it happened in). Each process reads the frames it encodes: the dataset must be at the
// same path for all.
//
// Checkpoints and resume. With a checkpoint path the encoder writes the functaset of
// the frames finished so far (meta "complete": false) every `checkpoint_every`
// frames, atomically, and once more when it stops: the complete functaset when done,
// the partial one when interrupted or when a frame fails to load (the error is then
// rethrown). With `resume`, frames already in the checkpoint file (same model checksum
// required) are taken from it and not encoded again; since encoding is deterministic
// the result equals an uninterrupted run.
//
// Errors (docs/ARCHITECTURE.md's three tiers): bad Options -> std::invalid_argument
// from the constructor; an interrupted run -> Summary::termination == kInterrupted; bad
// input (no trunk for a requested sensor, frames whose channels do not match the trunk,
// a corrupt frame file, a checkpoint of another model) -> an exception naming it.
//
// Thread safety: Encode and EncodeTargets are const and may run concurrently; the
// model must outlive the encoder and not change while it is used.
#ifndef TACTFUNC_ESTIMATION_FUNCTASET_LATENT_ENCODER_H_
#define TACTFUNC_ESTIMATION_FUNCTASET_LATENT_ENCODER_H_

#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "estimation/data/contact.h"
#include "estimation/data/dataset.h"
#include "estimation/fitting/latent_fitter.h"
#include "estimation/functaset/functaset.h"
#include "estimation/data/trunk_targets.h"
#include "estimation/training/photometric_warm_start.h"
#include "models/core/process_group.h"
#include "models/trunk/functa_model.h"

namespace tactfunc {

enum class EncodeTermination {
  kComplete,     // every selected frame has a latent
  kInterrupted,  // the interrupt flag was raised; the functaset is partial
};
// "complete" / "interrupted".
const char* ToString(EncodeTermination termination);

// What the progress callback receives.
struct EncodeProgress {
  std::int64_t done = 0;   // frames with a latent (resumed ones included)
  std::int64_t total = 0;  // frames selected
  double mean_psnr = 0;    // dB, over the finished frames with a finite PSNR (0 if none)
};

class LatentEncoder {
 public:
  struct Options {
    // Worker threads, >= 1. Measured (docs/FUNCTASET.md): throughput scales about
    // linearly up to the core count; more threads than cores does not help.
    int threads = 1;
    // Where partial functasets are written ("" = nowhere; then resume is impossible).
    // `tactfunc encode` uses its --out file.
    std::string checkpoint_path;
    // Frames encoded between two checkpoint writes, >= 0; 0 = write only when the
    // encoder stops. A checkpoint costs one atomic, fsynced file write (d * 4 bytes
    // per frame): 1000 frames keeps the cost far below 1% of the encoding time.
    int checkpoint_every = 1000;
    // Continue from checkpoint_path if it exists (requires a checkpoint_path).
    bool resume = false;
    // Sensors to encode; empty = every sensor of the dataset that the model has a
    // trunk for. A sensor listed here must be in both.
    std::vector<SensorKind> sensors;
    // Only frames of this split (nullopt = all frames).
    std::optional<Split> split;
    // Storage precision of the latents in the written functaset (Functaset::
    // LatentPrecision). The per-frame PSNR is that of the unrounded fit. Checkpoints
    // (partial files) of b-bit runs hold float32 latents: the codes' grid spans all
    // of a sensor's entries, so only the complete file is quantised.
    Functaset::LatentPrecision latent_precision = Functaset::LatentPrecision::kFloat32;
    // Bytes per frame of kAllocated latents (Functaset::set_latent_bytes); unused otherwise.
    int latent_bytes = 0;
    // The fit of every frame, as LatentFitter names it: "" (default) = each trunk's own
    // meta_sgd:K, what it was meta-trained for; "meta_sgd:K" (K >= 0) or "ceres:N"
    // (N >= 1). The k-NN strategies are not offered: they need a second functaset to
    // search. A resumed checkpoint must have been written with the same strategy.
    std::string strategy;
    // The latent problem of the ceres strategy (unused by meta_sgd): sigma (0 = the
    // trunk's residual_sigma), sigma_z, robust loss, pixel selection, precision.
    LatentProblem::Options problem;
    // Frames at rest (no contact above the sensor's noise by DetectFrameContact with
    // `contact`, estimation/data/contact.h) are not fitted: they share one latent per
    // sensor, the fit of a frame with no change (all-zero targets), stored once
    // (FunctasetEntry::at_rest). A resumed checkpoint must have been written with the
    // same choice.
    bool share_rest_latent = false;
    ContactOptions contact;
    // EncodeTargets scores a photometric trunk's fit (EncodedFrame::psnr, one more
    // whole-frame pass); false leaves psnr NaN, for callers that need the latent alone
    // (pose posteriors). Encode always scores: the functaset records every PSNR.
    bool score_targets = true;
    // The processes sharing the run (models/core/process_group.h); null = this process
    // alone. Every process calls Encode with the same dataset and options; see
    // "Several processes" above. Does not change the result.
    const ProcessGroup* processes = nullptr;

    // True if every field is in range; otherwise false and *error (if not null) names
    // the bad field and its value.
    bool IsValid(std::string* error) const;
  };

  struct Summary {
    EncodeTermination termination = EncodeTermination::kComplete;
    std::string message;              // one line, for humans
    std::int64_t frames_total = 0;    // frames selected
    std::int64_t frames_encoded = 0;  // frames encoded by this run
    std::int64_t frames_resumed = 0;  // frames taken from the checkpoint
    std::int64_t checkpoints_written = 0;
    std::int64_t non_finite_latents = 0;  // latents with a NaN or inf (alpha too large?)
    double seconds = 0;                   // wall time of this run
    double frames_per_second = 0;         // frames_encoded / seconds
    // Per sensor, over the functaset's entries (resumed ones included):
    std::map<SensorKind, std::int64_t> frames;  // entries
    std::map<SensorKind, double> mean_psnr;     // mean PSNR (dB) over finite PSNRs
    std::string BriefReport() const;            // one line
    std::string FullReport() const;             // several lines
  };

  // One frame's fit.
  struct EncodedFrame {
    Eigen::VectorXf latent;  // z_K, latent_dim
    double psnr = 0;         // Psnr(f(grid; z_K), targets), dB (NaN unscored)
  };

  using ProgressCallback = std::function<void(const EncodeProgress&)>;

  // Throws std::invalid_argument with IsValid's message for bad options.
  LatentEncoder(const FunctaModel& model, const Options& options);
  const Options& options() const { return options_; }

  // Encodes the selected frames of `dataset`. `progress` (may be null) is called from
  // the calling thread a few times a second and at the end. If `interrupt` is not null
  // and becomes true, workers finish the frame in hand, a checkpoint is written and
  // the partial functaset is returned with termination kInterrupted. `summary` may be
  // null. Throws as the header comment says.
  Functaset Encode(const Dataset& dataset, Summary* summary,
                   const ProgressCallback& progress = nullptr,
                   const std::atomic<bool>* interrupt = nullptr) const;

  // The fit of one frame's targets (as LoadTrunkTargets makes them with the sensor's
  // frame format). Throws std::invalid_argument if the model has no trunk for the
  // sensor or the targets are not N x C of the trunk's working resolution. A
  // photometric trunk draws the frame against `markers` (its own reference's,
  // PhotometricTrunk::MakeMarkers) if given, else against the trunk's own reference;
  // Encode gives every frame its own (estimation/data/photometric_markers.h).
  EncodedFrame EncodeTargets(SensorKind sensor, const TrunkTargets& targets,
                             const PhotometricTrunk::Markers* markers = nullptr) const;

  // The fit a sensor's frames get (Options::strategy, or the trunk's default when it is
  // "": its recorded default_fit, else the rules of the header comment). Throws
  // std::invalid_argument if the model has no trunk for the sensor.
  const FitStrategy& StrategyOf(SensorKind sensor) const { return State(sensor).strategy; }

  // The default fit of a photometric trunk's frames with a latent of `latent_dim`
  // values: knn+adam:N where the model holds the trunk's warm-start table (N = 140 per 64
  // latent values, at least 140), adam:N without one.
  static std::string DefaultPhotometricStrategy(bool warm_start_table, int latent_dim);

  // Why `strategy` cannot fit the latents of a photometric (or direct) trunk, with or
  // without a warm-start table; "" when it can. Photometric: adam:N, knn+adam:N,
  // knn+ceres:N or knn, the k-NN ones with a table; direct: meta_sgd:K or ceres:N.
  static std::string StrategyRefusal(const FitStrategy& strategy, bool photometric,
                                     bool warm_start_table);

 private:
  struct SensorState {
    SensorKind sensor;
    const SensorTrunk* trunk = nullptr;
    Eigen::MatrixXf grid;   // rows*cols x 2, built once
    Eigen::VectorXf alpha;  // float copy of the trunk's rates
    MetaSgd meta_sgd{MetaSgd::Options()};
    FitStrategy strategy;   // resolved: the trunk's meta_sgd:K when Options::strategy is ""
    std::optional<LatentFitter> fitter;  // for ceres:N
    // For knn+adam:N (photometric trunks): the trunk's warm-start table.
    std::shared_ptr<const PhotometricWarmStart> warm_start;
    Eigen::VectorXf rest_latent;  // with Options::share_rest_latent: the fit of no change
  };
  const SensorState& State(SensorKind sensor) const;
  EncodedFrame EncodeTargetsImpl(SensorKind sensor, const TrunkTargets& targets,
                                 const PhotometricTrunk::Markers* markers, bool score) const;

  const FunctaModel& model_;
  Options options_;
  std::vector<SensorState> states_;
};

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_FUNCTASET_LATENT_ENCODER_H_
