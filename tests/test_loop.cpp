// Loop closure's parts on their own: keyframe selection, the LSH place index, the MRPT pose graph
// (drift spread over a loop, a false loop removed instead of bending the map), and the loop
// verification on rendered frames of the synthetic loop and look-alike scenes.
#include <cstring>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <csignal>
#include <filesystem>
#include <fstream>
#include <atomic>
#include <functional>
#include <future>
#include <sstream>
#include <random>
#include <thread>

#include <mrpt/config/CConfigFile.h>
#include <opencv2/features2d.hpp>
#include <opencv2/flann.hpp>
#include <mrpt/config/CConfigFileMemory.h>

#include "support.h"
#include "vofusion/core/thread_name.h"
#include "vofusion/loop/keyframe.h"
#include "vofusion/loop/loop_closer.h"
#include "vofusion/loop/keyframe_store.h"
#include "vofusion/loop/loop_verifier.h"
#include "vofusion/tracking/residual_monitor.h"
#include "vofusion/loop/place_index.h"
#include "vofusion/loop/pose_graph.h"
#include "vofusion/odometry/rgbd_odometry.h"
#include "vofusion/sim/synthetic_sequence.h"

using namespace vofusion;
using namespace vofusion::loop;

namespace {

Eigen::Isometry3d pose(double x, double y, double z, double yaw_deg) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() << x, y, z;
  T.linear() = Eigen::AngleAxisd(yaw_deg * M_PI / 180.0, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return T;
}

Eigen::Isometry3d toEigen(const mrpt::poses::CPose3D& p) {
  Eigen::Isometry3d T;
  T.matrix() = p.getHomogeneousMatrixVal<mrpt::math::CMatrixDouble44>().asEigen();
  return T;
}

// A circle of n nodes (radius r) as ground truth, and the poses a tracker with a constant yaw bias
// per step would have measured: drift that grows around the loop.
struct Circle {
  std::vector<Eigen::Isometry3d> truth, tracked;
};
Circle circle(int n, double r, double bias_deg) {
  Circle c;
  for (int i = 0; i < n; ++i) {
    const double a = 360.0 * i / n;
    c.truth.push_back(pose(r * std::cos(a * M_PI / 180), r * std::sin(a * M_PI / 180), 0, a + 90));
  }
  c.tracked.push_back(c.truth[0]);
  for (int i = 1; i < n; ++i) {
    const Eigen::Isometry3d step = c.truth[i - 1].inverse() * c.truth[i];
    c.tracked.push_back(c.tracked.back() * step * pose(0, 0, 0, bias_deg));
  }
  return c;
}

PoseGraph graphOf(const Circle& c) {
  PoseGraph g;
  for (std::size_t i = 0; i < c.tracked.size(); ++i) {
    g.addNode(c.tracked[i]);
    if (i == 0) continue;
    GraphEdge e;
    e.from = i - 1;
    e.to = i;
    e.T_from_to = c.tracked[i - 1].inverse() * c.tracked[i];
    e.information = odometryInformation(e.T_from_to, kOdometrySigmaRate, kOdometrySigmaFloor);
    g.addEdge(e);
  }
  return g;
}

// sigma: the loop's noise, m and rad (ICP's 3 mm floor by default).
GraphEdge loopEdge(std::size_t from, std::size_t to, const Eigen::Isometry3d& T, double sigma = 0.003) {
  GraphEdge e;
  e.from = from;
  e.to = to;
  e.T_from_to = T;
  e.loop = true;
  e.information = Matrix6::Identity();
  for (int i = 0; i < 3; ++i) e.information(i, i) = 1.0 / (sigma * sigma), e.information(i + 3, i + 3) = 1.0 / (sigma * sigma);
  return e;
}

double maxError(const PoseGraph& g, const Circle& c) {
  double worst = 0.0;
  for (std::size_t i = 0; i < c.truth.size(); ++i)
    worst = std::max(worst, (g.pose(i).translation() - c.truth[i].translation()).norm());
  return worst;
}

}  // namespace

TEST(LoopKeyframes, MadeByMotionAndAfterRecovery) {
  LoopParams P;
  P.keyframe_translation = 0.1;
  P.keyframe_rotation = 10.0;
  KeyframeSelector s(P);
  EXPECT_TRUE(s.next(pose(0, 0, 0, 0), true));       // the first well-tracked frame
  EXPECT_FALSE(s.next(pose(0.05, 0, 0, 0), true));   // moved too little
  EXPECT_TRUE(s.next(pose(0.12, 0, 0, 0), true));    // moved enough
  EXPECT_FALSE(s.next(pose(0.12, 0, 0, 5), true));   // turned too little
  EXPECT_TRUE(s.next(pose(0.12, 0, 0, 11), true));   // turned enough
  EXPECT_FALSE(s.next(pose(0.13, 0, 0, 11), false)); // not well tracked: never
  EXPECT_TRUE(s.next(pose(0.14, 0, 0, 11), true));   // the first good frame after a bad one
  EXPECT_NEAR(s.pathLength(), 0.14, 1e-9);
}

// A pose that is not a number is a frame not well tracked: it made the path NaN (no keyframe joined the
// place index again) and became a keyframe whose NaN spread down the pose graph's chain.
TEST(LoopKeyframes, APoseThatIsNotANumberIsNoKeyframeAndNoPath) {
  LoopParams P;
  P.keyframe_translation = 0.1;
  KeyframeSelector s(P);
  EXPECT_TRUE(s.next(pose(0, 0, 0, 0), true));
  EXPECT_FALSE(s.next(pose(std::nan(""), 0, 0, 0), true));
  EXPECT_TRUE(s.next(pose(0.05, 0, 0, 0), true)) << "the first good frame after it";
  EXPECT_NEAR(s.pathLength(), 0.05, 1e-9);
}

// Strained frames (tracked, residual standing out) become keyframes by motion as any other, so a loop can
// observe the drift where it comes out; the edge that spans them is the weak kind.
TEST(LoopKeyframes, StrainedFramesAreKeyframesWithAWeakEdge) {
  LoopParams P;
  P.keyframe_translation = 0.1;
  P.keyframe_rotation = 10.0;
  KeyframeSelector s(P);
  EXPECT_TRUE(s.next(pose(0, 0, 0, 0), true, true));  // the first keyframe has no edge to weaken
  EXPECT_FALSE(s.lastAfterPoorTracking());
  EXPECT_FALSE(s.next(pose(0.05, 0, 0, 0), true, true));  // strained, but moved too little
  EXPECT_TRUE(s.next(pose(0.12, 0, 0, 0), true));          // moved enough; its edge spans a strained frame
  EXPECT_TRUE(s.lastAfterPoorTracking());
  EXPECT_TRUE(s.next(pose(0.24, 0, 0, 0), true, true));    // a strained frame that moved enough
  EXPECT_TRUE(s.lastAfterPoorTracking());
  EXPECT_FALSE(s.next(pose(0.26, 0, 0, 0), true));         // no keyframe forced after strained frames
  EXPECT_TRUE(s.next(pose(0.36, 0, 0, 0), true));
  EXPECT_FALSE(s.lastAfterPoorTracking());
}

