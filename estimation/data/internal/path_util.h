// Copyright 2026 The tactfunc Authors.
//
// Private helpers of estimation/data/image_io.cc and estimation/data/dataset.cc: paths, folder
// listings, image probing and locale-independent number formatting.
#ifndef TACTFUNC_ESTIMATION_DATA_INTERNAL_PATH_UTIL_H_
#define TACTFUNC_ESTIMATION_DATA_INTERNAL_PATH_UTIL_H_

#include <cstdint>
#include <string>
#include <vector>

namespace tactfunc::internal {

// a + "/" + b, without doubling a trailing slash; b if a is empty or b absolute.
std::string JoinPath(const std::string& a, const std::string& b);
std::string ToLower(std::string s);
// The last path component.
std::string BaseName(const std::string& path);

// An image file in a folder: its name and stem (name without the last extension).
struct ImageFileEntry {
  std::string name;
  std::string stem;
};
// Regular, non-hidden *.png, *.jpg, *.jpeg files (extension in any case) directly in
// `dir`, sorted by name. Throws DatasetError if `dir` is not a readable directory.
std::vector<ImageFileEntry> ListImageFiles(const std::string& dir);
bool IsDirectory(const std::string& path);
bool IsRegularFile(const std::string& path);
// Size of a regular file; throws DatasetError naming it if it cannot be read.
std::uint64_t FileSizeOrThrow(const std::string& path);

// What an image file holds, read from its header (ReadImageHeader) without decoding.
struct ImageProbe {
  int rows = 0;
  int cols = 0;
  int channels = 0;
  int bit_depth = 0;  // 8 or 16 (anything else is reported as found)
};
// Throws DatasetError naming `path` if it is missing, not a PNG/JPEG or too large.
ImageProbe ProbeImage(const std::string& path);

// Shortest decimal text that parses back to exactly `value` (std::to_chars);
// independent of the C locale.
std::string FormatDoubleExact(double value);
// "%g"-style short text for messages.
std::string FormatDoubleShort(double value);
// Parses the whole of `text` as a double (std::from_chars, locale-independent;
// no leading '+' or blanks). Returns false on anything else.
bool ParseDouble(const std::string& text, double* value);
// Parses the whole of `text` as an int.
bool ParseInt(const std::string& text, int* value);

}  // namespace tactfunc::internal

#endif  // TACTFUNC_ESTIMATION_DATA_INTERNAL_PATH_UTIL_H_
