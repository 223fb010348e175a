// The default tracker (mode joint) on synthetic motion with exact ground truth: the hand-shake
// trajectory (turns up to ~150 deg/s, blurred colour taken off the depth capture). Through the whole
// pipeline (odometry -> joint tracking -> fusion), at 320x240 to keep the suite quick.
#include <cstdio>
#include <functional>
#include <vector>

#include <mrpt/config/CConfigFileMemory.h>

#include "support.h"
#include "vofusion/eval/trajectory_eval.h"
#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/sim/synthetic_sequence.h"

using namespace vofusion;

namespace {

struct Tracked {
  double ate = 0;
  std::size_t lost = 0, predicted = 0;
  ColourTimeStats colour_time;
};

// restamp: what the recording says of each frame's colour offset (default: the true one).
Tracked track(const std::vector<Frame>& frames, TrackingMode mode, const std::string& colour_time_velocity = "auto",
              const std::function<double(std::size_t, double)>& restamp = {}) {
  mrpt::config::CConfigFileMemory cfg;
  cfg.write("odometry", "colour_time_velocity", colour_time_velocity);
  cfg.write("kinfu", "volume_voxels", 256);
  cfg.write("kinfu", "voxel_size", 0.012);
  cfg.write("kinfu", "truncation", 0.05);
  Reconstruction rec(cfg, mode);
  Trajectory truth;
  for (std::size_t i = 0; i < frames.size(); ++i) {
    Frame f = test::deepCopy(frames[i]);
    if (restamp) f.colour_offset = restamp(i, f.colour_offset);
    rec.push(f);  // as the apps run it: one frame late, each frame refitted once the next one is matched
    truth.push_back({f.timestamp, *f.groundTruth});
  }
  rec.flush();
  const AteResult ate = computeAte(truth, rec.trajectory());
  EXPECT_TRUE(ate.success) << ate.message;
  return {ate.trans.rmse, rec.lostFrames(), rec.predictedFrames(), rec.colourTime()};
}

}  // namespace

// The target is 2 cm. The shake's colour offsets are exact (the simulator's capture times); the
// default colour-time velocity (auto) finds from the frames that each frame's own velocity (capture)
// fits them better and switches to it: measured 1.18 cm here (interval 3.51; paper-handoff 0.94, kinfu
// 15.7), one frame late as the apps run (Reconstruction::push); 1.39 before frames were refitted. One seed guards what mode joint reaches; how it compares with its own
// sources is the five seeds' test below.
TEST(Tracking, ShakeThreeSecondsHeld) {
  const std::vector<Frame> frames = test::renderFrames(sim::SyntheticSequence(test::quickSim("room", 90, "shake")));
  const Tracked joint = track(frames, TrackingMode::Joint);
  const Tracked kinfu = track(frames, TrackingMode::KinFu);
  const Tracked paper = track(frames, TrackingMode::PaperHandoff);
  std::printf("shake, 90 frames: ATE joint %.4f m, kinfu %.4f m, paper-handoff %.4f m\n", joint.ate, kinfu.ate, paper.ate);
  EXPECT_LT(joint.ate, 0.02);
  EXPECT_EQ(joint.lost, 0u);
  EXPECT_EQ(joint.predicted, 0u);
  EXPECT_LT(joint.ate, kinfu.ate);  // ICP alone loses these turns
  EXPECT_LT(paper.ate, 0.02);
  EXPECT_TRUE(joint.colour_time.capture);
  std::printf("shake, 90 frames: %d of %d frames compared fitted capture better\n", joint.colour_time.capture_better,
              joint.colour_time.compared);
  const Tracked interval = track(frames, TrackingMode::Joint, "interval");
  std::printf("shake, 90 frames, colour_time_velocity interval: ATE joint %.4f m\n", interval.ate);
  EXPECT_LT(joint.ate, 0.5 * interval.ate);  // moving each keypoint at its own frame's velocity
  EXPECT_FALSE(interval.colour_time.capture);
}

