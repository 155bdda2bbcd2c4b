// Copyright 2026 The tactfunc Authors.
//
// Reconstruction quality and size of a functaset (Sec. IV-B and Tab. I of "Tactile
// Functasets"): how well the stored latents reproduce the dataset's frames, and how
// much smaller the trunk + latents are than the raw frames.
//
// For every entry (frame i of sensor s) of a functaset, with its sensor's trunk at the
// working resolution (the model's FrameFormat) and in float:
//   psnr        = Psnr(f(grid; z_i), targets of the noisy frame)
//   psnr_clean  = Psnr(f(grid; z_i), targets of the noise-free frame)  (simulated data
//                 only: Dataset::has_clean; NaN otherwise)
//   psnr_zero   = Psnr(f(grid; 0),   targets of the noisy frame)       (the "initial
//                 image" of the paper's Fig. 3: what the trunk knows before any fit)
//   psnr_source_peak = PsnrSourcePeak(f(grid; z_i), noisy targets)     (the paper
//                 release's convention: peak = the frame's range at source resolution)
// with Psnr the one definition of estimation/data/trunk_targets.h. Per sensor and split the
// evaluator reports mean, median and 5th percentile of each (PsnrStats).
//
// Contact (estimation/data/contact.h): every entry's raw difference with its reference, at
// the source resolution, is tested for contact (`contact`, `contact_score`, and the
// centre of the change in source pixels), and the centre of its reconstruction's change
// is mapped to the same pixels (`recon_contact_row/col`). Each group's PSNRs are also
// summarised over its contact and its no-contact frames apart: frames at rest are mostly
// sensor noise and say little about how well contacts are kept.
//
// Representation size (Tab. I's "Rep. size"):
//   representation_bytes = model bytes (the trunks of the functaset's sensors: theta
//                          and alpha as stored, float32) + latents (sum_s M_s d_s 4)
//   raw_bytes            = sum over the entries of rows x cols x channels x bytes per
//                          sample at the sensor's NATIVE resolution (2 for depth_u16_um,
//                          1 for rgb8): the uncompressed frames, not the PNG files
//   compression_ratio    = raw_bytes / representation_bytes
#ifndef TACTFUNC_ESTIMATION_EVALUATION_RECONSTRUCTION_H_
#define TACTFUNC_ESTIMATION_EVALUATION_RECONSTRUCTION_H_

#include <cstddef>
#include <cstdint>
#include <limits>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "estimation/data/contact.h"
#include "estimation/data/dataset.h"
#include "estimation/functaset/functaset.h"
#include "models/core/process_group.h"
#include "models/trunk/functa_model.h"

namespace tactfunc {

// Summary statistics of a list of PSNRs (dB). Only finite values count: NaN (a frame
// without valid pixels) and +inf (an exact fit) are left out and counted in `excluded`.
// With no finite value, mean, median and p5 are NaN.
struct PsnrStats {
  std::int64_t count = 0;     // finite values used
  std::int64_t excluded = 0;  // non-finite values left out
  double mean = std::numeric_limits<double>::quiet_NaN();
  double median = std::numeric_limits<double>::quiet_NaN();
  // 5th percentile, linear interpolation between order statistics (numpy's default
  // np.percentile(v, 5)): the PSNR that 95% of the frames reach.
  double p5 = std::numeric_limits<double>::quiet_NaN();
};
PsnrStats ComputePsnrStats(const std::vector<double>& values);

struct RepresentationSize {
  std::int64_t frames = 0;                 // functaset entries counted
  std::uint64_t model_bytes = 0;           // trunks of the functaset's sensors, float32
  // sum_s NumStoredLatents(s) x Functaset::BytesPerFrame(s) + SharedLatentBytes(s):
  // bytes on disk (frames at rest share one latent).
  std::uint64_t latent_bytes = 0;
  std::uint64_t representation_bytes = 0;  // model_bytes + latent_bytes
  std::uint64_t raw_bytes = 0;             // the entries' frames, uncompressed, native size
  double compression_ratio = 0;            // raw_bytes / representation_bytes (0 if empty)
};

// Bytes of one uncompressed frame of a sensor: rows x cols x channels x (2 for
// depth_u16_um, 1 for rgb8).
std::uint64_t RawFrameBytes(const SensorInfo& info);
// The sizes above. `sensors` must describe every sensor of the functaset (else
// std::invalid_argument); the model must have a trunk for each.
RepresentationSize ComputeRepresentationSize(const FunctaModel& model, const Functaset& functaset,
                                             const std::vector<SensorInfo>& sensors);

// f(grid; latent) of a trunk on its working-resolution grid, N x C (float): the
// reconstruction of a frame from its latent. Throws std::invalid_argument if the latent
// does not have latent_dim entries. A photometric trunk draws the markers of `markers`
// (the frame's own reference, estimation/data/photometric_markers.h) if given.
Eigen::MatrixXf Reconstruct(const SensorTrunk& trunk, const Eigen::VectorXf& latent,
                            const PhotometricTrunk::Markers* markers = nullptr);

class ReconstructionEvaluator {
 public:
  struct Options {
    // Worker threads over frames, >= 1. Results do not depend on it.
    int threads = 1;
    // Also compare with the noise-free frames when the dataset has them.
    bool clean = true;
    // The contact test; its encoding is set per sensor from the dataset.
    ContactOptions contact;
    // The processes sharing the run (models/core/process_group.h; `mpirun ... tactfunc
    // recon`, docs/SCALING.md); null = this process alone. Each process evaluates its
    // OwnItems of the entries, and every process receives all of them (GatherItems), so
    // the Summary is the same on every process and does not depend on their number.
    const ProcessGroup* processes = nullptr;
    bool IsValid(std::string* error) const;
  };

