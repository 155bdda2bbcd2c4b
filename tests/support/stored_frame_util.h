// Copyright 2026 The tactfunc Authors.
//
// A simulated Soft Bubble depth image as a dataset file holds it: depth rounded to 16-bit
// micrometres (estimation/data/image_io.h), so that a test frame is exactly what `tactfunc
// synth` would have written.
#ifndef TACTFUNC_TESTS_SUPPORT_STORED_FRAME_UTIL_H_
#define TACTFUNC_TESTS_SUPPORT_STORED_FRAME_UTIL_H_

#include "estimation/data/image_io.h"

namespace tactfunc::testing_util {

inline Image AsStoredDepth(const Image& depth) {
  return DecodeImage(EncodePng(depth, PixelEncoding::kDepthU16Micrometres),
                     PixelEncoding::kDepthU16Micrometres, "stored test frame");
}

}  // namespace tactfunc::testing_util

#endif  // TACTFUNC_TESTS_SUPPORT_STORED_FRAME_UTIL_H_
