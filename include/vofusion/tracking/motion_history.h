#pragma once
// The camera's recent path as the tracker predicts from it: the last pose, the poses of the last
// frames by Frame::index (a motion prior's reference is looked up there), and the last motion per
// second for the constant-velocity prediction.
#include <cstddef>
#include <deque>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "vofusion/core/state_archive.h"

namespace vofusion {

// The shortest time between two frames a sensor gives: the fastest RGB-D depth stream (RealSense D4xx at
// 300 fps). Stamps closer than this are the clock's doing, not the camera's: a motion over them is no
// velocity, a turn no turn rate.
constexpr double kShortestFrameInterval = 1.0 / 300.0;  // s

// Motion m scaled to s times its length (rotation angle and translation).
Eigen::Isometry3d scaledMotion(const Eigen::Isometry3d& m, double s);

class MotionHistory {
 public:
  explicit MotionHistory(const Eigen::Isometry3d& pose) : pose_(pose) {}

  const Eigen::Isometry3d& pose() const { return pose_; }
  // Pose of a recent frame (the last kRecent, and those held), nullptr when it has none.
  const Eigen::Isometry3d* poseOf(std::size_t index) const;
  // Frames whose poses stay past the last kRecent (at most kHeld of them) from the next remember() on:
  // the odometry's references, which it keeps however old (a covered lens for a second or more), and
  // a later prior names.
  void hold(std::vector<std::size_t> frames);
  // The last pose moved on by the last motion, scaled to the time since the last tracked frame.
  Eigen::Isometry3d constantVelocity(double timestamp) const;
  // The camera's motion over `offset` seconds at the last motion's velocity (camera frame): where the
  // colour camera was relative to the depth camera when the two were captured `offset` apart.
  Eigen::Isometry3d motionOver(double offset) const;
  // Whether a last motion is known (two tracked frames), and the time since the last tracked frame.
  bool hasMotion() const { return last_motion_dt_ > 0; }
  bool hasLast() const { return have_last_; }
  double lastTimestamp() const { return last_timestamp_; }
  // Frame `index` at `timestamp` was placed at T: measured (tracked, fallen back to the odometry,
  // relocalised) or predicted (moved on at constant velocity). Only measured frames teach the
  // velocity, over the time since the last measured one: learnt from a prediction, the velocity stayed
  // locked to itself, and the first measured frame after it put the whole prediction's error into
  // one frame's motion (a camera that stopped during three predicted frames came back at -3 times
  // its speed).
  void remember(std::size_t index, double timestamp, const Eigen::Isometry3d& T, bool measured = true);
  // The time of the last measured frame (hasLast: of any).
  bool hasMeasured() const { return have_measured_; }
  double lastMeasuredTimestamp() const { return measured_timestamp_; }
  // Placed at T from elsewhere (loop-closed re-fusion): no motion is learnt from it.
  void setPose(const Eigen::Isometry3d& T) { pose_ = T; }
  // A new start at T (a resumed map): no recent frames, no motion.
  void restart(const Eigen::Isometry3d& T);
  // Checkpoints: all of it but the held frames, which the caller hands over again before each frame
  // (Reconstruction calls holdFrames before it tracks a frame).
  void saveState(state::Archive& a) const;
  void loadState(state::Archive& a);

 private:
  static constexpr std::size_t kRecent = 32, kHeld = 16;
  void forgetOld();
  Eigen::Isometry3d pose_;  // camera-to-world of the last frame
  std::deque<std::pair<std::size_t, Eigen::Isometry3d>> recent_;  // oldest first
  std::vector<std::size_t> held_;
  Eigen::Isometry3d last_motion_ = Eigen::Isometry3d::Identity();  // over the last two measured frames
  double last_motion_dt_ = 0.0, last_timestamp_ = 0.0;
  bool have_last_ = false;
  Eigen::Isometry3d measured_pose_ = Eigen::Isometry3d::Identity();  // the last measured frame's
  double measured_timestamp_ = 0.0;
  bool have_measured_ = false;
};

}  // namespace vofusion
