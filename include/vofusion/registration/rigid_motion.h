#pragma once
// Rigid motion between matched 3D points: dst_i ~= R src_i + t.
// - fitPaper: the paper's Algorithm 1 — N hypotheses, each the closed-form (Umeyama) fit of s random
//   correspondences; the one with the least RMS error over ALL correspondences wins.
// - fitRobust: inlier-count RANSAC on minimal samples, least squares on the inliers, then optional
//   Gauss-Newton steps on depth-noise-weighted residuals (Kinect noise grows with z^2) under a Cauchy
//   kernel, so inliers whose depth came from the wrong surface pull little.
// Both return the covariance of the motion from the Gauss-Newton Hessian at the solution.
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "vofusion/core/described_keypoints.h"  // Points3

namespace vofusion {

struct RigidFit {
  bool ok = false;
  std::string failure;                   // why, when !ok
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();  // src -> dst
  std::vector<int> inliers;              // indices with residual <= the inlier threshold
  double rms = 0.0;                      // m, over the inliers
  double rms_all = 0.0;                  // m, over all correspondences
  double rms_at_1m = 0.0;                // m, over the inliers, each residual divided by max(1, z^2) (the
                                         // Kinect noise's growth): comparable across scene depths
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Identity();  // x y z yaw pitch roll
};

// Closed form least squares (Eigen::umeyama, no scale) over the given subset (all if empty).
Eigen::Isometry3d umeyamaRigid(const Points3& src, const Points3& dst, const std::vector<int>& subset = {});

struct PaperFitOptions {
  int hypotheses = 100;          // N
  int sample_size = 4;           // s, correspondences per hypothesis (>= 3)
  double inlier_threshold = 0.03;  // m, only to report inliers / compute covariance
  std::uint32_t seed = 1;
};
RigidFit fitPaper(const Points3& src, const Points3& dst, const PaperFitOptions& opts);

struct RobustFitOptions {
  int iterations = 200;            // RANSAC hypotheses (stops early at 99.9 % confidence)
  double inlier_threshold = 0.01;  // m at 1 m depth; scaled with z^2 beyond
  int gauss_newton_iterations = 6; // weighted refinement steps (0 = plain least squares)
  double cauchy = 1.0;             // sigmas; Gauss-Newton reweights whitened residuals by a Cauchy kernel of
                                   // this scale (iteratively reweighted least squares), 0 = plain
  bool ray_noise = true;           // Gauss-Newton whitens each residual by the Kinect noise along the
                                   // viewing rays (axial 0.0012 + 0.0019 (z-0.4)^2, lateral 1 px); else isotropic
  int seed = 1;                    // of the draws: a run repeats exactly for a seed
};
// with_covariance false: RigidFit::covariance stays identity (a fit that only seeds the next one).
RigidFit fitRobust(const Points3& src, const Points3& dst, const RobustFitOptions& opts, bool with_covariance = true);

// Spread of a point set: sqrt of the second largest eigenvalue of its covariance (m). Small means the
// points are (nearly) collinear or coincident and a rotation about their line is unobservable.
double secondaryExtent(const Points3& pts, const std::vector<int>& subset = {});

// Gauss-Newton on weighted point residuals over the subset (all if empty), parameters (x y z yaw pitch
// roll); returns the refined T and fills the covariance (inverse Hessian scaled by the reduced
// chi-square). cauchy > 0: iteratively reweighted with a Cauchy kernel of that scale on the whitened
// residuals. Without a covariance the Hessian at the solution is not evaluated.
Eigen::Isometry3d refineGaussNewton(const Points3& src, const Points3& dst, const std::vector<int>& subset,
                                    const Eigen::Isometry3d& T0, int iterations,
                                    Eigen::Matrix<double, 6, 6>* covariance, bool ray_noise = false,
                                    double cauchy = 0.0);

}  // namespace vofusion
