// Copyright 2026 The tactfunc Authors.
//
// Image bytes and values for tests of the image readers and frame preprocessing.
#ifndef TACTFUNC_TESTS_SUPPORT_IMAGE_TEST_UTIL_H_
#define TACTFUNC_TESTS_SUPPORT_IMAGE_TEST_UTIL_H_

#include <cstdint>
#include <limits>
#include <string>

namespace tactfunc::testing_util {

// A missing reading (a depth dropout, an invalid pixel).
inline constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// The first 33 bytes of a PNG: signature and an IHDR chunk claiming `width` x `height`
// (the chunk CRC is not checked by the header reader; OpenCV would check it).
inline std::string PngHeaderOnly(std::uint32_t width, std::uint32_t height, int bit_depth,
                                 int colour) {
  std::string out("\x89PNG\r\n\x1a\n\0\0\0\x0dIHDR", 16);
  for (std::uint32_t v : {width, height}) {
    for (int shift = 24; shift >= 0; shift -= 8) out.push_back(static_cast<char>(v >> shift));
  }
  out.push_back(static_cast<char>(bit_depth));
  out.push_back(static_cast<char>(colour));
  out += std::string(3, '\0') + std::string(4, '\0');  // methods, CRC
  return out;
}

}  // namespace tactfunc::testing_util

#endif  // TACTFUNC_TESTS_SUPPORT_IMAGE_TEST_UTIL_H_
