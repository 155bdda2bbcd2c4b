// Copyright 2026 The tactfunc Authors.
//
// PhotometricTrainer: trains an optical sensor's PhotometricTrunk
// (models/trunk/photometric_trunk.h) and fits its latents.
//
// Training is JOINT ("auto-decoding"): the SIREN's parameters, the head's parameters and
// one latent per training frame are optimised together by Adam (Kingma & Ba 2015) on
// random pixel subsets, every latent starting from its frame's moment pose (below) and a
// zero code. Meta-SGD, as TrunkTrainer trains the direct trunk, would need second
// derivatives of the head's slope through the inner steps; joint training is what
// docs/REPRESENTATION.md measured for this head. Each step draws Options::batch_frames
// frames (with replacement) and Options::batch_pixels pixels of each (with replacement),
// and minimises the mean of the frames' weighted MSEs. Adam updates every latent at
// every step (a latent outside the batch has a zero gradient and moves by its momentum
// alone), as a dense optimiser over one latent matrix does. The rates follow
// rate * (0.1 + 0.45 (1 + cos(pi k / steps))) at step k + 1 with Options::cosine_schedule
// (from the full rate to a tenth). For the first Options::marker_warmup_steps the markers
// are sampled at the working resolution (smooth gradients while the head learns how far
// a slope moves the skin; from the first step at the sensor's resolution the marker
// scale was measured to stay at zero), then at the sensor's.
//
// Fitting (FitPhotometricLatent) keeps the trunk fixed and runs Adam on one frame's
// latent: random pixel subsets, the rate annealed by a cosine from
// PhotometricFitOptions::learning_rate to final_learning_rate, from the moment pose and
// (with flipped_start) once more from the pose turned by pi (a principal axis has no
// direction), keeping the fit with the lower loss on all of the frame's valid pixels.
//
// The moment pose (MomentPose): the centroid t of the frame's difference energy
// e_j = w_j sum_c y_jc^2 over the trunk's isotropic coordinates, and the angle
// phi = atan2(2 c_01, c_00 - c_11) / 2 of its second central moments c; zero for a frame
// without energy.
//
// Determinism: every random choice is drawn from DeriveSeed (models/core/seed.h) of the
// seed, the step (or the frame) and the batch slot; the frames of a step are processed
// by Options::threads workers writing their own slots, summed in slot order, so a run
// is bit-identical for any thread count, and a run stopped, checkpointed and resumed is
// bit-identical to one that never stopped.
//
// With Options::learn_background the sensor's background (PhotometricTrunk::
// SetBackground) is a fourth set of parameters, learned from zero with the others, and
// with trunk.lighting_components the lighting images (PhotometricTrunk::SetLighting) a
// fifth.
//
// Checkpoints: a TensorFile of kind "checkpoint" (format "tactfunc-photometric-
// checkpoint", estimation/training/internal/checkpoint.h) holding the SIREN's and the
// head's parameters (and the background and lighting images), the training latents, the
// Adam moments, the step, every step's batch loss and the seconds spent, with the
// trajectory options and a fingerprint of the training frames and the reference.
// Resuming refuses, naming the field, a checkpoint of other options (steps included: the
// cosine schedule depends on them) or other frames.
//
// Errors: invalid options throw std::invalid_argument naming the field; frames of
// another shape than the trunk's working grid throw std::invalid_argument quoting both.
#ifndef TACTFUNC_ESTIMATION_TRAINING_PHOTOMETRIC_TRAINER_H_
#define TACTFUNC_ESTIMATION_TRAINING_PHOTOMETRIC_TRAINER_H_

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include "Eigen/Core"
#include "estimation/data/photometric_markers.h"
#include "estimation/data/trunk_targets.h"
#include "models/core/image.h"
#include "models/trunk/photometric_trunk.h"

