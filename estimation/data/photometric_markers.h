// Copyright 2026 The tactfunc Authors.
//
// The references a photometric trunk (models/trunk/photometric_trunk.h) draws a frame's
// markers from. Its head moves the no-contact reference's printed pattern by the skin's
// slope, so a frame must be drawn against ITS OWN reference: the clip's in a set of
// recordings (estimation/data/dataset.h, "clips"), each with its own no-contact frame,
// else its sensor's. A trunk keeps the reference it was trained on (the first clip's
// for a clip set) for frames given without one.
#ifndef TACTFUNC_ESTIMATION_DATA_PHOTOMETRIC_MARKERS_H_
#define TACTFUNC_ESTIMATION_DATA_PHOTOMETRIC_MARKERS_H_

#include <cstddef>
#include <map>
#include <memory>
#include <mutex>

#include "models/core/image.h"
#include "models/trunk/functa_model.h"
#include "models/trunk/photometric_trunk.h"

namespace tactfunc {

class Dataset;

// The sensor-resolution reference in the targets' units under `format`: the luma of an
// RGB reference if the format is grayscale (the luma of a difference is the difference of
// the lumas), divided by the format's fixed scale; not resized. Throws
// std::invalid_argument for a per-image min-max format (no fixed units).
Image PhotometricReference(const Image& reference, const FrameFormat& format);

// The markers a photometric `trunk` draws a frame against whose no-contact reference
// (physical units, as the dataset or --reference gives it) is `reference`:
// PhotometricTrunk::MakeMarkers of PhotometricReference under the trunk's format.
// Throws std::invalid_argument if the trunk has no photometric head, as
// PhotometricReference does, or for a reference of other channels than the trunk's.
std::shared_ptr<const PhotometricTrunk::Markers> FrameMarkers(const SensorTrunk& trunk,
                                                              const Image& reference);

// The markers of each frame's own reference in `dataset` for one photometric trunk,
// made on first use (FrameMarkers) and kept,
// one per clip (or one per sensor outside a clip set).
//
// Thread safety: Of() may be called concurrently. The dataset and the trunk must
// outlive this.
class DatasetMarkers {
 public:
  // Throws std::invalid_argument if `trunk` has no photometric head.
  DatasetMarkers(const Dataset& dataset, const SensorTrunk& trunk);

  // The markers frame `index` is drawn against. Throws std::out_of_range for a bad
  // index, std::invalid_argument for a frame of another sensor or a reference of other
  // channels than the trunk's.
  const PhotometricTrunk::Markers* Of(std::size_t index) const;

 private:
  const Dataset& dataset_;
  const SensorTrunk& trunk_;
  mutable std::mutex mutex_;
  mutable std::map<int, std::shared_ptr<const PhotometricTrunk::Markers>> by_clip_;
};

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_DATA_PHOTOMETRIC_MARKERS_H_
