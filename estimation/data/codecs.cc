// Copyright 2026 The tactfunc Authors.
#include "estimation/data/codecs.h"

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <mutex>
#include <stdexcept>
#include <system_error>

#include "estimation/data/internal/codecs_table.h"

#ifndef TACTFUNC_CODECS_LINKED
#include <dlfcn.h>
#endif

namespace tactfunc::codecs {
namespace {

using internal::CodecsTable;

std::atomic<const CodecsTable*> g_table{nullptr};
std::string g_module_path;  // written once, before g_table

#ifdef TACTFUNC_CODECS_LINKED

const CodecsTable& Table() { return *tactfunc_codecs_table(); }

#else

constexpr const char* kModuleName = "libtactfunc_codecs.so";

// The directory of the running program ("" if /proc is not mounted).
std::string ProgramDirectory() {
  std::error_code ec;
  const std::filesystem::path exe = std::filesystem::read_symlink("/proc/self/exe", ec);
  return ec ? std::string() : exe.parent_path().string();
}

std::vector<std::string> Candidates() {
  std::vector<std::string> paths;
  if (const char* env = std::getenv("TACTFUNC_CODECS_MODULE"); env != nullptr && *env != '\0') {
    paths.emplace_back(env);
    return paths;  // an explicit choice: nothing else is tried
  }
  if (const std::string dir = ProgramDirectory(); !dir.empty()) {
    paths.push_back(dir + "/../lib/tactfunc/" + kModuleName);
    paths.push_back(dir + "/../lib/" + kModuleName);
  }
#ifdef TACTFUNC_CODECS_BUILD_PATH
  paths.emplace_back(TACTFUNC_CODECS_BUILD_PATH);
#endif
#ifdef TACTFUNC_CODECS_INSTALL_PATH
  paths.emplace_back(TACTFUNC_CODECS_INSTALL_PATH);
#endif
  return paths;
}

const CodecsTable& Load() {
  static std::mutex mutex;
  std::lock_guard<std::mutex> lock(mutex);
  if (const CodecsTable* table = g_table.load(std::memory_order_acquire)) return *table;
  std::string tried;
  for (const std::string& path : Candidates()) {
    std::error_code ec;
    if (!std::filesystem::exists(path, ec)) {
      tried += "\n  " + path + ": no such file";
      continue;
    }
    void* handle = dlopen(path.c_str(), RTLD_NOW | RTLD_LOCAL);
    if (handle == nullptr) {
      const char* reason = dlerror();
      tried += "\n  " + path + ": " + (reason != nullptr ? reason : "dlopen failed");
      continue;
    }
    using Entry = const CodecsTable* (*)();
    auto entry = reinterpret_cast<Entry>(dlsym(handle, TACTFUNC_CODECS_TABLE_SYMBOL));
    const CodecsTable* table = entry != nullptr ? entry() : nullptr;
    if (table == nullptr || table->version != internal::kCodecsTableVersion) {
      tried += "\n  " + path + ": not a codecs module of this build (expected table version " +
               std::to_string(internal::kCodecsTableVersion) + ")";
      dlclose(handle);
      continue;
    }
    // Never unloaded: OpenCV's codec libraries keep global state for the process's life.
    g_module_path = path;
    g_table.store(table, std::memory_order_release);
    return *table;
  }
  throw std::runtime_error(
      std::string("tactfunc: cannot load the image and video codecs (") + kModuleName +
      ", OpenCV imgcodecs and videoio); tried:" + tried +
      "\nSet TACTFUNC_CODECS_MODULE to the module's path, or reinstall tactfunc.");
}

const CodecsTable& Table() {
  if (const CodecsTable* table = g_table.load(std::memory_order_acquire)) return *table;
  return Load();
}

#endif

}  // namespace

cv::Mat Decode(const std::uint8_t* data, std::size_t size, DecodeMode mode, std::string* error) {
  cv::Mat out;
  const int m = mode == DecodeMode::kColor ? 1 : mode == DecodeMode::kGrayscale ? 2 : 0;
  if (!Table().decode(data, size, m, &out, error)) out.release();
  return out;
}

bool Encode(const std::string& extension, const cv::Mat& image, const std::vector<int>& params,
            std::vector<std::uint8_t>* bytes) {
  return Table().encode(extension, image, params, bytes);
}

std::string ModulePath() {
  Table();
  return g_module_path;
}

bool Loaded() {
#ifdef TACTFUNC_CODECS_LINKED
  return true;
#else
  return g_table.load(std::memory_order_acquire) != nullptr;
#endif
}

VideoCapture::~VideoCapture() { release(); }

bool VideoCapture::open(const std::string& path, std::string* error) {
  release();
  handle_ = Table().capture_open(path, error);
  return handle_ != nullptr;
}

bool VideoCapture::read(cv::Mat* frame) {
  if (handle_ == nullptr) return false;
  return Table().capture_read(handle_, frame);
}

bool VideoCapture::grab() { return handle_ != nullptr && Table().capture_grab(handle_); }

bool VideoCapture::seek(std::size_t index) {
  return handle_ != nullptr && Table().capture_seek(handle_, static_cast<double>(index));
}

void VideoCapture::release() {
  if (handle_ == nullptr) return;
  Table().capture_close(handle_);
  handle_ = nullptr;
}

VideoWriter::~VideoWriter() { release(); }

bool VideoWriter::open(const std::string& path, const char fourcc[4], double fps, int rows,
                       int cols) {
  release();
  handle_ = Table().writer_open(path, fourcc, fps, rows, cols);
  return handle_ != nullptr;
}

bool VideoWriter::write(const cv::Mat& frame) {
  return handle_ != nullptr && Table().writer_write(handle_, frame);
}

void VideoWriter::release() {
  if (handle_ == nullptr) return;
  Table().writer_close(handle_);
  handle_ = nullptr;
}

}  // namespace tactfunc::codecs
