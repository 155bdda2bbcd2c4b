// Copyright 2026 The tactfunc Authors.
//
// `mpirun -np 2 tactfunc train|encode|recon|eval|bench posterior` on this machine
// (loopback), against the same command run as one process (docs/SCALING.md): encode
// writes the same functaset bytes, train the same model bytes, recon and eval the same
// files (but for eval's PCA fit time), bench posterior the same figures (but for its
// times); only rank 0 speaks. A process killed mid-run (SIGKILL from the
// die_in_mpi_call shim) stops the job with mpirun's error naming its rank, leaves no
// half-written file, and --resume under mpirun finishes an encode or a training with
// the bytes of an uninterrupted one. Other commands refuse mpirun. Skipped where the
// build has no MPI (then the last test checks that the program refuses to run as
// several processes).
#include <filesystem>
#include <set>
#include <string>
#include <utility>

#include <unistd.h>

#include "estimation/functaset/functaset.h"
#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "tests/apps/cli_test_util.h"

namespace tactfunc {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using Result = testing_util::CliResult;

#ifdef TACTFUNC_WITH_MPI
constexpr bool kWithMpi = true;
const char* const kMpiexec = TACTFUNC_MPIEXEC;
const char* const kDieShim = TACTFUNC_DIE_SHIM;
#else
constexpr bool kWithMpi = false;
const char* const kMpiexec = "";
const char* const kDieShim = "";
#endif

class MpiCliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    root_ = new fs::path(fs::path(::testing::TempDir()) /
                         ("tactfunc_mpi_cli_" + std::to_string(::getpid())));
    fs::remove_all(*root_);
    fs::create_directories(*root_);
    if (!kWithMpi) return;
    // Two tools x 3 contacts x two sensors = 12 frames, and a tiny model of them.
    const Result synth = Run("synth --out " + Root("d") +
                             " --frames-per-tool 3 --tools rod,square --seed 3 --threads 1");
    ASSERT_EQ(synth.exit_code, 0) << synth.err;
    const Result train = Run("train --data " + Root("d") + " --out " + Root("m.tfm") +
                             " --preset tiny --steps 3 --seed 2 --threads 1");
    ASSERT_EQ(train.exit_code, 0) << train.err;
  }
  static void TearDownTestSuite() {
    fs::remove_all(*root_);
    delete root_;
  }
  void SetUp() override {
    if (!kWithMpi) return;
    if (::access(kMpiexec, X_OK) != 0) GTEST_SKIP() << "no mpiexec at " << kMpiexec;
  }

  static std::string Root(const std::string& name) { return (*root_ / name).string(); }
  static Result Run(const std::string& args) { return testing_util::RunTactfunc(*root_, args); }
  // `mpiexec -np N tactfunc ARGS` on this machine, also as root (CI); `ranks_env` adds
  // "-x NAME=VALUE" settings for the processes. A run that hangs is ended after 2
  // minutes (timeout's SIGTERM: mpiexec ends its processes) and fails its test.
  static Result RunMpi(int np, const std::string& args, const std::string& ranks_env = "") {
    return testing_util::RunShell(
        *root_, "OMPI_ALLOW_RUN_AS_ROOT=1 OMPI_ALLOW_RUN_AS_ROOT_CONFIRM=1 timeout 120 " +
                    std::string(kMpiexec) + " -np " + std::to_string(np) +
                    " --oversubscribe --allow-run-as-root " + ranks_env + " " +
                    testing_util::TactfuncPath() + " " + args);
  }
  // "-x ..." that make rank `rank` die on entering its `at`-th work exchange.
  static std::string DieAt(int rank, int at) {
    return std::string("-x LD_PRELOAD=") + kDieShim + " -x TACTFUNC_TEST_DIE_RANK=" +
           std::to_string(rank) + " -x TACTFUNC_TEST_DIE_AT=" + std::to_string(at);
  }
  static bool SameBytes(const std::string& a, const std::string& b) {
    return fs::exists(a) && testing_util::Slurp(a) == testing_util::Slurp(b);
  }
  std::string Encode(const std::string& out) const {
    return "encode --model " + Root("m.tfm") + " --data " + Root("d") + " --out " + Root(out);
  }
  std::string Train(const std::string& out) const {
    return "train --data " + Root("d") + " --out " + Root(out) + " --preset tiny --seed 5";
  }
  // For recon, eval and bench posterior: a dataset with test frames (2 tools x 4
  // contacts, half of them test, two sensors = 16 frames), its functaset under the tiny
  // model, and a pose model of its bubble latents re-fitted with ceres:3 (so that eval
  // re-fits every bubble frame for the pose rows, per-frame work it shares out).
  static void MakeEvaluationInputs() {
    if (fs::exists(Root("pt.tpm"))) return;
    Result r = Run("synth --out " + Root("dt") +
                   " --frames-per-tool 4 --test-fraction 0.5 --tools rod,square --seed 4 "
                   "--threads 1");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    r = Run("encode --model " + Root("m.tfm") + " --data " + Root("dt") + " --out " +
            Root("ft.tfs") + " --threads 1");
    ASSERT_EQ(r.exit_code, 0) << r.err;
    r = Run("train-pose --functaset " + Root("ft.tfs") + " --model " + Root("m.tfm") +
            " --data " + Root("dt") + " --refit ceres:3 --out " + Root("pt.tpm") +
            " --hidden 16,16 --epochs 20 --batch 4");
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  std::string Recon(const std::string& out) const {
    return "recon --model " + Root("m.tfm") + " --functaset " + Root("ft.tfs") + " --data " +
           Root("dt") + " --out " + Root(out) + " --examples 3";
  }
  std::string Eval(const std::string& out) const {
    return "eval --data " + Root("dt") + " --model " + Root("m.tfm") + " --functaset " +
           Root("ft.tfs") + " --pose-model " + Root("pt.tpm") + " --extra-functaset " +
           Root("ft.tfs") + " --extra-model " + Root("m.tfm") + " --out " + Root(out);
  }
  std::string BenchPosterior() const {
    return "bench posterior --model " + Root("m.tfm") + " --pose-model " + Root("pt.tpm") +
           " --functaset " + Root("ft.tfs") + " --data " + Root("dt") +
           " --frames 4 --samples 10 --json";
  }
  // Moves folder `from` to `to` (replacing it): the one-process run's outputs, so that
  // the run of two processes writes to the same --out (eval's table.md and table.json
  // quote the command line).
  static void MoveFolder(const std::string& from, const std::string& to) {
    fs::remove_all(Root(to));
    fs::rename(Root(from), Root(to));
  }
  // Every file of folder `a` has the bytes of the same file in `b`, and both hold the
  // same names; `except` are compared by the caller.
  static void ExpectSameFiles(const std::string& a, const std::string& b,
                              const std::set<std::string>& except = {}) {
    std::set<std::string> names_a, names_b;
    for (const auto& e : fs::directory_iterator(Root(a))) names_a.insert(e.path().filename());
    for (const auto& e : fs::directory_iterator(Root(b))) names_b.insert(e.path().filename());
    EXPECT_EQ(names_a, names_b);
    for (const std::string& name : names_a) {
      if (except.count(name)) continue;
      EXPECT_TRUE(SameBytes(Root(a + "/" + name), Root(b + "/" + name))) << a << "/" << name;
    }
  }
  static int Count(const std::string& text, const std::string& part) {
    int n = 0;
    for (std::size_t at = text.find(part); at != std::string::npos; at = text.find(part, at + 1)) {
      ++n;
    }
    return n;
  }
  // No temporary file of an atomic write anywhere under the suite's folder.
  static void ExpectNoTemporaries() {
    for (const fs::directory_entry& entry : fs::recursive_directory_iterator(*root_)) {
      EXPECT_THAT(entry.path().filename().string(), ::testing::Not(HasSubstr(".tmp.")))
          << "left behind";
    }
  }

  static fs::path* root_;
};
fs::path* MpiCliTest::root_ = nullptr;

