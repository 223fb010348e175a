#pragma once
// Keyframes for loop closure: a tracked frame becomes one when the camera has moved or turned enough
// since the last one (or tracking just recovered). A keyframe keeps what a later revisit is verified
// against: its tracked pose, its BRAND descriptors with their 3D points, and a reduced depth image.
#include <cstddef>
#include <deque>
#include <memory>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "vofusion/core/camera.h"
#include "vofusion/core/frame.h"
#include "vofusion/core/state_archive.h"
#include "vofusion/loop/loop_params.h"
#include "vofusion/core/described_keypoints.h"

namespace vofusion::loop {

struct Keyframe {
  std::size_t id = 0;           // 0, 1, 2, ... in creation order (the pose graph's node)
  std::size_t frame_index = 0;  // Frame::index
  double timestamp = 0.0;       // s
  Eigen::Isometry3d tracked = Eigen::Isometry3d::Identity();  // camera-to-world, as tracked
  double path_length = 0.0;     // m the camera travelled from the first frame to this one
  bool after_poor_tracking = false;  // frames since the previous keyframe (this one included) were lost,
                                     // predicted, fell back or strained
  std::shared_ptr<const DescribedKeypoints> features;
  cv::Mat depth;                // CV_16U, kDepthUnitsPerMetre, 1/keyframe_downsample resolution (nearest reading)
  CameraIntrinsics camera;      // of `depth`
  static constexpr double kDepthUnitsPerMetre = 5000.0;  // TUM's: 0.2 mm steps up to 13 m, half a float's memory
  cv::Mat depthMetres() const;  // CV_32F m, 0 where no reading
};

// The keyframe of a frame: depth reduced by `downsample` (every n-th reading, never averaged across
// depth jumps) and its intrinsics scaled to match.
Keyframe makeKeyframe(std::size_t id, const Frame& frame, const Eigen::Isometry3d& tracked, double path_length,
                      std::shared_ptr<const DescribedKeypoints> features, int downsample);

// Decides which frames become keyframes, and measures the path length on the way.
class KeyframeSelector {
 public:
  explicit KeyframeSelector(const LoopParams& params) : params_(params) {}
  // Every frame in order; true when this one should become a keyframe. Frames not well tracked
  // (lost, predicted, fallback, a pose that is not finite) never do; the first well-tracked frame after
  // them always does.
  // Strained frames (tracked, but with an ICP residual that stands out) do by motion as any other: they
  // are where a revisit's drift comes out, and a loop from one of them observes it there. Their edge
  // to the previous keyframe is weak, as one across frames not well tracked.
  bool next(const Eigen::Isometry3d& pose, bool well_tracked, bool strained = false);
  double pathLength() const { return path_; }
  // The keyframe just made follows frames that were not well tracked, or strained ones (this one
  // included): its edge to the previous one is weak.
  bool lastAfterPoorTracking() const { return last_after_poor_; }
  // Checkpoints: where the last keyframe and the last pose were, and the path so far.
  void saveState(state::Archive& a) const;
  void loadState(state::Archive& a);

 private:
  LoopParams params_;
  Eigen::Isometry3d last_keyframe_ = Eigen::Isometry3d::Identity(), last_pose_ = Eigen::Isometry3d::Identity();
  bool have_keyframe_ = false, have_pose_ = false, recovering_ = false, last_after_poor_ = false;
  bool strained_since_keyframe_ = false;
  double path_ = 0.0;
};

}  // namespace vofusion::loop