// A burst of frames whose ICP residual stands out from the recent ones is strained; a residual that
// rises slowly (farther walls, more noise) is not, and frames without ICP never are.
TEST(LoopKeyframes, ResidualBurstIsStrainedSlowRiseIsNot) {
  ResidualMonitor m(2.0);
  for (int i = 0; i < 60; ++i) EXPECT_FALSE(m.strained(0.003 + 0.0001 * (i % 3)));
  int strained = 0;
  for (int i = 0; i < 20; ++i) strained += m.strained(0.012);  // the map met twice: 4x the median
  EXPECT_EQ(strained, 20);
  EXPECT_FALSE(m.strained(0.0035));
  EXPECT_FALSE(m.strained(0.0));
  ResidualMonitor slow(2.0);
  for (int i = 0; i < 600; ++i) EXPECT_FALSE(slow.strained(0.003 * std::pow(1.003, i))) << i;  // x6 over 20 s
  ResidualMonitor off(0.0);
  for (int i = 0; i < 30; ++i) EXPECT_FALSE(off.strained(i < 20 ? 0.003 : 0.1));
}

TEST(LoopKeyframes, DepthReducedWithMatchingIntrinsics) {
  sim::SimOptions o;
  o.frames = 2;
  o.noise = false;
  const sim::SyntheticSequence seq(o);
  const Frame f = seq.render(0);
  const Keyframe k = makeKeyframe(0, f, Eigen::Isometry3d::Identity(), 0.0, nullptr, 4);
  ASSERT_EQ(k.depth.cols, f.depth.cols / 4);
  const cv::Mat metres = k.depthMetres();
  // A reduced pixel back-projects to the same 3D point as the full-resolution pixel it was taken from.
  for (const cv::Point p : {cv::Point(10, 7), cv::Point(100, 50), cv::Point(150, 110)}) {
    const float z = metres.at<float>(p);
    const cv::Point full(p.x * 4, p.y * 4);
    ASSERT_GT(z, 0.0f);
    ASSERT_NEAR(z, f.depth.at<float>(full), 1e-4);  // kept in 0.2 mm steps
    EXPECT_NEAR((p.x - k.camera.cx) / k.camera.fx, (full.x - f.camera.cx) / f.camera.fx, 1e-9);
    EXPECT_NEAR((p.y - k.camera.cy) / k.camera.fy, (full.y - f.camera.cy) / f.camera.fy, 1e-9);
  }
}

TEST(LoopPlaceIndex, FindsTheKeyframeWhoseDescriptorsReturn) {
  LoopParams P;
  PlaceIndex index(P);
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> byte(0, 255);
  std::vector<cv::Mat> kf;
  for (int k = 0; k < 40; ++k) {
    cv::Mat d(300, 32, CV_8U);
    for (int i = 0; i < d.rows; ++i)
      for (int j = 0; j < 32; ++j) d.at<uchar>(i, j) = uchar(byte(rng));
    index.add(std::size_t(k), d);
    kf.push_back(d);
  }
  for (const int k : {5, 37}) {
    cv::Mat q = kf[std::size_t(k)].clone();
    std::uniform_int_distribution<int> bit(0, 255);
    for (int i = 0; i < q.rows; ++i)
      for (int f = 0; f < 12; ++f) {  // 12 flipped bits: a noisy re-observation
        const int b = bit(rng);
        q.at<uchar>(i, b / 8) ^= uchar(1 << (b % 8));
      }
    const auto c = index.query(q);
    ASSERT_FALSE(c.empty()) << "keyframe " << k;
    EXPECT_EQ(c[0].keyframe, std::size_t(k));
    EXPECT_GT(c[0].votes, 150);
  }
  cv::Mat unrelated(300, 32, CV_8U);
  for (int i = 0; i < unrelated.rows; ++i)
    for (int j = 0; j < 32; ++j) unrelated.at<uchar>(i, j) = uchar(byte(rng));
  EXPECT_TRUE(index.query(unrelated).empty());  // random bytes are ~128 bits apart: no votes
}

// A place seen again splits its votes between neighbouring indexed keyframes: together they make a
// candidate, named by the better-voted one; the same votes on keyframes far apart along the path do not.
TEST(LoopPlaceIndex, APlaceIsAKeyframeWithItsNeighboursInTheIndex) {
  LoopParams P;
  ASSERT_EQ(P.min_votes, 20);
  PlaceIndex index(P);
  std::mt19937 rng(5);
  std::uniform_int_distribution<int> byte(0, 255), bit(0, 255);
  const auto random = [&](int rows) {
    cv::Mat d(rows, 32, CV_8U);
    for (int i = 0; i < d.rows; ++i)
      for (int j = 0; j < 32; ++j) d.at<uchar>(i, j) = uchar(byte(rng));
    return d;
  };
  std::vector<cv::Mat> kf;
  for (int k = 0; k < 40; ++k) {
    kf.push_back(random(300));
    index.add(std::size_t(100 + k), kf.back());
  }
  // 16 re-observed descriptors (3 bits flipped) of each of two keyframes, the rest unrelated.
  const auto query = [&](int a, int b, const std::function<bool(std::size_t)>& usable = nullptr) {
    cv::Mat q = random(300);
    for (int i = 0; i < 32; ++i) {
      const cv::Mat& from = kf[std::size_t(i < 16 ? a : b)];
      from.row(i * 7).copyTo(q.row(i * 9));
      for (int f = 0; f < 3; ++f) {
        const int x = bit(rng);
        q.at<uchar>(i * 9, x / 8) ^= uchar(1 << (x % 8));
      }
    }
    return index.query(q, usable);
  };
  const auto together = query(10, 11);
  ASSERT_FALSE(together.empty());
  EXPECT_TRUE(together[0].keyframe == 110 || together[0].keyframe == 111) << together[0].keyframe;
  EXPECT_GE(together[0].votes, P.min_votes);
  EXPECT_LE(together[0].votes, 32);
  // Split either side of a keyframe that got none (blurred, or turned a little away): one place still,
  // the one centred on it (each side's own window held 16).
  const auto around = query(10, 12);
  ASSERT_FALSE(around.empty());
  EXPECT_TRUE(around[0].keyframe == 110 || around[0].keyframe == 112) << around[0].keyframe;
  EXPECT_GE(around[0].votes, P.min_votes);
  // A keyframe lost from the spill file names no place: its neighbour with votes does (it named the
  // place, and every visit spent a candidate on reading it again and refusing it).
  const std::size_t named = around[0].keyframe, other = named == 110 ? 112 : 110;
  const auto usable = query(10, 12, [&](std::size_t k) { return k != named; });
  ASSERT_FALSE(usable.empty());
  EXPECT_EQ(usable[0].keyframe, other);
  // A place whose only keyframe with votes is lost is none.
  ASSERT_FALSE(index.query(kf[10].rowRange(0, 40).clone()).empty());
  EXPECT_TRUE(index.query(kf[10].rowRange(0, 40).clone(), [](std::size_t k) { return k != 110; }).empty());
  EXPECT_TRUE(query(10, 30).empty());
}

