// The photometric term of joint tracking: its Gauss-Newton sums are the derivative of its cost (and the
// AVX2 and scalar builds of them agree bit for bit), and they alone bring a textured view back to the
// pose it was rendered from.
#include <cmath>
#include <cstring>
#include <limits>

#include <gtest/gtest.h>
#include <opencv2/core.hpp>
#include <opencv2/imgproc.hpp>

#include "vofusion/registration/photometric.h"
#include "vofusion/registration/photometric_association.h"

using namespace vofusion;
using namespace vofusion::fusion;

namespace {

const CameraIntrinsics kCam = [] {
  CameraIntrinsics c;
  c.width = 160, c.height = 120, c.fx = 150, c.fy = 150, c.cx = 79.5, c.cy = 59.5;
  return c;
}();

// A slanted textured plane z = 2 + 0.3 x (world frame); smooth texture so that gradients are exact.
float texture(const Eigen::Vector3d& p) {
  return float(128 + 50 * std::sin(7 * p.x()) * std::cos(5 * p.y()) + 30 * std::sin(11 * p.y() + 3 * p.x()));
}
Eigen::Vector3d hitPlane(const Eigen::Isometry3d& T, double u, double v) {
  const Eigen::Vector3d d = T.linear() * Eigen::Vector3d((u - kCam.cx) / kCam.fx, (v - kCam.cy) / kCam.fy, 1.0);
  const Eigen::Vector3d o = T.translation();
  const double s = (2.0 + 0.3 * o.x() - o.z()) / (d.z() - 0.3 * d.x());
  return o + s * d;
}

// The view from T: BGR image and world-frame vertex map.
void render(const Eigen::Isometry3d& T, cv::Mat& bgr, cv::Mat& vertices) {
  bgr.create(kCam.height, kCam.width, CV_8UC3);
  vertices.create(kCam.height, kCam.width, CV_32FC3);
  for (int y = 0; y < kCam.height; ++y)
    for (int x = 0; x < kCam.width; ++x) {
      const Eigen::Vector3d p = hitPlane(T, x, y);
      const uchar g = cv::saturate_cast<uchar>(texture(p));
      bgr.at<cv::Vec3b>(y, x) = cv::Vec3b(g, g, g);
      vertices.at<cv::Vec3f>(y, x) = cv::Vec3f(float(p.x()), float(p.y()), float(p.z()));
    }
}

// ICP's parameters: rotation about the camera centre, then translation (world frame).
Eigen::Isometry3d step(const Eigen::Matrix<double, 6, 1>& xi, const Eigen::Isometry3d& T) {
  Eigen::Isometry3d inc = Eigen::Isometry3d::Identity();
  const double a = xi.head<3>().norm();
  if (a > 0) inc.linear() = Eigen::AngleAxisd(a, xi.head<3>() / a).toRotationMatrix();
  const Eigen::Vector3d c = T.translation();
  inc.translation() = c - inc.linear() * c + xi.tail<3>();
  return inc * T;
}

Eigen::Isometry3d truth() {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(0.03, Eigen::Vector3d(0.2, 1, 0.1).normalized()).toRotationMatrix();
  T.translation() = Eigen::Vector3d(0.04, -0.02, 0.03);
  return T;
}

struct Pair {
  std::vector<IntensityLevel> reference, current;
  cv::Mat vertices;
  PhotometricLevel level() const { return {&reference[0], &current[0], &vertices, kCam}; }
};

Pair makePair() {
  Pair p;
  cv::Mat ref_bgr, cur_bgr, cur_vertices;
  render(Eigen::Isometry3d::Identity(), ref_bgr, p.vertices);
  render(truth(), cur_bgr, cur_vertices);
  p.reference = intensityPyramid(ref_bgr, ref_bgr.size(), 1);
  p.current = intensityPyramid(cur_bgr, cur_bgr.size(), 1);
  return p;
}

}  // namespace

