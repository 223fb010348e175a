// KinFu end to end on synthetic sequences with exact ground truth: tracking modes, the odometry
// fallback on a bare wall, and volume shifting along a long corridor.
#include <cstdio>
#include <functional>
#include <limits>
#include <memory>
#include <random>
#include <sstream>

#include <mrpt/config/CConfigFile.h>
#include <mrpt/config/CConfigFileMemory.h>

#include "support.h"
#include "vofusion/core/allocation_limit.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/point_maps.h"
#include "vofusion/core/pose_eigen.h"
#include "vofusion/features/brand.h"
#include "vofusion/fusion/tracked_map.h"
#include "vofusion/pipeline/mesh_by_region.h"
#include "vofusion/pipeline/region_premesher.h"
#include "vofusion/registration/rigid_motion.h"
#include "vofusion/sim/synthetic_sequence.h"
#include "vofusion/tracking/motion_history.h"
#include "vofusion/tracking/tracker.h"
#include "vofusion/tracking/tracker_params.h"

using namespace vofusion;
using mrpt::poses::CPose3D;

namespace {

KinFuParams testParams() {
  KinFuParams p;
  p.tsdf.volume_voxels = 256;
  p.tsdf.voxel_size = 0.01f;
  p.tsdf.truncation = 0.04f;
  return p;
}

sim::SimOptions simOpts(const std::string& scene, std::size_t frames) { return test::quickSim(scene, frames); }

// What a good RGB-D odometry delivers: the true motion plus ~1.5 mm / 0.1 deg of noise per frame; or
// (matches > 0) that many 3D point matches on a grid of the current frame, each reading with its
// Kinect noise, as the odometry's inliers, and their least-squares motion.
fusion::MotionPrior noisyPrior(const sim::SyntheticSequence& seq, std::size_t i, std::mt19937& rng, double sigma_t = 0.0015,
                               double sigma_r = 0.1 * M_PI / 180, int matches = 0) {
  std::normal_distribution<double> nt(0, sigma_t), nr(0, sigma_r), unit(0, 1);
  std::mt19937 match_rng(unsigned(1000 + i));  // apart from rng: the motion's noise is the same with and without matches
  fusion::MotionPrior o;
  o.reference_index = i - 1;
  const CPose3D motion = (seq.groundTruth(i) - seq.groundTruth(i - 1)) + CPose3D(nt(rng), nt(rng), nt(rng), nr(rng), nr(rng), nr(rng));
  o.T_ref_cur.matrix() = motion.getHomogeneousMatrixVal<mrpt::math::CMatrixDouble44>().asEigen();
  if (matches > 0) {
    const Frame f = seq.render(i);
    const CameraIntrinsics& c = f.camera;
    const CPose3D truth = seq.groundTruth(i) - seq.groundTruth(i - 1);
    Eigen::Isometry3d T_true;
    T_true.matrix() = truth.getHomogeneousMatrixVal<mrpt::math::CMatrixDouble44>().asEigen();
    const int step = std::max(1, int(std::sqrt(double(c.width * c.height) / matches)));
    for (int y = step / 2; y < f.depth.rows; y += step)
      for (int x = step / 2; x < f.depth.cols; x += step) {
        const double z = seq.exactDepth(seq.groundTruth(i), x, y);
        if (!(z > 0.4 && z < 4.0)) continue;
        const Eigen::Vector3d p((x - c.cx) * z / c.fx, (y - c.cy) * z / c.fy, z);
        const Eigen::Vector3d q = T_true * p;
        auto noisy = [&](const Eigen::Vector3d& v) {
          const double s = kinectAxialSigma(v.z());
          return Eigen::Vector3d(v + s * unit(match_rng) * v.normalized() +
                                 v.z() / 525.0 * Eigen::Vector3d(unit(match_rng), unit(match_rng), 0));
        };
        o.current_points.push_back(noisy(p));
        o.reference_points.push_back(noisy(q));
      }
    // As the odometry does: its motion is the fit of its matches.
    o.T_ref_cur = umeyamaRigid(o.current_points, o.reference_points);
  }
  return o;
}

struct RunSummary {
  double max_error = 0, final_error = 0;
  KinFuStats stats;
};

RunSummary runSequence(const sim::SyntheticSequence& seq, TrackingMode mode, const KinFuParams& p,
                       double odo_sigma_t = 0.0015, TrackedMap** keep = nullptr, int matches = 0) {
  std::mt19937 rng(7);
  auto* kf = new TrackedMap(p, mode, seq.groundTruth(0));
  RunSummary s;
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const Frame f = seq.render(i);
    fusion::MotionPrior prior;
    const bool have = i > 0;
    if (have) prior = noisyPrior(seq, i, rng, odo_sigma_t, 0.1 * M_PI / 180, matches);
    const FusionResult r = kf->process(f, have ? &prior : nullptr);
    const double err = (r.pose.translation() - seq.groundTruth(i).translation()).norm();
    s.max_error = std::max(s.max_error, err);
    s.final_error = err;
  }
  s.stats = kf->stats();
  if (keep) *keep = kf;
  else delete kf;
  return s;
}

}  // namespace