// The compact index finds the nearest neighbours that OpenCV's FLANN LSH index (same tables, key
// size and probe level) finds, on correlated descriptors like BRAND's; what either finds is never
// nearer than the brute-force nearest.
TEST(LoopPlaceIndex, FindsWhatFlannLshFinds) {
  LoopParams P;
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> byte(0, 255), bit(0, 255);
  // 60 keyframes of 300 descriptors: each a shared pattern with a third of its bytes random.
  cv::Mat train(0, 32, CV_8U);
  PlaceIndex index(P);
  for (int k = 0; k < 60; ++k) {
    cv::Mat d(300, 32, CV_8U);
    for (int i = 0; i < d.rows; ++i)
      for (int j = 0; j < 32; ++j) d.at<uchar>(i, j) = byte(rng) < 170 ? uchar((j * 37 + (i % 40) * 11) & 0xff) : uchar(byte(rng));
    index.add(std::size_t(k), d);
    train.push_back(d);
  }
  cv::FlannBasedMatcher flann(cv::makePtr<cv::flann::LshIndexParams>(P.lsh_tables, P.lsh_key_bits, P.lsh_probe_level));
  flann.add(std::vector<cv::Mat>{train});
  flann.train();
  cv::BFMatcher brute(cv::NORM_HAMMING);
  // Queries: 1000 indexed descriptors with 6 bits flipped (a re-observation).
  cv::Mat q(1000, 32, CV_8U);
  for (int i = 0; i < q.rows; ++i) {
    train.row(int(rng() % std::uint32_t(train.rows))).copyTo(q.row(i));
    for (int f = 0; f < 6; ++f) {
      const int b = bit(rng);
      q.at<uchar>(i, b / 8) ^= uchar(1 << (b % 8));
    }
  }
  std::vector<cv::DMatch> truth, by_flann;
  brute.match(q, train, truth);
  std::vector<std::vector<cv::DMatch>> nn;
  flann.knnMatch(q, nn, 1);
  int ours_right = 0, flann_right = 0;
  for (int i = 0; i < q.rows; ++i) {
    const auto [row, dist] = index.nearest(q.ptr<std::uint8_t>(i));
    if (row >= 0) {
      ASSERT_GE(dist, int(truth[std::size_t(i)].distance));
      ASSERT_EQ(dist, int(cv::norm(q.row(i), train.row(row), cv::NORM_HAMMING)));
      ours_right += dist == int(truth[std::size_t(i)].distance);
    }
    if (!nn[std::size_t(i)].empty()) flann_right += nn[std::size_t(i)][0].distance == truth[std::size_t(i)].distance;
  }
  std::printf("nearest found: compact index %d / 1000, FLANN LSH %d / 1000\n", ours_right, flann_right);
  EXPECT_GE(ours_right, flann_right - 30);
  EXPECT_GT(ours_right, 800);
  EXPECT_EQ(index.descriptors(), 60u * 300u);
}

// Each keyframe with a loop is solved as it comes up to 1000 keyframes (every scene measured); beyond,
// the loops of nodes / 500 keyframes at once: on an hour's walk (~12 000 keyframes) a solve per loop
// cost 1.3 s of CPU each, more than the loop thread's core at a loop every few keyframes.
TEST(LoopPoseGraph, LongGraphsAreSolvedInBatchesShortOnesAtEveryLoop) {
  const auto solves = [](std::size_t from, std::size_t to) {  // one loop at every keyframe in [from, to)
    std::size_t n = 0, unsolved = 0, solved_at = from;
    for (std::size_t nodes = from + 1; nodes <= to; ++nodes) {
      ++unsolved;
      if (graphSolveDue(unsolved, nodes, solved_at)) ++n, unsolved = 0, solved_at = nodes;
    }
    return n;
  };
  EXPECT_EQ(solves(0, 999), 999u);
  EXPECT_EQ(solves(2000, 2400), 100u);     // every 4th
  EXPECT_EQ(solves(10000, 10400), 20u);    // every 20th
  EXPECT_FALSE(graphSolveDue(0, 600, 10));  // no loop, no solve
}

TEST(LoopPoseGraph, TrueLoopSpreadsTheDrift) {
  const Circle c = circle(40, 3.0, 0.4);  // 16 deg of yaw drift around the loop
  PoseGraph g = graphOf(c);
  const double before = maxError(g, c);
  g.addEdge(loopEdge(0, 39, c.truth[0].inverse() * c.truth[39]));
  EXPECT_TRUE(g.optimise(kMaxLoopChi2, kMaxChainChi2).empty());
  const double after = maxError(g, c);
  std::printf("circle of 40 keyframes: max error %.3f m tracked, %.3f m optimised\n", before, after);
  EXPECT_GT(before, 0.5);
  EXPECT_LT(after, 0.25 * before);
  EXPECT_LT((g.pose(39).translation() - c.truth[39].translation()).norm(), 0.05);
}

// A straight path of keyframes 1 m apart, the cameras looking sideways (their x along the path): the
// tracker measured it 10 cm too long. One edge says it is unsure along the camera's x; a loop gives the
// true length. Only an optimiser that weighs each residual by its information puts the correction there.
TEST(LoopPoseGraph, AnEdgeUnsureAlongTheCameraTakesTheCorrectionAlongIt) {
  PoseGraph g;
  const int n = 6, unsure = 3;
  for (int i = 0; i < n; ++i) g.addNode(pose(0, i + (i >= unsure ? 0.1 : 0.0), 0, 90));
  for (int i = 1; i < n; ++i) {
    GraphEdge e;
    e.from = i - 1;
    e.to = i;
    e.T_from_to = g.pose(i - 1).inverse() * g.pose(i);
    Matrix6 cov = Matrix6::Identity() * 1e-6;  // 1 mm, 1 mrad
    if (i == unsure) cov(0, 0) = 0.05 * 0.05;    // 5 cm along the camera's x: the world's y, the path
    e.information = cov.inverse();
    g.addEdge(e);
  }
  g.addEdge(loopEdge(0, n - 1, pose(0, 0, 0, 90).inverse() * pose(0, n - 1, 0, 90)));
  EXPECT_TRUE(g.optimise(1e6, 1e6).empty());
  const double step = (g.pose(unsure).translation() - g.pose(unsure - 1).translation()).norm();
  EXPECT_NEAR(step, 1.0, 0.001) << "the unsure edge took the 10 cm";
  EXPECT_NEAR((g.pose(n - 1).translation() - g.pose(0).translation()).norm(), n - 1, 0.001);  // the loop's 3 mm against 5 cm
  for (int i = 1; i < n; ++i) {
    if (i != unsure) {
      EXPECT_NEAR((g.pose(i).translation() - g.pose(i - 1).translation()).norm(), 1.0, 0.001);
    }
  }
}

