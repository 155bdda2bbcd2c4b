// Copyright 2026 The tactfunc Authors.
//
// Contact detection: is a frame a touch, or the sensor at rest plus noise, and where
// is the touch? Most frames of a grasp recording show no contact; telling them apart
// lets evaluation report the two kinds separately and lets users spend nothing on
// frames that hold only noise.
//
// The test works on the difference d = frame - reference (Difference() in
// preprocess.h, physical units, any channel count, non-finite pixels invalid):
//
//   1. Noise. The sensor's per-pixel noise sigma is estimated from the frame itself,
//      robustly: sigma = 1.4826 median |d(r, c+1) - d(r, c)| / sqrt(2) over horizontal
//      neighbours where both pixels are valid, all channels pooled. A contact is smooth
//      at the pixel scale (a dent, a shading blob), so neighbour differences see the
//      noise and barely the contact; the median ignores the edges and markers that do
//      change between neighbours. The estimate is floored at the quantisation noise of
//      the sensor's encoding (step / sqrt(12)), so a frame identical to its reference
//      does not divide by zero.
//   2. Signal. Each channel is averaged over a window x window box around every pixel
//      (valid pixels only); the magnitude M = sqrt(sum_c box(d_c)^2) is the local
//      strength of the change. For white noise alone, box(d_c) has standard deviation
//      sigma / window, so score = max M window / sigma is the peak in units of its own
//      noise (sqrt of a chi-square with C degrees of freedom where there is no contact).
//   3. Decision: contact if score >= threshold (default 6: without contact a
//      19,200-pixel, 3-channel frame exceeds it with probability about 1e-4 under white
//      noise). Lighting flicker or compression artefacts that are not white raise the
//      scores of frames at rest; raise the threshold for such sensors.
//   4. Centre: the M^2-weighted centroid of the pixels whose M is at least half the
//      peak, in pixel coordinates of the difference (row, col; pixel centres at
//      integers). For several separate contacts it lies between them.
//
// The tests (tests/estimation/data/contact_test.cc) check the noise estimate on white
// noise, the false-alarm rate at rest, detection and centre of synthetic presses, and
// the centres of 49 real GelSight ball presses against their hand-placed labels.
#ifndef TACTFUNC_ESTIMATION_DATA_CONTACT_H_
#define TACTFUNC_ESTIMATION_DATA_CONTACT_H_

#include <cstddef>
#include <limits>
#include <string>

#include "estimation/data/image_io.h"
#include "models/core/image.h"

namespace tactfunc {

class Dataset;

struct ContactOptions {
  // Score (peak local change in units of its noise) at which a frame is a contact. > 0.
  double threshold = 6.0;
  // Side of the averaging box in pixels, odd, >= 1.
  int window = 5;
  // Lower bound of the noise sigma in the difference's units; 0 = the quantisation noise
  // of `encoding` below. >= 0.
  double noise_floor = 0;
  PixelEncoding encoding = PixelEncoding::kRgb8;
  bool IsValid(std::string* error) const;
};

struct ContactReport {
  bool contact = false;
  double score = 0;        // max M window / noise_sigma (0 without a valid pixel)
  double noise_sigma = 0;  // estimated per-pixel noise, the difference's units
  double peak = 0;         // max M, the difference's units
  // Centre of the strongest change (step 4), pixels; NaN without a valid pixel or when
  // the difference is exactly zero. Given for every frame: read it only when `contact`.
  double centre_row = std::numeric_limits<double>::quiet_NaN();
  double centre_col = std::numeric_limits<double>::quiet_NaN();
};

// The per-pixel noise sigma of a difference image (step 1), floored at `floor`.
double EstimateNoiseSigma(const Image& difference, double floor);

// The quantisation noise of an encoding: step / sqrt(12), step = 1 um for depth_u16_um
// (metres), 1/255 for rgb8 (intensity).
double QuantisationNoise(PixelEncoding encoding);

// Steps 1-4 on a difference image. Throws std::invalid_argument for invalid options or
// an empty image.
ContactReport DetectContact(const Image& difference, const ContactOptions& options = {});

// DetectContact of frame `index` of `dataset` against its reference (FrameReference:
// its clip's in a clip set), with the encoding of its sensor. Throws like
// Dataset::LoadFrame.
ContactReport DetectFrameContact(const Dataset& dataset, std::size_t index,
                                 ContactOptions options = {});
// The same from `frame`, frame `index` as already decoded (Dataset::LoadFrame), so that a
// caller building the frame's targets too decodes it once.
ContactReport DetectFrameContact(const Dataset& dataset, std::size_t index, const Image& frame,
                                 ContactOptions options = {});

// Step 4 alone with the box `window` (1 = no smoothing): the centre of the strongest
// change of an image, e.g. a reconstruction, whose noise is not the question. NaN,
// NaN when the image is zero or has no finite pixel.
void ContactCentre(const Image& difference, int window, double* row, double* col);

}  // namespace tactfunc

#endif  // TACTFUNC_ESTIMATION_DATA_CONTACT_H_
