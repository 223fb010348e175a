#pragma once
// A KinFu map with the tracker that poses each frame for it: the frame tracked against the map's
// model (tracking/tracker.h, the layer below), then fused at that pose (kinfu.h). The two stages meet
// here and nowhere else; checkpoints and saved maps keep both together.
//
//   TrackedMap t(params, TrackingMode::Joint);
//   for each frame: FusionResult r = t.process(frame, have_prior ? &prior : nullptr);
//   TriangleMesh m = t.extractMesh();
#include <iosfwd>
#include <string>
#include <vector>
#include <utility>

#include <mrpt/poses/CPose3D.h>
#include <opencv2/core.hpp>

#include "vofusion/core/frame.h"
#include "vofusion/core/point_maps.h"
#include "vofusion/core/triangle_mesh.h"
#include "vofusion/fusion/kinfu.h"
#include "vofusion/registration/motion_prior.h"
#include "vofusion/tracking/tracker.h"

namespace vofusion {

// The tracker's counts with the map's figures at the time they were read.
struct KinFuStats : TrackerStats, MapStats {};

class TrackedMap {
 public:
  // initial_pose: camera-to-world of the first frame (world = first camera frame by default).
  TrackedMap(const KinFuParams& params, TrackingMode mode, const mrpt::poses::CPose3D& initial_pose = mrpt::poses::CPose3D());

  // prior and geometry: as Tracker::track.
  FusionResult process(const Frame& frame, const fusion::MotionPrior* prior, const FrameGeometry* geometry = nullptr);

  // process() in two halves, for a caller that overlaps fusing frame k with the odometry of frame
  // k+1: track() estimates the frame's pose (it needs the previous frame's fuse() done); fuse()
  // integrates that frame and ray-casts the model for the next one, adding its stage times to res.
  // The frame's images must stay unchanged until fuse() returns.
  FusionResult track(const Frame& frame, const fusion::MotionPrior* prior, const FrameGeometry* geometry = nullptr);
  void fuse(FusionResult& res);

  // Fuses a frame at a pose known from elsewhere (re-integration with loop-closed poses): the volume
  // follows the camera as in tracking; no ICP, no ray cast. Whether it was fused: a pose that is not
  // finite, or a frame Tracker::placeAt cannot place, fuses nothing.
  bool integrateAt(const Frame& frame, const mrpt::poses::CPose3D& cam_to_world);

  mrpt::poses::CPose3D pose() const;
  // Tracking found again elsewhere (relocalisation): Tracker::relocalise, and the model predicted from
  // there before the next frame is tracked. A pose that is not finite throws std::invalid_argument.
  void relocalise(const mrpt::poses::CPose3D& cam_to_world, bool as_prior = false);
  // Tracker::holdFrames. Not while a fuse() runs.
  void holdFrames(std::vector<std::size_t> frames) { tracker_.holdFrames(std::move(frames)); }
  // The map and the camera pose to one file, atomically; a later run resumes from it with resume():
  // the next frame is tracked from the saved pose against the saved map, in its frame.
  void save(const std::string& path) const;
  void resume(const std::string& path);
  // Checkpoints: the map, the model predicted from it, the camera's recent motion and the counts.
  // A tracked map with the same parameters that loads the state tracks the next frame exactly as the
  // saved one would have. Call between frames (after fuse()).
  void saveState(std::ostream& os) const;
  void loadState(std::istream& is);
  TriangleMesh extractMesh() const { return map_.extractMesh(); }
  cv::Mat renderView(const mrpt::poses::CPose3D& cam_to_world, const CameraIntrinsics& cam, bool coloured = false) const {
    return map_.renderView(cam_to_world, cam, coloured);
  }
  KinFuStats stats() const;
  const fusion::TsdfVolume& volume() const { return map_.volume(); }
  void setShiftObserver(KinFu::ShiftObserver observer) { map_.setShiftObserver(std::move(observer)); }

 private:
  KinFu map_;
  Tracker tracker_;
};

}  // namespace vofusion
