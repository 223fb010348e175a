// The AVX2 and scalar builds of ICP's projective association agree bit for bit, and their sums are the
// point-to-plane normal equations that a plain per-pixel loop in double precision builds.
#include <cmath>
#include <cstring>
#include <limits>

#include <Eigen/Dense>
#include <gtest/gtest.h>

#include "vofusion/registration/icp_association.h"

using namespace vofusion;
using namespace vofusion::fusion;

namespace {

constexpr float kNan = std::numeric_limits<float>::quiet_NaN();

CameraIntrinsics camera(int w, int h) {
  CameraIntrinsics c;
  c.width = w, c.height = h, c.fx = c.fy = 0.9f * w, c.cx = 0.5f * w - 0.5f, c.cy = 0.5f * h - 0.5f;
  return c;
}

// A bumpy slanted surface z = f(x, y) seen by `cam` at `pose` (camera-to-world): vertices and normals in
// camera coordinates (world = false) or world coordinates, NaN in holes.
void surfaceMaps(const CameraIntrinsics& cam, const Eigen::Isometry3f& pose, bool world, cv::RNG& rng, cv::Mat& vertices,
                 cv::Mat& normals) {
  vertices.create(cam.height, cam.width, CV_32FC3);
  normals.create(cam.height, cam.width, CV_32FC3);
  for (int v = 0; v < cam.height; ++v)
    for (int u = 0; u < cam.width; ++u) {
      // Depth along the ray, a plane tilted in x plus a bump: close enough to a ray cast's output.
      const float x = (u - cam.cx) / cam.fx, y = (v - cam.cy) / cam.fy;
      const float z = 1.5f + 0.4f * x + 0.05f * std::sin(6.f * y) + float(rng.gaussian(0.002));
      Eigen::Vector3f p(x * z, y * z, z);
      Eigen::Vector3f n = Eigen::Vector3f(0.4f, 0.3f * std::cos(6.f * y), -1.f).normalized();
      if (n.dot(p) > 0) n = -n;
      if (world) {
        p = pose * p;
        n = pose.linear() * n;
      }
      cv::Vec3f& vertex = vertices.at<cv::Vec3f>(v, u);
      cv::Vec3f& normal = normals.at<cv::Vec3f>(v, u);
      vertex = cv::Vec3f(p.x(), p.y(), p.z());
      normal = cv::Vec3f(n.x(), n.y(), n.z());
      // Holes; in the frame's maps also the cases only one comparison's NaN rule decides: NaN in y or z
      // alone (the x test lets it through), a point behind the camera. (A ray cast's model has whole
      // holes only: a model vertex NaN in z alone would put NaN into both builds' sums.)
      const double r = rng.uniform(0.0, 1.0);
      if (r < 0.05) vertex = cv::Vec3f(kNan, kNan, kNan);
      else if (r < 0.07) normal = cv::Vec3f(kNan, kNan, kNan);
      else if (world) continue;
      else if (r < 0.09) vertex[1] = kNan;
      else if (r < 0.11) vertex[2] = kNan;
      else if (r < 0.13) normal[2] = kNan;
      else if (r < 0.15) vertex *= -1.f;
    }
}

Eigen::Isometry3f smallMotion(cv::RNG& rng, double rot, double trans) {
  Eigen::Isometry3f T = Eigen::Isometry3f::Identity();
  const Eigen::Vector3f axis = Eigen::Vector3f(float(rng.gaussian(1)), float(rng.gaussian(1)), float(rng.gaussian(1))).normalized();
  T.linear() = Eigen::AngleAxisf(float(rng.uniform(-rot, rot)), axis).toRotationMatrix();
  T.translation() = Eigen::Vector3f(float(rng.uniform(-trans, trans)), float(rng.uniform(-trans, trans)),
                                    float(rng.uniform(-trans, trans)));
  return T;
}

IcpRowSums sumAll(const IcpAssociator& a, const cv::Mat& v, const cv::Mat& n) {
  IcpRowSums total;
  for (int y = 0; y < v.rows; ++y) {
    total += a.sumRow(v.ptr<cv::Vec3f>(y), n.ptr<cv::Vec3f>(y), v.cols);
  }
  return total;
}

}  // namespace