TEST_F(MpiCliTest, EncodeAsTwoProcessesWritesTheBytesOfOneProcess) {
  if (!kWithMpi) GTEST_SKIP() << "this build has no MPI (configure found none)";
  const Result one = Run(Encode("one.tfs") + " --threads 1 --json");
  ASSERT_EQ(one.exit_code, 0) << one.err;
  EXPECT_EQ(one.LastJson()["processes"], 1);
  // One round, rounds of 2 frames (a checkpoint after each), and 2 threads per process.
  for (const std::string& flags :
       {std::string("--checkpoint-every 0 --threads 1"), std::string("--checkpoint-every 2 --threads 1"),
        std::string("--checkpoint-every 5 --threads 2")}) {
    fs::remove(Root("two.tfs"));
    const Result two = RunMpi(2, Encode("two.tfs") + " --json " + flags);
    ASSERT_EQ(two.exit_code, 0) << flags << "\n" << two.out << two.err;
    EXPECT_TRUE(SameBytes(Root("two.tfs"), Root("one.tfs"))) << flags;
    const nlohmann::json figures = two.LastJson();
    EXPECT_EQ(figures["processes"], 2);
    EXPECT_EQ(figures["frames_encoded"], 12);
    // Rank 0 alone speaks: one summary line, one JSON line.
    const std::string& out = two.out;
    EXPECT_EQ(out.find("encode: wrote"), out.rfind("encode: wrote")) << out;
    EXPECT_THAT(out, HasSubstr("on 2 processes x "));
  }
}

