#pragma once
// The 6D RGB-D odometry as an MRPT odometry source: feed it CObservation3DRangeScans (or Frames), get
// the incremental motion, the accumulated camera pose, and the motion as the action MRPT tools expect
// (CActionRobotMovement3D, estimationMethod = emVisualOdometry, pose change as CPose3DPDFGaussian).
#include <cstddef>
#include <map>
#include <optional>

#include <mrpt/obs/CActionRobotMovement3D.h>
#include <mrpt/obs/CObservation3DRangeScan.h>
#include <mrpt/poses/CPose3D.h>

#include "vofusion/odometry/rgbd_odometry.h"

namespace vofusion {

class OdometrySource {
 public:
  // initial_pose: camera-to-world of the first frame (optical axes).
  explicit OdometrySource(const OdometryParams& params = {}, const mrpt::poses::CPose3D& initial_pose = {});

  // Frames are numbered by this object in arrival order (Frame::index is not trusted).
  OdometryResult process(const Frame& frame);
  // Converts with the io stage's frameFromObservation (throws InputError on unusable observations); an
  // external range image is read checked whole (io/external_files.h), the observation left as it is.
  OdometryResult process(const mrpt::obs::CObservation3DRangeScan& obs);

  // Camera-to-world of the last frame processed. A frame whose motion failed moves on by one frame's
  // share of the last match's motion (constant velocity: a match that spanned k frames gives 1/k of
  // it), flagged by hasIncrement() == false.
  const mrpt::poses::CPose3D& pose() const { return pose_; }
  // Pose change to the last frame (camera-to-camera) from the last frame with an increment: the previous
  // one, or the one before the failed frames between (which have none); valid if hasIncrement(). The
  // increments add up to pose(); their covariance is the match's, not the failed frames' guesses.
  const mrpt::poses::CPose3D& increment() const { return increment_; }
  bool hasIncrement() const { return has_increment_; }
  // The increment as an MRPT action with the odometry's covariance; nullopt if !hasIncrement().
  std::optional<mrpt::obs::CActionRobotMovement3D> action() const;

  const StageTimes& times() const { return times_; }  // accumulated over all frames
  std::size_t frames() const { return count_; }
  std::size_t failures() const { return failures_; }  // frames after the first without a motion

 private:
  RgbdOdometry odometry_;
  mrpt::poses::CPose3D pose_, increment_;
  mrpt::poses::CPose3D pose_at_last_action_;  // where the actions so far add up to
  mrpt::poses::CPose3D velocity_;  // pose change over the last successful frame
  mrpt::math::CMatrixDouble66 covariance_;
  double timestamp_ = 0.0;
  bool has_increment_ = false, has_velocity_ = false;
  std::size_t count_ = 0, failures_ = 0;
  std::map<std::size_t, mrpt::poses::CPose3D> recent_poses_;  // frame number -> pose (the odometry's held frames)
  StageTimes times_;
};

}  // namespace vofusion
