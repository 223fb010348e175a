#pragma once
// The per-voxel half of TSDF integration that reads the depth frame: where the 8 voxels of one brick
// row project and the depth measured there. It is most of integrate()'s time, so it runs 8 voxels at
// once with AVX2 where the CPU has it; the scalar build computes the same numbers bit for bit (same
// operations in the same order, no fused multiply-add), so results do not depend on the machine.
#include <cstdint>

#include <Eigen/Core>
#include <opencv2/core.hpp>

#include "vofusion/core/camera.h"

namespace vofusion::fusion {

struct VoxelRowSamples {
  float depth[8];  // m, reading at the voxel's pixel: bilinear where its 4 neighbours agree, else nearest
  float z[8];      // m, the voxel's depth along the optical axis
  int pixel[8];    // v * width + u of the nearest pixel; -1: behind the camera, outside the image,
                   // or no reading in [min_depth, max_depth] there
};

class VoxelProjector {
 public:
  // depth: CV_32FC1, continuous. Readings in [min_depth, max_depth] count; the 4 neighbours agree
  // when they spread less than `agree` (m). simd = false: the scalar build even on an AVX2 CPU (tests).
  VoxelProjector(const cv::Mat& depth, const CameraIntrinsics& cam, float min_depth, float max_depth, float agree,
                 bool simd = true);
  // Voxel x of the row (x = 0..7) sits at first + x * step in camera coordinates (m).
  void sampleRow(const Eigen::Vector3f& first, const Eigen::Vector3f& step, VoxelRowSamples& out) const;
  static bool usesAvx2();

  struct Setup {  // what both builds read
    const float* depth;
    int w, h;
    float fx, fy, cx, cy, zmin, zmax, agree;
  };

 private:
  Setup s_;
  bool avx2_;
};

}  // namespace vofusion::fusion
