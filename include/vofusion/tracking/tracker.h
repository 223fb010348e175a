#pragma once
// Which pose each frame gets: KinectFusion's frame-to-model ICP, weighed together with a motion
// prior (the 6D RGB-D odometry's matches) by the tracking mode, against the map it keeps
// (vofusion/fusion/kinfu.h), which it then fuses the frame into.
//
//   Tracker t(params, TrackingMode::Joint);
//   for each frame: FusionResult r = t.process(frame, have_prior ? &prior : nullptr);
//   TriangleMesh m = t.extractMesh();
#include <iosfwd>
#include <memory>
#include <string>

#include <mrpt/poses/CPose3D.h>
#include <opencv2/core.hpp>

#include "vofusion/core/frame.h"
#include "vofusion/core/point_maps.h"
#include "vofusion/core/timing.h"
#include "vofusion/core/triangle_mesh.h"
#include "vofusion/fusion/kinfu.h"
#include "vofusion/registration/motion_prior.h"
#include "vofusion/tracking/tracking_mode.h"

namespace vofusion {

struct FusionResult {
  bool tracked = false;       // a pose was obtained for this frame (ICP, the prior, or a prediction)
  bool fell_back = false;     // ICP rejected, pose taken from the prior
  bool predicted = false;     // neither ICP nor a prior: pose from the constant-velocity prediction
  InitialGuess guess = InitialGuess::LastPose;
  bool integrated = false;    // the frame was fused into the TSDF
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
  bool shifted = false;       // the volume moved this frame
  StageTimes times;           // preprocess, icp, integrate, raycast, shift
};

struct KinFuStats {
  std::size_t frames = 0, tracked = 0, fell_back = 0, predicted = 0, lost = 0, shifts = 0;
  std::size_t guess_prior = 0, guess_velocity = 0, guess_last = 0;  // initial guesses chosen (ICP modes)
  std::size_t degenerate = 0;    // frames whose ICP left some direction at the prediction
  std::size_t model_overruled = 0;  // mode joint: frames posed frame to frame, the model's pull refused
  std::size_t bricks_in_volume = 0, bricks_in_world_model = 0;
  std::size_t memory_bytes = 0;  // TSDF storage in RAM (volume + the world model's cache)
  fusion::WorldModelStats world;  // the world model: cache, spill file, time spent spilling
  StageTimes times;              // accumulated over all frames
};

class Tracker {
 public:
  // initial_pose: camera-to-world of the first frame (world = first camera frame by default).
  Tracker(const KinFuParams& params, TrackingMode mode, const mrpt::poses::CPose3D& initial_pose = mrpt::poses::CPose3D());
  ~Tracker();

  // prior: the motion from an earlier frame (by Frame::index) to this one, nullptr when there is none.
  // geometry: the frame's point and normal maps when another stage computed them (the odometry, for
  // BRAND): ICP then reads them instead of filtering the depth again; nullptr: KinectFusion's own
  // bilateral filter and pyramid.
  FusionResult process(const Frame& frame, const fusion::MotionPrior* prior, const FrameGeometry* geometry = nullptr);

  // process() in two halves, for a caller that overlaps fusing frame k with the odometry of frame
  // k+1: track() estimates the frame's pose (it needs the previous frame's fuse() done); fuse()
  // integrates that frame and ray-casts the model for the next one, adding its stage times to res.
  // The frame's images must stay unchanged until fuse() returns.
  FusionResult track(const Frame& frame, const fusion::MotionPrior* prior, const FrameGeometry* geometry = nullptr);
  void fuse(FusionResult& res);

  // Fuses a frame at a pose known from elsewhere (re-integration with loop-closed poses): the volume
  // follows the camera as in tracking; no ICP, no ray cast.
  void integrateAt(const Frame& frame, const mrpt::poses::CPose3D& cam_to_world);

  mrpt::poses::CPose3D pose() const;
  // Tracking found again elsewhere (relocalisation): the camera is at `cam_to_world` (the map's frame),
  // with no recent motion; the model is predicted from there before the next frame is tracked.
  // as_prior: that pose is the next frame's prior (ICP starts there and may not jump from it; when it
  // does, the frame takes that pose as a fallback), as the odometry's motion is otherwise.
  void relocalise(const mrpt::poses::CPose3D& cam_to_world, bool as_prior = false);
  // The map and the camera pose to one file, atomically; a later run resumes from it with resume():
  // the next frame is tracked from the saved pose against the saved map, in its frame.
  void save(const std::string& path) const;
  void resume(const std::string& path);
  // Checkpoints: the map, the model predicted from it, the camera's recent motion and the counts.
  // A tracker with the same parameters that loads the state tracks the next frame exactly as the
  // saved one would have. Call between frames (after fuse()).
  void saveState(std::ostream& os) const;
  void loadState(std::istream& is);
  TriangleMesh extractMesh() const { return map().extractMesh(); }
  cv::Mat renderView(const mrpt::poses::CPose3D& cam_to_world, const CameraIntrinsics& cam, bool coloured = false) const {
    return map().renderView(cam_to_world, cam, coloured);
  }
  KinFuStats stats() const;
  const KinFu& map() const;
  const fusion::TsdfVolume& volume() const { return map().volume(); }
  void setShiftObserver(KinFu::ShiftObserver observer);  // KinFu::setShiftObserver
  const KinFuParams& params() const { return map().params(); }
  TrackingMode mode() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vofusion
