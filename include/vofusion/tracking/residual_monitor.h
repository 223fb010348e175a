#pragma once
#include <cstddef>
#include <deque>
#include <vector>

#include "vofusion/core/state_archive.h"

namespace vofusion {

// Tells frames whose ICP residual stands out from the run's recent ones. When the camera comes back
// to a place the map still holds (the volume, or bricks taken back from the world model) after some
// drift, ICP meets two versions of it: its residual rises for a few dozen frames and the tracker
// takes the drift out there, in a jump. Such frames count as poorly tracked, so that a loop puts its
// correction at that jump instead of spreading it over the whole path.
class ResidualMonitor {
 public:
  static constexpr std::size_t kWindow = 90;  // frames (3 s at 30 Hz): longer than such a jump
  static constexpr std::size_t kMinSamples = 15;
  explicit ResidualMonitor(double ratio) : ratio_(ratio) {}
  // rms: this frame's ICP residual RMS (m); 0 when no ICP ran (never strained). True when it is over
  // `ratio` x the median of the previous kWindow frames' residuals. ratio 0: never.
  bool strained(double rms);
  // Checkpoints: the recent residuals.
  void saveState(state::Archive& a) const { a << recent_; }
  void loadState(state::Archive& a) { a >> recent_; }

 private:
  double ratio_;
  std::deque<double> recent_;
  std::vector<double> sorted_;  // scratch for the median (no allocation per frame)
};

}  // namespace vofusion