TEST(LoopPoseGraph, FalseLoopRemovedNotBentAround) {
  const Circle c = circle(40, 3.0, 0.05);  // little drift
  PoseGraph g = graphOf(c);
  const double before = maxError(g, c);
  g.addEdge(loopEdge(0, 39, c.truth[0].inverse() * c.truth[39]));          // true
  const std::size_t bad = g.addEdge(loopEdge(10, 30, pose(0.3, 0, 0, 0)));  // 10 and 30 are 6 m apart
  const std::vector<std::size_t> removed = g.optimise(kMaxLoopChi2, kMaxChainChi2);
  ASSERT_EQ(removed.size(), 1u);
  EXPECT_EQ(removed[0], bad);
  EXPECT_FALSE(g.edges()[bad].active);
  EXPECT_LE(maxError(g, c), before + 1e-3);
}

// A crisp false loop beside less certain true ones: the loop removed is the one whose removal leaves the
// graph consistent, not the one with the largest chi2 of its own. A loop's own chi2 is its conflict
// over its certainty, so the less certain true loop scored worse, went, and the false one (0.5 m off)
// bent the map.
TEST(LoopPoseGraph, ATrueLoopIsNotDroppedForACrisperFalseOne) {
  const Circle c = circle(40, 3.0, 0.4);
  const Eigen::Isometry3d false_loop = c.truth[1].inverse() * c.truth[37] * pose(0.5, 0, 0, 0);
  for (const int true_loops : {1, 2, 3}) {
    PoseGraph g = graphOf(c);
    const double before = maxError(g, c);
    for (int k = 0; k < true_loops; ++k)
      g.addEdge(loopEdge(std::size_t(k), std::size_t(39 - k), c.truth[k].inverse() * c.truth[39 - k], 0.006));
    const std::size_t bad = g.addEdge(loopEdge(1, 37, false_loop, 0.003));
    EXPECT_EQ(g.optimise(kMaxLoopChi2, kMaxChainChi2), std::vector<std::size_t>{bad}) << true_loops << " true loops";
    EXPECT_LT(maxError(g, c), 0.25 * before) << true_loops << " true loops";
  }
}

// A loop edge of NaNs (a damaged pose) is the one removed: its chi2 lost every comparison, so the true
// loop beside it was removed as the worst, and the drift stayed.
TEST(LoopPoseGraph, ALoopOfNaNsIsRemovedNotTheTrueOne) {
  const Circle c = circle(40, 3.0, 0.4);
  PoseGraph g = graphOf(c);
  const double before = maxError(g, c);
  g.addEdge(loopEdge(0, 39, c.truth[0].inverse() * c.truth[39]));
  Eigen::Isometry3d broken = Eigen::Isometry3d::Identity();
  broken.translation().x() = std::nan("");
  const std::size_t bad = g.addEdge(loopEdge(10, 30, broken));
  EXPECT_EQ(g.optimise(kMaxLoopChi2, kMaxChainChi2), std::vector<std::size_t>{bad});
  EXPECT_LT(maxError(g, c), 0.25 * before);
}

TEST(LoopPoseGraph, NewNodesFollowTheirOptimisedPredecessor) {
  const Circle c = circle(20, 2.0, 0.5);
  PoseGraph g = graphOf(c);
  g.addEdge(loopEdge(0, 19, c.truth[0].inverse() * c.truth[19]));
  g.optimise(kMaxLoopChi2, kMaxChainChi2);
  const Eigen::Isometry3d step = pose(0.1, 0, 0, 0);
  const std::size_t n = g.addNode(c.tracked[19] * step);
  GraphEdge e;
  e.from = 19;
  e.to = n;
  e.T_from_to = step;
  g.addEdge(e);
  g.chainNewNode(n);
  EXPECT_TRUE(g.pose(n).isApprox(g.pose(19) * step, 1e-9));
  // A loop edge into it, newer than its tracker edge, does not place it: the search for its tracker
  // edge runs from the newest edge back, where the loops verified after it come.
  g.addEdge(loopEdge(3, n, pose(5.0, 0, 0, 0)));
  g.chainNewNode(n);
  EXPECT_TRUE(g.pose(n).isApprox(g.pose(19) * step, 1e-9));
}

namespace {

// A keyframe of frame i of `seq`, described by the odometry, with `tracked` as its pose.
Keyframe keyframeOf(const sim::SyntheticSequence& seq, std::size_t i, const Eigen::Isometry3d& tracked,
                    double path_length, std::size_t id) {
  OdometryParams op;
  RgbdOdometry odo(op);
  const Frame f = seq.render(i);
  const OdometryResult r = odo.process(f);
  EXPECT_TRUE(r.features) << "frame " << i;
  return makeKeyframe(id, f, tracked, path_length, r.features, LoopParams().keyframe_downsample);
}

}  // namespace

// The loop scene's first frame and the frame one lap later see the same place: verified, with the
// relative pose of the ground truth, although the tracked pose has drifted by 20 cm and 4 degrees.
// Full resolution: at 320x240 the detector finds ~30 keypoints a frame, too few to recognise a place.
TEST(LoopVerifier, SamePlaceAfterALapIsAcceptedWithTheTruePose) {
  sim::SimOptions o;
  o.scene = "loop";
  o.frames = 230;  // 1.15 laps: frame 200 is one lap after frame 0
  const sim::SyntheticSequence seq(o);
  const Eigen::Isometry3d t0 = toEigen(seq.groundTruth(0)), t1 = toEigen(seq.groundTruth(200));
  const Eigen::Isometry3d drifted = t0.inverse() * t1 * pose(0.2, 0, 0, 4);  // relative pose as tracked
  const Keyframe older = keyframeOf(seq, 0, Eigen::Isometry3d::Identity(), 0.0, 0);
  const Keyframe newer = keyframeOf(seq, 200, drifted, 26.0, 1);
  PyramidCache pyramids(2);
  const LoopCheck c = verifyLoop(older, newer, LoopParams(), pyramids);
  ASSERT_TRUE(c.accepted) << c.reason << " (" << c.matches << " matches, " << c.inliers << " inliers, ICP overlap "
                          << c.icp_overlap << ", rms " << c.icp_rms << ")";
  const auto [dt, dr] = poseDifference(c.T_old_new, t0.inverse() * t1);
  std::printf("loop verified: %d inliers, ICP rms %.4f m, error vs truth %.4f m %.3f deg, correction %.3f m\n", c.inliers,
              c.icp_rms, dt, dr, c.correction_m);
  // Measured 9.7 mm / 0.17 deg: the view reaches 5 m down the corridor, where depth noise is ~4 cm.
  EXPECT_LT(dt, 0.015);
  EXPECT_LT(dr, 0.5);
  EXPECT_NEAR(c.correction_m, 0.2, 0.05);
  // The covariance the graph takes is isotropic in translation and in rotation, so its axes' order
  // (the graph's: translation, rotation vector; a fit's: x y z yaw pitch roll) cannot mix them up.
  const Eigen::Matrix<double, 6, 6> cov = c.covariance;
  const Eigen::Matrix<double, 6, 6> diagonal = cov.diagonal().asDiagonal();
  EXPECT_TRUE(cov == diagonal);
  EXPECT_GT(cov(0, 0), 0.0);
  EXPECT_GT(cov(3, 3), 0.0);
  for (int i = 1; i < 3; ++i) {
    EXPECT_EQ(cov(i, i), cov(0, 0));
    EXPECT_EQ(cov(i + 3, i + 3), cov(3, 3));
  }
  // Verified again through the same cache: both pyramids are reused, the answer is the same.
  EXPECT_EQ(pyramids.misses(), 2u);
  const LoopCheck again = verifyLoop(older, newer, LoopParams(), pyramids);
  EXPECT_EQ(pyramids.hits(), 2u);
  EXPECT_TRUE(again.accepted);
  EXPECT_TRUE(again.T_old_new.isApprox(c.T_old_new, 1e-12));
  // A third keyframe evicts the least recently used pyramid (capacity 2), `newer`'s, which is made again
  // when it is next verified.
  const Keyframe third = keyframeOf(seq, 202, drifted, 26.2, 2);
  verifyLoop(older, third, LoopParams(), pyramids);
  EXPECT_EQ(pyramids.misses(), 3u);
  verifyLoop(newer, third, LoopParams(), pyramids);
  EXPECT_EQ(pyramids.misses(), 4u);
}

