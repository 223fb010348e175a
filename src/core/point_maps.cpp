#include "vofusion/core/point_maps.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "vofusion/core/parallel.h"

namespace vofusion {

cv::Mat depthToPointMap(const cv::Mat& depth, const CameraIntrinsics& c) {
  CV_Assert(depth.type() == CV_32FC1);
  cv::Mat pts(depth.size(), CV_32FC3);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const float ifx = float(1.0 / c.fx), ify = float(1.0 / c.fy), cx = float(c.cx), cy = float(c.cy);
  parallelFor(0, depth.rows, [&](int y) {
    const float* d = depth.ptr<float>(y);
    cv::Vec3f* p = pts.ptr<cv::Vec3f>(y);
    for (int x = 0; x < depth.cols; ++x) {
      const float z = d[x];
      p[x] = z > 0.f ? cv::Vec3f((x - cx) * z * ifx, (y - cy) * z * ify, z) : cv::Vec3f(nan, nan, nan);
    }
  });
  return pts;
}

void validPointIntegrals(const cv::Mat& points, cv::Mat& sum, cv::Mat& count) {
  CV_Assert(points.type() == CV_32FC3);
  const int rows = points.rows, cols = points.cols;
  sum.create(rows + 1, cols + 1, CV_64FC3);
  count.create(rows + 1, cols + 1, CV_32S);
  std::fill_n(sum.ptr<double>(0), 3 * (cols + 1), 0.0);
  std::fill_n(count.ptr<int>(0), cols + 1, 0);
  for (int y = 0; y < rows; ++y) {
    const cv::Vec3f* p = points.ptr<cv::Vec3f>(y);
    const double* above = sum.ptr<double>(y);
    double* row = sum.ptr<double>(y + 1);
    const int* count_above = count.ptr<int>(y);
    int* count_row = count.ptr<int>(y + 1);
    row[0] = row[1] = row[2] = 0.0;
    count_row[0] = 0;
    // cv::integral's order: each row's running sum, added to the integral of the row above.
    double s0 = 0.0, s1 = 0.0, s2 = 0.0;
    int n = 0;
    for (int x = 0; x < cols; ++x) {
      const bool ok = std::isfinite(p[x][2]);
      const cv::Vec3f q = ok ? p[x] : cv::Vec3f(0, 0, 0);
      s0 += q[0], s1 += q[1], s2 += q[2];
      n += ok;
      const int i = 3 * (x + 1);
      row[i] = above[i] + s0, row[i + 1] = above[i + 1] + s1, row[i + 2] = above[i + 2] + s2;
      count_row[x + 1] = count_above[x + 1] + n;
    }
  }
}

cv::Mat computeNormalMap(const cv::Mat& points, int w, float max_depth_step) {
  CV_Assert(points.type() == CV_32FC3 && w >= 1);
  const int rows = points.rows, cols = points.cols;
  // The integral images in buffers the calling thread keeps (8.6 MB at 640x480, otherwise new pages
  // every frame). Not for a caller inside a parallelFor body: a thread waiting in the rows' parallelFor
  // below could take another call's task, and it would overwrite these buffers.
  struct Buffers {
    cv::Mat sum, cnt;
  };
  thread_local Buffers buffers;
  // Named here: the rows below run on other threads, where `buffers` would be their own.
  cv::Mat &sum = buffers.sum, &cnt = buffers.cnt;
  validPointIntegrals(points, sum, cnt);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const cv::Vec3f none(nan, nan, nan);
  // Every pixel is written below (a normal, or none), so no fill beforehand.
  cv::Mat normals(points.size(), CV_32FC3);
  const int min_count = (w * (2 * w + 1)) / 2;
  // Mean point of the box [x0, x1) x [y0, y1); false if too few readings.
  auto mean = [&](int x0, int y0, int x1, int y1, cv::Vec3d& m) {
    const int n = cnt.at<int>(y1, x1) - cnt.at<int>(y0, x1) - cnt.at<int>(y1, x0) + cnt.at<int>(y0, x0);
    if (n < min_count) return false;
    m = (sum.at<cv::Vec3d>(y1, x1) - sum.at<cv::Vec3d>(y0, x1) - sum.at<cv::Vec3d>(y1, x0) + sum.at<cv::Vec3d>(y0, x0)) /
        double(n);
    return true;
  };
  // Evaluated on every second pixel and copied to its 2x2 block: the boxes are 2w+1 wide, so
  // neighbouring normals are nearly equal anyway, and this is 4x cheaper.
  const int pairs = std::max(0, (rows - 2 * w) / 2);
  parallelFor(0, pairs, [&](int i) {
    const int y = w + 2 * i;
    cv::Vec3f* out = normals.ptr<cv::Vec3f>(y);
    cv::Vec3f* out2 = normals.ptr<cv::Vec3f>(y + 1);
    const cv::Vec3f* p = points.ptr<cv::Vec3f>(y);
    int x = w;
    for (; x < cols - w - 1; x += 2) {
      out[x] = out[x + 1] = out2[x] = out2[x + 1] = none;
      if (!std::isfinite(p[x][2])) continue;
      cv::Vec3d l, r, t, b;
      if (!mean(x - w, y - w, x, y + w + 1, l) || !mean(x + 1, y - w, x + w + 1, y + w + 1, r) ||
          !mean(x - w, y - w, x + w + 1, y, t) || !mean(x - w, y + 1, x + w + 1, y + w + 1, b))
        continue;
      if (std::abs(r[2] - l[2]) > max_depth_step || std::abs(b[2] - t[2]) > max_depth_step) continue;
      cv::Vec3d n = (r - l).cross(b - t);
      const double len = cv::norm(n);
      if (len <= 0) continue;
      n /= len;
      if (n.dot(cv::Vec3d(p[x])) > 0) n = -n;  // face the camera
      out[x] = out[x + 1] = out2[x] = out2[x + 1] = cv::Vec3f(n);
    }
    for (int x2 = 0; x2 < std::min(w, cols); ++x2) out[x2] = out2[x2] = none;  // the left margin
    for (; x < cols; ++x) out[x] = out2[x] = none;              // the right one
  });
  for (int y = 0; y < rows; ++y)  // the rows above and below the pairs
    if (y < w || y >= w + 2 * pairs) std::fill_n(normals.ptr<cv::Vec3f>(y), cols, none);
  return normals;
}

}  // namespace vofusion