// BGRA and grey colour give the pyramid BGR gives (the term was dropped without a word), and a tiny
// image as many levels as it can halve (the resize to an empty size threw).
TEST(Photometric, PyramidOfAnyEightBitColourAndOfATinyImage) {
  cv::Mat bgr(48, 64, CV_8UC3);
  cv::RNG(7).fill(bgr, cv::RNG::UNIFORM, 0, 255);  // its own generator: the data whichever tests ran before
  const auto want = intensityPyramid(bgr, {64, 48}, 3);
  ASSERT_EQ(want.size(), 3u);
  cv::Mat bgra, grey;
  cv::cvtColor(bgr, bgra, cv::COLOR_BGR2BGRA);
  cv::cvtColor(bgr, grey, cv::COLOR_BGR2GRAY);
  for (const cv::Mat& img : {bgra, grey}) {
    const auto got = intensityPyramid(img, {64, 48}, 3);
    ASSERT_EQ(got.size(), 3u) << img.channels();
    EXPECT_EQ(cv::norm(got[0].grey, want[0].grey, cv::NORM_INF), 0.0) << img.channels();
  }
  std::vector<IntensityLevel> tiny;
  ASSERT_NO_THROW(tiny = intensityPyramid(cv::Mat(3, 3, CV_8UC3, cv::Scalar::all(9)), {3, 3}, 3));
  EXPECT_EQ(tiny.size(), 2u);  // 3x3, 1x1
}

// An odd-sized level halves to the 2x2 means of its even part, as the depth pyramid does (camera
// scaled by 0.5): INTER_AREA over the whole 5 columns averaged 2.5 columns a pixel.
TEST(Photometric, AnOddLevelHalvesToTwoByTwoMeans) {
  cv::Mat grey(5, 5, CV_8UC1);
  for (int y = 0; y < 5; ++y)
    for (int x = 0; x < 5; ++x) grey.at<std::uint8_t>(y, x) = std::uint8_t(10 * x);
  const auto pyr = intensityPyramid(grey, {5, 5}, 2);
  ASSERT_EQ(pyr.size(), 2u);
  ASSERT_EQ(pyr[1].grey.size(), cv::Size(2, 2));
  EXPECT_FLOAT_EQ(pyr[1].grey.at<float>(0, 0), 5.0f);   // columns 0 and 1
  EXPECT_FLOAT_EQ(pyr[1].grey.at<float>(1, 1), 25.0f);  // columns 2 and 3
}

TEST(Photometric, SumsAreTheCostsDerivative) {
  const Pair pair = makePair();
  PhotometricParams params;
  params.sigma = 1.0;
  params.huber = 1e6;  // least squares: the cost is half the sum of squares
  params.min_gradient = 1.0;
  Eigen::Matrix<double, 6, 1> off;
  off << 0.004, -0.003, 0.002, 0.006, 0.004, -0.005;
  const Eigen::Isometry3d T = step(off, truth());
  const PhotometricSums s = accumulatePhotometric(pair.level(), T, params, 1.0);
  ASSERT_GT(s.residuals, 5000);
  for (int i = 0; i < 6; ++i) {
    const double eps = 1e-5;
    Eigen::Matrix<double, 6, 1> e = Eigen::Matrix<double, 6, 1>::Zero();
    e[i] = eps;
    const double up = accumulatePhotometric(pair.level(), step(e, T), params, 1.0).r2;
    const double down = accumulatePhotometric(pair.level(), step(-e, T), params, 1.0).r2;
    const double numeric = 0.25 * (up - down) / eps;  // d(r2 / 2) / d xi_i
    EXPECT_NEAR(-s.b[i], numeric, 0.05 * std::abs(numeric) + 1e-3 * s.b.norm()) << "parameter " << i;
  }
}

