#pragma once
// What one frame's keypoints are to the stages after the odometry: BRAND descriptors and 3D points.
// Shared by the odometry (which makes them), the registration (Points3) and loop closure (which
// indexes them), so it lives below all three.
#include <vector>

#include <Eigen/Core>
#include <opencv2/core.hpp>

namespace vofusion {

// 3D points (m), one per keypoint or match, in one camera's frame.
using Points3 = std::vector<Eigen::Vector3d>;

// A frame's described keypoints, as place recognition indexes them: BRAND descriptors (CV_8U, 32
// bytes a row) and each keypoint's 3D point in the camera frame (m), row for row.
struct DescribedKeypoints {
  cv::Mat descriptors;
  Points3 points;
};

}  // namespace vofusion