// Keyframes beyond the RAM budget go to disk and come back bit for bit; the newest always stays in RAM.
TEST(LoopKeyframeStore, SpilledKeyframesComeBackWhole) {
  sim::SimOptions o;
  o.scene = "loop";
  o.frames = 30;
  const sim::SyntheticSequence seq(o);
  const std::vector<std::size_t> frames = {0, 10, 20};
  std::vector<Keyframe> made;
  KeyframeStore store(0, test::tempDir("keyframe_spill"));  // no budget: all but the newest spilled
  for (std::size_t i = 0; i < frames.size(); ++i) {
    made.push_back(keyframeOf(seq, frames[i], pose(0.1 * double(i), 0, 0, 0), 0.1 * double(i), i));
    store.add(made.back());
  }
  const KeyframeStoreStats st = store.stats();
  EXPECT_EQ(st.keyframes, 3u);
  EXPECT_EQ(st.spilled, 2u);
  EXPECT_EQ(st.in_ram, 1u);
  EXPECT_GT(st.spill_file_bytes, 0u);
  EXPECT_TRUE(store.at(0).depth.empty());   // its RAM is released...
  EXPECT_FALSE(store.at(0).features);
  EXPECT_FALSE(store.back().depth.empty());
  for (std::size_t i = 0; i < frames.size(); ++i) {
    const Keyframe k = store.load(i);          // ...and load() reads it back
    EXPECT_TRUE(k.tracked.isApprox(made[i].tracked));
    EXPECT_EQ(k.frame_index, made[i].frame_index);
    ASSERT_EQ(k.depth.size(), made[i].depth.size());
    EXPECT_EQ(cv::norm(k.depth, made[i].depth, cv::NORM_INF), 0.0);
    ASSERT_TRUE(k.features);
    ASSERT_EQ(k.features->descriptors.rows, made[i].features->descriptors.rows);
    EXPECT_EQ(cv::norm(k.features->descriptors, made[i].features->descriptors, cv::NORM_HAMMING), 0.0);
    ASSERT_EQ(k.features->points.size(), made[i].features->points.size());
    for (std::size_t j = 0; j < k.features->points.size(); ++j) ASSERT_EQ(k.features->points[j], made[i].features->points[j]);
  }
  EXPECT_EQ(store.stats().reloaded, 2u);
  // What a checkpoint writes of each: the bytes encodeKeyframeData makes, a spilled one's record as
  // stored (not read back and decoded).
  for (std::size_t i = 0; i < frames.size(); ++i) EXPECT_EQ(store.data(i), encodeKeyframeData(made[i])) << "keyframe " << i;
  EXPECT_EQ(store.stats().reloaded, 2u);
  // A record cut short is an error, not a keyframe with garbage in it.
  std::vector<std::uint8_t> bytes = encodeKeyframeData(made[0]);
  bytes.resize(bytes.size() / 2);
  Keyframe k;
  EXPECT_THROW(decodeKeyframeData(bytes, k), std::runtime_error);
  // So is a point count that differs from the descriptors' (matching read points past the end).
  bytes = encodeKeyframeData(made[0]);
  const std::size_t npoints = made[0].features->points.size();
  ASSERT_GT(npoints, 0u);
  const std::size_t at = bytes.size() - npoints * sizeof(Eigen::Vector3d) - sizeof(std::uint64_t);
  const std::uint64_t fewer = npoints - 1;
  std::memcpy(bytes.data() + at, &fewer, sizeof(fewer));
  EXPECT_THROW(decodeKeyframeData(bytes, k), std::runtime_error);
  // Descriptors of another width than 32 bytes (the place index threw on them, ending the loop thread),
  // and bytes past the record's end (another layout under the same tag).
  // A record consistent in itself, a point for each 16-byte row, as a caller's own descriptors make.
  Keyframe narrow = made[0];
  auto features = std::make_shared<DescribedKeypoints>(*made[0].features);
  features->descriptors = made[0].features->descriptors.colRange(0, 16).clone();
  narrow.features = features;
  bytes = encodeKeyframeData(narrow);
  EXPECT_THROW(decodeKeyframeData(bytes, k), std::runtime_error);
  bytes = encodeKeyframeData(made[0]);
  bytes.push_back(0);
  EXPECT_THROW(decodeKeyframeData(bytes, k), std::runtime_error);
  // And a depth size its compressed bytes cannot hold, before it asks for the memory.
  bytes = encodeKeyframeData(made[0]);
  const std::int32_t huge = 1 << 30;
  std::memcpy(bytes.data(), &huge, sizeof(huge));
  // (The size check's own message: inflating into such a buffer fails as "corrupt depth" after asking.
  // An allocation limit would not tell them apart: cv::Mat allocates past operator new.)
  try {
    decodeKeyframeData(bytes, k);
    ADD_FAILURE() << "a 2^30-row depth was read";
  } catch (const std::runtime_error& e) {
    EXPECT_EQ(std::string(e.what()), "corrupt record in the keyframes' spill file");
  }
}

