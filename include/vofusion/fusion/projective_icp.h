#pragma once
// Frame-to-model tracking of KinectFusion (§3.5): projective data association against the ray-cast
// model and point-to-plane ICP linearised as in Low (2004), coarse to fine.
#include <array>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "vofusion/fusion/preprocess.h"

namespace vofusion::fusion {

struct IcpParams {
  std::array<int, 3> iterations{6, 4, 3};  // per level, level 0 (full resolution) first
  float max_distance = 0.10f;    // m, correspondences farther apart are rejected
  float max_angle = 30.0f;       // degrees between normals
  // Directions of the 6x6 system (rotation scaled by the scene depth, so both are in metres) whose
  // eigenvalue is below this fraction of the largest are not solved: the pose keeps the initial
  // guess along them (the odometry prediction in mode paper, the last pose in mode kinfu).
  double degenerate_ratio = 1e-2;
};

struct IcpResult {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  // camera-to-world estimate
  int inliers = 0;             // correspondences at the last iteration of level 0
  int valid_pixels = 0;        // frame pixels with a vertex and normal at level 0
  double rms = 0.0;            // m, point-to-plane residual over the inliers
  double condition = 0.0;      // smallest / largest eigenvalue of the depth-scaled 6x6 normal matrix
  int degenerate_dims = 0;     // directions left at the initial guess at the last level-0 iteration
  bool solved = false;         // false when a linear system could not be solved
};

// model_vertices/normals: per level, world frame, ray-cast from model_pose (camera-to-world);
// model_cams: their intrinsics. frame: preprocessed current frame, same number of levels.
IcpResult projectiveIcp(const std::vector<DepthLevel>& frame, const std::vector<cv::Mat>& model_vertices,
                        const std::vector<cv::Mat>& model_normals, const Eigen::Isometry3d& model_pose,
                        const Eigen::Isometry3d& initial, const IcpParams& params);

// 2x2 block average of valid world-frame vertices/normals (for the model pyramid).
void downsampleMaps(const cv::Mat& vertices, const cv::Mat& normals, cv::Mat& vertices_out,
                    cv::Mat& normals_out);

}  // namespace vofusion::fusion
