#pragma once
// The photometric term's per-pixel half (registration/photometric.h): a reference pixel's model point
// projected into the current colour camera, the intensity there against the reference's, and the
// Huber-weighted residual and Jacobian summed into the normal equations. Beside ICP's association it is
// most of the joint tracker's time, so it runs 8 pixels at once with AVX2 where the CPU has it; the
// scalar build computes the same numbers bit for bit (same operations in the same order, no fused
// multiply-add, the same 8 sums per row), as ICP's (icp_association.h).
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "vofusion/registration/normal_equations.h"
#include "vofusion/registration/photometric.h"

namespace vofusion::fusion {

// One row's sums, unwhitened and unscaled (1/sigma^2 and the level's weight apply to the total). The
// k-th pixel of the row is summed in float into lane k % 8, the 8 lanes added in double in lane order.
struct PhotometricRowSums {
  NormalSums6 eq;    // J^T W J and -J^T W r (W: the Huber weight)
  double r2 = 0.0;   // squared residuals, grey levels^2
  int n = 0;         // residuals

  // Rows add up to a level (in a fixed order: see parallelReduce).
  PhotometricRowSums& operator+=(const PhotometricRowSums& o) {
    eq.join(o.eq);
    r2 += o.r2, n += o.n;
    return *this;
  }
};

class PhotometricAssociator {
 public:
  // T: the camera-to-world pose being estimated; colour_motion: the colour camera in the depth camera's
  // frame. simd = false: the scalar build even on an AVX2 CPU (tests).
  PhotometricAssociator(const PhotometricLevel& level, const Eigen::Isometry3d& T, const PhotometricParams& params,
                        const Eigen::Isometry3d& colour_motion, bool simd = true);
  // Reference row y, pixels first, first + stride, ... (< the row's width).
  PhotometricRowSums sumRow(int y, int first, int stride) const;
  static bool usesAvx2();

  struct Setup {  // what both builds read
    float Rt[9], M[9], Mt[3];  // T's rotation transposed; colour_motion^-1 (rotation, translation); row-major
    float R[9];                // T's rotation times colour_motion's, row-major
    float c[3];                // T's camera centre
    float fx, fy, cx, cy, max_x, max_y, g2, inv_sigma, huber;
    const float *cur_grey, *cur_dx, *cur_dy;  // continuous, `cur_cols` floats a row
    int cur_cols;
  };

 private:
  PhotometricLevel level_;  // pointers to the images, which must outlive the associator
  Setup s_;
  bool avx2_;
};

}  // namespace vofusion::fusion
