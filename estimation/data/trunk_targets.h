// Copyright 2026 The tactfunc Authors.
//
// Trunk targets: a tactile frame turned into what the SIREN trunk fits -- one row per
// pixel of the working resolution (pixel j = row * cols + col, the trunk's coordinate
// order, LatentModulatedSiren::Grid), one column per output channel, and a validity
// weight per pixel -- following a model's FrameFormat (models/trunk/functa_model.h).
//
// PSNR, defined once for all of tactfunc: for a target t with valid pixels V and a
// prediction p,
//   MSE  = sum_{j in V} sum_c (p_jc - t_jc)^2 / (|V| C)
//   PSNR = 10 log10(R^2 / MSE),  R = max_{V,c} t - min_{V,c} t  (the target's range)
// which equals the PSNR of per-image min-max normalised images at the working
// resolution, whatever normalisation the model uses. A target whose range is below
// 1e-9 (blank) uses R = 1.
//
// The paper's release normalises each frame by its min and max at the SOURCE
// resolution (320x427 GelSlim, 140x175 Bubble) and only then resizes, so its peak is
// the source frame's range R_s >= R (thin features and noise extremes shrink when
// averaged down). PsnrSourcePeak reports that convention,
//   PSNR_s = 10 log10(R_s^2 / MSE) = PSNR + 20 log10(R_s / R),
// for comparisons with the paper's figures; Psnr stays the stricter one used
// everywhere else. (The release also resizes bilinearly without antialiasing, which
// keeps more noise in the targets; we resize by area averaging, see preprocess.h.)
#ifndef TACTFUNC_ESTIMATION_DATA_TRUNK_TARGETS_H_
#define TACTFUNC_ESTIMATION_DATA_TRUNK_TARGETS_H_

#include <cstddef>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "estimation/data/preprocess.h"
#include "models/trunk/functa_model.h"
#include "models/core/image.h"

namespace tactfunc {

class Dataset;

struct TrunkTargets {
  Eigen::MatrixXf values;   // N x C normalised differences; invalid pixels hold 0
  Eigen::VectorXf weights;  // N: 1 for a valid pixel, 0 for an invalid one
  bool flat = false;        // per-image min-max on a frame with no range
  double scale = 1, offset = 0;  // values = (difference - offset) / scale
  // The difference's range before the resize, in the units of `values`
  // (PreprocessedFrame::source_range / scale); 0 without valid pixels.
  double source_range = 0;
  int rows = 0, cols = 0;
};

// The PreprocessOptions equivalent of a model's frame format.
PreprocessOptions ToPreprocessOptions(const FrameFormat& format);

// Preprocesses `frame` against `reference` (estimation/data/preprocess.h) into targets.
TrunkTargets MakeTrunkTargets(const Image& frame, const Image& reference, SensorKind sensor,
                              const FrameFormat& format);
// Frame `index` of `dataset` (its noisy frame, or its noise-free copy if `clean`).
TrunkTargets LoadTrunkTargets(const Dataset& dataset, std::size_t index,
                              const FrameFormat& format, bool clean = false);
// LoadTrunkTargets of every frame of `indices`, on `threads` workers (>= 1), in the
// order of `indices`.
std::vector<TrunkTargets> LoadTrunkTargets(const Dataset& dataset,
                                           const std::vector<std::size_t>& indices,
                                           const FrameFormat& format, bool clean, int threads);
// The same from `frame`, frame `index` as already decoded (Dataset::LoadFrame or
// LoadCleanFrame), against its own reference: for callers that also look at the raw frame
// (contact detection) and decode it once.
TrunkTargets DatasetFrameTargets(const Dataset& dataset, std::size_t index, const Image& frame,
                                 const FrameFormat& format);

// PSNR in dB of `prediction` (N x C) against `target`, as defined above. +inf for a
// perfect fit; NaN if the target has no valid pixel.
double Psnr(const Eigen::MatrixXf& prediction, const TrunkTargets& target);
// The paper release's convention: peak R_s = target.source_range (R = 1 if below
// 1e-9), same MSE. >= Psnr for targets made by MakeTrunkTargets.
double PsnrSourcePeak(const Eigen::MatrixXf& prediction, const TrunkTargets& target);

// The target's range R over its valid pixels and channels, in normalised units; 0
// without valid pixels. Psnr's peak is R, or 1 when R < 1e-9 (a blank target).
double TargetRange(const TrunkTargets& target);
// Root-mean-square error of `prediction` over the target's valid pixels and channels,
// in normalised units (Psnr = 20 log10(R / Rmse) for R >= 1e-9); NaN without valid
// pixels.
double Rmse(const Eigen::MatrixXf& prediction, const TrunkTargets& target);

// Throws std::invalid_argument, message starting with `who`, unless `targets` are the
// frame of a rows x cols grid with `channels` channels: rows * cols x channels values,
// rows * cols weights (or none), and rows, cols as stated.
void CheckTargetsShape(const TrunkTargets& targets, int rows, int cols, int channels,
                       const std::string& who);
// The indices of the target's valid pixels (weight > 0; every pixel without weights),
// in grid order.
std::vector<int> ValidPixels(const TrunkTargets& targets);

// Drawing a frame's pixels towards its contact. Pixel i of `pixels` (indices into the
// targets' rows, n of them) has probability p_i = (1 - share) / n + share e_i / sum(e),
// e_i = w_i ||target_i||^2 its weighted difference energy; p_i = 1 / n when the energies
// sum to 0 or to no finite number. share in [0, 1].
std::vector<double> ContactDrawProbabilities(const TrunkTargets& targets,
                                             const std::vector<int>& pixels, double share);
// Draws of one pixel among all of a frame's by ContactDrawProbabilities(targets, every
// pixel, share): Pixel(u) for a uniform u in [0, 1) is the first pixel whose cumulative
// probability exceeds u (the last pixel if none does). With the guide (a table of n
// entries, the first pixel past b / n for each b) a draw takes a step or two instead of a
// binary search over every pixel, and returns the same pixel.
struct ContactDraw {
  ContactDraw() = default;
  ContactDraw(const TrunkTargets& targets, double share, bool with_guide);
  int Pixel(double u) const;
  std::vector<double> cdf;  // cumulative probabilities in pixel order, the last 1
  std::vector<int> guide;   // empty without the guide
};

// Systematic sampling of m draws by those probabilities, at the positions (k + 1/2) / m
// of their cumulative sum in pixel order: *pixels keeps each pixel drawn (c_i times) once,
// in order, and *weight_factor gets c_i / (n p_i) for it, so that a weighted sum over the
// kept pixels estimates the sum over all n times m / n without bias.
void ContactSample(const TrunkTargets& targets, int m, double share, std::vector<int>* pixels,
                   std::vector<double>* weight_factor);

// The prediction back as a normalised Image (rows x cols x C), for pictures.
Image TargetsToImage(const Eigen::MatrixXf& values, int rows, int cols);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_DATA_TRUNK_TARGETS_H_
