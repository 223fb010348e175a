// The whole per-frame pipeline (odometry -> KinFu): fusing frame k on another thread while the
// odometry of frame k+1 runs must not change a single pose, and runs must repeat exactly.
#include <mrpt/config/CConfigFileMemory.h>

#include "support.h"
#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/sim/synthetic_sequence.h"

using namespace vofusion;

namespace {

struct PipelineRun {
  Trajectory trajectory;
  std::size_t faces = 0;
  std::size_t fallbacks = 0;
};

PipelineRun reconstruct(const sim::SyntheticSequence& seq, bool overlap) {
  mrpt::config::CConfigFileMemory cfg;
  cfg.write("kinfu", "volume_voxels", 256);
  cfg.write("kinfu", "voxel_size", 0.01);
  cfg.write("kinfu", "truncation", 0.04);
  cfg.write("kinfu", "tracking_downsample", 1);  // the frames are already 320x240
  cfg.write("kinfu", "overlap_fusion", overlap);
  cfg.write("odometry", "keypoints", "star");  // PCL's NARF is not part of this question
  Reconstruction rec(cfg, TrackingMode::Paper);
  // One Frame object refilled for every image, as the apps do: the overlapped fusion must not see
  // the next frame's pixels.
  Frame frame;
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const Frame f = seq.render(i);
    if (frame.depth.empty()) frame = f;
    f.depth.copyTo(frame.depth);
    f.rgb.copyTo(frame.rgb);
    frame.index = f.index, frame.timestamp = f.timestamp, frame.camera = f.camera, frame.groundTruth = f.groundTruth;
    rec.process(frame);
  }
  PipelineRun r;
  r.trajectory = rec.trajectory();
  r.faces = rec.extractMesh().faces.size();
  r.fallbacks = rec.fallbacks();
  return r;
}

void expectSame(const PipelineRun& a, const PipelineRun& b) {
  ASSERT_EQ(a.trajectory.size(), b.trajectory.size());
  for (std::size_t i = 0; i < a.trajectory.size(); ++i)
    EXPECT_EQ(a.trajectory[i].pose.asVectorVal(), b.trajectory[i].pose.asVectorVal()) << "frame " << i;
  EXPECT_EQ(a.faces, b.faces);
  EXPECT_EQ(a.fallbacks, b.fallbacks);
}

}  // namespace

TEST(Reconstruction, OverlappedFusionGivesTheSamePosesAndMeshAsSerial) {
  sim::SimOptions o;
  o.scene = "room";
  o.frames = 12;
  o.camera = CameraIntrinsics{}.scaled(0.5);
  const sim::SyntheticSequence seq(o);
  const PipelineRun serial = reconstruct(seq, false);
  const PipelineRun overlapped = reconstruct(seq, true);
  ASSERT_GT(serial.faces, 1000u);
  // Tracked, not just equal: within 4 cm of the truth at the end (the room's weak vertical direction
  // keeps the STAR-only odometry's estimate at 320x240; ~2 cm here).
  EXPECT_LT((serial.trajectory.back().pose.translation() - seq.groundTruth(seq.size() - 1).translation()).norm(), 0.04);
  expectSame(serial, overlapped);
  expectSame(overlapped, reconstruct(seq, true));  // deterministic run to run
}
