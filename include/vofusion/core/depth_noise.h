#pragma once
// The Kinect v1 depth noise model every stage weighs 3D points with (Khoshelham & Elberink 2012;
// Nguyen, Izadi & Lovell 2012): axial sigma(z) = 0.0012 + 0.0019 (z - 0.4)^2 m along the viewing ray,
// lateral one pixel of a 525 px focal length.
#include <algorithm>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace vofusion {

// Axial (along the ray) standard deviation of a reading at depth z, m.
inline double kinectAxialSigma(double z) { return 0.0012 + 0.0019 * (z - 0.4) * (z - 0.4); }

// 3x3 covariance of a point p (camera frame, m): axial sigma along its ray, one pixel across it.
inline Eigen::Matrix3d rayCovariance(const Eigen::Vector3d& p) {
  const double z = std::max(0.3, p.z());
  const double axial = kinectAxialSigma(z), lateral = z / 525.0;
  const Eigen::Vector3d ray = p.normalized();
  return lateral * lateral * Eigen::Matrix3d::Identity() + (axial * axial - lateral * lateral) * ray * ray.transpose();
}

}  // namespace vofusion
