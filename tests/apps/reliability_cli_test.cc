// Copyright 2026 The tactfunc Authors.
//
// The tactfunc program against hostile use (docs/RELIABILITY.md): an output path that
// names an input -- the same path, another spelling, a symlink or a hard link; the
// model, a functaset, the dataset folder or a file in it -- is refused before any work
// and the input is left byte for byte; a failed encode says where its partial
// functaset is; a non-UTF-8 tool name fails at open naming the file and line; Ctrl-C
// during train's final model write does not lose the model; the same seed gives the
// same model bytes; oversized frames and synth runs are refused up front; flag range
// errors read like every other error.
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "gmock/gmock.h"
#include "gtest/gtest.h"
#include "models/trunk/functa_model.h"
#include "tests/apps/cli_test_util.h"
#include "tests/support/image_test_util.h"
#include "tests/support/test_dir.h"

namespace tactfunc {
namespace {

namespace fs = std::filesystem;
using ::testing::HasSubstr;
using ::testing::Not;
using Result = testing_util::CliResult;
using testing_util::Slurp;

class ReliabilityCliTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    Result encode;
    root_ = new fs::path(testing_util::MakeEncodedFixture("tactfunc_reliability_cli", &encode));
    ASSERT_EQ(encode.exit_code, 0) << encode.err;
    const Result pose = Run("train-pose --functaset " + Root("f.tfs") + " --out " +
                            Root("p.tpm") + " --hidden 8 --epochs 3 --batch 4");
    ASSERT_EQ(pose.exit_code, 0) << pose.err;
    const Result synth = Run("synth --out " + Root("s") +
                             " --frames-per-tool 3 --tools rod --sensors bubble --seed 3");
    ASSERT_EQ(synth.exit_code, 0) << synth.err;
  }
  static void TearDownTestSuite() {
    fs::remove_all(*root_);
    delete root_;
  }
  static std::string Root(const std::string& name) { return (*root_ / name).string(); }
  static Result Run(const std::string& args) { return testing_util::RunTactfunc(*root_, args); }

  // Every regular file under `path` (or the file itself) with its bytes.
  static std::vector<std::pair<std::string, std::string>> Snapshot(const std::string& path) {
    std::vector<std::pair<std::string, std::string>> files;
    if (fs::is_regular_file(path)) return {{path, Slurp(path)}};
    for (const auto& entry : fs::recursive_directory_iterator(path)) {
      if (entry.is_regular_file()) files.push_back({entry.path().string(), Slurp(entry.path())});
    }
    std::sort(files.begin(), files.end());
    return files;
  }

  static fs::path* root_;
};

fs::path* ReliabilityCliTest::root_ = nullptr;

