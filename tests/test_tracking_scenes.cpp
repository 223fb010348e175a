// The default tracker (mode joint) on synthetic motion with exact ground truth: the hand-shake
// trajectory (turns up to ~150 deg/s, blurred colour taken off the depth capture). Through the whole
// pipeline (odometry -> joint tracking -> fusion), at 320x240 to keep the suite quick.
#include <cstdio>

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
};

Tracked track(const sim::SyntheticSequence& seq, TrackingMode mode, const std::string& colour_time_velocity = "interval") {
  mrpt::config::CConfigFileMemory cfg;
  cfg.write("odometry", "colour_time_velocity", colour_time_velocity);
  cfg.write("kinfu", "volume_voxels", 256);
  cfg.write("kinfu", "voxel_size", 0.012);
  cfg.write("kinfu", "truncation", 0.05);
  cfg.write("kinfu", "tracking_downsample", 1);  // the frames are already 320x240
  Reconstruction rec(cfg, mode);
  Trajectory truth;
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const Frame f = seq.render(i);
    rec.process(f);
    truth.push_back({f.timestamp, *f.groundTruth});
  }
  const AteResult ate = computeAte(truth, rec.trajectory());
  EXPECT_TRUE(ate.success) << ate.message;
  return {ate.trans.rmse, rec.lostFrames(), rec.predictedFrames()};
}

}  // namespace

// The target is 2 cm. With the default colour-time velocity (interval) measured 3.4 cm here
// (3.7 with joint_rolling_shutter 0.06, 3.5 without the photometric term; paper-handoff 3.2, odometry
// 5.9, kinfu 14.6): this guards what mode joint reaches and that it beats each of its own sources.
// The shake's colour offsets are exact, as "capture" assumes: 1.1 cm (0.6 without the photometric term).
TEST(Tracking, ShakeThreeSecondsHeldBetterThanEitherSource) {
  const sim::SyntheticSequence seq(test::quickSim("room", 90, "shake"));
  const Tracked joint = track(seq, TrackingMode::Joint);
  const Tracked kinfu = track(seq, TrackingMode::KinFu);
  const Tracked paper = track(seq, TrackingMode::PaperHandoff);
  const Tracked odo = track(seq, TrackingMode::Odometry);
  std::printf("shake, 90 frames: ATE joint %.4f m, kinfu %.4f m, paper-handoff %.4f m, odometry %.4f m\n", joint.ate,
              kinfu.ate, paper.ate, odo.ate);
  EXPECT_LT(joint.ate, 0.04);
  EXPECT_EQ(joint.lost, 0u);
  EXPECT_EQ(joint.predicted, 0u);
  EXPECT_LT(joint.ate, kinfu.ate);  // ICP alone loses these turns
  EXPECT_LT(joint.ate, odo.ate);
  EXPECT_LT(paper.ate, 0.04);
  const Tracked capture = track(seq, TrackingMode::Joint, "capture");
  std::printf("shake, 90 frames, colour_time_velocity capture: ATE joint %.4f m\n", capture.ate);
  EXPECT_LT(capture.ate, 0.02);
  EXPECT_LT(capture.ate, 0.5 * joint.ate);  // moving each keypoint at its own frame's velocity
  EXPECT_EQ(capture.lost, 0u);
}

