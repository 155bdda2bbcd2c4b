// Copyright 2026 The tactfunc Authors.
//
// LD_PRELOAD shim for reliability_cli_test: when the program renames a file onto a
// path ending in $TACTFUNC_TEST_SIGINT_ON_RENAME, it first raises SIGINT twice (two
// Ctrl-C) -- exactly inside an atomic write, after the temporary file is complete and
// before it replaces the target. Then the real rename runs (if the process lives).
#include <dlfcn.h>
#include <signal.h>

#include <cstdlib>
#include <cstring>

extern "C" int rename(const char* from, const char* to) {
  using Rename = int (*)(const char*, const char*);
  static const Rename real = reinterpret_cast<Rename>(dlsym(RTLD_NEXT, "rename"));
  const char* suffix = std::getenv("TACTFUNC_TEST_SIGINT_ON_RENAME");
  if (suffix != nullptr && *suffix != '\0') {
    const std::size_t n = std::strlen(to), m = std::strlen(suffix);
    if (n >= m && std::strcmp(to + n - m, suffix) == 0) {
      raise(SIGINT);
      raise(SIGINT);
    }
  }
  return real(from, to);
}