TEST_F(ReliabilityCliTest, AnOutputThatIsAnInputIsRefusedBeforeAnyWorkAndTheInputKept) {
  fs::create_symlink(Root("m.tfm"), Root("model_link.tfm"));
  fs::create_hard_link(Root("f.tfs"), Root("f_hard.tfs"));
  const std::string model = " --model " + Root("m.tfm"), data = " --data " + Root("d");
  struct Case {
    std::string args;     // the command line
    std::string guarded;  // the input that must survive
    std::string named;    // what the message must name
  };
  const std::vector<Case> cases = {
      {"encode" + model + data + " --out " + Root("m.tfm"), Root("m.tfm"), "--model"},
      {"encode" + model + data + " --out " + Root("model_link.tfm"), Root("m.tfm"), "--model"},
      {"encode" + model + data + " --out " + Root("d/../m.tfm"), Root("m.tfm"), "--model"},
      {"encode" + model + data + " --out " + Root("d/dataset.json"), Root("d"), "dataset.json"},
      {"encode" + model + data + " --out " + Root("d/labels.csv"), Root("d"), "labels.csv"},
      {"encode" + model + data + " --out " + Root("d"), Root("d"), "same folder as --data"},
      {"encode" + model + data + " --out " + Root("d/bubble/000001.png"), Root("d"),
       "000001.png"},
      {"train --data " + Root("s") + " --out " + Root("s/dataset.json") + " --preset tiny --steps 1",
       Root("s"), "dataset.json"},
      {"train --data " + Root("s") + " --out " + Root("s/bubble/000000.png") +
           " --preset tiny --steps 1",
       Root("s"), "000000.png"},
      {"train-pose --functaset " + Root("f.tfs") + " --out " + Root("f.tfs") + " --epochs 1",
       Root("f.tfs"), "--functaset"},
      {"train-pose --functaset " + Root("f.tfs") + " --out " + Root("f_hard.tfs") + " --epochs 1",
       Root("f.tfs"), "--functaset"},
      {"recon" + model + " --functaset " + Root("f.tfs") + data + " --out " + Root("d"),
       Root("d"), "--data"},
      {"show " + Root("d") + " --out " + Root("d/gelslim/000002.png"), Root("d"), "000002.png"},
      {"fit" + model + " --frame " + Root("d/bubble/000001.png") + " --reference " +
           Root("d/bubble/reference.png") + " --out " + Root("m.tfm"),
       Root("m.tfm"), "--model"},
      {"pose" + model + " --pose-model " + Root("p.tpm") + data + " --id 000003 --out " +
           Root("p.tpm"),
       Root("p.tpm"), "--pose-model"},
      {"eval" + model + " --functaset " + Root("f.tfs") + " --pose-model " + Root("p.tpm") +
           data + " --out " + Root("d"),
       Root("d"), "--data"},
  };
  for (const Case& c : cases) {
    const auto before = Snapshot(c.guarded);
    const Result r = Run(c.args);
    EXPECT_EQ(r.exit_code, 2) << c.args << "\n" << r.out << r.err;
    EXPECT_THAT(r.err, HasSubstr("refusing to overwrite an input")) << c.args;
    EXPECT_THAT(r.err, HasSubstr(c.named)) << c.args;
    EXPECT_THAT(r.err, HasSubstr(": error: --out")) << c.args;
    EXPECT_TRUE(Snapshot(c.guarded) == before) << "changed by: " << c.args;
  }
  // Another output path in the same folder is fine.
  EXPECT_EQ(Run("encode" + model + data + " --out " + Root("d/f2.tfs") + " --threads 1").exit_code,
            0);
}

TEST_F(ReliabilityCliTest, AFailedEncodeNamesThePartialFunctasetItLeaves) {
  fs::copy(Root("d"), Root("broken"), fs::copy_options::recursive);
  // Frames are encoded in id order: the last bubble frame is damaged, so checkpoints of
  // the frames before it are on disk when it fails.
  testing_util::WriteText(Root("broken/bubble/000011.png"), "\x89PNG damaged");
  const Result r = Run("encode --model " + Root("m.tfm") + " --data " + Root("broken") +
                       " --out " + Root("partial.tfs") + " --threads 1 --checkpoint-every 1");
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("000011.png"));
  EXPECT_THAT(r.err, HasSubstr(Root("partial.tfs") + " holds a PARTIAL functaset of"));
  EXPECT_THAT(r.err, HasSubstr("written by this run"));
  EXPECT_THAT(r.err, HasSubstr("--resume"));
  ASSERT_TRUE(fs::exists(Root("partial.tfs")));
}

TEST_F(ReliabilityCliTest, ANonUtf8ToolNameFailsInfoAndEncodeUpFrontNamingFileAndLine) {
  fs::copy(Root("d"), Root("bad_tool"), fs::copy_options::recursive);
  std::string labels = Slurp(Root("bad_tool/labels.csv"));
  const std::size_t at = labels.find(",pen,");
  ASSERT_NE(at, std::string::npos);
  labels.replace(at, 5, ",p\xff\xfen,");
  testing_util::WriteText(Root("bad_tool/labels.csv"), labels);
  const std::size_t line = std::count(labels.begin(), labels.begin() + at, '\n') + 1;
  const std::string where = "labels.csv:" + std::to_string(line) + ": field 'tool'";
  const Result info = Run("info " + Root("bad_tool"));
  EXPECT_EQ(info.exit_code, 1);
  EXPECT_THAT(info.err, HasSubstr(where));
  const Result encode = Run("encode --model " + Root("m.tfm") + " --data " + Root("bad_tool") +
                            " --out " + Root("bad_tool.tfs") + " --threads 1");
  EXPECT_EQ(encode.exit_code, 1);
  EXPECT_THAT(encode.err, HasSubstr(where));
  EXPECT_THAT(encode.err, HasSubstr("expected a tool name in UTF-8"));
  EXPECT_FALSE(fs::exists(Root("bad_tool.tfs")));  // nothing was encoded
}

