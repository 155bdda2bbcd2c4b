// Copyright 2026 The tactfunc Authors.
#include "estimation/data/internal/png_reader.h"

#include <libdeflate.h>
#include <png.h>

#include <csetjmp>
#include <cstdlib>
#include <cstring>
#include <memory>
#include <vector>

#include "estimation/data/internal/png_callbacks.h"

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

std::uint32_t BigEndian32(const std::uint8_t* p) {
  return (std::uint32_t{p[0]} << 24) | (std::uint32_t{p[1]} << 16) | (std::uint32_t{p[2]} << 8) |
         std::uint32_t{p[3]};
}

int PaethPredictor(int a, int b, int c) {
  const int p = a + b - c;
  const int pa = std::abs(p - a), pb = std::abs(p - b), pc = std::abs(p - c);
  if (pa <= pb && pa <= pc) return a;
  return pb <= pc ? b : c;
}

// Undoes the filter of one row in place (PNG specification, section 9); `previous` is the
// row above, unfiltered, or null for the first row. False for an unknown filter type.
bool Unfilter(int type, std::uint8_t* row, const std::uint8_t* previous, std::size_t bytes,
              std::size_t bpp) {
  switch (type) {
    case 0:
      return true;
    case 1:
      for (std::size_t i = bpp; i < bytes; ++i) row[i] = row[i] + row[i - bpp];
      return true;
    case 2:
      if (previous != nullptr) {
        for (std::size_t i = 0; i < bytes; ++i) row[i] = row[i] + previous[i];
      }
      return true;
    case 3:
      for (std::size_t i = 0; i < bytes; ++i) {
        const int left = i >= bpp ? row[i - bpp] : 0;
        const int up = previous != nullptr ? previous[i] : 0;
        row[i] = static_cast<std::uint8_t>(row[i] + ((left + up) >> 1));
      }
      return true;
    case 4:
      for (std::size_t i = 0; i < bytes; ++i) {
        const int left = i >= bpp ? row[i - bpp] : 0;
        const int up = previous != nullptr ? previous[i] : 0;
        const int corner = i >= bpp && previous != nullptr ? previous[i - bpp] : 0;
        row[i] = static_cast<std::uint8_t>(row[i] + PaethPredictor(left, up, corner));
      }
      return true;
    default:
      return false;
  }
}

struct DecompressorDeleter {
  void operator()(libdeflate_decompressor* d) const { libdeflate_free_decompressor(d); }
};

}  // namespace

