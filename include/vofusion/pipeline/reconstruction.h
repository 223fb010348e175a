#pragma once
// The whole per-frame pipeline (6D RGB-D odometry -> KinectFusion) behind one call, shared by the
// offline app (vofusion) and the live one (vofusion-grab --live).
//
//   Reconstruction rec(cfg, TrackingMode::Joint);
//   for each frame: FrameReport r = rec.process(frame);
//   TriangleMesh mesh = rec.extractMesh();
#include <map>
#include <memory>
#include <string>
#include <vector>

#include <mrpt/config/CConfigFileBase.h>
#include <opencv2/core.hpp>

#include "vofusion/core/config.h"
#include "vofusion/core/frame.h"
#include "vofusion/core/timing.h"
#include "vofusion/core/trajectory.h"
#include "vofusion/fusion/kinfu.h"
#include "vofusion/mesh/triangle_mesh.h"
#include "vofusion/odometry/rgbd_odometry.h"

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

// The sections every stage reads ([odometry...], [kinfu]), with the stages' defaults: for
// checkConfigKeys() and dumpConfig().
std::vector<ConfigSection> reconstructionConfigSections();

class Reconstruction {
 public:
  // Reads every stage's section of cfg (the caller checks for unknown keys first).
  Reconstruction(const mrpt::config::CConfigFileBase& cfg, TrackingMode mode);
  ~Reconstruction();
  FrameReport process(const Frame& frame);

  TrackingMode mode() const;
  const Trajectory& trajectory() const;  // one pose per processed frame (held pose when lost)
  TriangleMesh extractMesh() const;      // raw marching-cubes mesh of the whole world model
  cv::Mat renderView(const CameraIntrinsics& cam) const;  // shaded ray-cast from the current pose
  const StageTimes& totalTimes() const;  // accumulated over all frames, plus "total"
  std::size_t framesProcessed() const;
  std::size_t fallbacks() const;         // frames whose pose came from the odometry fallback
  std::size_t predictedFrames() const;   // frames whose pose came from the constant-velocity prediction
  const std::map<std::string, std::size_t>& icpRejections() const;  // why ICP was rejected, how often
  std::size_t lostFrames() const;
  std::size_t odometryFailures() const;
  KinFuStats fusionStats() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vofusion