// A plane constrains 3 of the 6 degrees of freedom: ICP alone cannot see the slide along the wall
// (it stays behind), while mode paper-handoff keeps the odometry along the unconstrained directions
// and mode joint lets the odometry's matches decide them.
TEST(KinFu, OdometryHoldsTheBareWallWhereKinFuDrifts) {
  const sim::SyntheticSequence seq(simOpts("bare_wall", 40));
  const KinFuParams p = testParams();
  const RunSummary kinfu = runSequence(seq, TrackingMode::KinFu, p);
  const RunSummary paper = runSequence(seq, TrackingMode::PaperHandoff, p);
  EXPECT_GT(kinfu.max_error, 0.05);
  EXPECT_EQ(paper.stats.lost, 0u);
  EXPECT_GT(paper.stats.degenerate, seq.size() * 3 / 4);  // the degenerate directions were noticed, not trusted
  EXPECT_LT(paper.max_error, 0.02) << "paper";
  const RunSummary joint = runSequence(seq, TrackingMode::Joint, p, 0.0015, nullptr, 150);
  std::printf("bare wall max error: kinfu %.4f paper-handoff %.4f joint %.4f m\n", kinfu.max_error, paper.max_error, joint.max_error);
  EXPECT_EQ(joint.stats.lost, 0u);
  EXPECT_EQ(joint.stats.fell_back, 0u);
  EXPECT_GT(joint.stats.degenerate, seq.size() * 3 / 4);
  // Before the model shows how bare the wall is, ICP takes it for a constraint along it for a few
  // frames (both modes drift ~1 cm there); then the odometry holds it.
  EXPECT_LT(joint.max_error, 0.03);
}

// Mode joint without any prior (the odometry failed on every frame) is ICP from the best of the
// constant-velocity prediction and the last pose: it tracks the room on exact depth like mode kinfu.
TEST(KinFu, JointModeWithoutPriorTracksLikeKinFu) {
  sim::SimOptions exact = simOpts("room", 30);
  exact.noise = false;
  const sim::SyntheticSequence seq(exact);
  TrackedMap kf(testParams(), TrackingMode::Joint, seq.groundTruth(0));
  double max_error = 0;
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const FusionResult r = kf.process(seq.render(i), nullptr);
    EXPECT_TRUE(r.tracked) << "frame " << i;
    max_error = std::max(max_error, (r.pose.translation() - seq.groundTruth(i).translation()).norm());
  }
  EXPECT_LT(max_error, 0.006);
  EXPECT_GT(kf.stats().guess_velocity + kf.stats().guess_last, seq.size() - 3);
}

// A damaged estimate (NaN or infinity in its motion, its covariance or a match) costs that frame's
// prior, not the run: the frame is tracked exactly as if the estimator had given nothing. The
// covariance is not read by the tracker today; a prior with a broken part is refused as a whole.
TEST(KinFu, ANonFinitePriorIsTrackedAsNoPrior) {
  const sim::SyntheticSequence seq(simOpts("room", 8));
  const std::size_t bad = 4;
  const double nan = std::numeric_limits<double>::quiet_NaN(), inf = std::numeric_limits<double>::infinity();
  using Damage = std::function<void(fusion::MotionPrior&)>;
  const std::vector<std::pair<std::string, Damage>> damages = {
      {"NaN motion", [&](fusion::MotionPrior& p) { p.T_ref_cur.translation().x() = nan; }},
      {"infinite covariance", [&](fusion::MotionPrior& p) { p.covariance(0, 0) = inf; }},
      {"NaN current point", [&](fusion::MotionPrior& p) { p.current_points.at(3).z() = nan; }},
      {"infinite reference point", [&](fusion::MotionPrior& p) { p.reference_points.at(7).x() = -inf; }}};
  // The run's poses with frame `bad` given `damage`, or no prior at all when there is none.
  auto run = [&](TrackingMode mode, const Damage* damage) {
    std::mt19937 rng(7);
    TrackedMap kf(testParams(), mode, seq.groundTruth(0));
    std::vector<CPose3D> path;
    for (std::size_t i = 0; i < seq.size(); ++i) {
      fusion::MotionPrior prior;
      if (i > 0) prior = noisyPrior(seq, i, rng, 0.0015, 0.1 * M_PI / 180, 40);
      if (i == bad && damage) (*damage)(prior);
      const bool given = i > 0 && !(i == bad && !damage);
      path.push_back(kf.process(seq.render(i), given ? &prior : nullptr).pose);
    }
    return path;
  };
  for (const TrackingMode mode : {TrackingMode::Joint, TrackingMode::PaperHandoff, TrackingMode::Odometry}) {
    const std::vector<CPose3D> without = run(mode, nullptr);
    for (const CPose3D& p : without) ASSERT_TRUE(p.asVectorVal().asEigen().allFinite()) << toString(mode);
    for (const auto& [name, damage] : damages) {
      const std::vector<CPose3D> path = run(mode, &damage);
      for (std::size_t i = 0; i < path.size(); ++i)
        ASSERT_EQ(path[i].asVectorVal(), without[i].asVectorVal()) << toString(mode) << ", " << name << ", frame " << i;
    }
  }
}

