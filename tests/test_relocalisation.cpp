// Relocalisation: a camera covered for a second while it moves on is found again in the same map by
// matching its frames against the loop closer's keyframes; the frames in between are reported lost,
// their pose held, never invented.
#include <mrpt/config/CConfigFileMemory.h>

#include "support.h"
#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/sim/synthetic_sequence.h"

using namespace vofusion;

namespace {

mrpt::poses::CPose3D truth(const sim::SyntheticSequence& seq, std::size_t i) { return seq.groundTruth(i) - seq.groundTruth(0); }

}  // namespace

// Mode odometry too: it has no map to check the keyframe's pose against, and predicted every frame
// after the loss from the held pose, so the camera stayed lost to the end.
TEST(Relocalisation, ACoveredCameraIsFoundAgainInTheSameMapAndTheGapIsReportedLost) {
  sim::SimOptions o = test::quickSim("room", 120);
  o.blackout_start = 1.5;  // frames 45..74 covered while the camera moves on
  o.blackout_seconds = 1.0;
  const sim::SyntheticSequence seq(o);
  for (const TrackingMode mode : {TrackingMode::Joint, TrackingMode::Odometry}) {
    SCOPED_TRACE(toString(mode));
    Reconstruction rec(test::quickRoomConfig(), mode);  // loop closure on: its keyframes find the camera
    std::vector<FrameReport> reports;
    for (std::size_t i = 0; i < seq.size(); ++i) reports.push_back(rec.process(seq.render(i)));
    rec.finish();
    const std::size_t first = 45, last = 74;
    for (std::size_t i = first; i <= last; ++i) {
      EXPECT_FALSE(reports[i].tracked) << i;
      EXPECT_EQ(reports[i].pose.asVectorVal(), reports[first - 1].pose.asVectorVal()) << "held at " << i;
    }
    EXPECT_EQ(rec.lostFrames(), last - first + 1);
    ASSERT_EQ(rec.relocalisations().size(), 1u);
    const loop::Relocalisation& r = rec.relocalisations()[0];
    EXPECT_EQ(r.frame, last + 1) << "found again at the first frame the camera sees";
    EXPECT_LT(r.keyframe_frame, first);
    // The path after it continues in the same map, near the truth (the moved-on camera is ~0.3 m away
    // from where it was lost).
    EXPECT_GT(truth(seq, last + 1).distanceTo(truth(seq, first - 1)), 0.1);
    for (std::size_t i = last + 1; i < seq.size(); ++i) {
      EXPECT_TRUE(reports[i].tracked) << i;
      EXPECT_LT((rec.trackedTrajectory()[i].pose.translation() - truth(seq, i).translation()).norm(), 0.03) << i;
    }
  }
}

// A sensor whose first frames have no depth (warming up): they are lost, and the first frame with depth
// starts the map. Counted tracked, the first blank frame used to become keyframe 0, and with no features
// there every frame after the next loss stayed lost, searched for against it.
TEST(Relocalisation, BlankFirstFramesAreLostAndTheFirstWithDepthStartsTheMap) {
  sim::SimOptions o = test::quickSim("room", 60);
  o.blackout_start = 0.0;  // frames 0 and 1
  o.blackout_seconds = 0.05;
  const sim::SyntheticSequence seq(o);
  Reconstruction rec(test::quickRoomConfig(), TrackingMode::Joint);
  std::vector<FrameReport> reports;
  for (std::size_t i = 0; i < seq.size(); ++i) reports.push_back(rec.process(seq.render(i)));
  rec.finish();
  EXPECT_FALSE(reports[0].tracked);
  EXPECT_FALSE(reports[1].tracked);
  EXPECT_EQ(rec.lostFrames(), 2u);
  // The odometry starts there too (a blank frame was its reference, the next one failed against it).
  EXPECT_TRUE(reports[2].odometry.started) << reports[2].odometry.failure;
  EXPECT_TRUE(reports[3].odometry.success) << reports[3].odometry.failure;
  EXPECT_EQ(reports[3].odometry.reference_index, 2u);
  EXPECT_EQ(rec.odometryFailures(), 2u) << "the blank frames";
  for (std::size_t i = 2; i < seq.size(); ++i) {
    EXPECT_TRUE(reports[i].tracked) << i;
    const mrpt::poses::CPose3D moved = rec.trackedTrajectory()[i].pose - rec.trackedTrajectory()[2].pose;
    EXPECT_LT((moved.translation() - (seq.groundTruth(i) - seq.groundTruth(2)).translation()).norm(), 0.03) << i;
  }
}

