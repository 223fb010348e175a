#pragma once
// A frame's geometry, computed once and read by every stage that needs it: the back-projected point
// map and the normal map of its depth image at full resolution. BRAND's geometric tests read it, and
// KinectFusion's ICP reads it averaged over 2x2 blocks when tracking at half resolution.
#include <opencv2/core.hpp>

#include "vofusion/core/camera.h"

namespace vofusion {

// Back-projects depth (CV_32F metres) to a CV_32FC3 point map in the camera frame; NaN where no reading.
cv::Mat depthToPointMap(const cv::Mat& depth, const CameraIntrinsics& camera);
// Integral-image normals (average 3D gradient over boxes of half-size `window`), CV_32FC3 unit
// vectors facing the camera; NaN where undefined (no depth, or a depth jump > max_depth_step).
cv::Mat computeNormalMap(const cv::Mat& points, int window, float max_depth_step);
// computeNormalMap's integral images, (rows + 1) x (cols + 1): of the valid points (CV_64FC3, a NaN
// point counted as 0) and of their count (CV_32S), in one pass: the doubles cv::integral gives (test
// PointMaps.IntegralsAreCvIntegrals).
void validPointIntegrals(const cv::Mat& points, cv::Mat& sum, cv::Mat& count);

struct FrameGeometry {
  cv::Mat points;   // CV_32FC3, camera frame, m; NaN where no reading
  cv::Mat normals;  // CV_32FC3, unit, facing the camera; NaN where undefined
};

}  // namespace vofusion
