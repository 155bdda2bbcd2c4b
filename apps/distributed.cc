// Copyright 2026 The tactfunc Authors.
#include "apps/distributed.h"

#include <fcntl.h>
#include <unistd.h>

#include <chrono>
#include <climits>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <iostream>
#include <memory>
#include <thread>

#include "apps/command.h"

#ifdef TACTFUNC_WITH_MPI
#include <mpi.h>
#endif

namespace tactfunc::apps {
namespace {

// The commands that run as several processes (`command`: the subcommand path, e.g.
// "bench posterior").
constexpr const char* kDistributed[] = {"train", "encode", "recon", "eval", "bench posterior"};

bool Distributes(const std::string& command) {
  for (const char* name : kDistributed) {
    if (command == name) return true;
  }
  return false;
}

int EnvInt(const char* name) {
  const char* value = std::getenv(name);
  if (value == nullptr || *value == '\0') return -1;
  char* end = nullptr;
  const long parsed = std::strtol(value, &end, 10);
  return *end == '\0' && parsed >= 0 && parsed <= INT_MAX ? static_cast<int>(parsed) : -1;
}

// The terminal's stderr, kept when a process other than rank 0 sends its output to
// /dev/null.
int g_error_fd = STDERR_FILENO;

// Sends stdout and stderr to /dev/null (keeping stderr for ReportError).
void Quieten() {
  std::cout.flush();
  std::cerr.flush();
  std::fflush(nullptr);
  const int saved = ::dup(STDERR_FILENO);
  const int null = ::open("/dev/null", O_WRONLY);
  if (saved < 0 || null < 0) return;
  g_error_fd = saved;
  ::dup2(null, STDOUT_FILENO);
  ::dup2(null, STDERR_FILENO);
  ::close(null);
}

#ifdef TACTFUNC_WITH_MPI

[[noreturn]] void MpiFailure(const char* call, int code) {
  char text[MPI_MAX_ERROR_STRING];
  int length = 0;
  MPI_Error_string(code, text, &length);
  throw std::runtime_error(std::string("MPI: ") + call + " failed: " + std::string(text, length));
}

void Check(const char* call, int code) {
  if (code != MPI_SUCCESS) MpiFailure(call, code);
}

// MPI counts are ints: a buffer beyond 2 GiB is refused.
int Count(std::size_t bytes) {
  if (bytes > static_cast<std::size_t>(INT_MAX)) {
    throw std::runtime_error("MPI: a message of " + std::to_string(bytes) +
                             " bytes is beyond the 2 GiB a collective can send");
  }
  return static_cast<int>(bytes);
}

class MpiWorld final : public ProcessGroup {
 public:
  MpiWorld() {
    MPI_Comm_set_errhandler(MPI_COMM_WORLD, MPI_ERRORS_RETURN);
    Check("MPI_Comm_rank", MPI_Comm_rank(MPI_COMM_WORLD, &rank_));
    Check("MPI_Comm_size", MPI_Comm_size(MPI_COMM_WORLD, &size_));
  }
  int rank() const override { return rank_; }
  int size() const override { return size_; }

  std::vector<Bytes> AllGather(const Bytes& mine) const override {
    const int count = Count(mine.size());
    std::vector<int> counts(size_), offsets(size_);
    Check("MPI_Allgather",
          MPI_Allgather(&count, 1, MPI_INT, counts.data(), 1, MPI_INT, MPI_COMM_WORLD));
    std::size_t total = 0;
    for (int r = 0; r < size_; ++r) {
      offsets[r] = Count(total);
      total += static_cast<std::size_t>(counts[r]);
    }
    Count(total);
    Bytes all(total);
    Check("MPI_Allgatherv",
          MPI_Allgatherv(mine.data(), count, MPI_BYTE, all.data(), counts.data(), offsets.data(),
                         MPI_BYTE, MPI_COMM_WORLD));
    std::vector<Bytes> out(size_);
    for (int r = 0; r < size_; ++r) {
      out[r].assign(all.begin() + offsets[r], all.begin() + offsets[r] + counts[r]);
    }
    return out;
  }

  void Broadcast(Bytes* data) const override {
    std::uint64_t size = data->size();
    Check("MPI_Bcast", MPI_Bcast(&size, 1, MPI_UINT64_T, 0, MPI_COMM_WORLD));
    data->resize(size);
    Check("MPI_Bcast", MPI_Bcast(data->data(), Count(size), MPI_BYTE, 0, MPI_COMM_WORLD));
  }

