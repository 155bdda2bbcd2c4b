// Copyright 2026 The tactfunc Authors.
#include "estimation/data/photometric_markers.h"

#include <stdexcept>
#include <string>

#include "estimation/data/dataset.h"

namespace tactfunc {

Image PhotometricReference(const Image& reference, const FrameFormat& format) {
  if (format.per_image_min_max || !(format.scale > 0)) {
    throw std::invalid_argument(
        "PhotometricReference: the photometric trunk needs a fixed-scale frame format");
  }
  const bool luma = format.grayscale && reference.channels == 3;
  Image out(reference.rows, reference.cols, luma ? 1 : reference.channels);
  for (int r = 0; r < reference.rows; ++r) {
    for (int c = 0; c < reference.cols; ++c) {
      if (luma) {
        // ITU-R BT.601 luma, as estimation/data/preprocess.h converts differences.
        out.at(r, c) = static_cast<float>((0.299 * reference.at(r, c, 0) +
                                           0.587 * reference.at(r, c, 1) +
                                           0.114 * reference.at(r, c, 2)) /
                                          format.scale);
      } else {
        for (int ch = 0; ch < out.channels; ++ch) {
          out.at(r, c, ch) = static_cast<float>(reference.at(r, c, ch) / format.scale);
        }
      }
    }
  }
  return out;
}

std::shared_ptr<const PhotometricTrunk::Markers> FrameMarkers(const SensorTrunk& trunk,
                                                              const Image& reference) {
  if (trunk.photometric == nullptr) {
    throw std::invalid_argument("FrameMarkers: the " + std::string(ToString(trunk.sensor)) +
                                " trunk has no photometric head");
  }
  return trunk.photometric->MakeMarkers(PhotometricReference(reference, trunk.format));
}

DatasetMarkers::DatasetMarkers(const Dataset& dataset, const SensorTrunk& trunk)
    : dataset_(dataset), trunk_(trunk) {
  if (trunk.photometric == nullptr) {
    throw std::invalid_argument("DatasetMarkers: the " + std::string(ToString(trunk.sensor)) +
                                " trunk has no photometric head");
  }
}

const PhotometricTrunk::Markers* DatasetMarkers::Of(std::size_t index) const {
  const FrameRecord& record = dataset_.frames().at(index);
  if (record.sensor != trunk_.sensor) {
    throw std::invalid_argument("DatasetMarkers: frame '" + record.id + "' is a " +
                                ToString(record.sensor) + " frame; the trunk draws " +
                                ToString(trunk_.sensor) + " frames");
  }
  const std::lock_guard<std::mutex> lock(mutex_);
  auto& markers = by_clip_[record.clip];
  if (markers == nullptr) {
    markers = FrameMarkers(trunk_, dataset_.FrameReference(index));
  }
  return markers.get();
}

}  // namespace tactfunc
