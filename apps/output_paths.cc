// Copyright 2026 The tactfunc Authors.
#include "apps/output_paths.h"

#include <sys/stat.h>

#include <filesystem>
#include <system_error>

#include "apps/command.h"

namespace tactfunc::apps {

namespace fs = std::filesystem;

namespace {

// What a path names: the file's device and inode if it exists (so hard links, symlinks
// and other spellings compare equal), else its absolute, weakly canonical form.
struct Identity {
  bool exists = false;
  dev_t device = 0;
  ino_t inode = 0;
  fs::path canonical;
};

fs::path Canonical(const std::string& path) {
  std::error_code ec;
  fs::path absolute = fs::absolute(path, ec);
  if (ec) return fs::path(path).lexically_normal();
  fs::path canonical = fs::weakly_canonical(absolute, ec);
  return ec ? absolute.lexically_normal() : canonical;
}

Identity Identify(const std::string& path, bool with_canonical) {
  Identity id;
  struct stat info;
  if (::stat(path.c_str(), &info) == 0) {
    id.exists = true;
    id.device = info.st_dev;
    id.inode = info.st_ino;
  }
  if (with_canonical || !id.exists) id.canonical = Canonical(path);
  return id;
}

bool Same(const Identity& out, const std::string& in_path) {
  const Identity in = Identify(in_path, /*with_canonical=*/false);
  if (out.exists && in.exists) return out.device == in.device && out.inode == in.inode;
  if (out.exists != in.exists && in.exists) return false;  // a new file is no existing one
  return out.canonical == (in.canonical.empty() ? Canonical(in_path) : in.canonical);
}

}  // namespace

std::string CheckpointBeside(const std::string& out, const std::string& part) {
  return out + "." + part + ".ckpt";
}

bool SamePath(const std::string& a, const std::string& b) {
  if (a.empty() || b.empty()) return false;
  return Same(Identify(a, /*with_canonical=*/true), b);
}

void RefuseOutputsThatAreInputs(const std::vector<NamedPath>& outputs,
                                const std::vector<NamedPath>& inputs) {
  for (const NamedPath& out : outputs) {
    if (out.path.empty()) continue;
    const Identity out_id = Identify(out.path, /*with_canonical=*/true);
    for (const NamedPath& in : inputs) {
      if (in.path.empty() || !Same(out_id, in.path)) continue;
      const bool same_spelling = out.path == in.path;
      std::error_code ec;
      throw UsageError(out.flag + " '" + out.path + "' is the same " +
                       (fs::is_directory(in.path, ec) ? "folder" : "file") + " as " + in.flag +
                       (same_spelling ? "" : " '" + in.path + "'") +
                       ": refusing to overwrite an input; choose another output path");
    }
  }
}

std::vector<NamedPath> DatasetPathInputs(const std::string& flag, const std::string& path,
                                         const DatasetFlags& flags) {
  std::vector<NamedPath> inputs = {{flag, path},
                                   {flag + " (dataset.json)", (fs::path(path) / "dataset.json").string()},
                                   {flag + " (labels.csv)", (fs::path(path) / "labels.csv").string()},
                                   {flag + " (clips.csv)", (fs::path(path) / "clips.csv").string()},
                                   {flag + " (sensor.json)", (fs::path(path) / "sensor.json").string()}};
  if (!flags.labels.empty()) inputs.push_back({"--labels", flags.labels});
  if (!flags.sensor_file.empty()) inputs.push_back({"--sensor-file", flags.sensor_file});
  if (!flags.reference.empty()) {
    inputs.push_back({"--reference", flags.reference});
    inputs.push_back({"--reference", (fs::path(path) / flags.reference).string()});
  }
  return inputs;
}

std::vector<NamedPath> DatasetFileInputs(const std::string& flag, const Dataset& dataset) {
  std::vector<NamedPath> inputs = {{flag, dataset.root()}};
  for (const std::string& file : dataset.Files()) {
    inputs.push_back({flag + " (" + file + ")", file});
  }
  return inputs;
}

std::vector<NamedPath> FilesIn(const std::string& flag, const std::string& folder,
                               const std::vector<std::string>& names) {
  std::vector<NamedPath> files;
  for (const std::string& name : names) {
    files.push_back({flag + " (" + name + ")", (fs::path(folder) / name).string()});
  }
  return files;
}

}  // namespace tactfunc::apps
