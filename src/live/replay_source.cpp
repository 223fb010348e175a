#include "vofusion/live/live_source.h"

#include <algorithm>
#include <cstdio>
#include <string>
#include <thread>

#include "vofusion/core/progress.h"  // printWarning

namespace vofusion {

namespace {
// A recording's clock may jump (NTP setting a robot's clock without a real-time clock mid-recording)
// or step back: the play then goes on as if the frames were this far apart, instead of sleeping for
// the jump (or for ever: a wait past 2^63 ns overflows).
constexpr double kLongestGap = 1.0;  // s of recorded time (the warning says "1 s")
}  // namespace

ReplaySource::ReplaySource(std::unique_ptr<FrameSource> source, double speed)
    : source_(std::move(source)), speed_(speed) {}

bool ReplaySource::grab(Frame& frame, mrpt::obs::CObservation3DRangeScan::Ptr& raw, const std::atomic<bool>& stop) {
  raw.reset();
  if (stop || !source_->next(frame)) return false;
  if (!started_) {
    started_ = true;
    first_stamp_ = last_stamp_ = frame.timestamp;
    wall_start_ = std::chrono::steady_clock::now();
    return true;
  }
  const double gap = frame.timestamp - last_stamp_;
  if (!(gap >= 0 && gap <= kLongestGap)) {
    cut_ += gap - std::clamp(gap, 0.0, kLongestGap);
    char what[160];
    std::snprintf(what, sizeof what, ": the recording's clock jumps by %.3f s at frame %zu (played as %s)", gap, frame.index,
                  gap > 0 ? "1 s" : "no wait");
    printWarning(name() + what);
  }
  last_stamp_ = frame.timestamp;
  if (speed_ <= 0) return true;
  // Wait until the frame's recorded time has come, in short slices so a stop is seen quickly.
  // Held below a wait the clock's nanoseconds overflow at (2^63 ns, 292 years): a library caller's
  // speed of 1e-12 (the options refuse it) played every frame at once.
  const double wait = std::min((frame.timestamp - first_stamp_ - cut_) / speed_, 1e9);
  const auto due = wall_start_ + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                     std::chrono::duration<double>(wait));
  while (!stop) {
    const auto now = std::chrono::steady_clock::now();
    if (now >= due) break;
    std::this_thread::sleep_for(std::min<std::chrono::steady_clock::duration>(due - now, std::chrono::milliseconds(50)));
  }
  return !stop;
}

}  // namespace vofusion
