// Copyright 2026 The tactfunc Authors.
//
// A PNG reader on libpng (and libdeflate for the common frames, below): the format of every dataset tactfunc writes is decoded without
// OpenCV's codec module (codecs.h), so reading, checking and refusing PNG frames never
// maps it. Decodes as cv::imdecode(..., cv::IMREAD_UNCHANGED) does: gray stays one
// channel, colour comes in B, G, R (and A) order, 16-bit samples stay 16-bit, palettes
// and bit depths under 8 are expanded to 8-bit samples, transparency becomes an alpha
// channel (gray with alpha becomes BGRA); no gamma correction.
#ifndef TACTFUNC_ESTIMATION_DATA_INTERNAL_PNG_READER_H_
#define TACTFUNC_ESTIMATION_DATA_INTERNAL_PNG_READER_H_

#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <string>

namespace tactfunc::internal {

// Decodes `size` bytes of PNG. An empty Mat and *error (libpng's reason) if they do not
// decode (bad signature, damaged or truncated data, bad CRC).
cv::Mat DecodePngSamples(const std::uint8_t* data, std::size_t size, std::string* error);

// The path DecodePngSamples takes first, for the frames tactfunc reads: a non-interlaced
// gray, RGB or RGBA PNG of 8- or 16-bit samples, with no transparency chunk and no
// critical chunk but IHDR, PLTE (colour only), IDAT and IEND. Every chunk's CRC is
// checked up to IEND, the IDAT stream is inflated by libdeflate in one call (about 2.5x
// zlib's inflate on noisy sensor frames, which hardly compress) and the rows are
// unfiltered here; the result is DecodePngSamples' (same layout and samples). An empty
// Mat for any other file, and for anything damaged: libpng then decodes it or says
// what is wrong.
cv::Mat DecodeCommonPng(const std::uint8_t* data, std::size_t size);

}  // namespace tactfunc::internal

#endif  // TACTFUNC_ESTIMATION_DATA_INTERNAL_PNG_READER_H_
