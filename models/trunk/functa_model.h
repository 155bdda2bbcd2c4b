// Copyright 2026 The tactfunc Authors.
//
// FunctaModel: what a model file (.tfm) holds -- for each sensor, the meta-learned
// latent-modulated SIREN trunk (models/trunk/latent_modulated_siren.h), its per-dimension
// meta-SGD rates alpha (models/trunk/meta_sgd.h) and the frame format that turns a sensor's
// frames into the trunk's targets (working resolution, grayscale, normalisation).
//
// One trunk per sensor. The paper trains one trunk on the combined Bubble + GelSlim
// data; we keep one per sensor because the two differ in resolution, physics and
// statistics, so each trunk can be the smallest that meets its sensor's accuracy
// ("model only what a scene requires"). A model file may hold one or both.
//
// On disk (a TensorFile of kind "model", models/core/tensor_file.h): the JSON meta holds
// {"format": "tactfunc-model", "version": 1, "trunks": [{"sensor", "siren": {...},
// "frame_format": {...}, "meta_sgd": {...}, "residual_sigma"}], "info": {...}} and
// the tensors "<sensor>/theta" (float32, the trunk's flat parameters in
// LatentModulatedSiren's layout) and "<sensor>/alpha" (float32, latent_dim). A trunk with
// the linear readout branch records its grid as "siren": {..., "readout": {"rows",
// "cols", "basis": "float16"}}: its basis is the tensor "<sensor>/readout_basis"
// (float16, the basis block of theta in theta's order) and "<sensor>/theta" holds every
// other parameter (the branch's mean last). Files whose "readout" has no "basis" hold the
// whole flat vector, basis included, in theta as float32; files without "readout" load as
// trunks without the branch. Its start gains, if any
// (LatentModulatedSiren::set_start_gains), are the tensor "<sensor>/start_gains"
// (float32, latent_dim); files without it load without gains. A trunk with spatial
// latents records its grid as "siren": {..., "spatial": {"rows", "cols", "channels",
// "global_latent_dim", "layout"}} (layout: how z and the modulation matrix split, one
// fixed string today); files without the key load as trunks with one global latent. A
// trunk trained on described frames records the description as "sensor_description"
// (the file format of models/core/sensor_description.h, "pixel_pitch_mm": 0 for an
// unknown pitch); files without it load without one. A trunk with the photometric head records it as
// "photometric": {"latent_dim", "shading_width", "supersample", "reference": {"rows",
// "cols", "channels"}} with the tensors "<sensor>/head" (float32, the head's parameters)
// and "<sensor>/reference" (float32, the sensor-resolution reference, HWC); files
// without the key load as direct trunks. Its warm-start table, if any, is recorded as
// "photometric": {..., "warm_start": {"rows", "grid", "extent", "supersample"}} with the
// tensors "<sensor>/warm_start/descriptors" and "<sensor>/warm_start/latents" (float16,
// rows x grid^2 C and rows x d). Loading checks every field and shape and names
// the file and field on error.
#ifndef TACTFUNC_MODELS_TRUNK_FUNCTA_MODEL_H_
#define TACTFUNC_MODELS_TRUNK_FUNCTA_MODEL_H_

#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "models/trunk/latent_modulated_siren.h"
#include "models/trunk/meta_sgd.h"
#include "models/trunk/photometric_trunk.h"
#include "models/core/sensor.h"
#include "models/core/sensor_description.h"