// Only measured frames teach the velocity, over the time since the last measured one. Learnt from
// predicted frames, the camera that stopped while three frames were predicted came back measured at
// -3 times its speed, and the next prediction went backwards. A checkpoint keeps what was measured.
TEST(MotionHistory, APredictedFrameTeachesNoVelocity) {
  const auto at = [](double x) {
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.translation().x() = x;
    return T;
  };
  const double dt = 1.0 / 30, step = 0.01;  // m a frame
  MotionHistory h(at(0));
  h.remember(0, 0.0, at(0));
  h.remember(1, dt, at(step));
  for (int k = 2; k <= 4; ++k) h.remember(std::size_t(k), k * dt, h.constantVelocity(k * dt), false);
  EXPECT_NEAR(h.pose().translation().x(), 4 * step, 1e-12) << "predicted on at the measured velocity";
  h.remember(5, 5 * dt, at(step));  // measured where frame 1 was: the camera had stopped
  EXPECT_NEAR(h.constantVelocity(6 * dt).translation().x(), step, 1e-12);
  EXPECT_EQ(h.lastMeasuredTimestamp(), 5 * dt);

  std::stringstream saved;
  {
    auto a = state::archiveOf(static_cast<std::ostream&>(saved));
    h.remember(6, 6 * dt, h.constantVelocity(6 * dt), false);
    h.saveState(a);
  }
  MotionHistory reloaded(at(9));
  {
    auto a = state::archiveOf(static_cast<std::istream&>(saved));
    reloaded.loadState(a);
  }
  for (MotionHistory* m : {&h, &reloaded}) m->remember(7, 7 * dt, at(3 * step));  // 2 steps over 2 frames since frame 5
  EXPECT_NEAR(h.constantVelocity(8 * dt).translation().x(), 4 * step, 1e-12);
  EXPECT_NEAR(reloaded.constantVelocity(8 * dt).translation().x(), 4 * step, 1e-12);
}

// Stamps a microsecond apart (a clock's doing) make no turn rate: the rolling shutter's ICP noise
// stays that of a frame at the fastest sensor's rate (300 fps). The prior's turn over 1e-6 s put it at
// 540 m, and ICP's weight at zero.
TEST(KinFu, StampsAMicrosecondApartMakeNoRollingShutterNoise) {
  const sim::SyntheticSequence seq(simOpts("room", 4));
  std::mt19937 rng(3);
  TrackedMap map(testParams(), TrackingMode::Joint, seq.groundTruth(0));
  ASSERT_TRUE(map.process(seq.render(0), nullptr).tracked);
  for (std::size_t i = 1; i <= 2; ++i) {
    Frame f = seq.render(i);
    const fusion::MotionPrior prior = noisyPrior(seq, i, rng, 0.0, 0.0);
    if (i == 2) f.timestamp = seq.render(1).timestamp + 1e-6;
    const FusionResult r = map.process(f, &prior);
    ASSERT_TRUE(r.tracked) << i;
    EXPECT_LT(r.icp_sigma, 0.5) << "frame " << i;
  }
}

// A pose that is not finite places nothing: fused at NaN, every ray marched from min_depth to max_depth
// a step at a time (minutes a frame at the config's extremes), and relocalised there the next frame had
// no model to track against.
TEST(KinFu, APoseThatIsNotFinitePlacesNothing) {
  const sim::SyntheticSequence seq(simOpts("room", 3));
  TrackedMap map(testParams(), TrackingMode::Joint, seq.groundTruth(0));
  ASSERT_TRUE(map.process(seq.render(0), nullptr).tracked);
  const std::size_t bricks = map.stats().bricks_in_volume;
  mrpt::poses::CPose3D nowhere = seq.groundTruth(1);
  nowhere.x(std::nan(""));
  EXPECT_FALSE(map.integrateAt(seq.render(1), nowhere));
  EXPECT_EQ(map.stats().bricks_in_volume, bricks);
  EXPECT_THROW(map.relocalise(nowhere), std::invalid_argument);
  EXPECT_TRUE(map.process(seq.render(2), nullptr).tracked);
}

