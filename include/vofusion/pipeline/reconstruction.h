#pragma once
// The whole per-frame pipeline (odometry -> KinectFusion) behind one call, shared by the offline
// app (vofusion) and the live one (vofusion-grab --live).
// CONTRACT: implemented by the lead in src/pipeline/.
#include <memory>
#include <string>

#include <mrpt/config/CConfigFileBase.h>
#include <opencv2/core.hpp>

#include "vofusion/core/frame.h"
#include "vofusion/core/timing.h"
#include "vofusion/core/trajectory.h"
#include "vofusion/mesh/triangle_mesh.h"

namespace vofusion {

enum class Mode { Paper, KinFu, Odometry };  // odometry-seeded ICP | ICP alone | odometry alone
Mode parseMode(const std::string& s);          // throws InputError("--mode", ...) when unknown
std::string modeName(Mode m);

struct FrameReport {
  std::size_t index = 0;
  double timestamp = 0.0;
  bool tracked = false;       // a pose was estimated for this frame (false: lost, pose held)
  bool fell_back = false;     // ICP rejected, odometry pose used instead (mode paper)
  bool odometry_ok = false;
  std::string note;           // why tracking failed or fell back, empty when all went well
  mrpt::poses::CPose3D pose;  // camera-to-world after this frame
  StageTimes times;           // this frame's per-stage wall time
};

class Reconstruction {
 public:
  // Reads every stage's section of cfg (already checked for unknown keys by the caller).
  Reconstruction(const mrpt::config::CConfigFileBase& cfg, Mode mode);
  ~Reconstruction();
  FrameReport process(const Frame& frame);

  const Trajectory& trajectory() const;  // one pose per processed frame
  TriangleMesh extractMesh();            // raw marching-cubes mesh of the whole world model
  cv::Mat renderView();                  // shaded ray-cast of the model from the current pose (BGR)
  const StageTimes& totalTimes() const;
  std::size_t framesProcessed() const;
  std::size_t fallbacks() const;
  std::size_t lostFrames() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vofusion
