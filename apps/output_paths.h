// Copyright 2026 The tactfunc Authors.
//
// Outputs never overwrite inputs: every command that writes files checks, before any
// work, that none of them is (or resolves to, through symlinks, hard links, "..", or
// another spelling) one of the files or folders it reads -- the model, a functaset,
// the dataset folder and every file in it (dataset.json, labels.csv, references,
// frames), a pose model, a checkpoint, a k-NN index.
#ifndef TACTFUNC_APPS_OUTPUT_PATHS_H_
#define TACTFUNC_APPS_OUTPUT_PATHS_H_

#include <string>
#include <vector>

#include "apps/dataset_flags.h"
#include "estimation/data/dataset.h"

namespace tactfunc::apps {

// The checkpoint of one part of a command's work beside its output: OUT.<part>.ckpt
// (train's per sensor, train-generator's per stage, train-pose's refit).
std::string CheckpointBeside(const std::string& out, const std::string& part);

// A path a command reads or writes, with the flag that named it (for the message).
struct NamedPath {
  std::string flag;  // e.g. "--model"; for derived files e.g. "--out (fit.png)"
  std::string path;
};

// True if `a` and `b` name the same file or folder: std::filesystem::equivalent when
// both exist, else their weakly_canonical forms are equal.
bool SamePath(const std::string& a, const std::string& b);

// Throws UsageError "--out 'X' is the same file as --model 'Y': refusing to overwrite
// an input" for the first output that is the same as an input. Empty paths are skipped.
void RefuseOutputsThatAreInputs(const std::vector<NamedPath>& outputs,
                                const std::vector<NamedPath>& inputs);

// The inputs a dataset argument names before it is opened: the folder (or video file),
// its dataset.json, labels.csv and clips.csv, and the --labels and --reference files if
// given.
std::vector<NamedPath> DatasetPathInputs(const std::string& flag, const std::string& path,
                                         const DatasetFlags& flags);
// Every file an opened dataset consists of (Dataset::Files) and its folder, each named
// "<flag> (<file>)".
std::vector<NamedPath> DatasetFileInputs(const std::string& flag, const Dataset& dataset);

// `folder`/`name` for each name: the files a command writes into an output folder.
std::vector<NamedPath> FilesIn(const std::string& flag, const std::string& folder,
                               const std::vector<std::string>& names);

}  // namespace tactfunc::apps

#endif  // TACTFUNC_APPS_OUTPUT_PATHS_H_
