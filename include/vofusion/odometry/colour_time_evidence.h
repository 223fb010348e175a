#pragma once
// Which velocity moves the keypoints to their depth capture ([odometry] colour_time_velocity auto),
// judged from the recording's own frames: each frame's own velocity at its capture (capture) or the
// fitted interval's mean velocity (interval). Both apply the stamps' colour offsets; they differ in
// the velocity. Each frame compared votes for the one whose fit left the smaller median residual. A
// one-sided sign test at 95 % (normal approximation, from kMinFrames votes on) switches from interval
// to capture, and only as strong a majority the other way switches back. It is checked after every
// vote, so it is a running choice with that margin, not a 95 % test of the recording: where neither
// fits better, 31 % of 300-vote runs pass through capture at some point (a review's simulation), which
// then costs nothing either way. Once the test is settled at
// 99.9 % one frame in kSettledEvery is compared (a comparison costs ~2.5 ms on xyz_first300, ~0.8 on
// rpy_first100: 0.4-0.5 ms per frame on both).
// Measured: capture wins the shake (exact offsets; also with another frame's offsets) and
// xyz_first300, interval rpy_first100 (19 of 63 votes for capture), where capture's ATE is worse.
#include "vofusion/core/state_archive.h"

namespace vofusion {

class ColourTimeEvidence {
 public:
  static constexpr int kMinFrames = 10;        // votes before the first decision (the approximation's floor)
  static constexpr double kSwitchZ = 1.645;    // one-sided 95 %
  static constexpr double kSettledZ = 3.09;    // one-sided 99.9 %
  static constexpr int kSettledEvery = 10;
  static constexpr double kMinOffset = 0.001;  // s; frames whose offsets are all smaller do not vote

  // Whether this frame should be compared (call once per frame).
  bool wantsVote();
  void add(bool capture_fitted_better);
  bool captureFitsBetter() const { return capture_; }  // what the votes say so far (false until shown)
  int compared() const { return compared_; }
  int captureBetter() const { return capture_better_; }
  // Checkpoints: the votes so far.
  void saveState(state::Archive& a) const;
  void loadState(state::Archive& a);

 private:
  double z() const;  // the sign test's statistic: > 0 when capture fits better more often than not
  int compared_ = 0, capture_better_ = 0, skipped_ = 0;
  bool capture_ = false;
};

}  // namespace vofusion