// A spill file that cannot be written (a file size limit, as a full disk) keeps every later keyframe in
// RAM, reported once in spill_error, instead of stopping the loop closer and the run with it; the
// keyframes spilled before stay readable.
TEST(LoopKeyframeStore, ASpillFileThatCannotBeWrittenKeepsTheKeyframesInRam) {
  sim::SimOptions o;
  o.scene = "loop";
  o.frames = 40;
  const sim::SyntheticSequence seq(o);
  KeyframeStore store(0, test::tempDir("keyframe_spill_full"));  // no budget: all but the newest spilled
  std::vector<Keyframe> made;
  const auto add = [&](std::size_t i) {
    made.push_back(keyframeOf(seq, 10 * i, pose(0.1 * double(i), 0, 0, 0), 0.1 * double(i), i));
    store.add(made.back());
  };
  add(0);
  add(1);
  ASSERT_EQ(store.stats().spilled, 1u);
  struct rlimit old_limit {};
  ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old_limit), 0);
  const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);  // the write fails with EFBIG instead
  struct rlimit limit = old_limit;
  limit.rlim_cur = rlim_t(store.stats().spill_file_bytes);  // not a byte more
  ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &limit), 0);
  EXPECT_NO_THROW(add(2));
  EXPECT_NO_THROW(add(3));
  setrlimit(RLIMIT_FSIZE, &old_limit);
  std::signal(SIGXFSZ, old_handler);
  const KeyframeStoreStats st = store.stats();
  EXPECT_EQ(st.spilled, 1u);
  EXPECT_EQ(st.in_ram, 3u);
  EXPECT_NE(st.spill_error.find("cannot write the keyframes' spill file: File too large"), std::string::npos) << st.spill_error;
  for (std::size_t i = 0; i < made.size(); ++i) {
    const Keyframe k = store.load(i);
    ASSERT_FALSE(k.depth.empty()) << "keyframe " << i;
    EXPECT_EQ(cv::norm(k.depth, made[i].depth, cv::NORM_INF), 0.0);
    ASSERT_TRUE(k.features);
    EXPECT_EQ(cv::norm(k.features->descriptors, made[i].features->descriptors, cv::NORM_HAMMING), 0.0);
  }
}

// A spilled keyframe whose record cannot be read back (bytes damaged on the disk) comes back without
// features and depth, from load() and from what a checkpoint writes: no loop is closed or relocalised at
// it any more, nothing throws on the loop closer's thread, it is said once and counted; the others come
// back whole.
TEST(LoopKeyframeStore, AKeyframeWhoseRecordIsDamagedIsLostAloneAndSaidOnce) {
  sim::SimOptions o;
  o.scene = "loop";
  o.frames = 30;
  const sim::SyntheticSequence seq(o);
  const std::string dir = test::tempDir("keyframe_spill_damaged");
  KeyframeStore store(0, dir);  // no budget: all but the newest spilled
  std::vector<Keyframe> made;
  for (std::size_t i = 0; i < 3; ++i) {
    made.push_back(keyframeOf(seq, 10 * i, pose(0.1 * double(i), 0, 0, 0), 0.1 * double(i), i));
    store.add(made.back());
  }
  ASSERT_EQ(store.stats().spilled, 2u);
  const int fd = test::spillFileIn(dir);
  ASSERT_GE(fd, 0);
  // Keyframe 0's compressed depth (zlib's own check would see it), and keyframe 1's last point (only
  // the record's checksum sees that: it decodes to a keyframe with one point moved).
  const std::vector<std::uint8_t> junk(8, 0xa5);
  const std::size_t second = encodeKeyframeData(made[0]).size() + 4, points_end = second + encodeKeyframeData(made[1]).size();
  ASSERT_EQ(::pwrite(fd, junk.data(), junk.size(), 32), ssize_t(junk.size()));
  ASSERT_EQ(::pwrite(fd, junk.data(), junk.size(), off_t(points_end - junk.size())), ssize_t(junk.size()));
  testing::internal::CaptureStderr();
  for (std::size_t id : {0, 1, 0, 1}) {
    Keyframe k;
    ASSERT_NO_THROW(k = store.load(id));
    EXPECT_FALSE(k.features) << id;
    EXPECT_TRUE(k.depth.empty()) << id;
    EXPECT_TRUE(k.tracked.isApprox(made[id].tracked));  // its pose stays: the pose graph holds it
    Keyframe saved;
    ASSERT_NO_THROW(decodeKeyframeData(store.data(id), saved));  // a checkpoint holds it as lost
    EXPECT_FALSE(saved.features);
  }
  const Keyframe kept = store.load(2);  // the newest, in RAM
  ASSERT_TRUE(kept.features);
  EXPECT_EQ(store.data(2), encodeKeyframeData(made[2]));
  const std::string said = testing::internal::GetCapturedStderr();
  EXPECT_NE(said.find(dir + ": cannot read a keyframe back from the keyframes' spill file (damaged record)"), std::string::npos) << said;
  EXPECT_EQ(std::count(said.begin(), said.end(), '\n'), 1) << said;
  EXPECT_EQ(store.stats().lost, 2u);
}

// Two places 3 m apart in the look-alike corridor look the same; the camera's tracked path says they
// are 3 m apart, so joining them is refused. Full resolution, so that the two are matched as one place
// (at 320x240 too few matches stop the check before the look-alike question is asked).
TEST(LoopVerifier, LookAlikePlacesAreNotJoined) {
  sim::SimOptions o = test::quickSim("lookalike", 300);
  o.camera = CameraIntrinsics{};
  const sim::SyntheticSequence seq(o);
  // Frames whose true x differs by one period (3 m).
  const Eigen::Isometry3d t0 = toEigen(seq.groundTruth(20));
  std::size_t j = 21;
  while (j + 1 < seq.size() && toEigen(seq.groundTruth(j)).translation().x() < t0.translation().x() + 3.0) ++j;
  const Eigen::Isometry3d t1 = toEigen(seq.groundTruth(j));
  ASSERT_NEAR(t1.translation().x() - t0.translation().x(), 3.0, 0.05);
  const Keyframe older = keyframeOf(seq, 20, t0, 0.0, 0);
  const Keyframe newer = keyframeOf(seq, j, t1, 3.0, 1);
  PyramidCache pyramids(2);
  const LoopCheck c = verifyLoop(older, newer, LoopParams(), pyramids);
  std::printf("look-alike: %d matches, %d inliers, reason '%s', correction %.3f m\n", c.matches, c.inliers,
              c.reason.c_str(), c.correction_m);
  EXPECT_FALSE(c.accepted);
  EXPECT_GE(c.inliers, LoopParams().min_inliers) << "matched as one place, or the look-alike question is never asked";
  EXPECT_EQ(c.reason, "correction larger than the drift could be (look-alike place?)");
}

namespace {
// The room at full resolution (enough keypoints to recognise a place), every third frame handed to
// `closer` (it takes keyframes by travel) until `wanted` frames became keyframes: their frames.
std::vector<std::size_t> walkTheRoomUntil(const sim::SyntheticSequence& seq, LoopCloser& closer, std::size_t wanted) {
  RgbdOdometry odo{OdometryParams()};
  std::vector<std::size_t> keyframe_frames;
  for (std::size_t i = 0; i < seq.size() && keyframe_frames.size() < wanted; i += 3) {
    const Frame f = seq.render(i);
    const OdometryResult r = odo.process(f);
    if (closer.addFrame(f, toEigen(seq.groundTruth(i) - seq.groundTruth(0)), true, 0.001, r.features)) keyframe_frames.push_back(i);
  }
  return keyframe_frames;
}

// Parks the loop thread in its after-indexing hook once keyframe `at` (1-based) is stored and indexed,
// until release(). Made before the LoopCloser, so that it outlives the thread; a releaseOnExit() guard
// made after it (and after any task that waits for the thread) frees the thread on the way out,
// whatever failed, before the closer's destructor joins it.
class ParkedLoopThread {
 public:
  explicit ParkedLoopThread(std::size_t at) : at_(at), release_(released_.get_future().share()) {}
  void install(LoopCloser& closer) {
    closer.setAfterIndexingHook([this](std::size_t id) {
      if (id + 1 != at_ || !armed_.exchange(false)) return;
      entered_.set_value();
      release_.wait();
    });
  }
  bool parked() { return entered_.get_future().wait_for(std::chrono::seconds(60)) == std::future_status::ready; }
  void release() {
    if (!done_.exchange(true)) released_.set_value();
  }
  struct Guard {
    ParkedLoopThread& p;
    ~Guard() { p.release(); }
  };
  Guard releaseOnExit() { return Guard{*this}; }