TEST_F(MpiCliTest, TrainAsTwoProcessesWritesTheModelOfOneProcess) {
  if (!kWithMpi) GTEST_SKIP() << "this build has no MPI (configure found none)";
  // Batches of 4 (2 + 2 slots) and 5 (2 + 3 slots), 3 steps.
  for (const std::string& batch : {std::string("4"), std::string("5")}) {
    const std::string flags = " --steps 3 --threads 1 --batch " + batch;
    const Result one = Run(Train("one_" + batch + ".tfm") + flags);
    ASSERT_EQ(one.exit_code, 0) << one.err;
    const Result two = RunMpi(2, Train("two_" + batch + ".tfm") + flags + " --json");
    ASSERT_EQ(two.exit_code, 0) << two.out << two.err;
    EXPECT_TRUE(SameBytes(Root("two_" + batch + ".tfm"), Root("one_" + batch + ".tfm")))
        << "batch " << batch;
    EXPECT_EQ(two.LastJson()["processes"], 2);
    EXPECT_EQ(two.out.find("train: wrote " + Root("two_" + batch + ".tfm")),
              two.out.rfind("train: wrote " + Root("two_" + batch + ".tfm")));
  }
}

TEST_F(MpiCliTest, TheSmallPresetTrainsToTheSameModelAsTwoProcesses) {
  if (!kWithMpi) GTEST_SKIP() << "this build has no MPI (configure found none)";
  // The trunk the pretrained model uses (21k parameters, batch 32): 2 steps, bubble.
  const std::string flags = " --preset small --sensors bubble --steps 2 --threads 1 --seed 1";
  const std::string common = "train --data " + Root("d") + flags + " --out ";
  const Result one = Run(common + Root("small_one.tfm"));
  ASSERT_EQ(one.exit_code, 0) << one.err;
  const Result two = RunMpi(2, common + Root("small_two.tfm"));
  ASSERT_EQ(two.exit_code, 0) << two.out << two.err;
  EXPECT_TRUE(SameBytes(Root("small_two.tfm"), Root("small_one.tfm")));
}

