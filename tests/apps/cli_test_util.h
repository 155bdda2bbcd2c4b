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

#include "nlohmann/json.hpp"

namespace tactfunc::testing_util {

inline std::string Slurp(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  std::stringstream buffer;
  buffer << in.rdbuf();
  return buffer.str();
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

// Runs `build/bin/tactfunc ARGS` with CI=true (no progress bars) and no standard input;
// stdout and stderr go through files in `dir`.
inline CliResult RunTactfunc(const std::filesystem::path& dir, const std::string& args) {
  static std::atomic<int> counter{0};
  const int n = counter++;
  const std::string out = (dir / ("stdout" + std::to_string(n) + ".txt")).string();
  const std::string err = (dir / ("stderr" + std::to_string(n) + ".txt")).string();
  const std::string command = "CI=true " + std::string(TACTFUNC_BINARY_DIR) + "/bin/tactfunc " +
                              args + " >" + out + " 2>" + err + " </dev/null";
  const int status = std::system(command.c_str());
  CliResult result;
  result.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : -1;
  result.out = Slurp(out);
  result.err = Slurp(err);
  return result;
}

}  // namespace tactfunc::testing_util

#endif  // TACTFUNC_TESTS_APPS_CLI_TEST_UTIL_H_
