#pragma once
// What every stage asks of Frame::depth before it reads it.
#include <opencv2/core.hpp>

namespace vofusion {

// Throws std::invalid_argument, naming `who`, unless depth is CV_32FC1 metres (an empty image passes):
// a 16-bit image is in sensor units, and no stage here knows its scale.
void requireMetricDepth(const cv::Mat& depth, const char* who);

// Whether depth holds a reading (> 0): zeros and NaN are none.
bool hasDepthReading(const cv::Mat& depth);

}  // namespace vofusion
