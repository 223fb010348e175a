#pragma once
// Ctrl-C and SIGTERM (a batch system's time limit, Slurm's scancel) as a request to stop cleanly:
// the first sets the stop flag and the app finishes the frame in hand and writes what it has; the
// second kills at once, as without a handler. For long-running apps (vofusion, vofusion-grab,
// rgbd-odometry), installed from main's thread once the command line is read:
//
//   installStopSignals();
//   while (!stopRequested() && source.next(frame)) ...
//   return stopSignal() ? 128 + stopSignal() : 0;   // the shell's code for the signal: 130, 143
#include <atomic>

namespace vofusion {

void installStopSignals();
// True once a stop was asked for, by a signal or by requestStop() (a closed window).
bool stopRequested();
// The flag itself, for loops on other threads that poll it (live/live_loop.h's LiveHooks::stop).
const std::atomic<bool>& stopFlag();
void requestStop();
// SIGINT or SIGTERM when a signal asked for the stop; 0 otherwise.
int stopSignal();
const char* signalName(int signal);  // "SIGINT", "SIGTERM"

}  // namespace vofusion