namespace {

// Mode kinfu on the quick room, its first frame's every reading at `depth` m: that frame must be lost
// with `why`, and every frame after it tracked (an empty map started by it lost them all).
void expectAFirstFrameAtThatDepthIsLost(float depth, const std::string& why) {
  const sim::SyntheticSequence seq(test::quickSim("room", 20));
  Reconstruction rec(test::quickRoomConfig(), TrackingMode::KinFu);
  Frame first = seq.render(0);
  first.depth.setTo(depth);
  std::vector<FrameReport> reports{rec.process(first)};
  for (std::size_t i = 1; i < seq.size(); ++i) reports.push_back(rec.process(seq.render(i)));
  rec.finish();
  EXPECT_FALSE(reports[0].tracked);
  EXPECT_EQ(reports[0].note, why);
  for (std::size_t i = 1; i < seq.size(); ++i) EXPECT_TRUE(reports[i].tracked) << i << ": " << reports[i].note;
  EXPECT_EQ(rec.lostFrames(), 1u);
}

}  // namespace

// A first frame whose readings all lie nearer than [kinfu] min_depth (a camera face down on a desk) is
// lost too: it used to start an empty model, and mode kinfu tracked no frame against it to the end.
TEST(Relocalisation, AFirstFrameWithNoReadingInRangeDoesNotStartTheMap) {
  expectAFirstFrameAtThatDepthIsLost(0.1f, "no depth reading in [min_depth, max_depth]");
}

// In mode kinfu, nor does one whose readings all lie beyond the fused range ([kinfu] integrate_max_depth,
// 3.5 m) though within the tracking range (max_depth, 4 m): it fused nothing yet started the map, and
// every frame after it was lost ("ICP system not solvable": a ray cast of an empty volume).
TEST(Relocalisation, AFirstFrameWithReadingsOnlyBeyondTheFusedRangeDoesNotStartTheMap) {
  expectAFirstFrameAtThatDepthIsLost(3.8f, "no depth reading in [integrate_min_depth, integrate_max_depth] to start the map");
}

