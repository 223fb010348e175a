// NARF keypoints on a synthetic range image (a box on a wall) and the depth reduction they run on;
// our implementation against PCL's on real depth.
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>

#include <mrpt/config/CConfigFileMemory.h>

#include "support.h"
#include "vofusion/core/errors.h"
#include "vofusion/features/narf_detector.h"
#include "vofusion/features/narf_fast.h"
#include "vofusion/io/tum_source.h"

using namespace vofusion;

namespace {
// Wall at 2 m with a 0.4 m cube standing out of it (front face at 1.6 m) in the image centre.
cv::Mat boxScene(const CameraIntrinsics& cam, cv::Rect* box_px) {
  cv::Mat d(cam.height, cam.width, CV_32F, cv::Scalar(2.0f));
  const double z = 1.6, half = 0.2;
  const int u0 = int(cam.cx - half * cam.fx / z), u1 = int(cam.cx + half * cam.fx / z);
  const int v0 = int(cam.cy - half * cam.fy / z), v1 = int(cam.cy + half * cam.fy / z);
  d(cv::Rect(u0, v0, u1 - u0, v1 - v0)).setTo(float(z));
  *box_px = cv::Rect(u0, v0, u1 - u0, v1 - v0);
  return d;
}

const char* const kImplementations[] = {"fast", "pcl"};

// Keypoints of `a` with one of `b` within `tol` pixels.
int matched(const std::vector<cv::KeyPoint>& a, const std::vector<cv::KeyPoint>& b, float tol) {
  int n = 0;
  for (const auto& k : a)
    for (const auto& o : b)
      if (std::abs(o.pt.x - k.pt.x) <= tol && std::abs(o.pt.y - k.pt.y) <= tol) {
        ++n;
        break;
      }
  return n;
}
}  // namespace

TEST(Narf, DownsampleKeepsNearestReading) {
  cv::Mat d(4, 4, CV_32F, cv::Scalar(0.f));
  d.at<float>(0, 1) = 2.f; d.at<float>(1, 0) = 1.5f;  // block (0,0): nearest valid is 1.5
  d.at<float>(3, 3) = 3.f;                            // block (1,1)
  const cv::Mat s = downsampleDepth(d, 2);
  ASSERT_EQ(s.size(), cv::Size(2, 2));
  EXPECT_FLOAT_EQ(s.at<float>(0, 0), 1.5f);
  EXPECT_FLOAT_EQ(s.at<float>(0, 1), 0.f);
  EXPECT_FLOAT_EQ(s.at<float>(1, 1), 3.f);
}

// A keypoint at its block's centre, as detectNarf places it, reads its block's own nearest reading: the
// one the reduced depth took, for every factor. An even factor's centre falls between pixels, and the
// window about the rounded centre took a row and a column of a neighbouring block (here a nearer
// surface's 1 m or 1.5 m beside a 2 m block, or block (0, 0)'s 1.8 m).
TEST(Narf, AKeypointReadsItsOwnBlocksReading) {
  for (int f = 2; f <= 8; ++f) {
    cv::Mat d(4 * f, 4 * f, CV_32F, cv::Scalar(2.f));
    d.col(f).setTo(1.f);              // the first column of block (1, *)
    d.row(f).setTo(1.5f);             // the first row of block (*, 1)
    d.at<float>(f - 1, f - 1) = 1.8f;  // block (0, 0)'s last pixel
    const cv::Mat reduced = downsampleDepth(d, f);
    for (int by = 0; by < 4; ++by)
      for (int bx = 0; bx < 4; ++bx) {
        const cv::Point2f centre((bx + 0.5f) * f - 0.5f, (by + 0.5f) * f - 0.5f);
        EXPECT_EQ(narfBlockDepth(d, centre, f), reduced.at<float>(by, bx)) << "factor " << f << ", block " << bx << ", " << by;
      }
  }
}

TEST(Narf, KeypointsSitOnTheBoxNotOnTheFlatWall) {
  CameraIntrinsics cam;
  cam = cam.scaled(0.5);  // 320x240 keeps the test quick
  cv::Rect box;
  const cv::Mat depth = boxScene(cam, &box);
  for (const char* impl : kImplementations) {
    SCOPED_TRACE(impl);
    NarfParams p;
    p.implementation = impl;
    p.downsample = 2;
    const auto kps = detectNarf(depth, cam, p);
    ASSERT_FALSE(kps.empty());
    // Interest points mark the box's borders and corners (within the support size, ~0.2 m = 50 px
    // at 1.6 m here), none far out on the featureless wall.
    const cv::Rect near(box.x - 40, box.y - 40, box.width + 80, box.height + 80);
    for (const auto& k : kps) {
      EXPECT_TRUE(near.contains(cv::Point(int(k.pt.x), int(k.pt.y)))) << k.pt;
      EXPECT_GT(k.size, 0.f);
    }
    // Full resolution finds them at the same places (the reduction maps back to full-res pixels).
    p.downsample = 1;
    const auto full = detectNarf(depth, cam, p);
    ASSERT_FALSE(full.empty());
    for (const auto& k : full) EXPECT_TRUE(near.contains(cv::Point(int(k.pt.x), int(k.pt.y)))) << k.pt;
  }
}

