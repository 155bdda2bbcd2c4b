// Copyright 2026 The tactfunc Authors.
//
// Every test executable gets a temporary directory of its own. testing::TempDir() reads
// TEST_TMPDIR on each call; before main, this sets it to a fresh directory (mkdtemp)
// under the caller's TEST_TMPDIR, else the system's temporary directory, and removes it
// with its contents at exit. Suites that write fixed names there (m.tfm, ...) then
// neither overwrite a user's files in /tmp nor collide with each other when ctest runs
// several test processes at once, or two build trees test at the same time. Linked into
// every GoogleTest executable by tactfunc_test() (tests/CMakeLists.txt).
#include <stdlib.h>

#include <cstdlib>
#include <filesystem>
#include <string>
#include <system_error>
#include <vector>

namespace {

class UniqueTempDir {
 public:
  UniqueTempDir() {
    const char* given = std::getenv("TEST_TMPDIR");
    std::error_code ec;
    const std::filesystem::path parent = given != nullptr && given[0] != '\0'
                                             ? std::filesystem::path(given)
                                             : std::filesystem::temp_directory_path(ec);
    if (ec) return;  // gtest's default stays
    const std::string pattern = (parent / "tactfunc_test_XXXXXX").string();
    std::vector<char> name(pattern.begin(), pattern.end());
    name.push_back('\0');
    if (::mkdtemp(name.data()) == nullptr) return;
    path_ = name.data();
    ::setenv("TEST_TMPDIR", path_.c_str(), 1);
  }
  ~UniqueTempDir() {
    if (path_.empty()) return;
    std::error_code ec;
    std::filesystem::remove_all(path_, ec);
  }
  UniqueTempDir(const UniqueTempDir&) = delete;
  UniqueTempDir& operator=(const UniqueTempDir&) = delete;

 private:
  std::string path_;
};

const UniqueTempDir unique_temp_dir;

}  // namespace
