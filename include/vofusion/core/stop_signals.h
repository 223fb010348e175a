#pragma once
// Ctrl-C and SIGTERM (a batch system's time limit, Slurm's scancel) as a request to stop cleanly:
// the first stop request (a signal, or requestStop(): vofusion-grab's window closed) sets the stop
// flag (a signal also prints "stopping after the frame in hand ..." on stderr at once), and the app
// finishes the frame in hand and writes what it has; a signal after that kills at
// once, as without a handler. A stop signal within kSameRequestSeconds of the one that asked, where
// either was sent by a process, is the same request delivered twice, not a second one: a batch system
// signals the job's processes, a terminal's Ctrl-C reaches batch-job and vofusion alike, and batch-job
// passes it on (as SIGTERM). A second Ctrl-C from the terminal after a first kills however soon it comes.
// For long-running apps (vofusion, vofusion-grab, rgbd-odometry, tum2rawlog, rgbd-simulate), installed
// from main's thread once the command line is read:
//
//   installStopSignals();
//   while (true) {
//     if (!source.next(frame)) break;                             // first: a stop during the last
//     if (stopRequested()) { stopped_by = stopSignal(); break; }  // frame is no interruption
//     ...
//   }
//   return stopped_by ? 128 + stopped_by : 0;   // the shell's code for the signal: 130, 143
#include <atomic>
#include <string>

namespace vofusion {

inline constexpr double kSameRequestSeconds = 1.0;

// `stopping`: what the first signal says at once, when not the default "stopping after the frame in
// hand; what was done is written (Ctrl-C again to kill)" (a string that outlives the run). SIGPIPE is
// ignored from here on: a closed stderr pipe (tee gone with the Ctrl-C) is a failed write, not the end.
void installStopSignals(const char* stopping = nullptr);
// The `stopping` of apps whose part-done work is no result (a conversion, a rendering).
inline constexpr char kStoppingWithNothingWritten[] = "\nstopping; nothing is written (Ctrl-C again to kill)\n";
// What the first signal says while this lives (a string that outlives it); the earlier words after
// it. For a step whose part-done work is no result inside an app whose is (vofusion's first run
// rendering the default recording). Main's thread only, one at a time.
class ScopedStoppingMessage {
 public:
  explicit ScopedStoppingMessage(const char* stopping);
  ~ScopedStoppingMessage();
  ScopedStoppingMessage(const ScopedStoppingMessage&) = delete;
  ScopedStoppingMessage& operator=(const ScopedStoppingMessage&) = delete;

 private:
  const char* earlier_;
};
// True once a stop was asked for, by a signal or by requestStop().
bool stopRequested();
// The flag itself, for loops on other threads that poll it (live/live_loop.h's LiveHooks::stop).
const std::atomic<bool>& stopFlag();
void requestStop();
// SIGINT or SIGTERM when a signal made the stop request; 0 otherwise.
int stopSignal();
const char* signalName(int signal);  // "SIGINT", "SIGTERM"
// A stop that leaves nothing written: "<app>: stopped (SIGTERM)<when>: nothing written[; <more>]" on
// stderr; returns the exit code, 128 + the signal.
int stoppedWithNothingWritten(const char* app, const std::string& when, const std::string& more = "");
inline int stoppedBeforeTheFirstFrame(const char* app, const std::string& more = "") {
  return stoppedWithNothingWritten(app, " before the first frame", more);
}

}  // namespace vofusion
