// The frame geometry's hand-written integral images against OpenCV's: the same doubles, bit for bit.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <limits>
#include <string>

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

namespace {
// computeNormalMap as it was written before it skipped the fill: the map filled with NaN first, the
// integral images from cv::integral, then the same boxes.
cv::Mat normalsFilledFirst(const cv::Mat& points, int w, float max_depth_step) {
  const int rows = points.rows, cols = points.cols;
  cv::Mat clean(points.size(), CV_32FC3), valid(points.size(), CV_8U);
  for (int y = 0; y < rows; ++y)
    for (int x = 0; x < cols; ++x) {
      const cv::Vec3f p = points.at<cv::Vec3f>(y, x);
      const bool ok = std::isfinite(p[2]);
      clean.at<cv::Vec3f>(y, x) = ok ? p : cv::Vec3f(0, 0, 0);
      valid.at<uchar>(y, x) = ok;
    }
  cv::Mat sum, cnt;
  cv::integral(clean, sum, CV_64F);
  cv::integral(valid, cnt, CV_32S);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  cv::Mat normals(points.size(), CV_32FC3, cv::Scalar::all(nan));
  const int min_count = (w * (2 * w + 1)) / 2;
  auto mean = [&](int x0, int y0, int x1, int y1, cv::Vec3d& m) {
    const int n = cnt.at<int>(y1, x1) - cnt.at<int>(y0, x1) - cnt.at<int>(y1, x0) + cnt.at<int>(y0, x0);
    if (n < min_count) return false;
    m = (sum.at<cv::Vec3d>(y1, x1) - sum.at<cv::Vec3d>(y0, x1) - sum.at<cv::Vec3d>(y1, x0) + sum.at<cv::Vec3d>(y0, x0)) /
        double(n);
    return true;
  };
  const int pairs = std::max(0, (rows - 2 * w) / 2);
  for (int i = 0; i < pairs; ++i)
    for (int x = w, y = w + 2 * i; x < cols - w - 1; x += 2) {
      const cv::Vec3f p = points.at<cv::Vec3f>(y, x);
      if (!std::isfinite(p[2])) continue;
      cv::Vec3d l, r, t, b;
      if (!mean(x - w, y - w, x, y + w + 1, l) || !mean(x + 1, y - w, x + w + 1, y + w + 1, r) ||
          !mean(x - w, y - w, x + w + 1, y, t) || !mean(x - w, y + 1, x + w + 1, y + w + 1, b))
        continue;
      if (std::abs(r[2] - l[2]) > max_depth_step || std::abs(b[2] - t[2]) > max_depth_step) continue;
      cv::Vec3d n = (r - l).cross(b - t);
      const double len = cv::norm(n);
      if (len <= 0) continue;
      n /= len;
      if (n.dot(cv::Vec3d(p)) > 0) n = -n;
      normals.at<cv::Vec3f>(y, x) = normals.at<cv::Vec3f>(y, x + 1) = normals.at<cv::Vec3f>(y + 1, x) =
          normals.at<cv::Vec3f>(y + 1, x + 1) = cv::Vec3f(n);
    }
  return normals;
}
}  // namespace

// Without a fill beforehand every pixel is still written, at every size and window: the same bytes as
// the map filled first (NaN included), on images narrower or lower than the boxes too.
TEST(PointMaps, NormalMapWritesEveryPixel) {
  cv::RNG rng(12);
  for (const cv::Size size : {cv::Size(640, 480), cv::Size(37, 23), cv::Size(9, 20), cv::Size(3, 20), cv::Size(20, 7)})
    for (const int w : {1, 2, 4}) {
      cv::Mat points(size, CV_32FC3);
      for (int y = 0; y < size.height; ++y)
        for (int x = 0; x < size.width; ++x) {
          const float z = 1.0f + 0.002f * x + (x > size.width / 2 ? 0.2f : 0.f) + float(rng.uniform(-0.002, 0.002));
          const bool hole = rng.uniform(0.0, 1.0) < 0.05;
          const float nan = std::numeric_limits<float>::quiet_NaN();
          points.at<cv::Vec3f>(y, x) = hole ? cv::Vec3f(nan, nan, nan) : cv::Vec3f((x - 20.f) * z / 60.f, (y - 15.f) * z / 60.f, z);
        }
      const cv::Mat got = computeNormalMap(points, w, 0.05f), want = normalsFilledFirst(points, w, 0.05f);
      SCOPED_TRACE(std::to_string(size.width) + "x" + std::to_string(size.height) + ", window " + std::to_string(w));
      ASSERT_EQ(got.size(), want.size());
      for (int y = 0; y < size.height; ++y)
        ASSERT_EQ(std::memcmp(got.ptr(y), want.ptr(y), size.width * got.elemSize()), 0) << "row " << y;
    }
}
