// Copyright 2026 The tactfunc Authors.
#include "estimation/evaluation/table_evaluation.h"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <map>
#include <optional>
#include <set>
#include <stdexcept>
#include <utility>

#include "estimation/data/contact.h"
#include "estimation/data/image_io.h"
#include "estimation/data/photometric_markers.h"
#include "estimation/data/trunk_targets.h"
#include "estimation/evaluation/reconstruction.h"
#include "estimation/fitting/latent_fitter.h"
#include "estimation/functaset/latent_codes.h"
#include "estimation/posterior/pose_posterior.h"
#include "models/core/parallel_for.h"
#include "models/pose/pose_model_provenance.h"
#include "models/simulator/tool.h"

namespace tactfunc {
namespace {

// The most components PCA codes in B allocated bytes per frame may keep: 8 B, each at one
// bit (the top of eval's ladder of component counts).
int LadderTop(int bytes) { return 8 * bytes; }

using Observer = TableEvaluation::Observer;
using Row = TableEvaluation::Row;
using RdCurves = TableEvaluation::RdCurves;

constexpr double kNan = std::numeric_limits<double>::quiet_NaN();

// Mean of the finite values (ComputePsnrStats' rule: NaN and +inf left out).
double MeanPsnr(const std::vector<double>& values) { return ComputePsnrStats(values).mean; }

// Per-frame work shared over the processes (Options::processes): compute(i, &out) packs
// item i's result for this process's items of [0, n) (ProcessGroup::OwnItems) on
// `threads` workers; then read(i, in) unpacks every item's, in item order, whichever
// process computed it (GatherItems). Results travel as the bits computed, so every
// process ends with the same values as one process alone. The observer's task (if any)
// ticks size() times per own item -- the other processes advance alike -- and is topped
// up to n once all results are in.
template <typename Compute, typename Read>
void ShardedFor(const ProcessGroup& group, std::size_t n, int threads, Observer* observer,
                const Compute& compute, const Read& read) {
  const std::int64_t count = static_cast<std::int64_t>(n);
  const std::vector<std::int64_t> own = group.OwnItems(count);
  std::vector<Bytes> mine(own.size());
  std::atomic<std::int64_t> ticked{0};
  internal::ParallelFor(static_cast<int>(own.size()), threads, [&](int k) {
    ByteWriter out;
    compute(static_cast<std::size_t>(own[k]), &out);
    mine[k] = std::move(out.bytes());
    if (observer == nullptr) return;
    for (int t = 0; t < group.size() && ticked.fetch_add(1) < count; ++t) observer->Tick();
  });
  if (observer != nullptr) {
    for (std::int64_t t = std::min(ticked.load(), count); t < count; ++t) observer->Tick();
  }
  const std::vector<Bytes> all = group.GatherItems(count, mine);
  for (std::size_t i = 0; i < n; ++i) {
    ByteReader in(all[i]);
    read(i, in);
  }
}

void PutTargets(const TrunkTargets& t, ByteWriter* out) {
  out->Put<std::int64_t>(t.values.rows());
  out->Put<std::int64_t>(t.values.cols());
  out->PutFloats(t.values.data(), static_cast<std::size_t>(t.values.size()));
  out->PutFloats(t.weights.data(), static_cast<std::size_t>(t.weights.size()));
  out->Put<std::uint8_t>(t.flat ? 1 : 0);
  out->Put(t.scale);
  out->Put(t.offset);
  out->Put(t.source_range);
  out->Put(t.rows);
  out->Put(t.cols);
}

// Reads what PutTargets wrote; throws std::runtime_error on arrays of inconsistent sizes.
TrunkTargets GetTargets(ByteReader& in) {
  TrunkTargets t;
  const auto rows = in.Get<std::int64_t>();
  const auto cols = in.Get<std::int64_t>();
  const std::size_t values = in.FloatCount();
  if (rows < 0 || cols < 0 || values != static_cast<std::size_t>(rows * cols)) {
    throw std::runtime_error("eval: frame targets of " + std::to_string(values) +
                             " values for " + std::to_string(rows) + " x " +
                             std::to_string(cols) + " came from another process");
  }
  t.values.resize(rows, cols);
  in.GetFloats(t.values.data(), values);
  const std::size_t weights = in.FloatCount();
  if (weights != static_cast<std::size_t>(rows)) {
    throw std::runtime_error("eval: frame targets of " + std::to_string(weights) +
                             " weights for " + std::to_string(rows) +
                             " pixels came from another process");
  }
  t.weights.resize(rows);
  in.GetFloats(t.weights.data(), weights);
  t.flat = in.Get<std::uint8_t>() != 0;
  t.scale = in.Get<double>();
  t.offset = in.Get<double>();
  t.source_range = in.Get<double>();
  t.rows = in.Get<int>();
  t.cols = in.Get<int>();
  return t;
}

// One sensor's frames as every approach sees them.
struct SensorFrames {
  SensorKind sensor = SensorKind::kSoftBubble;
  const SensorTrunk* trunk = nullptr;
  std::vector<const FunctasetEntry*> entries;  // the functaset's, in its order
  std::vector<TrunkTargets> targets;           // the same frames at the working resolution
  // Their noise-free versions, where the dataset has them (simulated data).
  std::vector<std::optional<TrunkTargets>> clean;
  std::vector<std::size_t> train, test;        // indices into entries
  // Whether each entry's raw frame is a contact (DetectFrameContact).
  std::vector<char> contact;
  // A functaset of test entries only (encode --split test): the dataset's train-split
  // frames, loaded for the baselines (PCA's basis, JPEG's range and quality) alone.
  std::vector<TrunkTargets> baseline_train;
  // The frames the baselines are fitted on: the train entries', else baseline_train.
  std::vector<const TrunkTargets*> BaselineTrain() const {
    if (!train.empty()) return Targets(train);
    std::vector<const TrunkTargets*> out;
    for (const TrunkTargets& t : baseline_train) out.push_back(&t);
    return out;
  }
  const std::vector<std::size_t>& Of(Split split) const {
    return split == Split::kTrain ? train : test;
  }
  // The indices of `indices` whose frames are (or are not) contacts.
  std::vector<std::size_t> WithContact(const std::vector<std::size_t>& indices, bool is) const {
    std::vector<std::size_t> out;
    for (std::size_t i : indices) {
      if ((contact[i] != 0) == is) out.push_back(i);
    }
    return out;
  }
  std::vector<const TrunkTargets*> Targets(const std::vector<std::size_t>& indices) const {
    std::vector<const TrunkTargets*> out;
    for (std::size_t i : indices) out.push_back(&targets[i]);
    return out;
  }
};

// Every process ends with every frame's targets (each decodes its share of the frames).
SensorFrames LoadSensorFrames(const TableEvaluation::Inputs& in, const SensorTrunk& trunk,
                              const ProcessGroup& group, int threads, Observer* observer) {
  SensorFrames s;
  s.sensor = trunk.sensor;
  s.trunk = &trunk;
  std::vector<std::size_t> dataset_index;
  for (const FunctasetEntry& e : in.functaset->entries(trunk.sensor)) {
    const std::optional<std::size_t> index = in.dataset->FindFrame(e.id, trunk.sensor);
    if (!index) {
      throw DatasetError("dataset '" + in.dataset_name + "' has no " + ToString(trunk.sensor) +
                         " frame '" + e.id + "' of functaset '" + in.functaset_name +
                         "' (a functaset of another dataset?)");
    }
    (e.split == Split::kTrain ? s.train : s.test).push_back(s.entries.size());
    s.entries.push_back(&e);
    dataset_index.push_back(*index);
  }
  s.targets.resize(s.entries.size());
  s.clean.resize(s.entries.size());
  s.contact.assign(s.entries.size(), 0);
  if (observer) {
    observer->BeginTask(std::string("eval: loading ") + ToString(trunk.sensor),
                        static_cast<std::int64_t>(s.entries.size()), "frames");
  }
  ShardedFor(
      group, s.entries.size(), threads, observer,
      [&](std::size_t i, ByteWriter* out) {
        const Image frame = in.dataset->LoadFrame(dataset_index[i]);
        PutTargets(DatasetFrameTargets(*in.dataset, dataset_index[i], frame, trunk.format), out);
        out->Put<std::uint8_t>(DetectFrameContact(*in.dataset, dataset_index[i], frame).contact);
        const bool clean = in.dataset->has_clean() &&
                           !in.dataset->frames()[dataset_index[i]].clean_path.empty();
        out->Put<std::uint8_t>(clean);
        if (clean) {
          PutTargets(LoadTrunkTargets(*in.dataset, dataset_index[i], trunk.format, /*clean=*/true),
                     out);
        }
      },
      [&](std::size_t i, ByteReader& in) {
        s.targets[i] = GetTargets(in);
        s.contact[i] = in.Get<std::uint8_t>() != 0 ? 1 : 0;
        if (in.Get<std::uint8_t>() != 0) s.clean[i] = GetTargets(in);
      });
  if (observer) observer->EndTask();
  if (!s.train.empty() || s.entries.empty()) return s;
  const std::vector<std::size_t> train = in.dataset->FrameIndices(trunk.sensor, Split::kTrain);
  if (train.empty()) {
    throw DatasetError("functaset '" + in.functaset_name + "' has no train-split " +
                       ToString(trunk.sensor) + " entries and dataset '" + in.dataset_name +
                       "' no train-split " + ToString(trunk.sensor) +
                       " frames: the baselines are fitted on those");
  }
  s.baseline_train.resize(train.size());
  if (observer) {
    observer->BeginTask(std::string("eval: loading ") + ToString(trunk.sensor) +
                            " train frames for the baselines",
                        static_cast<std::int64_t>(train.size()), "frames");
  }
  ShardedFor(
      group, train.size(), threads, observer,
      [&](std::size_t i, ByteWriter* out) {
        PutTargets(LoadTrunkTargets(*in.dataset, train[i], trunk.format), out);
      },
      [&](std::size_t i, ByteReader& in) { s.baseline_train[i] = GetTargets(in); });
  if (observer) observer->EndTask();
  return s;
}

// Per-frame PSNR of f(grid; z) for every entry of `frames` with the latents of `entries`,
// and, if `clean` is given, against the noise-free frames it holds (NaN where none).
// A photometric trunk draws each entry against its own frame's reference in `dataset`.
std::vector<double> LatentPsnrs(const SensorTrunk& trunk, const Dataset& dataset,
                                const std::vector<const FunctasetEntry*>& entries,
                                const std::vector<const TrunkTargets*>& targets,
                                const ProcessGroup& group, int threads,
                                const std::string& label, Observer* observer,
                                const std::vector<std::optional<TrunkTargets>>* clean = nullptr,
                                std::vector<double>* psnr_clean = nullptr) {
  std::vector<double> psnr(entries.size(), kNan);
  if (psnr_clean != nullptr) psnr_clean->assign(entries.size(), kNan);
  std::optional<DatasetMarkers> markers;
  if (trunk.photometric != nullptr) markers.emplace(dataset, trunk);
  auto markers_of = [&](const FunctasetEntry& entry) -> const PhotometricTrunk::Markers* {
    if (!markers) return nullptr;
    const std::optional<std::size_t> index = dataset.FindFrame(entry.id, trunk.sensor);
    if (!index) {
      throw DatasetError("the dataset has no " + std::string(ToString(trunk.sensor)) +
                         " frame '" + entry.id + "' to draw the markers of");
    }
    return markers->Of(*index);
  };
  if (observer) observer->BeginTask(label, static_cast<std::int64_t>(entries.size()), "frames");
  ShardedFor(
      group, entries.size(), threads, observer,
      [&](std::size_t i, ByteWriter* out) {
        const Eigen::MatrixXf prediction =
            Reconstruct(trunk, entries[i]->latent, markers_of(*entries[i]));
        out->Put(Psnr(prediction, *targets[i]));
        out->Put(clean != nullptr && (*clean)[i] ? Psnr(prediction, *(*clean)[i]) : kNan);
      },
      [&](std::size_t i, ByteReader& in) {
        psnr[i] = in.Get<double>();
        const double c = in.Get<double>();
        if (psnr_clean != nullptr) (*psnr_clean)[i] = c;
      });
  if (observer) observer->EndTask();
  return psnr;
}

std::vector<double> Pick(const std::vector<double>& values, const std::vector<std::size_t>& idx) {
  std::vector<double> out;
  for (std::size_t i : idx) out.push_back(values[i]);
  return out;
}

// Labelled frames of one split as pose samples.
// PCA codes of n components stored as a functaset stores latents: the test split's mean
// PSNR against the frames and against the noise-free ones (NaN where none).
struct StoredPca {
  int n = 0;
  double psnr = 0, psnr_clean = 0;
};

struct PoseSamples {
  std::vector<std::size_t> frames;  // indices into SensorFrames::entries
  PoseTargets targets;
};

PoseSamples LabelledSamples(const SensorFrames& s, const Dataset& dataset, Split split) {
  PoseSamples p;
  for (std::size_t i : s.Of(split)) {
    if (s.entries[i]->label.has_value()) p.frames.push_back(i);
  }
  const int m = static_cast<int>(p.frames.size());
  p.targets.poses.resize(m, 3);
  p.targets.symmetry_orders.resize(m);
  for (int k = 0; k < m; ++k) {
    const PoseLabel& label = *s.entries[p.frames[k]]->label;
    const SE2d& pose = label.sensor_T_object;
    p.targets.poses.row(k) << pose.x(), pose.y(), pose.yaw();
    p.targets.symmetry_orders[k] = dataset.ToolSymmetryOrder(label.tool);
  }
  return p;
}

// Rows of `source` (one per frame of s.entries) picked for the samples.
Eigen::MatrixXf Rows(const Eigen::MatrixXf& source, const std::vector<std::size_t>& frames) {
  Eigen::MatrixXf out(static_cast<Eigen::Index>(frames.size()), source.cols());
  for (std::size_t k = 0; k < frames.size(); ++k) out.row(k) = source.row(frames[k]);
  return out;
}

void CheckInputs(const TableEvaluation::Inputs& in, const TableEvaluation::Options& options) {
  std::string error;
  if (!options.IsValid(&error)) throw std::invalid_argument(error);
  if (in.dataset == nullptr || in.model == nullptr || in.functaset == nullptr) {
    throw std::invalid_argument(
        "TableEvaluation::Inputs: dataset, model and functaset must be set");
  }
  if (in.sensors.empty()) throw std::invalid_argument("TableEvaluation::Inputs: no sensor");
  if (in.pose_model != nullptr &&
      std::find(in.sensors.begin(), in.sensors.end(), in.pose_sensor) == in.sensors.end()) {
    throw std::invalid_argument(std::string("TableEvaluation::Inputs: pose_sensor ") +
                                ToString(in.pose_sensor) + " is not among the sensors");
  }
  for (const TableEvaluation::Extra& e : in.extras) {
    if (e.model == nullptr || e.functaset == nullptr) {
      throw std::invalid_argument("TableEvaluation::Inputs: an extra without model or functaset");
    }
  }
}

}  // namespace

bool TableEvaluation::Options::IsValid(std::string* error) const {
  std::string message;
  if (threads < 1) {
    message = "threads must be >= 1, found " + std::to_string(threads);
  } else if (raw_downsample < 1) {
    message = "raw_downsample must be >= 1, found " + std::to_string(raw_downsample);
  } else if (knn_k < 1) {
    message = "knn_k must be >= 1, found " + std::to_string(knn_k);
  } else {
    for (int q : jpeg_curve_qualities) {
      if (q < 1 || q > 100) {
        message = "jpeg_curve_qualities must lie in [1, 100], found " + std::to_string(q);
        break;
      }
    }
    if (message.empty()) return true;
  }
  if (error != nullptr) *error = "TableEvaluation::Options::" + message;
  return false;
}

TableEvaluation::Result TableEvaluation::Evaluate(const Inputs& in, const Options& options,
                                                  Observer* observer) {
  CheckInputs(in, options);
  const int threads = options.threads;
  const ProcessGroup& group = options.processes != nullptr ? *options.processes : SingleProcess();
  const FunctaModel& model = *in.model;
  const Functaset& functaset = *in.functaset;
  const Dataset& dataset = *in.dataset;
  // Without a pose model: the reconstruction columns alone (no sensor is the pose sensor).
  const bool has_pose_model = in.pose_model != nullptr;
  const PoseModelProvenance provenance =
      has_pose_model ? PoseModelProvenance::FromJson(in.pose_model->info_json(), "pose model")
                     : PoseModelProvenance();
  auto is_pose_sensor = [&](SensorKind sensor) {
    return has_pose_model && sensor == in.pose_sensor;
  };
  auto message = [&](const std::string& line) {
    if (observer) observer->Message(line);
  };

  Result result;
  result.pose_sensor = in.pose_sensor;
  result.has_pose = has_pose_model;
  for (SensorKind sensor : in.sensors) {
    SensorResult sensor_result;
    sensor_result.sensor = sensor;
    RdCurves& curves = sensor_result.curves;
    Details& details = sensor_result.details;
    const SensorTrunk& trunk = model.Trunk(sensor);
    const SensorFrames s = LoadSensorFrames(in, trunk, group, threads, observer);
    if (s.entries.empty()) {
      throw DatasetError("functaset '" + in.functaset_name + "' has no " + ToString(sensor) +
                         " entries");
    }
    const std::vector<const TrunkTargets*> baseline_train = s.BaselineTrain();
    if (!s.baseline_train.empty()) {
      message("eval: " + std::string(ToString(sensor)) + ": the functaset holds no train-split " +
              "entries; the baselines are fitted on the dataset's " +
              std::to_string(baseline_train.size()) + " train-split frames\n");
    }
    const std::uint64_t m = s.entries.size();
    const int d = functaset.latent_dim(sensor);
    const int channels = static_cast<int>(s.targets[0].values.cols());
    message("eval: " + std::string(ToString(sensor)) + ": " + std::to_string(s.train.size()) +
            " train + " + std::to_string(s.test.size()) + " test frames at " +
            std::to_string(trunk.format.rows) + "x" + std::to_string(trunk.format.cols) + "x" +
            std::to_string(channels) + ", latent " + std::to_string(d) + " floats\n");

    // -- TactFunc ------------------------------------------------------------------------
    std::vector<const TrunkTargets*> frame_targets;
    for (const TrunkTargets& t : s.targets) frame_targets.push_back(&t);
    std::vector<double> tf_psnr_clean;
    const std::vector<double> tf_psnr =
        LatentPsnrs(trunk, dataset, s.entries, frame_targets, group, threads,
                    std::string("eval: TactFunc ") + ToString(sensor), observer, &s.clean,
                    &tf_psnr_clean);
    const std::uint64_t trunk_bytes = TrunkParameterBytes(trunk);
    // Bytes per frame as stored (encode --latent-precision); the representation also
    // counts the b-bit codes' shared tables and stores no latent for frames at rest
    // (encode --share-rest) but their one shared latent.
    const double tf_frame_bytes = functaset.BytesPerFrame(sensor);
    const std::uint64_t tf_rep =
        trunk_bytes +
        static_cast<std::uint64_t>(functaset.NumStoredLatents(sensor)) *
            static_cast<std::uint64_t>(tf_frame_bytes) +
        functaset.SharedLatentBytes(sensor);
    curves.tactfunc.push_back({tf_frame_bytes, MeanPsnr(Pick(tf_psnr, s.test)),
                               "d=" + std::to_string(d), MeanPsnr(Pick(tf_psnr_clean, s.test))});

    // -- PCA -----------------------------------------------------------------------------
    const Eigen::MatrixXf train_matrix = StackFrames(baseline_train);
    std::set<int> sweep = {std::max(1, d / 4), std::max(1, d / 2), d, 2 * d, 4 * d};
    for (const Extra& e : in.extras) {
      if (e.functaset->has_sensor(sensor)) sweep.insert(e.functaset->latent_dim(sensor));
    }
    PcaCodec::Options pca_options;
    pca_options.components = *sweep.rbegin();
    // PCA codes in allocated bytes B may keep any count of stored_pca's ladder up to
    // LadderTop (below): the main functaset's shared-bytes baseline at its bytes per frame,
    // and every allocated functaset, main or extra, at its own. The fit keeps that many
    // components too, as many as the train frames allow, so that no budget's baseline is
    // cut at the sweep's top (a 256 B functaset scored beside a 128 B one would otherwise
    // be held to PCA of at most 4 x 64 components).
    // The main functaset's bytes per frame as allocated codes share them: its own budget,
    // or its bytes per frame rounded down (0 below one byte: no shared-bytes baseline).
    const int shared_bytes =
        functaset.latent_precision() == Functaset::LatentPrecision::kAllocated
            ? functaset.latent_bytes()
            : (tf_frame_bytes >= 1 ? static_cast<int>(std::floor(tf_frame_bytes)) : 0);
    int ladder_top = LadderTop(shared_bytes);
    for (const Extra& e : in.extras) {
      if (e.functaset->has_sensor(sensor) &&
          e.functaset->latent_precision() == Functaset::LatentPrecision::kAllocated) {
        ladder_top = std::max(ladder_top, LadderTop(e.functaset->latent_bytes()));
      }
    }
    pca_options.components =
        std::max(pca_options.components,
                 std::min(ladder_top, static_cast<int>(baseline_train.size())));
    PcaCodec::Summary pca_summary;
    message("eval: fitting PCA on " + std::to_string(baseline_train.size()) + " frames of " +
            std::to_string(train_matrix.cols()) + " floats...\n");
    const PcaCodec pca_full = PcaCodec::Fit(train_matrix, pca_options, &pca_summary);
    message(pca_summary.BriefReport() + "\n");
    const int pca_n = std::min(d, pca_full.components());
    const PcaCodec pca = pca_full.Truncated(pca_n);
    Eigen::MatrixXf all_matrix(static_cast<Eigen::Index>(m), train_matrix.cols());
    for (std::size_t i = 0; i < m; ++i) all_matrix.row(i) = FlattenFrame(s.targets[i]);
    const Eigen::MatrixXf full_codes = pca_full.Encode(all_matrix);  // m x n_max
    // PSNR of the n-component PCA reconstructions against the frames and, if psnr_clean
    // is given, against the noise-free ones (NaN where none).
    // `codes` (m x n) replaces the exact codes when given (stored codes).
    auto pca_psnrs = [&](int n, std::vector<double>* psnr_clean = nullptr,
                         const Eigen::MatrixXf* codes = nullptr) {
      const Eigen::MatrixXf decoded =
          pca_full.Truncated(n).Decode(codes ? *codes : Eigen::MatrixXf(full_codes.leftCols(n)));
      std::vector<double> psnr(m);
      if (psnr_clean != nullptr) psnr_clean->assign(m, kNan);
      for (std::size_t i = 0; i < m; ++i) {
        const Eigen::MatrixXf frame = UnflattenFrame(decoded.row(i), channels);
        psnr[i] = Psnr(frame, s.targets[i]);
        if (psnr_clean != nullptr && s.clean[i]) (*psnr_clean)[i] = Psnr(frame, *s.clean[i]);
      }
      return psnr;
    };
    std::vector<double> pca_psnr_clean;
    const std::vector<double> pca_psnr = pca_psnrs(pca_n, &pca_psnr_clean);
    for (int n : sweep) {
      if (n > pca_full.components()) continue;
      std::vector<double> clean;
      const std::vector<double> noisy = pca_psnrs(n, &clean);
      curves.pca.push_back({4.0 * n, MeanPsnr(Pick(noisy, s.test)), "n=" + std::to_string(n),
                            MeanPsnr(Pick(clean, s.test))});
    }
    // PCA codes stored as a functaset `like` stores latents of `latent_d` values: the
    // codes through a functaset of the same precision (Serialize and Parse, so float16
    // rounding, b-bit grids and allocated bits are the product's own), decoded, scored on
    // the test split. The latent's own count first (latent_d components: the same bits);
    // allocated codes fix the bytes B, not the number of values, so PCA then also keeps
    // any count of the ladder 1, 2, 3, 4, 6, 8, 12, ... (powers of two and one and a half
    // times them) up to 8 B, what 1-bit codes fit in (more components follow more of the
    // noise, fewer draw less of the frame; fewer than B / 2 take 2 n bytes, 16 bits each).
    auto stored_pca = [&](const Functaset& like, int latent_d) {
      const int most = std::min(latent_d, pca_full.components());
      std::vector<int> order = {most};
      if (like.latent_precision() == Functaset::LatentPrecision::kAllocated) {
        for (int p = 1; p <= pca_full.components(); p *= 2) {
          for (int n : {p, p + p / 2}) {
            if (n <= LadderTop(like.latent_bytes()) && n <= pca_full.components() &&
                std::find(order.begin(), order.end(), n) == order.end()) {
              order.push_back(n);
            }
          }
        }
      }
      std::vector<StoredPca> out;
      for (int n : order) {
        Functaset stored(0, "");
        stored.set_latent_precision(like.latent_precision());
        stored.set_latent_bytes(std::min(like.latent_bytes(), MaxCodeBytes(n)));
        stored.AddSensor(sensor, n);
        const Eigen::MatrixXf codes = full_codes.leftCols(n);
        for (Eigen::Index i = 0; i < codes.rows(); ++i) {
          FunctasetEntry entry;
          entry.id = "pca" + std::to_string(i);
          entry.latent = codes.row(i).transpose();
          stored.Add(sensor, std::move(entry));
        }
        const Functaset read = Functaset::Parse(stored.Serialize(), "PCA codes");
        Eigen::MatrixXf stored_codes(codes.rows(), n);
        for (Eigen::Index i = 0; i < codes.rows(); ++i) {
          stored_codes.row(i) = read.entries(sensor)[i].latent.transpose();
        }
        std::vector<double> clean;
        const std::vector<double> noisy = pca_psnrs(n, &clean, &stored_codes);
        out.push_back({n, MeanPsnr(Pick(noisy, s.test)), MeanPsnr(Pick(clean, s.test))});
      }
      return out;
    };
    // Its point in the picture: the count that scores best, against the noise-free frames
    // where the test frames have them.
    auto stored_pca_point = [&](const std::vector<StoredPca>& candidates, double bytes) {
      const bool by_clean = std::isfinite(candidates.front().psnr_clean);
      const StoredPca* best = &candidates.front();
      for (const StoredPca& c : candidates) {
        if (by_clean ? c.psnr_clean > best->psnr_clean : c.psnr > best->psnr) best = &c;
      }
      return RdPoint{bytes, best->psnr, "n=" + std::to_string(best->n), best->psnr_clean};
    };
    const std::vector<StoredPca> main_stored_pca = stored_pca(functaset, d);
    curves.pca_same_storage.push_back(stored_pca_point(main_stored_pca, tf_frame_bytes));
    // PCA codes in the functaset's bytes per frame with those bytes shared among their
    // values (allocated codes, PCA's strongest codec here): the same candidates as
    // stored_pca for an allocated functaset at B = the bytes per frame, rounded down. For
    // an allocated functaset that is main_stored_pca itself.
    std::vector<StoredPca> shared_pca;
    if (functaset.latent_precision() == Functaset::LatentPrecision::kAllocated) {
      shared_pca = main_stored_pca;
    } else if (shared_bytes >= 1) {
      Functaset like(0, "");
      like.set_latent_precision(Functaset::LatentPrecision::kAllocated);
      like.set_latent_bytes(shared_bytes);
      shared_pca = stored_pca(like, d);
    }
    std::string pca_note;
    if (pca_n < d) {
      pca_note = "only " + std::to_string(pca_n) + " components (train frames)";
    }

    // -- JPEG ----------------------------------------------------------------------------
    JpegCodec::Options jpeg_options;
    JpegRangeOfFrames(baseline_train, &jpeg_options.lo, &jpeg_options.hi);
    const JpegQualitySearchSummary search =
        FindJpegQuality(baseline_train, jpeg_options, tf_frame_bytes);
    message(search.BriefReport() + "\n");
    jpeg_options.quality = search.quality;
    auto jpeg_eval = [&](const JpegCodec::Options& o, std::vector<double>* psnr,
                         std::vector<double>* bytes) {
      const JpegCodec codec(o);
      psnr->assign(m, kNan);
      bytes->assign(m, 0);
      ShardedFor(
          group, m, threads, nullptr,
          [&](std::size_t i, ByteWriter* out) {
            Eigen::MatrixXf decoded;
            out->Put(static_cast<double>(codec.EncodeDecode(
                s.targets[i].values, s.targets[i].rows, s.targets[i].cols, &decoded)));
            out->Put(Psnr(decoded, s.targets[i]));
          },
          [&](std::size_t i, ByteReader& in) {
            (*bytes)[i] = in.Get<double>();
            (*psnr)[i] = in.Get<double>();
          });
    };
    std::vector<double> jpeg_psnr, jpeg_bytes;
    jpeg_eval(jpeg_options, &jpeg_psnr, &jpeg_bytes);
    const std::uint64_t jpeg_tables =
        JpegCodec(jpeg_options).TableBytes(s.targets[0].values, s.targets[0].rows, s.targets[0].cols);
    double jpeg_total = 0;
    for (double b : jpeg_bytes) jpeg_total += b;
    const std::uint64_t jpeg_rep = jpeg_tables + static_cast<std::uint64_t>(jpeg_total);
    for (int quality : options.jpeg_curve_qualities) {
      JpegCodec::Options o = jpeg_options;
      o.quality = quality;
      std::vector<double> p, b;
      jpeg_eval(o, &p, &b);
      const std::vector<double> test_bytes = Pick(b, s.test.empty() ? s.train : s.test);
      double mean_bytes = 0;
      for (double v : test_bytes) mean_bytes += v / test_bytes.size();
      curves.jpeg.push_back(
          {mean_bytes, MeanPsnr(Pick(p, s.test)), "q=" + std::to_string(quality)});
    }

    // -- Raw frames ----------------------------------------------------------------------
    const std::uint64_t raw_frame = RawFrameBytes(dataset.sensor_info(sensor));

    // -- Extra TactFunc points -----------------------------------------------------------
    for (const Extra& e : in.extras) {
      if (!e.functaset->has_sensor(sensor)) continue;
      const SensorTrunk& t2 = e.model->Trunk(sensor);
      std::vector<const FunctasetEntry*> test_entries;
      for (const FunctasetEntry& entry : e.functaset->entries(sensor)) {
        if (entry.split == Split::kTest) test_entries.push_back(&entry);
      }
      std::vector<TrunkTargets> own(test_entries.size());
      std::vector<const TrunkTargets*> t_targets(test_entries.size());
      // Noise-free frames where they are the main functaset's (same format).
      std::vector<std::optional<TrunkTargets>> own_clean(test_entries.size());
      const bool same_format = t2.format.rows == trunk.format.rows &&
                               t2.format.cols == trunk.format.cols &&
                               t2.format.grayscale == trunk.format.grayscale &&
                               t2.format.per_image_min_max == trunk.format.per_image_min_max &&
                               t2.format.scale == trunk.format.scale;
      for (std::size_t k = 0; k < test_entries.size(); ++k) {
        const std::optional<std::size_t> in_main = functaset.Find(sensor, test_entries[k]->id);
        if (same_format && in_main) {
          t_targets[k] = &s.targets[*in_main];
          own_clean[k] = s.clean[*in_main];
          continue;
        }
        const std::optional<std::size_t> index = dataset.FindFrame(test_entries[k]->id, sensor);
        if (!index) {
          throw DatasetError("dataset '" + in.dataset_name + "' has no " + ToString(sensor) +
                             " frame '" + test_entries[k]->id + "' of functaset '" +
                             e.functaset_name + "'");
        }
        own[k] = LoadTrunkTargets(dataset, *index, t2.format);
        t_targets[k] = &own[k];
      }
      const int d2 = e.functaset->latent_dim(sensor);
      std::vector<double> psnr_clean;
      const std::vector<double> psnr = LatentPsnrs(
          t2, dataset, test_entries, t_targets, group, threads,
          "eval: TactFunc d=" + std::to_string(d2) + " " + ToString(sensor), observer, &own_clean,
          &psnr_clean);
      const double bytes = e.functaset->BytesPerFrame(sensor);
      curves.tactfunc.push_back(
          {bytes, MeanPsnr(psnr), "d=" + std::to_string(d2), MeanPsnr(psnr_clean)});
      curves.pca_same_storage.push_back(stored_pca_point(stored_pca(*e.functaset, d2), bytes));
    }

    // -- Poses ---------------------------------------------------------------------------
    std::map<std::pair<std::string, Split>, PoseErrors> pose;
    std::string tf_pose_latents;  // the latent map the TactFunc pose rows used
    if (is_pose_sensor(sensor)) {
      const PoseMlp& pose_model = *in.pose_model;
      const PoseSamples train = LabelledSamples(s, *in.dataset, Split::kTrain);
      const PoseSamples test = LabelledSamples(s, *in.dataset, Split::kTest);
      if (train.frames.empty()) {
        throw DatasetError("functaset '" + in.functaset_name + "' has no labelled train-split " +
                           ToString(sensor) + " entries: the pose baselines are trained on those");
      }
      // The pose model reads the kind of latent it was trained on (its latent map,
      // PosePosterior's rule): the functaset's own latents if they were fitted that way,
      // else the frames re-fitted with that map, as train-pose --refit fitted them. A
      // photometric trunk's latents are encode's fits, which train-pose trains on; no
      // other map exists for it (train-pose --refit fits the direct trunk's problem).
      const bool photometric = trunk.photometric != nullptr;
      const std::string stored =
          functaset.fit_strategy(sensor).empty()
              ? "meta_sgd:" + std::to_string(trunk.meta_sgd.inner_steps)
              : functaset.fit_strategy(sensor);
      // A photometric pose model records its functaset's strategy (or "functaset", from
      // before it did): the functaset must hold latents of that fit.
      if (photometric && provenance.latent_map != "functaset" &&
          provenance.latent_map != stored) {
        throw DatasetError("the pose model reads " + provenance.latent_map + " latents, the "
                           "functaset holds " + stored + " ones, and eval does not re-fit the "
                           "photometric " + ToString(sensor) + " trunk: encode with --strategy " +
                           provenance.latent_map + ", or train the pose model on this "
                           "functaset");
      }
      const FitStrategy latent_map = LatentMapOfPoseModel(pose_model, trunk);
      Eigen::MatrixXf latents(static_cast<Eigen::Index>(m), d);
      if (photometric || latent_map.ToString() == stored) {
        for (std::size_t i = 0; i < m; ++i) latents.row(i) = s.entries[i]->latent.transpose();
      } else {
        LatentFitter::Options fit;
        fit.strategy = latent_map;
        const LatentFitter fitter(trunk, fit);
        LatentProblem::Options problem;
        problem.sigma = provenance.refit_sigma;  // 0 = the trunk's residual sigma
        if (observer) {
          observer->BeginTask("eval: latents for the pose model (" + latent_map.ToString() + ")",
                              static_cast<std::int64_t>(m), "frames");
        }
        ShardedFor(
            group, m, threads, observer,
            [&](std::size_t i, ByteWriter* out) {
              Eigen::VectorXd z;
              fitter.Fit(LatentProblem(trunk, s.targets[i], problem), &z);
              const Eigen::VectorXf latent = z.cast<float>();
              out->PutFloats(latent.data(), static_cast<std::size_t>(latent.size()));
            },
            [&](std::size_t i, ByteReader& in) {
              if (in.FloatCount() != static_cast<std::size_t>(d)) {
                throw std::runtime_error("eval: a re-fitted latent of another length than " +
                                         std::to_string(d) + " came from another process");
              }
              Eigen::VectorXf latent(d);
              in.GetFloats(latent.data(), static_cast<std::size_t>(d));
              latents.row(static_cast<Eigen::Index>(i)) = latent.transpose();
            });
        if (observer) observer->EndTask();
        message("eval: the pose model reads " + latent_map.ToString() + " latents, the functaset holds " +
                stored + " ones: re-fitted every " + ToString(sensor) + " frame for the pose rows\n");
      }
      tf_pose_latents = photometric ? stored : latent_map.ToString();
      const Eigen::MatrixXf codes = full_codes.leftCols(pca_n);
      const int factor = options.raw_downsample;
      Eigen::MatrixXf pixels;
      for (std::size_t i = 0; i < m; ++i) {
        const Eigen::RowVectorXf row = DownsamplePixels(s.targets[i], factor);
        if (i == 0) pixels.resize(static_cast<Eigen::Index>(m), row.size());
        pixels.row(i) = row;
      }
      auto score = [&](const std::string& key, const auto& predict) {
        for (const PoseSamples* p : {&train, &test}) {
          if (p->frames.empty()) continue;
          const Split split = p == &train ? Split::kTrain : Split::kTest;
          pose[{key, split}] =
              ScorePoses(predict(p->frames, p->targets.symmetry_orders), p->targets.poses,
                         p->targets.symmetry_orders);
        }
      };
      // TactFunc: the pose model on the latents.
      score("tactfunc", [&](const std::vector<std::size_t>& f, const Eigen::VectorXi& n) {
        return PredictPoses(pose_model, Rows(latents, f), n);
      });
      // PCA codes: the same architecture, trained as the pose model was (its provenance:
      // epochs, batch, learning rate, seed; train-pose's defaults where it says nothing).
      PoseMlp::Options mlp_options = pose_model.options();
      mlp_options.input_dim = pca_n;
      PoseMlpTrainingOptions training;
      training.epochs = provenance.epochs.value_or(training.epochs);
      training.batch_size = provenance.batch.value_or(training.batch_size);
      training.learning_rate = provenance.learning_rate.value_or(training.learning_rate);
      training.seed = provenance.seed.value_or(training.seed);
      PoseMlp pca_mlp(mlp_options, training.seed);
      {
        if (observer) observer->BeginTask("eval: pose MLP on PCA codes", training.epochs, "epochs");
        const PoseMlpTrainingSummary summary =
            TrainPoseMlp(&pca_mlp, Rows(codes, train.frames), train.targets, training,
                         [&](int, double) {
                           if (observer) observer->Tick();
                           return true;
                         });
        if (observer) observer->EndTask();
        message("eval: pose MLP on PCA codes: " + summary.BriefReport() + "\n");
        if (summary.termination == PoseMlpTrainingTermination::kNonFinite && observer) {
          observer->Warning("eval: warning: the pose MLP on PCA codes diverged (" +
                            summary.message + "); its last finite parameters are scored\n");
        }
      }
      score("pca", [&](const std::vector<std::size_t>& f, const Eigen::VectorXi& n) {
        return PredictPoses(pca_mlp, Rows(codes, f), n);
      });
      // Raw pixels: ridge and k-NN.
      RidgePoseRegressor::Options ridge_options;
      ridge_options.position_scale = pose_model.options().position_scale;
      RidgePoseRegressor::Summary ridge_summary;
      const RidgePoseRegressor ridge = RidgePoseRegressor::Fit(
          Rows(pixels, train.frames), train.targets, ridge_options, &ridge_summary);
      message("eval: " + ridge_summary.BriefReport() + "\n");
      score("ridge", [&](const std::vector<std::size_t>& f, const Eigen::VectorXi& n) {
        return ridge.Predict(Rows(pixels, f), n);
      });
      KnnPoseRegressor::Options knn_options;
      knn_options.k = options.knn_k;
      const KnnPoseRegressor knn(Rows(pixels, train.frames), train.targets, knn_options);
      score("knn", [&](const std::vector<std::size_t>& f, const Eigen::VectorXi& n) {
        return knn.Predict(Rows(pixels, f), n);
      });
      Details::Pose p;
      p.mlp_hidden = pose_model.options().hidden_sizes;
      p.mlp_training = training;
      p.ridge = ridge_summary;
      p.raw_downsample = factor;
      p.raw_features = pixels.cols();
      p.knn_k = options.knn_k;
      p.labelled_train = train.frames.size();
      p.labelled_test = test.frames.size();
      details.pose = p;
    }

    // -- Rows ----------------------------------------------------------------------------
    const std::string down = std::to_string(options.raw_downsample);
    for (Split split : {Split::kTrain, Split::kTest}) {
      const std::vector<std::size_t>& idx = s.Of(split);
      if (idx.empty()) continue;
      auto find_pose = [&](const std::string& key) {
        const auto it = pose.find({key, split});
        return it == pose.end() ? PoseErrors() : it->second;
      };
      const bool posed = is_pose_sensor(sensor);
      Row tf{"TactFunc", posed ? "pose MLP on " + tf_pose_latents + " latents" : "", sensor, split,
             tf_rep, tf_frame_bytes,
             MeanPsnr(Pick(tf_psnr, idx)), true, static_cast<int>(idx.size()),
             find_pose("tactfunc"), "", MeanPsnr(Pick(tf_psnr_clean, idx))};
      Row pc{"PCA", posed ? "pose MLP on PCA codes" : "", sensor, split,
             pca.ModelBytes() + m * pca.BytesPerFrame(), static_cast<double>(pca.BytesPerFrame()),
             MeanPsnr(Pick(pca_psnr, idx)), true, static_cast<int>(idx.size()), find_pose("pca"),
             pca_note, MeanPsnr(Pick(pca_psnr_clean, idx))};
      double jb = 0;
      for (std::size_t i : idx) jb += jpeg_bytes[i] / idx.size();
      Row jp{"JPEG", "", sensor, split, jpeg_rep, jb, MeanPsnr(Pick(jpeg_psnr, idx)), true,
             static_cast<int>(idx.size()), PoseErrors(),
             "quality " + std::to_string(search.quality)};
      Row raw_ridge{"Raw frames", posed ? "ridge on pixels /" + down : "", sensor, split,
                    m * raw_frame, static_cast<double>(raw_frame), kNan, false,
                    static_cast<int>(idx.size()), find_pose("ridge"), ""};
      // Contact and rest apart: frames at rest are mostly sensor noise.
      const std::vector<std::size_t> touching = s.WithContact(idx, true);
      const std::vector<std::size_t> resting = s.WithContact(idx, false);
      auto split_by_contact = [&](Row* row, const std::vector<double>& psnr) {
        row->contact_frames = static_cast<int>(touching.size());
        row->psnr_contact = MeanPsnr(Pick(psnr, touching));
        row->psnr_no_contact = MeanPsnr(Pick(psnr, resting));
      };
      split_by_contact(&tf, tf_psnr);
      split_by_contact(&pc, pca_psnr);
      split_by_contact(&jp, jpeg_psnr);
      result.rows.push_back(tf);
      result.rows.push_back(pc);
      result.rows.push_back(jp);
      result.rows.push_back(raw_ridge);
      if (posed) {
        Row raw_knn = raw_ridge;
        raw_knn.pose_from = "k-NN (k=" + std::to_string(options.knn_k) + ") on pixels /" + down;
        raw_knn.pose = find_pose("knn");
        result.rows.push_back(raw_knn);
      }
    }

    // -- Targets (test split) --------------------------------------------------------------
    Targets& t = sensor_result.targets;
    const double tf_test = MeanPsnr(Pick(tf_psnr, s.test));
    // The PSNR target compares at equal bytes per frame: PCA with as many float32
    // components as TactFunc's stored latent has bytes / 4 (= d for float32 latents,
    // d / 2 for float16 ones, d / 4 for 8-bit codes); the PCA row itself keeps d
    // components, as many as the latent has values.
    const int pca_equal_n =
        std::max(1, std::min(pca_full.components(), static_cast<int>(tf_frame_bytes / 4)));
    std::vector<double> pca_equal_clean = pca_psnr_clean;
    const double pca_test =
        pca_equal_n == pca_n ? MeanPsnr(Pick(pca_psnr, s.test))
                             : MeanPsnr(Pick(pca_psnrs(pca_equal_n, &pca_equal_clean), s.test));
    // PCA codes stored as the latents are (stored_pca above): each target takes the count
    // that scores best on the test split, the latent's own count unless another beats it.
    {
      auto fill = [&](Targets::PsnrAbovePca* target, double tf, double pca_db, int n,
                      bool first) {
        if (!first && !(pca_db > target->pca_db)) return;  // keep the best
        target->tactfunc_db = tf;
        target->pca_db = pca_db;
        target->margin_db = tf - pca_db;
        target->required_margin_db = 3;
        target->pca_components = n;
        target->bytes_per_frame = tf_frame_bytes;
        target->met = std::isfinite(tf) && std::isfinite(pca_db) && tf >= pca_db + 3;
      };
      for (std::size_t k = 0; k < main_stored_pca.size(); ++k) {
        const StoredPca& p = main_stored_pca[k];
        fill(&t.psnr_above_pca_same_bits, tf_test, p.psnr, p.n, k == 0);
        fill(&t.psnr_above_pca_same_bits_clean, MeanPsnr(Pick(tf_psnr_clean, s.test)),
             p.psnr_clean, p.n, k == 0);
      }
      t.has_shared_bytes = !shared_pca.empty();
      for (std::size_t k = 0; k < shared_pca.size(); ++k) {
        const StoredPca& p = shared_pca[k];
        fill(&t.psnr_above_pca_shared_bytes, tf_test, p.psnr, p.n, k == 0);
        fill(&t.psnr_above_pca_shared_bytes_clean, MeanPsnr(Pick(tf_psnr_clean, s.test)),
             p.psnr_clean, p.n, k == 0);
      }
      result.all_targets_met = result.all_targets_met && t.psnr_above_pca_same_bits.met;
    }
    const double jpeg_test = MeanPsnr(Pick(jpeg_psnr, s.test));
    double jpeg_test_bytes = 0;
    for (std::size_t i : s.test) jpeg_test_bytes += jpeg_bytes[i] / s.test.size();
    t.psnr_above_pca.met =
        std::isfinite(tf_test) && std::isfinite(pca_test) && tf_test >= pca_test + 3;
    t.psnr_above_pca.tactfunc_db = tf_test;
    t.psnr_above_pca.pca_db = pca_test;
    t.psnr_above_pca.margin_db = tf_test - pca_test;
    t.psnr_above_pca.required_margin_db = 3;
    t.psnr_above_pca.pca_components = pca_equal_n;
    t.psnr_above_pca.bytes_per_frame = tf_frame_bytes;
    const double tf_test_clean = MeanPsnr(Pick(tf_psnr_clean, s.test));
    const double pca_test_clean = MeanPsnr(Pick(pca_equal_clean, s.test));
    t.has_clean = std::isfinite(tf_test_clean) && std::isfinite(pca_test_clean);
    if (t.has_clean) {
      result.all_targets_met = result.all_targets_met && t.psnr_above_pca_same_bits_clean.met;
      t.psnr_above_pca_clean = t.psnr_above_pca;
      t.psnr_above_pca_clean.tactfunc_db = tf_test_clean;
      t.psnr_above_pca_clean.pca_db = pca_test_clean;
      t.psnr_above_pca_clean.margin_db = tf_test_clean - pca_test_clean;
      t.psnr_above_pca_clean.met = tf_test_clean >= pca_test_clean + 3;
      result.all_targets_met = result.all_targets_met && t.psnr_above_pca_clean.met;
    }
    t.psnr_above_jpeg.met =
        std::isfinite(tf_test) && std::isfinite(jpeg_test) && tf_test > jpeg_test;
    t.psnr_above_jpeg.tactfunc_db = tf_test;
    t.psnr_above_jpeg.jpeg_db = jpeg_test;
    t.psnr_above_jpeg.margin_db = tf_test - jpeg_test;
    t.psnr_above_jpeg.tactfunc_bytes_per_frame = tf_frame_bytes;
    t.psnr_above_jpeg.jpeg_bytes_per_frame = jpeg_test_bytes;
    t.psnr_above_jpeg.jpeg_quality = search.quality;
    t.psnr_above_jpeg.jpeg_target_reachable = search.target_reachable;
    result.all_targets_met =
        result.all_targets_met && t.psnr_above_pca.met && t.psnr_above_jpeg.met;
    if (is_pose_sensor(sensor)) {
      const auto mse = [&](const std::string& key) {
        const auto it = pose.find({key, Split::kTest});
        return it == pose.end() ? kNan : it->second.PoseMse();
      };
      const double tf_mse = mse("tactfunc"), pca_mse = mse("pca");
      const double raw_mse = std::min(mse("ridge"), mse("knn"));
      t.has_pose = true;
      t.pose_beats_pca_codes.met =
          std::isfinite(tf_mse) && std::isfinite(pca_mse) && tf_mse < pca_mse;
      t.pose_beats_pca_codes.tactfunc_pose_mse = tf_mse;
      t.pose_beats_pca_codes.pca_pose_mse = pca_mse;
      t.pose_not_worse_than_raw.met =
          std::isfinite(tf_mse) && std::isfinite(raw_mse) && tf_mse <= raw_mse;
      t.pose_not_worse_than_raw.tactfunc_pose_mse = tf_mse;
      t.pose_not_worse_than_raw.raw_best_pose_mse = raw_mse;
      t.pose_not_worse_than_raw.ridge_pose_mse = mse("ridge");
      t.pose_not_worse_than_raw.knn_pose_mse = mse("knn");
      result.all_targets_met = result.all_targets_met && t.pose_beats_pca_codes.met &&
                               t.pose_not_worse_than_raw.met;
    }
    details.pca = pca_summary;
    details.pca_components = pca_n;
    details.jpeg_search = search;
    details.jpeg = jpeg_options;
    details.jpeg_table_bytes = jpeg_tables;
    details.rows = trunk.format.rows;
    details.cols = trunk.format.cols;
    details.channels = channels;
    details.raw_frame_bytes = raw_frame;
    result.sensors.push_back(std::move(sensor_result));
  }
  return result;
}

}  // namespace tactfunc
