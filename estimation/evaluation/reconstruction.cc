// Copyright 2026 The tactfunc Authors.
#include "estimation/evaluation/reconstruction.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <map>
#include <memory>
#include <sstream>
#include <stdexcept>

#include "models/core/parallel_for.h"
#include "estimation/data/photometric_markers.h"
#include "estimation/data/trunk_targets.h"

namespace tactfunc {

PsnrStats ComputePsnrStats(const std::vector<double>& values) {
  PsnrStats stats;
  std::vector<double> finite;
  finite.reserve(values.size());
  for (double v : values) {
    if (std::isfinite(v)) {
      finite.push_back(v);
    } else {
      ++stats.excluded;
    }
  }
  stats.count = static_cast<std::int64_t>(finite.size());
  if (finite.empty()) return stats;
  std::sort(finite.begin(), finite.end());
  double sum = 0;
  for (double v : finite) sum += v;
  stats.mean = sum / finite.size();
  // Linear interpolation at rank q (n - 1), as numpy's default percentile.
  auto percentile = [&](double q) {
    const double rank = q * (finite.size() - 1);
    const std::size_t lo = static_cast<std::size_t>(std::floor(rank));
    const std::size_t hi = std::min(lo + 1, finite.size() - 1);
    return finite[lo] + (rank - lo) * (finite[hi] - finite[lo]);
  };
  stats.median = percentile(0.5);
  stats.p5 = percentile(0.05);
  return stats;
}

std::uint64_t RawFrameBytes(const SensorInfo& info) {
  const std::uint64_t bytes_per_sample =
      info.encoding == PixelEncoding::kDepthU16Micrometres ? 2 : 1;
  return static_cast<std::uint64_t>(info.rows) * info.cols * info.channels * bytes_per_sample;
}

RepresentationSize ComputeRepresentationSize(const FunctaModel& model, const Functaset& functaset,
                                             const std::vector<SensorInfo>& sensors) {
  RepresentationSize size;
  for (SensorKind sensor : functaset.sensors()) {
    const auto info = std::find_if(sensors.begin(), sensors.end(),
                                   [&](const SensorInfo& i) { return i.kind == sensor; });
    if (info == sensors.end()) {
      throw std::invalid_argument(std::string("ComputeRepresentationSize: no SensorInfo for '") +
                                  ToString(sensor) + "'");
    }
    const SensorTrunk& trunk = model.Trunk(sensor);
    const std::uint64_t m = functaset.entries(sensor).size();
    size.frames += static_cast<std::int64_t>(m);
    size.model_bytes += TrunkParameterBytes(trunk);
    // As on disk: per-frame codes (none for frames at rest) plus the sensor's shared
    // tables (b-bit latents) and shared rest latent.
    size.latent_bytes += static_cast<std::uint64_t>(functaset.BytesPerFrame(sensor)) *
                             static_cast<std::uint64_t>(functaset.NumStoredLatents(sensor)) +
                         functaset.SharedLatentBytes(sensor);
    size.raw_bytes += m * RawFrameBytes(*info);
  }
  size.representation_bytes = size.model_bytes + size.latent_bytes;
  size.compression_ratio = size.representation_bytes > 0
                               ? static_cast<double>(size.raw_bytes) / size.representation_bytes
                               : 0.0;
  return size;
}

Eigen::MatrixXf Reconstruct(const SensorTrunk& trunk, const Eigen::VectorXf& latent,
                            const PhotometricTrunk::Markers* markers) {
  if (latent.size() != TrunkLatentDim(trunk)) {
    throw std::invalid_argument("Reconstruct: latent has " + std::to_string(latent.size()) +
                                " values, the " + ToString(trunk.sensor) +
                                " trunk's latent_dim is " + std::to_string(TrunkLatentDim(trunk)));
  }
  return TrunkDecode(trunk, latent, markers);
}

bool ReconstructionEvaluator::Options::IsValid(std::string* error) const {
  if (threads < 1) {
    if (error != nullptr) {
      *error = "ReconstructionEvaluator::Options::threads must be >= 1, found " +
               std::to_string(threads);
    }
    return false;
  }
  return true;
}

ReconstructionEvaluator::ReconstructionEvaluator() : ReconstructionEvaluator(Options()) {}

ReconstructionEvaluator::ReconstructionEvaluator(const Options& options) : options_(options) {
  std::string error;
  if (!options_.IsValid(&error)) throw std::invalid_argument(error);
}

const ReconstructionEvaluator::GroupSummary* ReconstructionEvaluator::Summary::Find(
    SensorKind sensor, Split split) const {
  for (const GroupSummary& g : groups) {
    if (g.sensor == sensor && g.split == split) return &g;
  }
  return nullptr;
}

namespace {

std::string Db(double value) {
  if (!std::isfinite(value)) return "n/a";
  char buffer[32];
  std::snprintf(buffer, sizeof(buffer), "%.2f", value);
  return buffer;
}

}  // namespace

namespace {

// The centre of a reconstruction's change (ContactCentre, no smoothing: the trunk's output
// is smooth) at the working resolution, mapped to source pixels: working pixel centres
// sit at (i + 0.5) source_size / working_size - 0.5.
void ReconstructionCentre(const Eigen::MatrixXf& prediction, const FrameFormat& format,
                          int source_rows, int source_cols, double* row, double* col) {
  ContactCentre(TargetsToImage(prediction, format.rows, format.cols), 1, row, col);
  *row = (*row + 0.5) * source_rows / format.rows - 0.5;
  *col = (*col + 0.5) * source_cols / format.cols - 0.5;
}

// A FrameResult's computed figures (not its id, sensor, split and index, which every
// process knows) as bytes for ProcessGroup::GatherItems, and back.
Bytes PackFigures(const ReconstructionEvaluator::FrameResult& r) {
  ByteWriter out;
  for (double v : {r.psnr, r.psnr_clean, r.psnr_zero, r.psnr_source_peak, r.target_range,
                   r.source_range, r.rmse, r.contact_score, r.contact_row, r.contact_col,
                   r.recon_contact_row, r.recon_contact_col}) {
    out.Put(v);
  }
  out.Put<std::uint8_t>(r.contact ? 1 : 0);
  return std::move(out.bytes());
}

void UnpackFigures(const Bytes& bytes, ReconstructionEvaluator::FrameResult* r) {
  ByteReader in(bytes);
  for (double* v : {&r->psnr, &r->psnr_clean, &r->psnr_zero, &r->psnr_source_peak,
                    &r->target_range, &r->source_range, &r->rmse, &r->contact_score,
                    &r->contact_row, &r->contact_col, &r->recon_contact_row,
                    &r->recon_contact_col}) {
    *v = in.Get<double>();
  }
  r->contact = in.Get<std::uint8_t>() != 0;
}

}  // namespace

std::string ReconstructionEvaluator::Summary::BriefReport() const {
  std::ostringstream out;
  out << "recon: " << frames.size() << " frames";
  for (const GroupSummary& g : groups) {
    if (g.split != Split::kTest) continue;
    out << ", " << ToString(g.sensor) << " test " << Db(g.noisy.mean) << " dB";
    if (g.clean.count > 0) out << " (clean " << Db(g.clean.mean) << " dB)";
  }
  char ratio[32];
  std::snprintf(ratio, sizeof(ratio), "%.1f", size.compression_ratio);
  out << ", compression " << ratio << "x";
  return out.str();
}

std::string ReconstructionEvaluator::Summary::FullReport() const {
  std::ostringstream out;
  char line[256];
  std::snprintf(line, sizeof(line), "%-8s %-6s %6s  %-23s %-23s %-23s %-23s\n", "sensor",
                "split", "frames", "PSNR noisy mean/med/p5", "PSNR clean mean/med/p5",
                "z=0 mean/med/p5", "source peak mean/med/p5");
  out << line;
  auto triple = [](const PsnrStats& s) {
    return Db(s.mean) + " / " + Db(s.median) + " / " + Db(s.p5);
  };
  for (const GroupSummary& g : groups) {
    std::snprintf(line, sizeof(line), "%-8s %-6s %6lld  %-23s %-23s %-23s %-23s\n",
                  ToString(g.sensor), ToString(g.split),
                  static_cast<long long>(g.noisy.count + g.noisy.excluded),
                  triple(g.noisy).c_str(), has_clean ? triple(g.clean).c_str() : "-",
                  triple(g.zero).c_str(), triple(g.source_peak).c_str());
    out << line;
  }
  std::snprintf(line, sizeof(line),
                "representation: %llu B (model %llu B + latents %llu B) vs raw %llu B: "
                "compression %.1fx\n",
                static_cast<unsigned long long>(size.representation_bytes),
                static_cast<unsigned long long>(size.model_bytes),
                static_cast<unsigned long long>(size.latent_bytes),
                static_cast<unsigned long long>(size.raw_bytes), size.compression_ratio);
  out << line;
  std::snprintf(line, sizeof(line), "%-8s %-6s %8s  %-23s %11s  %-23s\n", "sensor", "split",
                "contact", "PSNR noisy mean/med/p5", "no contact", "PSNR noisy mean/med/p5");
  out << line;
  for (const GroupSummary& g : groups) {
    std::snprintf(line, sizeof(line), "%-8s %-6s %8lld  %-23s %11lld  %-23s\n",
                  ToString(g.sensor), ToString(g.split),
                  static_cast<long long>(g.contact.count + g.contact.excluded),
                  g.contact.count > 0 ? triple(g.contact).c_str() : "-",
                  static_cast<long long>(g.no_contact.count + g.no_contact.excluded),
                  g.no_contact.count > 0 ? triple(g.no_contact).c_str() : "-");
    out << line;
  }
  return out.str();
}

ReconstructionEvaluator::Summary ReconstructionEvaluator::Evaluate(const FunctaModel& model,
                                                                   const Functaset& functaset,
                                                                   const Dataset& dataset) const {
  const auto start = std::chrono::steady_clock::now();
  functaset.CheckModel(model);
  Summary summary;
  summary.has_clean = options_.clean && dataset.has_clean();

  struct SensorState {
    const SensorTrunk* trunk = nullptr;
    Eigen::MatrixXf grid;
    // A photometric trunk's markers of each frame's own reference.
    std::unique_ptr<DatasetMarkers> markers;
    // f(grid; 0) for each set of markers the frames are drawn against (the key null for
    // a direct trunk): the same for every frame of a clip.
    std::map<const PhotometricTrunk::Markers*, Eigen::MatrixXf> zero_prediction;
  };
  std::map<SensorKind, SensorState> states;
  std::vector<SensorInfo> infos;
  for (SensorKind sensor : functaset.sensors()) {
    if (functaset.entries(sensor).empty()) continue;
    if (!dataset.has_sensor(sensor)) {
      throw std::invalid_argument(std::string("the functaset holds ") + ToString(sensor) +
                                  " frames but the dataset " + dataset.root() + " has none");
    }
    SensorState& state = states[sensor];
    state.trunk = &model.Trunk(sensor);
    if (state.trunk->photometric != nullptr) {
      state.markers = std::make_unique<DatasetMarkers>(dataset, *state.trunk);
    }
    state.grid = state.trunk->siren.Grid<float>(state.trunk->format.rows, state.trunk->format.cols);
    infos.push_back(dataset.sensor_info(sensor));
  }
  for (SensorKind sensor : functaset.sensors()) {
    if (!functaset.entries(sensor).empty()) continue;
    SensorInfo empty;  // no frames: contributes no raw bytes
    empty.kind = sensor;
    infos.push_back(empty);
  }

  // The work list, in functaset order.
  std::vector<const FunctasetEntry*> entries;
  for (SensorKind sensor : functaset.sensors()) {
    for (const FunctasetEntry& e : functaset.entries(sensor)) {
      const auto index = dataset.FindFrame(e.id, sensor);
      if (!index) {
        throw std::invalid_argument("the functaset holds frame '" + e.id + "' (" +
                                    ToString(sensor) + ") which the dataset " + dataset.root() +
                                    " does not have");
      }
      FrameResult r;
      r.id = e.id;
      r.sensor = sensor;
      r.split = e.split;
      r.dataset_index = *index;
      summary.frames.push_back(r);
      entries.push_back(&e);
    }
  }

  // This process's entries on its threads, then every process's (GatherItems): each
  // frame's figures travel as the doubles computed, so they are the same bits whichever
  // process computed them.
  const ProcessGroup& group =
      options_.processes != nullptr ? *options_.processes : SingleProcess();
  const std::int64_t count = static_cast<std::int64_t>(entries.size());
  const std::vector<std::int64_t> own = group.OwnItems(count);
  // Each of this process's frames' markers, and the zero latent's frame under each.
  std::vector<const PhotometricTrunk::Markers*> frame_markers(own.size(), nullptr);
  for (std::size_t k = 0; k < own.size(); ++k) {
    const FrameResult& r = summary.frames[static_cast<std::size_t>(own[k])];
    SensorState& state = states.at(r.sensor);
    if (state.markers) frame_markers[k] = state.markers->Of(r.dataset_index);
    if (state.zero_prediction.count(frame_markers[k]) == 0) {
      state.zero_prediction[frame_markers[k]] =
          TrunkDecode(*state.trunk, Eigen::VectorXf::Zero(TrunkLatentDim(*state.trunk)),
                      frame_markers[k]);
    }
  }
  std::vector<Bytes> computed(own.size());
  internal::ParallelFor(static_cast<int>(own.size()), options_.threads, [&](int k) {
    const std::size_t i = static_cast<std::size_t>(own[k]);
    FrameResult& r = summary.frames[i];
    const SensorState& state = states.at(r.sensor);
    const FrameFormat& format = state.trunk->format;
    const PhotometricTrunk::Markers* markers = frame_markers[k];
    const Eigen::MatrixXf prediction = TrunkDecode(*state.trunk, entries[i]->latent, markers);
    const Image frame = dataset.LoadFrame(r.dataset_index);
    const TrunkTargets targets = DatasetFrameTargets(dataset, r.dataset_index, frame, format);
    const ContactReport contact =
        DetectFrameContact(dataset, r.dataset_index, frame, options_.contact);
    r.contact = contact.contact;
    r.contact_score = contact.score;
    r.contact_row = contact.centre_row;
    r.contact_col = contact.centre_col;
    ReconstructionCentre(prediction, format, frame.rows, frame.cols, &r.recon_contact_row,
                         &r.recon_contact_col);
    r.psnr = Psnr(prediction, targets);
    r.psnr_source_peak = PsnrSourcePeak(prediction, targets);
    r.target_range = TargetRange(targets);
    r.source_range = targets.source_range;
    r.rmse = Rmse(prediction, targets);
    // A photometric trunk's zero latent still moves the frame's own markers.
    r.psnr_zero = Psnr(state.zero_prediction.at(markers), targets);
    if (summary.has_clean && !dataset.frames()[r.dataset_index].clean_path.empty()) {
      r.psnr_clean = Psnr(prediction, LoadTrunkTargets(dataset, r.dataset_index, format, true));
    }
    computed[k] = PackFigures(r);
  });
  const std::vector<Bytes> all = group.GatherItems(count, computed);
  for (std::size_t i = 0; i < entries.size(); ++i) UnpackFigures(all[i], &summary.frames[i]);

  for (const auto& [sensor, state] : states) {
    for (Split split : {Split::kTrain, Split::kTest}) {
      std::vector<double> noisy, clean, zero, source_peak, contact, no_contact;
      for (const FrameResult& r : summary.frames) {
        if (r.sensor != sensor || r.split != split) continue;
        noisy.push_back(r.psnr);
        (r.contact ? contact : no_contact).push_back(r.psnr);
        source_peak.push_back(r.psnr_source_peak);
        zero.push_back(r.psnr_zero);
        if (summary.has_clean) clean.push_back(r.psnr_clean);
      }
      if (noisy.empty()) continue;
      GroupSummary g;
      g.sensor = sensor;
      g.split = split;
      g.noisy = ComputePsnrStats(noisy);
      g.clean = ComputePsnrStats(clean);
      g.zero = ComputePsnrStats(zero);
      g.source_peak = ComputePsnrStats(source_peak);
      g.contact = ComputePsnrStats(contact);
      g.no_contact = ComputePsnrStats(no_contact);
      summary.groups.push_back(g);
    }
  }
  summary.size = ComputeRepresentationSize(model, functaset, infos);
  summary.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return summary;
}

}  // namespace tactfunc
