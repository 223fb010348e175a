// The whole per-frame pipeline (odometry -> KinFu): fusing frame k on another thread while the
// odometry of frame k+1 runs must not change a single pose, and runs must repeat exactly.
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <limits>

#include <mrpt/config/CConfigFileMemory.h>
#include <opencv2/imgproc.hpp>

#include "support.h"
#include "vofusion/pipeline/mesh_by_region.h"
#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/sim/synthetic_sequence.h"

using namespace vofusion;

namespace {

struct PipelineRun {
  Trajectory trajectory;
  std::size_t faces = 0;
  std::size_t fallbacks = 0;
  std::size_t odometry_failures = 0, lost = 0;
};

// blank: a frame whose colour image is replaced by grey (the odometry finds nothing on it).
PipelineRun reconstruct(const sim::SyntheticSequence& seq, bool overlap, TrackingMode mode = TrackingMode::Joint,
                        std::size_t blank = SIZE_MAX) {
  mrpt::config::CConfigFileMemory cfg;
  cfg.write("kinfu", "volume_voxels", 256);
  cfg.write("kinfu", "voxel_size", 0.01);
  cfg.write("kinfu", "truncation", 0.04);
  cfg.write("kinfu", "overlap_fusion", overlap);
  cfg.write("odometry", "keypoints", "star");  // PCL's NARF is not part of this question
  Reconstruction rec(cfg, mode);
  // One Frame object refilled for every image, as the apps do: the overlapped fusion must not see
  // the next frame's pixels.
  Frame frame;
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const Frame f = seq.render(i);
    if (frame.depth.empty()) frame = f;
    f.depth.copyTo(frame.depth);
    f.rgb.copyTo(frame.rgb);
    if (i == blank) frame.rgb.setTo(cv::Scalar(128, 128, 128));
    frame.index = f.index, frame.timestamp = f.timestamp, frame.camera = f.camera, frame.groundTruth = f.groundTruth;
    rec.process(frame);
  }
  PipelineRun r;
  r.odometry_failures = rec.odometryFailures();
  r.lost = rec.lostFrames();
  r.trajectory = rec.trajectory();
  r.faces = rec.extractMesh().faces.size();
  r.fallbacks = rec.fallbacks();
  return r;
}

// Ground truth in the map's frame: the map is anchored at the first camera.
mrpt::poses::CPose3D truth(const sim::SyntheticSequence& seq, std::size_t i) { return seq.groundTruth(i) - seq.groundTruth(0); }

void expectSame(const PipelineRun& a, const PipelineRun& b) {
  ASSERT_EQ(a.trajectory.size(), b.trajectory.size());
  for (std::size_t i = 0; i < a.trajectory.size(); ++i)
    EXPECT_EQ(a.trajectory[i].pose.asVectorVal(), b.trajectory[i].pose.asVectorVal()) << "frame " << i;
  EXPECT_EQ(a.faces, b.faces);
  EXPECT_EQ(a.fallbacks, b.fallbacks);
}

// 12 frames of the synthetic room at 320x240.
sim::SimOptions smallRoom() { return test::quickSim("room", 12); }

// The first `frames` frames, then finish().
void fuse(Reconstruction& rec, const sim::SyntheticSequence& seq, std::size_t frames) {
  for (std::size_t i = 0; i < frames && i < seq.size(); ++i) rec.process(seq.render(i));
  rec.finish();
}

}  // namespace

TEST(Reconstruction, OverlappedFusionGivesTheSamePosesAndMeshAsSerial) {
  const sim::SyntheticSequence seq(smallRoom());
  const PipelineRun serial = reconstruct(seq, false);
  const PipelineRun overlapped = reconstruct(seq, true);
  ASSERT_GT(serial.faces, 1000u);
  // Tracked, not just equal: within 4 cm of the truth at the end (the room's weak vertical direction
  // keeps the STAR-only odometry's estimate at 320x240; ~2 cm here).
  EXPECT_LT((serial.trajectory.back().pose.translation() - truth(seq, seq.size() - 1).translation()).norm(), 0.04);
  expectSame(serial, overlapped);
  expectSame(overlapped, reconstruct(seq, true));  // deterministic run to run
}

