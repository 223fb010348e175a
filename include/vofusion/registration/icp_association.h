#pragma once
// Projective ICP's per-pixel half (KinectFusion §3.5): a frame pixel's vertex moved by the pose and
// projected into the model's ray-cast view, matched with the model's vertex and normal there, and its
// point-to-plane residual and Jacobian summed into the normal equations. It is most of ICP's time, so
// it runs 8 pixels at once with AVX2 where the CPU has it; the scalar build computes the same numbers
// bit for bit (same operations in the same order, no fused multiply-add, the same 8 sums per row), so
// results do not depend on the machine. Back to back on xyz_first300 (bench/results/2026-12-01-simd-association.md):
// ICP with the photometric term beside it 7.2-7.5 -> 3.3-3.5 ms a frame.
#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "vofusion/core/camera.h"
#include "vofusion/registration/normal_equations.h"

namespace vofusion::fusion {

// One row's sums. Pixel x goes to lane x % 8, each lane a double sum of exact float products (as the
// scalar loop before it summed every pixel in double), and the 8 lanes are added in lane order.
struct IcpRowSums {
  NormalSums6 eq;  // J^T J and -J^T r; J = (rotation about the camera centre, translation)
  double r2 = 0.0;            // squared point-to-plane residuals of the inliers
  double r2_truncated = 0.0;  // min(r^2, truncation^2) over the inliers
  double d2 = 0.0;            // squared distances of the inliers from the camera centre
  int n = 0;        // inliers
  int valid = 0;    // pixels with a vertex and a normal
  int in_view = 0;  // valid pixels landing on a model pixel with a vertex and a normal

  // Rows add up to a level (in a fixed order: see parallelReduce).
  IcpRowSums& operator+=(const IcpRowSums& o) {
    eq.join(o.eq);
    r2 += o.r2, r2_truncated += o.r2_truncated, d2 += o.d2;
    n += o.n, valid += o.valid, in_view += o.in_view;
    return *this;
  }
};

class IcpAssociator {
 public:
  // model_vertices / model_normals: the ray cast (CV_32FC3, continuous, NaN where empty) in the view of
  // model_inv^-1, seen through `camera`. A pixel is an inlier when its model point is within
  // max_distance (m) and the normals within max_angle_deg. simd = false: the scalar build even on an
  // AVX2 CPU (tests).
  IcpAssociator(const cv::Mat& model_vertices, const cv::Mat& model_normals, const CameraIntrinsics& camera,
                const Eigen::Isometry3f& model_inv, const Eigen::Isometry3f& pose, float max_distance,
                float max_angle_deg, float truncation, bool simd = true);
  // One row of the frame's vertex and normal maps (camera coordinates, NaN where empty).
  IcpRowSums sumRow(const cv::Vec3f* vertices, const cv::Vec3f* normals, int cols) const;
  static bool usesAvx2();

  struct Setup {  // what both builds read
    float R[9], t[3];    // pose, row-major
    float Rm[9], tm[3];  // model_inv, row-major
    float fx, fy, cx, cy;
    float max_d2, min_cos, trunc2;
    const float *model_vertices, *model_normals;
    int mw, mh;
  };

 private:
  Setup s_;
  bool avx2_;
};

}  // namespace vofusion::fusion
