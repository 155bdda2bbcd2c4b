// Copyright 2026 The tactfunc Authors.
//
// Inputs the model-using subcommands share (fit, pose, bench posterior): reading one
// frame and its reference from the command line (sensor inferred from the file as
// Dataset::Open infers a user folder's), encode's fit of one frame, and the k-NN pose
// posterior over a functaset's labelled training latents.
#ifndef TACTFUNC_APPS_MODEL_INPUTS_H_
#define TACTFUNC_APPS_MODEL_INPUTS_H_

#include <memory>
#include <optional>

#include "nlohmann/json.hpp"
#include <string>

#include "estimation/data/dataset.h"
#include "estimation/functaset/functaset.h"
#include "estimation/functaset/latent_encoder.h"
#include "estimation/knn/knn_index.h"
#include "models/trunk/functa_model.h"
#include "models/core/image.h"
#include "models/pose/pose_generator.h"
#include "models/pose/pose_mlp.h"
#include "models/core/sensor.h"
#include "models/core/sensor_description.h"
#include "models/simulator/tool.h"  // SymmetryOrderOfTool
#include "estimation/posterior/knn_posterior.h"

namespace tactfunc::apps {

// The sensor of an image file: 16-bit one-channel = bubble, 8-bit = gelslim. Throws
// DatasetError naming `flag` and the path if the file is missing, unreadable or neither.
SensorKind InferSensor(const std::string& path, const std::string& flag);
// The image at `path` in `sensor`'s on-disk encoding; throws DatasetError naming `flag`.
Image ReadInput(const std::string& path, SensorKind sensor, const std::string& flag);
// "rows x cols x channels" of an image.
std::string Shape(const Image& image);
// Parses --sensor (empty = not given: returns false); throws UsageError for a bad name.
bool ParseSensorFlag(const std::string& text, SensorKind* sensor);
// Parses --sensors, a comma-separated list (empty = not given: returns {}), keeping the
// first of repeated names; throws UsageError naming --sensors for an unknown name.
std::vector<SensorKind> ParseSensorsFlag(const std::string& list);


// A frame and its no-contact reference given as files (--frame, --reference), with the
// sensor description of --sensor-file (if given) applied to both: its geometry, aspect
// and luma, so they are differenced on the grid the description's trunk models. The
// sensor is --sensor if given (it must be the description's kind), else the
// description's kind, else inferred from the frame (InferSensor). Throws UsageError for
// a --sensor that contradicts the description and DatasetError naming the flag and file
// for anything unreadable, a description that does not fit the frames, or a frame and
// reference of different shapes.
struct FramePair {
  Image frame;
  Image reference;
  SensorKind sensor = SensorKind::kSoftBubble;
  std::optional<SensorDescription> description;  // of --sensor-file
};
FramePair ReadFramePair(const std::string& frame_path, const std::string& reference_path,
                        const std::string& sensor_flag, const std::string& sensor_file);

// Pixel pitch (m) of `sensor` in the tactfunc dataset a frame file lies in
// (<dataset>/<sensor>/<id>.png with <dataset>/dataset.json), or 0 if it is not in one.
double DatasetPixelPitch(const std::string& frame_path, SensorKind sensor);

// One frame's latent fitted as `encode` fits it (LatentEncoder::EncodeTargets, with the
// encoder's strategy), the PSNR that fit reports, and its wall time: how fit, pose and
// bench posterior fit a photometric trunk's frame.
struct EncodedFrameFit {
  Eigen::VectorXd latent;
  double psnr = 0;
  double ms = 0;
};
EncodedFrameFit EncodeFrame(const LatentEncoder& encoder, SensorKind sensor,
                            const TrunkTargets& targets,
                            const PhotometricTrunk::Markers* markers = nullptr);

// The encoder of a photometric trunk's frames for pose posteriors under `pose_model`
// (from `pose_model_path`): the strategy of the functaset the pose MLP was trained on
// (PhotometricLatentMapOfPoseModel), so that it reads the kind of latent it saw. A pose
// model whose latent map the photometric trunk does not fit (a direct trunk's
// meta_sgd:K or ceres:N) throws DatasetError naming both files and the map. Its fits
// are not scored (EncodedFrameFit::psnr is NaN): a posterior needs the latent alone.
std::unique_ptr<LatentEncoder> PhotometricPoseEncoder(const FunctaModel& model,
                                                      const std::string& model_path,
                                                      SensorKind sensor,
                                                      const PoseMlp& pose_model,
                                                      const std::string& pose_model_path);

// A k-NN pose posterior over the labelled latents of one sensor of a functaset, with
// the brute-force index it searches (exact; copying the latents is the whole build, so
// it is built in memory rather than cached beside the functaset as fit's FLANN indexes
// are). Only the TRAIN split by default: a test frame must not find its own labelled
// entry (that would make bench posterior's k-NN coverage meaningless).
struct FunctasetKnn {
  std::unique_ptr<KnnIndex> index;  // brute force (BuildKnnIndex's default)
  std::unique_ptr<KnnPosterior> posterior;
  int size = 0;  // latents in the index
};
FunctasetKnn MakeFunctasetKnn(const Functaset& functaset, SensorKind sensor, bool train_only,
                              const KnnPosterior::Options& options,
                              const std::string& functaset_name);

// Loads a pose model (--pose-model) for the trunk of `sensor` in `model`: throws
// DatasetError naming the file when its input dimension is not the trunk's latent
// dimension, when its info is not a PoseModelProvenance (written by train-pose), or
// when that names another sensor or a functaset of another model checksum (a latent
// space it was not trained on).
// The frames a trunk was trained on, as `tactfunc train` records them in the model's
// info: {"trunks": {"<sensor>": {"data_frames": {"rows", "cols", "channels",
// "pixel_pitch_m"}}}}. DataFramesJson makes that record from a dataset's SensorInfo.
nlohmann::json DataFramesJson(const SensorInfo& info);

// Checks `dataset`'s `sensor` frames (from `data_path`) against the frames the model's
// trunk was trained on: their sensor descriptions (CheckModelDescription), then the record
// above (a model without one -- hand-built or older -- passes that part). Another frame
// size or channel count: throws DatasetError naming both files, both sizes and
// `override_flag` (which skips the throw, leaving a warning). Another pixel pitch (both
// known, more than 1 % apart) in a model without a description: a warning on stderr
// naming both. Warnings start with `command`.
void CheckModelMatchesData(const FunctaModel& model, const std::string& model_path,
                           const Dataset& dataset, const std::string& data_path,
                           SensorKind sensor, const std::string& command,
                           const std::string& override_flag, bool override_given);

// Checks the sensor description of the data (`data` from `data_where`, e.g. "--data 'DIR'
// (DIR/sensor.json)") against the one the model's `sensor` trunk was trained on
// (TrunkSensorDescription). What one side leaves open is not a difference: a data
// working size that is not set, a pitch either side does not know, the scale of data
// without a description file (`data_described` false: the kind's default, while
// preprocessing uses the model's scale anyway), and for a trunk without a recorded
// description (older files) the pitch and scale, which it never recorded. Any other difference in kind, channels, geometry (crop / perspective),
// working size, pitch or scale: throws DatasetError naming both sides and each
// differing field, or with `override_given` writes it as a warning starting with
// `command`.
void CheckModelDescription(const FunctaModel& model, const std::string& model_path,
                           const SensorDescription& data, const std::string& data_where,
                           SensorKind sensor, const std::string& command,
                           const std::string& override_flag, bool override_given,
                           bool data_described = true);

// Where a dataset's description of `sensor` came from, for messages:
// "--data 'DIR' (DIR/sensor.json)" or "--data 'DIR' (built-in gelslim description)".
std::string DataDescriptionWhere(const Dataset& dataset, const std::string& data_path,
                                 SensorKind sensor);

PoseMlp LoadPoseModelFor(const std::string& path, const FunctaModel& model, SensorKind sensor,
                         const std::string& model_path);

// Loads the pose generator at `path` (--generator) for the `sensor` trunk of `model`
// (loaded from model_path, for messages) and checks that it renders through that trunk:
// the latent dimension, and the trunk's checksum where the generator recorded the model
// it was trained on (`train-generator` writes "model_checksum" into its info). Another
// trunk of the same latent size would render garbage without a word. Throws DatasetError
// naming the file and what differs.
PoseGenerator LoadPoseGeneratorFor(const std::string& path, const FunctaModel& model,
                                   SensorKind sensor, const std::string& model_path);

// The model a pose generator renders through (--generator-model): `model` itself (owned
// empty, path model_path) when `path` is empty, else the model loaded from `path`, checked
// to have a `sensor` trunk that sees the frame at the format of `model`'s (the frame's
// targets are made once, for `model`; FrameFormat::SameAs). Throws DatasetError naming
// both models.
struct GeneratorModel {
  std::unique_ptr<FunctaModel> owned;  // null when the generator renders through --model
  const FunctaModel* model = nullptr;
  std::string path;
};
GeneratorModel LoadGeneratorModel(const std::string& path, const FunctaModel& model,
                                  const std::string& model_path, SensorKind sensor);

}  // namespace tactfunc::apps

#endif  // TACTFUNC_APPS_MODEL_INPUTS_H_