// A frame the odometry cannot match (here a grey colour image) loses no motion: in mode joint ICP
// poses it; in mode odometry it moves on at constant velocity and the next frame is matched against
// the last good one, so the path continues from the right place.
// Frame::index must grow (the odometry names its reference by it, and the tracker finds that frame's
// pose by it): frames a library caller left at index 0 are refused at the second, where they were all
// "frame 0" and got wrong poses (in mode odometry, stuck near the start).
TEST(Reconstruction, FramesLeftAtIndexZeroAreRefused) {
  const sim::SyntheticSequence seq(smallRoom());
  Reconstruction rec(test::quickRoomConfig(), TrackingMode::Odometry);
  Frame first = seq.render(0), second = seq.render(1);
  first.index = second.index = 0;
  rec.process(first);
  try {
    rec.process(second);
    FAIL() << "a second frame 0 was taken";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("frame index 0 after 0"), std::string::npos) << e.what();
  }
}

// A frame stamped NaN or infinite is refused: the motion model scaled by it put NaN in the pose (mode
// joint, on a frame the odometry could not match), in the trajectory and in the run's ATE.
TEST(Reconstruction, AFrameStampedWithNoNumberIsRefused) {
  const sim::SyntheticSequence seq(smallRoom());
  for (const double stamp : {std::numeric_limits<double>::quiet_NaN(), std::numeric_limits<double>::infinity()}) {
    Reconstruction rec(test::quickRoomConfig(), TrackingMode::Joint);
    rec.process(seq.render(0));
    Frame f = seq.render(1);
    f.timestamp = stamp;
    try {
      rec.process(f);
      ADD_FAILURE() << "a frame stamped " << stamp << " was taken";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("frame 1 has a timestamp of"), std::string::npos) << e.what();
    }
  }
}

TEST(Reconstruction, AFrameWhoseOdometryFailsLosesNoMotion) {
  const sim::SyntheticSequence seq(smallRoom());
  const std::size_t blank = 6;
  for (const TrackingMode mode : {TrackingMode::Joint, TrackingMode::Odometry}) {
    const PipelineRun run = reconstruct(seq, true, mode, blank);
    EXPECT_EQ(run.odometry_failures, 1u) << toString(mode);
    EXPECT_EQ(run.lost, 0u) << toString(mode);
    // The frame's own pose: ICP's in mode joint (a few mm), constant velocity in mode odometry.
    const double at_blank = (run.trajectory[blank].pose.translation() - truth(seq, blank).translation()).norm();
    EXPECT_LT(at_blank, mode == TrackingMode::Joint ? 0.02 : 0.03) << toString(mode);
    // The motion of the failed frame is not lost: the path ends where it should (a dropped motion
    // here is ~2 cm).
    const auto& end = run.trajectory.back().pose;
    EXPECT_LT((end.translation() - truth(seq, seq.size() - 1).translation()).norm(), 0.04) << toString(mode);
    const PipelineRun clean = reconstruct(seq, true, mode);
    // Those bounds would pass a frame held where the last one was (a step here is ~5 mm): mode
    // odometry moves it on by the last motion (the frames are evenly spaced).
    if (mode == TrackingMode::Odometry) {
      const auto& p = run.trajectory;
      const mrpt::poses::CPose3D moved_on = p[blank - 1].pose + (p[blank - 1].pose - p[blank - 2].pose);
      const mrpt::poses::CPose3D off = p[blank].pose - moved_on;
      EXPECT_LT(off.translation().norm(), 1e-4);
      EXPECT_LT(Eigen::AngleAxisd(off.getRotationMatrix().asEigen()).angle(), 1e-5);
    }
    EXPECT_LT((end.translation() - clean.trajectory.back().pose.translation()).norm(), 0.01) << toString(mode);
  }
}