namespace tactfunc {

class TensorFile;

// How one sensor's frames become trunk targets; mirrors estimation/data/preprocess.h's
// PreprocessOptions (stored here because models/ does not depend on estimation/).
struct FrameFormat {
  int rows = 0;              // working resolution (area interpolation), > 0
  int cols = 0;
  bool grayscale = false;    // rgb -> luma before fitting
  bool per_image_min_max = false;  // false: fixed physical scale (a blank frame stays 0)
  double scale = 0;          // fixed scale: the physical difference that maps to 1.0, > 0
  bool IsValid(std::string* error) const;
  // The same working frame: equal size, channels and normalisation, so that one set of
  // targets serves two trunks.
  bool SameAs(const FrameFormat& other) const {
    return rows == other.rows && cols == other.cols && grayscale == other.grayscale &&
           per_image_min_max == other.per_image_min_max && scale == other.scale;
  }
};

// A photometric trunk's warm-start table (estimation/training/photometric_warm_start.h):
// one row per training frame, its descriptor (grid x grid cells x the trunk's channels of
// its targets in its moment frame, `extent` the square's half-width in the trunk's
// isotropic units, `supersample` samples per cell and side) and its latent with the
// contact frame relative to the moment frame. Stored as float16.
struct WarmStartTable {
  int grid = 0;
  double extent = 0;
  int supersample = 0;
  Eigen::MatrixXf descriptors;  // n x grid * grid * channels
  Eigen::MatrixXf latents;      // n x d
};

struct SensorTrunk {
  SensorKind sensor = SensorKind::kSoftBubble;
  FrameFormat format;
  LatentModulatedSiren siren{LatentModulatedSiren::Options()};
  Eigen::VectorXd alpha;     // meta-SGD inner rates, size latent_dim, each in [0, 1]
  MetaSgd::Options meta_sgd;
  // Standard deviation of the per-pixel fit residual on the training frames
  // (normalised units); the likelihood scale of the posterior samplers. 0 = unknown.
  double residual_sigma = 0;
  // The sensor description of the frames the trunk was trained on
  // (models/core/sensor_description.h), its working size the format's. Absent in files
  // written before descriptions (and in hand-built trunks): TrunkSensorDescription then
  // gives the built-in description of the trunk's kind.
  std::optional<SensorDescription> description;
  // The photometric head of an optical sensor's trunk (models/trunk/photometric_trunk.h;
  // docs/REPRESENTATION.md): absent (null) for the direct trunk. With it a frame's
  // latent has photometric->latent_dim() values (its rigid motion first), `siren` is a
  // copy of the head's SIREN (latent_dim three less) and alpha, meta_sgd are unused
  // (alpha holds zeros): its latents are fitted by FitPhotometricLatent
  // (estimation/training/photometric_trainer.h), not by meta-SGD.
  std::shared_ptr<const PhotometricTrunk> photometric;
  // With the photometric head: the table its fits can start from (null: none; files
  // written before tables, and trunks trained without one).
  std::shared_ptr<const WarmStartTable> warm_start;
  // The fit `encode` and `fit` use for this trunk when none is asked for (a strategy's
  // name, estimation/fitting/latent_fitter.h, e.g. "knn+adam:400"), recorded by `train
  // --default-fit` for a trunk whose documented quality needs more than the encoder's
  // rule gives. Empty (the default, and files written before it): the encoder's rule
  // (LatentEncoder). Checked against the trunk's kind where it is used.
  std::string default_fit;
};

// The values of one frame's latent under `trunk`: the photometric head's d, else the
// SIREN's latent_dim.
int TrunkLatentDim(const SensorTrunk& trunk);
// The channels of the trunk's targets: the photometric head's C, else the SIREN's outputs.
int TrunkOutputChannels(const SensorTrunk& trunk);
// The whole working-resolution frame the trunk draws for `latent` (TrunkLatentDim
// values): rows * cols x C, pixel j = row * cols + col. Throws std::invalid_argument for
// a latent of another size. A photometric head draws the markers of `markers` (its
// frame's own reference, PhotometricTrunk::MakeMarkers) if given, else its own.
Eigen::MatrixXf TrunkDecode(const SensorTrunk& trunk, const Eigen::VectorXf& latent,
                            const PhotometricTrunk::Markers* markers = nullptr);
// Bytes of the trunk as stored: its parameters and rates (float32; a readout branch's
// basis float16), and with the photometric head the head's parameters and its
// sensor-resolution reference (float32) and its warm-start table (float16).
std::uint64_t TrunkParameterBytes(const SensorTrunk& trunk);

// The trunk's description, or for a trunk without one the built-in description of its
// kind with the format's working size (aspect "stretch": such trunks resized whatever
// they got), the trunk's output channels (unless grayscale) and a fixed-scale format's
// scale. Its pitch is unknown.
SensorDescription TrunkSensorDescription(const SensorTrunk& trunk);

class FunctaModel {
 public:
  // Adds (or replaces) the trunk of trunk.sensor. Throws std::invalid_argument if alpha
  // does not have latent_dim entries or the format is invalid.
  void SetTrunk(SensorTrunk trunk);
  bool HasSensor(SensorKind sensor) const;
  // Throws std::invalid_argument naming the sensor if the model has no trunk for it.
  const SensorTrunk& Trunk(SensorKind sensor) const;
  SensorTrunk& MutableTrunk(SensorKind sensor);
  std::vector<SensorKind> sensors() const;

  // Free-form JSON object stored with the model: preset name, training summary.
  const std::string& info_json() const { return info_json_; }
  void set_info_json(const std::string& json);  // throws if not a JSON object

  // Atomic write; returns nothing, sets checksum().
  void Save(const std::string& path) const;
  // Throws TensorFileError (models/core/tensor_file.h) naming the file and what is wrong.
  static FunctaModel Load(const std::string& path);
  // Serialised form, as Save writes it.
  std::string Serialize() const;
  static FunctaModel Parse(const std::string& bytes, const std::string& source);

  // CRC-32 of the model file as last saved or loaded: a functaset names its model so.
  std::uint32_t checksum() const { return checksum_; }
  // Bytes of the trunk parameters and rates as stored (float32), for compression ratios.
  std::uint64_t ParameterBytes() const;

 private:
  static FunctaModel FromTensorFile(const TensorFile& file, const std::string& source);

  std::vector<SensorTrunk> trunks_;
  std::string info_json_ = "{}";
  mutable std::uint32_t checksum_ = 0;
};

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_TRUNK_FUNCTA_MODEL_H_
