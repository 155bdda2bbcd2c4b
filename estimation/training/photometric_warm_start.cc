// Copyright 2026 The tactfunc Authors.
#include "estimation/training/photometric_warm_start.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <utility>

#include "estimation/knn/knn_index.h"
#include "models/core/internal/checks.h"
#include "models/core/parallel_for.h"
#include "models/core/se2.h"

namespace tactfunc {
namespace {

using internal::kPi;

PhotometricWarmStart::Options TableOptions(const WarmStartTable& table) {
  PhotometricWarmStart::Options options;
  options.grid = table.grid;
  options.extent = table.extent;
  options.supersample = table.supersample;
  return options;
}

// The descriptor of the square turned by pi: cell (a, b) becomes (G-1-a, G-1-b), whose
// samples are the turned ones (the sample offsets are symmetric about the cell centre).
Eigen::VectorXf Flipped(const Eigen::VectorXf& descriptor, int grid, int channels) {
  Eigen::VectorXf out(descriptor.size());
  const int cells = grid * grid;
  for (int cell = 0; cell < cells; ++cell) {
    out.segment(static_cast<Eigen::Index>(cells - 1 - cell) * channels, channels) =
        descriptor.segment(static_cast<Eigen::Index>(cell) * channels, channels);
  }
  return out;
}

}  // namespace

bool PhotometricWarmStart::Options::IsValid(std::string* error) const {
  std::ostringstream message;
  if (grid < 1 || grid > 64) {
    message << "grid must be in [1, 64], found " << grid;
  } else if (!(extent > 0) || !std::isfinite(extent)) {
    message << "extent must be finite and > 0, found " << extent;
  } else if (supersample < 1 || supersample > 8) {
    message << "supersample must be in [1, 8], found " << supersample;
  }
  if (error != nullptr) *error = message.str();
  return message.str().empty();
}

Eigen::VectorXf PhotometricWarmStart::Descriptor(const PhotometricTrunk& trunk,
                                                 const TrunkTargets& frame,
                                                 const Eigen::Vector3d& moment,
                                                 const Options& options) {
  const int rows = trunk.options().rows, cols = trunk.options().cols;
  const int channels = trunk.channels();
  if (frame.rows != rows || frame.cols != cols || frame.values.cols() != channels ||
      frame.values.rows() != static_cast<Eigen::Index>(rows) * cols) {
    std::ostringstream message;
    message << "PhotometricWarmStart: expected a frame of " << rows << " x " << cols << " x "
            << channels << ", found " << frame.rows << " x " << frame.cols << " x "
            << frame.values.cols();
    throw std::invalid_argument(message.str());
  }
  const int g = options.grid, k = options.supersample;
  const double c = std::cos(moment[2]), s = std::sin(moment[2]);
  Eigen::VectorXf out = Eigen::VectorXf::Zero(static_cast<Eigen::Index>(g) * g * channels);
  const bool weighted = frame.weights.size() > 0;
  const float per_sample = 1.0f / static_cast<float>(k * k);
  for (int a = 0; a < g; ++a) {
    for (int b = 0; b < g; ++b) {
      float* cell = out.data() + (static_cast<Eigen::Index>(a) * g + b) * channels;
      for (int i = 0; i < k; ++i) {
        for (int j = 0; j < k; ++j) {
          // The square's point q (q_0 along b, q_1 along a), then the frame's p = t + R q.
          const double q0 = options.extent * (2.0 * (b + (j + 0.5) / k) / g - 1.0);
          const double q1 = options.extent * (2.0 * (a + (i + 0.5) / k) / g - 1.0);
          const double p0 = moment[0] + c * q0 - s * q1;
          const double p1 = moment[1] + s * q0 + c * q1;
          // PhotometricTrunk's coordinates inverted: pixel centres at integers.
          const double col = (p0 * rows + cols - 1) / 2.0;
          const double row = ((p1 + 1.0) * rows - 1.0) / 2.0;
          const int r0 = static_cast<int>(std::floor(row));
          const int c0 = static_cast<int>(std::floor(col));
          const double fr = row - r0, fc = col - c0;
          for (int dr = 0; dr < 2; ++dr) {
            for (int dc = 0; dc < 2; ++dc) {
              const int r = r0 + dr, cc = c0 + dc;
              if (r < 0 || r >= rows || cc < 0 || cc >= cols) continue;  // zero outside
              const Eigen::Index pixel = static_cast<Eigen::Index>(r) * cols + cc;
              float w = static_cast<float>((dr ? fr : 1 - fr) * (dc ? fc : 1 - fc)) * per_sample;
              if (weighted) w *= frame.weights[pixel];
              for (int ch = 0; ch < channels; ++ch) cell[ch] += w * frame.values(pixel, ch);
            }
          }
        }
      }
    }
  }
  return out;
}

WarmStartTable PhotometricWarmStart::BuildTable(const PhotometricTrunk& trunk,
                                                const std::vector<TrunkTargets>& frames,
                                                const Eigen::MatrixXd& latents,
                                                const Options& options, int threads) {
  std::string error;
  if (!options.IsValid(&error)) {
    throw std::invalid_argument("PhotometricWarmStart::Options: " + error);
  }
  const int d = trunk.latent_dim();
  if (frames.empty()) throw std::invalid_argument("PhotometricWarmStart: no frames");
  if (latents.cols() != d || latents.rows() != static_cast<Eigen::Index>(frames.size())) {
    std::ostringstream message;
    message << "PhotometricWarmStart: expected latents of " << frames.size() << " x " << d
            << " (one row per frame), found " << latents.rows() << " x " << latents.cols();
    throw std::invalid_argument(message.str());
  }
  WarmStartTable table;
  table.grid = options.grid;
  table.extent = options.extent;
  table.supersample = options.supersample;
  const Eigen::Index n = static_cast<Eigen::Index>(frames.size());
  table.descriptors.resize(n, static_cast<Eigen::Index>(options.grid) * options.grid *
                                  trunk.channels());
  table.latents.resize(n, d);
  internal::ParallelFor(static_cast<int>(n), threads, [&](int i) {
    const Eigen::Vector3d moment = MomentPose(trunk, frames[i]);
    table.descriptors.row(i) = Descriptor(trunk, frames[i], moment, options).transpose();
    const SE2d frame_of_moment = SE2d::FromXYYaw(moment[0], moment[1], moment[2]);
    const SE2d contact = SE2d::FromXYYaw(latents(i, 0), latents(i, 1), latents(i, 2));
    const SE2d relative = frame_of_moment.Inverse() * contact;
    table.latents(i, 0) = static_cast<float>(relative.x());
    table.latents(i, 1) = static_cast<float>(relative.y());
    table.latents(i, 2) = static_cast<float>(relative.yaw());
    table.latents.row(i).tail(d - PhotometricTrunk::kPoseValues) =
        latents.row(i).tail(d - PhotometricTrunk::kPoseValues).cast<float>();
  });
  return table;
}

PhotometricWarmStart::PhotometricWarmStart(const PhotometricTrunk& trunk,
                                           std::shared_ptr<const WarmStartTable> table)
    : trunk_(&trunk), table_(std::move(table)) {
  if (table_ == nullptr) throw std::invalid_argument("PhotometricWarmStart: no table");
  options_ = TableOptions(*table_);
  std::string error;
  if (!options_.IsValid(&error)) {
    throw std::invalid_argument("PhotometricWarmStart: the table's " + error);
  }
  const Eigen::Index columns =
      static_cast<Eigen::Index>(options_.grid) * options_.grid * trunk.channels();
  if (table_->latents.cols() != trunk.latent_dim() || table_->descriptors.cols() != columns ||
      table_->latents.rows() != table_->descriptors.rows() || table_->latents.rows() < 1) {
    std::ostringstream message;
    message << "PhotometricWarmStart: the table holds " << table_->descriptors.rows() << " x "
            << table_->descriptors.cols() << " descriptors and " << table_->latents.rows()
            << " x " << table_->latents.cols() << " latents; the trunk expects " << columns
            << " descriptor values and " << trunk.latent_dim() << " latent values per row";
    throw std::invalid_argument(message.str());
  }
  FlannKnnIndex::Options index;
  index.algorithm = FlannKnnIndex::Algorithm::kLinear;
  index_ = std::make_unique<FlannKnnIndex>(static_cast<int>(columns), index);
  const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor> rows =
      table_->descriptors;
  index_->Add(rows.data(), rows.rows());
}

PhotometricWarmStart::~PhotometricWarmStart() = default;
PhotometricWarmStart::PhotometricWarmStart(PhotometricWarmStart&&) noexcept = default;
PhotometricWarmStart& PhotometricWarmStart::operator=(PhotometricWarmStart&&) noexcept = default;

std::vector<Eigen::VectorXd> PhotometricWarmStart::Starts(const TrunkTargets& frame,
                                                          int k) const {
  if (k < 1) throw std::invalid_argument("PhotometricWarmStart: k must be >= 1");
  const Eigen::Vector3d moment = MomentPose(*trunk_, frame);
  const Eigen::VectorXf descriptor = Descriptor(*trunk_, frame, moment, options_);
  Eigen::Matrix<float, 2, Eigen::Dynamic, Eigen::RowMajor> queries(2, descriptor.size());
  queries.row(0) = descriptor.transpose();
  queries.row(1) = Flipped(descriptor, options_.grid, trunk_->channels()).transpose();
  std::vector<float> distances(2 * static_cast<std::size_t>(k));
  std::vector<std::int64_t> labels(distances.size());
  index_->Search(queries.data(), 2, k, distances.data(), labels.data());
  // Both turns' neighbours, nearest first; a tie keeps the unturned one first.
  std::vector<int> order(distances.size());
  for (int i = 0; i < static_cast<int>(order.size()); ++i) order[i] = i;
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) {
    return distances[a] < distances[b];
  });
  const SE2d frame_of_moment = SE2d::FromXYYaw(moment[0], moment[1], moment[2]);
  std::vector<Eigen::VectorXd> starts;
  for (int i : order) {
    if (static_cast<int>(starts.size()) == k) break;
    if (labels[i] < 0) continue;
    const bool turned = i >= k;
    const Eigen::VectorXf row = table_->latents.row(labels[i]).transpose();
    const SE2d relative = SE2d::FromXYYaw(row[0], row[1], row[2]);
    const SE2d base = turned ? frame_of_moment * SE2d::Rot(kPi) : frame_of_moment;
    const SE2d contact = base * relative;
    Eigen::VectorXd start = row.cast<double>();
    start[0] = contact.x();
    start[1] = contact.y();
    start[2] = contact.yaw();
    starts.push_back(std::move(start));
  }
  return starts;
}