// The odometry keeps its last good frame as its reference through any number of failed frames (a lens
// covered for more than a second, its depth still read); the view that comes back is matched against
// it and placed from it. Past the tracker's 32 recent frames that reference's pose was gone: the frame
// was guessed at constant velocity, and the guesses' drift stayed in the path.
// With one reference, or a keyframe, the odometry no longer holds the old reference once it matched
// against it: its pose must still be there when that match is tracked.
TEST(Reconstruction, AMatchAfterMoreThan32FailedFramesIsPlacedFromItsReference) {
  for (const auto& [key, value] : std::vector<std::pair<std::string, int>>{{"references", 3}, {"references", 1},
                                                                            {"keyframe_min_inliers", 20}}) {
    SCOPED_TRACE(key + " = " + std::to_string(value));
    const sim::SyntheticSequence seq(smallRoom());
    mrpt::config::CConfigFileMemory cfg = test::quickRoomConfig();
    cfg.write("loop", "enabled", false);
    cfg.write("odometry", key, value);
    Reconstruction rec(cfg, TrackingMode::Odometry);
    constexpr std::size_t kSeen = 10, kCovered = 40;
    std::vector<FrameReport> reports;
    for (std::size_t i = 0; i < kSeen; ++i) reports.push_back(rec.process(seq.render(i)));
    const Frame view = seq.render(kSeen - 1);
    Frame covered = view;
    covered.rgb = cv::Mat(view.rgb.size(), CV_8UC3, cv::Scalar(90, 90, 90));
    covered.depth = cv::Mat(view.depth.size(), CV_32F, cv::Scalar(1.8f));
    for (std::size_t k = 1; k <= kCovered + 1; ++k) {
      Frame f = k <= kCovered ? covered : view;  // the same view again after the covered frames
      f.index = view.index + k;
      f.timestamp = view.timestamp + double(k) / 30.0;
      reports.push_back(rec.process(f));
    }
    EXPECT_EQ(rec.odometryFailures(), kCovered);
    const FrameReport& back = reports.back();
    ASSERT_TRUE(back.tracked);
    EXPECT_FALSE(back.predicted) << back.note;
    const FrameReport& before = reports[kSeen - 1];
    EXPECT_GT((reports[reports.size() - 2].pose.translation() - before.pose.translation()).norm(), 0.05)
        << "the covered frames must have carried the pose away for the test to show anything";
    EXPECT_LT((back.pose.translation() - before.pose.translation()).norm(), 0.005);
  }
}

// A depth image with NaN and infinite readings (a damaged float range image in a rawlog) costs those
// readings, not the frame or the run: no frame is lost, every pose stays finite, and the damaged frame
// and the path's end are within 1 cm of the undamaged run's.
TEST(Reconstruction, NonFiniteDepthReadingsCostOnlyThemselves) {
  const sim::SyntheticSequence seq(smallRoom());
  const std::size_t damaged_frame = 6;
  for (const TrackingMode mode : {TrackingMode::Joint, TrackingMode::KinFu, TrackingMode::Odometry}) {
    Trajectory clean;
    for (const bool damaged : {false, true}) {
      Reconstruction rec(test::quickRoomConfig(), mode);
      for (std::size_t i = 0; i < seq.size(); ++i) {
        Frame f = seq.render(i);
        if (i == damaged_frame && damaged) {
          f.depth(cv::Rect(40, 40, 60, 60)).setTo(std::numeric_limits<float>::quiet_NaN());
          f.depth(cv::Rect(200, 120, 60, 60)).setTo(std::numeric_limits<float>::infinity());
          f.depth(cv::Rect(120, 160, 20, 20)).setTo(-std::numeric_limits<float>::infinity());
        }
        rec.process(f);
      }
      rec.finish();
      const Trajectory path = rec.trajectory();
      ASSERT_EQ(path.size(), seq.size()) << toString(mode);
      for (std::size_t i = 0; i < path.size(); ++i)
        ASSERT_TRUE(path[i].pose.asVectorVal().asEigen().allFinite()) << toString(mode) << " frame " << i;
      EXPECT_EQ(rec.lostFrames(), 0u) << toString(mode);
      const TriangleMesh mesh = rec.extractMesh();
      EXPECT_GT(mesh.faces.size(), 1000u) << toString(mode);
      for (const Eigen::Vector3f& v : mesh.vertices) ASSERT_TRUE(v.allFinite()) << toString(mode);
      if (!damaged) {
        clean = path;
        continue;
      }
      for (const std::size_t i : {damaged_frame, path.size() - 1})
        EXPECT_LT((path[i].pose.translation() - clean[i].pose.translation()).norm(), 0.01) << toString(mode) << " frame " << i;
    }
  }
}

