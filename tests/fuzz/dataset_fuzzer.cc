// Copyright 2026 The tactfunc Authors.
//
// The dataset loader (Dataset::Open, then every frame loaded). The input is
// dataset.json, a NUL byte, then labels.csv (no NUL: no labels.csv); they replace
// those files of a small valid dataset (written once, by DatasetWriter) whose
// references and frames stay in place.
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>

#include "estimation/data/dataset.h"
#include "tests/fuzz/fuzz_util.h"
#include "tests/support/functa_test_util.h"

namespace {

std::string g_dir;

void Write(const std::string& path, const char* data, std::size_t size) {
  std::ofstream out(path, std::ios::binary | std::ios::trunc);
  out.write(data, static_cast<std::streamsize>(size));
}

}  // namespace

extern "C" int LLVMFuzzerInitialize(int*, char***) {
  const char* shm = "/dev/shm";
  const std::filesystem::path base =
      std::filesystem::is_directory(shm) ? shm : std::filesystem::temp_directory_path();
  g_dir = (base / ("tactfunc_dataset_fuzzer_" + std::to_string(::getpid()))).string();
  std::filesystem::remove_all(g_dir);
  tactfunc::testing_util::WriteTinyDataset(g_dir, 3, /*clean=*/true);
  std::atexit([] {
    std::error_code ec;
    std::filesystem::remove_all(g_dir, ec);
  });
  return 0;
}

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  using namespace tactfunc;
  const char* text = reinterpret_cast<const char*>(data);
  const void* nul = std::memchr(text, 0, size);
  const std::size_t json_size = nul ? static_cast<const char*>(nul) - text : size;
  Write(g_dir + "/dataset.json", text, json_size);
  const std::string labels = g_dir + "/labels.csv";
  if (nul) {
    Write(labels, text + json_size + 1, size - json_size - 1);
  } else {
    std::filesystem::remove(labels);
  }
  try {
    const Dataset dataset = Dataset::Open(g_dir);
    dataset.ValidateAllFrames();
    (void)dataset.BytesOnDisk();
  } catch (const DatasetError& e) {
    fuzz::CheckMessage(e.what(), g_dir);
  }
  return 0;
}
