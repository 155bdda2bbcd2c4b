// Copyright 2026 The tactfunc Authors.
//
// Image codecs and video decoders, loaded on first use.
//
// OpenCV's imgcodecs and videoio and the libraries they pull in (FFmpeg, GDAL, OpenEXR,
// GStreamer, ...) make up about 60 MB of the resident size of a process that merely links
// them. They live in a module, libtactfunc_codecs.so, that this file loads with dlopen the
// first time a pixel is decoded or encoded, so a command that never decodes (or that
// refuses an oversized frame from its header, read by image_io.h without them) never maps
// them. The module is looked for, in order, at
//   1. $TACTFUNC_CODECS_MODULE (a path to the file),
//   2. <directory of the program>/../lib/tactfunc/libtactfunc_codecs.so (installed),
//   3. <directory of the program>/../lib/libtactfunc_codecs.so (the build tree),
//   4. the build tree and the install prefix this library was configured with.
// A build configured with -DTACTFUNC_CODECS_MODULE=OFF links the codecs in instead (the
// fuzz build does). If no module loads, the first use throws std::runtime_error listing
// the paths tried and the loader's reason.
//
// Every function is thread-safe (the module is loaded once).
#ifndef TACTFUNC_ESTIMATION_DATA_CODECS_H_
#define TACTFUNC_ESTIMATION_DATA_CODECS_H_

#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace tactfunc::codecs {

// How Decode returns the pixels (the cv::IMREAD_* flags of the same names).
enum class DecodeMode { kUnchanged, kColor, kGrayscale };

// cv::imdecode of `size` bytes. An empty Mat if they do not decode; *error (if given) then
// holds OpenCV's reason when it gave one. Throws std::runtime_error if the module cannot be
// loaded.
cv::Mat Decode(const std::uint8_t* data, std::size_t size, DecodeMode mode,
               std::string* error = nullptr);

// cv::IMWRITE_JPEG_QUALITY (checked in the module), for Encode's params.
constexpr int kJpegQuality = 1;

// cv::imencode to `extension` (".png", ".jpg"); params as cv::imencode takes them
// (pairs of an option and its value, e.g. {kJpegQuality, 90}). false if OpenCV cannot
// encode the image.
bool Encode(const std::string& extension, const cv::Mat& image, const std::vector<int>& params,
            std::vector<std::uint8_t>* bytes);

// The path the module was loaded from ("" when linked in); loads it if needed.
std::string ModulePath();
// Whether the module is in this process yet (true when linked in). Loads nothing.
bool Loaded();

// A video decoder (cv::VideoCapture): FFmpeg first, then any other backend.
class VideoCapture {
 public:
  VideoCapture() = default;
  ~VideoCapture();
  VideoCapture(const VideoCapture&) = delete;
  VideoCapture& operator=(const VideoCapture&) = delete;

  // Opens `path`, closing what was open. false (and *error: OpenCV's reason, if it gave
  // one) if no backend opens it.
  bool open(const std::string& path, std::string* error = nullptr);
  bool isOpened() const { return handle_ != nullptr; }
  // The next frame (8-bit BGR as OpenCV decodes it); false at the end, on an error or
  // for an empty frame.
  bool read(cv::Mat* frame);
  // Steps over the next frame without decoding it into a Mat.
  bool grab();
  // Seeks so that the next read returns frame `index` (as the container's index says).
  bool seek(std::size_t index);
  void release();

 private:
  void* handle_ = nullptr;
};

// A video encoder (cv::VideoWriter) writing 8-bit BGR frames with a FourCC codec.
class VideoWriter {
 public:
  VideoWriter() = default;
  ~VideoWriter();
  VideoWriter(const VideoWriter&) = delete;
  VideoWriter& operator=(const VideoWriter&) = delete;

  bool open(const std::string& path, const char fourcc[4], double fps, int rows, int cols);
  bool isOpened() const { return handle_ != nullptr; }
  bool write(const cv::Mat& frame);
  void release();

 private:
  void* handle_ = nullptr;
};

}  // namespace tactfunc::codecs

#endif  // TACTFUNC_ESTIMATION_DATA_CODECS_H_
