#pragma once
// 6D RGB-D odometry (Figueroa et al., §3.1): frame-to-frame motion from colour + depth keypoints.
// CONTRACT used by fusion/ and the apps; implemented in src/odometry/.
#include <memory>
#include <string>

#include <mrpt/config/CLoadableOptions.h>
#include <mrpt/math/CMatrixFixed.h>
#include <mrpt/poses/CPose3D.h>

#include "vofusion/core/frame.h"
#include "vofusion/core/timing.h"

namespace vofusion {

struct OdometryParams : public mrpt::config::CLoadableOptions {
  // Filled in by the odometry stage: keypoint, descriptor, matching, RANSAC and motion parameters,
  // each with its unit in a comment, read from INI sections [odometry], [star], [narf], [brand] ...
  void loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& section) override;
  void saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& section) const override;
};

struct OdometryResult {
  bool success = false;
  std::string failure;                 // why, when !success ("too few matches", "degenerate geometry", ...)
  mrpt::poses::CPose3D motion;         // current camera pose in the previous camera's frame (T_prev_curr)
  mrpt::math::CMatrixDouble66 covariance;  // of motion, (x y z yaw pitch roll), for CPose3DPDFGaussian
  int keypoints = 0, matches = 0, inliers = 0;
  double rms_error = 0.0;              // m, over the inlier 3D correspondences
  StageTimes times;                    // this frame's per-stage wall time
};

class RgbdOdometry {
 public:
  explicit RgbdOdometry(const OdometryParams& params = {});
  ~RgbdOdometry();
  // Motion since the previous frame given; the first frame (or the first after reset()) returns
  // success=false with failure "first frame".
  OdometryResult process(const Frame& frame);
  void reset();

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vofusion