namespace tactfunc {

class PhotometricTrainer {
 public:
  struct Options {
    // The trunk; rows, cols and channels are taken from the training frames.
    PhotometricTrunk::Options trunk;
    // Adam steps. >= 1.
    int steps = 3000;
    // Frames and pixels per frame of one step. >= 1 each.
    int batch_frames = 64;
    int batch_pixels = 512;
    // Share of a frame's pixels drawn towards its contact, as PhotometricFitOptions::
    // contact_share draws a fit's: the step's loss still estimates each frame's whole
    // loss, with less of its variance from the pixels at rest. In [0, 1). 0.5 trained
    // GelSlim trunks 0.27-0.52 dB closer to fresh frames than 0, in two seeds
    // (docs/REPRESENTATION.md, "Pixels drawn towards the contact").
    double contact_share = 0.5;
    // Adam step sizes of the trunk (SIREN and head) and of the latents. > 0.
    double trunk_learning_rate = 2e-4;
    double latent_learning_rate = 2e-2;
    // The marker scale m's Adam step size (0 = trunk_learning_rate). Adam moves a
    // parameter by at most about its rate per step, so at the trunk's 2e-4 m can reach
    // only about 0.5 px per unit slope in 3000 steps; at 2e-3 it settled at 1.55-1.67
    // (docs/REPRESENTATION.md, "The photometric trunk in C++"). >= 0.
    double marker_learning_rate = 2e-3;
    bool cosine_schedule = true;
    // Steps with working-resolution markers before switching to the sensor's. >= 0.
    int marker_warmup_steps = 1000;
    std::uint64_t seed = 1;
    // Learn the sensor's background B (PhotometricTrunk::SetBackground) along with the
    // trunk: a value per working pixel and channel, from zero, Adam at the trunk's step
    // size on the step's gradient; a finished run then adds the frames' MeanResidual at
    // their final latents (over up to 8192 of them). The result's trunk holds it.
    bool learn_background = false;
    // With trunk.lighting_components K > 0 (which needs learn_background) the trunk's K
    // lighting images (PhotometricTrunk::SetLighting) are learned too: from small random
    // values, Adam at the trunk's step size, the frames' lighting values among their
    // latents; a finished run then takes the background's and the lighting images'
    // exact least-squares correction at the final latents (TableCorrection).
    //
    // Standard deviation of Gaussian noise added to a drawn frame's code values (not its
    // rigid motion or lighting values) each time a step draws it; the gradient taken
    // there moves the frame's latent. 0 = none. The trunk then learns to draw the frames
    // from anywhere near their latents, not only at them, which a few training frames do
    // not teach otherwise: on real GelSight presses 0.5 drew unseen presses 1.5 to 2.2 dB
    // closer (docs/REAL_DATA.md, "Noise on the training latents"). Finite, >= 0.
    double latent_noise = 0;
    // Worker threads over a step's frames. >= 1.
    int threads = 1;
    // Checkpoints (header comment): written atomically to this path ("" = none; the
    // folder must exist) every checkpoint_every steps (>= 0; 0 = only at the end or on a
    // stop), when the callback stops the run, and at the end. With resume, Train()
    // continues from the checkpoint if one exists. Do not change the result.
    std::string checkpoint_path;
    int checkpoint_every = 500;
    bool resume = false;
    bool IsValid(std::string* error) const;
    // The options that shape the trajectory, as a JSON object (a checkpoint must match
    // them to be resumed): every one but threads and the checkpoint settings.
    std::string TrajectoryOptionsJson() const;
  };

  struct Summary {
    int steps = 0;              // steps taken
    double seconds = 0;         // training seconds, those of the runs resumed from included
    double final_loss = 0;      // the last step's batch loss
    bool stopped = false;       // the callback asked to stop
    std::vector<double> loss;   // every step's batch loss
  };

  // Called after every step with (step (1-based), batch loss); returning false stops.
  using Callback = std::function<bool(int step, double loss)>;

  // Throws std::invalid_argument with IsValid's message.
  explicit PhotometricTrainer(const Options& options);
  const Options& options() const { return options_; }

  struct Result {
    PhotometricTrunk trunk;
    Eigen::MatrixXd latents;  // the training frames' latents, one row each
    Summary summary;
  };

  // Trains a trunk on `frames` (all of one working size) given the sensor-resolution
  // reference in the targets' units (PhotometricTrunk's constructor). Throws
  // std::invalid_argument for no frames or frames of mixed sizes; TensorFileError or
  // std::runtime_error (naming the field) for a checkpoint that cannot be resumed.
  Result Train(const std::vector<TrunkTargets>& frames, const Image& reference,
               const Callback& callback = {}) const;
  // The same for frames of several recordings ("clips"), each with its own reference:
  // frame i is drawn against references[frame_reference[i]]
  // (PhotometricTrunk::Markers); the trunk keeps references[0] as its own. Throws
  // std::invalid_argument as above, and for no references, references of other
  // channels, or an index outside them (naming the frame).
  Result Train(const std::vector<TrunkTargets>& frames, const std::vector<Image>& references,
               const std::vector<int>& frame_reference, const Callback& callback = {}) const;

  // What the frames share that the trunk does not draw: per pixel of the working grid
  // (rows x cols x C), the weighted mean over the frames of target - f(z_i), each frame
  // drawn at latents.row(i) against markers[frame_reference[i]] (null: the trunk's own)
  // over all of its pixels, a pixel no frame weighs left 0. Added to the trunk's
  // background (PhotometricTrunk::SetBackground), it is the background minimising the
  // frames' weighted squared error with the latents and the trunk held: one
  // alternating step over a table that costs no latent bytes. Up to max_frames frames,
  // evenly spaced, are used (>= 1). Throws std::invalid_argument for mismatched sizes.
  static Image MeanResidual(
      const PhotometricTrunk& trunk, const std::vector<TrunkTargets>& frames,
      const Eigen::MatrixXd& latents, const std::vector<const PhotometricTrunk::Markers*>& markers,
      const std::vector<int>& frame_reference, int max_frames, int threads);