// Frame::rgb is 8-bit BGR; a library caller's colour of another pixel type (16 bits a channel, BGRA) is
// read as the odometry reads it, by every stage: the photometric term dropped it without a word, and the
// map's colour read its bytes as 8-bit BGR. Here 16 bits are the 8-bit values times 256, so the run is
// the 8-bit run's, pose for pose and colour for colour.
TEST(Reconstruction, ColourOfAnotherPixelTypeIsTrackedAndFusedAsEightBitBgr) {
  const sim::SyntheticSequence seq(test::quickSim("room", 6));
  const auto run = [&](int type) {
    Reconstruction rec(test::quickRoomConfig(), TrackingMode::Joint);
    for (std::size_t i = 0; i < seq.size(); ++i) {
      Frame f = seq.render(i);
      if (type == CV_16UC3) f.rgb.convertTo(f.rgb, CV_16UC3, 256.0);
      if (type == CV_8UC4) cv::cvtColor(f.rgb, f.rgb, cv::COLOR_BGR2BGRA);
      f.colour_file.reset();
      rec.process(f);
    }
    rec.finish();
    return std::pair(rec.trajectory(), rec.extractMesh());
  };
  const auto [path, mesh] = run(CV_8UC3);
  ASSERT_GT(mesh.faces.size(), 1000u);
  for (const int type : {CV_16UC3, CV_8UC4}) {
    const auto [other_path, other_mesh] = run(type);
    ASSERT_EQ(other_path.size(), path.size()) << type;
    for (std::size_t i = 0; i < path.size(); ++i)
      EXPECT_EQ(other_path[i].pose.asVectorVal(), path[i].pose.asVectorVal()) << type << " frame " << i;
    EXPECT_EQ(other_mesh.colors, mesh.colors) << type;
  }
}

// A caller that refills one Frame's buffers for every image (as the apps' readers may) gets the poses
// of fresh frames, with the colour-time correction on: the odometry kept the caller's depth buffer for
// its held frames, and read the current frame's depths at the reference's pixels.
TEST(Reconstruction, ARefilledFrameGivesTheFreshFramesPoses) {
  const sim::SyntheticSequence seq(test::quickSim("room", 12, "shake"));  // colour up to 15 ms off the depth
  // late: push() (the held frame's images read after the caller refilled its buffer), else process().
  const auto run = [&](bool refill, bool overlap, bool late) {
    mrpt::config::CConfigFileMemory cfg = test::quickRoomConfig();
    cfg.write("kinfu", "overlap_fusion", overlap);
    Reconstruction rec(cfg, TrackingMode::Joint);
    const auto give = [&](const Frame& f) { late ? void(rec.push(f)) : void(rec.process(f)); };
    Frame frame;
    for (std::size_t i = 0; i < seq.size(); ++i) {
      const Frame f = seq.render(i);
      if (!refill) {
        give(f);
        continue;
      }
      if (frame.depth.empty()) frame = test::deepCopy(f);
      f.depth.copyTo(frame.depth);
      f.rgb.copyTo(frame.rgb);
      frame.index = f.index, frame.timestamp = f.timestamp, frame.colour_offset = f.colour_offset;
      give(frame);
    }
    rec.flush();
    return rec.trajectory();
  };
  for (const bool overlap : {true, false})
    for (const bool late : {false, true}) {
      const Trajectory fresh = run(false, overlap, late), refilled = run(true, overlap, late);
      ASSERT_EQ(refilled.size(), fresh.size());
      for (std::size_t i = 0; i < fresh.size(); ++i)
        EXPECT_EQ(refilled[i].pose.asVectorVal(), fresh[i].pose.asVectorVal())
            << "overlap " << overlap << " late " << late << " frame " << i;
    }
}