TEST_F(MpiCliTest, AnEncodeWhoseProcessDiesLeavesACheckpointThatResumesToTheSameBytes) {
  if (!kWithMpi) GTEST_SKIP() << "this build has no MPI (configure found none)";
  const Result one = Run(Encode("one.tfs") + " --threads 1");
  ASSERT_EQ(one.exit_code, 0) << one.err;
  // Rounds of 2 frames: rank 1 dies entering the third exchange, so rank 0 (the writer)
  // has written the checkpoints of rounds 1 and 2, or is killed writing the second.
  const std::string flags = " --threads 1 --checkpoint-every 2";
  const Result dead = RunMpi(2, Encode("dead.tfs") + flags, DieAt(1, 3));
  EXPECT_NE(dead.exit_code, 0);
  EXPECT_THAT(dead.out + dead.err, HasSubstr("signal 9"));
  EXPECT_FALSE(fs::exists(Root("dead.tfm")));
  ASSERT_TRUE(fs::exists(Root("dead.tfs")));
  const Functaset partial = Functaset::Load(Root("dead.tfs"));  // never half-written
  EXPECT_FALSE(partial.complete());
  EXPECT_GE(partial.size(), 2u);
  EXPECT_LE(partial.size(), 4u);
  const Result resumed = RunMpi(2, Encode("dead.tfs") + flags + " --resume --json");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.out << resumed.err;
  EXPECT_EQ(resumed.LastJson()["frames_resumed"], partial.size());
  EXPECT_TRUE(SameBytes(Root("dead.tfs"), Root("one.tfs")));
  for (const fs::directory_entry& entry : fs::directory_iterator(*root_)) {
    EXPECT_THAT(entry.path().filename().string(), ::testing::Not(HasSubstr(".tmp."))) << "left behind";
  }
}

TEST_F(MpiCliTest, ATrainingWhoseWriterDiesResumesToTheModelOfAnUninterruptedRun) {
  if (!kWithMpi) GTEST_SKIP() << "this build has no MPI (configure found none)";
  const std::string flags = " --sensors bubble --steps 6 --threads 1 --checkpoint-every 2";
  const Result one = Run(Train("whole.tfm") + flags);
  ASSERT_EQ(one.exit_code, 0) << one.err;
  // Two exchanges a step (the gradients, then the stop flag): rank 0 dies entering the
  // gradients of step 3, after writing the checkpoint of step 2.
  const Result dead = RunMpi(2, Train("dead.tfm") + flags, DieAt(0, 5));
  EXPECT_NE(dead.exit_code, 0);
  EXPECT_THAT(dead.out + dead.err, HasSubstr("signal 9"));
  EXPECT_FALSE(fs::exists(Root("dead.tfm")));
  const Result info = Run("info " + Root("dead.tfm.bubble.ckpt") + " --json");
  ASSERT_EQ(info.exit_code, 0) << info.err;
  EXPECT_THAT(info.out, HasSubstr("\"step\":2"));
  const Result resumed = RunMpi(2, Train("dead.tfm") + flags + " --resume");
  ASSERT_EQ(resumed.exit_code, 0) << resumed.out << resumed.err;
  EXPECT_THAT(resumed.out, HasSubstr("resuming from"));
  EXPECT_TRUE(SameBytes(Root("dead.tfm"), Root("whole.tfm")));
}

TEST_F(MpiCliTest, ReconAsTwoProcessesWritesTheFilesOfOneProcess) {
  if (!kWithMpi) GTEST_SKIP() << "this build has no MPI (configure found none)";
  MakeEvaluationInputs();
  const Result one = Run(Recon("recon") + " --threads 1 --json");
  ASSERT_EQ(one.exit_code, 0) << one.err;
  MoveFolder("recon", "recon_one");
  for (const std::string& threads : {std::string("1"), std::string("2")}) {
    const Result two = RunMpi(2, Recon("recon") + " --json --threads " + threads);
    ASSERT_EQ(two.exit_code, 0) << two.out << two.err;
    // frames.csv (16 rows) and both pictures, byte for byte.
    ExpectSameFiles("recon", "recon_one");
    EXPECT_EQ(Count(testing_util::Slurp(Root("recon/frames.csv")), "\n"), 17);
    // The figures but the wall time; rank 0 alone prints.
    nlohmann::json a = one.LastJson(), b = two.LastJson();
    EXPECT_EQ(a["frames"], 16);
    a.erase("seconds");
    b.erase("seconds");
    EXPECT_EQ(a.dump(), b.dump()) << "threads " << threads;
    EXPECT_EQ(Count(two.out, "recon: wrote "), 3) << two.out;  // two pictures, frames.csv
    const std::string table = one.out.substr(0, one.out.find("recon: wrote"));
    EXPECT_THAT(two.out, HasSubstr(table));
  }
}

