#include "vofusion/io/colour_registration.h"

#include <opencv2/imgproc.hpp>

#include "vofusion/core/parallel.h"

namespace vofusion {

cv::Mat colourInDepthCamera(const cv::Mat& colour, const cv::Mat& depth, const CameraIntrinsics& d,
                            const CameraIntrinsics& c, const Eigen::Isometry3d& T_colour_depth) {
  // Where each depth pixel's reading lands in the colour image; -1 (outside) where there is none.
  cv::Mat map_x(depth.size(), CV_32F, cv::Scalar(-1)), map_y(depth.size(), CV_32F, cv::Scalar(-1));
  const Eigen::Matrix3d R = T_colour_depth.linear();
  const Eigen::Vector3d t = T_colour_depth.translation();
  const auto& k = c.dist;  // k1 k2 p1 p2 k3
  parallelFor(0, depth.rows, [&](int v) {
    const float* z = depth.ptr<float>(v);
    float* mx = map_x.ptr<float>(v);
    float* my = map_y.ptr<float>(v);
    for (int u = 0; u < depth.cols; ++u) {
      if (!(z[u] > 0.f)) continue;
      const Eigen::Vector3d p = R * Eigen::Vector3d((u - d.cx) * z[u] / d.fx, (v - d.cy) * z[u] / d.fy, z[u]) + t;
      if (!(p.z() > 0)) continue;
      const double x = p.x() / p.z(), y = p.y() / p.z(), r2 = x * x + y * y;
      const double radial = 1 + k[0] * r2 + k[1] * r2 * r2 + k[4] * r2 * r2 * r2;
      const double xd = x * radial + 2 * k[2] * x * y + k[3] * (r2 + 2 * x * x);
      const double yd = y * radial + k[2] * (r2 + 2 * y * y) + 2 * k[3] * x * y;
      const double cu = c.fx * xd + c.cx, cv = c.fy * yd + c.cy;
      // Outside the colour image: no colour (black), not a blend of its edge with the black border.
      if (!(cu >= 0 && cu <= colour.cols - 1 && cv >= 0 && cv <= colour.rows - 1)) continue;
      mx[u] = float(cu);
      my[u] = float(cv);
    }
  });
  cv::Mat out;
  cv::remap(colour, out, map_x, map_y, cv::INTER_LINEAR, cv::BORDER_CONSTANT, cv::Scalar(0, 0, 0));
  return out;
}

}  // namespace vofusion
