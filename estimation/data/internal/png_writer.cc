// Copyright 2026 The tactfunc Authors.
#include "estimation/data/internal/png_writer.h"

#include <png.h>
#include <zlib.h>

#include <csetjmp>
#include <stdexcept>
#include <vector>

#include "estimation/data/internal/png_callbacks.h"

namespace tactfunc::internal {
namespace {

void AppendBytes(png_structp png, png_bytep data, png_size_t size) {
  auto* out = static_cast<std::string*>(png_get_io_ptr(png));
  out->append(reinterpret_cast<const char*>(data), size);
}

void Flush(png_structp) {}

}  // namespace

std::string EncodePngSamples(const void* samples, int rows, int cols, int channels,
                             int bit_depth, int compression_level) {
  if ((channels != 1 && channels != 3) || (bit_depth != 8 && bit_depth != 16) ||
      rows <= 0 || cols <= 0) {
    throw std::runtime_error("PNG writer: unsupported image " + std::to_string(rows) + "x" +
                             std::to_string(cols) + "x" + std::to_string(channels) + " at " +
                             std::to_string(bit_depth) + " bits");
  }
  std::string error;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, &error, PngKeepErrorAndJump,
                                            PngIgnoreWarning);
  if (png == nullptr) throw std::runtime_error("PNG writer: out of memory");
  png_infop info = png_create_info_struct(png);
  std::string out;
  out.reserve(static_cast<std::size_t>(rows) * cols * channels * (bit_depth / 8) / 2 + 1024);
  const std::size_t row_bytes = static_cast<std::size_t>(cols) * channels * (bit_depth / 8);
  const auto* bytes = static_cast<const unsigned char*>(samples);
  if (info == nullptr || setjmp(png_jmpbuf(png))) {
    png_destroy_write_struct(&png, &info);
    throw std::runtime_error("PNG writer: " + (error.empty() ? std::string("failed") : error));
  }
  png_set_write_fn(png, &out, AppendBytes, Flush);
  png_set_IHDR(png, info, cols, rows, bit_depth,
               channels == 3 ? PNG_COLOR_TYPE_RGB : PNG_COLOR_TYPE_GRAY, PNG_INTERLACE_NONE,
               PNG_COMPRESSION_TYPE_DEFAULT, PNG_FILTER_TYPE_DEFAULT);
  png_set_compression_level(png, compression_level);
  if (compression_level == 1) {
    png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_FILTER_SUB);
    png_set_compression_strategy(png, Z_HUFFMAN_ONLY);
  }
  png_write_info(png, info);
  if (bit_depth == 16) png_set_swap(png);  // PNG is big-endian; our samples are native
  for (int r = 0; r < rows; ++r) {
    png_write_row(png, const_cast<png_bytep>(bytes + r * row_bytes));
  }
  png_write_end(png, info);
  png_destroy_write_struct(&png, &info);
  return out;
}

}  // namespace tactfunc::internal