TEST(IcpAssociation, Avx2AndScalarAgreeBitForBit) {
  if (!IcpAssociator::usesAvx2()) GTEST_SKIP() << "no AVX2 on this CPU: only the scalar build runs";
  cv::RNG rng(7);
  int inliers = 0, rejected = 0;
  for (const int width : {64, 61}) {  // 61: rows that end in a scalar tail
    const CameraIntrinsics cam = camera(width, 48);
    const Eigen::Isometry3f model_pose = smallMotion(rng, 0.2, 0.3);
    cv::Mat mv, mn;
    surfaceMaps(cam, model_pose, true, rng, mv, mn);
    for (int trial = 0; trial < 40; ++trial) {
      // Frames near the model's view and far from it (most pixels off the model or beyond max_distance).
      const Eigen::Isometry3f pose = model_pose * smallMotion(rng, trial < 30 ? 0.05 : 0.6, trial < 30 ? 0.05 : 0.5);
      cv::Mat fv, fn;
      surfaceMaps(cam, pose, false, rng, fv, fn);
      const float truncation = trial % 2 ? 0.01f : 0.f;
      const IcpAssociator simd(mv, mn, cam, model_pose.inverse(), pose, 0.05f, 20.f, truncation);
      const IcpAssociator scalar(mv, mn, cam, model_pose.inverse(), pose, 0.05f, 20.f, truncation, false);
      for (int y = 0; y < fv.rows; ++y) {
        const IcpRowSums a = simd.sumRow(fv.ptr<cv::Vec3f>(y), fn.ptr<cv::Vec3f>(y), fv.cols);
        const IcpRowSums b = scalar.sumRow(fv.ptr<cv::Vec3f>(y), fn.ptr<cv::Vec3f>(y), fv.cols);
        ASSERT_EQ(a.n, b.n) << width << " " << trial << " " << y;
        ASSERT_EQ(a.valid, b.valid);
        ASSERT_EQ(a.in_view, b.in_view);
        ASSERT_EQ(std::memcmp(a.eq.A, b.eq.A, sizeof a.eq.A), 0) << width << " " << trial << " " << y;
        ASSERT_EQ(std::memcmp(a.eq.b, b.eq.b, sizeof a.eq.b), 0);
        ASSERT_EQ(std::memcmp(&a.r2, &b.r2, sizeof a.r2), 0);
        ASSERT_EQ(std::memcmp(&a.r2_truncated, &b.r2_truncated, sizeof a.r2), 0);
        ASSERT_EQ(std::memcmp(&a.d2, &b.d2, sizeof a.d2), 0);
        inliers += a.n;
        rejected += a.in_view - a.n;
      }
    }
  }
  // The comparison is not vacuous: many inliers, and many pixels on the model rejected by distance or angle.
  EXPECT_GT(inliers, 50000);
  EXPECT_GT(rejected, 5000);
}

TEST(IcpAssociation, SumsAreThePointToPlaneNormalEquations) {
  cv::RNG rng(11);
  const CameraIntrinsics cam = camera(80, 60);
  const Eigen::Isometry3f model_pose = smallMotion(rng, 0.2, 0.3);
  const Eigen::Isometry3f pose = model_pose * smallMotion(rng, 0.03, 0.03);
  cv::Mat mv, mn, fv, fn;
  surfaceMaps(cam, model_pose, true, rng, mv, mn);
  surfaceMaps(cam, pose, false, rng, fv, fn);
  const float max_distance = 0.08f, max_angle = 25.f, truncation = 0.01f;
  // The system written out per pixel, in double (decisions in float, as the association makes them).
  Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Zero();
  Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
  double r2 = 0, r2t = 0, d2 = 0;
  int n = 0, valid = 0, in_view = 0;
  const Eigen::Isometry3f model_inv = model_pose.inverse();
  for (int y = 0; y < fv.rows; ++y)
    for (int x = 0; x < fv.cols; ++x) {
      const cv::Vec3f v = fv.at<cv::Vec3f>(y, x), nc = fn.at<cv::Vec3f>(y, x);
      if (std::isnan(v[0]) || std::isnan(nc[0])) continue;
      ++valid;
      const Eigen::Vector3f vg = pose * Eigen::Vector3f(v[0], v[1], v[2]);
      const Eigen::Vector3f pm = model_inv * vg;
      const float uf = cam.fx * pm.x() / pm.z() + cam.cx, vf = cam.fy * pm.y() / pm.z() + cam.cy;
      if (!(pm.z() > 0 && uf > -0.5f && vf > -0.5f && uf < cam.width - 0.5f && vf < cam.height - 0.5f)) continue;
      const cv::Vec3f m = mv.at<cv::Vec3f>(int(vf + 0.5f), int(uf + 0.5f)), mnv = mn.at<cv::Vec3f>(int(vf + 0.5f), int(uf + 0.5f));
      if (std::isnan(m[0]) || std::isnan(mnv[0])) continue;
      ++in_view;
      const Eigen::Vector3d d = (vg - Eigen::Vector3f(m[0], m[1], m[2])).cast<double>();
      const Eigen::Vector3d nm(mnv[0], mnv[1], mnv[2]);
      const Eigen::Vector3d ng = (pose.linear() * Eigen::Vector3f(nc[0], nc[1], nc[2])).cast<double>();
      if (d.norm() > max_distance || ng.dot(nm) < std::cos(max_angle * M_PI / 180)) continue;
      const double r = nm.dot(d);
      Eigen::Matrix<double, 6, 1> J;
      J << (vg - pose.translation()).cast<double>().cross(nm), nm;
      A += J * J.transpose();
      b -= J * r;
      r2 += r * r;
      r2t += std::min(r * r, double(truncation) * truncation);
      d2 += (vg - pose.translation()).cast<double>().squaredNorm();
      ++n;
    }
  ASSERT_GT(n, 2000);
  for (const bool simd : {true, false}) {
    const IcpRowSums s = sumAll(IcpAssociator(mv, mn, cam, model_inv, pose, max_distance, max_angle, truncation, simd), fv, fn);
    EXPECT_NEAR(s.n, n, 2);  // a pixel at a threshold may fall either side in float
    EXPECT_EQ(s.valid, valid);
    EXPECT_NEAR(s.in_view, in_view, 2);
    int k = 0;
    for (int i = 0; i < 6; ++i) {
      for (int j = i; j < 6; ++j, ++k) EXPECT_NEAR(s.eq.A[k], A(i, j), 2e-3 * A.diagonal().maxCoeff()) << i << " " << j;
      EXPECT_NEAR(s.eq.b[i], b[i], 2e-3 * b.cwiseAbs().maxCoeff()) << i;
    }
    EXPECT_NEAR(s.r2, r2, 2e-3 * r2);
    EXPECT_NEAR(s.r2_truncated, r2t, 2e-3 * r2t);
    EXPECT_NEAR(s.d2, d2, 2e-3 * d2);
  }
}