TEST_F(ReliabilityCliTest, CtrlCDuringTheFinalModelWriteDoesNotLoseTheModel) {
  // The shim raises SIGINT twice inside the atomic write of the model, between the
  // complete temporary file and its rename (tests/apps/sigint_on_rename.cc).
  fs::create_directories(Root("sig"));
  const std::string out = Root("sig/m_sig.tfm");
#if defined(__SANITIZE_ADDRESS__)
  // Under AddressSanitizer (scripts/sanitize.sh) the preloaded shim comes before ASan's
  // runtime in the library list, which ASan refuses unless told to accept it (added to
  // the caller's ASAN_OPTIONS, which the shell expands).
  const std::string asan = "ASAN_OPTIONS=\"$ASAN_OPTIONS:verify_asan_link_order=0\" ";
#else
  const std::string asan;
#endif
  const std::string command = asan + "LD_PRELOAD=" + std::string(TACTFUNC_SIGINT_SHIM) +
                              " TACTFUNC_TEST_SIGINT_ON_RENAME=/m_sig.tfm CI=true " +
                              TACTFUNC_BINARY_DIR + "/bin/tactfunc train --data " + Root("s") +
                              " --out " + out + " --preset tiny --steps 2 --seed 1 >" +
                              Root("sig/out.txt") + " 2>" + Root("sig/err.txt") + " </dev/null";
  const int status = std::system(command.c_str());
  ASSERT_TRUE(WIFEXITED(status)) << "killed: " << Slurp(Root("sig/err.txt"));
  EXPECT_EQ(WEXITSTATUS(status), 130) << Slurp(Root("sig/err.txt"));
  EXPECT_THAT(Slurp(Root("sig/out.txt")), HasSubstr("the model was written completely to " + out));
  ASSERT_TRUE(fs::exists(out));
  EXPECT_NO_THROW(FunctaModel::Load(out));
  for (const auto& entry : fs::directory_iterator(Root("sig"))) {
    EXPECT_THAT(entry.path().filename().string(), Not(HasSubstr(".tmp."))) << "left behind";
  }
}

TEST_F(ReliabilityCliTest, StaleTemporaryFilesOfAKilledRunAreRemoved) {
  fs::create_directories(Root("stale"));
  // pid 2^22 + 1 is above Linux's pid_max: no process runs with it.
  testing_util::WriteText(Root("stale/.m.tfm.tmp.4194305.0"), "half a model");
  testing_util::WriteText(Root("stale/.m.tfm.tmp." + std::to_string(::getpid()) + ".0"), "live");
  const Result r = Run("train --data " + Root("s") + " --out " + Root("stale/m.tfm") +
                       " --preset tiny --steps 1");
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_FALSE(fs::exists(Root("stale/.m.tfm.tmp.4194305.0")));
  EXPECT_TRUE(fs::exists(Root("stale/.m.tfm.tmp." + std::to_string(::getpid()) + ".0")));
}

