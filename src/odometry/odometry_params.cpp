#include <mrpt/config/CConfigFileBase.h>

#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"
#include "vofusion/odometry/rgbd_odometry.h"

namespace vofusion {

namespace {

// Every key, once per section: loading and saving both walk these lists.
std::vector<ConfigKey> odometryKeys(OdometryParams& p) {
  return {
      ConfigKey::oneOf("keypoints", &p.keypoints, "union = STAR + NARF (the paper)", kKeypointSets),
      ConfigKey::oneOf("motion_method", &p.motion_method, "paper = Algorithm 1; robust = RANSAC + LS + Gauss-Newton",
                       kMotionMethods),
      {"narf_concurrent", &p.narf_concurrent, "NARF beside STAR, normals and smoothing"},
      {"union_radius", &p.union_radius, "pixels, duplicate radius", 0.0, 50.0},
      {"keyframe_min_inliers", &p.keyframe_min_inliers, "keep the keyframe while this many inliers, 0 = off", 0.0, 100000.0},
      {"undistort", &p.undistort, "undistort keypoints before 3D/homography"},
      {"depth_window", &p.depth_window, "pixels, half-size of the keypoint depth window", 0.0, 10.0},
      ConfigKey::oneOf("depth_mode", &p.depth_mode, "of that window's valid readings (depth_window > 0 only)", kDepthModes),
      {"references", &p.references, "frames matched: the previous one and references-1 before it (keyframe_min_inliers = 0 only)", 1.0, 8.0},
      {"colour_time", &p.colour_time, "keypoints moved to the depth capture time"},
      ConfigKey::oneOf("colour_time_velocity", &p.colour_time_velocity,
                       "interval = the fitted interval's mean; capture = each frame's own (exact offsets); auto = capture once the recording's frames fit it better (sign test)",
                       kColourTimeVelocities),
  };
}

std::vector<ConfigKey> matchingKeys(OdometryParams& p) {
  return {
      {"max_hamming", &p.max_hamming, "bits of 256, 256 = no limit", 0.0, 256.0},
      {"use_homography", &p.use_homography, "RANSAC homography filter"},
      {"homography_threshold", &p.homography_threshold, "pixels", 0.1, 100.0},
      {"min_matches", &p.min_matches, "after the homography filter; also the keypoints a frame needs", 4.0, 100000.0},
  };
}

std::vector<ConfigKey> motionKeys(OdometryParams& p) {
  return {
      {"hypotheses", &p.paper.hypotheses, "paper: N", 1.0, 100000.0},
      {"sample_size", &p.paper.sample_size, "paper: s correspondences", 3.0, 100.0},
      {"paper_inlier_threshold", &p.paper.inlier_threshold, "m, paper: inlier report", 0.0001, 1.0},
      {"ransac_iterations", &p.robust.iterations, "robust: max hypotheses", 1.0, 100000.0},
      {"inlier_threshold", &p.robust.inlier_threshold, "m at <= 1 m depth, grows with z^2", 0.0001, 1.0},
      {"gauss_newton_iterations", &p.robust.gauss_newton_iterations, "robust: refinement steps", 0.0, 100.0},
      {"ray_noise", &p.robust.ray_noise, "robust: Kinect noise along rays in Gauss-Newton"},
      {"cauchy", &p.robust.cauchy, "robust: Cauchy kernel scale in Gauss-Newton, sigmas (0 = off)", 0.0, 100.0},
      {"ransac_seed", &p.robust.seed, "robust: seed of the odometry's RANSAC draws; a run repeats exactly for a seed, and bench/run --rules --perturb N runs seeds 1..N to tell a change from chaos", 0.0, 999999.0},
      {"min_inliers", &p.min_inliers, "3D inliers needed, the current frame's keypoints counted once however many references matched them", 3.0, 100000.0},
      {"min_extent", &p.min_extent, "m, inlier spread needed", 0.0, 10.0},
      {"max_rms", &p.max_rms, "m at <= 1 m depth (grows with z^2 as the inlier threshold; motion_method paper: plain, at any depth), inlier RMS accepted", 0.0001, 10.0},
  };
}

}  // namespace

void OdometryParams::loadFromConfigFile(const mrpt::config::CConfigFileBase& c, const std::string& s) {
  loadKeys(c, s, odometryKeys(*this));
  loadKeys(c, "matching", matchingKeys(*this));
  loadKeys(c, "motion", motionKeys(*this));
  if (references < 1 || references > 8) throw InputError("[" + s + "] references", "must be 1..8 frames");
  if (depth_window < 0 || depth_window > 10) throw InputError("[" + s + "] depth_window", "must be 0..10 pixels");

  star.loadFromConfigFile(c, "star");
  narf.loadFromConfigFile(c, "narf");
  brand.loadFromConfigFile(c, "brand");
}

void OdometryParams::saveToConfigFile(mrpt::config::CConfigFileBase& c, const std::string& s) const {
  auto& p = const_cast<OdometryParams&>(*this);
  saveKeys(c, s, odometryKeys(p));
  saveKeys(c, "matching", matchingKeys(p));
  saveKeys(c, "motion", motionKeys(p));
  star.saveToConfigFile(c, "star");
  narf.saveToConfigFile(c, "narf");
  brand.saveToConfigFile(c, "brand");
}

}  // namespace vofusion
