#pragma once
// Depth preprocessing for KinectFusion (Newcombe et al. 2011, §3.2): bilateral filter, a depth
// pyramid, and per level the vertex and normal maps in the camera frame.
#include <vector>

#include <opencv2/core.hpp>

#include "vofusion/core/camera.h"
#include "vofusion/core/point_maps.h"

namespace vofusion::fusion {

struct PreprocessParams {
  float sigma_depth = 0.04f;    // m, bilateral range sigma
  float sigma_spatial = 4.5f;   // pixels, bilateral spatial sigma
  int kernel = 7;               // pixels, bilateral window edge
  float min_depth = 0.3f;       // m, closer readings are dropped
  float max_depth = 4.0f;       // m, farther readings are dropped
  int levels = 3;               // pyramid levels (level 0 = full resolution)
  float max_normal_jump = 0.05f;  // fraction of depth: larger neighbour jumps give no normal
};

// One pyramid level. vertices/normals are CV_32FC3 in the camera frame; invalid = NaN in x.
struct DepthLevel {
  cv::Mat depth;     // CV_32F metres, 0 = invalid
  cv::Mat vertices;  // CV_32FC3
  cv::Mat normals;   // CV_32FC3, unit, pointing towards the camera
  CameraIntrinsics camera;
};

// Keeps 0 (no reading) where the input is 0 and never mixes invalid pixels into valid ones. Eight pixels
// at a time where the CPU has AVX2, the same bytes as the scalar loop (simd = false: that loop, for tests).
cv::Mat bilateralFilterDepth(const cv::Mat& depth, float sigma_depth, float sigma_spatial, int kernel, bool simd = true);
// 2x2 block -> 1 pixel: mean of the valid readings within 3*sigma_depth of the block's nearest one.
cv::Mat downsampleDepth(const cv::Mat& depth, float sigma_depth);
cv::Mat depthToVertices(const cv::Mat& depth, const CameraIntrinsics& cam);
// Central differences; NaN where a neighbour is missing or the depth jumps (occlusion edges).
cv::Mat verticesToNormals(const cv::Mat& vertices, float max_jump);
// Sets to 0 readings outside [min_depth, max_depth] (and NaN/inf).
cv::Mat clipDepth(const cv::Mat& depth, float min_depth, float max_depth);

// Full chain: clip, filter, pyramid, vertex + normal maps.
std::vector<DepthLevel> preprocessDepth(const cv::Mat& depth, const CameraIntrinsics& cam,
                                        const PreprocessParams& p);
// The pyramid from a frame's shared geometry (core/point_maps.h) instead of filtering again: the full
// resolution point and normal maps averaged over 2x2 blocks `downsample - 1` times for level 0, then
// once per level; readings outside [min_depth, max_depth] are dropped. `depth` is the frame's raw depth
// (the levels' depth images), cam its full-resolution camera.
std::vector<DepthLevel> levelsFromGeometry(const FrameGeometry& geometry, const cv::Mat& depth, const CameraIntrinsics& cam,
                                           int downsample, const PreprocessParams& p);

}  // namespace vofusion::fusion
