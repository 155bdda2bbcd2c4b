// Copyright 2026 The tactfunc Authors.
#include "estimation/data/internal/path_util.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cstdio>
#include <filesystem>
#include <opencv2/core.hpp>
#include <system_error>

#include "estimation/data/image_io.h"

namespace tactfunc::internal {

namespace fs = std::filesystem;

std::string JoinPath(const std::string& a, const std::string& b) {
  if (a.empty() || (!b.empty() && b.front() == '/')) return b;
  if (a.back() == '/') return a + b;
  return a + "/" + b;
}

std::string ToLower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(),
                 [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

std::string BaseName(const std::string& path) { return fs::path(path).filename().string(); }

std::vector<ImageFileEntry> ListImageFiles(const std::string& dir) {
  std::error_code ec;
  fs::directory_iterator it(dir, ec);
  if (ec) {
    throw DatasetError(dir + ": expected a readable directory, got error '" + ec.message() + "'");
  }
  std::vector<ImageFileEntry> entries;
  for (const fs::directory_entry& entry : it) {
    const fs::path& p = entry.path();
    const std::string name = p.filename().string();
    if (name.empty() || name[0] == '.') continue;  // hidden, and our temp files
    std::error_code type_ec;
    if (!entry.is_regular_file(type_ec)) continue;
    const std::string ext = ToLower(p.extension().string());
    if (ext != ".png" && ext != ".jpg" && ext != ".jpeg") continue;
    entries.push_back({name, p.stem().string()});
  }
  std::sort(entries.begin(), entries.end(),
            [](const ImageFileEntry& a, const ImageFileEntry& b) { return a.name < b.name; });
  return entries;
}

bool IsDirectory(const std::string& path) {
  std::error_code ec;
  return fs::is_directory(path, ec);
}

bool IsRegularFile(const std::string& path) {
  std::error_code ec;
  return fs::is_regular_file(path, ec);
}

std::uint64_t FileSizeOrThrow(const std::string& path) {
  std::error_code ec;
  const std::uintmax_t size = fs::file_size(path, ec);
  if (ec) {
    throw DatasetError(path + ": expected a readable file, got error '" + ec.message() + "'");
  }
  return size;
}

ImageProbe ProbeImage(const std::string& path) {
  // The header alone: the sensor kind of a folder is decided without decoding a pixel.
  const ImageHeader header = ReadImageHeader(path);
  ImageProbe probe;
  probe.rows = header.rows;
  probe.cols = header.cols;
  probe.channels = header.channels;
  // OpenCV decodes PNGs of 1, 2 or 4 bits and every JPEG to 8 bits per sample.
  probe.bit_depth = header.format == ImageHeader::Format::kPng && header.bit_depth == 16 ? 16 : 8;
  return probe;
}

std::string FormatDoubleExact(double value) {
  char buffer[64];
  const std::to_chars_result result = std::to_chars(buffer, buffer + sizeof(buffer), value);
  return std::string(buffer, result.ptr);
}

std::string FormatDoubleShort(double value) {
  char buffer[64];
  std::snprintf(buffer, sizeof(buffer), "%.5g", value);
  return buffer;
}

bool ParseDouble(const std::string& text, double* value) {
  if (text.empty()) return false;
  const char* begin = text.data();
  const char* end = begin + text.size();
  double parsed = 0;
  const std::from_chars_result result = std::from_chars(begin, end, parsed);
  if (result.ec != std::errc() || result.ptr != end) return false;
  *value = parsed;
  return true;
}

bool ParseInt(const std::string& text, int* value) {
  if (text.empty()) return false;
  const char* begin = text.data();
  const char* end = begin + text.size();
  int parsed = 0;
  const std::from_chars_result result = std::from_chars(begin, end, parsed);
  if (result.ec != std::errc() || result.ptr != end) return false;
  *value = parsed;
  return true;
}

}  // namespace tactfunc::internal