// A placement (relocalise as prior) is for the next frame tracked: one lost before it (no depth) does
// not carry it on to a later frame, which the stale placement would have pulled back to where it was.
TEST(KinFu, APlacementIsNotCarriedPastALostFrame) {
  const sim::SyntheticSequence seq(simOpts("room", 12));
  TrackedMap map(testParams(), TrackingMode::Joint, seq.groundTruth(0));
  for (std::size_t i = 0; i < 3; ++i) ASSERT_TRUE(map.process(seq.render(i), nullptr).tracked);
  map.relocalise(seq.groundTruth(2), true);
  Frame blank = seq.render(3);
  blank.depth.setTo(0.f);
  EXPECT_FALSE(map.process(blank, nullptr).tracked);
  const FusionResult next = map.process(seq.render(4), nullptr);
  EXPECT_NE(next.guess, InitialGuess::Prior) << "the placement outlived the frame it was for";
}

// A frame that is not fused (a fallback or a predicted pose) still moves the model's prediction with
// the camera: the ray cast looks where that frame has readings. Hinted by the last prediction alone,
// the model kept only pixels that had a surface the frame before, and lost a band each frame the
// camera panned without fusing, leaving ICP less to pair with.
TEST(KinFu, PredictionFollowsAPanWhileFramesAreNotFused) {
  const sim::SyntheticSequence seq(simOpts("room", 2));
  const Frame f0 = seq.render(0);
  const CameraIntrinsics cam = f0.camera;
  auto iso = [](const CPose3D& p) {
    Eigen::Isometry3d t;
    t.matrix() = p.getHomogeneousMatrixVal<mrpt::math::CMatrixDouble44>().asEigen();
    return t;
  };
  KinFu map(testParams(), iso(seq.groundTruth(0)), {true, false});
  StageTimes times;
  FrameToFuse f;
  f.depth = f.hint = f0.depth;
  f.rgb = f0.rgb;
  f.cam = f.track_cam = cam;
  f.pose = iso(seq.groundTruth(0));
  map.fuse(f, times);
  for (int k = 1; k <= 8; ++k) {
    const CPose3D pose = seq.groundTruth(0) + CPose3D(0, 0, 0, 0, 2.0 * k * M_PI / 180, 0);  // yaw about the camera's y
    cv::Mat depth(cam.height, cam.width, CV_32F);
    for (int y = 0; y < depth.rows; ++y)
      for (int x = 0; x < depth.cols; ++x) depth.at<float>(y, x) = float(seq.exactDepth(pose, x, y));
    FrameToFuse panned;
    panned.integrate = false;
    panned.depth = panned.hint = depth;
    panned.cam = panned.track_cam = cam;
    panned.pose = iso(pose);
    map.fuse(panned, times);
    const fusion::RaycastMaps full = map.volume().raycast(iso(pose).cast<float>(), cam, nullptr, false, false);
    auto surfaces = [](const cv::Mat& vertices) {
      int n = 0;
      for (auto it = vertices.begin<cv::Vec3f>(); it != vertices.end<cv::Vec3f>(); ++it) n += std::isfinite((*it)[0]);
      return n;
    };
    const int predicted = surfaces(map.model().vertices[0]), there = surfaces(full.vertices);
    ASSERT_GT(there, cam.width * cam.height / 4) << "frame " << k;
    EXPECT_GT(predicted, 0.97 * there) << "frame " << k << ": the prediction has " << predicted << " surface pixels, the volume "
                                       << there;
  }
}

// A frame ICP rejects with no prior is posed by constant velocity, a guess: it hands the map no
// intensity, so the next frame's photometric term has no reference seen from where the camera was not
// (its pixels were paired with model points through the guessed pose). A measured frame hands it over.
TEST(Tracker, AGuessedFrameLeavesNoPhotometricReference) {
  const sim::SyntheticSequence seq(simOpts("room", 3));
  const KinFuParams params = testParams();
  const Eigen::Isometry3d start = toEigen(seq.groundTruth(0));
  KinFu map(params, start, {true, true});
  Tracker tracker(params, TrackingMode::Joint, start);
  StageTimes times;
  const auto trackAndFuse = [&](const Frame& frame) {
    const FusionResult r = tracker.track(frame, nullptr, nullptr, map);
    const FrameToFuse* f = tracker.frameToFuse();
    const bool handed_intensity = f && !f->intensity.empty();
    if (f) tracker.fused(map.fuse(*f, times), times);
    return std::make_pair(r, handed_intensity);
  };
  ASSERT_TRUE(trackAndFuse(seq.render(0)).first.tracked);
  const auto [measured, measured_intensity] = trackAndFuse(seq.render(1));
  ASSERT_TRUE(measured.tracked && !measured.predicted) << measured.reason;
  EXPECT_TRUE(measured_intensity) << "a measured frame is the photometric term's next reference";
  EXPECT_FALSE(map.model().intensity.empty());
  Frame wall = seq.render(2);  // a board 0.4 m before the lens, far in front of every modelled wall: no pair
  wall.depth.setTo(0.4f);
  const auto [guessed, guessed_intensity] = trackAndFuse(wall);
  ASSERT_TRUE(guessed.predicted) << "rejection: " << guessed.reason;
  EXPECT_FALSE(guessed_intensity);
  EXPECT_TRUE(map.model().intensity.empty()) << "the next frame would be paired through the guessed pose";
}