// push() is the frame loop one frame late: each frame's report comes when the next frame is pushed, the
// last one's from flush() (finish() refuses while one is held). Without capture mode's refit (interval
// mode) nothing else changes: the poses are process()'s, bit for bit.
TEST(Reconstruction, PushReportsEachFrameWhenTheNextIsPushed) {
  const sim::SyntheticSequence seq(test::quickSim("room", 8, "shake"));
  mrpt::config::CConfigFileMemory cfg = test::quickRoomConfig();
  cfg.write("odometry", "colour_time_velocity", "interval");
  Reconstruction at_once(cfg, TrackingMode::Joint), late(cfg, TrackingMode::Joint);
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const Frame f = seq.render(i);
    at_once.process(f);
    const std::optional<FrameReport> r = late.push(f);
    ASSERT_EQ(r.has_value(), i > 0) << "frame " << i;
    if (r) EXPECT_EQ(r->index, seq.render(i - 1).index);
    EXPECT_EQ(late.framesProcessed(), i);
  }
  EXPECT_THROW(late.process(seq.render(0)), std::logic_error);
  const std::optional<FrameReport> last = late.flush();
  ASSERT_TRUE(last);
  EXPECT_EQ(last->index, seq.render(seq.size() - 1).index);
  EXPECT_FALSE(late.flush());
  ASSERT_EQ(late.trajectory().size(), at_once.trajectory().size());
  for (std::size_t i = 0; i < seq.size(); ++i)
    EXPECT_EQ(late.trajectory()[i].pose.asVectorVal(), at_once.trajectory()[i].pose.asVectorVal()) << "frame " << i;

  Reconstruction ended(cfg, TrackingMode::Joint);
  for (std::size_t i = 0; i < 3; ++i) ended.push(seq.render(i));
  EXPECT_THROW(ended.finish(), std::logic_error) << "the held frame's report would be lost";
  ASSERT_TRUE(ended.flush());
  ended.finish();
  EXPECT_EQ(ended.trajectory().size(), 3u);
}

// In capture mode a frame held back is fitted again with the motion after it: its colour camera is
// placed from both sides (the tracker's colour pose too). process() has no next motion to refit with.
TEST(Reconstruction, AHeldFrameIsRefittedInCaptureMode) {
  const sim::SyntheticSequence seq(test::quickSim("room", 8, "shake"));
  mrpt::config::CConfigFileMemory cfg = test::quickRoomConfig();
  cfg.write("odometry", "colour_time_velocity", "capture");
  Reconstruction at_once(cfg, TrackingMode::Joint), late(cfg, TrackingMode::Joint);
  int refitted = 0;
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const Frame f = seq.render(i);
    EXPECT_FALSE(at_once.process(f).odometry.colour_motion) << "frame " << i;
    if (const std::optional<FrameReport> r = late.push(f); r && r->odometry.colour_motion) ++refitted;
  }
  EXPECT_FALSE(late.flush()->odometry.colour_motion) << "the last frame has no next one";
  EXPECT_GE(refitted, int(seq.size()) - 3);  // not the first frame, nor the one it starts from
}

// A frame whose every reading is NaN has no depth, as one of zeros: lost with the pose held, in every
// mode (NaN counted as a reading: modes joint and odometry moved the frame on at constant velocity).
TEST(Reconstruction, DepthOfNaNOnlyIsNoDepthAsZerosAre) {
  const sim::SyntheticSequence seq(smallRoom());
  const std::size_t blank_frame = 6;
  for (const TrackingMode mode : {TrackingMode::Joint, TrackingMode::KinFu, TrackingMode::Odometry, TrackingMode::PaperHandoff}) {
    std::vector<std::pair<std::size_t, std::size_t>> counts;  // lost, predicted
    std::vector<Trajectory> paths;
    for (const float blank : {0.f, std::numeric_limits<float>::quiet_NaN()}) {
      Reconstruction rec(test::quickRoomConfig(), mode);
      for (std::size_t i = 0; i < 10; ++i) {
        Frame f = seq.render(i);
        if (i == blank_frame) f.depth.setTo(blank);
        rec.process(f);
      }
      rec.finish();
      counts.emplace_back(rec.lostFrames(), rec.predictedFrames());
      paths.push_back(rec.trajectory());
    }
    EXPECT_EQ(counts[0], std::make_pair(std::size_t(1), std::size_t(0))) << toString(mode);
    EXPECT_EQ(counts[1], counts[0]) << toString(mode) << " (lost, predicted)";
    ASSERT_EQ(paths[1].size(), paths[0].size()) << toString(mode);
    for (std::size_t i = 0; i < paths[0].size(); ++i)
      EXPECT_LT((paths[1][i].pose.translation() - paths[0][i].pose.translation()).norm(), 1e-6) << toString(mode) << " frame " << i;
  }
}

