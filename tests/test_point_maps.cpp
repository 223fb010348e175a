// The frame geometry's hand-written integral images against OpenCV's: the same doubles, bit for bit.
#include <cmath>
#include <cstring>
#include <limits>

#include <gtest/gtest.h>
#include <opencv2/imgproc.hpp>

#include "vofusion/core/point_maps.h"

using namespace vofusion;

TEST(PointMaps, IntegralsAreCvIntegrals) {
  cv::RNG rng(11);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (const cv::Size size : {cv::Size(640, 480), cv::Size(37, 5), cv::Size(1, 1)}) {
    // A Kinect-like point map: x and y through zero (where sums of floats in double round), holes.
    cv::Mat points(size, CV_32FC3), clean(size, CV_32FC3), valid(size, CV_8U);
    for (int y = 0; y < size.height; ++y)
      for (int x = 0; x < size.width; ++x) {
        const float z = float(rng.uniform(0.4, 4.0));
        const cv::Vec3f p((x - 319.5f) * z / 525.f, (y - 239.5f) * z / 525.f, z);
        const bool hole = rng.uniform(0.0, 1.0) < 0.1;
        points.at<cv::Vec3f>(y, x) = hole ? cv::Vec3f(nan, nan, nan) : p;
        clean.at<cv::Vec3f>(y, x) = hole ? cv::Vec3f(0, 0, 0) : p;
        valid.at<uchar>(y, x) = hole ? 0 : 1;
      }
    cv::Mat sum, count, want_sum, want_count;
    validPointIntegrals(points, sum, count);
    cv::integral(clean, want_sum, CV_64F);
    cv::integral(valid, want_count, CV_32S);
    ASSERT_EQ(sum.type(), want_sum.type());
    ASSERT_EQ(sum.size(), want_sum.size());
    ASSERT_EQ(count.type(), want_count.type());
    for (int y = 0; y < sum.rows; ++y) {
      ASSERT_EQ(std::memcmp(sum.ptr(y), want_sum.ptr(y), sum.cols * sum.elemSize()), 0) << "row " << y;
      ASSERT_EQ(std::memcmp(count.ptr(y), want_count.ptr(y), count.cols * count.elemSize()), 0) << "row " << y;
    }
  }
}
