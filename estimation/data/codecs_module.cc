// Copyright 2026 The tactfunc Authors.
//
// libtactfunc_codecs.so: OpenCV's image codecs and video I/O behind the table of
// internal/codecs_table.h (codecs.h says why they are a module). Built as a MODULE
// library, or into tactfunc::data when TACTFUNC_CODECS_MODULE is OFF.
#include <exception>
#include <opencv2/core.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/videoio.hpp>

#include "estimation/data/codecs.h"
#include "estimation/data/internal/codecs_table.h"

static_assert(tactfunc::codecs::kJpegQuality == cv::IMWRITE_JPEG_QUALITY);

namespace tactfunc::codecs::internal {
namespace {

bool Decode(const std::uint8_t* data, std::size_t size, int mode, cv::Mat* out,
            std::string* error) {
  const int flags = mode == 1   ? cv::IMREAD_COLOR
                    : mode == 2 ? cv::IMREAD_GRAYSCALE
                                : cv::IMREAD_UNCHANGED;
  try {
    out->release();
    if (size == 0 || size > static_cast<std::size_t>(INT32_MAX)) return false;
    *out = cv::imdecode(cv::Mat(1, static_cast<int>(size), CV_8U, const_cast<std::uint8_t*>(data)),
                        flags);
    return !out->empty();
  } catch (const std::exception& e) {
    if (error != nullptr) *error = e.what();
    out->release();
    return false;
  }
}

bool Encode(const std::string& extension, const cv::Mat& image, const std::vector<int>& params,
            std::vector<std::uint8_t>* bytes) {
  try {
    return cv::imencode(extension, image, *bytes, params);
  } catch (const std::exception&) {
    return false;
  }
}

void* CaptureOpen(const std::string& path, std::string* error) {
  auto* capture = new cv::VideoCapture;
  try {
    // FFmpeg first: it reads AVI, MP4, MKV and MOV without the other backends' noisy
    // attempts (GStreamer, image sequences) on files they cannot open.
    if (!capture->open(path, cv::CAP_FFMPEG)) capture->open(path, cv::CAP_ANY);
  } catch (const std::exception& e) {
    if (error != nullptr) *error = e.what();
  }
  if (capture->isOpened()) return capture;
  delete capture;
  return nullptr;
}

void CaptureClose(void* capture) { delete static_cast<cv::VideoCapture*>(capture); }

bool CaptureRead(void* capture, cv::Mat* frame) {
  try {
    return static_cast<cv::VideoCapture*>(capture)->read(*frame) && !frame->empty();
  } catch (const std::exception&) {
    return false;
  }
}

bool CaptureGrab(void* capture) {
  try {
    return static_cast<cv::VideoCapture*>(capture)->grab();
  } catch (const std::exception&) {
    return false;
  }
}

bool CaptureSeek(void* capture, double index) {
  try {
    return static_cast<cv::VideoCapture*>(capture)->set(cv::CAP_PROP_POS_FRAMES, index);
  } catch (const std::exception&) {
    return false;
  }
}

void* WriterOpen(const std::string& path, const char* fourcc, double fps, int rows, int cols) {
  auto* writer = new cv::VideoWriter;
  try {
    writer->open(path, cv::VideoWriter::fourcc(fourcc[0], fourcc[1], fourcc[2], fourcc[3]), fps,
                 cv::Size(cols, rows), /*isColor=*/true);
  } catch (const std::exception&) {
  }
  if (writer->isOpened()) return writer;
  delete writer;
  return nullptr;
}

bool WriterWrite(void* writer, const cv::Mat& frame) {
  try {
    static_cast<cv::VideoWriter*>(writer)->write(frame);
    return true;
  } catch (const std::exception&) {
    return false;
  }
}

void WriterClose(void* writer) { delete static_cast<cv::VideoWriter*>(writer); }

constexpr CodecsTable kTable = {kCodecsTableVersion, &Decode,      &Encode,      &CaptureOpen,
                                &CaptureClose,       &CaptureRead, &CaptureGrab, &CaptureSeek,
                                &WriterOpen,         &WriterWrite, &WriterClose};

}  // namespace
}  // namespace tactfunc::codecs::internal

extern "C" __attribute__((visibility("default"))) const tactfunc::codecs::internal::CodecsTable*
tactfunc_codecs_table() {
  return &tactfunc::codecs::internal::kTable;
}