// A checkpoint holds the tracker and the map together: between track() and fuse() the tracker has posed
// a frame the map has not fused yet, so saving then is refused; once fused, the saved state reloads
// into a map that tracks the next frame to the same pose.
TEST(KinFu, CheckpointRefusedBetweenTrackingAFrameAndFusingIt) {
  sim::SimOptions exact = simOpts("room", 4);
  exact.noise = false;
  const sim::SyntheticSequence seq(exact);
  TrackedMap kf(testParams(), TrackingMode::KinFu, seq.groundTruth(0));
  kf.process(seq.render(0), nullptr);
  const Frame second = seq.render(1);
  FusionResult r = kf.track(second, nullptr);
  ASSERT_TRUE(r.tracked);
  std::stringstream early;
  EXPECT_THROW(kf.saveState(early), std::logic_error);
  kf.fuse(r);
  EXPECT_TRUE(r.integrated);
  std::stringstream saved;
  kf.saveState(saved);
  TrackedMap reloaded(testParams(), TrackingMode::KinFu);
  reloaded.loadState(saved);
  EXPECT_EQ(reloaded.stats().frames, 2u);
  const Frame third = seq.render(2);
  const FusionResult a = kf.process(third, nullptr), b = reloaded.process(third, nullptr);
  EXPECT_TRUE(a.tracked);
  EXPECT_EQ(a.pose.asString(), b.pose.asString());
}

// The room's view (one far wall, a corner, box tops seen at a grazing angle) constrains the camera's
// height only weakly: with Kinect noise ICP alone drifts vertically there, so mode kinfu is checked on
// exact depth (it must then recover the known motion: this is what caught a biased ray cast) and mode
// paper on noisy depth.
TEST(KinFu, TracksTheRoomInEveryMode) {
  const sim::SyntheticSequence seq(simOpts("room", 30));
  const KinFuParams p = testParams();
  const RunSummary paper = runSequence(seq, TrackingMode::PaperHandoff, p);
  EXPECT_EQ(paper.stats.lost, 0u);
  EXPECT_LT(paper.max_error, 0.02);  // the odometry's noise along the weak vertical direction
  const RunSummary joint = runSequence(seq, TrackingMode::Joint, p, 0.0015, nullptr, 150);
  std::printf("room max error: paper-handoff %.4f joint %.4f m\n", paper.max_error, joint.max_error);
  EXPECT_EQ(joint.stats.lost, 0u);
  EXPECT_LT(joint.max_error, 0.02);
  // ICP alone, no odometry at all, follows the room's motion (~2 cm, 1 deg) to a few mm.
  sim::SimOptions exact = simOpts("room", 30);
  exact.noise = false;
  const sim::SyntheticSequence seq_exact(exact);
  const RunSummary kinfu = runSequence(seq_exact, TrackingMode::KinFu, p);
  std::printf("room max error, exact depth: kinfu %.4f m\n", kinfu.max_error);
  EXPECT_EQ(kinfu.stats.lost, 0u);
  EXPECT_LT(kinfu.max_error, 0.006);
  // Odometry mode composes the (noisy) motions: it drifts like a random walk, ICP does not add to it.
  const RunSummary odo = runSequence(seq, TrackingMode::Odometry, p, 0.0);
  EXPECT_LT(odo.max_error, 0.005);
}

// The corridor walked with a volume that shifts along it (18 s: ~7 m), and meshing regions of 8^3
// bricks (64 cells a side: a seam fragment is judged with the neighbours' pieces).
struct PremeshingCorridor {
  sim::SyntheticSequence seq{options()};
  KinFuParams params = kinfuParams();
  MeshCleanParams mesh;  // defaults: fragments under 50 faces go, error-bounded simplification

