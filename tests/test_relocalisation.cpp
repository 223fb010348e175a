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

TEST(Relocalisation, ACoveredCameraIsFoundAgainInTheSameMapAndTheGapIsReportedLost) {
  sim::SimOptions o = test::quickSim("room", 120);
  o.blackout_start = 1.5;  // frames 45..74 covered while the camera moves on
  o.blackout_seconds = 1.0;
  const sim::SyntheticSequence seq(o);
  Reconstruction rec(test::quickRoomConfig(), TrackingMode::Joint);  // loop closure on: its keyframes find the camera
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