// Issue 30: a joint estimate is no worse than its sources. Over the shake's seeds 1-5 (one seed is
// noise: any change moves a seed by millimetres either way), mode joint's mean ATE is within the
// guide's 1 mm of the odometry's, its better source here (ICP alone loses the turns). Measured, one
// frame late as the apps run: joint 0.0118 0.0089 0.0304 0.0173 0.0528 (mean 0.0242), odometry 0.0150
// 0.0202 0.0288 0.0220 0.0514 (mean 0.0275); frame by frame (process(), before 2026-12-07): joint 0.0139
// 0.0099 0.0506 0.0202 0.0464 (mean 0.0282), odometry 0.0124 0.0162 0.0474 0.0208 0.0432 (mean 0.0280). With ICP's weak directions decided at every iteration (before 2026-12-02) joint's
// mean was 0.0334, 5.4 mm behind: this test failed.
TEST(Tracking, ShakeOverFiveSeedsJointKeepsUpWithTheOdometry) {
  double joint_sum = 0.0, odometry_sum = 0.0;
  for (std::uint32_t seed = 1; seed <= 5; ++seed) {
    sim::SimOptions o = test::quickSim("room", 90, "shake");
    o.seed = seed;
    const std::vector<Frame> frames = test::renderFrames(sim::SyntheticSequence(o));
    const Tracked joint = track(frames, TrackingMode::Joint);
    const Tracked odometry = track(frames, TrackingMode::Odometry);
    std::printf("shake seed %u, 90 frames: ATE joint %.4f m, odometry %.4f m\n", seed, joint.ate, odometry.ate);
    EXPECT_EQ(joint.lost, 0u) << "seed " << seed;
    joint_sum += joint.ate;
    odometry_sum += odometry.ate;
  }
  std::printf("shake seeds 1-5: mean ATE joint %.4f m, odometry %.4f m\n", joint_sum / 5, odometry_sum / 5);
  EXPECT_LT(joint_sum / 5, odometry_sum / 5 + 0.001);
}

// The same shake with stamps that do not tell the capture times: each frame carries another frame's
// offset. Both corrections then move the keypoints by the wrong offsets (no correction at all measured
// 2.3 cm on seed 1); auto's vote only chooses the velocity, so it must do no worse than the interval
// mean. Over seeds 1-5 (one frame late, as the apps run): auto 0.0548 0.0512 0.0793 0.0468 0.0685
// (mean 0.0601), interval 0.0468 0.0967 0.1818 0.0571 0.0743 (mean 0.0913). Seed 1 alone, the test's
// scene until 2026-12-07, is the one seed where auto is behind.
TEST(Tracking, StampsThatAreNotCaptureTimesNoWorseThanTheIntervalMean) {
  double automatic_sum = 0.0, interval_sum = 0.0;
  for (std::uint32_t seed = 1; seed <= 5; ++seed) {
    sim::SimOptions o = test::quickSim("room", 90, "shake");
    o.seed = seed;
    const std::vector<Frame> frames = test::renderFrames(sim::SyntheticSequence(o));
    std::vector<double> offsets(frames.size());
    for (std::size_t i = 0; i < frames.size(); ++i) offsets[i] = frames[i].colour_offset;
    // Another frame's offset, 37 frames on: unrelated to this frame's capture, with the same spread.
    const auto other = [&](std::size_t i, double) { return offsets[(i + 37) % offsets.size()]; };
    const Tracked automatic = track(frames, TrackingMode::Joint, "auto", other);
    const Tracked interval = track(frames, TrackingMode::Joint, "interval", other);
    std::printf("shake seed %u, 90 frames, offsets of other frames: ATE joint auto %.4f m (%d of %d frames compared "
                "fitted capture better), interval %.4f m\n",
                seed, automatic.ate, automatic.colour_time.capture_better, automatic.colour_time.compared, interval.ate);
    EXPECT_GT(automatic.colour_time.compared, 20) << "seed " << seed;
    EXPECT_EQ(automatic.lost, 0u) << "seed " << seed;
    automatic_sum += automatic.ate;
    interval_sum += interval.ate;
  }
  std::printf("shake seeds 1-5, offsets of other frames: mean ATE auto %.4f m, interval %.4f m\n", automatic_sum / 5,
              interval_sum / 5);
  EXPECT_LT(automatic_sum / 5, interval_sum / 5 + 0.001);
}