cv::Mat DecodeCommonPng(const std::uint8_t* data, std::size_t size) {
  constexpr std::size_t kSignature = 8;
  if (size < kSignature + 25) return {};
  const std::uint8_t* ihdr = data + kSignature;
  if (BigEndian32(ihdr) != 13 || std::memcmp(ihdr + 4, "IHDR", 4) != 0 ||
      libdeflate_crc32(0, ihdr + 4, 17) != BigEndian32(ihdr + 21)) {
    return {};
  }
  const std::uint32_t width = BigEndian32(ihdr + 8), height = BigEndian32(ihdr + 12);
  const int bit_depth = ihdr[16], color_type = ihdr[17];
  if (width == 0 || height == 0 || width > (1u << 24) || height > (1u << 24) ||
      (bit_depth != 8 && bit_depth != 16) ||
      (color_type != 0 && color_type != 2 && color_type != 6) || ihdr[18] != 0 ||
      ihdr[19] != 0 || ihdr[20] != 0) {
    return {};
  }
  const int channels = color_type == 0 ? 1 : color_type == 2 ? 3 : 4;
  const std::size_t bpp = static_cast<std::size_t>(channels) * (bit_depth / 8);
  const std::size_t row_bytes = bpp * width;
  // The IDAT chunks (consecutive), every chunk's CRC checked up to IEND.
  std::vector<std::uint8_t> stream;
  bool idat_seen = false, idat_done = false, end_seen = false;
  for (std::size_t at = kSignature + 25; !end_seen;) {
    if (size - at < 12) return {};
    const std::uint32_t length = BigEndian32(data + at);
    if (length > size - at - 12) return {};
    const std::uint8_t* type = data + at + 4;
    if (libdeflate_crc32(0, type, length + 4) != BigEndian32(type + 4 + length)) return {};
    const bool critical = (type[0] & 0x20) == 0;
    if (std::memcmp(type, "IDAT", 4) == 0) {
      if (idat_done) return {};
      idat_seen = true;
      stream.insert(stream.end(), type + 4, type + 4 + length);
    } else {
      if (idat_seen) idat_done = true;
      if (std::memcmp(type, "IEND", 4) == 0) {
        end_seen = true;
      } else if (std::memcmp(type, "PLTE", 4) == 0) {
        if (color_type == 0 || idat_seen) return {};  // a suggested palette, before IDAT
      } else if (critical || std::memcmp(type, "tRNS", 4) == 0) {
        return {};
      }
    }
    at += 12 + static_cast<std::size_t>(length);
  }
  if (!idat_seen) return {};
  // The filtered rows: one filter-type byte, then the row's bytes. DEFLATE expands by
  // at most 1032:1, so more than that cannot come out of this stream (no allocation
  // beyond what the file can fill).
  const std::size_t filtered_bytes = (row_bytes + 1) * height;
  if (filtered_bytes / 1032 > stream.size()) return {};
  std::vector<std::uint8_t> filtered(filtered_bytes);
  static thread_local std::unique_ptr<libdeflate_decompressor, DecompressorDeleter> inflater(
      libdeflate_alloc_decompressor());
  if (inflater == nullptr) return {};
  std::size_t consumed = 0, produced = 0;
  if (libdeflate_zlib_decompress_ex(inflater.get(), stream.data(), stream.size(),
                                    filtered.data(), filtered.size(), &consumed,
                                    &produced) != LIBDEFLATE_SUCCESS ||
      consumed != stream.size() || produced != filtered_bytes) {
    return {};
  }
  cv::Mat image(static_cast<int>(height), static_cast<int>(width),
                CV_MAKETYPE(bit_depth == 16 ? CV_16U : CV_8U, channels));
  const std::uint8_t* previous = nullptr;
  for (std::uint32_t r = 0; r < height; ++r) {
    std::uint8_t* row = filtered.data() + r * (row_bytes + 1);
    if (!Unfilter(row[0], row + 1, previous, row_bytes, bpp)) return {};
    previous = row + 1;
    // Into the Mat as libpng's path leaves it: B, G, R (and A), native-endian samples.
    std::uint8_t* out = image.ptr<std::uint8_t>(static_cast<int>(r));
    const std::uint8_t* in = row + 1;
    if (bit_depth == 8) {
      if (channels == 1) {
        std::memcpy(out, in, row_bytes);
      } else {
        for (std::uint32_t c = 0; c < width; ++c, in += channels, out += channels) {
          out[0] = in[2];
          out[1] = in[1];
          out[2] = in[0];
          if (channels == 4) out[3] = in[3];
        }
      }
    } else {
      auto* out16 = reinterpret_cast<std::uint16_t*>(out);
      for (std::uint32_t c = 0; c < width; ++c, in += 2 * channels, out16 += channels) {
        for (int k = 0; k < channels; ++k) {
          const int from = channels >= 3 && k < 3 ? 2 - k : k;
          out16[k] = static_cast<std::uint16_t>((in[2 * from] << 8) | in[2 * from + 1]);
        }
      }
    }
  }
  return image;
}

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
  image = DecodeCommonPng(data, size);
  if (!image.empty()) return image;
  png_structp png = png_create_read_struct(PNG_LIBPNG_VER_STRING, &reason, PngKeepErrorAndJump,
                                           PngIgnoreWarning);
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