// Frame::depth is metres as float: a 16-bit image (sensor units, no scale) is a caller's error in every
// mode (mode kinfu took it for a frame without depth and lost every frame).
TEST(Reconstruction, DepthInSensorUnitsIsRefusedInEveryMode) {
  const sim::SyntheticSequence seq(smallRoom());
  for (const TrackingMode mode : {TrackingMode::Joint, TrackingMode::KinFu, TrackingMode::Odometry, TrackingMode::PaperHandoff}) {
    Reconstruction rec(test::quickRoomConfig(), mode);
    Frame f = seq.render(0);
    f.depth.convertTo(f.depth, CV_16U, 5000.0);
    try {
      rec.process(f);
      ADD_FAILURE() << toString(mode) << ": 16-bit depth was taken";
    } catch (const std::invalid_argument& e) {
      EXPECT_NE(std::string(e.what()).find("CV_32FC1 metres"), std::string::npos) << toString(mode) << ": " << e.what();
    }
  }
}

// Once meshed the map can go (RunRecorder does so before the whole-mesh repair and the pictures):
// the trajectory and the fusion statistics stay, what needs the map says so instead of crashing.
TEST(Reconstruction, ReleasingTheMapKeepsTrajectoryAndStatistics) {
  Reconstruction rec(test::quickRoomConfig(), TrackingMode::Joint);
  fuse(rec, sim::SyntheticSequence(smallRoom()), 4);
  const KinFuStats before = rec.fusionStats();
  const Trajectory poses = rec.trajectory();
  ASSERT_GT(before.bricks_in_volume, 0u);
  ASSERT_GT(rec.extractMesh().faces.size(), 1000u);
  EXPECT_FALSE(rec.mapReleased());

  rec.releaseMap();
  EXPECT_TRUE(rec.mapReleased());
  EXPECT_EQ(rec.fusionStats().bricks_in_volume, before.bricks_in_volume);
  EXPECT_EQ(rec.fusionStats().memory_bytes, before.memory_bytes);
  ASSERT_EQ(rec.trajectory().size(), poses.size());
  EXPECT_EQ(rec.trajectory().back().pose.asVectorVal(), poses.back().pose.asVectorVal());
  EXPECT_THROW(rec.extractMesh(), std::logic_error);
  EXPECT_THROW(rec.saveVolume(testing::TempDir() + "/released.vfvol"), std::logic_error);
  // Re-fusing needs the tracked map's statistics: it dereferenced the released map.
  EXPECT_THROW(rec.reintegrate([](Frame&) { return false; }), std::logic_error);
  rec.releaseMap();  // twice is harmless
}

// Re-fusing reads the recording again. Frames it lacks now (damaged since the run) pass their poses
// over: the frames after them used to be fused at the missing frames' poses, ten frames behind here.
TEST(Reconstruction, ReintegrationPassesOverFramesTheRecordingNoLongerHas) {
  const std::size_t frames = 24;
  const sim::SyntheticSequence seq(test::quickSim("room", frames));
  Reconstruction rec(test::quickRoomConfig(), TrackingMode::Joint);
  for (std::size_t i = 0; i < frames; ++i) rec.process(seq.render(i));
  std::size_t next = 0, last_progress = 0;
  const std::size_t fused = rec.reintegrate(
      [&](Frame& f) {
        if (next == 5) next = 15;  // frames 5-14 gone
        return next < frames ? (f = seq.render(next++), true) : false;
      },
      [&](std::size_t read) { last_progress = read; });
  EXPECT_EQ(fused, frames - 10);
  EXPECT_EQ(last_progress, frames) << "frame 23 was fused at frame 13's pose";
}

