// The AVX2 and scalar builds of the voxel projection (TSDF integration's depth lookup) agree bit for
// bit, and a voxel's sample is what the camera model says: its pixel, its depth, the reading there.
#include <cmath>
#include <cstring>
#include <limits>

#include <gtest/gtest.h>

#include "vofusion/fusion/voxel_projection.h"

using namespace vofusion;
using namespace vofusion::fusion;

namespace {
CameraIntrinsics camera() {
  CameraIntrinsics c;
  c.width = 64, c.height = 48, c.fx = c.fy = 60, c.cx = 31.5, c.cy = 23.5;
  return c;
}

// Smooth slopes, steps (where the 4 neighbours disagree), holes and out-of-range readings.
cv::Mat testDepth(cv::RNG& rng) {
  cv::Mat d(48, 64, CV_32F);
  for (int v = 0; v < d.rows; ++v)
    for (int u = 0; u < d.cols; ++u) {
      float z = 1.0f + 0.01f * u + 0.005f * v + (u > 40 ? 0.3f : 0.f);
      const double r = rng.uniform(0.0, 1.0);
      if (r < 0.05) z = 0.f;
      else if (r < 0.07) z = 9.f;
      d.at<float>(v, u) = z;
    }
  return d;
}
}  // namespace

TEST(VoxelProjection, Avx2AndScalarAgreeBitForBit) {
  if (!VoxelProjector::usesAvx2()) GTEST_SKIP() << "no AVX2 on this CPU: only the scalar build runs";
  cv::RNG rng(3);
  const cv::Mat depth = testDepth(rng);
  const VoxelProjector simd(depth, camera(), 0.3f, 3.5f, 0.015f), scalar(depth, camera(), 0.3f, 3.5f, 0.015f, false);
  int valid = 0, compared = 0;
  for (int i = 0; i < 20000; ++i) {
    // Rows from behind the camera to beyond the image edges, in any direction.
    const Eigen::Vector3f first(float(rng.uniform(-1.2, 1.2)), float(rng.uniform(-1.0, 1.0)), float(rng.uniform(-0.1, 2.5)));
    const Eigen::Vector3f step = Eigen::Vector3f(float(rng.uniform(-1.0, 1.0)), float(rng.uniform(-1.0, 1.0)),
                                                 float(rng.uniform(-1.0, 1.0))) * 0.006f;
    VoxelRowSamples a, b;
    simd.sampleRow(first, step, a);
    scalar.sampleRow(first, step, b);
    for (int x = 0; x < 8; ++x) {
      ASSERT_EQ(a.pixel[x], b.pixel[x]) << i << " " << x;
      ASSERT_EQ(std::memcmp(&a.z[x], &b.z[x], sizeof(float)), 0);
      if (a.pixel[x] < 0) continue;
      ++valid;
      ASSERT_EQ(std::memcmp(&a.depth[x], &b.depth[x], sizeof(float)), 0) << i << " " << x << " " << a.depth[x] << " " << b.depth[x];
      ++compared;
    }
  }
  EXPECT_GT(valid, 20000);  // most rows hit the image: the comparison is not vacuous
  EXPECT_EQ(valid, compared);
}

TEST(VoxelProjection, SampleIsTheReadingAtTheVoxelsPixel) {
  cv::RNG rng(5);
  cv::Mat depth = testDepth(rng);
  depth.at<float>(20, 10) = 1.7f;  // a reading in range, whatever the generator left there
  for (const bool simd : {true, false}) {
    const VoxelProjector p(depth, camera(), 0.3f, 3.5f, 0.015f, simd);
    VoxelRowSamples s;
    // Voxel 0 projects exactly onto pixel (10, 20) at 1.5 m; the row runs along +x by 1 mm.
    const float z = 1.5f;
    const Eigen::Vector3f first((10 - 31.5f) * z / 60.f, (20 - 23.5f) * z / 60.f, z);
    p.sampleRow(first, Eigen::Vector3f(0.001f, 0, 0), s);
    EXPECT_EQ(s.pixel[0], 20 * 64 + 10);
    EXPECT_FLOAT_EQ(s.z[3], z);
    EXPECT_NEAR(s.depth[0], 1.7f, 1e-5);
    // Behind the camera: no sample.
    p.sampleRow(Eigen::Vector3f(0, 0, -0.5f), Eigen::Vector3f(0.001f, 0, 0), s);
    for (int x = 0; x < 8; ++x) EXPECT_EQ(s.pixel[x], -1);
  }
}

// A NaN reading beside a voxel's pixel (a caller's missing reading) gives that voxel no NaN depth:
// std::min / _mm256_min_ps drop a NaN that is not their first operand, so the neighbours "agreed" and
// the blend took the NaN in, which the TSDF update read as free space up to the camera.
TEST(VoxelProjection, ANaNNeighbourGivesNoNaNDepth) {
  cv::RNG rng(7);
  cv::Mat depth = testDepth(rng);
  for (int v = 0; v < depth.rows; ++v)
    for (int u = 0; u < depth.cols; ++u)
      if (rng.uniform(0.0, 1.0) < 0.1) depth.at<float>(v, u) = std::numeric_limits<float>::quiet_NaN();
  for (const bool simd : {true, false}) {
    const VoxelProjector p(depth, camera(), 0.3f, 3.5f, 0.015f, simd);
    int valid = 0;
    for (int i = 0; i < 5000; ++i) {
      const Eigen::Vector3f first(float(rng.uniform(-1.2, 1.2)), float(rng.uniform(-1.0, 1.0)), float(rng.uniform(0.5, 2.5)));
      const Eigen::Vector3f step = Eigen::Vector3f(float(rng.uniform(-1.0, 1.0)), float(rng.uniform(-1.0, 1.0)),
                                                   float(rng.uniform(-1.0, 1.0))) * 0.006f;
      VoxelRowSamples s;
      p.sampleRow(first, step, s);
      for (int x = 0; x < 8; ++x) {
        if (s.pixel[x] < 0) continue;
        ++valid;
        ASSERT_TRUE(std::isfinite(s.depth[x])) << (simd ? "AVX2" : "scalar") << " row " << i << " lane " << x;
      }
    }
    EXPECT_GT(valid, 5000) << (simd ? "AVX2" : "scalar");
  }
}
