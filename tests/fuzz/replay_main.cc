// Copyright 2026 The tactfunc Authors.
//
// A main for the fuzz targets without libFuzzer (ctest's fuzz.replay.*, built by the
// normal compiler with the normal build; docs/RELIABILITY.md):
//
//   <target>_replay SEED_DIR [--mutations N] [--seed S] [--max-len L] [--only I]
//
// runs the target's LLVMFuzzerTestOneInput on every file of SEED_DIR, then on N inputs
// made from them by a fixed, seeded sequence of mutations (bit flips, interesting bytes
// and integers, insertions, erasures, duplicated ranges, truncations, splices of two
// seeds, digits swapped in text), each at most L bytes (default 8192, as the libFuzzer
// runs). Deterministic given S: input I of a run is input I of every run with the same
// seeds, so `--only I` replays one input.
//
// A finding ends the run with exit status 1 and the input written to
// ./replay-crash-<target>-<I>: an exception escaping the target (the targets catch only
// their reader's documented error type), an abort (the targets' own checks,
// tests/fuzz/fuzz_util.h) or a crash signal. The normal build has no sanitizer: memory
// errors that do not crash need the libFuzzer build (scripts/fuzz.sh) or the sanitized
// test build (scripts/sanitize.sh), which builds and runs these replays too.
#include <fcntl.h>
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <exception>
#include <filesystem>
#include <fstream>
#include <iterator>
#include <random>
#include <string>
#include <vector>

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size);
extern "C" __attribute__((weak)) int LLVMFuzzerInitialize(int* argc, char*** argv);

namespace {

using Bytes = std::vector<std::uint8_t>;

// What the signal handler writes: the current input and where it goes.
const Bytes* g_current = nullptr;
char g_artifact[4096] = {0};

void WriteArtifact() {
  if (g_current == nullptr || g_artifact[0] == 0) return;
  const int fd = ::open(g_artifact, O_WRONLY | O_CREAT | O_TRUNC, 0644);
  if (fd < 0) return;
  std::size_t done = 0;
  while (done < g_current->size()) {
    const ssize_t n = ::write(fd, g_current->data() + done, g_current->size() - done);
    if (n <= 0) break;
    done += static_cast<std::size_t>(n);
  }
  ::close(fd);
}

extern "C" void OnCrash(int signal) {
  WriteArtifact();
  static const char kMessage[] = "fuzz replay: FINDING: crash signal; input written to ";
  (void)!::write(2, kMessage, sizeof(kMessage) - 1);
  (void)!::write(2, g_artifact, std::strlen(g_artifact));
  (void)!::write(2, "\n", 1);
  std::signal(signal, SIG_DFL);
  std::raise(signal);
}

// Seeded mutations of the seeds, after the operators libFuzzer and AFL use.
class Mutator {
 public:
  Mutator(const std::vector<Bytes>& seeds, std::uint64_t seed, std::size_t max_len)
      : seeds_(seeds), max_len_(max_len), rng_(seed) {}

  Bytes Next() {
    Bytes bytes = seeds_[Below(seeds_.size())];
    const int rounds = 1 + static_cast<int>(Below(4));
    for (int i = 0; i < rounds; ++i) MutateOnce(&bytes);
    if (bytes.size() > max_len_) bytes.resize(max_len_);
    return bytes;
  }

 private:
  std::size_t Below(std::size_t n) { return n == 0 ? 0 : rng_() % n; }

  void MutateOnce(Bytes* bytes) {
    static constexpr std::uint8_t kBytes[] = {0x00, 0x01, 0x7f, 0x80, 0xff, '-', '"', ',', '\n'};
    static constexpr std::uint64_t kIntegers[] = {0,          1,          0xff,
                                                  0x7fff,     0xffff,     0x7fffffff,
                                                  0x80000000, 0xffffffff, 0x7fffffffffffffff,
                                                  ~0ull,      1ull << 20, 1ull << 31};
    Bytes& b = *bytes;
    switch (Below(10)) {
      case 0:  // flip one bit
        if (!b.empty()) b[Below(b.size())] ^= static_cast<std::uint8_t>(1u << Below(8));
        break;
      case 1:  // a random byte
        if (!b.empty()) b[Below(b.size())] = static_cast<std::uint8_t>(rng_());
        break;
      case 2:  // an interesting byte
        if (!b.empty()) b[Below(b.size())] = kBytes[Below(std::size(kBytes))];
        break;
      case 3: {  // an interesting little-endian integer of 2, 4 or 8 bytes
        const std::size_t width = std::size_t{2} << Below(3);
        if (b.size() < width) break;
        const std::size_t at = Below(b.size() - width + 1);
        const std::uint64_t value = kIntegers[Below(std::size(kIntegers))];
        for (std::size_t i = 0; i < width; ++i) b[at + i] = static_cast<std::uint8_t>(value >> (8 * i));
        break;
      }
      case 4: {  // erase a range
        if (b.empty()) break;
        const std::size_t at = Below(b.size());
        const std::size_t n = 1 + Below(std::min<std::size_t>(64, b.size() - at));
        b.erase(b.begin() + at, b.begin() + at + n);
        break;
      }
      case 5: {  // insert random bytes
        const std::size_t at = Below(b.size() + 1);
        Bytes extra(1 + Below(16));
        for (auto& x : extra) x = static_cast<std::uint8_t>(rng_());
        b.insert(b.begin() + at, extra.begin(), extra.end());
        break;
      }
      case 6: {  // copy a range of the input to another place
        if (b.size() < 2) break;
        const std::size_t from = Below(b.size());
        const Bytes chunk(b.begin() + from,
                          b.begin() + from + 1 + Below(std::min<std::size_t>(128, b.size() - from)));
        b.insert(b.begin() + Below(b.size() + 1), chunk.begin(), chunk.end());
        break;
      }
      case 7:  // truncate
        b.resize(Below(b.size() + 1));
        break;
      case 8: {  // this input's head, another seed's tail
        const Bytes& other = seeds_[Below(seeds_.size())];
        b.resize(Below(b.size() + 1));
        const std::size_t from = Below(other.size() + 1);
        b.insert(b.end(), other.begin() + from, other.end());
        break;
      }
      default: {  // text: a digit becomes another digit or a sign, point or exponent
        static constexpr char kDigits[] = "0123456789-+.eE";
        if (b.empty()) break;
        const std::size_t start = Below(b.size());
        for (std::size_t i = 0; i < b.size(); ++i) {
          std::uint8_t& c = b[(start + i) % b.size()];
          if (c >= '0' && c <= '9') {
            c = static_cast<std::uint8_t>(kDigits[Below(sizeof(kDigits) - 1)]);
            break;
          }
        }
        break;
      }
    }
  }

