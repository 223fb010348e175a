#pragma once
// The whole per-frame pipeline (6D RGB-D odometry -> KinectFusion) behind one call, shared by the
// offline app (vofusion) and the live one (vofusion-grab --live).
//
//   Reconstruction rec(cfg, TrackingMode::Joint);
//   for each frame: if (auto r = rec.push(frame)) use(*r);   // the report of the frame before it
//   if (auto r = rec.flush()) use(*r);              // the last frame's
//   rec.finish();                                   // loop closure done, trajectory() optimised
//   if (rec.mapNeedsReintegration()) rec.reintegrate(next_frame_from_the_start);
//   TriangleMesh mesh = rec.extractMesh();
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <mrpt/config/CConfigFileBase.h>
#include <opencv2/core.hpp>

#include "vofusion/core/config.h"
#include "vofusion/core/frame.h"
#include "vofusion/core/timing.h"
#include "vofusion/core/trajectory.h"
#include "vofusion/fusion/tracked_map.h"
#include "vofusion/fusion/marching_cubes.h"
#include "vofusion/loop/loop_closer.h"
#include "vofusion/core/triangle_mesh.h"
#include "vofusion/odometry/rgbd_odometry.h"
#include "vofusion/tracking/path_smoother.h"

namespace vofusion {

struct FrameReport {
  std::size_t index = 0;
  double timestamp = 0.0;
  bool tracked = false;       // a pose was estimated for this frame (false: lost, pose held)
  bool fell_back = false;     // ICP rejected, odometry pose used instead
  bool predicted = false;     // neither ICP nor the odometry: constant-velocity prediction
  std::string note;           // why ICP was rejected or tracking lost; empty when all went well
  mrpt::poses::CPose3D pose;  // camera-to-world after this frame
  OdometryResult odometry;    // success=false when not run (mode kinfu) or failed
  StageTimes times;           // this frame's wall time: odometry, preprocess, icp, integrate, raycast, ...
};

// The odometry's colour-time correction ([odometry] colour_time_velocity): whether its last frame moved
// the keypoints at each frame's own velocity (capture), and the frames compared (ColourTimeEvidence).
struct ColourTimeStats {
  bool known = false;  // false until the odometry has estimated a motion (never in mode kinfu)
  bool capture = false;
  int compared = 0, capture_better = 0;
};

// The sections every stage reads ([odometry...], [kinfu], [loop]), with the stages' defaults: for
// checkConfigKeys() and dumpConfig().
std::vector<ConfigSection> reconstructionConfigSections();
// Reads those sections of cfg as a Reconstruction would, so that a bad value fails before any output
// is made: InputError("[section] key", ...).
void checkReconstructionValues(const mrpt::config::CConfigFileBase& cfg);

class Reconstruction {
 public:
  // Reads every stage's section of cfg (the caller checks for unknown keys first).
  Reconstruction(const mrpt::config::CConfigFileBase& cfg, TrackingMode mode);
  ~Reconstruction();
  // One frame late, as the apps run: the frame's odometry now, then the frame before it tracked and fused,
  // its report returned (none for the first). Held back a frame, a frame's motion is fitted again once
  // the next frame's is known: in the odometry's capture mode its colour camera is placed from the
  // motions on both sides of it, not extrapolated from the one before (RgbdOdometry::refitPrevious), for
  // its keypoints and the tracker's colour alike (the shake's ATE 12-13 % lower on seeds 1-5 and 6-10 when
  // it came; with a 30 ms depth readout, mixed: docs/tracking.md). Interval mode: the same poses as process().
  std::optional<FrameReport> push(const Frame& frame);
  // The frame push() holds, tracked now without the next one (none if none is held): the input's end.
  std::optional<FrameReport> flush();
  // The frame tracked at once (push() then flush()): its own report. Not while push() holds a frame.
  FrameReport process(const Frame& frame);
  // The frame the last report is of, with the reconstruction's own copy of its images (the caller's may
  // have been refilled since), until the next push() or flush(). Empty before the first report.
  const Frame& trackedFrame() const;

