// Copyright 2026 The tactfunc Authors.
//
// Shared plumbing of the tactfunc subcommands: registration, JSON output, lists.
//
// Conventions every subcommand follows:
// - `--help` describes it; errors go to stderr as "tactfunc <cmd>: error: ..." with
//   exit code 1 (2 for bad flags), and nothing half-written is left behind.
// - With `--json`, the last line of stdout is one JSON object with the command's figures.
#ifndef TACTFUNC_APPS_COMMAND_H_
#define TACTFUNC_APPS_COMMAND_H_

#include <cstdint>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include "nlohmann/json.hpp"

namespace CLI {
class App;  // CLI11; a subcommand's registration includes "CLI/CLI.hpp"
}  // namespace CLI

namespace tactfunc {
class Functaset;  // estimation/functaset/functaset.h
}  // namespace tactfunc

namespace tactfunc::apps {

// A subcommand's body, chosen during parsing and run by main() under its error handler.
using CommandBody = std::function<void()>;

// Each Register* adds one subcommand to `app`; when it is selected on the command line,
// its body is stored in *selected.
void RegisterSynth(CLI::App& app, CommandBody* selected);
void RegisterShow(CLI::App& app, CommandBody* selected);
void RegisterInfo(CLI::App& app, CommandBody* selected);
void RegisterBench(CLI::App& app, CommandBody* selected);
void RegisterTrain(CLI::App& app, CommandBody* selected);   // apps/train_command.cc
void RegisterEncode(CLI::App& app, CommandBody* selected);  // apps/encode_command.cc
void RegisterRecon(CLI::App& app, CommandBody* selected);   // apps/recon_command.cc
void RegisterFit(CLI::App& app, CommandBody* selected);     // apps/fit_command.cc
void RegisterTrainPose(CLI::App& app, CommandBody* selected);  // apps/train_pose_command.cc
void RegisterPose(CLI::App& app, CommandBody* selected);         // apps/pose_command.cc
void RegisterEval(CLI::App& app, CommandBody* selected);         // apps/eval_command.cc
void RegisterTrainGenerator(CLI::App& app, CommandBody* selected);  // apps/generator_command.cc
void RegisterEvalGenerator(CLI::App& app, CommandBody* selected);   // apps/generator_command.cc
void RegisterExport(CLI::App& app, CommandBody* selected);         // apps/export_command.cc

// Degrees per radian, for what the commands print.
inline constexpr double kDeg = 57.29577951308232;

// Bad user input that the command detected itself (flag values, lists).
class UsageError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

// Prints `figures` as one line on stdout (the --json contract).
void EmitJson(const nlohmann::json& figures);

// "a,b,,c" -> {"a", "b", "c"}; surrounding spaces trimmed.
std::vector<std::string> SplitList(const std::string& text);

// A flag's comma-separated list of whole numbers >= 1 ("64,128"), in order. Throws
// UsageError "<flag>: expected a comma-separated list of <what> >= 1, got '<text>'" for
// an empty list or any item that is not such a number.
std::vector<int> ParsePositiveIntList(const std::string& text, const std::string& flag,
                                      const std::string& what);

// The worker count for a --threads flag: `requested` if > 0, else every core (>= 1).
int ResolveThreads(int requested);

// "12.3 MB"-style byte counts for humans.
std::string FormatBytes(std::uint64_t bytes);

// A finite number as JSON, null otherwise (JSON has no NaN or infinity).
nlohmann::json NumberOrNull(double value);

// `value` with `digits` decimals for tables and reports; "inf" / "-inf" for infinities
// and `missing` for NaN.
std::string FormatFixed(double value, int digits, const char* missing = "n/a");

// The --products flag of the commands that run the trunks' batched passes: "float" (the
// default) or "bf16", the products' operands in bfloat16 with float sums
// (models/trunk/product_precision.h). ApplyProductPrecision sets the process's precision
// from the flag's value; on a CPU without AVX512_BF16 it throws UsageError saying so.
// as_functaset: the commands that render a functaset's latents (recon, eval), whose
// --products defaults to "" (the flag's help says so), meaning the precision the
// functaset was encoded with (ProductPrecisionFor).
void AddProductPrecisionFlag(CLI::App* sub, std::string* value, bool as_functaset = false);
void ApplyProductPrecision(const std::string& value);
// The precision for such a command: `flag` if given; else "bf16" if a sensor of the
// functaset (read from `path`) was encoded with bfloat16 products and this CPU runs them
// (saying so on stdout), "float" otherwise (with a note on stderr when the CPU lacks them).
std::string ProductPrecisionFor(const std::string& flag, const Functaset& functaset,
                                const std::string& path, const std::string& command);

}  // namespace tactfunc::apps

#endif  // TACTFUNC_APPS_COMMAND_H_