 private:
  std::size_t at_;
  std::promise<void> entered_, released_;
  std::shared_future<void> release_;
  std::atomic<bool> armed_{true}, done_{false};
};

sim::SyntheticSequence roomAtFullResolution() {
  sim::SimOptions o;
  o.scene = "room";
  o.frames = 450;
  return sim::SyntheticSequence(o);
}
}  // namespace

// Only well-tracked frames' residuals make the window a frame is judged against: a fallback's is the
// residual of the ICP that was refused, large by definition. A stretch of fallbacks lifted the median,
// and the jump when tracking met the map again was not strained (nor were they counted as strained).
TEST(LoopCloser, ResidualsOfFramesNotWellTrackedAreNoPartOfTheWindow) {
  LoopCloser closer{LoopParams()};
  Frame f;  // no depth: no keyframe, the residual judged all the same
  const auto add = [&](bool well_tracked, double rms) {
    closer.addFrame(f, Eigen::Isometry3d::Identity(), well_tracked, rms, nullptr);
    ++f.index, f.timestamp += 1.0 / 30;
  };
  for (int i = 0; i < 60; ++i) add(true, 0.003);
  for (int i = 0; i < 50; ++i) add(false, 0.05);
  EXPECT_EQ(closer.strainedFrames(), 0u) << "fallbacks counted as strained";
  add(true, 0.012);  // the map met again: 4x the well-tracked median
  EXPECT_EQ(closer.strainedFrames(), 1u);
}

// Lost a few metres on, the camera is placed again by a keyframe the place index has not taken yet
// (the last min_travel of path: neither among the newest keyframes nor indexed), not only by the
// newest and the indexed ones: turned back to where it was 2 m before, it stayed lost.
TEST(LoopCloser, RelocalisesAgainstAKeyframeTheIndexHasNotTakenYet) {
  const sim::SyntheticSequence seq = roomAtFullResolution();
  const LoopParams params;
  LoopCloser closer(params);
  // Keyframe `target` three older than the newest recent_keyframes.
  const std::size_t target = 2, wanted = target + std::size_t(params.recent_keyframes) + 3;
  const auto truth = [&](std::size_t i) { return toEigen(seq.groundTruth(i) - seq.groundTruth(0)); };
  const std::vector<std::size_t> keyframe_frames = walkTheRoomUntil(seq, closer, wanted);
  ASSERT_EQ(keyframe_frames.size(), wanted);
  double path_since_target = 0;
  for (std::size_t i = keyframe_frames[target] + 3; i <= keyframe_frames.back(); i += 3)
    path_since_target += (truth(i).translation() - truth(i - 3).translation()).norm();
  ASSERT_LT(path_since_target, params.min_travel) << "keyframe " << target << " must not be indexed yet";
  const std::size_t j = keyframe_frames[target];
  RgbdOdometry fresh{OdometryParams()};
  Frame view = seq.render(j);
  view.timestamp = seq.render(keyframe_frames.back()).timestamp + 2.0;  // the walk back takes its time
  const auto found = closer.relocalise(view, fresh.process(view).features);
  ASSERT_TRUE(found.has_value()) << "frame " << j << " (keyframe " << target << ") not placed";
  EXPECT_EQ(found->keyframe, target);  // its own view: the most inliers
  EXPECT_LT((found->pose.translation() - truth(j).translation()).norm(), 0.02);
  closer.finish();
}

// The thread's verification and solve after its last keyframe (a solve takes seconds on a long run) do
// not hold relocalise() up: the thread parked there by a hook, the camera is placed all the same, as
// once the thread is done (relocalise waited for the thread to be idle, and a lost live camera's frame
// loop with it).
TEST(LoopCloser, RelocalisesWhileTheThreadStillVerifiesItsLastKeyframe) {
  const sim::SyntheticSequence seq = roomAtFullResolution();
  const LoopParams params;
  const std::size_t target = 2, wanted = target + std::size_t(params.recent_keyframes) + 3;
  ParkedLoopThread park(wanted);
  LoopCloser closer(params);
  park.install(closer);
  const auto before_the_closer_goes = park.releaseOnExit();  // its destructor joins the thread
  const std::vector<std::size_t> keyframe_frames = walkTheRoomUntil(seq, closer, wanted);
  ASSERT_EQ(keyframe_frames.size(), wanted);
  ASSERT_TRUE(park.parked());
  const std::size_t j = keyframe_frames[target];
  RgbdOdometry fresh{OdometryParams()};
  Frame view = seq.render(j);
  view.timestamp = seq.render(keyframe_frames.back()).timestamp + 2.0;
  const auto features = fresh.process(view).features;
  auto placing = std::async(std::launch::async, [&] { return closer.relocalise(view, features); });
  const auto before_placing_goes = park.releaseOnExit();  // its destructor waits for relocalise, which may wait for the thread
  ASSERT_EQ(placing.wait_for(std::chrono::seconds(60)), std::future_status::ready) << "relocalise waited for the thread";
  const auto found = placing.get();
  park.release();
  ASSERT_TRUE(found.has_value());
  EXPECT_EQ(found->keyframe, target);
  closer.finish();
  const auto again = closer.relocalise(view, features);
  ASSERT_TRUE(again.has_value());
  EXPECT_EQ(again->keyframe, found->keyframe);
  EXPECT_TRUE(again->pose.isApprox(found->pose, 0.0)) << "the same keyframes and index: the same placement";
}

// A checkpoint reads the stored keyframes only: it does not wait for the thread's verification and solve
// (a live run's checkpoint stalled its frame loop for them), and the same closer's state comes out once
// the thread is done.
TEST(LoopCloser, SavesItsStateWhileTheThreadStillVerifiesItsLastKeyframe) {
  const sim::SyntheticSequence seq = roomAtFullResolution();
  const LoopParams params;
  const std::size_t wanted = std::size_t(params.recent_keyframes) + 5;
  ParkedLoopThread park(wanted);
  LoopCloser closer(params);
  park.install(closer);
  const auto before_the_closer_goes = park.releaseOnExit();
  ASSERT_EQ(walkTheRoomUntil(seq, closer, wanted).size(), wanted);
  ASSERT_TRUE(park.parked());
  auto saving = std::async(std::launch::async, [&] {
    std::ostringstream os;
    closer.saveState(os);
    return os.str();
  });
  const auto before_saving_goes = park.releaseOnExit();
  ASSERT_EQ(saving.wait_for(std::chrono::seconds(60)), std::future_status::ready) << "saveState waited for the thread";
  const std::string parked = saving.get();
  park.release();
  closer.finish();
  std::ostringstream idle;
  closer.saveState(idle);
  EXPECT_TRUE(parked == idle.str()) << "the same state as once the thread is done";
}

