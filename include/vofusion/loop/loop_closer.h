#pragma once
// Loop closure beside the frame loop: every frame's tracked pose goes in (cheap); frames that become
// keyframes are queued to a thread of their own, which indexes them (place recognition), verifies
// the candidates, adds the accepted loops to the MRPT pose graph and optimises it. The frame loop
// never waits for that thread; finish() does, once, at the end of a run.
//
//   loop::LoopCloser lc(params);
//   for each frame: lc.addFrame(frame, tracked_pose, well_tracked, icp_rms, odometry.features);
//   lc.finish();
//   Trajectory optimised = lc.correct(tracked);   // every pose follows its keyframe
#include <cstddef>
#include <iosfwd>
#include <functional>
#include <map>
#include <optional>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Geometry>

#include "vofusion/core/frame.h"
#include "vofusion/core/timing.h"
#include "vofusion/core/trajectory.h"
#include "vofusion/loop/keyframe_store.h"
#include "vofusion/loop/loop_params.h"
#include "vofusion/core/described_keypoints.h"

namespace vofusion::loop {

// One accepted loop (summary.json "loops").
struct LoopRecord {
  std::size_t from_frame = 0, to_frame = 0;        // Frame::index of the older and the newer keyframe
  std::size_t from_keyframe = 0, to_keyframe = 0;  // keyframe ids
  int matches = 0, inliers = 0;
  double icp_rms = 0.0;                            // m
  double icp_condition = 0.0;                      // smallest / largest eigenvalue of the loop's ICP
  double correction_m = 0.0, correction_deg = 0.0;  // measured vs tracked relative pose
  bool active = true;                              // false: removed after optimisation (did not fit)
  double from_timestamp = 0.0, to_timestamp = 0.0;  // s, of the two keyframes
  Eigen::Isometry3d measured = Eigen::Isometry3d::Identity();  // the newer keyframe in the older's camera frame
};

// Tracking found again (LoopCloser::relocalise): the keyframe the frame was matched with and the
// frame's camera-to-world pose in the tracker's coordinates (the keyframe's tracked pose, moved by
// the verified relative pose). summary.json "relocalisations".
struct Relocalisation {
  std::size_t frame = 0;                 // Frame::index of the relocalised frame
  std::size_t keyframe = 0, keyframe_frame = 0;  // keyframe id and its Frame::index
  int inliers = 0;                       // RANSAC inliers of the match
  double icp_rms = 0.0;                  // m
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
};
struct KeyframePose {
  std::size_t frame_index = 0;
  double timestamp = 0.0;
  Eigen::Isometry3d tracked = Eigen::Isometry3d::Identity(), optimised = Eigen::Isometry3d::Identity();
};

class LoopCloser {
 public:
  // spill_dir: where old keyframes' features and depth go beyond [loop] keyframe_cache_mib (see
  // KeyframeStore; "auto" or empty: the system's temporary folder).
  explicit LoopCloser(const LoopParams& params, const std::string& spill_dir = "auto");
  ~LoopCloser();

  // Every processed frame, in order (lost ones too, well_tracked = false); icp_rms: the tracker's ICP
  // residual RMS (m, 0 when none ran), judged against the well-tracked frames' recent ones
  // (ResidualMonitor). Returns true when the frame became a keyframe (its features and a reduced depth
  // are kept; features may be null).
  bool addFrame(const Frame& frame, const Eigen::Isometry3d& tracked, bool well_tracked, double icp_rms,
                std::shared_ptr<const DescribedKeypoints> features);
  // Checkpoints. saveState waits for the thread to take in every queued keyframe, then writes the
  // frame loop's side (keyframe selection, residuals, which keyframe each frame follows) and every
  // keyframe. loadState, on a new loop closer with the same parameters, hands those keyframes to its
  // thread again: place recognition, verification and the graph are rebuilt as they were, in order.
  void saveState(std::ostream& os) const;
  void loadState(std::istream& is);
  // Relocalisation, when the tracker has lost the camera: the frame matched against the keyframes (the
  // newest ones, those the place index has not taken yet one per index_spacing, then the index's
  // candidates) and verified as a loop is, without the drift bound; a placement beyond the camera's
  // reach since the last well-tracked frame (kMaxCameraSpeed) is refused, however many inliers it has.
  // Waits for the thread to store and index the queued keyframes first, not for their verification or
  // the graph's solve (seconds on a long run). nullopt: no keyframe verified.
  std::optional<Relocalisation> relocalise(const Frame& frame, std::shared_ptr<const DescribedKeypoints> features);
  // Tests only, before the first addFrame: called on the thread with each keyframe's id once it is
  // stored and indexed, before its verification and the graph's solve.
  void setAfterIndexingHook(std::function<void(std::size_t)> hook);
  // Waits until every queued keyframe is processed and the graph optimised.
  void finish();

  // Snapshots, safe while the thread runs.
  std::vector<LoopRecord> loops() const;
  std::size_t activeLoops() const;
  std::vector<KeyframePose> keyframes() const;
  std::size_t keyframesMade() const;  // frames that became keyframes so far (frame loop: not waiting for the thread)
  std::map<std::string, std::size_t> rejections() const;  // verification failures by reason
  KeyframeStoreStats storeStats() const;
  // The most keyframes that waited for the thread at once, and how often the frame loop waited for it
  // (at most 16 wait: beyond, the frame loop blocks until the thread takes one).
  std::pair<std::size_t, std::size_t> queueStats() const;
  std::size_t strainedFrames() const;  // frames whose ICP residual stood out (ResidualMonitor); frame loop only
  double threadCpuSeconds() const;  // the thread's CPU time on keyframes (its stages' wall time counts waits too)
  StageTimes times() const;  // the thread's: "place_recognition", "loop_verification", "pose_graph" (the frame
                             // loop's keyframing is the pipeline's stage "keyframes")

  // `tracked` (one pose per frame given to addFrame, in order) with every pose moved with its
  // keyframe: T' = K_optimised K_tracked^-1 T.
  Trajectory correct(const Trajectory& tracked) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vofusion::loop