  PremeshingCorridor() { mesh.region_bricks = 8; }
  static sim::SimOptions options() {
    sim::SimOptions o = simOpts("corridor", 90);
    o.fps = 5;
    return o;
  }
  static KinFuParams kinfuParams() {
    KinFuParams p = testParams();
    p.tsdf.volume_voxels = 160;  // 3.2 m: shifts along the corridor
    p.tsdf.voxel_size = 0.02f;
    p.tsdf.truncation = 0.06f;
    p.focus_distance = 1.0f;
    p.tsdf.max_depth = 2.0f;
    return p;
  }
  // Every frame, with a noisy odometry prior.
  void track(TrackedMap& kf) const {
    std::mt19937 rng(7);
    for (std::size_t i = 0; i < seq.size(); ++i) {
      fusion::MotionPrior prior;
      if (i > 0) prior = noisyPrior(seq, i, rng, 0.0, 0.1 * M_PI / 180, 0);
      kf.process(seq.render(i), i > 0 ? &prior : nullptr);
    }
  }
  std::unique_ptr<TrackedMap> newTrackedMap() const {
    return std::make_unique<TrackedMap>(params, TrackingMode::Odometry, seq.groundTruth(0));
  }
  // A tracked map whose volume's moves premesher follows while `feed` gives it frames or a map; the thread
  // has finished every region queued when this returns.
  std::unique_ptr<TrackedMap> meshedWhile(RegionPremesher& premesher, const std::function<void(TrackedMap&)>& feed) const {
    std::unique_ptr<TrackedMap> kf = newTrackedMap();
    kf->setShiftObserver([&premesher](const fusion::TsdfVolume& v, const std::optional<Eigen::Vector3i>& old) {
      premesher.volumeShifted(v, old);
    });
    feed(*kf);
    premesher.waitIdle();
    premesher.stop();
    return kf;
  }
  // Meshing at the end of kf's map with the regions premesher made gives the mesh meshing alone gives.
  std::size_t expectTheMeshOfMeshingAtTheEnd(const TrackedMap& kf, RegionPremesher& premesher) const {
    const auto regions = [&](const std::function<void(fusion::RegionMesh&)>& sink) {
      kf.volume().extractMeshByRegion(mesh.region_bricks, sink);
    };
    const RegionMeshResult alone = meshByRegion(regions, mesh);
    const std::size_t held = premesher.regionsHeld();
    const RegionMeshResult with = meshByRegion(regions, mesh, "", {}, {}, premesher.lookup());
    std::printf("regions %zu, simplified while tracking %zu, taken at the end %zu\n", with.regions,
                premesher.regionsMeshed(), with.regions_premeshed);
    EXPECT_LT(with.regions_premeshed, with.regions);  // those the volume still reaches are made at the end
    EXPECT_GT(alone.mesh.faces.size(), 2000u);
    EXPECT_EQ(with.mesh.faces, alone.mesh.faces);
    EXPECT_EQ(with.mesh.vertices, alone.mesh.vertices);
    EXPECT_EQ(with.mesh.colors, alone.mesh.colors);
    EXPECT_EQ(with.report.simplification.faces_after, alone.report.simplification.faces_after);
    // Handed over, not copied: the premesher no longer holds those it gave.
    EXPECT_EQ(premesher.regionsHeld(), held - with.regions_premeshed);
    return with.regions_premeshed;
  }
};

// Meshing while tracking: the regions the shifting volume leaves behind are simplified during the
// run, and meshing at the end takes them and gives the mesh it makes alone, bit for bit.
TEST(KinFu, RegionsMeshedWhileTrackingGiveTheMeshOfMeshingAtTheEnd) {
  const PremeshingCorridor c;
  RegionPremesher premesher(c.mesh);
  const std::unique_ptr<TrackedMap> tracked = c.meshedWhile(premesher, [&](TrackedMap& kf) { c.track(kf); });
  const TrackedMap& kf = *tracked;
  EXPECT_GT(kf.stats().shifts, 3u);
  // A region is taken only for the input it was made from: with one colour bit changed in each
  // (a face less could fall in a fragment the end drops anyway), none is, and all stay.
  const auto changed = [&](const std::function<void(fusion::RegionMesh&)>& sink) {
    kf.volume().extractMeshByRegion(c.mesh.region_bricks, [&](fusion::RegionMesh& r) {
      r.mesh.colors.at(0)[0] ^= 1;
      sink(r);
    });
  };
  const std::size_t held = premesher.regionsHeld();
  EXPECT_EQ(meshByRegion(changed, c.mesh, "", {}, {}, premesher.lookup()).regions_premeshed, 0u);
  EXPECT_EQ(premesher.regionsHeld(), held);
  EXPECT_GE(c.expectTheMeshOfMeshingAtTheEnd(kf, premesher), 2u);
}

// Meshing while tracking only saves time: without memory for its lists at a shift (on the fusion thread)
// it stops, and the run goes on; the mesh is the one meshing at the end gives. The bad_alloc was the
// fusion's error, and the run's.
TEST(KinFu, MeshingWhileTrackingWithoutMemoryStopsInsteadOfFailingTheRun) {
  const PremeshingCorridor c;
  RegionPremesher premesher(c.mesh);
  int shifts = 0;
  std::unique_ptr<TrackedMap> kf = c.newTrackedMap();
  kf->setShiftObserver([&](const fusion::TsdfVolume& v, const std::optional<Eigen::Vector3i>& old) {
    std::optional<ScopedAllocationLimit> none;
    if (++shifts >= 3) none.emplace(1, 1);  // from the third shift on, not a byte
    premesher.volumeShifted(v, old);
  });
  ASSERT_NO_THROW(c.track(*kf));
  premesher.waitIdle();
  premesher.stop();
  EXPECT_GT(shifts, 3);
  EXPECT_TRUE(premesher.stoppedWithoutMemory());
  c.expectTheMeshOfMeshingAtTheEnd(*kf, premesher);
}

