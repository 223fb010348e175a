#pragma once
// The tracker's settings: the [kinfu] keys that decide which pose a frame gets. The section's other keys
// (the map's) and the one table that loads and saves them all are fusion's KinFuParams
// (vofusion/fusion/kinfu.h), which extends this struct.
#include "vofusion/registration/preprocess.h"
#include "vofusion/registration/projective_icp.h"

namespace vofusion {

// The factor (1 or 2) preprocessing, ray casting and ICP divide the depth image's resolution by;
// integration always fuses the full-resolution depth. Half from 640 px wide on (a quarter of the work at
// 640x480, which coarse-to-fine ICP hardly misses), so halving stops at a 320 px wide tracking image; a
// narrower image tracks at its own size (the 320x240 shake tracked at 160x120 was 3.7 mm worse,
// docs/tracking.md). Was the key [kinfu] tracking_downsample (2 for every input).
inline int trackingDownsample(int depth_width) { return depth_width >= 640 ? 2 : 1; }

struct TrackerParams {
  fusion::PreprocessParams preprocess;  // bilateral_*, min_depth, max_depth, max_normal_jump
  fusion::IcpParams icp;              // icp_iterations_l0..l2, icp_max_distance, icp_max_angle

  // Tracking failure (divergence, degeneracy) detection; the conditioning bound is fixed in code
  // (tracking::kMinCondition).
  float min_inlier_ratio = 0.10f;     // inliers / pixels that land on the model (mode joint) or valid pixels, finest level
  float max_jump_translation = 0.05f; // m, ICP pose vs the prior's prediction (modes joint, paper-handoff)
  float max_jump_rotation = 5.0f;     // degrees, same
  bool integrate_on_fallback = true;  // fuse frames whose pose came from the odometry fallback
  // Mode joint: one Gauss-Newton over the ICP residuals and the prior's point matches (its robust
  // kernels and the initial guess's margin are fixed in code: tracking/joint_policy.h).
  double joint_icp_sigma = 0.005;     // m, noise of one finest-level point-to-plane residual (smaller:
                                      // geometry outweighs the matches more)
  double joint_rolling_shutter = 0.05;  // s, mode joint: readout time of the depth camera; a residual's
                                      // noise grows by this x the turn rate x the scene depth (rows are
                                      // captured at different times, so fast turns bend the frame)
  double motion_sigma_translation = 0.002;  // m per 1/30 s, mode joint: how far the camera centre may
                                      // depart from the constant-velocity prediction (0 = no motion model)
  double motion_sigma_rotation = 0.0;  // degrees per 1/30 s, same for the rotation (0 = none)
  // Mode joint, the photometric term (registration/photometric.h): each textured pixel of the last frame keeps
  // its intensity in this one.
  double joint_photometric_sigma = 40.0;  // grey levels, noise of one finest-level residual (0 = no term)
  bool joint_photometric_rotation_only = true;  // the term informs the rotation only (its translation
                                      // part marginalised): on xyz_first300 it moved the path, not the turns
  bool joint_photometric_colour_time = true;  // each colour image placed at its capture (Frame::colour_offset)
};

}  // namespace vofusion