// A run that went on from a saved map (--resume map) and closed a loop fuses its frames again into
// that map: re-fusing into an empty one dropped every surface of the earlier sessions.
TEST(Reconstruction, ReintegrationKeepsTheMapTheRunWentOnFrom) {
  const std::size_t frames = 24, first_session = 20;
  const sim::SyntheticSequence seq(test::quickSim("room", frames));
  const std::string map_file = test::tempDir("reintegrate_resumed") + "/first.vfmap";
  std::size_t saved_bricks = 0;
  {
    Reconstruction first(test::quickRoomConfig(), TrackingMode::Joint);
    for (std::size_t i = 0; i < first_session; ++i) first.process(seq.render(i));
    first.finish();
    first.saveVolume(map_file);
    const KinFuStats s = first.fusionStats();
    saved_bricks = s.bricks_in_volume + s.bricks_in_world_model;
  }
  {
    // Only before the first frame: the map would be replaced under what reads it during the run.
    Reconstruction late(test::quickRoomConfig(), TrackingMode::Joint);
    late.process(seq.render(0));
    EXPECT_THROW(late.resumeVolume(map_file), std::logic_error);
  }
  Reconstruction second(test::quickRoomConfig(), TrackingMode::Joint);
  second.resumeVolume(map_file);
  for (std::size_t i = first_session; i < frames; ++i) second.process(seq.render(i));
  std::size_t next = first_session;
  EXPECT_EQ(second.reintegrate([&](Frame& f) { return next < frames ? (f = seq.render(next++), true) : false; }),
            frames - first_session);
  const KinFuStats after = second.fusionStats();
  EXPECT_GE(after.bricks_in_volume + after.bricks_in_world_model, saved_bricks);
  EXPECT_GT(second.extractMesh().faces.size(), 1000u);
  EXPECT_FALSE(second.reintegrationBlocked().has_value());

  // A map saved over since (this run's --save-volume, then its checkpoint resumed) holds the frames
  // already, so it cannot be fused into again; fusing them without it lost the earlier sessions (and
  // --save-volume then wrote that over the file). The map stays as tracked, which holds them, and why is said.
  Reconstruction third(test::quickRoomConfig(), TrackingMode::Joint);
  third.resumeVolume(map_file);
  for (std::size_t i = first_session; i < frames; ++i) third.process(seq.render(i));
  third.saveVolume(map_file);
  ASSERT_TRUE(third.reintegrationBlocked().has_value());
  EXPECT_NE(third.reintegrationBlocked()->find("changed or gone since the run went on from it"), std::string::npos);
  next = first_session;
  EXPECT_EQ(third.reintegrate([&](Frame& f) { return next < frames ? (f = seq.render(next++), true) : false; }), 0u);
  EXPECT_FALSE(third.reintegrated());
  const KinFuStats kept = third.fusionStats();
  EXPECT_GE(kept.bricks_in_volume + kept.bricks_in_world_model, saved_bricks) << "the earlier session was lost";

  // Unchanged by its size and time but unreadable since (a byte flipped on a failing disk): found before
  // the tracked map goes. The frames were fused without it, and --save-volume wrote that over the file.
  const std::string damaged_file = test::tempDir("reintegrate_resumed_damaged") + "/first.vfmap";
  {
    Reconstruction first(test::quickRoomConfig(), TrackingMode::Joint);
    for (std::size_t i = 0; i < first_session; ++i) first.process(seq.render(i));
    first.finish();
    first.saveVolume(damaged_file);
  }
  Reconstruction fourth(test::quickRoomConfig(), TrackingMode::Joint);
  fourth.resumeVolume(damaged_file);
  for (std::size_t i = first_session; i < frames; ++i) fourth.process(seq.render(i));
  const auto written = std::filesystem::last_write_time(damaged_file);
  {
    std::fstream f(damaged_file, std::ios::in | std::ios::out | std::ios::binary);
    f.seekg(200);
    const char c = char(f.get());
    f.seekp(200);
    f.put(char(c ^ 0x10));
  }
  std::filesystem::last_write_time(damaged_file, written);
  ASSERT_TRUE(fourth.reintegrationBlocked().has_value());
  EXPECT_NE(fourth.reintegrationBlocked()->find("truncated or corrupt map"), std::string::npos) << *fourth.reintegrationBlocked();
  next = first_session;
  EXPECT_EQ(fourth.reintegrate([&](Frame& f) { return next < frames ? (f = seq.render(next++), true) : false; }), 0u);
  const KinFuStats tracked = fourth.fusionStats();
  EXPECT_GE(tracked.bricks_in_volume + tracked.bricks_in_world_model, saved_bricks) << "the earlier session was lost";
}

