// Copyright 2026 The tactfunc Authors.
//
// Functaset: the set of latents of a tactile dataset (Sec. III-B of "Tactile
// Functasets"). Every frame i of the dataset is stored as ONE short latent z_i in R^d
// that modulates its sensor's shared SIREN trunk (models/trunk/functa_model.h); the frame is
// recovered as f_theta(x; z_i) at every pixel x (estimation/evaluation/reconstruction.h). The
// functaset is what downstream models (k-NN, the pose MLP, SGLD) read instead of the
// raw frames.
//
// Per entry: the frame id (the dataset's file stem), its split, its pose label if it
// has one, the latent (latent_dim floats of its sensor's trunk) and the PSNR of the
// fit against the (noisy) frame it was encoded from (estimation/data/trunk_targets.h, Psnr).
// Entries are grouped by sensor (in SensorKind order); within a sensor they keep the
// order in which they were added (the encoder adds them in Dataset::frames() order).
//
// A functaset belongs to exactly one model: it records the model file's CRC-32
// (FunctaModel::checksum()) and CheckModel refuses any other model, because latents
// are meaningless under another trunk. It also records the dataset path it came from.
//
// On disk (docs/FUNCTASET.md): a TensorFile (models/core/tensor_file.h) of kind
// "functaset", written atomically, with the JSON meta
//   {"format": "tactfunc-functaset", "version": 1, "complete": true|false,
//    "model_checksum": <uint32>, "dataset": "<path>",
//    "sensors": [{"sensor": "bubble", "latent_dim": d, "count": M, "fit_strategy": "...",
//                 "products": "bf16" (absent: float),
//                 "ids": [M strings], "splits": [M of "train"|"test"],
//                 "tools": [M of tool name or null (unlabelled)]}, ...]}
// and per sensor the tensors
//   "<sensor>/latents"  float32 [M x d]   row i = latent of entry i (float16 at kFloat16)
//   "<sensor>/psnr"     float32 [M]       dB; NaN if the frame had no valid pixel
//   "<sensor>/poses"    float64 [M x 4]   x_m, y_m, yaw_rad, depth_m; NaN if unlabelled
// With b-bit latents (kUint8/6/4) "<sensor>/latents" is absent and the sensor's meta
// holds "latent_bits": b; instead
//   "<sensor>/latent_codes"   uint8   [M x B]  B = ceil(d b / 8): row i = the codes
//                                               q_0..q_{d-1} of entry i packed LSB-first
//                                               (q_k occupies bits k b .. k b + b - 1 of
//                                               the row), zero-padded to whole bytes
//   "<sensor>/latent_offset"  float32 [d]      lo_k = min_i z_ik
//   "<sensor>/latent_step"    float32 [d]      step_k = (max_i z_ik - lo_k) / (2^b - 1)
// and z_ik = lo_k + q_ik step_k, q_ik = round((z_ik - lo_k) / step_k) in [0, 2^b - 1]
// (q = 0 and step 0 for a dimension constant over the entries). With allocated codes
// (kAllocated) the sensor's meta holds "latent_bytes": B instead of "latent_bits", and
//   "<sensor>/latent_bits"    uint8   [d]      b_k in [0, 16], sum <= 8 B: dimension k's
//                                               bits (0: the dimension is not stored,
//                                               every entry reads lo_k)
//   "<sensor>/latent_codes"   uint8   [M x B]  q_k of b_k bits each, packed LSB-first one
//                                               after another, zero-padded to B bytes
//   "<sensor>/latent_offset", "<sensor>/latent_step"   as above, but each dimension's
//                                               grid is its least-squares grid
//                                               (latent_codes.h): values beyond its ends
//                                               read back as the nearest end
// Readers tell the layouts apart by the tensors present; the format version stays 1.
// The stored PSNR is that of the unrounded fit at every precision. A partial file
// (below) written with codes by the encoder holds float32 latents, so that resuming
// re-quantises nothing.
// "complete": false marks a partial file written by an interrupted or running encoder
// (estimation/functaset/latent_encoder.h), which `tactfunc encode --resume` continues.
//
// Errors: Load/Parse raise TensorFileError naming the file and the bad field or tensor
// (the container itself -- magic, version, kind, extents, CRC -- is checked by
// TensorFile); CheckModel raises FunctasetModelMismatch; Add raises
// std::invalid_argument for an entry that does not fit.
#ifndef TACTFUNC_ESTIMATION_FUNCTASET_FUNCTASET_H_
#define TACTFUNC_ESTIMATION_FUNCTASET_FUNCTASET_H_

