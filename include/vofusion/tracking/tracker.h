#pragma once
// Which pose each frame gets: KinectFusion's frame-to-model ICP, weighed together with a motion
// prior (the 6D RGB-D odometry's matches) by the tracking mode, against the model a map predicts
// (ModelSource). The tracker does not own the map: the map sits above it (fusion's KinFu) and takes
// each tracked frame from it; fusion's TrackedMap (vofusion/fusion/tracked_map.h) puts the two together.
//
//   per frame: FusionResult r = tracker.track(frame, have_prior ? &prior : nullptr, geometry, map);
//              if (const FrameToFuse* f = tracker.frameToFuse()) tracker.fused(map.fuse(*f, times), times);
#include <iosfwd>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <mrpt/poses/CPose3D.h>

#include "vofusion/core/frame.h"
#include "vofusion/core/point_maps.h"
#include "vofusion/core/timing.h"
#include "vofusion/registration/motion_prior.h"
#include "vofusion/tracking/model_prediction.h"
#include "vofusion/tracking/tracker_params.h"
#include "vofusion/tracking/tracking_mode.h"

namespace vofusion {

struct FusionResult {
  bool tracked = false;       // a pose was obtained for this frame (ICP, the prior, or a prediction)
  bool fell_back = false;     // ICP rejected, pose taken from the prior
  bool predicted = false;     // neither ICP nor a prior: pose from the constant-velocity prediction
  InitialGuess guess = InitialGuess::LastPose;
  bool integrated = false;    // the frame was fused into the TSDF (filled by the map's owner, TrackedMap)
  Rejection rejection = Rejection::None;  // why ICP was rejected / tracking lost
  std::string reason;         // the same with its figures ("" when ICP was accepted)
  mrpt::poses::CPose3D pose;  // camera-to-world after this frame (unchanged when lost)
  int icp_inliers = 0;
  double icp_rms = 0.0;       // m
  double condition = 0.0;     // of the ICP normal matrix (0 when no ICP ran)
  int degenerate_dims = 0;    // ICP directions too weak to solve, kept from the prediction
  int match_inliers = 0;      // prior matches within 3 sigmas of the joint estimate
  double icp_sigma = 0.0;     // m, mode joint: the noise the ICP residuals were weighed with
  bool model_overruled = false;  // mode joint: the pose is the frame-to-frame estimate's, the model had
                                 // pulled the frame away from it and the odometry (an earlier pass's surface)
  bool shifted = false;       // the volume moved this frame (filled by the map's owner)
  StageTimes times;           // preprocess, icp; integrate, raycast, shift added by the map's owner
};

// The tracker's counts over all frames, and the stage times of the frames it posed. The map's shifts and
// stage times are counted here too (handed over by fused()): one record per run, as checkpoints keep it.
struct TrackerStats {
  std::size_t frames = 0, tracked = 0, fell_back = 0, predicted = 0, lost = 0, shifts = 0;
  std::size_t guess_prior = 0, guess_velocity = 0, guess_last = 0;  // initial guesses chosen (ICP modes)
  std::size_t degenerate = 0;    // frames whose ICP left some direction at the prediction
  std::size_t model_overruled = 0;  // mode joint: frames posed frame to frame, the model's pull refused
  StageTimes times;              // accumulated over all frames
};

class Tracker {
 public:
  // initial_pose: camera-to-world of the frame that starts the map (the first with readings in range).
  Tracker(const TrackerParams& params, TrackingMode mode, const Eigen::Isometry3d& initial_pose);
  ~Tracker();

  // The frame's pose against the model `map` predicts (without a model yet, the frame defines the map).
  // prior: the motion from an earlier frame (by Frame::index) to this one, nullptr when there is none.
  // geometry: the frame's point and normal maps when another stage computed them (the odometry, for
  // BRAND): ICP then reads them instead of filtering the depth again; nullptr: KinectFusion's own
  // bilateral filter and pyramid. The previous frame must have been fused first.
  FusionResult track(const Frame& frame, const fusion::MotionPrior* prior, const FrameGeometry* geometry, ModelSource& map);
  // The frame the last track() posed, as the map fuses it; nullptr when it was lost or already fused.
  // Its images are the frame's: they must stay unchanged until the map's fuse() returns.
  const FrameToFuse* frameToFuse() const;
  // The map fused that frame (or only re-predicted its model): whether its volume shifted, and the
  // stage times. Until then saveState() refuses, so a checkpoint never holds a frame the map lacks.
  void fused(bool shifted, const StageTimes& times);
  // A frame posed from elsewhere (re-integration with loop-closed poses) at `cam_to_world`; false (and
  // the pose kept) when the frame has no depth image to fuse. The map's integration is counted by fused().
  bool placeAt(const Frame& frame, const Eigen::Isometry3d& cam_to_world);

  Eigen::Isometry3d pose() const;  // camera-to-world after the last frame
  // Tracking found again elsewhere (relocalisation), or a saved map resumed: the camera is at
  // `cam_to_world` (the map's frame), with no recent motion. as_prior: that pose is the next frame's
  // prior (ICP starts there and may not jump from it; when it does, the frame takes that pose as a
  // fallback), as the odometry's motion is otherwise. The map is to predict its model from there
  // before the next frame (TrackedMap::relocalise, TrackedMap::resume).
  void relocalise(const Eigen::Isometry3d& cam_to_world, bool as_prior = false);
  // Frames (Frame::index) a later prior may name however old (RgbdOdometry::heldFrames): their poses
  // stay in the tracker's recent path past its last 32 frames.
  void holdFrames(std::vector<std::size_t> frames);
  // Checkpoints: the camera's recent motion and the counts. Call between frames, once the map fused
  // the last one (fused(); it throws before); the map's own state follows in the same stream.
  void saveState(std::ostream& os) const;
  void loadState(std::istream& is);
  TrackerStats stats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vofusion
