// Copyright 2026 The tactfunc Authors.
//
// Atomic file writes, used by every file tactfunc produces (model files, functasets,
// dataset frames and metadata, pictures): readers see either the old file or the whole
// new one, never a part.
#ifndef TACTFUNC_MODELS_CORE_ATOMIC_FILE_H_
#define TACTFUNC_MODELS_CORE_ATOMIC_FILE_H_

#include <string>

namespace tactfunc {

enum class Durability {
  // fsync the data before the rename: after a crash the file is either the old one or
  // the complete new one. The default for everything written one at a time.
  kSynced,
  // Skip the per-file fsync (the rename is still atomic, so no reader ever sees a
  // partial file). For bulk writes of many small files, which call SyncFileSystem()
  // once before writing the file that marks them complete (a dataset's dataset.json).
  kDeferred,
};

// Writes `bytes` to `path` through a hidden temporary file in the same directory
// (".<name>.tmp.<pid>.<n>") renamed over `path`. The directory must exist. On failure
// the temporary file is removed and std::runtime_error naming `path` is thrown.
// Safe to call from several threads.
void WriteFileAtomically(const std::string& path, const std::string& bytes,
                         Durability durability = Durability::kSynced);

// Removes the temporary files WriteFileAtomically left beside `path` when a writer was
// killed mid-write (".<name>.tmp.<pid>.<n>" whose process no longer runs); files of
// running processes are left alone. Returns how many were removed; never throws.
int RemoveStaleTemporaries(const std::string& path);

// Flushes everything written to the file system holding `dir` (syncfs). Throws
// std::runtime_error naming `dir` on failure.
void SyncFileSystem(const std::string& dir);

}  // namespace tactfunc

#endif  // TACTFUNC_MODELS_CORE_ATOMIC_FILE_H_
