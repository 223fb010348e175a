#pragma once
// Geometric verification of a loop candidate, as the issue and RGB-D SLAM systems do it: the two
// keyframes' descriptors matched (cross-checked Hamming), a RANSAC rigid motion on their 3D points
// (the odometry's fit), then ICP of the two reduced depth images from that motion; and a
// plausibility test: the loop may correct the tracked relative pose by no more than the drift the
// path between the two keyframes could have gathered (a look-alike place farther away is refused).
#include <cstddef>
#include <list>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "vofusion/registration/preprocess.h"

#include "vofusion/loop/keyframe.h"
#include "vofusion/loop/loop_params.h"

namespace vofusion::loop {

struct LoopCheck {
  bool accepted = false;
  std::string reason;            // why not, when !accepted ("too few inliers", "ICP overlap", ...)
  int matches = 0, inliers = 0;  // descriptor matches, RANSAC inliers
  double icp_overlap = 0.0;      // ICP inliers / valid pixels
  double icp_rms = 0.0;          // m
  double icp_condition = 0.0;    // smallest / largest eigenvalue of the ICP system (depth-scaled)
  Eigen::Isometry3d T_old_new = Eigen::Isometry3d::Identity();  // the newer keyframe in the older's camera frame
  // Of T_old_new, in the pose graph's order (GraphEdge: translation, then rotation vector), set on
  // acceptance: the same on the three translation axes and on the three rotation axes, so the order
  // and frame of the axes do not matter. Anything per axis needs converting from a fit's (x y z yaw
  // pitch roll) first.
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Identity();
  double correction_m = 0.0, correction_deg = 0.0;  // measured vs tracked relative pose
};

// The ICP pyramids (filtered depth, vertices, normals at two levels) of the keyframes verified last.
// A revisit verifies consecutive keyframes against the same older ones, and one keyframe against up to
// `candidates` places: each pyramid is made once while it is among the newest `capacity` used.
class PyramidCache {
 public:
  explicit PyramidCache(std::size_t capacity) : capacity_(capacity) {}
  // Keyed by keyframe id: a keyframe's depth never changes once made.
  const std::vector<fusion::DepthLevel>& of(const Keyframe& k);
  std::size_t hits() const { return hits_; }
  std::size_t misses() const { return misses_; }

 private:
  std::size_t capacity_, hits_ = 0, misses_ = 0;
  std::list<std::pair<std::size_t, std::vector<fusion::DepthLevel>>> newest_first_;
};

LoopCheck verifyLoop(const Keyframe& older, const Keyframe& newer, const LoopParams& params, PyramidCache& pyramids);
// The same features and ICP for relocalisation, without the drift bound (the view's own pose is what
// is sought) nor the overlap bound (the view is usually a step from the keyframe). The tracker then
// refines the pose against the map; where its ICP rejects, the frame keeps this pose as a fallback
// (fused as fallbacks are), so these checks are the placement's only proof. T_old_new: the view in the
// keyframe's camera frame.
LoopCheck verifyRelocalisation(const Keyframe& keyframe, const Keyframe& view, const LoopParams& params,
                               PyramidCache& pyramids);

// Translation (m) and rotation (degrees) of the pose difference a^-1 b.
std::pair<double, double> poseDifference(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b);

}  // namespace vofusion::loop
