// Copyright 2026 The tactfunc Authors.
//
// A progress bar for long work: "label [#######     ] 120/240  53.1/s  ETA 0:02".
// Drawn on stderr only when stderr is a terminal and CI is not set (so logs and CI stay
// quiet); redrawn at most 10 times a second. Tick() is thread-safe.
//
// With Lines::kWhenNotDrawn, where no bar is drawn (a log file, a pipe, CI) it writes
// plain progress lines instead, one per 10 % of the work or per 10 s, whichever comes
// first, and a last one at Finish:
//   "encode: DONE/TOTAL frames (P%), R frames/s, ETA T"
// (the long commands use them -- synth, encode, eval, export, train-pose's refit,
// train-generator, eval-generator: minutes without a word otherwise).
#ifndef TACTFUNC_APPS_PROGRESS_BAR_H_
#define TACTFUNC_APPS_PROGRESS_BAR_H_

#include <atomic>
#include <chrono>
#include <cstdint>
#include <mutex>
#include <string>

namespace tactfunc::apps {

class ProgressBar {
 public:
  enum class Lines { kNever, kWhenNotDrawn };
  // `total` units of work; `unit` names them in the rate ("frames").
  ProgressBar(std::string label, std::int64_t total, std::string unit = "it",
              Lines lines = Lines::kNever);
  ~ProgressBar();
  ProgressBar(const ProgressBar&) = delete;
  ProgressBar& operator=(const ProgressBar&) = delete;

  void Tick(std::int64_t n = 1);
  // Extra text after the ETA, e.g. "loss 1.2e-3  psnr 31.4 dB".
  void SetStatus(const std::string& status);
  // Draws the final state and a newline (once).
  void Finish();

  std::int64_t done() const { return done_.load(); }
  double ElapsedSeconds() const;
  // True when bars are drawn: stderr is a tty and the CI variable is unset.
  static bool Enabled();

 private:
  void Draw(bool force);
  // A progress line when a new tenth of the work is done, 10 s have passed, or `last`.
  void Line(bool last);

  std::string label_;
  std::int64_t total_;
  std::string unit_;
  std::atomic<std::int64_t> done_{0};
  std::chrono::steady_clock::time_point start_;
  std::chrono::steady_clock::time_point last_draw_;
  std::string status_;
  std::mutex mutex_;
  bool enabled_;
  bool lines_;  // progress lines instead of the bar (Lines::kWhenNotDrawn, no bar)
  bool finished_ = false;
  std::int64_t last_line_tenth_ = 0;
  std::chrono::steady_clock::time_point last_line_;
};

// "1:02:03" or "2:03".
std::string FormatDuration(double seconds);

}  // namespace tactfunc::apps

#endif  // TACTFUNC_APPS_PROGRESS_BAR_H_
