// BRAND descriptors: self-match under in-plane rotation, the geometric bits, integral-image normals.
#include <random>

#include <opencv2/features2d.hpp>
#include <opencv2/imgproc.hpp>

#include "support.h"
#include "vofusion/features/brand.h"
#include "vofusion/features/keypoint_union.h"

using namespace vofusion;

namespace {
cv::Mat texture(int w, int h, std::uint32_t seed) {
  cv::Mat img(h, w, CV_8U);
  cv::RNG rng(seed);
  rng.fill(img, cv::RNG::UNIFORM, 0, 256);
  cv::GaussianBlur(img, img, cv::Size(0, 0), 3.0);
  cv::normalize(img, img, 0, 255, cv::NORM_MINMAX);
  return img;
}
CameraIntrinsics camera() { return CameraIntrinsics{}; }  // 640x480, f = 525
}  // namespace

TEST(Normals, PlaneFacingTheCameraAndTiltedPlane) {
  const CameraIntrinsics cam = camera();
  cv::Mat depth(480, 640, CV_32F, cv::Scalar(1.5f));
  cv::Mat n = computeNormalMap(depthToPointMap(depth, cam), 4, 0.05f);
  const cv::Vec3f c = n.at<cv::Vec3f>(240, 320);
  EXPECT_NEAR(c[2], -1.0f, 1e-4f);  // faces the camera: -z
  // Plane z = 1.5 + 0.5 x (x in metres): normal ~ (0.5, 0, -1) normalised.
  for (int v = 0; v < 480; ++v)
    for (int u = 0; u < 640; ++u) {
      const double x_over_z = (u - cam.cx) / cam.fx;
      depth.at<float>(v, u) = float(1.5 / (1.0 - 0.5 * x_over_z));
    }
  n = computeNormalMap(depthToPointMap(depth, cam), 4, 0.05f);
  const cv::Vec3f t = n.at<cv::Vec3f>(300, 200);
  const cv::Vec3f expect = cv::normalize(cv::Vec3f(0.5f, 0.f, -1.f));
  EXPECT_GT(t.dot(expect), 0.999f);
}

