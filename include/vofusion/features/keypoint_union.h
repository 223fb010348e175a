#pragma once
// Union of two keypoint sets without duplicates: a keypoint of `b` within `radius` pixels of a
// keypoint of `a` is the same feature and is dropped (`a` wins).
#include <vector>

#include <opencv2/core.hpp>

namespace vofusion {

std::vector<cv::KeyPoint> mergeKeypoints(const std::vector<cv::KeyPoint>& a, const std::vector<cv::KeyPoint>& b,
                                         float radius);

}  // namespace vofusion
