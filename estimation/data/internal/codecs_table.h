// Copyright 2026 The tactfunc Authors.
//
// The table of functions libtactfunc_codecs.so exports (codecs_module.cc) and codecs.cc
// calls. Private to those two files. The module and the program are built together by
// the same compiler, so C++ types cross the boundary; the version guards against a
// module left over from another build.
#ifndef TACTFUNC_ESTIMATION_DATA_INTERNAL_CODECS_TABLE_H_
#define TACTFUNC_ESTIMATION_DATA_INTERNAL_CODECS_TABLE_H_

#include <cstddef>
#include <cstdint>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

namespace tactfunc::codecs::internal {

constexpr int kCodecsTableVersion = 1;

// None of these throws: OpenCV's exceptions are caught inside the module.
struct CodecsTable {
  int version;
  // mode: 0 unchanged, 1 color, 2 grayscale.
  bool (*decode)(const std::uint8_t* data, std::size_t size, int mode, cv::Mat* out,
                 std::string* error);
  bool (*encode)(const std::string& extension, const cv::Mat& image,
                 const std::vector<int>& params, std::vector<std::uint8_t>* bytes);
  void* (*capture_open)(const std::string& path, std::string* error);
  void (*capture_close)(void* capture);
  bool (*capture_read)(void* capture, cv::Mat* frame);
  bool (*capture_grab)(void* capture);
  bool (*capture_seek)(void* capture, double index);
  void* (*writer_open)(const std::string& path, const char* fourcc, double fps, int rows,
                       int cols);
  bool (*writer_write)(void* writer, const cv::Mat& frame);
  void (*writer_close)(void* writer);
};

}  // namespace tactfunc::codecs::internal

// The module's one exported symbol.
#define TACTFUNC_CODECS_TABLE_SYMBOL "tactfunc_codecs_table"
extern "C" const tactfunc::codecs::internal::CodecsTable* tactfunc_codecs_table();

#endif  // TACTFUNC_ESTIMATION_DATA_INTERNAL_CODECS_TABLE_H_
