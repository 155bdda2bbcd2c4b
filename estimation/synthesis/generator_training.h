// Copyright 2026 The tactfunc Authors.
//
// Training the pose-conditioned generator h (models/pose/pose_generator.h) from labelled
// contacts, two ways (docs/POSES.md, "The generator path" has the comparison):
//
//   TrainGeneratorOnLatents  regression: the mean over samples of
//                            ||(h(pose_i) - z_i) ./ stddev||^2 / d against the labelled
//                            functaset latents z_i (the output standardisation is set
//                            from them first).
//   TrainGeneratorOnPixels   through the frozen trunk on pixels: the mean over samples of
//                            the trunk's weighted MSE (LatentModulatedSiren::Loss) of
//                            f_theta(x_j; h(pose_i)) against frame i over
//                            pixels_per_frame valid pixels drawn afresh per sample and
//                            epoch; dL/dz comes from the trunk's reverse pass and is
//                            pushed through h. Usually started from a regressed h.
//                            Optionally the trunk's SIREN is trained along with h
//                            (trunk_step_fraction), into a trunk of the generator's own.
//
// Both: Adam on shuffled minibatches, everything seeded (DeriveSeed per epoch and
// sample), single-threaded and deterministic.
//
// Checkpoints. With GeneratorTrainingOptions::checkpoint_path set, a TensorFile of kind
// "checkpoint" (format "tactfunc-generator-checkpoint", estimation/training/internal/
// checkpoint.h: the stage, the options that shape the trajectory, the samples' count and
// fingerprint) holding the generator's parameters, Adam's moments and step and the loss
// history is written atomically every checkpoint_every epochs, when the progress callback
// stops the run, and at the end. With resume, training continues from it if it exists:
// since every epoch's shuffle and pixel draws are seeded by the epoch, a run stopped and
// resumed gives the same generator, bit for bit, as one never stopped. A checkpoint of
// another stage, other options or other samples is refused (std::runtime_error naming
// the field; TensorFileError for an unreadable file).
//
// Errors: bad options, shapes that do not match, unknown tool indices or non-finite
// latents throw std::invalid_argument.
#ifndef TACTFUNC_ESTIMATION_SYNTHESIS_GENERATOR_TRAINING_H_
#define TACTFUNC_ESTIMATION_SYNTHESIS_GENERATOR_TRAINING_H_

#include <cstdint>
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "estimation/data/trunk_targets.h"
#include "models/pose/pose_generator.h"
#include "models/trunk/functa_model.h"

namespace tactfunc {

// One labelled contact: the generator's tool index, the pose and the press depth.
struct GeneratorSample {
  int tool = 0;
  SE2d sensor_T_object;
  double depth_m = 0;
};

struct GeneratorTrainingOptions {
  int epochs = 200;           // >= 1
  int batch_size = 128;       // >= 1
  double learning_rate = 1e-3;  // Adam step, > 0
  double beta1 = 0.9, beta2 = 0.999, epsilon = 1e-8;
  // Cosine decay of the step to learning_rate * final_lr_fraction over the epochs, [0, 1].
  double final_lr_fraction = 0.05;
  // Pixels drawn per sample and step (pixel training only), >= 1.
  int pixels_per_frame = 256;
  // Set the output standardisation from the latents (regression only).
  bool standardize_outputs = true;
  // Pixel training only: > 0 trains the trunk's SIREN along with the generator, its Adam
  // step this fraction of the generator's (TrainGeneratorOnPixels); 0 keeps it frozen.
  double trunk_step_fraction = 0;
  std::uint64_t seed = 0;
  // Checkpoints (header comment): the path ("" = none), every how many epochs (>= 1), and
  // whether to continue from the file if it exists. They do not change the result.
  std::string checkpoint_path;
  int checkpoint_every = 10;
  bool resume = false;
  bool IsValid(std::string* error) const;
};

struct GeneratorTrainingSummary {
  int epochs_completed = 0;  // counting those a resumed run found done
  int epochs_resumed = 0;    // epochs the checkpoint already held (0: started anew)
  double initial_loss = 0, final_loss = 0;  // mean epoch loss of the first / last epoch
  std::vector<double> loss_history;
  double total_time_in_seconds = 0;
  std::string BriefReport() const;
};

// Called after each epoch with (epoch, mean loss); return false to stop.
using GeneratorProgressCallback = std::function<bool(int epoch, double loss)>;

// latents: M x d, one per sample.
GeneratorTrainingSummary TrainGeneratorOnLatents(PoseGenerator* generator,
                                                 const std::vector<GeneratorSample>& samples,
                                                 const Eigen::MatrixXd& latents,
                                                 const GeneratorTrainingOptions& options,
                                                 const GeneratorProgressCallback& progress = {});

// frames: one TrunkTargets per sample, at any resolution (the trunk is continuous).
// With options.trunk_step_fraction > 0 the trunk's SIREN is trained jointly, from
// trunk.siren (which stays as it is), and the result written to *tuned_siren (required
// then; untouched otherwise): a trunk of the generator's own, for rendering poses only
// (the functaset's latents belong to the trunk they were fitted with).
GeneratorTrainingSummary TrainGeneratorOnPixels(PoseGenerator* generator,
                                                const SensorTrunk& trunk,
                                                const std::vector<GeneratorSample>& samples,
                                                const std::vector<TrunkTargets>& frames,
                                                const GeneratorTrainingOptions& options,
                                                const GeneratorProgressCallback& progress = {},
                                                LatentModulatedSiren* tuned_siren = nullptr);

// Mean PSNR (trunk_targets.h's Psnr, all valid pixels) of f_theta(.; h(pose_i)) against
// frames[i]: how well the generator renders the labelled contacts.
double MeanGeneratorPsnr(const PoseGenerator& generator, const SensorTrunk& trunk,
                         const std::vector<GeneratorSample>& samples,
                         const std::vector<TrunkTargets>& frames);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_SYNTHESIS_GENERATOR_TRAINING_H_
