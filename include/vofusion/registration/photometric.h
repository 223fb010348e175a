#pragma once
// The photometric term of joint tracking (as Kintinuous' and ElasticFusion's RGB-D tracking): each
// textured pixel of the frame the model was last ray cast for keeps its intensity when its model
// point is projected into the current frame, in the same Gauss-Newton as the point-to-plane
// residuals. Like every joint term it acts in the directions the geometry constrains (JointTerms in
// projective_icp.h: the weak ones go to the prior's pose), where it sharpens ICP's estimate.
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "vofusion/core/camera.h"

namespace vofusion::fusion {

// One tracking level of a colour image: intensity (0..255, CV_32F) and its per-pixel derivatives.
struct IntensityLevel {
  cv::Mat grey, dx, dy;
};

// Intensity pyramid of a BGR image on the tracking levels' pixel grids: level 0 is `size` (the image
// averaged down to it), each next level half the last (2x2 means, as the depth and model pyramids).
std::vector<IntensityLevel> intensityPyramid(const cv::Mat& bgr, cv::Size size, int levels);

struct PhotometricParams {
  double sigma = 0.0;         // grey levels, noise of one residual at level 0 (coarser: 4x the weight per level)
  double huber = 1.0;         // level-0 sigmas, Huber kernel's threshold on the residual at every level:
                              // a coarse level's own noise is lower (sigma / 2^l), so its kernel is
                              // 2^l times as tolerant. Whitening by each level's own sigma was measured
                              // worse (shake seed 3 +6.9 mm, loop seed 3 +3.9 mm: bench/results/
                              // 2026-12-05-photometric-huber-per-level.md).
  double min_gradient = 4.0;  // grey levels per pixel, reference pixels with a weaker gradient carry no residual
};

// `image` (a frame's level, taken from the camera-to-world pose `colour_pose`) resampled on the model's
// pixel grid: each model vertex's intensity and gradient where the image saw it. Where a pixel has no
// vertex or the image did not see it: intensity NaN, gradient 0 (no residual). The colour camera's
// pose differs from the depth camera's (the model's) when the two were not captured at once.
IntensityLevel resampleAtModel(const IntensityLevel& image, const cv::Mat& model_vertices, const Eigen::Isometry3d& colour_pose,
                               const CameraIntrinsics& camera);

// What one level contributes: the reference (intensity on the model's pixel grid) and the current image.
struct PhotometricLevel {
  const IntensityLevel* reference = nullptr;  // of the frame the model was ray cast for
  const IntensityLevel* current = nullptr;
  const cv::Mat* model_vertices = nullptr;    // world frame, on the reference's grid
  CameraIntrinsics camera;                    // the level's intrinsics (both images)
};

// Gauss-Newton sums of the photometric residuals I_cur(pi(T^-1 v)) - I_ref for the camera-to-world
// pose T, in ICP's parameters (rotation about the camera centre, then translation; world frame),
// whitened by sigma and scaled by `weight`. colour_motion: the current colour camera in the depth
// camera's frame (its motion over the colour/depth time offset; identity when captured at once).
struct PhotometricSums {
  Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
  int residuals = 0;
  double r2 = 0.0;  // sum of squared residuals, grey levels^2
};
// Levels of 30000 pixels or more use every other pixel of every other row, each weighed for four.
PhotometricSums accumulatePhotometric(const PhotometricLevel& level, const Eigen::Isometry3d& T,
                                      const PhotometricParams& params, double weight,
                                      const Eigen::Isometry3d& colour_motion = Eigen::Isometry3d::Identity());

}  // namespace vofusion::fusion
