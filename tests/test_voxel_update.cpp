// TSDF integration's per-voxel step: the AVX2 and scalar builds write the same bytes, and the scalar
// one is the running average it promises.
#include <cmath>
#include <cstring>
#include <limits>
#include <vector>

#include <gtest/gtest.h>

#include "vofusion/core/cpu_features.h"
#include "vofusion/fusion/voxel_update.h"

using namespace vofusion;
using namespace vofusion::fusion;

namespace {
// A power of two, and depths on a 2^-12 m grid: depth - z is exact, so a voxel can sit exactly on the
// cut of the update (sdf = -truncation) and of the colour (sdf = +truncation).
constexpr float kTrunc = 0.03125f;
constexpr int kPixels = 64 * 48;

// A row whose voxels see every case: no reading, far behind the surface (skipped), inside the band,
// in front of it beyond the truncation (no colour), exactly on either cut, a NaN or infinite reading,
// on pixel 0 (the gather's exception) and on the image's last pixel.
VoxelRowSamples randomRow(cv::RNG& rng) {
  VoxelRowSamples row;
  for (int x = 0; x < 8; ++x) {
    row.z[x] = std::round(float(rng.uniform(0.3, 3.0)) * 4096.f) / 4096.f;
    const double kind = rng.uniform(0.0, 1.0);
    row.pixel[x] = kind < 0.15 ? -1 : kind < 0.17 ? 0 : kind < 0.19 ? kPixels - 1 : rng.uniform(0, kPixels);
    row.depth[x] = row.pixel[x] < 0 ? std::numeric_limits<float>::quiet_NaN()
                                    : row.z[x] + std::round(float(rng.uniform(-2.5, 2.5)) * 32.f) / 32.f * kTrunc;
    const double special = rng.uniform(0.0, 1.0);
    if (special < 0.05) row.depth[x] = row.z[x] - kTrunc;
    else if (special < 0.10) row.depth[x] = row.z[x] + kTrunc;
    else if (special < 0.11) row.depth[x] = std::numeric_limits<float>::quiet_NaN();
    else if (special < 0.12) row.depth[x] = std::numeric_limits<float>::infinity();
    else if (special < 0.13) row.depth[x] = -std::numeric_limits<float>::infinity();
    if (special < 0.10) {
      EXPECT_EQ(std::abs(row.depth[x] - row.z[x]), kTrunc);  // exactly on a cut
    }
  }
  return row;
}

void randomVoxels(cv::RNG& rng, Voxel* v) {
  for (int x = 0; x < 8; ++x) {
    v[x].tsdf = std::int16_t(rng.uniform(-32767, 32768));
    const double w = rng.uniform(0.0, 1.0);
    v[x].weight = std::uint8_t(w < 0.2 ? 0 : w < 0.3 ? 255 : w < 0.4 ? 64 : rng.uniform(0, 256));
    v[x].r = std::uint8_t(rng.uniform(0, 256)), v[x].g = std::uint8_t(rng.uniform(0, 256)), v[x].b = std::uint8_t(rng.uniform(0, 256));
    if (rng.uniform(0.0, 1.0) < 0.2) v[x].r = v[x].g = v[x].b = 0;  // never painted
  }
}
}  // namespace

TEST(VoxelUpdate, Avx2AndScalarGiveTheSameBytes) {
  if (!cpuHasAvx2()) GTEST_SKIP() << "no AVX2 on this CPU: only the scalar build runs";
  cv::RNG rng(5);
  std::vector<cv::Vec3b> colours(kPixels);
  for (auto& c : colours) c = cv::Vec3b(uchar(rng.uniform(0, 256)), uchar(rng.uniform(0, 256)), uchar(rng.uniform(0, 256)));
  for (std::size_t i = 0; i < colours.size(); i += 7) colours[i] = cv::Vec3b(0, 0, 0);  // no colour
  int updated = 0;
  for (const int max_weight : {64, 255})
    for (const cv::Vec3b* palette : {static_cast<const cv::Vec3b*>(colours.data()), static_cast<const cv::Vec3b*>(nullptr)}) {
      const VoxelUpdater simd(kTrunc, max_weight, palette), scalar(kTrunc, max_weight, palette, false);
      for (int i = 0; i < 20000; ++i) {
        const VoxelRowSamples row = randomRow(rng);
        Voxel a[8], b[8];
        randomVoxels(rng, a);
        std::memcpy(b, a, sizeof a);
        const int na = simd.updateRow(row, a), nb = scalar.updateRow(row, b);
        ASSERT_EQ(na, nb) << i;
        ASSERT_EQ(std::memcmp(a, b, sizeof a), 0) << "row " << i << ", max weight " << max_weight;
        updated += na;
      }
    }
  EXPECT_GT(updated, 4 * 20000 * 3);  // over a third of the voxels are updated: the comparison is not vacuous
}

