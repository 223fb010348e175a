#pragma once
// TSDF integration's per-voxel step (KinectFusion §3.3): each voxel of a brick row that sees a reading,
// and lies no farther than the truncation behind it, takes the frame's projective signed distance into
// its weighted running average (weight capped), and the pixel's colour where it lies within the band.
// Two builds, chosen at run time: scalar, and AVX2 for the row's 8 voxels at once. They give the same
// bytes (test VoxelUpdate.Avx2AndScalarGiveTheSameBytes).
#include <opencv2/core.hpp>

#include "vofusion/fusion/voxel_brick.h"
#include "vofusion/fusion/voxel_projection.h"

namespace vofusion::fusion {

class VoxelUpdater {
 public:
  // truncation > 0 (m); max_weight in [1, 255] (a voxel's weight is a byte); colours: the frame's BGR
  // pixels, covering every index a row's VoxelRowSamples::pixel holds, or null (depth only).
  // simd = false: the scalar build even on an AVX2 CPU (tests).
  VoxelUpdater(float truncation, int max_weight, const cv::Vec3b* colours, bool simd = true);
  // Updates the row's 8 consecutive voxels (x fastest in the brick) from their samples; returns how
  // many were updated.
  int updateRow(const VoxelRowSamples& row, Voxel* voxels) const;

  struct Setup {  // what both builds read
    float truncation, inv_truncation;
    int max_weight;
    const cv::Vec3b* colours;
  };

 private:
  Setup s_;
  bool avx2_;
};

}  // namespace vofusion::fusion