Eigen::VectorXd PhotometricWarmStart::BestStart(const TrunkTargets& frame, int k, int pixels,
                                                const PhotometricTrunk::Markers* markers) const {
  std::vector<Eigen::VectorXd> starts = Starts(frame, k);
  if (starts.empty()) {
    // No neighbour (a descriptor that is not finite): the cold fit's moment start.
    Eigen::VectorXd start = Eigen::VectorXd::Zero(trunk_->latent_dim());
    start.head<PhotometricTrunk::kPoseValues>() = MomentPose(*trunk_, frame);
    return start;
  }
  if (starts.size() == 1) return starts[0];
  const int n = static_cast<int>(frame.values.rows());
  const int count = std::max(1, std::min(pixels, n));
  std::vector<int> subset(count);
  Eigen::MatrixXf targets(count, frame.values.cols());
  Eigen::VectorXf weights(count);
  for (int i = 0; i < count; ++i) {
    subset[i] = static_cast<int>(static_cast<std::int64_t>(i) * n / count);
    targets.row(i) = frame.values.row(subset[i]);
    weights[i] = frame.weights.size() == 0 ? 1.0f : frame.weights[subset[i]];
  }
  std::size_t best = 0;
  double best_loss = std::numeric_limits<double>::infinity();
  for (std::size_t i = 0; i < starts.size(); ++i) {
    const double loss = trunk_->LossAndGradient<float>(subset, starts[i].cast<float>(), targets,
                                                       weights, nullptr, nullptr, nullptr,
                                                       nullptr, markers);
    if (loss < best_loss) {
      best_loss = loss;
      best = i;
    }
  }
  return starts[best];
}

PhotometricFit PhotometricWarmStart::Fit(const TrunkTargets& frame, int k,
                                         PhotometricFitOptions options,
                                         std::uint64_t seed) const {
  const Eigen::VectorXd start = BestStart(frame, k, kScoredPixels, options.markers);
  if (options.steps == 0) {
    PhotometricFit fit;
    fit.latent = start;
    fit.loss = std::numeric_limits<double>::quiet_NaN();
    return fit;
  }
  options.flipped_start = false;
  options.score = false;
  return FitPhotometricLatent(*trunk_, frame, options, seed, &start);
}

}  // namespace tactfunc
