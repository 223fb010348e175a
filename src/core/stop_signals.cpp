#include "vofusion/core/stop_signals.h"

#include <csignal>

namespace vofusion {

namespace {

std::atomic<bool> g_stop{false};
std::atomic<int> g_signal{0};

// Only async-signal-safe work: lock-free atomics, signal() and raise().
void onStopSignal(int signal) {
  if (g_signal.exchange(signal) == 0) {
    g_stop = true;
    return;
  }
  std::signal(signal, SIG_DFL);  // the second: what the signal does without a handler, now
  std::raise(signal);
}

}  // namespace

void installStopSignals() {
  std::signal(SIGINT, onStopSignal);  // also where a background job started with SIGINT ignored
  std::signal(SIGTERM, onStopSignal);
}

bool stopRequested() { return g_stop.load(); }
const std::atomic<bool>& stopFlag() { return g_stop; }
void requestStop() { g_stop = true; }
int stopSignal() { return g_signal.load(); }
const char* signalName(int signal) { return signal == SIGTERM ? "SIGTERM" : signal == SIGINT ? "SIGINT" : "a signal"; }

}  // namespace vofusion
