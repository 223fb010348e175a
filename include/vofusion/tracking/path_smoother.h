#pragma once
// The tracked path's camera centres smoothed under a constant-velocity motion model (issue 30: the
// 50 ms RPE's tail). A frame's pose is tracked against a map averaged over many frames, so its error
// is mostly its own (rotation and translation trading off along the same image motion) and the next
// frame does not inherit it: the path jitters by millimetres from frame to frame while the camera,
// a body with mass, does not. Each run of measured frames is smoothed whole (a fixed-interval
// smoother: every centre from the frames before and after it), orientations are kept as tracked.
//
// The two noise levels come from the path itself, not from a table: of the constant-velocity
// prediction errors e_i (second differences), white measurement noise sigma_m adds 6 sigma_m^2 to
// their variance and -4 sigma_m^2 to the covariance of neighbours (at equal frame intervals; the
// estimate uses each pair's own coefficients), acceleration noise adds to the variance only (Mehra's
// innovation correlation). One noise level per recording: squared sums, so a few large errors raise
// it for the whole path.
// bench/results/2026-12-02-path-smoothing.md.
//
//   PathSmoothing how;
//   Trajectory smoothed = smoothPath(tracked, measured, &how);
#include <cstddef>
#include <vector>

#include "vofusion/core/trajectory.h"

namespace vofusion {

struct PathNoise {
  double measurement = 0.0;   // m, sigma of a tracked centre
  double acceleration = 0.0;  // m, sigma of the constant-velocity prediction error over one frame interval
  double interval = 0.0;      // s, the median frame interval the two refer to
  std::size_t pairs = 0;      // neighbouring prediction errors the estimate rests on
  bool smoothed() const { return measurement > 0.0 && acceleration > 0.0; }
};

// A path's smoothing as a run reports it: the noise levels, and how far the centres moved.
struct PathSmoothing {
  PathNoise noise;
  double mean_shift = 0.0, max_shift = 0.0;  // m
};

// The noise levels of the measured frames' centres. Too few pairs, or no negative correlation (no
// white noise to remove): measurement = 0, and smoothPath leaves the path as it is.
PathNoise estimatePathNoise(const Trajectory& path, const std::vector<bool>& measured);

// Every run of consecutive measured frames (at least 3) with its centres smoothed by least squares:
// sum |c_i - z_i|^2 / sigma_m^2 + sum |e_i|^2 / sigma_i^2, where e_i is centre i+1's error against
// the constant-velocity prediction from i-1 and i, and sigma_i scales sigma_a by the frame intervals
// (a constant acceleration over them). Unmeasured frames (lost, predicted, not fused) keep their pose
// and end a run. out: the noise levels used and how far the centres moved.
Trajectory smoothPath(const Trajectory& path, const std::vector<bool>& measured, PathSmoothing* out = nullptr);

// The same with given noise levels (tests; noise.interval > 0).
Trajectory smoothPathWith(const Trajectory& path, const std::vector<bool>& measured, const PathNoise& noise);

}  // namespace vofusion
