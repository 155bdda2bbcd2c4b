// Copyright 2026 The tactfunc Authors.
//
// tactfunc bench video-memory: the peak resident memory of reading a long video. Writes
// MJPG .avi videos of synthetic GelSight-like frames (a lit gel with a moving, pressing
// blob) and runs, as child processes measured with wait4's ru_maxrss,
//
//   tactfunc --version                                       (the program's baseline)
//   tactfunc info VIDEO
//   tactfunc encode --model M --data VIDEO --labels L --split test --out F.tfs
//   tactfunc recon --model M --functaset F.tfs --data VIDEO --labels L --out DIR
//
// where L puts every --test-every'th frame in the test split (encode and recon read
// those frames, spread over the whole video). --tactfunc measures another build of the
// program; this one writes the videos either way.
//
//   tactfunc bench video-memory [--frames 225,2000] [--rows 480] [--cols 640]
//       [--model models/pretrained/default.tfm] [--tactfunc BIN] [--work DIR] [--json]
#include <fcntl.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <iostream>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "CLI/CLI.hpp"
#include "apps/bench.h"
#include "apps/command.h"
#include "estimation/data/codecs.h"
#include "estimation/data/image_io.h"

namespace tactfunc::apps {
namespace {

namespace fs = std::filesystem;

struct VideoMemoryFlags {
  std::vector<int> frames = {225, 2000};
  int rows = 480;
  int cols = 640;
  int test_every = 10;
  std::string model = "models/pretrained/default.tfm";
  std::string tactfunc;  // "" = this program
  std::string work;      // "" = a fresh folder under the temporary directory
  bool json = false;
};

// Frame `index` of the synthetic video: a smooth lit background and a bright blob that
// circles the image while it presses in and out, 8-bit BGR.
cv::Mat SyntheticFrame(int index, int rows, int cols) {
  cv::Mat frame(rows, cols, CV_8UC3);
  const double angle = 0.05 * index;
  const double cx = cols * (0.5 + 0.25 * std::cos(angle));
  const double cy = rows * (0.5 + 0.25 * std::sin(angle));
  const double radius = 0.08 * std::min(rows, cols);
  const double press = 0.5 + 0.5 * std::sin(0.21 * index);
  for (int r = 0; r < rows; ++r) {
    auto* row = frame.ptr<cv::Vec3b>(r);
    for (int c = 0; c < cols; ++c) {
      const double d2 = ((c - cx) * (c - cx) + (r - cy) * (r - cy)) / (radius * radius);
      const double blob = 90.0 * press * std::exp(-d2);
      const double base = 60.0 + 50.0 * c / cols + 30.0 * r / rows;
      // A fixed dot pattern, like the markers printed on a gel.
      const double dots = ((r / 12 + c / 12) % 2 == 0 && r % 12 < 3 && c % 12 < 3) ? -40.0 : 0.0;
      row[c] = cv::Vec3b(cv::saturate_cast<uchar>(base + dots + 0.6 * blob),
                         cv::saturate_cast<uchar>(base + dots + blob),
                         cv::saturate_cast<uchar>(base + 20 + dots + 0.8 * blob));
    }
  }
  return frame;
}

void WriteVideo(const std::string& path, int frames, int rows, int cols) {
  codecs::VideoWriter writer;
  if (!writer.open(path, "MJPG", 30.0, rows, cols)) {
    throw std::runtime_error(path + ": this OpenCV build cannot write MJPG .avi");
  }
  for (int i = 0; i < frames; ++i) writer.write(SyntheticFrame(i, rows, cols));
}

// labels.csv putting frames 000001.. of a video of `frames` frames (frame 0 is the
// reference) in the test split every `every`'th frame, train otherwise, unlabelled.
void WriteSplitLabels(const std::string& path, int frames, int every) {
  std::string text = "frame,sensor,tool,x_m,y_m,yaw_rad,depth_m,split\n";
  char id[32];
  for (int i = 1; i < frames; ++i) {
    std::snprintf(id, sizeof(id), "%06d", i);
    text += std::string(id) + ",gelslim,,,,,," + (i % every == 0 ? "test" : "train") + "\n";
  }
  WriteFileAtomically(path, text);
}

struct Measured {
  int exit_code = -1;
  double peak_rss_mb = 0;
  double seconds = 0;
};

// Runs `argv` as a child process with its output in `log`, and measures it.
Measured RunMeasured(const std::vector<std::string>& argv, const std::string& log) {
  std::vector<char*> args;
  for (const std::string& a : argv) args.push_back(const_cast<char*>(a.c_str()));
  args.push_back(nullptr);
  const auto start = std::chrono::steady_clock::now();
  const pid_t pid = fork();
  if (pid < 0) throw std::runtime_error("bench video-memory: fork failed");
  if (pid == 0) {
    const int fd = open(log.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
    if (fd >= 0) {
      dup2(fd, STDOUT_FILENO);
      dup2(fd, STDERR_FILENO);
    }
    execv(args[0], args.data());
    _exit(127);
  }
  int status = 0;
  struct rusage usage {};
  if (wait4(pid, &status, 0, &usage) < 0) {
    throw std::runtime_error("bench video-memory: wait4 failed");
  }
  Measured m;
  m.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  m.exit_code = WIFEXITED(status) ? WEXITSTATUS(status) : 128 + WTERMSIG(status);
  m.peak_rss_mb = usage.ru_maxrss / 1024.0;  // kB on Linux
  return m;
}

void RunVideoMemoryBench(const VideoMemoryFlags& flags) {
  const std::string self = fs::read_symlink("/proc/self/exe").string();
  const std::string measured = flags.tactfunc.empty() ? self : fs::absolute(flags.tactfunc).string();
  const std::string work =
      flags.work.empty()
          ? (fs::temp_directory_path() / ("tactfunc_video_memory_" + std::to_string(getpid())))
                .string()
          : flags.work;
  fs::create_directories(work);
  const std::string model = fs::absolute(flags.model).string();
  std::cout << "bench video-memory: " << measured << ", videos " << flags.rows << "x"
            << flags.cols << " MJPG in " << work << "\n";
  nlohmann::json runs = nlohmann::json::array();
  auto report = [&](const std::string& name, int frames, const Measured& m) {
    std::printf("  %-8s %6d frames  exit %d  peak RSS %8.1f MB  %7.1f s\n", name.c_str(), frames,
                m.exit_code, m.peak_rss_mb, m.seconds);
    std::fflush(stdout);
    runs.push_back({{"command", name},
                    {"frames", frames},
                    {"exit_code", m.exit_code},
                    {"peak_rss_mb", m.peak_rss_mb},
                    {"seconds", m.seconds}});
  };
  report("--version", 0, RunMeasured({measured, "--version"}, work + "/version.log"));
  for (int frames : flags.frames) {
    const std::string stem = work + "/v" + std::to_string(frames) + "_" +
                             std::to_string(flags.rows) + "x" + std::to_string(flags.cols);
    const std::string video = stem + ".avi";
    if (!fs::exists(video)) WriteVideo(video, frames, flags.rows, flags.cols);
    WriteSplitLabels(stem + "_labels.csv", frames, flags.test_every);
    report("info", frames, RunMeasured({measured, "info", video}, stem + "_info.log"));
    fs::remove(stem + ".tfs");
    report("encode", frames,
           RunMeasured({measured, "encode", "--model", model, "--data", video, "--labels",
                        stem + "_labels.csv", "--split", "test", "--out", stem + ".tfs"},
                       stem + "_encode.log"));
    fs::remove_all(stem + "_recon");
    report("recon", frames,
           RunMeasured({measured, "recon", "--model", model, "--functaset", stem + ".tfs",
                        "--data", video, "--labels", stem + "_labels.csv", "--out",
                        stem + "_recon"},
                       stem + "_recon.log"));
  }
  std::cout << "  (logs of each command in " << work << ")\n";
  if (flags.json) {
    EmitJson({{"bench", "video-memory"},
              {"tactfunc", measured},
              {"rows", flags.rows},
              {"cols", flags.cols},
              {"runs", runs},
              {"machine", MachineDescription()}});
  }
}

}  // namespace

void RegisterVideoMemoryBenchmark(CLI::App* bench, CommandBody* selected) {
  auto flags = std::make_shared<VideoMemoryFlags>();
  CLI::App* sub = bench->add_subcommand(
      "video-memory",
      "Peak resident memory of info, encode and recon reading long MJPG videos (written "
      "here), each run as a child process.");
  sub->add_option("--frames", flags->frames, "Video lengths in frames (default 225,2000)")
      ->delimiter(',')
      ->check(CLI::Range(2, 1000000));
  sub->add_option("--rows", flags->rows, "Frame height (default 480)")->check(CLI::Range(8, 4096));
  sub->add_option("--cols", flags->cols, "Frame width (default 640)")->check(CLI::Range(8, 4096));
  sub->add_option("--test-every", flags->test_every,
                  "Every n-th frame is encoded and reconstructed (default 10)")
      ->check(CLI::Range(1, 1000000));
  sub->add_option("--model", flags->model,
                  "Model with a gelslim trunk (default models/pretrained/default.tfm)");
  sub->add_option("--tactfunc", flags->tactfunc,
                  "The tactfunc program to measure (default: this one)");
  sub->add_option("--work", flags->work,
                  "Folder for the videos and outputs (default: a new temporary folder); "
                  "videos already there are reused");
  sub->add_flag("--json", flags->json, "Print the figures as one JSON line");
  sub->callback([flags, selected]() { *selected = [flags]() { RunVideoMemoryBench(*flags); }; });
}

}  // namespace tactfunc::apps