  const std::vector<Bytes>& seeds_;
  std::size_t max_len_;
  std::mt19937_64 rng_;
};

[[noreturn]] void Usage(const char* program, const std::string& error) {
  std::fprintf(stderr,
               "%s: %s\nusage: %s SEED_DIR [--mutations N] [--seed S] [--max-len L] "
               "[--only I]\n",
               program, error.c_str(), program);
  std::exit(2);
}

std::uint64_t Number(const char* program, const std::string& flag, const char* text) {
  char* end = nullptr;
  const unsigned long long value = std::strtoull(text, &end, 10);
  if (end == text || *end != 0 || text[0] == '-') {
    Usage(program, flag + ": expected a whole number >= 0, got '" + text + "'");
  }
  return value;
}

}  // namespace

int main(int argc, char** argv) {
  const char* program = argv[0];
  if (argc < 2) Usage(program, "no seed directory");
  const std::string seed_dir = argv[1];
  std::uint64_t mutations = 10000, seed = 1, max_len = 8192;
  long long only = -1;
  for (int i = 2; i < argc; i += 2) {
    const std::string flag = argv[i];
    if (i + 1 >= argc) Usage(program, flag + ": expected a value");
    if (flag == "--mutations") mutations = Number(program, flag, argv[i + 1]);
    else if (flag == "--seed") seed = Number(program, flag, argv[i + 1]);
    else if (flag == "--max-len") max_len = Number(program, flag, argv[i + 1]);
    else if (flag == "--only") only = static_cast<long long>(Number(program, flag, argv[i + 1]));
    else Usage(program, "unknown flag " + flag);
  }

  std::vector<std::filesystem::path> files;
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(seed_dir, ec)) {
    if (entry.is_regular_file()) files.push_back(entry.path());
  }
  if (ec) Usage(program, seed_dir + ": " + ec.message());
  if (files.empty()) Usage(program, seed_dir + ": no seed files");
  std::sort(files.begin(), files.end());
  std::vector<Bytes> seeds;
  for (const auto& path : files) {
    std::ifstream in(path, std::ios::binary);
    seeds.emplace_back(std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>());
  }

  std::string target = std::filesystem::path(program).filename().string();
  if (const auto cut = target.rfind("_replay"); cut != std::string::npos) target.resize(cut);
#if defined(__SANITIZE_ADDRESS__)
  // Built with ASan (scripts/sanitize.sh): its own handler reports a bad access; abort
  // alone is ours.
  std::signal(SIGABRT, OnCrash);
#else
  for (int s : {SIGSEGV, SIGABRT, SIGBUS, SIGFPE, SIGILL}) std::signal(s, OnCrash);
#endif
  if (LLVMFuzzerInitialize != nullptr) LLVMFuzzerInitialize(&argc, &argv);

  // Inputs 0..seeds-1 are the seeds, then the mutations.
  Mutator mutator(seeds, seed, max_len);
  const std::uint64_t total = seeds.size() + mutations;
  for (std::uint64_t i = 0; i < total; ++i) {
    Bytes input = i < seeds.size() ? seeds[i] : mutator.Next();
    if (only >= 0 && static_cast<std::uint64_t>(only) != i) continue;
    std::snprintf(g_artifact, sizeof(g_artifact), "replay-crash-%s-%llu", target.c_str(),
                  static_cast<unsigned long long>(i));
    g_current = &input;
    try {
      LLVMFuzzerTestOneInput(input.data(), input.size());
    } catch (const std::exception& e) {
      WriteArtifact();
      std::fprintf(stderr, "fuzz replay: FINDING: input %llu: uncaught exception: %s; input "
                   "written to %s\n", static_cast<unsigned long long>(i), e.what(), g_artifact);
      return 1;
    } catch (...) {
      WriteArtifact();
      std::fprintf(stderr, "fuzz replay: FINDING: input %llu: uncaught exception of a type "
                   "not derived from std::exception; input written to %s\n",
                   static_cast<unsigned long long>(i), g_artifact);
      return 1;
    }
    g_current = nullptr;
  }
  if (only >= 0) {
    std::printf("fuzz replay %s: input %lld, 0 findings\n", target.c_str(), only);
    return 0;
  }
  std::printf("fuzz replay %s: %zu seeds and %llu mutations (seed %llu, inputs <= %llu "
              "bytes), 0 findings\n",
              target.c_str(), seeds.size(), static_cast<unsigned long long>(mutations),
              static_cast<unsigned long long>(seed), static_cast<unsigned long long>(max_len));
  return 0;
}