TEST_F(ReliabilityCliTest, TheSameSeedGivesTheSameModelBytes) {
  for (const char* name : {"seed_a.tfm", "seed_b.tfm"}) {
    const Result r = Run("train --data " + Root("s") + " --out " + Root(name) +
                         " --preset tiny --steps 3 --seed 5");
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  const std::string a = Slurp(Root("seed_a.tfm")), b = Slurp(Root("seed_b.tfm"));
  ASSERT_FALSE(a.empty());
  EXPECT_TRUE(a == b) << "the two model files differ";
  EXPECT_EQ(FunctaModel::Load(Root("seed_a.tfm")).checksum(),
            FunctaModel::Load(Root("seed_b.tfm")).checksum());
}

TEST_F(ReliabilityCliTest, AnOversizedFrameIsRefusedFromItsHeaderNamingTheFile) {
  // A PNG header claiming 100000 x 100000 16-bit pixels, nothing behind it.
  testing_util::WriteText(Root("huge.png"), testing_util::PngHeaderOnly(100000, 100000, 16, 0));
  const Result r = Run("fit --model " + Root("m.tfm") + " --frame " + Root("huge.png") +
                       " --reference " + Root("d/bubble/reference.png"));
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_THAT(r.err, HasSubstr("tactfunc fit: error: --frame: " + Root("huge.png") +
                               ": expected a frame of at most 16777216 pixels"));
  EXPECT_THAT(r.err, HasSubstr("100000x100000"));
}

TEST_F(ReliabilityCliTest, WithoutItsCodecsModuleAFrameIsRefusedOrTheMissingModuleNamed) {
  if (!fs::exists(std::string(TACTFUNC_BINARY_DIR) + "/lib/libtactfunc_codecs.so")) {
    GTEST_SKIP() << "this build links the codecs in (TACTFUNC_CODECS_MODULE=OFF)";
  }
  const std::string missing = Root("no_codecs.so");
  const std::string env = "TACTFUNC_CODECS_MODULE=" + missing + " ";
  // The header alone refuses an oversized frame: no decoder is needed for that.
  testing_util::WriteText(Root("huge_no_codecs.png"),
                          testing_util::PngHeaderOnly(100000, 100000, 16, 0));
  const Result refused = testing_util::RunShell(
      *root_, env + testing_util::TactfuncPath() + " fit --model " + Root("m.tfm") +
                  " --frame " + Root("huge_no_codecs.png") + " --reference " +
                  Root("d/bubble/reference.png"));
  EXPECT_EQ(refused.exit_code, 1);
  EXPECT_THAT(refused.err, HasSubstr("expected a frame of at most 16777216 pixels"));
  // A command that needs the module (show writes its sheet through it) names the module
  // and the path it tried.
  const Result shown = testing_util::RunShell(
      *root_, env + testing_util::TactfuncPath() + " show " + Root("d") + " --out " +
                  Root("sheet_no_codecs.png"));
  EXPECT_NE(shown.exit_code, 0);
  EXPECT_THAT(shown.err, HasSubstr("cannot load the image and video codecs"));
  EXPECT_THAT(shown.err, HasSubstr(missing + ": no such file"));
  EXPECT_THAT(shown.err, HasSubstr("TACTFUNC_CODECS_MODULE"));
}

TEST_F(ReliabilityCliTest, SynthPrintsASizeBoundAndRefusesAnAbsurdOneUnlessForced) {
  const Result r = Run("synth --out " + Root("huge_synth") + " --frames-per-tool 1000000");
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_THAT(r.err, HasSubstr("synth: 12000000 contacts, 24000000 images: at most"));
  EXPECT_THAT(r.err, HasSubstr("tactfunc synth: error: --frames-per-tool 1000000"));
  EXPECT_THAT(r.err, HasSubstr("--force"));
  EXPECT_FALSE(fs::exists(Root("huge_synth")));
  const Result small = Run("synth --out " + Root("small_synth") +
                           " --frames-per-tool 1 --tools rod --sensors bubble");
  EXPECT_EQ(small.exit_code, 0) << small.err;
  EXPECT_THAT(small.err, HasSubstr("synth: 1 contacts, 1 images: at most 49.0 kB on disk"));
}

TEST_F(ReliabilityCliTest, FlagRangeErrorsReadLikeEveryOtherErrorWithShortNumbers) {
  const Result sigma = Run("fit --model " + Root("m.tfm") + " --frame x.png --sigma inf");
  EXPECT_EQ(sigma.exit_code, 2);
  EXPECT_THAT(sigma.err, HasSubstr("tactfunc fit: error: --sigma: Value inf not in range 0 to "
                                   "1.79769e+308"));
  EXPECT_LT(sigma.err.size(), 200u) << sigma.err;
  const Result threads = Run("encode --model a --data b --out c --threads 999");
  EXPECT_EQ(threads.exit_code, 2);
  EXPECT_THAT(threads.err, HasSubstr("tactfunc encode: error: --threads: Value 999 not in range "
                                     "0 to 256"));
  const Result missing = Run("train --out x.tfm");
  EXPECT_EQ(missing.exit_code, 2);
  EXPECT_THAT(missing.err, HasSubstr("tactfunc train: error: --data is required"));
}

}  // namespace
}  // namespace tactfunc