  struct FrameResult {
    std::string id;
    SensorKind sensor = SensorKind::kSoftBubble;
    Split split = Split::kTrain;
    std::size_t dataset_index = 0;                                 // index into Dataset::frames()
    double psnr = std::numeric_limits<double>::quiet_NaN();        // vs the noisy frame
    double psnr_clean = std::numeric_limits<double>::quiet_NaN();  // vs clean; NaN if none
    double psnr_zero = std::numeric_limits<double>::quiet_NaN();   // z = 0 vs noisy
    // vs noisy, peak = the source-resolution range (PsnrSourcePeak)
    double psnr_source_peak = std::numeric_limits<double>::quiet_NaN();
    // Of the noisy target, normalised units: its range R over the valid pixels (the
    // peak of psnr; 0 without valid pixels), its source-resolution range (the peak of
    // psnr_source_peak) and the reconstruction's RMSE (NaN without valid pixels).
    double target_range = 0;
    double source_range = 0;
    double rmse = std::numeric_limits<double>::quiet_NaN();
    // The contact test of the raw frame against its reference (DetectContact), and the
    // centres of the change in the frame and in the reconstruction, in source pixels
    // (row, col; NaN when the image holds no change).
    bool contact = false;
    double contact_score = 0;
    double contact_row = std::numeric_limits<double>::quiet_NaN();
    double contact_col = std::numeric_limits<double>::quiet_NaN();
    double recon_contact_row = std::numeric_limits<double>::quiet_NaN();
    double recon_contact_col = std::numeric_limits<double>::quiet_NaN();
  };

  struct GroupSummary {
    SensorKind sensor = SensorKind::kSoftBubble;
    Split split = Split::kTrain;
    PsnrStats noisy;  // psnr
    PsnrStats clean;  // psnr_clean (count 0 without clean frames)
    PsnrStats zero;   // psnr_zero
    PsnrStats source_peak;  // psnr_source_peak
    PsnrStats contact;      // psnr of the group's contact frames
    PsnrStats no_contact;   // psnr of the group's frames without contact
  };

  // Evaluation has no algorithmic outcome to report (no iteration, nothing to
  // converge), so this Summary holds figures and timings but no termination type:
  // it either completes or throws on bad input.
  struct Summary {
    std::vector<FrameResult> frames;   // in functaset order (by sensor, then entry)
    std::vector<GroupSummary> groups;  // per sensor (SensorKind order) and split
                                       // (train, test); only non-empty groups
    RepresentationSize size;
    bool has_clean = false;  // clean PSNRs were computed
    double seconds = 0;      // wall time
    // The group of (sensor, split), or nullptr.
    const GroupSummary* Find(SensorKind sensor, Split split) const;
    std::string BriefReport() const;  // one line
    std::string FullReport() const;   // a table
  };

  // Default options. (Not a default argument: GCC rejects a nested struct with member
  // initialisers there.)
  ReconstructionEvaluator();
  // Throws std::invalid_argument with IsValid's message for bad options.
  explicit ReconstructionEvaluator(const Options& options);

  // Evaluates every entry of `functaset`. Throws FunctasetModelMismatch if the
  // functaset was not encoded with `model` (Functaset::CheckModel), std::invalid_argument
  // if an entry's frame is not in `dataset`, and DatasetError for an unreadable frame.
  Summary Evaluate(const FunctaModel& model, const Functaset& functaset,
                   const Dataset& dataset) const;

 private:
  Options options_;
};

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_EVALUATION_RECONSTRUCTION_H_
