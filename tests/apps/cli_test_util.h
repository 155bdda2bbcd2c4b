// Copyright 2026 The tactfunc Authors.
//
// Running the tactfunc program from tests, as a user would: exit code, stdout, stderr,
// and the --json last line.
#ifndef TACTFUNC_TESTS_APPS_CLI_TEST_UTIL_H_
#define TACTFUNC_TESTS_APPS_CLI_TEST_UTIL_H_

#include <sys/wait.h>

#include <atomic>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <unistd.h>

#include "nlohmann/json.hpp"
#include "tests/support/functa_test_util.h"

namespace tactfunc::testing_util {

inline std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
}

// Parses one line of a CSV without quoted fields (recon's frames.csv), keeping empty
// fields.
inline std::vector<std::string> CsvFields(const std::string& line) {
  std::vector<std::string> f(1);
  for (char c : line) {
    if (c == ',') {
      f.emplace_back();
    } else {
      f.back().push_back(c);
    }
  }
  return f;
}

struct CliResult {
  int exit_code = -1;
  std::string out;
  std::string err;
  // The last non-empty line of stdout, parsed (the --json contract).
  nlohmann::json LastJson() const {
    std::istringstream lines(out);
    std::string line, last;
    while (std::getline(lines, line)) {
      if (!line.empty()) last = line;
    }
    return nlohmann::json::parse(last);
  }
};

// The built program, build/bin/tactfunc.
inline std::string TactfuncPath() { return std::string(TACTFUNC_BINARY_DIR) + "/bin/tactfunc"; }

// Runs the shell command `command` with CI=true (no progress bars) and no standard
// input; stdout and stderr go through files in `dir`.
inline CliResult RunShell(const std::filesystem::path& dir, const std::string& command) {
  static std::atomic<int> counter{0};
  const int n = counter++;
  const std::string out = (dir / ("stdout" + std::to_string(n) + ".txt")).string();
  const std::string err = (dir / ("stderr" + std::to_string(n) + ".txt")).string();
  const std::string line = "CI=true " + command + " >" + out + " 2>" + err + " </dev/null";
  const int status = std::system(line.c_str());
  CliResult result;
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  result.out = Slurp(out);
  result.err = Slurp(err);
  return result;
}

// Runs `build/bin/tactfunc ARGS` as RunShell does.
inline CliResult RunTactfunc(const std::filesystem::path& dir, const std::string& args) {
  return RunShell(dir, TactfuncPath() + " " + args);
}

// A suite's shared inputs in a fresh per-process folder (ctest -j runs a suite's tests in
// parallel processes): a hand-built model `m.tfm`, a tiny paired dataset `d/` with
// clean frames, and its functaset `f.tfs` made by `tactfunc encode`. Returns the
// folder; *encode gets the encode run (check its exit code).
inline std::filesystem::path MakeEncodedFixture(const std::string& prefix, CliResult* encode) {
  const std::filesystem::path root = std::filesystem::path(::testing::TempDir()) /
                                     (prefix + "_" + std::to_string(::getpid()));
  std::filesystem::remove_all(root);
  std::filesystem::create_directories(root);
  MakeModel().Save((root / "m.tfm").string());
  WriteTinyDataset((root / "d").string(), 12, /*clean=*/true);
  *encode = RunTactfunc(root, "encode --model " + (root / "m.tfm").string() + " --data " +
                                  (root / "d").string() + " --out " +
                                  (root / "f.tfs").string() + " --threads 1 --json");
  return root;
}

}  // namespace tactfunc::testing_util

#endif  // TACTFUNC_TESTS_APPS_CLI_TEST_UTIL_H_