// A run resumed from a checkpoint or a saved map: the regions the volume had left before it are queued
// when the map is loaded (they were queued only as the volume left them, in the run that saved it).
TEST(KinFu, RegionsLeftBeforeALoadedMapAreMeshedAfterIt) {
  const PremeshingCorridor c;
  const std::unique_ptr<TrackedMap> saved = c.newTrackedMap();
  c.track(*saved);
  ASSERT_GT(saved->stats().shifts, 3u);
  std::stringstream checkpoint;
  saved->saveState(checkpoint);
  RegionPremesher premesher(c.mesh);
  const std::unique_ptr<TrackedMap> resumed = c.meshedWhile(premesher, [&](TrackedMap& kf) { kf.loadState(checkpoint); });
  EXPECT_GE(c.expectTheMeshOfMeshingAtTheEnd(*resumed, premesher), 2u);
  // The same from a map saved to a file (--save-volume, then --resume with it).
  const std::string map = test::tempDir("premesh_saved_map") + "/map.bin";
  saved->save(map);
  RegionPremesher from_file(c.mesh);
  const std::unique_ptr<TrackedMap> reloaded = c.meshedWhile(from_file, [&](TrackedMap& kf) { kf.resume(map); });
  EXPECT_GE(c.expectTheMeshOfMeshingAtTheEnd(*reloaded, from_file), 2u);
  // A map loaded once the premesher has seen the volume (moved, or loaded) replaces the one it reads:
  // refused.
  RegionPremesher late(c.mesh);
  late.volumeShifted(reloaded->volume(), std::nullopt);
  EXPECT_THROW(late.volumeShifted(reloaded->volume(), std::nullopt), std::logic_error);
  // What was made and not handed over is freed on demand, once the thread has stopped.
  EXPECT_THROW(late.discard(), std::logic_error);
  late.waitIdle();
  late.stop();
  ASSERT_GT(late.regionsHeld(), 0u);
  late.discard();
  EXPECT_EQ(late.regionsHeld(), 0u);
}

TEST(KinFu, CorridorMeshWithShiftingCoversWhatABigVolumeCovers) {
  sim::SimOptions o = simOpts("corridor", 45);
  o.fps = 5;  // 9 s: ~3.6 m along the corridor
  const sim::SyntheticSequence seq(o);
  KinFuParams small = testParams();
  // 3.2 m edge: covers the corridor's cross-section (2.2 x 2.6 m) but not its length, so it must
  // shift many times along it.
  small.tsdf.volume_voxels = 160;
  small.tsdf.voxel_size = 0.02f;
  small.tsdf.truncation = 0.06f;
  small.focus_distance = 1.0f;
  small.tsdf.max_depth = 2.0f;  // within reach of the volume ahead of the camera: both runs fuse the same readings
  KinFuParams big = small;
  big.tsdf.volume_voxels = 1024;  // 20 m: the whole corridor, never shifts
  big.shift_threshold = 100.f;
  TrackedMap *ks = nullptr, *kb = nullptr;
  const RunSummary rs = runSequence(seq, TrackingMode::Odometry, small, 0.0, &ks);
  const RunSummary rb = runSequence(seq, TrackingMode::Odometry, big, 0.0, &kb);
  std::unique_ptr<TrackedMap> hold_s(ks), hold_b(kb);
  EXPECT_GT(rs.stats.shifts, 3u);
  EXPECT_EQ(rb.stats.shifts, 0u);
  EXPECT_GT(rs.stats.bricks_in_world_model, 0u);
  const TriangleMesh ms = ks->extractMesh(), mb = kb->extractMesh();
  ASSERT_GT(mb.faces.size(), 10000u);
  // Per 0.25 m slice along the corridor, the shifted run keeps (nearly) every vertex the big volume
  // has; what differs is only the band each small volume could not reach at the time.
  std::map<int, std::pair<int, int>> bins;
  for (const auto& v : ms.vertices) ++bins[int(std::floor(v.x() / 0.25f))].first;
  for (const auto& v : mb.vertices) ++bins[int(std::floor(v.x() / 0.25f))].second;
  const double x_end = seq.groundTruth(seq.size() - 1).x();
  int compared = 0;
  for (const auto& [bin, c] : bins) {
    const double x = bin * 0.25;
    if (c.second < 200 || x > x_end + 0.3) continue;  // the far end only the big volume reached
    EXPECT_GT(c.first, 0.95 * c.second) << "slice x=" << x;
    ++compared;
  }
  EXPECT_GT(compared, 10);
  // Surfaces behind the final volume come from the world model.
  const Eigen::Vector3f lo = ks->volume().minCorner();
  EXPECT_GT(std::count_if(ms.vertices.begin(), ms.vertices.end(), [&](const Eigen::Vector3f& v) { return v.x() < lo.x(); }), 1000);
}

