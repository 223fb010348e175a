#include "vofusion/odometry/odometry_source.h"

#include <mrpt/poses/Lie/SE.h>

#include <algorithm>

#include "vofusion/io/external_files.h"
#include "vofusion/io/rawlog.h"

namespace vofusion {

OdometrySource::OdometrySource(const OdometryParams& params, const mrpt::poses::CPose3D& initial_pose)
    : odometry_(params), pose_(initial_pose), pose_at_last_action_(initial_pose) {
  covariance_.setZero();
}

OdometryResult OdometrySource::process(const mrpt::obs::CObservation3DRangeScan& obs) {
  const std::string origin = obs.sensorLabel.empty() ? "observation" : obs.sensorLabel;
  if (!obs.rangeImage_isExternallyStored()) return process(frameFromObservation(obs, origin));
  // An external range image is read checked whole, as RawlogSource reads one (MRPT's load() takes a
  // file cut short as it comes), from a copy: the caller's observation keeps naming its file.
  mrpt::obs::CObservation3DRangeScan checked(obs);
  useExternalRangeImage(checked, obs.rangeImage_getExternalStorageFileAbsolutePath(""));
  loadExternalRangeImage(checked);
  return process(frameFromObservation(checked, origin));
}

namespace {
// `motion` spread evenly over `frames` frames: one frame's share, on the manifold.
mrpt::poses::CPose3D motionPerFrame(const mrpt::poses::CPose3D& motion, std::size_t frames) {
  if (frames <= 1) return motion;
  auto twist = mrpt::poses::Lie::SE<3>::log(motion);
  twist *= 1.0 / double(frames);
  return mrpt::poses::Lie::SE<3>::exp(twist);
}
}  // namespace

OdometryResult OdometrySource::process(const Frame& input) {
  Frame frame = input;  // shallow: images are shared
  frame.index = count_;
  OdometryResult r = odometry_.process(frame);
  times_.merge(r.times);
  timestamp_ = frame.timestamp;
  const mrpt::poses::CPose3D previous = pose_;
  std::size_t frames_since_reference = 1;
  has_increment_ = false;
  if (r.success) {
    // The motion is relative to the odometry's reference, usually (not always) the previous frame.
    const auto ref = recent_poses_.find(r.reference_index);
    const mrpt::poses::CPose3D ref_pose = ref != recent_poses_.end() ? ref->second : previous;
    if (ref != recent_poses_.end() && r.reference_index < count_) frames_since_reference = count_ - r.reference_index;
    pose_ = ref_pose + r.motion;
    // From the pose of the last action, not the last guess: frames that failed write no action, and the
    // actions of a rawlog must add up to the path (they missed each failure's guessed motion).
    increment_ = pose_ - pose_at_last_action_;
    covariance_ = r.covariance;
    has_increment_ = count_ > 0;
    pose_at_last_action_ = pose_;
  } else if (count_ > 0 && !r.started) {
    // No motion is dropped: the frame moves on by one frame's share of the last match's motion (constant
    // velocity); the next
    // frame is matched against the last good one and lands where the odometry says.
    ++failures_;
    if (has_velocity_) pose_ = previous + velocity_;
  }
  // The speed is one frame's motion: the motion from the reference spread over the frames since it. A
  // match against an older reference (after failed frames) puts the pose back where it belongs; the
  // difference to the last guessed pose is the guesses' drift, not a speed.
  if (r.success && count_ > 0) {
    velocity_ = motionPerFrame(r.motion, frames_since_reference);
    has_velocity_ = true;
  }
  recent_poses_[count_] = pose_;
  // The poses of the frames the odometry still holds, however old: it keeps its reference (and its
  // last failed frame) through failed frames, a covered lens. A frame matched after many of them lands
  // from its reference, not where constant velocity has carried the pose.
  const std::vector<std::size_t> held = odometry_.heldFrames();
  for (auto it = recent_poses_.begin(); it != recent_poses_.end();)
    it = std::find(held.begin(), held.end(), it->first) != held.end() ? std::next(it) : recent_poses_.erase(it);
  ++count_;
  return r;
}

std::optional<mrpt::obs::CActionRobotMovement3D> OdometrySource::action() const {
  if (!has_increment_) return std::nullopt;
  return makeOdometryAction(increment_, timestamp_, &covariance_);
}

}  // namespace vofusion