TEST(Photometric, TextureAloneFindsThePose) {
  const Pair pair = makePair();
  PhotometricParams params;
  params.sigma = 5.0;
  Eigen::Matrix<double, 6, 1> off;
  off << 0.01, -0.008, 0.006, 0.015, -0.01, 0.012;  // ~0.8 deg and 2 cm away
  Eigen::Isometry3d T = step(off, truth());
  for (int it = 0; it < 30; ++it) {
    const PhotometricSums s = accumulatePhotometric(pair.level(), T, params, 1.0);
    T = step(s.A.ldlt().solve(s.b), T);
  }
  const Eigen::Isometry3d d = truth().inverse() * T;
  EXPECT_LT(d.translation().norm(), 0.002);
  EXPECT_LT(Eigen::AngleAxisd(d.linear()).angle() * 180 / M_PI, 0.05);
}

TEST(Photometric, Avx2AndScalarSumsAgreeBitForBit) {
  if (!PhotometricAssociator::usesAvx2()) GTEST_SKIP() << "no AVX2 on this CPU: only the scalar build runs";
  Pair pair = makePair();
  // 157 columns: rows end in a scalar tail at both strides and both first columns.
  const cv::Rect crop(0, 0, 157, kCam.height);
  pair.vertices = pair.vertices(crop).clone();
  IntensityLevel& ref = pair.reference[0];
  ref.grey = ref.grey(crop).clone(), ref.dx = ref.dx(crop).clone(), ref.dy = ref.dy(crop).clone();
  // Holes in the model and the reference intensity, as a ray cast and a colour image leave them, and the
  // cases only one comparison's NaN rule decides: a NaN gradient, NaN in y alone, a point behind the camera.
  cv::RNG rng(9);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  for (int i = 0; i < 3000; ++i) {
    const int x = rng.uniform(0, crop.width), y = rng.uniform(0, crop.height);
    cv::Vec3f& vertex = pair.vertices.at<cv::Vec3f>(y, x);
    switch (i % 5) {
      case 0: vertex = cv::Vec3f(nan, nan, nan); break;
      case 1: ref.grey.at<float>(y, x) = nan; break;
      case 2: ref.dx.at<float>(y, x) = nan; break;
      case 3: vertex[1] = nan; break;
      default: vertex[2] = -vertex[2]; break;
    }
  }
  PhotometricParams params;
  params.sigma = 3.0;
  params.huber = 1.0;  // many residuals down-weighted
  params.min_gradient = 2.0;
  Eigen::Isometry3d colour_motion = Eigen::Isometry3d::Identity();
  colour_motion.linear() = Eigen::AngleAxisd(0.01, Eigen::Vector3d(1, 0.3, -0.2).normalized()).toRotationMatrix();
  colour_motion.translation() = Eigen::Vector3d(0.003, -0.002, 0.001);
  int residuals = 0;
  for (int trial = 0; trial < 20; ++trial) {
    Eigen::Matrix<double, 6, 1> off;
    for (int i = 0; i < 6; ++i) off[i] = rng.uniform(-0.03, 0.03) * (trial < 15 ? 1 : 8);  // some far off the image
    const Eigen::Isometry3d T = step(off, truth());
    const PhotometricAssociator simd(pair.level(), T, params, colour_motion);
    const PhotometricAssociator scalar(pair.level(), T, params, colour_motion, false);
    for (const int stride : {1, 2})
      for (int y = 0; y < crop.height; ++y) {
        const int first = stride == 2 ? y & 1 : 0;
        const PhotometricRowSums a = simd.sumRow(y, first, stride), b = scalar.sumRow(y, first, stride);
        ASSERT_EQ(a.n, b.n) << trial << " " << stride << " " << y;
        ASSERT_EQ(std::memcmp(a.eq.A, b.eq.A, sizeof a.eq.A), 0) << trial << " " << stride << " " << y;
        ASSERT_EQ(std::memcmp(a.eq.b, b.eq.b, sizeof a.eq.b), 0);
        ASSERT_EQ(std::memcmp(&a.r2, &b.r2, sizeof a.r2), 0);
        residuals += a.n;
      }
  }
  EXPECT_GT(residuals, 100000);  // the comparison is not vacuous
}