// table.json without its one timing (the PCA fit's seconds per sensor).
nlohmann::json WithoutTimes(nlohmann::json table) {
  for (auto& [sensor, details] : table["details"].items()) details["pca"].erase("fit_seconds");
  return table;
}

TEST_F(MpiCliTest, EvalAsTwoProcessesWritesTheTableOfOneProcess) {
  if (!kWithMpi) GTEST_SKIP() << "this build has no MPI (configure found none)";
  MakeEvaluationInputs();
  const Result one = Run(Eval("eval") + " --threads 1 --json");
  ASSERT_EQ(one.exit_code, 0) << one.err;
  EXPECT_THAT(one.out, HasSubstr("re-fitted every bubble frame"));
  MoveFolder("eval", "eval_one");
  const Result two = RunMpi(2, Eval("eval") + " --threads 1 --json");
  ASSERT_EQ(two.exit_code, 0) << two.out << two.err;
  // table.md and rate_distortion.png byte for byte; table.json but for the PCA fit time.
  ExpectSameFiles("eval", "eval_one", {"table.json"});
  const nlohmann::json a = nlohmann::json::parse(testing_util::Slurp(Root("eval_one/table.json")));
  const nlohmann::json b = nlohmann::json::parse(testing_util::Slurp(Root("eval/table.json")));
  ASSERT_TRUE(a["details"]["bubble"]["pca"].contains("fit_seconds"));
  EXPECT_EQ(WithoutTimes(a).dump(2), WithoutTimes(b).dump(2));
  EXPECT_EQ(WithoutTimes(one.LastJson()).dump(), WithoutTimes(two.LastJson()).dump());
  EXPECT_EQ(a["rows"].size(), b["rows"].size());
  // Rank 0 alone speaks: one table, one "wrote" line.
  EXPECT_EQ(Count(two.out, "eval: wrote"), 1) << two.out;
  EXPECT_EQ(Count(two.out, "| approach |"), 1) << two.out;
}

// bench posterior's --json figures without its times (per-frame medians and p90 of
// wall times, measured on whichever process ran the frame).
nlohmann::json WithoutPosteriorTimes(nlohmann::json figures) {
  for (auto& sampler : figures["samplers"]) {
    for (const char* key : {"ms_median", "ms_p90", "ms_median_after_fit"}) {
      EXPECT_TRUE(sampler[key].is_number()) << key;
      sampler.erase(key);
    }
  }
  return figures;
}

TEST_F(MpiCliTest, BenchPosteriorAsTwoProcessesReportsTheFiguresOfOneProcess) {
  if (!kWithMpi) GTEST_SKIP() << "this build has no MPI (configure found none)";
  MakeEvaluationInputs();
  const Result one = Run(BenchPosterior());
  ASSERT_EQ(one.exit_code, 0) << one.err;
  const Result two = RunMpi(2, BenchPosterior());
  ASSERT_EQ(two.exit_code, 0) << two.out << two.err;
  const nlohmann::json a = one.LastJson(), b = two.LastJson();
  EXPECT_EQ(a["frames"], 4);
  ASSERT_EQ(a["samplers"].size(), 3u);
  EXPECT_EQ(WithoutPosteriorTimes(a).dump(), WithoutPosteriorTimes(b).dump());
  // Every time gathered: the medians are of all 4 frames' times, not of rank 0's two.
  EXPECT_GT(b["samplers"][0]["ms_median"].get<double>(), 0.0);
  EXPECT_EQ(Count(two.out, "bench posterior: 4 labelled bubble test frames"), 1) << two.out;
}