#include <cstddef>
#include <cstdint>
#include <map>
#include <optional>
#include <stdexcept>
#include <string>
#include <unordered_map>
#include <vector>

#include <Eigen/Core>

#include "estimation/data/dataset.h"
#include "estimation/functaset/latent_codes.h"
#include "models/trunk/functa_model.h"
#include "models/core/sensor.h"

namespace tactfunc {

inline constexpr int kFunctasetVersion = 1;

// A functaset used with a model it was not encoded with.
class FunctasetModelMismatch : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

struct FunctasetEntry {
  std::string id;  // frame id in the dataset (file stem)
  Split split = Split::kTrain;
  std::optional<PoseLabel> label;  // absent for unlabelled frames
  Eigen::VectorXf latent;          // latent_dim of the sensor's trunk
  // PSNR (dB) of f(x; latent) against the noisy frame, as Psnr() defines it. NaN when
  // the frame has no valid pixel, +inf for an exact fit.
  float psnr = 0;
  // A frame at rest (no contact above the sensor's noise, estimation/data/contact.h)
  // whose latent is the sensor's shared rest latent (Functaset::rest_latent): stored
  // once per sensor, so such a frame costs no latent bytes.
  bool at_rest = false;
};

class Functaset {
 public:
  // Row-major M x d latent matrix (one latent per row), as k-NN indexes take them.
  using LatentMatrix = Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>;

  Functaset() = default;
  Functaset(std::uint32_t model_checksum, std::string dataset)
      : model_checksum_(model_checksum), dataset_(std::move(dataset)) {}

  // CRC-32 of the model file the latents belong to (FunctaModel::checksum()).
  std::uint32_t model_checksum() const { return model_checksum_; }
  void set_model_checksum(std::uint32_t checksum) { model_checksum_ = checksum; }
  // The dataset the frames came from (as given to the encoder; informational).
  const std::string& dataset() const { return dataset_; }
  void set_dataset(const std::string& dataset) { dataset_ = dataset; }
  // Storage precision of the latents in the file:
  //   kFloat32 (default)  4 bytes per latent value;
  //   kFloat16            IEEE binary16, 2 bytes, relative rounding error <= 2^-11 (its
  //                       PSNR cost is measured in docs/RESULTS_RECONSTRUCTION.md);
  //   kUint8/6/4          b-bit unsigned codes (b = 8, 6, 4) of a per-sensor, per-dimension
  //                       uniform grid over [min, max] of that dimension over the sensor's
  //                       entries: absolute error <= step_k / 2, step_k = range_k / (2^b - 1);
  //   kAllocated          latent_bytes() bytes per frame shared among the dimensions:
  //                       AllocateBits (latent_codes.h) gives each dimension its bits
  //                       (0-16) and LeastSquaresGrid its grid, both from the sensor's
  //                       entries: the least squared error the budget buys, not a bound.
  // In memory latents stay float; Save rounds or quantises, Load reads any of them,
  // hands out the rounded / dequantised values and reports which precision it read.
  enum class LatentPrecision { kFloat32, kFloat16, kUint8, kUint6, kUint4, kAllocated };
  LatentPrecision latent_precision() const { return latent_precision_; }
  void set_latent_precision(LatentPrecision precision) { latent_precision_ = precision; }
  // The bytes per frame of kAllocated codes (0 until set; Serialize of a kAllocated
  // functaset throws std::invalid_argument while it is below 1 or above 2 d, what 16 bits
  // per dimension fill, for any sensor's d).
  int latent_bytes() const { return latent_bytes_; }
  void set_latent_bytes(int bytes) { latent_bytes_ = bytes; }
  // Bytes one frame's latent of `sensor` takes on disk: 4 d, 2 d, ceil(d b / 8) (codes
  // of a frame are padded to whole bytes) or latent_bytes(). Throws like latent_dim().
  double BytesPerFrame(SensorKind sensor) const;
  // Bytes on disk shared by all of the sensor's frames for their latents: the b-bit
  // codes' offset and step tables (2 x d float32, 0 for float latents; allocated codes
  // add d bytes of bits per dimension) and the shared
  // rest latent (d float32) if the sensor has one.
  std::uint64_t SharedLatentBytes(SensorKind sensor) const;
  // Bits per latent dimension of the codes the sensor's latents were read with (Parse of
  // a code file); empty for float latents and for latents not read from a file.
  std::vector<int> code_bits(SensorKind sensor) const;
  // Entries whose latents are stored one per frame: those not at rest.
  std::int64_t NumStoredLatents(SensorKind sensor) const;