// The loop scene's corridor at its default pace (one lap in 300 frames: 3 m/s, 10 cm a frame), full
// size and default settings, its first 80 frames: the odometry's prior holds every step to a few
// millimetres, while the last pose (10 cm behind, the ray cast's own viewpoint) explains the frame
// better at the coarse level only because the model was cast from it. Taken as the start it cost
// 2-10 cm steps along the corridor: measured here 0.031 m with 11 ICP fallbacks before, 0.0033 m after
// (odometry alone 0.0027).
TEST(Tracking, ACorridorAtRunningPaceKeepsToTheOdometry) {
  sim::SimOptions o = test::quickSim("loop", 300);
  o.camera = CameraIntrinsics{};
  o.seed = 3;
  const std::vector<Frame> frames = test::renderFrames(sim::SyntheticSequence(o), 80);
  const auto run = [&](TrackingMode mode) {
    mrpt::config::CConfigFileMemory cfg;
    cfg.write("loop", "enabled", false);
    Reconstruction rec(cfg, mode);
    Trajectory truth;
    for (const Frame& rendered : frames) {
      const Frame f = test::deepCopy(rendered);
      rec.process(f);
      truth.push_back({f.timestamp, *f.groundTruth});
    }
    const AteResult ate = computeAte(truth, rec.trajectory());
    EXPECT_TRUE(ate.success) << ate.message;
    return std::make_pair(ate.trans.rmse, rec.fallbacks());
  };
  const auto [joint, fallbacks] = run(TrackingMode::Joint);
  const double odometry = run(TrackingMode::Odometry).first;
  std::printf("loop seed 3, 80 of 300 frames: ATE joint %.4f m (%zu ICP fallbacks), odometry %.4f m\n", joint, fallbacks,
              odometry);
  EXPECT_LT(joint, odometry + 0.002);
  EXPECT_LE(fallbacks, 2u);
}

// The lap's end before its loop is closed: the corridor round the last corner was fused at the lap's
// start, a few centimetres off the tracked path that now returns to it. ICP against the model pulls
// frames there onto those surfaces, away from where the odometry and ICP against the last frame agree;
// the frame-to-frame check keeps them there. The path is 1.15 laps: it comes back to its start at
// frame ~260. Seed 5, without loop closure: ICP's pull overruled at frames 261-264, ATE 0.0084 m
// (0.0096 without the check, measured with it switched off). Seed 1 was this test's scene until its
// tracking stopped drifting enough to be pulled (ICP's weak directions decided once per frame,
// 2026-12-02: 0 frames overruled, ATE 0.0108 m; 0.0540 m at bc18cf2, before the check).
TEST(Tracking, TheLapsEndIsNotPulledOntoTheStartsSurfaces) {
  sim::SimOptions o;
  o.scene = "loop";
  o.seed = 5;
  const sim::SyntheticSequence seq(o);
  mrpt::config::CConfigFileMemory cfg;
  cfg.write("loop", "enabled", false);
  Reconstruction rec(cfg, TrackingMode::Joint);
  Trajectory truth;
  std::vector<std::size_t> overruled;
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const Frame f = seq.render(i);
    rec.process(f);
    truth.push_back({f.timestamp, *f.groundTruth});
    if (rec.fusionStats().model_overruled > overruled.size()) overruled.push_back(i);
  }
  const AteResult ate = computeAte(truth, rec.trajectory());
  ASSERT_TRUE(ate.success) << ate.message;
  std::printf("loop seed 5, 300 frames, no loop closure: ATE %.4f m, %zu frames overruled the model\n", ate.trans.rmse,
              overruled.size());
  EXPECT_LT(ate.trans.rmse, 0.02);
  ASSERT_FALSE(overruled.empty());
  for (const std::size_t i : overruled) EXPECT_GE(i, 250u) << "frame " << i << " overruled before the lap's end";
}
