// Copyright 2026 The tactfunc Authors.
//
// Image headers and decoding (DecodeImage: PNG/JPEG header, pixel limit, then OpenCV).
// The first byte picks the encoding (depth or rgb8).
#include <cstddef>
#include <cstdint>

#include "estimation/data/image_io.h"
#include "tests/fuzz/fuzz_util.h"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tactfunc;
  if (size < 1) return 0;
  const PixelEncoding encoding =
      data[0] & 1 ? PixelEncoding::kRgb8 : PixelEncoding::kDepthU16Micrometres;
  const std::string bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
  try {
    const Image image = DecodeImage(bytes, encoding, "fuzz.png");
    if (static_cast<std::int64_t>(image.rows) * image.cols > kMaxFramePixels) {
      fuzz::Finding("decoded an image beyond the pixel limit");
    }
  } catch (const DatasetError& e) {
    fuzz::CheckMessage(e.what(), "fuzz.png");
  }
  return 0;
}
