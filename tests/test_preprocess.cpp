// Depth preprocessing on analytic surfaces: bilateral filter, pyramid, vertex and normal maps.
#include <cmath>
#include <cstring>
#include <limits>
#include <random>

#include "support.h"
#include "vofusion/core/cpu_features.h"
#include "vofusion/registration/preprocess.h"

using namespace vofusion;
using namespace vofusion::fusion;

namespace {

CameraIntrinsics cam640() { return CameraIntrinsics{}; }

// Depth of the plane n.p = d (camera frame) at every pixel.
cv::Mat planeDepth(const CameraIntrinsics& c, const cv::Vec3d& n, double d) {
  cv::Mat z(c.height, c.width, CV_32F);
  for (int v = 0; v < c.height; ++v)
    for (int u = 0; u < c.width; ++u) {
      const cv::Vec3d ray((u - c.cx) / c.fx, (v - c.cy) / c.fy, 1.0);
      z.at<float>(v, u) = static_cast<float>(d / n.dot(ray));
    }
  return z;
}

cv::Mat sphereDepth(const CameraIntrinsics& c, const cv::Vec3d& centre, double r) {
  cv::Mat z(c.height, c.width, CV_32F, cv::Scalar(0));
  for (int v = 0; v < c.height; ++v)
    for (int u = 0; u < c.width; ++u) {
      const cv::Vec3d ray((u - c.cx) / c.fx, (v - c.cy) / c.fy, 1.0);
      // |t ray - c|^2 = r^2
      const double a = ray.dot(ray), b = -2 * ray.dot(centre), cc = centre.dot(centre) - r * r;
      const double disc = b * b - 4 * a * cc;
      if (disc < 0) continue;
      z.at<float>(v, u) = static_cast<float>((-b - std::sqrt(disc)) / (2 * a));
    }
  return z;
}

double angleDeg(const cv::Vec3f& a, const cv::Vec3d& b) {
  const cv::Vec3d ad(a[0], a[1], a[2]);
  return std::acos(std::clamp(ad.dot(b) / (cv::norm(ad) * cv::norm(b)), -1.0, 1.0)) * 180.0 / M_PI;
}

}  // namespace

TEST(Bilateral, ReducesNoiseKeepsHolesAndDoesNotLeakZeros) {
  const CameraIntrinsics c = cam640();
  const cv::Vec3d n = cv::normalize(cv::Vec3d(0.2, -0.1, -1.0));
  const cv::Mat truth = planeDepth(c, n, -1.5);
  cv::Mat noisy = truth.clone();
  std::mt19937 rng(3);
  std::normal_distribution<float> noise(0.f, 0.004f);
  for (auto it = noisy.begin<float>(); it != noisy.end<float>(); ++it) *it += noise(rng);
  noisy(cv::Rect(200, 150, 60, 40)).setTo(0.f);  // a hole
  const cv::Mat f = bilateralFilterDepth(noisy, 0.04f, 4.5f, 7);
  double e_in = 0, e_out = 0;
  int n_px = 0;
  for (int v = 5; v < c.height - 5; ++v)
    for (int u = 5; u < c.width - 5; ++u) {
      if (noisy.at<float>(v, u) == 0.f) {
        EXPECT_EQ(f.at<float>(v, u), 0.f);
        continue;
      }
      const double t = truth.at<float>(v, u);
      // Valid readings next to the hole must not be dragged towards 0.
      ASSERT_NEAR(f.at<float>(v, u), t, 0.02) << u << "," << v;
      e_in += std::pow(noisy.at<float>(v, u) - t, 2);
      e_out += std::pow(f.at<float>(v, u) - t, 2);
      ++n_px;
    }
  EXPECT_LT(std::sqrt(e_out / n_px), 0.5 * std::sqrt(e_in / n_px));
}

TEST(Bilateral, PreservesDepthEdges) {
  cv::Mat d(100, 100, CV_32F, cv::Scalar(1.0f));
  d(cv::Rect(50, 0, 50, 100)).setTo(1.5f);
  const cv::Mat f = bilateralFilterDepth(d, 0.04f, 4.5f, 7);
  for (int v = 0; v < 100; ++v) {
    EXPECT_NEAR(f.at<float>(v, 49), 1.0f, 1e-3);
    EXPECT_NEAR(f.at<float>(v, 50), 1.5f, 1e-3);
  }
}

// The AVX2 loop must give the scalar loop's bytes: holes, depth edges, readings far apart (outside the
// range table), NaN and infinity, widths that leave part-full runs of eight, and a view into a larger image.
TEST(Bilateral, EightAtATimeGivesTheScalarLoopsBytes) {
  if (!cpuHasAvx2()) GTEST_SKIP() << "no AVX2 on this CPU: only the scalar loop runs";
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> depth(0.5f, 3.f), jitter(-0.05f, 0.05f), u01(0.f, 1.f);
  for (const cv::Size size : {cv::Size(320, 240), cv::Size(37, 11), cv::Size(9, 9)}) {
    cv::Mat big(size.height + 4, size.width + 6, CV_32F);
    float base = depth(rng);
    for (auto it = big.begin<float>(); it != big.end<float>(); ++it) {
      const float p = u01(rng);
      if (p < 0.02f) base = depth(rng);  // a depth edge
      *it = p < 0.1f ? 0.f : p < 0.11f ? -1.f : base + jitter(rng);
    }
    big.at<float>(3, 5) = std::numeric_limits<float>::quiet_NaN();
    big.at<float>(4, 9) = std::numeric_limits<float>::infinity();
    const cv::Mat view = big(cv::Rect(3, 2, size.width, size.height));
    for (const int kernel : {3, 5, 7}) {
      const cv::Mat simd = bilateralFilterDepth(view, 0.04f, 2.f, kernel, true);
      const cv::Mat scalar = bilateralFilterDepth(view, 0.04f, 2.f, kernel, false);
      ASSERT_EQ(simd.size(), scalar.size());
      for (int v = 0; v < simd.rows; ++v)
        ASSERT_EQ(0, std::memcmp(simd.ptr(v), scalar.ptr(v), simd.cols * sizeof(float)))
            << size << " kernel " << kernel << " row " << v;
    }
  }
}

