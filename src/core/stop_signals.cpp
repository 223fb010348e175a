#include "vofusion/core/stop_signals.h"

#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdint>
#include <cstdio>
#include <ctime>

namespace vofusion {

namespace {

static_assert(std::atomic<bool>::is_always_lock_free && std::atomic<int>::is_always_lock_free &&
                  std::atomic<std::int64_t>::is_always_lock_free,
              "the handler touches only lock-free atomics");

std::atomic<bool> g_stop{false};
std::atomic<int> g_signal{0};
// When the signal that asked to stop came, and whether it was sent by a process: (ns << 1) | sent, in
// one word, so that a second handler running at once sees both of the first's.
std::atomic<std::int64_t> g_first{0};

std::int64_t monotonicNs() {
  timespec t{};
  clock_gettime(CLOCK_MONOTONIC, &t);  // async-signal-safe
  return std::int64_t(t.tv_sec) * 1000000000 + t.tv_nsec;
}

// Said at once, so that a stop during a long start-up (rendering, a checkpoint read again) is seen.
constexpr char kStopping[] = "\nstopping after the frame in hand; what was done is written (Ctrl-C again to kill)\n";
std::atomic<const char*> g_stopping{kStopping};

// Only async-signal-safe work: lock-free atomics, clock_gettime(), write(), signal() and raise().
// `sent`: by a process (kill, raise, sigqueue: si_code <= 0), not by the terminal's keys (SI_KERNEL).
void onStopSignal(int signal, siginfo_t* info, void*) {
  const bool sent = info && info->si_code <= 0;
  const int saved_errno = errno;  // the interrupted code may be about to read its own (a failed pwrite's)
  struct RestoreErrno {
    int value;
    ~RestoreErrno() { errno = value; }
  } restore{saved_errno};
  const std::int64_t now = monotonicNs();
  // Its time before the flag: a second signal that sees the flag set sees the first one's time too.
  if (!g_stop.load()) {
    std::int64_t unset = 0;
    g_first.compare_exchange_strong(unset, (now << 1) | std::int64_t(sent));
  }
  // The first request's signal before the flag: whoever sees the flag sees which signal it was.
  int none = 0;
  g_signal.compare_exchange_strong(none, signal);
  if (!g_stop.exchange(true)) {  // the first stop request
    const char* said = g_stopping.load();
    std::size_t length = 0;
    while (said[length]) ++length;
    [[maybe_unused]] const ssize_t n = ::write(STDERR_FILENO, said, length);
    return;
  }
  // One request can come twice at once: Slurm signals every process of a job, a terminal's Ctrl-C
  // reaches batch-job too, and batch-job passes it on (an INT as TERM), in either order when both are
  // pending at once. One of the two is sent; a second Ctrl-C pressed after a first pressed is the
  // user's own, and kills however soon it comes (one 0.3 s after the first did nothing, unsaid).
  const std::int64_t first = g_first.load();
  const bool first_sent = (first & 1) != 0;
  if ((sent || first_sent) && now - (first >> 1) < std::int64_t(kSameRequestSeconds * 1e9)) return;
  std::signal(signal, SIG_DFL);  // the second: what the signal does without a handler, now
  std::raise(signal);
}

}  // namespace

void installStopSignals(const char* stopping) {
  static_assert(std::atomic<const char*>::is_always_lock_free);
  if (stopping) g_stopping = stopping;
  struct sigaction on_stop {};
  on_stop.sa_sigaction = onStopSignal;
  on_stop.sa_flags = SA_SIGINFO | SA_RESTART;  // SA_RESTART: as std::signal installs a handler (glibc)
  sigemptyset(&on_stop.sa_mask);
  sigaction(SIGINT, &on_stop, nullptr);  // also where a background job started with SIGINT ignored
  sigaction(SIGTERM, &on_stop, nullptr);
  // "vofusion ... | tee run.log" and Ctrl-C: tee exits too, and a write to stderr after it (the stop
  // message, a progress line) ended the run by SIGPIPE before it wrote what it had. A closed pipe is
  // then only a failed write.
  std::signal(SIGPIPE, SIG_IGN);
}

ScopedStoppingMessage::ScopedStoppingMessage(const char* stopping) : earlier_(g_stopping.exchange(stopping)) {}
ScopedStoppingMessage::~ScopedStoppingMessage() { g_stopping = earlier_; }

bool stopRequested() { return g_stop.load(); }
const std::atomic<bool>& stopFlag() { return g_stop; }
void requestStop() { g_stop = true; }
int stopSignal() { return g_signal.load(); }
int stoppedWithNothingWritten(const char* app, const std::string& when, const std::string& more) {
  std::fprintf(stderr, "%s: stopped (%s)%s: nothing written%s\n", app, signalName(stopSignal()), when.c_str(),
               more.empty() ? "" : ("; " + more).c_str());
  return 128 + stopSignal();
}

const char* signalName(int signal) { return signal == SIGTERM ? "SIGTERM" : signal == SIGINT ? "SIGINT" : "a signal"; }

}  // namespace vofusion