  // The same least squares with the lighting images too (lighting = true): per pixel
  // and channel, the background's and the K lighting images' corrections (dB, dL_1..
  // dL_K) minimising sum_i w_i (r_i - dB - sum_k a_ik dL_k)^2, r_i = target - f(z_i)
  // and a_i the frame's lighting values (its latent's last K). Added to the trunk's
  // tables they are their exact minimiser with the latents and the rest of the trunk
  // held. lighting = false gives MeanResidual's background and no lighting columns.
  struct Tables {
    Image background;          // rows x cols x C
    Eigen::MatrixXf lighting;  // (rows cols C) x K, as PhotometricTrunk::lighting()
  };
  static Tables TableCorrection(
      const PhotometricTrunk& trunk, const std::vector<TrunkTargets>& frames,
      const Eigen::MatrixXd& latents, const std::vector<const PhotometricTrunk::Markers*>& markers,
      const std::vector<int>& frame_reference, int max_frames, int threads, bool lighting);

 private:
  Options options_;
};

struct PhotometricFitOptions {
  // The defaults (200 steps from 5e-2) were picked on a tuning set no other measurement
  // uses: 0.4 dB above 400 steps from 1e-2 in half the time (docs/REPRESENTATION.md, "How
  // long to fit a photometric latent").
  int steps = 200;           // Adam steps per start, >= 1
  int batch_pixels = 512;    // pixels per step (with replacement), >= 1
  double learning_rate = 5e-2;  // the first step size, falling by a cosine to the final one
  double final_learning_rate = 1e-4;
  bool flipped_start = true;  // also start from the moment pose turned by pi
  // With flipped_start: after this many steps only the start whose latent then has the
  // lower loss on all of the frame's pixels goes on to `steps` (0: both run all `steps`).
  // Each start's trajectory does not depend on the other, so the result equals the full
  // two-start fit's whenever the start ahead at the probe is also ahead at the end; the
  // cost is steps + probe_steps instead of 2 steps. In [0, steps].
  int probe_steps = 0;
  // Score the fit on all of the frame's pixels (PhotometricFit::loss). Two starts are
  // always scored (the lower loss wins); a single start's full-frame pass (as costly as
  // about 17 steps of 512 pixels) can be left out: its loss is then NaN.
  bool score = true;
  // Side of the square blocks a step's pixels come in: batch_pixels / block^2 blocks
  // (at least one), each block's corner drawn uniformly (with replacement) so that it
  // lies inside the frame. Pixels of a block are each other's neighbours, so the trunk
  // evaluates its SIREN about (block + 2)^2 - 4 times per block instead of 5 block^2
  // (PhotometricTrunk::Forward). 1: independent pixels. In [1, 16] and at most the
  // frame's rows and columns.
  int pixel_block = 1;
  // Share of a step's pixels drawn towards the contact, a in [0, 1): pixel j of the
  // frame's N is drawn with probability p_j = (1 - a) / N + a e_j / sum(e), e_j its
  // weighted difference energy w_j ||target_j||^2, and weighs w_j / (N p_j), so that a
  // step's weighted loss still estimates the whole frame's (below 1 every pixel can be
  // drawn, which the estimate needs). 0: every pixel alike. Needs pixel_block 1.
  // encode's knn+adam:N draws with 0.5 (estimation/functaset/latent_encoder.cc).
  double contact_share = 0;
  // The frame's own markers (PhotometricTrunk::MakeMarkers of its reference; not owned,
  // must outlive the fit), or null for the trunk's own reference.
  const PhotometricTrunk::Markers* markers = nullptr;
  bool IsValid(std::string* error) const;
};

struct PhotometricFit {
  Eigen::VectorXd latent;
  double loss = 0;        // the weighted MSE on all of the frame's valid pixels (NaN
                          // for one start without PhotometricFitOptions::score)
  bool flipped = false;   // the start turned by pi won
};

// The moment pose of the header comment, (t_0, t_1, phi).
Eigen::Vector3d MomentPose(const PhotometricTrunk& trunk, const TrunkTargets& frame);

// Fits one frame's latent with the trunk fixed (header comment); `seed` draws the pixel
// subsets. `start` (d values; null: the moment pose and a zero code) is a warm start
// instead, e.g. a neighbour's latent (with flipped_start also turned by pi). Throws
// std::invalid_argument for invalid options, a frame of another size or a start of
// another size.
PhotometricFit FitPhotometricLatent(const PhotometricTrunk& trunk, const TrunkTargets& frame,
                                    const PhotometricFitOptions& options, std::uint64_t seed,
                                    const Eigen::VectorXd* start = nullptr);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_TRAINING_PHOTOMETRIC_TRAINER_H_
