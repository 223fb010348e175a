#pragma once
// What KinectFusion's tracker is told about a frame's motion by another estimator (the 6D RGB-D
// odometry, an IMU, a wheel odometry): the motion from an earlier frame, its covariance, and, when
// the estimator had them, the 3D point correspondences it rests on. The tracker weighs the
// correspondences in its own estimate (tracking/joint_policy.h, registration/projective_icp.h); the pose
// alone is enough for the paper's hand-off. tracking/ knows nothing of who produced it.
#include <cstddef>
#include <optional>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace vofusion::fusion {

struct MotionPrior {
  std::size_t reference_index = 0;  // Frame::index of the frame the motion starts from
  Eigen::Isometry3d T_ref_cur = Eigen::Isometry3d::Identity();  // current camera in the reference camera
  Eigen::Matrix<double, 6, 6> covariance = Eigen::Matrix<double, 6, 6>::Identity();  // x y z yaw pitch roll
  // Inlier correspondences: a point of the current frame (its camera coordinates, m) and the same
  // point in the reference camera's coordinates. Empty when the estimator has none.
  std::vector<Eigen::Vector3d> current_points, reference_points;
  // The colour camera in the depth camera (over Frame::colour_offset), where the estimator knew the
  // motion on both sides of the frame (RgbdOdometry::refitPrevious); else the tracker extrapolates its own.
  std::optional<Eigen::Isometry3d> colour_motion;
};

// False when any of the motion, its covariance or the points is NaN or infinite: a damaged estimate,
// which the tracker ignores as a whole.
inline bool isFinite(const MotionPrior& p) {
  if (!p.T_ref_cur.matrix().allFinite() || !p.covariance.allFinite()) return false;
  if (p.colour_motion && !p.colour_motion->matrix().allFinite()) return false;
  for (const auto* points : {&p.current_points, &p.reference_points})
    for (const Eigen::Vector3d& v : *points)
      if (!v.allFinite()) return false;
  return true;
}

}  // namespace vofusion::fusion
