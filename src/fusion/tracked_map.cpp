#include "vofusion/fusion/tracked_map.h"

#include <stdexcept>

#include "vofusion/core/pose_eigen.h"

namespace vofusion {

TrackedMap::TrackedMap(const KinFuParams& params, TrackingMode mode, const mrpt::poses::CPose3D& initial_pose)
    : map_(params, toEigen(initial_pose), {mode != TrackingMode::Odometry, mode == TrackingMode::Joint}),
      tracker_(params, mode, toEigen(initial_pose)) {}

FusionResult TrackedMap::process(const Frame& frame, const fusion::MotionPrior* prior, const FrameGeometry* geometry) {
  FusionResult res = track(frame, prior, geometry);
  fuse(res);
  return res;
}

FusionResult TrackedMap::track(const Frame& frame, const fusion::MotionPrior* prior, const FrameGeometry* geometry) {
  return tracker_.track(frame, prior, geometry, map_);
}

void TrackedMap::fuse(FusionResult& res) {
  const FrameToFuse* frame = tracker_.frameToFuse();
  if (!frame) return;
  StageTimes times;
  res.shifted = map_.fuse(*frame, times);
  res.integrated = frame->integrate;
  tracker_.fused(res.shifted, times);
  res.times.merge(times);
}

bool TrackedMap::integrateAt(const Frame& frame, const mrpt::poses::CPose3D& cam_to_world) {
  const Eigen::Isometry3d pose = toEigen(cam_to_world);
  // No place to fuse it at: NaN marched every ray from min_depth to max_depth a step at a time.
  if (!pose.matrix().allFinite()) return false;
  if (!tracker_.placeAt(frame, pose)) return false;
  StageTimes times;
  tracker_.fused(map_.integrateAt(frame, pose, times), times);
  return true;
}

mrpt::poses::CPose3D TrackedMap::pose() const { return toMrpt(tracker_.pose()); }

void TrackedMap::relocalise(const mrpt::poses::CPose3D& cam_to_world, bool as_prior) {
  const Eigen::Isometry3d pose = toEigen(cam_to_world);
  if (!pose.matrix().allFinite()) throw std::invalid_argument("TrackedMap::relocalise: the pose is not finite");
  tracker_.relocalise(pose, as_prior);
  map_.predictAgain(pose);
}

void TrackedMap::save(const std::string& path) const { map_.save(path, tracker_.pose()); }

// Before the first frame: the tracker starts afresh at the saved pose (as relocalised there).
void TrackedMap::resume(const std::string& path) { tracker_.relocalise(map_.resume(path)); }

void TrackedMap::saveState(std::ostream& os) const {
  tracker_.saveState(os);
  map_.saveState(os);
}

void TrackedMap::loadState(std::istream& is) {
  tracker_.loadState(is);
  map_.loadState(is);
}

KinFuStats TrackedMap::stats() const {
  KinFuStats st;
  static_cast<TrackerStats&>(st) = tracker_.stats();
  static_cast<MapStats&>(st) = map_.stats();
  return st;
}

}  // namespace vofusion