TEST_F(MpiCliTest, AnEvalOrReconWhoseProcessDiesLeavesTheEarlierFilesUntouched) {
  if (!kWithMpi) GTEST_SKIP() << "this build has no MPI (configure found none)";
  MakeEvaluationInputs();
  // The files of an earlier complete run in --out; then a run whose rank 1 (or rank 0,
  // the writer) is killed entering an exchange: the job stops, mpirun names the rank,
  // and --out still holds the earlier bytes, without temporary files.
  const Result eval = Run(Eval("eval_dead") + " --threads 1");
  ASSERT_EQ(eval.exit_code, 0) << eval.err;
  fs::remove_all(Root("eval_before"));
  fs::copy(Root("eval_dead"), Root("eval_before"));
  // Exchanges: per sensor the frames, the TactFunc PSNRs, 10 JPEG qualities and the
  // extra functaset's PSNRs, and for bubble (the pose sensor) the re-fitted latents:
  // 14 + 13. Rank 1 dies in the first, rank 0 in the third, rank 1 in the last (after
  // which rank 0 would write the files).
  for (const auto& [rank, at] : {std::pair<int, int>{1, 1}, std::pair<int, int>{0, 3},
                                 std::pair<int, int>{1, 27}}) {
    const Result dead = RunMpi(2, Eval("eval_dead") + " --threads 1", DieAt(rank, at));
    EXPECT_NE(dead.exit_code, 0) << rank << " " << at;
    EXPECT_THAT(dead.out + dead.err, HasSubstr("rank " + std::to_string(rank)));
    EXPECT_THAT(dead.out + dead.err, HasSubstr("signal 9"));
    ExpectSameFiles("eval_dead", "eval_before");
  }
  const Result recon = Run(Recon("recon_dead") + " --threads 1");
  ASSERT_EQ(recon.exit_code, 0) << recon.err;
  fs::remove_all(Root("recon_before"));
  fs::copy(Root("recon_dead"), Root("recon_before"));
  const Result dead = RunMpi(2, Recon("recon_dead") + " --threads 1", DieAt(1, 1));
  EXPECT_NE(dead.exit_code, 0);
  EXPECT_THAT(dead.out + dead.err, HasSubstr("rank 1"));
  EXPECT_THAT(dead.out + dead.err, HasSubstr("signal 9"));
  ExpectSameFiles("recon_dead", "recon_before");
  // bench posterior writes no file: the job stops naming the rank, and no figures.
  const Result bench = RunMpi(2, BenchPosterior(), DieAt(1, 1));
  EXPECT_NE(bench.exit_code, 0);
  EXPECT_THAT(bench.out + bench.err, HasSubstr("rank 1"));
  EXPECT_THAT(bench.out, ::testing::Not(HasSubstr("\"samplers\"")));
  ExpectNoTemporaries();
}

TEST_F(MpiCliTest, OtherCommandsRefuseToRunAsSeveralProcesses) {
  if (!kWithMpi) GTEST_SKIP() << "this build has no MPI (configure found none)";
  // A command of its own, a bench suite other than posterior, and one that writes files.
  for (const std::string& command :
       {std::string("info --tools"), std::string("bench synth"),
        "synth --out " + Root("refused") + " --frames-per-tool 1 --tools rod"}) {
    const Result run = RunMpi(2, command);
    EXPECT_NE(run.exit_code, 0) << command;
    const std::string name = command.substr(0, command.find(" --"));
    EXPECT_THAT(run.err, HasSubstr("tactfunc " + name + ": error: started as 2 processes "
                                   "(mpirun), but only train, encode, recon, eval and bench "
                                   "posterior run as several processes; run " + name +
                                   " without mpirun"));
  }
  EXPECT_FALSE(fs::exists(Root("refused")));
}

TEST_F(MpiCliTest, ABuildWithoutMpiRefusesToRunAsSeveralProcesses) {
  if (kWithMpi) GTEST_SKIP() << "this build has MPI (the tests above run it)";
  // What mpirun sets in each process it starts.
  const Result run = testing_util::RunShell(
      *root_, "OMPI_COMM_WORLD_SIZE=2 OMPI_COMM_WORLD_RANK=0 " + testing_util::TactfuncPath() +
                  " info --tools");
  EXPECT_EQ(run.exit_code, 2);
  EXPECT_THAT(run.err, HasSubstr("this build of tactfunc has no MPI"));
  const Result alone = Run("info --tools");
  EXPECT_EQ(alone.exit_code, 0) << alone.err;
}

}  // namespace
}  // namespace tactfunc
