// Copyright 2026 The tactfunc Authors.
//
// `mpirun -np 2 tactfunc train|encode` on this machine (loopback), against the same
// command run as one process (docs/SCALING.md): encode writes the same functaset bytes,
// train the same model bytes; only rank 0 speaks. A process killed mid-run (SIGKILL
// from the die_in_mpi_call shim) stops the job with mpirun's error, leaves no
// half-written file, and --resume under mpirun finishes the run with the bytes of an
// uninterrupted one. Other commands refuse mpirun. Skipped where the build has no MPI
// (then the last test checks that the program refuses to run as several processes).
#include <filesystem>
#include <string>

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

TEST_F(MpiCliTest, OtherCommandsRefuseToRunAsSeveralProcesses) {
  if (!kWithMpi) GTEST_SKIP() << "this build has no MPI (configure found none)";
  const Result info = RunMpi(2, "info --tools");
  EXPECT_NE(info.exit_code, 0);
  EXPECT_THAT(info.err, HasSubstr("tactfunc info: error: started as 2 processes (mpirun), but "
                                  "only train and encode run as several processes"));
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
