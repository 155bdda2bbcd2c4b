// Copyright 2026 The tactfunc Authors.
//
// The libpng error and warning callbacks the PNG reader and writer share. libpng's error
// pointer is a std::string that receives the message; the callback then jumps back to
// the caller's setjmp, which reports it.
// Warnings (a chunk libpng skips, a gamma it ignores) change nothing we read or write.
#ifndef TACTFUNC_ESTIMATION_DATA_INTERNAL_PNG_CALLBACKS_H_
#define TACTFUNC_ESTIMATION_DATA_INTERNAL_PNG_CALLBACKS_H_

#include <png.h>

#include <string>

namespace tactfunc::internal {

inline void PngKeepErrorAndJump(png_structp png, png_const_charp message) {
  *static_cast<std::string*>(png_get_error_ptr(png)) = message;
  png_longjmp(png, 1);
}

inline void PngIgnoreWarning(png_structp, png_const_charp) {}

}  // namespace tactfunc::internal

#endif  // TACTFUNC_ESTIMATION_DATA_INTERNAL_PNG_CALLBACKS_H_
