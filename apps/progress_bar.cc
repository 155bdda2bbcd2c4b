// Copyright 2026 The tactfunc Authors.
#include "apps/progress_bar.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <cstdlib>

namespace tactfunc::apps {

bool ProgressBar::Enabled() {
  const char* ci = std::getenv("CI");
  if (ci != nullptr && *ci != '\0') return false;
  return isatty(fileno(stderr)) != 0;
}

ProgressBar::ProgressBar(std::string label, std::int64_t total, std::string unit, Lines lines)
    : label_(std::move(label)),
      total_(total),
      unit_(std::move(unit)),
      start_(std::chrono::steady_clock::now()),
      last_draw_(start_),
      enabled_(Enabled()),
      lines_(!enabled_ && lines == Lines::kWhenNotDrawn),
      last_line_(start_) {}

ProgressBar::~ProgressBar() { Finish(); }

double ProgressBar::ElapsedSeconds() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_)
      .count();
}

void ProgressBar::Tick(std::int64_t n) {
  done_.fetch_add(n);
  if (enabled_) Draw(false);
  if (lines_) Line(false);
}

void ProgressBar::Line(bool last) {
  std::unique_lock<std::mutex> lock(mutex_, std::defer_lock);
  if (last) {
    lock.lock();
  } else if (!lock.try_lock()) {
    return;
  }
  if (finished_) return;
  const auto now = std::chrono::steady_clock::now();
  const std::int64_t done = done_.load();
  const std::int64_t tenth = total_ > 0 ? std::min<std::int64_t>(10, done * 10 / total_) : 0;
  if (!last && tenth <= last_line_tenth_ && now - last_line_ < std::chrono::seconds(10)) return;
  last_line_tenth_ = std::max(last_line_tenth_, tenth);
  last_line_ = now;
  const double elapsed = std::chrono::duration<double>(now - start_).count();
  const double rate = elapsed > 0 ? done / elapsed : 0.0;
  const double percent = total_ > 0 ? std::min(100.0, 100.0 * done / total_) : 0.0;
  if (last) {
    std::fprintf(stderr, "%s: %lld/%lld %s (%.0f%%) in %s, %.1f %s/s%s%s\n", label_.c_str(),
                 static_cast<long long>(done), static_cast<long long>(total_), unit_.c_str(),
                 percent, FormatDuration(elapsed).c_str(), rate, unit_.c_str(),
                 status_.empty() ? "" : ", ", status_.c_str());
    finished_ = true;
  } else {
    const double eta = rate > 0 ? (total_ - done) / rate : 0.0;
    std::fprintf(stderr, "%s: %lld/%lld %s (%.0f%%), %.1f %s/s, ETA %s%s%s\n", label_.c_str(),
                 static_cast<long long>(done), static_cast<long long>(total_), unit_.c_str(),
                 percent, rate, unit_.c_str(), FormatDuration(eta).c_str(),
                 status_.empty() ? "" : ", ", status_.c_str());
  }
  std::fflush(stderr);
}

void ProgressBar::SetStatus(const std::string& status) {
  std::lock_guard<std::mutex> lock(mutex_);
  status_ = status;
}

void ProgressBar::Finish() {
  if (lines_) {
    Line(true);
    return;
  }
  if (!enabled_ || finished_) return;
  Draw(true);
  std::lock_guard<std::mutex> lock(mutex_);
  if (!finished_) {
    std::fputc('\n', stderr);
    finished_ = true;
  }
}

void ProgressBar::Draw(bool force) {
  std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
  if (!lock.owns_lock() || finished_) return;
  const auto now = std::chrono::steady_clock::now();
  if (!force && now - last_draw_ < std::chrono::milliseconds(100)) return;
  last_draw_ = now;
  const std::int64_t done = done_.load();
  const double elapsed = std::chrono::duration<double>(now - start_).count();
  const double rate = elapsed > 0 ? done / elapsed : 0.0;
  const double fraction =
      total_ > 0 ? std::min(1.0, static_cast<double>(done) / total_) : 0.0;
  constexpr int kWidth = 28;
  const int filled = static_cast<int>(std::lround(fraction * kWidth));
  std::string bar(filled, '#');
  bar.append(kWidth - filled, ' ');
  const double eta = rate > 0 ? (total_ - done) / rate : 0.0;
  std::fprintf(stderr, "\r%s [%s] %lld/%lld  %.1f %s/s  ETA %s  %s\x1b[K",
               label_.c_str(), bar.c_str(), static_cast<long long>(done),
               static_cast<long long>(total_), rate, unit_.c_str(),
               FormatDuration(eta).c_str(), status_.c_str());
  std::fflush(stderr);
}

std::string FormatDuration(double seconds) {
  if (!std::isfinite(seconds) || seconds < 0) seconds = 0;
  long s = std::lround(seconds);
  char buffer[32];
  if (s >= 3600) {
    std::snprintf(buffer, sizeof(buffer), "%ld:%02ld:%02ld", s / 3600, (s / 60) % 60,
                  s % 60);
  } else {
    std::snprintf(buffer, sizeof(buffer), "%ld:%02ld", s / 60, s % 60);
  }
  return buffer;
}

}  // namespace tactfunc::apps
