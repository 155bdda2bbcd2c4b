// Copyright 2026 The tactfunc Authors.
//
// The paper's Table I on a dataset ("Tactile Functasets", Tab. I): representation size,
// reconstruction PSNR and pose error of TactFunc against the baselines of
// estimation/evaluation/baselines.h, per sensor and split, plus the rate-distortion
// curves and the product's targets. `tactfunc eval` parses flags, calls Evaluate and
// prints / writes / draws the Result.
//
// Rows, per sensor and split (every frame of the functaset; the test rows are the
// held-out frames):
//   TactFunc    the functaset's latents decoded by the model's trunk; pose: the pose
//               model on latents of the kind it was trained on (LatentMapOfPoseModel):
//               the functaset's if its fit strategy is that map, else every frame
//               re-fitted with the map (the row's pose_from names it)
//   PCA         PcaCodec fitted on the train frames, as many components as the latent has
//               floats; pose: the same MLP architecture, trained as the pose model was
//               (its PoseModelProvenance: epochs, batch, learning rate, seed; train-pose's
//               defaults where it says nothing), on PCA codes
//   JPEG        8-bit JPEG, quality chosen on the train frames so that its mean bytes per
//               frame match the latent's bytes; no pose row
//   Raw frames  the frames uncompressed; PSNR not applicable; pose: ridge and k-NN on
//               downsampled pixels (stand-ins for the paper's ResNet-18)
// Every PSNR is THE PSNR of estimation/data/trunk_targets.h on the model's working-
// resolution frames; pose errors are scored as train-pose scores them (ScorePoses).
//
// Targets (test split, per sensor):
//   psnr_3db_above_pca      TactFunc >= 3 dB above PCA at equal bytes per frame (PCA
//                           with as many float32 components as the stored latent has
//                           bytes / 4), both measured against the (noisy) frames
//   psnr_3db_above_pca_clean
//                           the same against the noise-free frames, where the dataset has
//                           them (simulated data, `synth --clean`): the simulated sensor
//                           noise caps PSNR against noisy frames and would hide the gap
//   psnr_3db_above_pca_same_bits, psnr_3db_above_pca_same_bits_clean
//                           the same against PCA codes stored as the latents are (as many
//                           components as the latent has values, at the functaset's
//                           precision: float16 rounding or b-bit codes on the same kind
//                           of per-dimension grid), so both spend the same bits the same
//                           way: the fair baseline for a functaset with quantised latents
//                           (allocated codes: the same bytes per frame B, PCA keeping d
//                           components or a count of the ladder 1, 2, 3, 4, 6, 8, 12, ...
//                           up to 8 B, whichever scores best on the test split)
//   psnr_3db_above_pca_shared_bytes, psnr_3db_above_pca_shared_bytes_clean
//                           the same against PCA codes in the functaset's bytes per frame
//                           B (rounded down) with those bytes shared among their values
//                           as `encode --latent-bytes B` shares them, at the count that
//                           scores best: PCA's strongest codec at these bytes, whatever
//                           the functaset's own precision (for allocated codes the same
//                           figures as the line above). Reported beside the targets, not
//                           counted in all_targets_met (the product's target is the
//                           same-bits baseline); absent below one byte per frame
//   psnr_above_jpeg         TactFunc above JPEG at matched bytes
//   pose_beats_pca_codes    (pose sensor) pose MSE from latents below that from PCA codes
//   pose_not_worse_than_raw (pose sensor) pose MSE from latents <= the best raw-pixel one
//
// Without a pose model (Inputs::pose_model null: data without pose labels, or no
// pose model at hand) the table holds the reconstruction columns alone: every row's
// pose is empty (count 0, pose_from ""), no k-NN raw row, no pose targets
// (Targets::has_pose false, Details::pose empty) and Result::has_pose false.
//
// Errors: invalid Options or Inputs throw std::invalid_argument; data that cannot be
// evaluated (a functaset frame missing from the dataset, no train-split frames, no
// labelled train-split frames of the pose sensor, with a pose model) throws DatasetError
// naming the files.
#ifndef TACTFUNC_ESTIMATION_EVALUATION_TABLE_EVALUATION_H_
#define TACTFUNC_ESTIMATION_EVALUATION_TABLE_EVALUATION_H_

#include <cstddef>
#include <cstdint>
#include <limits>
#include <optional>
#include <string>
#include <vector>

