#include "vofusion/fusion/preprocess.h"

#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

namespace vofusion::fusion {

namespace {
const float kNaN = std::numeric_limits<float>::quiet_NaN();
}

cv::Mat clipDepth(const cv::Mat& depth, float min_depth, float max_depth) {
  CV_Assert(depth.type() == CV_32FC1);
  cv::Mat out(depth.size(), CV_32FC1);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < depth.rows; ++y) {
    const float* s = depth.ptr<float>(y);
    float* d = out.ptr<float>(y);
    for (int x = 0; x < depth.cols; ++x) {
      const float z = s[x];
      d[x] = (z >= min_depth && z <= max_depth) ? z : 0.f;  // NaN fails both tests
    }
  }
  return out;
}

cv::Mat bilateralFilterDepth(const cv::Mat& depth, float sigma_depth, float sigma_spatial, int kernel) {
  CV_Assert(depth.type() == CV_32FC1);
  // OpenCV's filter weighs neighbours by exp(-dz^2 / 2 sigma^2): a 0 (invalid) neighbour of a valid
  // reading is > 0.3 m away, i.e. weight < e^-28 at sigma 4 cm, so it never leaks in. Invalid pixels
  // themselves get a tiny average of their neighbours and are reset to 0 below.
  cv::Mat out;
  cv::bilateralFilter(depth, out, kernel, sigma_depth, sigma_spatial, cv::BORDER_REPLICATE);
#pragma omp parallel for schedule(static)
  for (int y = 0; y < depth.rows; ++y) {
    const float* s = depth.ptr<float>(y);
    float* d = out.ptr<float>(y);
    for (int x = 0; x < depth.cols; ++x)
      if (!(s[x] > 0.f)) d[x] = 0.f;
  }
  return out;
}

cv::Mat downsampleDepth(const cv::Mat& depth, float sigma_depth) {
  const int w = depth.cols / 2, h = depth.rows / 2;
  cv::Mat out(h, w, CV_32FC1);
  const float band = 3.f * sigma_depth;
#pragma omp parallel for schedule(static)
  for (int y = 0; y < h; ++y) {
    const float* r0 = depth.ptr<float>(2 * y);
    const float* r1 = depth.ptr<float>(2 * y + 1);
    float* d = out.ptr<float>(y);
    for (int x = 0; x < w; ++x) {
      const float v[4] = {r0[2 * x], r0[2 * x + 1], r1[2 * x], r1[2 * x + 1]};
      float nearest = std::numeric_limits<float>::max();
      for (float z : v)
        if (z > 0.f && z < nearest) nearest = z;
      float sum = 0.f;
      int n = 0;
      for (float z : v)
        if (z > 0.f && z - nearest <= band) sum += z, ++n;
      d[x] = n ? sum / n : 0.f;
    }
  }
  return out;
}

cv::Mat depthToVertices(const cv::Mat& depth, const CameraIntrinsics& cam) {
  cv::Mat out(depth.size(), CV_32FC3);
  const float ifx = 1.f / cam.fx, ify = 1.f / cam.fy, cx = cam.cx, cy = cam.cy;
#pragma omp parallel for schedule(static)
  for (int y = 0; y < depth.rows; ++y) {
    const float* s = depth.ptr<float>(y);
    cv::Vec3f* d = out.ptr<cv::Vec3f>(y);
    const float ry = (y - cy) * ify;
    for (int x = 0; x < depth.cols; ++x) {
      const float z = s[x];
      d[x] = z > 0.f ? cv::Vec3f((x - cx) * ifx * z, ry * z, z) : cv::Vec3f(kNaN, kNaN, kNaN);
    }
  }
  return out;
}

cv::Mat verticesToNormals(const cv::Mat& vertices, float max_jump) {
  cv::Mat out(vertices.size(), CV_32FC3, cv::Scalar::all(kNaN));
  const int w = vertices.cols, h = vertices.rows;
#pragma omp parallel for schedule(static)
  for (int y = 1; y < h - 1; ++y) {
    const cv::Vec3f* up = vertices.ptr<cv::Vec3f>(y - 1);
    const cv::Vec3f* row = vertices.ptr<cv::Vec3f>(y);
    const cv::Vec3f* down = vertices.ptr<cv::Vec3f>(y + 1);
    cv::Vec3f* d = out.ptr<cv::Vec3f>(y);
    for (int x = 1; x < w - 1; ++x) {
      const cv::Vec3f& c = row[x];
      const cv::Vec3f &l = row[x - 1], &r = row[x + 1], &u = up[x], &b = down[x];
      if (std::isnan(c[0]) || std::isnan(l[0]) || std::isnan(r[0]) || std::isnan(u[0]) || std::isnan(b[0]))
        continue;
      const float jump = max_jump * c[2];
      if (std::fabs(l[2] - c[2]) > jump || std::fabs(r[2] - c[2]) > jump || std::fabs(u[2] - c[2]) > jump ||
          std::fabs(b[2] - c[2]) > jump)
        continue;
      cv::Vec3f n = (r - l).cross(b - u);
      const float len = std::sqrt(n.dot(n));
      if (!(len > 0.f)) continue;
      n *= 1.f / len;
      if (n.dot(c) > 0.f) n = -n;  // face the camera
      d[x] = n;
    }
  }
  return out;
}

std::vector<DepthLevel> preprocessDepth(const cv::Mat& depth, const CameraIntrinsics& cam,
                                        const PreprocessParams& p) {
  std::vector<DepthLevel> levels(std::max(1, p.levels));
  const cv::Mat clipped = clipDepth(depth, p.min_depth, p.max_depth);
  levels[0].depth = p.kernel > 1 ? bilateralFilterDepth(clipped, p.sigma_depth, p.sigma_spatial, p.kernel) : clipped;
  levels[0].camera = cam;
  levels[0].camera.width = depth.cols;
  levels[0].camera.height = depth.rows;
  for (std::size_t l = 1; l < levels.size(); ++l) {
    levels[l].depth = downsampleDepth(levels[l - 1].depth, p.sigma_depth);
    levels[l].camera = levels[l - 1].camera.scaled(0.5);
  }
  for (auto& lv : levels) {
    lv.vertices = depthToVertices(lv.depth, lv.camera);
    lv.normals = verticesToNormals(lv.vertices, p.max_normal_jump);
  }
  return levels;
}

}  // namespace vofusion::fusion
