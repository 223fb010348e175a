#include <thread>

#include "vofusion/live/live_source.h"

namespace vofusion {

ReplaySource::ReplaySource(std::unique_ptr<FrameSource> source, double speed)
    : source_(std::move(source)), speed_(speed) {}

bool ReplaySource::grab(Frame& frame, mrpt::obs::CObservation3DRangeScan::Ptr& raw, const std::atomic<bool>& stop) {
  raw.reset();
  if (stop || !source_->next(frame)) return false;
  if (!started_) {
    started_ = true;
    first_stamp_ = frame.timestamp;
    wall_start_ = std::chrono::steady_clock::now();
    return true;
  }
  if (speed_ <= 0) return true;
  // Wait until the frame's recorded time has come, in short slices so a stop is seen quickly.
  const auto due = wall_start_ + std::chrono::duration_cast<std::chrono::steady_clock::duration>(
                                     std::chrono::duration<double>((frame.timestamp - first_stamp_) / speed_));
  while (!stop) {
    const auto now = std::chrono::steady_clock::now();
    if (now >= due) break;
    std::this_thread::sleep_for(std::min<std::chrono::steady_clock::duration>(due - now, std::chrono::milliseconds(50)));
  }
  return !stop;
}

}  // namespace vofusion