TEST(KinFuParams, SaveWritesEveryKeyAndLoadReadsItBack) {
  KinFuParams a;
  a.tsdf.voxel_size = 0.004f;
  a.icp.iterations = {7, 3, 2};
  a.min_inlier_ratio = 0.25f;
  a.integrate_on_fallback = false;
  mrpt::config::CConfigFileMemory cfg;
  a.saveToConfigFile(cfg, "kinfu");
  KinFuParams b;
  b.loadFromConfigFile(cfg, "kinfu");
  EXPECT_FLOAT_EQ(b.tsdf.voxel_size, 0.004f);
  EXPECT_EQ(b.icp.iterations[0], 7);
  EXPECT_EQ(b.icp.iterations[2], 2);
  EXPECT_FLOAT_EQ(b.min_inlier_ratio, 0.25f);
  EXPECT_FALSE(b.integrate_on_fallback);
  std::vector<std::string> keys;
  cfg.getAllKeys("kinfu", keys);
  EXPECT_GE(keys.size(), 26u);
  mrpt::config::CConfigFileMemory bad;
  bad.write("kinfu", "volume_voxels", 100);
  EXPECT_THROW(b.loadFromConfigFile(bad, "kinfu"), InputError);
}

// A frame tracks at half resolution from 640 px wide on and at its own size below: the shake at 320x240
// tracked at 160x120 was worse (docs/tracking.md). So the room at 640x480 and at 320x240 both track at
// 320x240: ICP counts its inliers at the finest tracking level, and they come out about the same (at
// 160x120 a quarter).
TEST(Tracking, HalfResolutionFrom640PixelsWideOnOwnSizeBelow) {
  EXPECT_EQ(trackingDownsample(640), 2);
  EXPECT_EQ(trackingDownsample(1280), 2);
  EXPECT_EQ(trackingDownsample(639), 1);
  EXPECT_EQ(trackingDownsample(320), 1);

  sim::SimOptions full_size = simOpts("room", 3);
  full_size.camera = CameraIntrinsics{};
  const sim::SyntheticSequence small(simOpts("room", 3)), large(full_size);
  // Both ways the tracker makes its levels: from the depth alone, and from the point and normal maps the
  // odometry hands over in vofusion's joint mode (made here as RgbdOdometry makes them, BRAND's defaults).
  const BrandParams brand;
  const auto inliers = [&](const sim::SyntheticSequence& seq, bool with_geometry) {
    TrackedMap map(testParams(), TrackingMode::KinFu, seq.groundTruth(0));
    int last = 0;
    for (const Frame& f : test::renderFrames(seq)) {
      FrameGeometry g;
      g.points = depthToPointMap(f.depth, f.camera);
      g.normals = computeNormalMap(g.points, brand.normal_window, float(brand.max_depth_step));
      last = map.process(f, nullptr, with_geometry ? &g : nullptr).icp_inliers;
    }
    return last;
  };
  for (const bool with_geometry : {false, true}) {
    SCOPED_TRACE(with_geometry ? "levels from the point and normal maps" : "levels from the depth");
    const int at_320 = inliers(small, with_geometry), at_640 = inliers(large, with_geometry);
    std::printf("ICP inliers of the third frame: 320x240 %d, 640x480 %d\n", at_320, at_640);
    EXPECT_GT(at_320, 1000);
    EXPECT_GT(at_320, 0.7 * at_640);
    EXPECT_LT(at_320, 1.4 * at_640);
  }
}

TEST(KinFuParams, ShippedDefaultsFileMatchesTheCode) {
  const std::string path = test::shareDir() + "/kinfu.ini";
  mrpt::config::CConfigFile file(path);
  std::vector<std::string> keys;
  file.getAllKeys("kinfu", keys);
  mrpt::config::CConfigFileMemory mem;
  KinFuParams{}.saveToConfigFile(mem, "kinfu");
  std::vector<std::string> expected;
  mem.getAllKeys("kinfu", expected);
  std::sort(keys.begin(), keys.end());
  std::sort(expected.begin(), expected.end());
  EXPECT_EQ(keys, expected);
  for (const auto& k : expected) EXPECT_EQ(file.read_string("kinfu", k, "?"), mem.read_string("kinfu", k, "!")) << k;
}

TEST(TrackingMode, ParsesNamesAndRejectsOthers) {
  EXPECT_EQ(parseTrackingMode("joint"), TrackingMode::Joint);
  EXPECT_EQ(parseTrackingMode("paper-handoff"), TrackingMode::PaperHandoff);
  EXPECT_EQ(parseTrackingMode("paper"), TrackingMode::PaperHandoff);  // the former name
  EXPECT_EQ(parseTrackingMode("kinfu"), TrackingMode::KinFu);
  EXPECT_EQ(toString(parseTrackingMode("odometry")), "odometry");
  EXPECT_THROW(parseTrackingMode("icp"), InputError);
}
