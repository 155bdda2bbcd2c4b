// Copyright 2026 The tactfunc Authors.
#include "apps/interrupt.h"

#include <csignal>
#include <cstdlib>
#include <iostream>

namespace tactfunc::apps {
namespace {

std::atomic<bool> g_interrupt{false};
static_assert(std::atomic<bool>::is_always_lock_free);

extern "C" void OnInterrupt(int) {
  g_interrupt.store(true);
  std::signal(SIGINT, SIG_DFL);  // a second Ctrl-C ends the program at once
}

}  // namespace

InterruptScope::InterruptScope() {
  g_interrupt.store(false);
  previous_ = std::signal(SIGINT, OnInterrupt);
}

InterruptScope::~InterruptScope() { std::signal(SIGINT, previous_); }

std::atomic<bool>& InterruptScope::Flag() { return g_interrupt; }

void ExitInterrupted() {
  std::cout.flush();
  std::exit(130);
}

}  // namespace tactfunc::apps