// A depth image of odd width or height: halved for tracking, its odd column and row are dropped, and
// the tracking camera says so. It said one pixel more (rounded up), the ray cast's hint never matched
// the frame's size, the model stayed empty, and mode kinfu lost every frame after the first.
TEST(Reconstruction, AnOddSizedDepthImageIsTracked) {
  sim::SimOptions o = test::quickSim("room", 8);
  o.camera = CameraIntrinsics{};
  o.camera.width = 641;
  o.camera.height = 481;
  const sim::SyntheticSequence seq(o);
  Reconstruction rec(test::quickRoomConfig(), TrackingMode::KinFu);
  for (std::size_t i = 0; i < seq.size(); ++i) {
    const FrameReport r = rec.process(seq.render(i));
    EXPECT_TRUE(r.tracked && !r.fell_back) << i << ": " << r.note;
  }
}

// The repair's counts are the regions' and the welded mesh's together: summary.json's mesh_clean gave
// only the welded mesh's (rpy_first100: 462 non-manifold vertices split of 9377, 124 border edges
// stitched of 2011), whose repair only joins regions repaired each on its own.
TEST(Reconstruction, MeshByRegionCountsEveryRegionsRepair) {
  Reconstruction rec(test::quickRoomConfig(), TrackingMode::Joint);
  fuse(rec, sim::SyntheticSequence(smallRoom()), smallRoom().frames);
  MeshCleanParams params;
  params.min_component_faces = 0;  // no fragment dropped before the regions' repair: the test's regions are meshByRegion's
  params.min_component_area = 0;
  MeshCleanReport regions;
  rec.extractMeshByRegion(4, [&](fusion::RegionMesh& r) {
    const MeshCleanReport rr = simplifyRegion(r.mesh, r.on_seam, regionSimplifyParams(params));
    ASSERT_TRUE(rr.success) << rr.failure;
    regions.duplicate_vertices_merged += rr.duplicate_vertices_merged;
    regions.degenerate_faces_removed += rr.degenerate_faces_removed;
    regions.duplicate_faces_removed += rr.duplicate_faces_removed;
    regions.border_edges_stitched += rr.border_edges_stitched;
    regions.non_manifold_vertices_split += rr.non_manifold_vertices_split;
  });
  ASSERT_GT(regions.non_manifold_vertices_split + regions.border_edges_stitched + regions.duplicate_faces_removed, 0u);
  const RegionMeshResult r = meshByRegion(
      [&](const std::function<void(fusion::RegionMesh&)>& sink) { rec.extractMeshByRegion(4, sink); }, params);
  ASSERT_TRUE(r.report.success) << r.report.failure;
  EXPECT_GE(r.report.duplicate_vertices_merged, regions.duplicate_vertices_merged);
  EXPECT_GE(r.report.degenerate_faces_removed, regions.degenerate_faces_removed);
  EXPECT_GE(r.report.duplicate_faces_removed, regions.duplicate_faces_removed);
  EXPECT_GE(r.report.border_edges_stitched, regions.border_edges_stitched);
  EXPECT_GE(r.report.non_manifold_vertices_split, regions.non_manifold_vertices_split);
}

// Region by region the fused room comes out in as many pieces as the whole world cleaned at once:
// no slivers left where a region's repair cut a kept surface at a seam (they were the specks along
// the bundled room's wall tops in mesh.png).
TEST(Reconstruction, MeshByRegionLeavesNoSeamSlivers) {
  Reconstruction rec(test::quickRoomConfig(), TrackingMode::Joint);
  fuse(rec, sim::SyntheticSequence(smallRoom()), smallRoom().frames);
  MeshCleanParams params;  // defaults: repair, fragments under 50 faces, error-bounded simplification
  TriangleMesh whole = rec.extractMesh();
  const MeshCleanReport at_once = cleanMesh(whole, params);
  ASSERT_TRUE(at_once.success) << at_once.failure;
  for (int region_bricks : {2, 4, 8}) {
    const RegionMeshResult r = meshByRegion(
        [&](const std::function<void(fusion::RegionMesh&)>& sink) { rec.extractMeshByRegion(region_bricks, sink); }, params);
    ASSERT_TRUE(r.report.success) << r.report.failure;
    EXPECT_GT(r.regions, 8u);
    EXPECT_LE(r.report.components_kept, at_once.components_kept + 2) << region_bricks << " bricks a region";
  }
}