  TrackingMode mode() const;
  // One pose per processed frame (held pose when lost): after finish(), the loop-closed poses when
  // loop closure ran, else the tracked ones smoothed; before finish(), the tracked ones.
  const Trajectory& trajectory() const;
  // The tracker's poses, before any loop; after finish(), their camera centres smoothed over each run of
  // fused frames (tracking/path_smoother.h), orientations as tracked.
  const Trajectory& trackedTrajectory() const;
  // Where each frame was fused into the map: as tracked, loop-corrected once reintegrate() ran.
  const Trajectory& fusedTrajectory() const;
  const PathSmoothing& pathSmoothing() const;  // after finish(): what smoothed the tracked path, how far
  // KinFu::setShiftObserver on the tracking map (not on the volume reintegrate() fuses anew).
  void setShiftObserver(KinFu::ShiftObserver observer);
  // End of the frames (not while push() holds one: flush() it first): waits for the fusion and the
  // loop-closure thread, smooths the tracked path's
  // centres, then corrects it (every pose follows its keyframe). Idempotent; process() must not be
  // called afterwards.
  void finish();
  // Loop closure ([loop] enabled, and a mode with the odometry's features); null when off.
  const loop::LoopCloser* loopCloser() const;
  // After finish(): loops moved some pose by more than [loop] reintegrate_min_correction, so the map
  // (fused at the tracked poses) should be fused again at the corrected ones.
  bool mapNeedsReintegration() const;
  // Why the map cannot be fused again, if so: the saved map the run went on from (resumeVolume) changed
  // since (an interrupted run saved over it), so it holds some of these frames already, or cannot be read
  // again (KinFu::savedMapProblem: a failing disk), and fusing them again without it would lose the
  // sessions before this one. reintegrate() then leaves the map as tracked.
  std::optional<std::string> reintegrationBlocked() const;
  double maxLoopCorrection() const;  // after finish(): largest distance the loops moved a fused pose, m
  // Fuses the frames again, from the first (next(frame) gives them in the order processed), into a
  // fresh volume at the corrected poses (the loops' corrections of the poses as tracked); frames not
  // fused the first time are skipped again, and so are frames the run never processed (found by
  // Frame::index: the input read again gives each frame its index of the run). progress gets the number
  // of frames read. Returns the number of frames fused: 0, the map left as tracked, when
  // reintegrationBlocked() says why not.
  std::size_t reintegrate(const std::function<bool(Frame&)>& next,
                          const std::function<void(std::size_t)>& progress = nullptr);
  bool reintegrated() const;
  // The map and the current pose to a file (TrackedMap::save), after the fusion in flight finished.
  void saveVolume(const std::string& path) const;
  // Before the first frame: continue from a saved map and pose (TrackedMap::resume). reintegrate()
  // reads the file again and fuses the frames into it (a checkpoint keeps its name); changed or gone
  // since, it blocks re-fusion (reintegrationBlocked).
  void resumeVolume(const std::string& path);
  // Checkpoints, between frames: every stage's state (odometry, tracker and map, loop closer) and the
  // run's poses and counts so far. A reconstruction made with the same configuration and mode that
  // loads it (before its first frame) goes on exactly as the saved one would have. A frame push() holds
  // is not in it (its odometry is undone: the state is the one before it), so the loading one is given
  // that frame next: the frame after the framesProcessed() ones it tracked.
  void saveState(std::ostream& os) const;
  void loadState(std::istream& is);
  TriangleMesh extractMesh() const;      // raw marching-cubes mesh of the whole world model
  // The same mesh one region of region_bricks^3 bricks at a time (fusion::marchingCubesByRegion).
  void extractMeshByRegion(int region_bricks, const std::function<void(fusion::RegionMesh&)>& sink) const;
  cv::Mat renderView(const CameraIntrinsics& cam) const;  // shaded ray-cast from the current pose
  // Once meshed: frees the map (volume, world model and its spill file) so that what comes after
  // (whole-mesh repair, scene, pictures) does not add to it. Trajectories and statistics stay
  // (fusionStats() as at release); the calls above that need the map throw std::logic_error.
  void releaseMap();
  bool mapReleased() const;
  const StageTimes& totalTimes() const;  // accumulated over all frames, plus "total"
  std::size_t framesProcessed() const;   // frames tracked (push() may hold one more)
  std::size_t framesFused() const;       // frames fused into the map while tracking (reintegrate() fuses them again)
  std::size_t fallbacks() const;         // frames whose pose came from the odometry fallback
  std::size_t predictedFrames() const;   // frames whose pose came from the constant-velocity prediction
  const std::map<Rejection, std::size_t>& icpRejections() const;  // why ICP was rejected, how often
  std::size_t lostFrames() const;
  // Where tracking was found again after it was lost (loop closure on: matched against its keyframes).
  const std::vector<loop::Relocalisation>& relocalisations() const;
  std::size_t odometryFailures() const;
  ColourTimeStats colourTime() const;  // the odometry's colour-time correction at the last frame
  KinFuStats fusionStats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vofusion