  // The latent every frame at rest of `sensor` shares (a fit to the frame with no
  // change), or null if the sensor has none. Set it before adding entries at rest;
  // entries already at rest take the new value. Throws std::invalid_argument for an
  // undeclared sensor or a latent of another dimension.
  const Eigen::VectorXf* rest_latent(SensorKind sensor) const;
  void set_rest_latent(SensorKind sensor, const Eigen::VectorXf& latent);

  // The rotational symmetry orders the dataset declared for its own tools (its
  // tools.csv, Dataset::tool_symmetries), carried so that pose training and evaluation
  // on the functaset fold yaw as the data says. Empty for files without them.
  const std::map<std::string, int>& tool_symmetries() const { return tool_symmetries_; }
  void set_tool_symmetries(std::map<std::string, int> orders) {
    tool_symmetries_ = std::move(orders);
  }
  // Declared here, else the built-in tool's (SymmetryOrderOfTool), else 1.
  int ToolSymmetryOrder(const std::string& tool, bool* known = nullptr) const;

  // False for a partial functaset (an interrupted or running encoder's checkpoint).
  bool complete() const { return complete_; }
  void set_complete(bool complete) { complete_ = complete; }

  // Declares a sensor with its latent dimension (>= 1). Declaring it again with the
  // same dimension does nothing; another dimension throws std::invalid_argument.
  void AddSensor(SensorKind sensor, int latent_dim);
  bool has_sensor(SensorKind sensor) const;
  // The sensors declared, in SensorKind order.
  std::vector<SensorKind> sensors() const;
  // Throws std::invalid_argument naming the sensor if it was not declared.
  int latent_dim(SensorKind sensor) const;
  // How the sensor's latents were fitted: a fit strategy as LatentFitter names it
  // ("meta_sgd:3", "ceres:20"; estimation/fitting/latent_fitter.h). "" for files written
  // before the field existed (their encoder ran the trunk's meta-SGD inner loop).
  // Throws like latent_dim().
  const std::string& fit_strategy(SensorKind sensor) const;
  void set_fit_strategy(SensorKind sensor, const std::string& strategy);
  // The precision of the trunk's matrix products the sensor's latents were fitted with:
  // "float", or "bf16" (`encode --products bf16`; models/trunk/product_precision.h).
  // "float" for files without the field. Throws like latent_dim(); set_products also
  // for any other value.
  const std::string& products(SensorKind sensor) const;
  void set_products(SensorKind sensor, const std::string& products);

