#pragma once
// Poses between MRPT (CPose3D: what the apps, rawlogs and trajectories carry) and Eigen (what the
// tracker, the loop closer and the pose graph compute with). Both camera-to-world, exact copies.
#include <Eigen/Geometry>
#include <mrpt/math/CMatrixFixed.h>
#include <mrpt/poses/CPose3D.h>

namespace vofusion {

inline Eigen::Isometry3d toEigen(const mrpt::poses::CPose3D& p) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = p.getRotationMatrix().asEigen();
  T.translation() = Eigen::Vector3d(p.x(), p.y(), p.z());
  return T;
}

inline mrpt::poses::CPose3D toMrpt(const Eigen::Isometry3d& T) {
  mrpt::math::CMatrixDouble44 M;
  M.asEigen() = T.matrix();
  return mrpt::poses::CPose3D(M);
}

}  // namespace vofusion
