#include "vofusion/core/depth_image.h"

#include <stdexcept>
#include <string>

namespace vofusion {

void requireMetricDepth(const cv::Mat& depth, const char* who) {
  if (depth.empty() || depth.type() == CV_32FC1) return;
  throw std::invalid_argument(std::string(who) + ": depth must be CV_32FC1 metres (a 16-bit image is in sensor units: "
                              "convert it with the sensor's depth scale)");
}

bool hasDepthReading(const cv::Mat& depth) {
  CV_Assert(depth.empty() || depth.type() == CV_32FC1);
  // Stops at the first reading: a frame with any depth has one in its first rows.
  for (int y = 0; y < depth.rows; ++y) {
    const float* row = depth.ptr<float>(y);
    for (int x = 0; x < depth.cols; ++x)
      if (row[x] > 0.f) return true;  // false for NaN
  }
  return false;
}

}  // namespace vofusion