namespace {

// The first second-long stretch from frame `from` on in which the camera turns at least 30 deg and
// moves at least 0.3 m (issue 30's blackout), as its first frame; 0 when there is none.
std::size_t briskSecond(const sim::SyntheticSequence& seq, std::size_t from, std::size_t frames_per_second) {
  for (std::size_t i = from; i + frames_per_second < seq.size(); ++i) {
    const mrpt::poses::CPose3D d = seq.groundTruth(i + frames_per_second) - seq.groundTruth(i);
    const double turn = Eigen::AngleAxisd(d.getRotationMatrix().asEigen()).angle() * 180.0 / M_PI;
    if (turn >= 30.0 && d.norm() >= 0.3) return i;
  }
  return 0;
}

// A wall fused from poses within the 2 cm of the truth, in 1 cm voxels, lies within 3 cm of
// the scene; a wall fused a second time from a wrong relocalisation puts that wall's vertices beyond
// it. Measured on seeds 1-5 (default settings): 0.06-0.71 % of the vertices are, 1 % is allowed.
constexpr double kOneSurface = 0.03;

struct BlackoutRun {
  std::size_t view_back = 0, resumed = 0;  // first frame with a view again, first tracked frame after it
  double ate_after = 0;                    // m, RMSE of the positions from `resumed` on, in the map's frame
  double off_surface = 0;                  // share of mesh vertices more than kOneSurface from every surface
};

BlackoutRun runBlackout(std::uint32_t seed) {
  sim::SimOptions o;  // full size and the default settings: the place index's features need the full image
  o.pace = 2.5;  // the room's path turns up to ~46 deg/s
  o.seed = seed;
  const std::size_t second = std::size_t(o.fps);
  const std::size_t start = briskSecond(sim::SyntheticSequence(o), 45, second);  // 1.5 s of map first
  if (start == 0) {
    ADD_FAILURE() << "seed " << seed << ": no second with a 30 deg turn and 0.3 m of travel";
    return {0, 0, 1.0, 1.0};
  }
  o.blackout_start = double(start) / o.fps;
  o.blackout_seconds = 1.0;
  o.frames = start + 3 * second;  // the covered second and two seconds after it
  const sim::SyntheticSequence seq(o);
  Reconstruction rec(mrpt::config::CConfigFileMemory(), TrackingMode::Joint);
  std::vector<FrameReport> reports;
  for (std::size_t i = 0; i < seq.size(); ++i) reports.push_back(rec.process(seq.render(i)));
  rec.finish();
  // The map stays where the frames were fused (as tracked), and follows the loops, not the smoothing.
  Trajectory as_reported;
  for (const FrameReport& fr : reports) as_reported.push_back({fr.timestamp, fr.pose});
  const auto expectSamePoses = [](const Trajectory& a, const Trajectory& b, const char* what) {
    ASSERT_EQ(a.size(), b.size()) << what;
    for (std::size_t i = 0; i < a.size(); ++i) EXPECT_EQ(a[i].pose.asVectorVal(), b[i].pose.asVectorVal()) << what << " " << i;
  };
  expectSamePoses(rec.fusedTrajectory(), as_reported, "fused while tracking");
  if (rec.mapNeedsReintegration()) {
    std::size_t next = 0;
    rec.reintegrate([&](Frame& f) { return next < seq.size() ? (f = seq.render(next++), true) : false; }, [](std::size_t) {});
    expectSamePoses(rec.fusedTrajectory(), rec.loopCloser()->correct(as_reported), "fused again");
  }
  BlackoutRun r;
  r.view_back = start + second;
  r.resumed = r.view_back;
  while (r.resumed < seq.size() && !reports[r.resumed].tracked) ++r.resumed;
  double sq = 0;
  for (std::size_t i = r.resumed; i < seq.size(); ++i)
    sq += (rec.trajectory()[i].pose.translation() - truth(seq, i).translation()).sqrNorm();
  r.ate_after = std::sqrt(sq / std::max<std::size_t>(1, seq.size() - r.resumed));
  const TriangleMesh mesh = rec.extractMesh();
  const mrpt::poses::CPose3D map_to_scene = seq.groundTruth(0);
  std::size_t off = 0;
  for (const Eigen::Vector3f& v : mesh.vertices) {
    const mrpt::math::TPoint3D p = map_to_scene.composePoint(mrpt::math::TPoint3D(v.x(), v.y(), v.z()));
    if (seq.distanceToSurface(Eigen::Vector3d(p.x, p.y, p.z)) > kOneSurface) ++off;
  }
  r.off_surface = double(off) / std::max<std::size_t>(1, mesh.vertices.size());
  return r;
}

}  // namespace

// Issue 30's blackout: the camera covered for a second while it turns 30 deg and moves 0.3 m (the
// room's path at 2.5x its pace), seeds 1-5 at full size: the place index needs full-size features
// (at 320x240 the best keyframe had 19 inliers of the 30 a relocalisation needs).
TEST(Relocalisation, ABriskSecondUnderCoverResumesWithinTenFramesInOneMap) {
  for (std::uint32_t seed = 1; seed <= 5; ++seed) {
    const BlackoutRun r = runBlackout(seed);
    std::printf("seed %u: resumed %zu frames after the view came back, ATE after %.4f m, %.4f of the mesh off the scene\n",
                seed, r.resumed - r.view_back, r.ate_after, r.off_surface);
    EXPECT_LE(r.resumed - r.view_back, 10u) << "seed " << seed;
    EXPECT_LE(r.ate_after, 0.02) << "seed " << seed;
    EXPECT_LE(r.off_surface, 0.01) << "seed " << seed;
  }
}