#include "estimation/data/dataset.h"
#include "estimation/evaluation/baselines.h"
#include "estimation/functaset/functaset.h"
#include "models/core/process_group.h"
#include "models/core/sensor.h"
#include "models/pose/pose_mlp.h"
#include "models/trunk/functa_model.h"

namespace tactfunc {

class TableEvaluation {
 public:
  struct Options {
    // Worker threads for per-frame work. >= 1. Default 1.
    int threads = 1;
    // Block size of the pixel features of the raw-pixel pose baselines. >= 1. Default 2
    // (2x2 block means of the working-resolution frame).
    int raw_downsample = 2;
    // Neighbours of the raw-pixel k-NN pose baseline. >= 1. Default 5.
    int knn_k = 5;
    // JPEG qualities of the rate-distortion curve.
    std::vector<int> jpeg_curve_qualities = {1, 3, 5, 10, 20, 30, 50, 70, 90};
    // The processes sharing the run (models/core/process_group.h; `mpirun ... tactfunc
    // eval`, docs/SCALING.md); null = this process alone. The per-frame work -- decoding
    // the frames, TactFunc and extra functasets' reconstructions, JPEG coding, the
    // pose model's latent re-fits -- is shared out (ProcessGroup::OwnItems) and its
    // results gathered on every process (GatherItems); the fits over all frames (PCA,
    // the JPEG quality search, the pose baselines) run on every process alike. So the
    // Result is the same on every process and does not depend on their number.
    const ProcessGroup* processes = nullptr;

    bool IsValid(std::string* error) const;
  };

  // Another functaset of the same data (e.g. another latent size) with its model: a
  // further TactFunc point of the rate-distortion curves (test split).
  struct Extra {
    const FunctaModel* model = nullptr;
    const Functaset* functaset = nullptr;
    std::string functaset_name;  // for messages
  };

  // What is evaluated. The pointers must outlive Evaluate.
  struct Inputs {
    const Dataset* dataset = nullptr;
    std::string dataset_name;  // for messages
    const FunctaModel* model = nullptr;
    const Functaset* functaset = nullptr;  // checked against model by the caller
    std::string functaset_name;
    // The pose model of pose_sensor's latents (LoadPoseModelFor-checked by the caller),
    // or null: no pose columns or targets (header comment); pose_sensor is then unused.
    const PoseMlp* pose_model = nullptr;
    SensorKind pose_sensor = SensorKind::kSoftBubble;
    // The sensors to evaluate, in table order; each in the functaset and the dataset,
    // pose_sensor among them when there is a pose model.
    std::vector<SensorKind> sensors;
    std::vector<Extra> extras;
  };

  // Progress and log lines while Evaluate runs (all optional). Tick may be called from
  // worker threads; everything else from the calling thread.
  class Observer {
   public:
    virtual ~Observer() = default;
    // One line of the log, with its trailing newline.
    virtual void Message(const std::string& /*line*/) {}
    virtual void Warning(const std::string& /*line*/) {}
    // A task of `total` units ("frames", "epochs") begins / advances by one / ends.
    virtual void BeginTask(const std::string& /*label*/, std::int64_t /*total*/,
                           const std::string& /*unit*/) {}
    virtual void Tick() {}
    virtual void EndTask() {}
  };

  // One row of the table.
  struct Row {
    std::string approach;   // TactFunc, PCA, JPEG, Raw frames
    std::string pose_from;  // how the pose column was obtained ("" = no pose)
    SensorKind sensor = SensorKind::kSoftBubble;
    Split split = Split::kTrain;
    std::uint64_t rep_bytes = 0;  // model + per-frame data, all frames of the sensor
    double bytes_per_frame = std::numeric_limits<double>::quiet_NaN();
    double psnr = std::numeric_limits<double>::quiet_NaN();  // NaN: n/a or no finite value
    bool psnr_applicable = true;
    int frames = 0;
    PoseErrors pose;  // count 0: no pose
    std::string note;
    // The same PSNR against the noise-free frames (NaN: the dataset has none, or n/a).
    double psnr_clean = std::numeric_limits<double>::quiet_NaN();
    // The PSNR over the split's contact frames and over its frames at rest apart
    // (estimation/data/contact.h; NaN where none or n/a), and the number of contacts.
    int contact_frames = 0;
    double psnr_contact = std::numeric_limits<double>::quiet_NaN();
    double psnr_no_contact = std::numeric_limits<double>::quiet_NaN();
  };

