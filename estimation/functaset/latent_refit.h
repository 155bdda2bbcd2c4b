// Copyright 2026 The tactfunc Authors.
//
// RefitLatents: every labelled entry of one sensor of a functaset fitted again from its
// dataset frame by a LatentFitter (`tactfunc train-pose --refit`: the pose MLP is trained
// on the latent map its posteriors centre on, docs/CLI.md "Latent maps"). Entries
// without a label are copied as they are. The fits are independent, so the result does
// not depend on the thread count.
//
// Long work, stopped and resumed. The entries are fitted in order, a block at a time;
// after each block `progress` is told how many are done and may return false to stop.
// With RefitOptions::checkpoint_path set, the latents fitted so far are written there
// atomically (a TensorFile of kind "checkpoint", format "tactfunc-refit-checkpoint",
// estimation/training/internal/checkpoint.h) every checkpoint_every entries, when the
// run stops and when it completes. With resume, a run continues after the entries the
// checkpoint holds; the checkpoint must belong to the same run: the same sensor, fit
// strategy, latent problem options (sigma, prior, robust loss, pixel selection,
// precision) and model checksum (RefitOptions::model_checksum) and the same functaset
// entries (ids, labels and latents, fingerprinted), or RefitLatents throws naming what
// differs. A resumed run returns the same latents, bit for bit, as one never
// stopped. The caller removes the checkpoint once it has what it needs.
//
// Errors: std::invalid_argument for bad options, a sensor the functaset lacks, or a
// photometric trunk (its latents are encode's fits); DatasetError for an entry whose
// frame the dataset lacks; TensorFileError / std::runtime_error for a checkpoint that
// cannot be read or belongs to another run.
#ifndef TACTFUNC_ESTIMATION_FUNCTASET_LATENT_REFIT_H_
#define TACTFUNC_ESTIMATION_FUNCTASET_LATENT_REFIT_H_

#include <cstdint>
#include <functional>
#include <string>

#include "estimation/data/dataset.h"
#include "estimation/fitting/latent_fitter.h"
#include "estimation/fitting/latent_problem.h"
#include "estimation/functaset/functaset.h"
#include "models/trunk/functa_model.h"

namespace tactfunc {

struct RefitOptions {
  LatentFitter::Options fit;  // its strategy: meta_sgd:K or ceres:N (no knn)
  LatentProblem::Options problem;
  int threads = 1;  // >= 1
  // The checksum of the model file of `trunk` (FunctaModel::checksum), recorded in and
  // checked against the checkpoint.
  std::uint32_t model_checksum = 0;
  std::string checkpoint_path;  // "" = no checkpoints (and no resume)
  int checkpoint_every = 1024;  // entries between checkpoint writes, >= 1
  bool resume = false;          // continue from checkpoint_path if it exists
  bool IsValid(std::string* error) const;
};

struct RefitSummary {
  bool stopped = false;  // `progress` returned false: the result is partial
  int entries = 0;       // of the sensor
  int done = 0;          // entries handled, counting those resumed
  int resumed = 0;       // entries the checkpoint already held
  int fitted = 0;        // labelled entries this run fitted
  double seconds = 0;    // wall time of this run
};

// (entries done, entries in all); false stops the run after the block in hand.
using RefitProgress = std::function<bool(int done, int total)>;

// The functaset with `sensor`'s labelled latents re-fitted (only `sensor`; of a stopped
// run, only the entries done, so check summary->stopped). `trunk` is the functaset's
// model's trunk for `sensor`.
Functaset RefitLatents(const Functaset& functaset, SensorKind sensor, const Dataset& dataset,
                       const SensorTrunk& trunk, const RefitOptions& options, RefitSummary* summary,
                       const RefitProgress& progress = nullptr);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_FUNCTASET_LATENT_REFIT_H_