TEST(Brand, SelfMatchUnderInPlaneRotation) {
  const cv::Mat img = texture(640, 480, 3);
  cv::Mat depth(480, 640, CV_32F, cv::Scalar(1.5f));
  const cv::Mat pts = depthToPointMap(depth, camera());
  const cv::Mat nrm = computeNormalMap(pts, 4, 0.05f);
  std::vector<cv::KeyPoint> kps;
  for (int y = 140; y <= 340; y += 20)
    for (int x = 220; x <= 420; x += 20) kps.emplace_back(float(x), float(y), 10.f);
  BrandExtractor brand;
  for (double angle : {0.0, 20.0, 60.0}) {
    const cv::Mat M = cv::getRotationMatrix2D(cv::Point2f(320, 240), angle, 1.0);
    cv::Mat rot;
    cv::warpAffine(img, rot, M, img.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
    std::vector<cv::KeyPoint> a = kps, b;
    for (const auto& k : kps) {
      const cv::Point2f q(float(M.at<double>(0, 0) * k.pt.x + M.at<double>(0, 1) * k.pt.y + M.at<double>(0, 2)),
                          float(M.at<double>(1, 0) * k.pt.x + M.at<double>(1, 1) * k.pt.y + M.at<double>(1, 2)));
      b.emplace_back(q, 10.f);
    }
    cv::Mat da, db;
    brand.compute(img, pts, nrm, a, da);
    brand.compute(rot, pts, nrm, b, db);
    ASSERT_EQ(a.size(), kps.size());
    ASSERT_EQ(b.size(), kps.size());
    std::vector<cv::DMatch> m;
    cv::BFMatcher(cv::NORM_HAMMING, true).match(da, db, m);
    int correct = 0;
    for (const auto& x : m) correct += x.queryIdx == x.trainIdx;
    // Canonical orientation makes the tests rotate with the image.
    EXPECT_GT(correct, int(0.8 * kps.size())) << "angle " << angle;
  }
}

TEST(Brand, UnorientedDescriptorFailsUnderLargeRotation) {
  // The control for the test above: without the canonical orientation, 60 degrees breaks matching.
  const cv::Mat img = texture(640, 480, 4);
  cv::Mat depth(480, 640, CV_32F, cv::Scalar(1.5f));
  const cv::Mat pts = depthToPointMap(depth, camera());
  const cv::Mat nrm = computeNormalMap(pts, 4, 0.05f);
  BrandParams p;
  p.oriented = false;
  BrandExtractor brand(p);
  std::vector<cv::KeyPoint> a, b;
  const cv::Mat M = cv::getRotationMatrix2D(cv::Point2f(320, 240), 60.0, 1.0);
  for (int y = 140; y <= 340; y += 20)
    for (int x = 220; x <= 420; x += 20) {
      a.emplace_back(float(x), float(y), 10.f);
      b.emplace_back(float(M.at<double>(0, 0) * x + M.at<double>(0, 1) * y + M.at<double>(0, 2)),
                     float(M.at<double>(1, 0) * x + M.at<double>(1, 1) * y + M.at<double>(1, 2)), 10.f);
    }
  cv::Mat rot, da, db;
  cv::warpAffine(img, rot, M, img.size(), cv::INTER_LINEAR, cv::BORDER_REFLECT);
  brand.compute(img, pts, nrm, a, da);
  brand.compute(rot, pts, nrm, b, db);
  std::vector<cv::DMatch> m;
  cv::BFMatcher(cv::NORM_HAMMING, true).match(da, db, m);
  int correct = 0;
  for (const auto& x : m) correct += x.queryIdx == x.trainIdx;
  EXPECT_LT(correct, int(0.5 * a.size()));
}

TEST(Brand, GeometricBitsSeeShapeWhereIntensityIsFlat) {
  // Uniform grey: intensity bits are all 0. A sphere cap in front of a wall sets geometric bits.
  const CameraIntrinsics cam = camera();
  cv::Mat grey(480, 640, CV_8U, cv::Scalar(100));
  cv::Mat depth(480, 640, CV_32F, cv::Scalar(1.5f));
  for (int v = 0; v < 480; ++v)
    for (int u = 0; u < 640; ++u) {
      const double r2 = (u - 320.0) * (u - 320.0) + (v - 240.0) * (v - 240.0);
      if (r2 < 30.0 * 30.0) depth.at<float>(v, u) = float(1.5 - 0.08 * std::sqrt(1.0 - r2 / 900.0));
    }
  const cv::Mat pts = depthToPointMap(depth, cam);
  const cv::Mat nrm = computeNormalMap(pts, 3, 0.05f);
  BrandExtractor brand;
  std::vector<cv::KeyPoint> on{cv::KeyPoint(320, 240, 10)}, off{cv::KeyPoint(120, 120, 10)};
  cv::Mat d_on, d_off;
  brand.compute(grey, pts, nrm, on, d_on);
  brand.compute(grey, pts, nrm, off, d_off);
  ASSERT_EQ(d_on.rows, 1);
  ASSERT_EQ(d_off.rows, 1);
  EXPECT_EQ(cv::countNonZero(d_off), 0);
  EXPECT_GT(cv::norm(d_on, cv::NORM_HAMMING), 10.0);
}

TEST(Brand, KeypointsWithoutDepthAreDropped) {
  const cv::Mat img = texture(640, 480, 5);
  cv::Mat depth(480, 640, CV_32F, cv::Scalar(0.f));
  const cv::Mat pts = depthToPointMap(depth, camera());
  std::vector<cv::KeyPoint> k{cv::KeyPoint(320, 240, 10)};
  cv::Mat d;
  BrandExtractor().compute(img, pts, computeNormalMap(pts, 4, 0.05f), k, d);
  EXPECT_TRUE(k.empty());
  EXPECT_EQ(d.rows, 0);
}

TEST(KeypointUnion, DropsNearDuplicatesOnly) {
  std::vector<cv::KeyPoint> a{cv::KeyPoint(10, 10, 5), cv::KeyPoint(100, 50, 5)};
  std::vector<cv::KeyPoint> b{cv::KeyPoint(12, 11, 5), cv::KeyPoint(104, 50, 5), cv::KeyPoint(300, 300, 5)};
  const auto u = mergeKeypoints(a, b, 3.f);
  ASSERT_EQ(u.size(), 4u);  // (12,11) is within 3 px of (10,10); (104,50) is 4 px away
  EXPECT_EQ(u[2].pt, cv::Point2f(104, 50));
  EXPECT_EQ(mergeKeypoints(a, b, 0.f).size(), 5u);
}

// The point and normal maps are read at the image's pixels: maps of another size (a depth at half the
// colour's resolution) are refused, where a keypoint at (600, 440) read row 440 of a 240-row map.
TEST(Brand, MapsOfAnotherSizeThanTheImageAreRefused) {
  const cv::Mat grey = texture(640, 480, 7);
  const cv::Mat pts = depthToPointMap(cv::Mat(240, 320, CV_32F, cv::Scalar(1.5f)), camera().scaled(0.5));
  const cv::Mat nrm = computeNormalMap(pts, 3, 0.05f);
  std::vector<cv::KeyPoint> kps{cv::KeyPoint(600, 440, 10)};
  cv::Mat d;
  EXPECT_THROW(BrandExtractor().compute(grey, pts, nrm, kps, d), cv::Exception);
}
