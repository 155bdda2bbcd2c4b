// Copyright 2026 The tactfunc Authors.
#include "estimation/data/internal/png_reader.h"

#include <png.h>

#include <csetjmp>
#include <cstring>
#include <vector>

namespace tactfunc::internal {
namespace {

struct Source {
  const std::uint8_t* data;
  std::size_t size;
  std::size_t offset;
};

void ReadBytes(png_structp png, png_bytep out, png_size_t n) {
  auto* source = static_cast<Source*>(png_get_io_ptr(png));
  if (n > source->size - source->offset) png_error(png, "truncated PNG data");
  std::memcpy(out, source->data + source->offset, n);
  source->offset += n;
}

void OnError(png_structp png, png_const_charp message) {
  *static_cast<std::string*>(png_get_error_ptr(png)) = message;
  png_longjmp(png, 1);
}

void OnWarning(png_structp, png_const_charp) {}

}  // namespace

cv::Mat DecodePngSamples(const std::uint8_t* data, std::size_t size, std::string* error) {
  // Everything the error path must destroy exists before setjmp (a longjmp may not skip
  // a destructor).
  std::string reason;
  cv::Mat image;
  std::vector<png_bytep> rows;
  Source source{data, size, 0};
  if (size < 8 || png_sig_cmp(data, 0, 8) != 0) {
    if (error != nullptr) *error = "not a PNG signature";
    return image;
  }
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &reason, OnError, OnWarning);
  if (png == nullptr) {
    if (error != nullptr) *error = "out of memory";
    return image;
  }
  png_infop info = png_create_info_struct(png);
  if (info == nullptr || setjmp(png_jmpbuf(png))) {
    png_destroy_read_struct(&png, &info, nullptr);
    image.release();
    if (error != nullptr) *error = reason.empty() ? "libpng failed" : reason;
    return image;
  }
  // The header's size was checked against the frame limit before any call gets here;
  // libpng's own limits stay as a second bound.
  png_set_read_fn(png, &source, ReadBytes);
  png_read_info(png, info);
  const png_uint_32 width = png_get_image_width(png, info);
  const png_uint_32 height = png_get_image_height(png, info);
  const int color_type = png_get_color_type(png, info);
  const int bit_depth = png_get_bit_depth(png, info);
  if (color_type == PNG_COLOR_TYPE_PALETTE) png_set_palette_to_rgb(png);
  if (color_type == PNG_COLOR_TYPE_GRAY && bit_depth < 8) png_set_expand_gray_1_2_4_to_8(png);
  const bool transparency = png_get_valid(png, info, PNG_INFO_tRNS) != 0;
  if (transparency) png_set_tRNS_to_alpha(png);
  if (color_type == PNG_COLOR_TYPE_GRAY_ALPHA ||
      (color_type == PNG_COLOR_TYPE_GRAY && transparency)) {
    png_set_gray_to_rgb(png);
  }
  if (bit_depth == 16) png_set_swap(png);  // PNG is big-endian; cv::Mat samples are native
  png_set_bgr(png);
  png_set_interlace_handling(png);
  png_read_update_info(png, info);
  const int channels = png_get_channels(png, info);
  const int depth = png_get_bit_depth(png, info) == 16 ? CV_16U : CV_8U;
  image.create(static_cast<int>(height), static_cast<int>(width), CV_MAKETYPE(depth, channels));
  if (png_get_rowbytes(png, info) != image.step[0]) png_error(png, "unexpected row size");
  rows.resize(height);
  for (png_uint_32 r = 0; r < height; ++r) rows[r] = image.ptr<png_byte>(static_cast<int>(r));
  png_read_image(png, rows.data());
  png_read_end(png, nullptr);
  png_destroy_read_struct(&png, &info, nullptr);
  return image;
}

}  // namespace tactfunc::internal
