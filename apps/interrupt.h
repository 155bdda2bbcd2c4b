// Copyright 2026 The tactfunc Authors.
//
// Ctrl-C for long commands that stop cleanly (encode, train-generator): while an
// InterruptScope lives, the first SIGINT only sets a flag the command polls between units
// of work (it then writes what it has, atomically, and says how to resume); a second
// SIGINT ends the program at once (the default action). One scope at a time.
#ifndef TACTFUNC_APPS_INTERRUPT_H_
#define TACTFUNC_APPS_INTERRUPT_H_

#include <atomic>

namespace tactfunc::apps {

class InterruptScope {
 public:
  InterruptScope();  // clears the flag and installs the handler
  ~InterruptScope();  // restores the previous handler
  InterruptScope(const InterruptScope&) = delete;
  InterruptScope& operator=(const InterruptScope&) = delete;

  // The flag, set by the first SIGINT (lock-free, so a signal handler may store it).
  static std::atomic<bool>& Flag();
  static bool Requested() { return Flag().load(); }

 private:
  void (*previous_)(int);
};

// Ends an interrupted command once it has said what it kept: flushes stdout and exits
// with 130 (128 + SIGINT, as shells report an interrupted program).
[[noreturn]] void ExitInterrupted();

}  // namespace tactfunc::apps

#endif  // TACTFUNC_APPS_INTERRUPT_H_