 private:
  int rank_ = 0;
  int size_ = 1;
};

std::unique_ptr<MpiWorld> g_world;

#endif  // TACTFUNC_WITH_MPI

}  // namespace

bool BuiltWithMpi() {
#ifdef TACTFUNC_WITH_MPI
  return true;
#else
  return false;
#endif
}

int LaunchedProcessCount() {
  for (const char* name : {"OMPI_COMM_WORLD_SIZE", "PMI_SIZE"}) {
    if (const int n = EnvInt(name); n >= 1) return n;
  }
  return 1;
}

int LaunchedRank() {
  for (const char* name : {"OMPI_COMM_WORLD_RANK", "PMI_RANK"}) {
    if (const int r = EnvInt(name); r >= 0) return r;
  }
  return 0;
}

void StartProcesses(const std::string& command) {
  const int launched = LaunchedProcessCount();
  if (launched <= 1) return;
  if (!BuiltWithMpi()) {
    throw UsageError(
        "started as " + std::to_string(launched) +
        " processes (mpirun), but this build of tactfunc has no MPI: install an MPI "
        "(Debian: libopenmpi-dev openmpi-bin) and build again, or run without mpirun "
        "(docs/SCALING.md)");
  }
  if (!Distributes(command)) {
    throw UsageError("started as " + std::to_string(launched) +
                     " processes (mpirun), but only train, encode, recon, eval and bench "
                     "posterior run as several processes; run " + command +
                     " without mpirun (docs/SCALING.md)");
  }
#ifdef TACTFUNC_WITH_MPI
  int provided = 0;
  // Only the thread that runs the command calls MPI; the workers never do.
  Check("MPI_Init_thread", MPI_Init_thread(nullptr, nullptr, MPI_THREAD_FUNNELED, &provided));
  std::atexit(FinishProcesses);  // std::exit paths (an interrupted encode) end MPI too
  g_world = std::make_unique<MpiWorld>();
  if (g_world->rank() != 0) Quieten();
#endif
}

const ProcessGroup& Processes() {
#ifdef TACTFUNC_WITH_MPI
  if (g_world) return *g_world;
#endif
  return SingleProcess();
}

void RefuseUnsharedFile(const ProcessGroup& group, const std::string& path) {
  if (group.size() == 1) return;
  // What this process sees: present or not, the size and an FNV-1a hash of the bytes.
  ByteWriter seen;
  std::ifstream in(path, std::ios::binary);
  std::uint64_t size = 0, hash = 1469598103934665603ull;
  char buffer[1 << 16];
  while (in) {
    in.read(buffer, sizeof(buffer));
    const std::streamsize got = in.gcount();
    for (std::streamsize i = 0; i < got; ++i) {
      hash = (hash ^ static_cast<unsigned char>(buffer[i])) * 1099511628211ull;
    }
    size += static_cast<std::uint64_t>(got);
  }
  seen.Put<std::uint8_t>(std::filesystem::exists(path) ? 1 : 0);
  seen.Put(size);
  seen.Put(hash);
  const std::vector<Bytes> all = group.AllGather(seen.bytes());
  for (int rank = 1; rank < group.size(); ++rank) {
    if (all[rank] == all[0]) continue;
    auto describe = [&](int r) {
      ByteReader reader(all[r]);
      if (reader.Get<std::uint8_t>() == 0) return std::string("no file");
      return std::to_string(reader.Get<std::uint64_t>()) + " bytes";
    };
    throw std::runtime_error("process " + std::to_string(rank) + " of " +
                             std::to_string(group.size()) + " reads other bytes at " + path +
                             " (" + describe(rank) + ") than process 0 (" + describe(0) +
                             "): the output folder must be on a file system every process "
                             "shares (docs/SCALING.md)");
  }
}

void ReportError(const std::string& line) {
  const ProcessGroup& group = Processes();
  std::string text = line;
  if (group.rank() != 0) {
    std::this_thread::sleep_for(std::chrono::seconds(1));
    text += " [process " + std::to_string(group.rank()) + " of " + std::to_string(group.size()) +
            "]";
  }
  text += "\n";
  std::cerr.flush();
  if (::write(g_error_fd, text.data(), text.size()) < 0) {
    // Nowhere left to report to.
  }
}

void AbortProcesses(int code) {
#ifdef TACTFUNC_WITH_MPI
  if (g_world && g_world->size() > 1) {
    std::cout.flush();
    std::cerr.flush();
    MPI_Abort(MPI_COMM_WORLD, code);
  }
#else
  (void)code;
#endif
}

void FinishProcesses() {
#ifdef TACTFUNC_WITH_MPI
  int initialized = 0, finalized = 0;
  MPI_Initialized(&initialized);
  MPI_Finalized(&finalized);
  if (initialized && !finalized) MPI_Finalize();
#endif
}

}  // namespace tactfunc::apps