  // A point of the rate-distortion curves (test split).
  struct RdPoint {
    double bytes_per_frame = 0;
    double psnr = std::numeric_limits<double>::quiet_NaN();
    std::string label;  // "d=64", "n=32", "q=20"
    // Against the noise-free frames; NaN where the test frames have none (and for JPEG).
    double psnr_clean = std::numeric_limits<double>::quiet_NaN();
  };
  // pca: float32 components; pca_same_storage: PCA codes stored as each functaset (the
  // main one, then each extra) stores its latents, at the component count that scores
  // best (against the noise-free frames where there are some), at that functaset's bytes.
  struct RdCurves {
    std::vector<RdPoint> tactfunc, pca, pca_same_storage, jpeg;
  };

  // The targets of one sensor (header comment), with the figures they compare.
  struct Targets {
    struct PsnrAbovePca {
      bool met = false;
      double tactfunc_db = 0, pca_db = 0, margin_db = 0;
      int required_margin_db = 3;
      int pca_components = 0;
      double bytes_per_frame = 0;
    };
    PsnrAbovePca psnr_above_pca;
    // Against the noise-free frames; filled (has_clean) only where the test frames have them.
    bool has_clean = false;
    PsnrAbovePca psnr_above_pca_clean;
    // Against PCA codes stored at the latents' precision (header comment); the clean
    // one only where has_clean.
    PsnrAbovePca psnr_above_pca_same_bits;
    PsnrAbovePca psnr_above_pca_same_bits_clean;
    // Against PCA codes in the same bytes per frame shared among their values (header
    // comment; reported, not counted in all_targets_met); filled where has_shared_bytes,
    // the clean one only where has_clean as well.
    bool has_shared_bytes = false;
    PsnrAbovePca psnr_above_pca_shared_bytes;
    PsnrAbovePca psnr_above_pca_shared_bytes_clean;
    struct PsnrAboveJpeg {
      bool met = false;
      double tactfunc_db = 0, jpeg_db = 0, margin_db = 0;
      double tactfunc_bytes_per_frame = 0, jpeg_bytes_per_frame = 0;
      int jpeg_quality = 0;
      bool jpeg_target_reachable = true;
    } psnr_above_jpeg;
    bool has_pose = false;  // the two below are filled for the pose sensor only
    struct PoseBeatsPca {
      bool met = false;
      double tactfunc_pose_mse = 0, pca_pose_mse = 0;
    } pose_beats_pca_codes;
    struct PoseNotWorseThanRaw {
      bool met = false;
      double tactfunc_pose_mse = 0, raw_best_pose_mse = 0, ridge_pose_mse = 0,
             knn_pose_mse = 0;
    } pose_not_worse_than_raw;
  };

  // How the baselines of one sensor were set up.
  struct Details {
    PcaCodec::Summary pca;  // of the fit with the most components
    int pca_components = 0;
    JpegQualitySearchSummary jpeg_search;
    JpegCodec::Options jpeg;  // the chosen quality and range
    std::uint64_t jpeg_table_bytes = 0;
    int rows = 0, cols = 0, channels = 0;  // working resolution
    std::uint64_t raw_frame_bytes = 0;
    // The pose sensor only.
    struct Pose {
      std::vector<int> mlp_hidden;
      PoseMlpTrainingOptions mlp_training;
      RidgePoseRegressor::Summary ridge;
      int raw_downsample = 0;
      std::int64_t raw_features = 0;
      int knn_k = 0;
      std::size_t labelled_train = 0, labelled_test = 0;
    };
    std::optional<Pose> pose;
  };

  struct SensorResult {
    SensorKind sensor = SensorKind::kSoftBubble;
    RdCurves curves;
    Targets targets;
    Details details;
  };

  struct Result {
    std::vector<Row> rows;               // in table order
    std::vector<SensorResult> sensors;   // in Inputs::sensors order
    bool all_targets_met = true;  // the reconstruction targets alone without a pose model
    bool has_pose = false;        // a pose model was given: pose_sensor has pose columns
    SensorKind pose_sensor = SensorKind::kSoftBubble;
  };

  // Evaluates; see the header comment. observer may be null.
  static Result Evaluate(const Inputs& inputs, const Options& options, Observer* observer);
};

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_EVALUATION_TABLE_EVALUATION_H_
