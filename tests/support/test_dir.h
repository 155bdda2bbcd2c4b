// Copyright 2026 The tactfunc Authors.
//
// A uniquely named temporary directory for one test, removed with its contents when
// the test ends (shared by the estimation tests).
#ifndef TACTFUNC_TESTS_SUPPORT_TEST_DIR_H_
#define TACTFUNC_TESTS_SUPPORT_TEST_DIR_H_

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "gtest/gtest.h"
#include "models/core/image.h"

namespace tactfunc::testing_util {

class TestDir {
 public:
  TestDir() {
    static std::atomic<int> counter{0};
    const ::testing::TestInfo* info = ::testing::UnitTest::GetInstance()->current_test_info();
    std::string name = "tactfunc_";
    if (info != nullptr) name += std::string(info->test_suite_name()) + "_" + info->name();
    name += "_" + std::to_string(::getpid()) + "_" + std::to_string(counter++);
    path_ = (std::filesystem::path(::testing::TempDir()) / name).string();
    std::filesystem::remove_all(path_);
    std::filesystem::create_directories(path_);
  }
  ~TestDir() {
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  TestDir(const TestDir&) = delete;
  TestDir& operator=(const TestDir&) = delete;

  const std::string& path() const { return path_; }
  std::string operator/(const std::string& name) const { return path_ + "/" + name; }

 private:
  std::string path_;
};

// The names of the entries of `dir` (hidden ones included), sorted.
inline std::vector<std::string> ListDir(const std::string& dir) {
  std::vector<std::string> names;
  for (const auto& entry : std::filesystem::directory_iterator(dir)) {
    names.push_back(entry.path().filename().string());
  }
  std::sort(names.begin(), names.end());
  return names;
}

inline void WriteText(const std::string& path, const std::string& text) {
  std::ofstream out(path, std::ios::binary);
  out << text;
}

// True if both images have the same shape and identical values, NaN matching NaN.
inline ::testing::AssertionResult BitIdentical(const Image& a, const Image& b) {
  if (!a.SameShape(b)) {
    return ::testing::AssertionFailure() << a.ShapeString() << " vs " << b.ShapeString();
  }
  for (std::size_t i = 0; i < a.size(); ++i) {
    const bool same = std::isnan(a.data[i]) ? std::isnan(b.data[i]) : a.data[i] == b.data[i];
    if (!same) {
      return ::testing::AssertionFailure()
             << "value " << i << ": " << a.data[i] << " vs " << b.data[i];
    }
  }
  return ::testing::AssertionSuccess();
}

}  // namespace tactfunc::testing_util

#endif  // TACTFUNC_TESTS_SUPPORT_TEST_DIR_H_
