// Copyright 2026 The tactfunc Authors.
//
// tactfunc: the command-line program. `tactfunc --help` lists the subcommands;
// `tactfunc <subcommand> --help` describes one.
#include <malloc.h>

#include <cctype>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <iostream>
#include <string>

#include "CLI/CLI.hpp"
#include "apps/command.h"
#include "apps/distributed.h"
#include "estimation/data/dataset.h"

namespace {

// "tactfunc" and the subcommand chosen so far, as every error message starts.
std::string CommandName(const CLI::App& app) {
  std::string name = "tactfunc";
  for (const CLI::App* sub : app.get_subcommands()) name += " " + sub->get_name();
  return name;
}

// The subcommands chosen, down to the last: "bench posterior".
std::string CommandPath(const CLI::App& app) {
  std::string path;
  for (const CLI::App* sub = &app; !sub->get_subcommands().empty();) {
    sub = sub->get_subcommands().front();
    path += (path.empty() ? "" : " ") + sub->get_name();
  }
  return path;
}

// Numbers in CLI11's range messages as people write them: "0.000000" -> "0" and the
// 309-digit "179769313...368.000000" (the largest double) -> "1.79769e+308".
std::string ShortNumbers(const std::string& text) {
  std::string out;
  for (std::size_t i = 0; i < text.size();) {
    const bool starts = std::isdigit(static_cast<unsigned char>(text[i])) &&
                        (i == 0 || !std::isalnum(static_cast<unsigned char>(text[i - 1])));
    if (!starts) {
      out += text[i++];
      continue;
    }
    std::size_t end = i;
    while (end < text.size() &&
           (std::isdigit(static_cast<unsigned char>(text[end])) || text[end] == '.')) {
      ++end;
    }
    const std::string number = text.substr(i, end - i);
    if (number.find('.') != std::string::npos || number.size() > 12) {
      char buffer[32];
      std::snprintf(buffer, sizeof(buffer), "%.6g", std::strtod(number.c_str(), nullptr));
      out += buffer;
    } else {
      out += number;
    }
    i = end;
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  using namespace tactfunc::apps;
  // The trunk's batched passes allocate a few MB of temporaries per call; glibc serves
  // blocks that large with mmap and returns them to the kernel on free, so every pass
  // page-faulted its buffers in again (measured: a 32x32 Jacobian 4.9 -> 2.3 ms, encoding
  // 3-4x faster with a width-64 trunk). Keep such blocks in the heap, untrimmed. A
  // process setting, so it is made here and not in the libraries.
  mallopt(M_MMAP_THRESHOLD, 32 << 20);  // glibc's maximum on 64-bit
  mallopt(M_TRIM_THRESHOLD, 512 << 20);
  CLI::App app{
      "tactfunc: tactile functasets -- compact neural implicit representations of "
      "tactile datasets and in-hand pose posteriors.",
      "tactfunc"};
  app.require_subcommand(1);
  app.set_version_flag("--version", "tactfunc 0.1.0");
  // Flag errors (a value out of range, a missing required flag) read like every other
  // error: "tactfunc <cmd>: error: ...", with short numbers.
  app.failure_message([](const CLI::App* failed, const CLI::Error& e) {
    return CommandName(*failed) + ": error: " + ShortNumbers(e.what()) +
           "\nRun with --help for more information.\n";
  });
  CommandBody body;
  RegisterSynth(app, &body);
  RegisterShow(app, &body);
  RegisterInfo(app, &body);
  RegisterTrain(app, &body);
  RegisterEncode(app, &body);
  RegisterRecon(app, &body);
  RegisterFit(app, &body);
  RegisterTrainPose(app, &body);
  RegisterPose(app, &body);
  RegisterEval(app, &body);
  RegisterTrainGenerator(app, &body);
  RegisterEvalGenerator(app, &body);
  RegisterExport(app, &body);
  RegisterBench(app, &body);
  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // CLI11 prints the help (exit 0) or the usage error; every usage error exits 2.
    return app.exit(e) == 0 ? 0 : 2;
  }
  const std::string name = "tactfunc " + CommandPath(app);
  // Started by mpirun: train, encode, recon, eval and bench posterior join the other
  // processes (apps/distributed.h); anything else is refused, said once (by rank 0).
  try {
    StartProcesses(CommandPath(app));
  } catch (const std::exception& e) {
    // One write of the whole line: mpirun prints to the same stderr as the processes
    // exit, and a line written in pieces could be split by its message.
    if (LaunchedRank() == 0) std::cerr << (name + ": error: " + e.what() + "\n") << std::flush;
    return 2;
  }
  int code = 0;
  try {
    if (body) body();
  } catch (const UsageError& e) {
    ReportError(name + ": error: " + e.what());
    code = 2;
  } catch (const std::exception& e) {
    ReportError(name + ": error: " + e.what());
    code = 1;
  }
  // A process of several that failed ends them all: the others may be waiting for it.
  if (code != 0) AbortProcesses(code);
  FinishProcesses();
  return code;
}
