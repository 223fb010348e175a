#include <mrpt/config/CConfigFileBase.h>

#include "vofusion/core/errors.h"
#include "vofusion/odometry/rgbd_odometry.h"

namespace vofusion {

void OdometryParams::loadFromConfigFile(const mrpt::config::CConfigFileBase& c, const std::string& s) {
  keypoints = c.read_string(s, "keypoints", keypoints);
  motion_method = c.read_string(s, "motion_method", motion_method);
  narf_concurrent = c.read_bool(s, "narf_concurrent", narf_concurrent);
  union_radius = c.read_double(s, "union_radius", union_radius);
  keyframe_min_inliers = c.read_int(s, "keyframe_min_inliers", keyframe_min_inliers);
  undistort = c.read_bool(s, "undistort", undistort);
  depth_window = c.read_int(s, "depth_window", depth_window);
  depth_mode = c.read_string(s, "depth_mode", depth_mode);
  if (depth_window < 0 || depth_window > 10) throw InputError("[" + s + "] depth_window", "must be 0..10 pixels");
  if (depth_mode != "median" && depth_mode != "min")
    throw InputError("[" + s + "] depth_mode", "must be median or min (got '" + depth_mode + "')");
  if (keypoints != "union" && keypoints != "star" && keypoints != "narf")
    throw InputError("[" + s + "] keypoints", "must be union, star or narf (got '" + keypoints + "')");
  if (motion_method != "paper" && motion_method != "robust")
    throw InputError("[" + s + "] motion_method", "must be paper or robust (got '" + motion_method + "')");

  const std::string m = "matching";
  max_hamming = c.read_int(m, "max_hamming", max_hamming);
  use_homography = c.read_bool(m, "use_homography", use_homography);
  homography_threshold = c.read_double(m, "homography_threshold", homography_threshold);
  min_matches = c.read_int(m, "min_matches", min_matches);

  const std::string mo = "motion";
  paper.hypotheses = c.read_int(mo, "hypotheses", paper.hypotheses);
  paper.sample_size = c.read_int(mo, "sample_size", paper.sample_size);
  paper.inlier_threshold = c.read_double(mo, "paper_inlier_threshold", paper.inlier_threshold);
  robust.iterations = c.read_int(mo, "ransac_iterations", robust.iterations);
  robust.inlier_threshold = c.read_double(mo, "inlier_threshold", robust.inlier_threshold);
  robust.gauss_newton_iterations = c.read_int(mo, "gauss_newton_iterations", robust.gauss_newton_iterations);
  robust.ray_noise = c.read_bool(mo, "ray_noise", robust.ray_noise);
  min_inliers = c.read_int(mo, "min_inliers", min_inliers);
  min_extent = c.read_double(mo, "min_extent", min_extent);
  max_rms = c.read_double(mo, "max_rms", max_rms);
  if (paper.sample_size < 3) throw InputError("[motion] sample_size", "must be at least 3");

  star.loadFromConfigFile(c, "star");
  narf.loadFromConfigFile(c, "narf");
  brand.loadFromConfigFile(c, "brand");
}

void OdometryParams::saveToConfigFile(mrpt::config::CConfigFileBase& c, const std::string& s) const {
  c.write(s, "keypoints", keypoints, -1, -1, "union | star | narf");
  c.write(s, "motion_method", motion_method, -1, -1, "paper (Algorithm 1) | robust");
  c.write(s, "narf_concurrent", narf_concurrent, -1, -1, "NARF on a second thread");
  c.write(s, "union_radius", union_radius, -1, -1, "pixels, duplicate radius");
  c.write(s, "keyframe_min_inliers", keyframe_min_inliers, -1, -1, "keep the keyframe while this many inliers, 0 = off");
  c.write(s, "undistort", undistort, -1, -1, "undistort keypoints before 3D/homography");
  c.write(s, "depth_window", depth_window, -1, -1, "pixels, half-size of the keypoint depth window");
  c.write(s, "depth_mode", depth_mode, -1, -1, "median | min of that window");
  const std::string m = "matching";
  c.write(m, "max_hamming", max_hamming, -1, -1, "bits of 256, 256 = no limit");
  c.write(m, "use_homography", use_homography, -1, -1, "RANSAC homography filter");
  c.write(m, "homography_threshold", homography_threshold, -1, -1, "pixels");
  c.write(m, "min_matches", min_matches, -1, -1, "after the homography filter");
  const std::string mo = "motion";
  c.write(mo, "hypotheses", paper.hypotheses, -1, -1, "paper: N");
  c.write(mo, "sample_size", paper.sample_size, -1, -1, "paper: s correspondences");
  c.write(mo, "paper_inlier_threshold", paper.inlier_threshold, -1, -1, "m, paper: inlier report");
  c.write(mo, "ransac_iterations", robust.iterations, -1, -1, "robust: max hypotheses");
  c.write(mo, "inlier_threshold", robust.inlier_threshold, -1, -1, "m at <= 1 m depth, grows with z^2");
  c.write(mo, "gauss_newton_iterations", robust.gauss_newton_iterations, -1, -1, "robust: refinement steps");
  c.write(mo, "ray_noise", robust.ray_noise, -1, -1, "robust: Kinect noise along rays in Gauss-Newton");
  c.write(mo, "min_inliers", min_inliers, -1, -1, "3D inliers needed");
  c.write(mo, "min_extent", min_extent, -1, -1, "m, inlier spread needed");
  c.write(mo, "max_rms", max_rms, -1, -1, "m, inlier RMS accepted");
  star.saveToConfigFile(c, "star");
  narf.saveToConfigFile(c, "narf");
  brand.saveToConfigFile(c, "brand");
}

}  // namespace vofusion