TEST(Normals, PlaneNormalsMatchAnalyticNormal) {
  const CameraIntrinsics c = cam640();
  const cv::Vec3d n = cv::normalize(cv::Vec3d(0.3, 0.2, -1.0));  // facing the camera
  const cv::Mat depth = planeDepth(c, n, -1.2);
  PreprocessParams p;
  const auto levels = preprocessDepth(depth, c, p);
  ASSERT_EQ(levels.size(), 3u);
  for (const auto& lv : levels) {
    int checked = 0;
    for (int v = 4; v < lv.normals.rows - 4; v += 3)  // the filter replicates borders: skip them
      for (int u = 4; u < lv.normals.cols - 4; u += 3) {
        const cv::Vec3f nn = lv.normals.at<cv::Vec3f>(v, u);
        ASSERT_FALSE(std::isnan(nn[0]));
        ASSERT_LT(angleDeg(nn, n), 0.5) << "level size " << lv.normals.cols << " at " << u << "," << v;
        // Vertices lie on the plane.
        const cv::Vec3f vv = lv.vertices.at<cv::Vec3f>(v, u);
        ASSERT_NEAR(n.dot(cv::Vec3d(vv[0], vv[1], vv[2])), -1.2, 1e-3);
        ++checked;
      }
    EXPECT_GT(checked, 1000);
  }
  EXPECT_EQ(levels[1].depth.cols, 320);
  EXPECT_EQ(levels[2].depth.rows, 120);
}

TEST(Normals, SphereNormalsPointOutwardsTowardsCamera) {
  const CameraIntrinsics c = cam640();
  const cv::Vec3d centre(0.1, -0.05, 1.5);
  const double r = 0.4;
  PreprocessParams p;
  p.kernel = 0;  // analytic input, no filter
  const auto levels = preprocessDepth(sphereDepth(c, centre, r), c, p);
  const auto& lv = levels[0];
  int checked = 0;
  for (int v = 0; v < lv.normals.rows; v += 2)
    for (int u = 0; u < lv.normals.cols; u += 2) {
      const cv::Vec3f vv = lv.vertices.at<cv::Vec3f>(v, u);
      const cv::Vec3f nn = lv.normals.at<cv::Vec3f>(v, u);
      if (std::isnan(vv[0]) || std::isnan(nn[0])) continue;
      const cv::Vec3d radial = cv::Vec3d(vv[0], vv[1], vv[2]) - centre;
      if (cv::norm(radial - r * cv::normalize(radial)) > 1e-3) FAIL() << "vertex off the sphere";
      // Skip the grazing rim where central differences straddle the silhouette.
      if (-cv::normalize(radial).dot(cv::normalize(cv::Vec3d(vv[0], vv[1], vv[2]))) < 0.3) continue;
      ASSERT_LT(angleDeg(nn, radial), 2.0) << u << "," << v;
      ++checked;
    }
  EXPECT_GT(checked, 5000);
}

TEST(Preprocess, ClipsDepthRangeAndMarksInvalid) {
  cv::Mat d(10, 10, CV_32F, cv::Scalar(1.0f));
  d.at<float>(0, 0) = 0.1f;
  d.at<float>(1, 1) = 9.0f;
  d.at<float>(2, 2) = std::numeric_limits<float>::quiet_NaN();
  const cv::Mat c = clipDepth(d, 0.3f, 4.0f);
  EXPECT_EQ(c.at<float>(0, 0), 0.f);
  EXPECT_EQ(c.at<float>(1, 1), 0.f);
  EXPECT_EQ(c.at<float>(2, 2), 0.f);
  EXPECT_EQ(c.at<float>(3, 3), 1.f);
  CameraIntrinsics cam;
  cam.width = cam.height = 10;
  cam.cx = cam.cy = 4.5;
  const cv::Mat v = depthToVertices(c, cam);
  EXPECT_TRUE(std::isnan(v.at<cv::Vec3f>(0, 0)[0]));
  EXPECT_FLOAT_EQ(v.at<cv::Vec3f>(3, 3)[2], 1.f);
}

TEST(Pyramid, DownsampleAveragesOnlyConsistentReadings) {
  cv::Mat d = (cv::Mat_<float>(2, 4) << 1.0f, 1.02f, 0.f, 0.f, 1.0f, 2.0f, 0.f, 3.0f);
  const cv::Mat h = downsampleDepth(d, 0.04f);
  ASSERT_EQ(h.cols, 2);
  EXPECT_NEAR(h.at<float>(0, 0), (1.0f + 1.02f + 1.0f) / 3, 1e-6);  // 2.0 is another surface
  EXPECT_NEAR(h.at<float>(0, 1), 3.0f, 1e-6);                       // the only valid reading
}
