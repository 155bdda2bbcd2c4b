// Copyright 2026 The tactfunc Authors.
//
// Shared by the libFuzzer targets (tests/fuzz/*_fuzzer.cc; docs/RELIABILITY.md).
//
// What a target treats as a finding, besides AddressSanitizer / UBSan reports:
// - an exception that is not the reader's documented error type (e.g. a JSON library
//   exception or std::length_error escaping a reader) -- libFuzzer reports it;
// - an error message that does not name the source or is longer than kMaxMessage bytes
//   (a reader must quote excerpts, never whole values) -- Finding() aborts.
#ifndef TACTFUNC_TESTS_FUZZ_FUZZ_UTIL_H_
#define TACTFUNC_TESTS_FUZZ_FUZZ_UTIL_H_

#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <string>

#include "models/core/tensor_file.h"

namespace tactfunc::fuzz {

inline constexpr std::size_t kMaxMessage = 4096;

// Prints `what` and aborts: libFuzzer saves the input as a crash.
[[noreturn]] inline void Finding(const std::string& what) {
  std::fprintf(stderr, "FUZZ FINDING: %s\n", what.substr(0, 8192).c_str());
  std::abort();
}

// Checks an error message of a rejected input.
inline void CheckMessage(const std::string& message, const std::string& source) {
  if (message.find(source) == std::string::npos) {
    Finding("error message does not name '" + source + "': " + message);
  }
  if (message.size() > kMaxMessage) {
    Finding("error message of " + std::to_string(message.size()) + " bytes: " + message);
  }
}

// The input with its last four bytes replaced by the CRC-32 of the rest, so that the
// mutations reach the header and payload checks behind the checksum (a random
// mutation almost never keeps a CRC valid).
inline std::string WithValidChecksum(const std::uint8_t* data, std::size_t size) {
  std::string bytes(reinterpret_cast<const char*>(data), size);
  if (bytes.size() >= 28) {
    const std::uint32_t crc = Crc32(bytes.data(), bytes.size() - 4);
    for (int i = 0; i < 4; ++i) bytes[bytes.size() - 4 + i] = static_cast<char>(crc >> (8 * i));
  }
  return bytes;
}

}  // namespace tactfunc::fuzz

#endif  // TACTFUNC_TESTS_FUZZ_FUZZ_UTIL_H_