// In the look-alike corridor the camera, 3 m (one period) past the first keyframe, sees what that
// keyframe saw. Lost for 0.1 s it cannot be back there: the look-alike is refused, however many
// inliers it has (it was taken, 3 m off). Lost for 10 s it may have been carried there, and is placed.
TEST(LoopCloser, ALookAlikeOutOfReachIsRefusedAfterAShortLossAndTakenAfterALongOne) {
  sim::SimOptions o = test::quickSim("lookalike", 300);
  o.camera = CameraIntrinsics{};  // full resolution: enough matches to verify a place
  const sim::SyntheticSequence seq(o);
  LoopCloser closer{LoopParams()};
  RgbdOdometry odo{OdometryParams()};
  const auto truth = [&](std::size_t i) { return toEigen(seq.groundTruth(i) - seq.groundTruth(0)); };
  std::size_t last = 0;
  for (std::size_t i = 0; i < seq.size() && truth(last).translation().x() < 3.0; i += 3) {
    const Frame f = seq.render(i);
    closer.addFrame(f, truth(i), true, 0.001, odo.process(f).features);
    last = i;
  }
  ASSERT_NEAR(truth(last).translation().x(), 3.0, 0.1);
  Frame view = seq.render(0);  // what the camera sees one period on
  view.index = last + 1;
  const double last_seen = seq.render(last).timestamp;
  RgbdOdometry fresh{OdometryParams()};
  const auto features = fresh.process(view).features;

  view.timestamp = last_seen + 0.1;
  const auto soon = closer.relocalise(view, features);
  if (soon) {
    EXPECT_NE(soon->keyframe, 0u);
    EXPECT_LT((soon->pose.translation() - truth(last).translation()).norm(), 1.0) << "placed at the look-alike";
  }
  // Stamps that do not go forward (a clock stepped back) say nothing of the time lost: no bound.
  view.timestamp = last_seen - 5.0;
  const auto unstamped = closer.relocalise(view, features);
  ASSERT_TRUE(unstamped.has_value());
  EXPECT_EQ(unstamped->keyframe, 0u);
  view.timestamp = last_seen + 10.0;
  const auto later = closer.relocalise(view, features);
  ASSERT_TRUE(later.has_value()) << "the look-alike must verify, or the short loss tests nothing";
  EXPECT_EQ(later->keyframe, 0u);  // its own view: the most inliers
  EXPECT_LT(later->pose.translation().norm(), 0.05);

  // The loss is timed from the last well-tracked frame, not the newest keyframe: a camera that stood
  // still, tracked, for 20 s made no keyframe, and those seconds widened the reach to 60 m (the
  // look-alike 3 m off was taken after a loss of 0.1 s).
  Frame still = seq.render(last);
  for (int s = 1; s <= 20; ++s) {
    still.index = last + 1 + std::size_t(s);
    still.timestamp = last_seen + s;
    EXPECT_FALSE(closer.addFrame(still, truth(last), true, 0.001, nullptr)) << "a keyframe standing still";
  }
  view.index = still.index + 1;
  view.timestamp = last_seen + 20.1;
  const auto after_standing = closer.relocalise(view, features);
  if (after_standing) {
    EXPECT_NE(after_standing->keyframe, 0u);
    EXPECT_LT((after_standing->pose.translation() - truth(last).translation()).norm(), 1.0) << "placed at the look-alike";
  }
  closer.finish();
}

// The names of this process's threads, from /proc (what top -H and perf show).
std::vector<std::string> threadNames() {
  std::vector<std::string> names;
  for (const auto& task : std::filesystem::directory_iterator("/proc/self/task")) {
    std::ifstream comm(task.path() / "comm");
    std::string name;
    if (std::getline(comm, name)) names.push_back(name);
  }
  return names;
}

TEST(LoopCloser, ItsThreadIsNamedForTopAndPerf) {
  const auto named = [](const std::string& n) {
    const std::vector<std::string> all = threadNames();
    return std::count(all.begin(), all.end(), n);
  };
  const auto before = named("vof-loop");
  // The thread names itself when it starts, and leaves /proc a moment after it was joined.
  const auto waitFor = [&](long count) {
    for (int i = 0; i < 400 && named("vof-loop") != count; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(5));
    return named("vof-loop");
  };
  {
    loop::LoopCloser closer(loop::LoopParams{});
    EXPECT_EQ(waitFor(before + 1), before + 1);
  }
  EXPECT_EQ(waitFor(before), before);
}

TEST(ThreadName, CutAtLinuxsFifteenCharacters) {
  std::string got;
  std::thread([&] {
    nameThisThread("vof-a-name-longer-than-fifteen");
    char buf[32] = {};
    pthread_getname_np(pthread_self(), buf, sizeof buf);
    got = buf;
  }).join();
  EXPECT_EQ(got, "vof-a-name-long");
}

TEST(LoopParams, ShippedDefaultsFileMatchesTheCode) {
  mrpt::config::CConfigFile file(test::shareDir() + "/loop.ini");
  mrpt::config::CConfigFileMemory mem;
  LoopParams{}.saveToConfigFile(mem, "loop");
  std::vector<std::string> keys, expected;
  file.getAllKeys("loop", keys);
  mem.getAllKeys("loop", expected);
  std::sort(keys.begin(), keys.end());
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(keys, expected);
  for (const auto& k : expected) EXPECT_EQ(file.read_string("loop", k, "?"), mem.read_string("loop", k, "!")) << k;
}

// A failure on the loop closer's thread (here descriptors the place index refuses; a keyframe that
// cannot be read back from its spill file is another) reaches the caller's thread, where the app
// names it in one line; it used to end the process in std::terminate.
TEST(LoopCloser, AFailureOnItsThreadIsTheCallersToCatch) {
  sim::SimOptions o = test::quickSim("room", 4);
  const sim::SyntheticSequence seq(o);
  auto features = std::make_shared<DescribedKeypoints>();
  features->descriptors = cv::Mat(40, 16, CV_8U, cv::Scalar(7));  // BRAND's rows are 32 bytes
  for (int i = 0; i < 40; ++i) features->points.emplace_back(0.01 * i, 0.0, 1.0);
  loop::LoopCloser closer(loop::LoopParams{});
  std::string what;
  try {
    for (std::size_t i = 0; i < 4; ++i) closer.addFrame(seq.render(i), pose(0.5 * double(i), 0, 0, 0), true, 0.001, features);
    closer.finish();
  } catch (const std::exception& e) {
    what = e.what();
  }
  EXPECT_NE(what.find("place index: descriptors must be CV_8U with 32 bytes a row"), std::string::npos) << what;
}