  // Appends an entry to a declared sensor. An entry at rest takes the sensor's rest
  // latent (its own latent is ignored). Throws std::invalid_argument if the sensor is
  // not declared, the latent does not have latent_dim(sensor) entries (not checked at
  // rest), an entry is at rest but the sensor has no rest latent, the id is empty or
  // (sensor, id) is already present.
  void Add(SensorKind sensor, FunctasetEntry entry);
  // The entries of one sensor, in the order added. Throws like latent_dim().
  const std::vector<FunctasetEntry>& entries(SensorKind sensor) const;
  // Index into entries(sensor) of frame `id`, or nullopt.
  std::optional<std::size_t> Find(SensorKind sensor, const std::string& id) const;
  // Entries over all sensors.
  std::size_t size() const;

  // The latents of one sensor (optionally of one split), M x d, in entry order.
  LatentMatrix Latents(SensorKind sensor, std::optional<Split> split = std::nullopt) const;

  // Throws FunctasetModelMismatch if `model` is not the model the latents were encoded
  // with: "functaset F was encoded with model checksum 0x..., but model M has 0x...".
  // Also if the model lacks a trunk for one of the functaset's sensors or its latent
  // dimension differs. `functaset_name` and `model_name` (paths) are for the message.
  void CheckModel(const FunctaModel& model, const std::string& model_name = "the model",
                  const std::string& functaset_name = "") const;

  // Writes atomically (models/core/atomic_file.h). Throws std::runtime_error naming the path.
  void Save(const std::string& path) const;
  // Throws TensorFileError naming the file and what is wrong.
  static Functaset Load(const std::string& path);
  std::string Serialize() const;
  // `source` names the bytes in messages (a path).
  static Functaset Parse(const std::string& bytes, const std::string& source);

  // The file this functaset was loaded from ("" if not loaded).
  const std::string& source() const { return source_; }

 private:
  // A sensor's grids, one per dimension: z_k = offset + q_k step (float32 in the file),
  // q_k of grids[k].bits bits.
  struct CodeTable {
    LatentPrecision precision = LatentPrecision::kUint8;
    int bytes = 0;  // kAllocated: the bytes per frame the bits were allocated for
    std::vector<LatentGrid> grids;
  };
  struct SensorBlock {
    int latent_dim = 0;
    // The grid the entries were read with (Load of a b-bit file); Serialize reuses it
    // while every latent still lies on it, so a second save writes the same codes.
    std::optional<CodeTable> codes;
    std::string fit_strategy;
    std::string products = "float";
    std::optional<Eigen::VectorXf> rest_latent;
    std::vector<FunctasetEntry> entries;
    std::unordered_map<std::string, std::size_t> index;  // id -> entries position
  };
  const SensorBlock& Block(SensorKind sensor) const;
  // The grids Serialize writes the block's latents on at the functaset's precision.
  CodeTable Codes(const SensorBlock& block) const;

  std::uint32_t model_checksum_ = 0;
  std::string dataset_;
  bool complete_ = true;
  LatentPrecision latent_precision_ = LatentPrecision::kFloat32;
  int latent_bytes_ = 0;
  std::map<SensorKind, SensorBlock> blocks_;
  std::map<std::string, int> tool_symmetries_;
  std::string source_;
};

// "float32", "float16", "uint8", "uint6", "uint4", "allocated".
const char* ToString(Functaset::LatentPrecision precision);
// Parses ToString's names; false for anything else.
bool LatentPrecisionFromString(const std::string& name, Functaset::LatentPrecision* precision);
// Bits per stored latent value: 32, 16, 8, 6 or 4; 0 for kAllocated (per dimension).
int LatentBits(Functaset::LatentPrecision precision);
// True for the code precisions (kUint8, kUint6, kUint4, kAllocated).
bool IsQuantised(Functaset::LatentPrecision precision);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_FUNCTASET_FUNCTASET_H_