TEST(Narf, FlatWallGivesNoKeypoints) {
  CameraIntrinsics cam;
  cam = cam.scaled(0.5);
  const cv::Mat depth(cam.height, cam.width, CV_32F, cv::Scalar(2.0f));
  for (const char* impl : kImplementations) {
    NarfParams p;
    p.implementation = impl;
    p.downsample = 2;
    EXPECT_TRUE(detectNarf(depth, cam, p).empty()) << impl;
  }
}

TEST(Narf, RejectsUnknownImplementation) {
  mrpt::config::CConfigFileMemory cfg;
  cfg.write("narf", "implementation", "magic");
  NarfParams p;
  EXPECT_THROW(p.loadFromConfigFile(cfg, "narf"), InputError);
}

// Ours follows PCL's steps in PCL's float order, so on fr1_xyz its keypoints are PCL's (identical on
// all 300 frames when written); the test asks what matters downstream: at least 90 % of either set
// within one pixel of the reduced image of the other, on 10 frames across the sequence, with all
// keypoints and with the strongest 10 only.
TEST(Narf, FastFindsPclsKeypointsOnRealDepth) {
  const std::string dir = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(dir);
  TumFolderSource src(dir, {});
  for (int max_points : {0, 10}) {
    NarfParams fast, pcl;
    fast.implementation = "fast";
    pcl.implementation = "pcl";
    fast.max_points = pcl.max_points = max_points;
    const float tol = float(fast.downsample);
    int n_fast = 0, n_pcl = 0, fast_in_pcl = 0, pcl_in_fast = 0;
    for (std::size_t frame = 0; frame < 300; frame += 30) {
      const Frame f = src.read(frame);
      const auto a = detectNarf(f.depth, f.camera, fast), b = detectNarf(f.depth, f.camera, pcl);
      n_fast += int(a.size()), n_pcl += int(b.size());
      fast_in_pcl += matched(a, b, tol), pcl_in_fast += matched(b, a, tol);
    }
    SCOPED_TRACE("max_points " + std::to_string(max_points));
    ASSERT_GT(n_pcl, max_points > 0 ? 50 : 200);  // fr1_xyz's desk has plenty
    EXPECT_GE(pcl_in_fast, 0.9 * n_pcl) << pcl_in_fast << " of " << n_pcl << " PCL keypoints matched";
    EXPECT_GE(fast_in_pcl, 0.9 * n_fast) << fast_in_pcl << " of " << n_fast << " fast keypoints matched";
    std::printf("max_points %d: %d fast, %d pcl keypoints; %.1f %% / %.1f %% matched\n", max_points, n_fast, n_pcl,
                100.0 * fast_in_pcl / std::max(1, n_fast), 100.0 * pcl_in_fast / std::max(1, n_pcl));
  }
}

// PCL's NARF interest search on more than one OpenMP thread varies run to run (see narf_detector.cpp);
// neither implementation may, or the odometry's trajectories do. On fr1_xyz reduced as the odometry
// reduces it, two threads change about one frame in ten between two runs: 50 frames catch that but
// for ~0.5 %.
TEST(Narf, DeterministicOnRealDepth) {
  const std::string dir = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(dir);
  TumFolderSource src(dir, {});
  for (const char* impl : kImplementations) {
    SCOPED_TRACE(impl);
    NarfParams p;
    p.implementation = impl;
    for (std::size_t frame = 0; frame < 300; frame += 6) {
      const Frame f = src.read(frame);
      const auto a = detectNarf(f.depth, f.camera, p), b = detectNarf(f.depth, f.camera, p);
      ASSERT_EQ(a.size(), b.size()) << "frame " << frame;
      for (std::size_t k = 0; k < a.size(); ++k) {
        ASSERT_EQ(a[k].pt, b[k].pt) << "frame " << frame;
        ASSERT_EQ(a[k].response, b[k].response) << "frame " << frame;
      }
    }
  }
}

// The interest search's direction cells by comparisons are PCL's acos cells, float for float: at every
// 4099th float of [-1, 1], and at every float between two such where the cell changes (the whole range
// was checked once by hand: 2.1e9 floats, 17 steps, no difference).
namespace {
// The float n floats above x, through the bits as an ordered key (-0 just below +0).
float floatsAfter(float x, std::uint32_t n) {
  std::uint32_t b;
  std::memcpy(&b, &x, sizeof b);
  std::uint32_t key = (b & 0x80000000u) ? ~b : (b | 0x80000000u);
  key += n;
  b = (key & 0x80000000u) ? (key & 0x7fffffffu) : ~key;
  float y;
  std::memcpy(&y, &b, sizeof y);
  return y;
}
}  // namespace

TEST(Narf, DirectionCellsAreAcosCells) {
  const narf::DirectionCells cells;
  int steps = 0;
  float prev = -1.f;
  for (float x = -1.f;;) {
    ASSERT_EQ(cells.cellOf(x), narf::cellOfX(x)) << "x = " << x;
    if (narf::cellOfX(x) != narf::cellOfX(prev)) {  // a step in (prev, x]
      ++steps;
      for (float y = prev; y <= x; y = std::nextafter(y, 2.f)) ASSERT_EQ(cells.cellOf(y), narf::cellOfX(y)) << "y = " << y;
    }
    if (x == 1.f) break;
    prev = x;
    x = std::min(1.f, floatsAfter(x, 4099));
  }
  for (const float x : {-0.f, 0.f}) EXPECT_EQ(cells.cellOf(x), narf::cellOfX(x));
  EXPECT_EQ(steps, 17);  // 8 down to 0 below zero, 17 down to 9 above it
}