// Free space seen before the surface (a silhouette's background, a grazing view) raises the weight but
// brings no colour: the first colour is then taken whole, not as c / (weight + 1). It was: red 200 came
// out 18 after ten free-space updates, and at the weight's cap the byte average never caught up (a dark
// fringe along every silhouette of the mesh).
TEST(VoxelUpdate, FreeSpaceBeforeTheSurfaceDoesNotDarkenItsColour) {
  const cv::Vec3b colours[3] = {cv::Vec3b(0, 0, 0), cv::Vec3b(10, 20, 200), cv::Vec3b(0, 0, 0)};  // BGR; pixel 1 (pixel 0 is AVX2's exception)
  for (const bool simd : {false, true}) {
    SCOPED_TRACE(simd ? "AVX2" : "scalar");
    const VoxelUpdater updater(kTrunc, 64, colours, simd);
    VoxelRowSamples row;
    Voxel v[8] = {};
    for (int x = 0; x < 8; ++x) row.z[x] = 1.0f, row.pixel[x] = 1;
    for (int i = 0; i < 10; ++i) {
      for (float& d : row.depth) d = 1.0f + 2.0f * kTrunc;  // free space
      ASSERT_EQ(updater.updateRow(row, v), 8);
    }
    for (float& d : row.depth) d = 1.0f + 0.5f * kTrunc;  // the surface's band
    ASSERT_EQ(updater.updateRow(row, v), 8);
    for (const Voxel& x : v) {
      EXPECT_EQ(x.weight, 11);
      EXPECT_EQ(int(x.r), 200);
      EXPECT_EQ(int(x.g), 20);
      EXPECT_EQ(int(x.b), 10);
    }
    ASSERT_EQ(updater.updateRow(row, v), 8);  // painted once: now the running average
    EXPECT_EQ(int(v[0].r), 200);
    // A black pixel is no colour (one the colour camera did not see): the depth is fused, the colour kept.
    for (int x = 0; x < 8; ++x) row.pixel[x] = 2;
    ASSERT_EQ(updater.updateRow(row, v), 8);
    EXPECT_EQ(v[0].weight, 13);
    EXPECT_EQ(int(v[0].r), 200);
    EXPECT_EQ(int(v[0].g), 20);
  }
}

TEST(VoxelUpdate, ScalarIsTheWeightedRunningAverage) {
  const cv::Vec3b colour(10, 20, 200);  // BGR
  const VoxelUpdater updater(kTrunc, 64, &colour, false);
  VoxelRowSamples row;
  for (int x = 0; x < 8; ++x) row.z[x] = 1.0f, row.pixel[x] = 0, row.depth[x] = 1.0f + 0.5f * kTrunc;  // half the band in front
  row.pixel[7] = -1;                  // no reading: untouched
  row.depth[6] = 1.0f - 1.5f * kTrunc;  // far behind the surface: untouched
  row.depth[5] = 1.0f + 2.0f * kTrunc;  // free space beyond the band: distance 1, no colour
  Voxel v[8];
  for (auto& x : v) x.tsdf = 0, x.weight = 3, x.r = x.g = x.b = 100;
  v[0].weight = 64;  // at the cap
  EXPECT_EQ(updater.updateRow(row, v), 6);
  // tsdf (0 * 3 + 0.5 * 32767) / 4 = 4095.875 -> 4096; each colour (100 * 3 + c) / 4, rounded:
  // red (300 + 200) / 4 = 125, green (300 + 20) / 4 = 80, blue (300 + 10) / 4 = 77.5 -> 78.
  EXPECT_EQ(v[1].tsdf, 4096);
  EXPECT_EQ(v[1].weight, 4);
  EXPECT_EQ(v[1].r, 125);
  EXPECT_EQ(v[1].g, 80);
  EXPECT_EQ(v[1].b, 78);
  EXPECT_EQ(v[0].weight, 64);
  EXPECT_EQ(v[5].tsdf, 8192);  // (0 + 32767) / 4 = 8191.75 -> 8192
  EXPECT_EQ(v[5].r, 100);
  EXPECT_EQ(v[6].weight, 3);
  EXPECT_EQ(v[7].weight, 3);
}
