#include <Eigen/Dense>
// MRPT rawlog reading and writing: a real OpenNI2 capture, round trips in both formats, bad input.
#include <unistd.h>

#include <algorithm>
#include <csignal>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <chrono>
#include <thread>
#include <limits>
#include <tuple>

#include <sys/resource.h>

#include <mrpt/core/Clock.h>
#include <mrpt/io/CFileGZOutputStream.h>
#include <mrpt/obs/CObservationOdometry.h>
#include <mrpt/obs/CObservationRobotPose.h>
#include <mrpt/obs/CRawlog.h>
#include <mrpt/serialization/CArchive.h>

#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "support.h"
#include "link_watch.h"
#include "sync_watch.h"
#include "vofusion/core/errors.h"
#include "vofusion/io/rawlog.h"
#include "vofusion/io/rawlog_time.h"
#include "vofusion/sim/synthetic_sequence.h"
#include "vofusion/sim/any_source.h"

using namespace vofusion;
namespace fs = std::filesystem;

namespace {
const char* kMrptRgbd = "/usr/share/mrpt/datasets/tests_rgbd.rawlog";

std::vector<Frame> simFrames(std::size_t n) {
  sim::SimOptions o;
  o.frames = n;
  o.camera = o.camera.scaled(0.5);
  return test::renderFrames(sim::SyntheticSequence(o));
}

std::string writeRawlog(const std::string& path, const std::vector<Frame>& frames, const RawlogWriterOptions& o) {
  RawlogWriter w(path, o);
  for (std::size_t i = 0; i < frames.size(); ++i) {
    if (o.format == RawlogWriterOptions::Format::ActionsSensoryFrames && i > 0)
      w.writeAction(makeOdometryAction(*frames[i].groundTruth - *frames[i - 1].groundTruth, frames[i].timestamp));
    w.write(frames[i]);
  }
  w.commit();
  return path;
}

// frames into `path` with their ground truth in the companion file only; committed.
void writeWithGroundTruthFile(const std::string& path, const std::vector<Frame>& frames) {
  RawlogWriterOptions o;
  o.ground_truth_observations = false;
  RawlogWriter w(path, o);
  Trajectory gt;
  for (const auto& f : frames) {
    w.write(f);
    gt.push_back({f.timestamp, *f.groundTruth});
  }
  w.writeGroundTruth(gt);
  w.commit();
}

void expectSameFrames(const std::vector<Frame>& a, FrameSource& src, double depth_tol) {
  ASSERT_EQ(src.size(), a.size());
  Frame f;
  for (const Frame& e : a) {
    ASSERT_TRUE(src.next(f));
    EXPECT_NEAR(f.timestamp, e.timestamp, 1e-6);
    EXPECT_EQ(cv::norm(f.rgb, e.rgb, cv::NORM_INF), 0.0);
    EXPECT_LE(cv::norm(f.depth, e.depth, cv::NORM_INF), depth_tol);
    EXPECT_EQ(cv::countNonZero(f.depth > 0), cv::countNonZero(e.depth > 0));
    EXPECT_DOUBLE_EQ(f.camera.fx, e.camera.fx);
    EXPECT_DOUBLE_EQ(f.camera.cy, e.camera.cy);
    EXPECT_EQ(f.camera.width, e.camera.width);
    ASSERT_TRUE(f.groundTruth.has_value());
    EXPECT_LT((f.groundTruth->asVectorVal() - e.groundTruth->asVectorVal()).norm(), 1e-5);
  }
  EXPECT_FALSE(src.next(f));
}
}  // namespace

TEST(Rawlog, ReadsRealOpenNI2Capture) {
  VOFUSION_REQUIRE_DATA(kMrptRgbd);
  auto src = openFrameSource(kMrptRgbd);
  ASSERT_EQ(src->size(), 1u);
  Frame f;
  ASSERT_TRUE(src->next(f));
  Frame none;
  EXPECT_FALSE(src->next(none));  // one frame, as size() says
  EXPECT_EQ(f.rgb.type(), CV_8UC3);
  EXPECT_EQ(f.depth.type(), CV_32FC1);
  EXPECT_EQ(f.rgb.size(), f.depth.size());
  EXPECT_EQ(f.camera.width, f.depth.cols);
  EXPECT_NEAR(f.timestamp, 1462879443.617188, 1e-3);  // as rawlog-edit --info reports
  EXPECT_GT(f.camera.fx, 100.0);
  const double valid = cv::countNonZero(f.depth > 0) / double(f.depth.total());
  EXPECT_GT(valid, 0.3);
  const double mean = cv::mean(f.depth, f.depth > 0)[0];
  EXPECT_GT(mean, 0.3);  // metres, an indoor scene
  EXPECT_LT(mean, 8.0);
  cv::Scalar m, sd;
  cv::meanStdDev(f.rgb, m, sd);
  EXPECT_GT(sd[0], 5.0);  // a real image, not a blank
  src->rewind();
  Frame g;
  ASSERT_TRUE(src->next(g));
  EXPECT_EQ(cv::norm(f.depth, g.depth, cv::NORM_INF), 0.0);
}

TEST(Rawlog, RoundTripObservationsExternalImages) {
  const auto frames = simFrames(4);
  const std::string dir = test::tempDir("rawlog_obs");
  const std::string path = writeRawlog(dir + "/seq.rawlog", frames, {});
  EXPECT_TRUE(fs::is_directory(dir + "/seq_Images"));
  EXPECT_EQ(std::distance(fs::directory_iterator(dir + "/seq_Images"), fs::directory_iterator{}), 8);
  RawlogSource src(path, {});
  expectSameFrames(frames, src, 1e-4 + 1e-6);  // 2e-4 m units: half a unit
  src.rewind();
  expectSameFrames(frames, src, 1e-4 + 1e-6);
  // Nothing temporary left behind.
  for (const auto& e : fs::directory_iterator(dir))
    EXPECT_EQ(e.path().filename().string().find(".tmp-"), std::string::npos) << e.path();
  // Its images in a folder "Images" beside it, as MRPT's CRawlog also finds them (RawLogViewer opens
  // such a recording): every frame was "missing or corrupt".
  fs::rename(dir + "/seq_Images", dir + "/Images");
  RawlogSource beside(path, {});
  expectSameFrames(frames, beside, 1e-4 + 1e-6);
}

// A long sensor label names each frame's images whole: cut to a fixed buffer, every frame's images had
// one name, and each frame's replaced those of the frames recorded before it.
TEST(Rawlog, ALongSensorLabelGivesEachFrameItsOwnImages) {
  const auto frames = simFrames(3);
  const std::string dir = test::tempDir("rawlog_long_label");
  RawlogWriterOptions o;
  o.sensor_label = std::string(121, 'A');  // the frame number was cut at its last digit
  const std::string path = writeRawlog(dir + "/seq.rawlog", frames, o);
  EXPECT_EQ(std::distance(fs::directory_iterator(dir + "/seq_Images"), fs::directory_iterator{}), 6);
  RawlogSource src(path, {});
  expectSameFrames(frames, src, 1e-4 + 1e-6);
}

// A rawlog of several cameras (a rig; Robot@Home records four) is read as the first camera's: the
// others' scans, read as its frames, were views from cameras facing elsewhere tracked as one path.
TEST(Rawlog, ARawlogOfSeveralCamerasIsReadAsTheFirstOnes) {
  const auto frames = simFrames(4);
  const std::string dir = test::tempDir("rawlog_two_cameras");
  auto other = simFrames(4);
  {
    RawlogWriterOptions o;
    o.external_images = false;
    RawlogWriter w(dir + "/two.rawlog", o);
    for (std::size_t i = 0; i < frames.size(); ++i) {
      w.write(frames[i]);
      cv::flip(other[i].depth, other[i].depth, 1);  // another view
      w.writeObservation(*observationFromFrame(other[i], 2e-4, "OTHER"));
    }
    w.commit();
  }
  RawlogSource src(dir + "/two.rawlog", {});
  EXPECT_EQ(src.size(), frames.size());
  expectSameFrames(frames, src, 1e-4 + 1e-6);
  src.rewind();
  expectSameFrames(frames, src, 1e-4 + 1e-6);
}

namespace {
std::string fileBytes(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  return {std::istreambuf_iterator<char>(f), std::istreambuf_iterator<char>()};
}
}  // namespace

// Frames decoded from an 8-bit RGB PNG (TUM, 7-Scenes) keep that file's bytes in the rawlog's
// images; anything else (here a grey PNG the reader expanded to BGR) is encoded from the pixels.
TEST(Rawlog, ExternalImagesCopySourcePngsWhenTheyMatch) {
  auto frames = simFrames(2);
  const std::string dir = test::tempDir("rawlog_copy_png");
  const std::string rgb_png = dir + "/rgb0.png", grey_png = dir + "/grey1.png";
  ASSERT_TRUE(cv::imwrite(rgb_png, frames[0].rgb, {cv::IMWRITE_PNG_COMPRESSION, 9}));
  cv::Mat grey;
  cv::cvtColor(frames[1].rgb, grey, cv::COLOR_BGR2GRAY);
  ASSERT_TRUE(cv::imwrite(grey_png, grey));
  cv::cvtColor(grey, frames[1].rgb, cv::COLOR_GRAY2BGR);
  frames[0].colour_file = ColourFile{rgb_png};
  frames[1].colour_file = ColourFile{grey_png};
  const std::string path = writeRawlog(dir + "/seq.rawlog", frames, {});
  std::vector<std::string> written;
  for (const auto& e : fs::directory_iterator(dir + "/seq_Images"))
    if (e.path().extension() == ".png") written.push_back(e.path().string());
  std::sort(written.begin(), written.end());
  ASSERT_EQ(written.size(), 2u);
  EXPECT_EQ(fileBytes(written[0]), fileBytes(rgb_png));  // level 9: our own encoder (level 1) differs
  EXPECT_NE(fileBytes(written[1]), fileBytes(grey_png));
  RawlogSource src(path, {});
  expectSameFrames(frames, src, 1e-4 + 1e-6);
  // Frames read from a rawlog name its colour PNGs: a rawlog written from them (vofusion's result of a
  // rawlog input) copies those bytes too (level 9 again, not our level 1).
  src.rewind();
  std::vector<Frame> again(2);
  for (auto& f : again) ASSERT_TRUE(src.next(f));
  ASSERT_TRUE(again[0].colour_file);
  EXPECT_EQ(again[0].colour_file->path, fs::absolute(written[0]).string());
  EXPECT_FALSE(again[0].colour_file->recorded);
  writeRawlog(dir + "/again.rawlog", again, {});
  std::vector<std::string> copied;
  for (const auto& e : fs::directory_iterator(dir + "/again_Images"))
    if (e.path().extension() == ".png") copied.push_back(e.path().string());
  std::sort(copied.begin(), copied.end());
  ASSERT_EQ(copied.size(), 2u);
  EXPECT_EQ(fileBytes(copied[0]), fileBytes(rgb_png));
  EXPECT_EQ(fileBytes(copied[1]), fileBytes(written[1]));
}

// Frames read from a rawlog name their range-image files: a rawlog written from them at the same
// units copies those bytes instead of compressing the depth again; at other units, or when the file is
// no longer the one read, the depth is written anew.
TEST(Rawlog, RangeImageFilesOfARawlogInputAreCopiedAtTheirUnits) {
  const std::string dir = test::tempDir("rawlog_copy_bin");
  writeRawlog(dir + "/src.rawlog", simFrames(3), {});
  std::vector<std::string> bins;
  for (const auto& e : fs::directory_iterator(dir + "/src_Images"))
    if (e.path().extension() == ".bin") bins.push_back(e.path().string());
  std::sort(bins.begin(), bins.end());
  ASSERT_EQ(bins.size(), 3u);
  for (const std::string& bin : bins) {  // gzip's OS byte (no checksum covers it): these bytes are no writer's own
    std::string b = fileBytes(bin);
    b[9] = 7;
    std::ofstream(bin, std::ios::binary) << b;
  }
  RawlogSource src(dir + "/src.rawlog", {});
  std::vector<Frame> frames(3);
  for (auto& f : frames) ASSERT_TRUE(src.next(f));
  ASSERT_TRUE(frames[0].depth_file);
  EXPECT_EQ(frames[0].depth_file->path, fs::absolute(bins[0]).string());
  EXPECT_EQ(float(frames[0].depth_file->units), float(RawlogWriterOptions{}.range_units));
  {  // frame 1's file changed since it was read: its CRC-32 (the readings in memory are what counts)
    std::string b = fileBytes(bins[1]);
    b[b.size() - 8] ^= 1;
    std::ofstream(bins[1], std::ios::binary) << b;
  }
  cv::resize(frames[2].depth, frames[2].depth, cv::Size(), 0.5, 0.5, cv::INTER_NEAREST);  // changed: no file holds it
  frames[2].depth_file.reset();
  frames[2].camera = frames[2].camera.scaled(0.5);
  frames[2].rgb = cv::Mat(frames[2].depth.size(), CV_8UC3, cv::Scalar(9, 9, 9));
  frames[2].colour_file.reset();
  auto binsOf = [&](const std::string& name) {
    std::vector<std::string> out, paths;
    for (const auto& e : fs::directory_iterator(dir + "/" + name + "_Images"))
      if (e.path().extension() == ".bin") paths.push_back(e.path().string());
    std::sort(paths.begin(), paths.end());
    for (const auto& p : paths) out.push_back(fileBytes(p));
    return out;
  };
  writeRawlog(dir + "/same.rawlog", frames, {});
  const auto same = binsOf("same");
  ASSERT_EQ(same.size(), 3u);
  EXPECT_EQ(same[0], fileBytes(bins[0]));
  EXPECT_NE(same[1], fileBytes(bins[1]));
  EXPECT_NE(same[2], fileBytes(bins[2]));
  RawlogWriterOptions mm;
  mm.range_units = 1e-3;
  writeRawlog(dir + "/mm.rawlog", frames, mm);
  const auto other = binsOf("mm");
  ASSERT_EQ(other.size(), 3u);
  EXPECT_NE(other[0], fileBytes(bins[0]));
  RawlogSource same_src(dir + "/same.rawlog", {}), mm_src(dir + "/mm.rawlog", {});
  expectSameFrames(frames, same_src, 1e-4 + 1e-6);
  expectSameFrames(frames, mm_src, 5e-4 + 1e-6);
}

// Depth is written at the units the observation says, as MRPT's readers take them (units times the
// stored value): only the float's own error from 1/n is snapped to 1/n (2e-4 = 1/5000; 0.0019, 0.1 % off
// 1/526, was written at 1/526 m a unit, read 0.1 % short).
TEST(Rawlog, DepthIsWrittenAtTheUnitsItsObservationSays) {
  Frame f = simFrames(1).front();
  f.depth.setTo(5.0f);
  for (const double units : {2e-4, 1e-3, 0.0019, 0.0015}) {
    const auto obs = observationFromFrame(f, units);
    const double as_mrpt_reads = double(obs->rangeImage(0, 0)) * double(obs->rangeUnits);
    EXPECT_NEAR(as_mrpt_reads, 5.0, 0.5 * units + 1e-6) << units;
    EXPECT_NEAR(frameFromObservation(*obs, "x").depth.at<float>(0, 0), 5.0f, 0.5 * units + 1e-6) << units;
  }
}

// A record whose stamp no rawlog clock holds (a flipped byte) is a damaged frame, named: rgbd-odometry
// lost its whole run at writing it ("timestamp ... beyond what a rawlog's clock holds", no file named).
TEST(Rawlog, AStampBeyondAnySensorsClockIsTheFramesDamage) {
  const Frame f = simFrames(1).front();
  const auto obs = observationFromFrame(f, 1e-3);
  obs->timestamp = rawlogTime(1.0e9);
  obs->timestamp += std::chrono::seconds(1000000000000LL);  // 1e12 s after 1970: past the clock's end
  try {
    frameFromObservation(*obs, "x.rawlog: entry 3");
    ADD_FAILURE() << "read";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("x.rawlog: entry 3: timestamp 1.001e+12 s is beyond any sensor's clock"),
              std::string::npos) << e.what();
  }
}

// Depth camera parameters calibrated at another size of the same aspect (640x480 over a 320x240 range
// image) are scaled to the image: they were taken as they were, the focal length twice the image's.
// Parameters whose size fields are stale (MRPT's default 640x480 around parameters for the stored
// image) are taken as they are; another aspect is refused in one line.
TEST(Rawlog, DepthCameraParametersOfAnotherSizeAreScaledToTheImage) {
  const Frame f = simFrames(1).front();
  ASSERT_EQ(f.camera.width, 320);
  const auto obs = observationFromFrame(f, 1e-3);
  const auto expectCamera = [&](const char* what) {
    const CameraIntrinsics got = frameFromObservation(*obs, "x").camera;
    EXPECT_NEAR(got.fx, f.camera.fx, 1e-9) << what;
    EXPECT_NEAR(got.fy, f.camera.fy, 1e-9) << what;
    EXPECT_NEAR(got.cx, f.camera.cx, 1e-9) << what;
    EXPECT_NEAR(got.cy, f.camera.cy, 1e-9) << what;
  };
  const CameraIntrinsics full = f.camera.scaled(2.0);
  obs->cameraParams = full.toMrpt();
  expectCamera("calibrated at 640x480");
  obs->cameraParams = f.camera.toMrpt();
  obs->cameraParams.ncols = 640;
  obs->cameraParams.nrows = 480;
  expectCamera("stale size fields");
  CameraIntrinsics taller = full;
  taller.height = 512;
  taller.cy = 255.5;
  obs->cameraParams = taller.toMrpt();
  try {
    frameFromObservation(*obs, "x");
    ADD_FAILURE() << "another aspect was taken";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "x: the depth camera's parameters are for 640x512 images, the range image is 320x240 "
                                     "(another aspect: give --intrinsics)");
  }
}

TEST(Rawlog, RoundTripSensoryFramesEmbeddedWithActions) {
  const auto frames = simFrames(3);
  const std::string dir = test::tempDir("rawlog_sf");
  RawlogWriterOptions o;
  o.format = RawlogWriterOptions::Format::ActionsSensoryFrames;
  o.external_images = false;
  o.range_units = 1e-3;
  const std::string path = writeRawlog(dir + "/sf.rawlog", frames, o);
  EXPECT_FALSE(fs::exists(dir + "/sf_Images"));
  RawlogSource src(path, {});
  expectSameFrames(frames, src, 5e-4 + 1e-6);
  // MRPT itself sees the action/sensory-frame pairs with our odometry.
  mrpt::obs::CRawlog log;
  ASSERT_TRUE(log.loadFromRawLogFile(path));
  ASSERT_EQ(log.size(), 6u);
  auto acts = log.getAsAction(2);
  ASSERT_EQ(acts->size(), 1u);
  const auto delta = *frames[1].groundTruth - *frames[0].groundTruth;
  auto mv = std::dynamic_pointer_cast<mrpt::obs::CActionRobotMovement3D>(acts->get(0));
  ASSERT_TRUE(mv);
  EXPECT_EQ(mv->estimationMethod, mrpt::obs::CActionRobotMovement3D::emVisualOdometry);
  EXPECT_LT((mv->poseChange.mean.asVectorVal() - delta.asVectorVal()).norm(), 1e-12);
}

// Observations that follow no frame (poses.rawlog's optimised poses, one per frame of the run) go out
// in sensory frames of at most 4096: in one, a long run's passed what a reader allows one entry.
TEST(Rawlog, ManyObservationsAfterTheFramesGoOutInBoundedEntries) {
  const std::string dir = test::tempDir("rawlog_many_obs");
  RawlogWriterOptions o;
  o.format = RawlogWriterOptions::Format::ActionsSensoryFrames;
  o.external_images = false;
  const std::size_t n = 10000;
  {
    RawlogWriter w(dir + "/p.rawlog", o);
    w.write(simFrames(1)[0]);
    for (std::size_t i = 0; i < n; ++i) {
      mrpt::obs::CObservationRobotPose pose;
      pose.sensorLabel = "VOFUSION_POSE_OPTIMISED";
      pose.timestamp = mrpt::Clock::fromDouble(1.0 + double(i) / 30);
      w.writeObservation(pose);
    }
    w.commit();
  }
  mrpt::obs::CRawlog log;
  ASSERT_TRUE(log.loadFromRawLogFile(dir + "/p.rawlog"));
  std::size_t poses = 0;
  for (std::size_t i = 0; i < log.size(); ++i) {
    if (log.getType(i) != mrpt::obs::CRawlog::etSensoryFrame) continue;
    const auto sf = log.getAsObservations(i);
    EXPECT_LE(sf->size(), 4096u) << "entry " << i;
    for (const auto& obs : *sf) poses += obs->sensorLabel == "VOFUSION_POSE_OPTIMISED";
  }
  EXPECT_EQ(poses, n);
}

// Each frame's colour offset (its colour image taken off the depth's time, TUM fr1: up to 20 ms) comes
// back from a rawlog, in both formats: an observation holds one time, so a COLOUR_TIME comment stamped at
// the colour image's time follows the scan. Without it the odometry's colour-time correction had nothing
// to use (rpy_first100 from a rawlog: ATE 0.0177 against 0.0164 m from the folder).
// Frame 0 is at 0 s, so its colour image, taken 8.1 ms before, is stamped before 1970: MRPT's toDouble
// read that back as ~1.8e12 s, and the offset was dropped.
TEST(Rawlog, ColourOffsetsComeBack) {
  auto frames = simFrames(4);
  ASSERT_EQ(frames[0].timestamp, 0.0);
  const double offsets[] = {-0.0081, 0.0172, -0.0081, 0.0};
  for (std::size_t i = 0; i < frames.size(); ++i) frames[i].colour_offset = offsets[i];
  const std::string dir = test::tempDir("rawlog_colour_offsets");
  for (const auto format : {RawlogWriterOptions::Format::Observations, RawlogWriterOptions::Format::ActionsSensoryFrames}) {
    RawlogWriterOptions o;
    o.format = format;
    const std::string path = writeRawlog(dir + "/f" + std::to_string(int(format)) + ".rawlog", frames, o);
    RawlogSource src(path, {});
    Frame f;
    std::size_t read = 0;
    for (; src.next(f); ++read) EXPECT_NEAR(f.colour_offset, offsets[read], 1e-6) << "frame " << read;
    EXPECT_EQ(read, frames.size());
    // Read on to the last frame's entry with --max-frames (it follows the scan).
    SourceOptions two;
    two.max_frames = 2;
    RawlogSource first_two(path, two);
    for (read = 0; first_two.next(f); ++read) EXPECT_NEAR(f.colour_offset, offsets[read], 1e-6) << "max-frames, frame " << read;
    EXPECT_EQ(read, 2u);
    // MRPT's own reader keeps every entry (RawLogViewer loads and saves through it): a comment it folded
    // into the rawlog's one text, keeping the last only.
    if (format == RawlogWriterOptions::Format::Observations) {
      mrpt::obs::CRawlog log;
      ASSERT_TRUE(log.loadFromRawLogFile(path));
      std::size_t colour_times = 0;
      for (std::size_t i = 0; i < log.size(); ++i)
        if (log.getType(i) == mrpt::obs::CRawlog::etObservation) colour_times += log.getAsObservation(i)->sensorLabel == "COLOUR_TIME";
      EXPECT_EQ(colour_times, 3u);
    }
  }
}

// Against MRPT's own conversion where it is defined (from 0 s on), the same ticks and the same seconds
// (but for a value just under a whole tick, below); before 1970 back to the same seconds; beyond the
// clock, refused.
TEST(RawlogTime, MrptsConversionFromZeroOnAndExactBefore) {
  for (const double t : {0.0, 1e-7, 0.033333, 1305031102.175304, 1305031102.2, 1.7e9, 8.9e11}) {
    EXPECT_EQ(rawlogTime(t), mrpt::Clock::fromDouble(t)) << t;
    EXPECT_EQ(rawlogSeconds(rawlogTime(t)), mrpt::Clock::toDouble(mrpt::Clock::fromDouble(t))) << t;
  }
  for (const double t : {-0.0081, -1.5, -1e9, kEarliestRawlogSeconds + 1}) EXPECT_NEAR(rawlogSeconds(rawlogTime(t)), t, 1e-7) << t;
  EXPECT_EQ(rawlogSeconds(mrpt::Clock::time_point()), 0.0);  // unset, as MRPT's
  // A stamp read from a rawlog is written back as the same tick: truncated, 3 % of 30 Hz stamps from 0
  // (8/30 s read as 0.2666666 s, times 1e7 just under 2666666) lost one, so a replay recorded again was
  // not the recording played (a review's finding).
  for (std::uint64_t k = 0; k < 200000; k += 7) {
    const mrpt::Clock::time_point tick(mrpt::Clock::duration(mrpt::Clock::rep(rawlogTime(0.0).time_since_epoch().count() + k * 333333 / 100)));
    EXPECT_EQ(rawlogTime(rawlogSeconds(tick)), tick) << k;
  }
  for (const double t : {1.7e18, 1.7e15, -2e10, kEarliestRawlogSeconds, std::numeric_limits<double>::quiet_NaN()}) EXPECT_THROW(rawlogTime(t), std::out_of_range) << t;
}

TEST(Rawlog, GroundTruthCompanionFile) {
  const auto frames = simFrames(2);
  const std::string dir = test::tempDir("rawlog_gt");
  writeWithGroundTruthFile(dir + "/g.rawlog", frames);
  ASSERT_TRUE(fs::exists(dir + "/g.groundtruth.txt"));
  RawlogSource src(dir + "/g.rawlog", {});
  ASSERT_EQ(src.groundTruth().size(), 2u);
  Frame f;
  ASSERT_TRUE(src.next(f));
  ASSERT_TRUE(f.groundTruth.has_value());
  EXPECT_LT((f.groundTruth->asVectorVal() - frames[0].groundTruth->asVectorVal()).norm(), 1e-5);
}

// A rawlog written again without ground truth takes the earlier one's companion file away: RawlogSource
// reads that file first, so it would evaluate the new frames against the old path.
TEST(Rawlog, AGroundTruthFileIsTheRawlogsOwnOrNone) {
  const auto frames = simFrames(2);
  const std::string dir = test::tempDir("rawlog_gt_stale");
  writeWithGroundTruthFile(dir + "/g.rawlog", frames);
  ASSERT_TRUE(fs::exists(dir + "/g.groundtruth.txt"));
  RawlogWriterOptions o;
  o.ground_truth_observations = false;
  {
    RawlogWriter w(dir + "/g.rawlog", o);
    w.write(frames[0]);
    // not committed: the earlier rawlog and its ground truth stay as they were
  }
  EXPECT_EQ(RawlogSource(dir + "/g.rawlog", {}).groundTruth().size(), 2u);
  {
    RawlogWriter w(dir + "/g.rawlog", o);
    w.write(frames[0]);
    w.commit();
  }
  EXPECT_FALSE(fs::exists(dir + "/g.groundtruth.txt"));
  EXPECT_TRUE(RawlogSource(dir + "/g.rawlog", {}).groundTruth().empty());
}

// --max-frames N keeps the Nth frame's ground truth: the writer puts each frame's GROUND_TRUTH entry
// after its scan, and the count used to stop right at the scan.
TEST(Rawlog, MaxFramesKeepsTheLastFramesGroundTruth) {
  const auto frames = simFrames(3);
  const std::string dir = test::tempDir("rawlog_gt_max_frames");
  writeRawlog(dir + "/g.rawlog", frames, RawlogWriterOptions{});
  for (const std::size_t n : {1u, 2u}) {
    SourceOptions o;
    o.max_frames = n;
    const RawlogSource src(dir + "/g.rawlog", o);
    EXPECT_EQ(src.size(), n);
    const auto gt = src.groundTruth();
    ASSERT_GE(gt.size(), n) << "max_frames " << n;
    EXPECT_NEAR(gt[n - 1].timestamp, frames[n - 1].timestamp, 1e-6);
    EXPECT_LT((gt[n - 1].pose.asVectorVal() - frames[n - 1].groundTruth->asVectorVal()).norm(), 1e-5);
  }
}

// A GROUND_TRUTH entry that is no pose (NaN or infinite: mocap lost the camera, written so by another
// tool) is an unknown pose, as in a 7-Scenes folder: left out. It made every frame near it NaN and the
// run's ATE null.
TEST(Rawlog, AGroundTruthEntryThatIsNoPoseIsLeftOut) {
  auto frames = simFrames(4);
  frames[1].groundTruth = mrpt::poses::CPose3D(std::numeric_limits<double>::quiet_NaN(), 0, 0, 0, 0, 0);
  frames[2].groundTruth = mrpt::poses::CPose3D(0, std::numeric_limits<double>::infinity(), 0, 0, 0, 0);
  const std::string dir = test::tempDir("rawlog_gt_not_a_pose");
  writeRawlog(dir + "/g.rawlog", frames, RawlogWriterOptions{});
  RawlogSource src(dir + "/g.rawlog", {});
  ASSERT_EQ(src.groundTruth().size(), 2u);
  for (const StampedPose& p : src.groundTruth()) EXPECT_TRUE(p.pose.asVectorVal().asEigen().allFinite()) << p.timestamp;
  Frame f;
  while (src.next(f))
    if (f.groundTruth) {
      EXPECT_TRUE(f.groundTruth->asVectorVal().asEigen().allFinite()) << "frame " << f.index;
    }
}

// A depth file that cannot be written is named where the user will look for it, <out>_Images/..., not
// in the writer's temporary folder (gone by the time the message is read), as the colour file is.
TEST(Rawlog, ADepthFileThatCannotBeWrittenIsNamedWhereItWouldBe) {
  const auto frames = simFrames(1);
  const std::string dir = test::tempDir("rawlog_depth_unwritable");
  RawlogWriter w(dir + "/o.rawlog", {});
  std::string images_tmp;
  for (const auto& e : fs::directory_iterator(dir))
    if (e.path().filename().string().rfind("o_Images.tmp-", 0) == 0) images_tmp = e.path().string();
  ASSERT_FALSE(images_tmp.empty());
  char stem[64];
  std::snprintf(stem, sizeof stem, "KINECT_000000_%.6f_DEPTH.bin", frames[0].timestamp);
  fs::create_directories(images_tmp + "/" + stem + "/in_the_way");  // a folder where the file goes
  try {
    w.write(frames[0]);
    FAIL() << "written";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), dir + "/o_Images/" + stem);
    EXPECT_NE(e.problem().find("cannot write range image"), std::string::npos) << e.problem();
  }
}

// --overwrite whose rawlog cannot be put in place keeps the earlier recording whole: its images folder
// was replaced first and the earlier rawlog then named images that were gone (every frame damaged).
TEST(Rawlog, AnOverwriteThatFailsKeepsTheEarlierRecordingsImages) {
  const auto frames = simFrames(2);
  const std::string dir = test::tempDir("rawlog_overwrite_fails");
  writeRawlog(dir + "/a.rawlog", frames, RawlogWriterOptions{});
  const auto listing = [&] {
    std::vector<std::string> n;
    for (const auto& e : fs::directory_iterator(dir + "/a_Images")) n.push_back(e.path().filename().string());
    std::sort(n.begin(), n.end());
    return n;
  };
  const auto before = listing();
  RawlogWriterOptions o;
  o.replace = true;
  RawlogWriter w(dir + "/a.rawlog", o);
  auto later = frames;
  for (auto& f : later) f.timestamp += 100.0;  // other file names
  for (const auto& f : later) w.write(f);
  fs::remove(dir + "/a.rawlog");
  fs::create_directories(dir + "/a.rawlog/in_the_way");  // the rename cannot replace it
  EXPECT_THROW(w.commit(), InputError);
  EXPECT_EQ(listing(), before);
}

// A companion file beside the rawlog is read before the rawlog's GROUND_TRUTH entries, unless it gives
// no pose (none, or damaged): then the rawlog's own ground truth is used, not dropped.
TEST(Rawlog, ACompanionFileWithNoPoseGivesWayToTheEmbeddedGroundTruth) {
  const auto frames = simFrames(2);
  const std::string dir = test::tempDir("rawlog_gt_embedded");
  writeRawlog(dir + "/g.rawlog", frames, RawlogWriterOptions{});
  std::ofstream(dir + "/g.groundtruth.txt") << "# timestamp tx ty tz qx qy qz qw\n";
  const auto gt = RawlogSource(dir + "/g.rawlog", {}).groundTruth();
  ASSERT_EQ(gt.size(), 2u);
  EXPECT_LT((gt[1].pose.asVectorVal() - frames[1].groundTruth->asVectorVal()).norm(), 1e-5);
  // One that holds a pose wins.
  std::ofstream(dir + "/g.groundtruth.txt") << "# timestamp tx ty tz qx qy qz qw\n5 1 2 3 0 0 0 1\n";
  const auto own = RawlogSource(dir + "/g.rawlog", {}).groundTruth();
  ASSERT_EQ(own.size(), 1u);
  EXPECT_DOUBLE_EQ(own[0].timestamp, 5.0);
  // A damaged one is said and gives way too; with --strict it stops the run.
  std::ofstream(dir + "/g.groundtruth.txt") << "5 1 2 3 0 0 0\n";
  EXPECT_EQ(RawlogSource(dir + "/g.rawlog", {}).groundTruth().size(), 2u);
  SourceOptions strict;
  strict.strict = true;
  EXPECT_THROW(RawlogSource(dir + "/g.rawlog", strict), InputError);
}

// The disk fills while the rawlog's last buffered bytes are flushed (MRPT's close() drops gzclose's
// result): commit() says so naming the rawlog, and the earlier rawlog, its ground truth and the folder
// stay as they were.
TEST(Rawlog, AFlushThatFailsAtTheEndFailsTheCommitAndKeepsTheEarlierRawlog) {
  const auto frames = simFrames(3);
  const std::string dir = test::tempDir("rawlog_close_fails");
  RawlogWriterOptions o;
  o.external_images = false;
  o.ground_truth_observations = false;
  Trajectory gt;
  for (const auto& f : frames) gt.push_back({f.timestamp, *f.groundTruth});
  {
    RawlogWriter w(dir + "/g.rawlog", o);
    w.write(frames[0]);
    w.writeGroundTruth({gt[0]});
    w.commit();
  }
  const auto size_before = fs::file_size(dir + "/g.rawlog");
  const auto entries = [&dir] {
    std::vector<std::string> names;
    for (const auto& e : fs::directory_iterator(dir)) names.push_back(e.path().filename().string());
    std::sort(names.begin(), names.end());
    return names;
  };
  const std::vector<std::string> before = entries();
  {
    RawlogWriter w(dir + "/g.rawlog", o);
    for (const auto& f : frames) w.write(f);
    w.writeGroundTruth(gt);
    // Whatever zlib still buffers cannot reach the disk: the file may not grow past what it has now.
    std::uintmax_t on_disk = 0;
    for (const auto& e : fs::directory_iterator(dir))
      if (e.path().filename().string().rfind("g.rawlog.tmp-", 0) == 0) on_disk = e.file_size();
    struct rlimit old_limit {};
    ASSERT_EQ(getrlimit(RLIMIT_FSIZE, &old_limit), 0);
    const auto old_handler = std::signal(SIGXFSZ, SIG_IGN);  // the write fails with EFBIG instead
    struct rlimit limit = old_limit;
    limit.rlim_cur = rlim_t(on_disk);
    ASSERT_EQ(setrlimit(RLIMIT_FSIZE, &limit), 0);
    std::string error;
    try {
      w.commit();
    } catch (const InputError& e) {
      error = e.what();
    }
    setrlimit(RLIMIT_FSIZE, &old_limit);
    std::signal(SIGXFSZ, old_handler);
    EXPECT_EQ(error, dir + "/g.rawlog: write failed while closing the rawlog (disk full?)");
  }
  EXPECT_EQ(entries(), before);
  EXPECT_EQ(fs::file_size(dir + "/g.rawlog"), size_before);
  RawlogSource back(dir + "/g.rawlog", {});
  EXPECT_EQ(back.size(), 1u);
  EXPECT_EQ(back.groundTruth().size(), 1u);
}

// A damaged companion ground truth costs the evaluation, not the rawlog's frames; --strict stops at it.
TEST(Rawlog, ADamagedGroundTruthFileCostsTheGroundTruthUnlessStrict) {
  const auto frames = simFrames(2);
  const std::string dir = test::tempDir("rawlog_gt_damaged");
  RawlogWriterOptions o;
  o.ground_truth_observations = false;
  const std::string path = writeRawlog(dir + "/g.rawlog", frames, o);
  std::ofstream(dir + "/g.groundtruth.txt") << "2.0 0 0 0 0 0 0 1\n1.0 0 0 0 0 0 0 1\n";  // out of order
  RawlogSource src(path, {});
  EXPECT_EQ(src.size(), 2u);
  EXPECT_TRUE(src.groundTruth().empty());
  SourceOptions strict;
  strict.strict = true;
  try {
    RawlogSource stops(path, strict);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()).rfind(dir + "/g.groundtruth.txt: ", 0), 0u) << e.what();
  }
}

TEST(Rawlog, IntrinsicsOverrideAndMaxFrames) {
  const auto frames = simFrames(3);
  const std::string dir = test::tempDir("rawlog_intr");
  const std::string path = writeRawlog(dir + "/i.rawlog", frames, {});
  SourceOptions so;
  so.intrinsics = "300,301,160,120";
  so.max_frames = 2;
  auto src = openFrameSource(path, so);
  EXPECT_EQ(src->size(), 2u);
  Frame f;
  ASSERT_TRUE(src->next(f));
  EXPECT_DOUBLE_EQ(f.camera.fy, 301.0);
  so.intrinsics = "fr9";
  try {
    openFrameSource(path, so);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("fr9"), std::string::npos) << e.what();
  }
}

TEST(Rawlog, UncommittedWriterLeavesNothingAndKeepsOldOutput) {
  const auto frames = simFrames(2);
  const std::string dir = test::tempDir("rawlog_atomic");
  {
    RawlogWriter w(dir + "/a.rawlog");
    w.write(frames[0]);
  }
  EXPECT_TRUE(fs::is_empty(dir));
  writeRawlog(dir + "/a.rawlog", {frames[0]}, {});
  const auto size_before = fs::file_size(dir + "/a.rawlog");
  {
    RawlogWriter w(dir + "/a.rawlog");
    w.write(frames[0]);
    w.write(frames[1]);
  }
  EXPECT_EQ(fs::file_size(dir + "/a.rawlog"), size_before);
  EXPECT_EQ(RawlogSource(dir + "/a.rawlog", {}).size(), 1u);
  EXPECT_EQ(std::distance(fs::directory_iterator(dir), fs::directory_iterator{}), 2);  // .rawlog + _Images
}

// A recorder killed while it appends a record can leave the file ending inside that record: Linux cuts
// a write(2) short between two pages when a fatal signal arrives. Wherever in its last record an
// in-place recording ends, the frames before that record are read, then RecordingCutShort says where
// the file ends (a crash's end, not damage).
// A recording made in place ends with its images on the disk as well as its records (syncfs), and a
// converted one with both put in place durably: a power cut after "recorded" must not leave records
// naming empty image files (each a lost frame). Only the records were synced (fdatasync).
TEST(Rawlog, ARecordingEndsWithItsImagesOnTheDisk) {
  const auto frames = simFrames(2);
  const std::string dir = test::tempDir("rawlog_synced");
  RawlogWriterOptions o;
  o.in_place = true;
  {
    RawlogWriter w(dir + "/rec.rawlog", o);
    for (const Frame& f : frames) w.write(f);
    test::SyncWatch watch;
    w.commit();
    const auto synced = watch.synced();
    EXPECT_NE(std::find(synced.begin(), synced.end(), "syncfs " + dir + "/rec.rawlog"), synced.end())
        << ::testing::PrintToString(synced);
  }
  {
    RawlogWriter w(dir + "/conv.rawlog", RawlogWriterOptions{});
    for (const Frame& f : frames) w.write(f);
    test::SyncWatch watch;
    w.commit();
    const auto synced = watch.synced();
    const std::string pid = std::to_string(::getpid());
    for (const std::string& want : {"syncfs " + dir + "/conv_Images.tmp-" + pid, "fsync " + dir + "/conv.rawlog.tmp-" + pid})
      EXPECT_NE(std::find(synced.begin(), synced.end(), want), synced.end()) << want << ::testing::PrintToString(synced);
  }
}

// A frame whose record is in the file is recorded, even when the sync due after it fails (an I/O error):
// the writer counted one frame fewer than the file held, and with none counted the recording was removed.
TEST(Rawlog, AFrameWhoseSyncFailsIsStillCountedAndKept) {
  const auto frames = simFrames(1);
  const std::string dir = test::tempDir("rawlog_sync_fails");
  const std::string path = std::filesystem::absolute(dir + "/rec.rawlog").string();
  RawlogWriterOptions o;
  o.in_place = true;
  {
    RawlogWriter w(path, o);
    std::this_thread::sleep_for(std::chrono::milliseconds(1100));  // the first sync is due at the first frame
    test::SyncWatch watch;
    watch.fail("fdatasync", path, EIO);
    EXPECT_THROW(w.write(frames[0]), InputError);
    EXPECT_EQ(w.framesWritten(), 1u);
    EXPECT_EQ(RawlogSource(path, {}).size(), w.framesWritten());
  }
  EXPECT_TRUE(std::filesystem::exists(path)) << "a recording holding a whole frame was removed";
}

// A recording in place never takes a ground truth it did not write: one left beside no recording (an
// earlier replay's, its recording deleted) is refused, naming it; one left by a recording killed before
// its first record goes with that empty recording.
TEST(Rawlog, InPlaceRecordingTakesNoGroundTruthLeftBesideNoRecording) {
  const auto frames = simFrames(2);
  const std::string dir = test::tempDir("rawlog_stale_gt");
  RawlogWriterOptions o;
  o.in_place = true;
  const std::string gt = RawlogWriter::groundTruthPathFor(dir + "/grab.rawlog");
  writeTumTrajectory(gt, {{0.0, mrpt::poses::CPose3D()}, {1.0, mrpt::poses::CPose3D(1, 0, 0, 0, 0, 0)}});
  try {
    RawlogWriter w(dir + "/grab.rawlog", o);
    ADD_FAILURE() << "recorded beside another recording's ground truth";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), gt);
  }
  EXPECT_TRUE(fs::exists(gt)) << "nothing written is removed";
  // A killed recording's leftovers: its empty rawlog and folder, and the ground truth its first frame wrote.
  std::ofstream(dir + "/grab.rawlog").close();
  fs::create_directory(dir + "/grab_Images");
  {
    RawlogWriter w(dir + "/grab.rawlog", o);
    w.write(frames[0]);
    w.write(frames[1]);
    w.commit();
  }
  EXPECT_FALSE(fs::exists(gt)) << "the killed recording's ground truth went with it";
  const RawlogSource back(dir + "/grab.rawlog", {});
  ASSERT_NE(back.recordedGroundTruth(), nullptr);  // the frames' own, in the rawlog's entries
  const Trajectory& truth = *back.recordedGroundTruth();
  ASSERT_EQ(truth.size(), 2u);
  for (std::size_t i = 0; i < 2; ++i) EXPECT_LT(truth[i].pose.distanceTo(*frames[i].groundTruth), 1e-4) << i;
}

// An empty recording no recorder holds is a killed one's, with its images folder or without it (a kill
// before the folder was made): the next recording replaces it. One a recorder is still making is never
// taken for it, even before its folder is made: the file is locked before it appears (made under a name of
// its own, then linked into place), where once a second recorder could find it empty and unlocked and
// remove it under the first.
TEST(Rawlog, InPlaceRecordingReplacesOnlyAnAbandonedEmptyOne) {
  const auto frames = simFrames(1);
  const std::string dir = test::tempDir("rawlog_abandoned");
  const std::string path = dir + "/grab.rawlog", images = dir + "/grab_Images";
  RawlogWriterOptions o;
  o.in_place = true;
  std::ofstream(path).close();  // killed before its folder was made
  {
    RawlogWriter w(path, o);
    w.write(frames[0]);
    w.commit();
  }
  EXPECT_EQ(RawlogSource(path, {}).size(), 1u);
  fs::remove(path);
  fs::remove_all(images);
  {
    RawlogWriter first(path, o);
    EXPECT_EQ(std::distance(fs::directory_iterator(dir), fs::directory_iterator{}), 2) << "a staged name was left";
    fs::remove(images);  // as the first recorder is between making its file and its folder
    try {
      RawlogWriter second(path, o);
      ADD_FAILURE() << "a recording being made was replaced";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("a recording is already there"), std::string::npos) << e.what();
    }
    EXPECT_TRUE(fs::exists(path)) << "the first recorder's file was removed";
  }
  // One with something in it is never replaced.
  std::ofstream(path) << "x";
  EXPECT_THROW(RawlogWriter(path, o), InputError);
  EXPECT_EQ(fs::file_size(path), 1u);
  // A name too long for a staged name beside it (the staged one past 255 characters) records as before.
  const std::string longest = dir + "/" + std::string(239, 'r') + ".rawlog";
  {
    RawlogWriter w(longest, o);
    w.write(frames[0]);
    w.commit();
  }
  EXPECT_EQ(RawlogSource(longest, {}).size(), 1u);
}

// An in-place recording is locked before it has its name: made under a name of its own, locked, then
// linked into place. Made in place and locked after, a second recorder could find it empty and unlocked
// between the two and remove it as a killed recorder's.
TEST(Rawlog, AnInPlaceRecordingIsLockedBeforeItHasItsName) {
  const std::string dir = test::tempDir("rawlog_locked_first");
  const std::string path = dir + "/grab.rawlog";
  RawlogWriterOptions o;
  o.in_place = true;
  test::LinkWatch watch;
  RawlogWriter w(path, o);
  const auto linked = watch.linked();
  ASSERT_EQ(linked.size(), 1u) << "the recording got its name by no link";
  EXPECT_EQ(linked[0].to, path);
  EXPECT_TRUE(linked[0].locked) << "named before it was locked";
  EXPECT_FALSE(fs::exists(linked[0].from)) << "its staged name was left";
}

// A staged name a killed recorder left (this process's pid again: pids are reused) is passed over, not
// reported as "cannot create: File exists" for a recording that is not there. Run in a process of its
// own (ctest), so the first names tried are the ones left.
TEST(Rawlog, InPlaceRecordingPassesOverAStagedNameLeftBehind) {
  const auto frames = simFrames(1);
  const std::string dir = test::tempDir("rawlog_staged_left");
  const std::string path = dir + "/grab.rawlog";
  for (int n = 0; n < 10; ++n) std::ofstream(path + "." + std::to_string(::getpid()) + "." + std::to_string(n) + ".new").close();
  RawlogWriterOptions o;
  o.in_place = true;
  {
    RawlogWriter w(path, o);
    w.write(frames[0]);
    w.commit();
  }
  EXPECT_EQ(RawlogSource(path, {}).size(), 1u);
  EXPECT_TRUE(fs::exists(path + "." + std::to_string(::getpid()) + ".0.new")) << "another's file was removed";
}

TEST(Rawlog, InPlaceRecordingEndingInsideItsLastRecordReadsToTheFrameBefore) {
  const auto frames = simFrames(3);
  const std::string dir = test::tempDir("rawlog_torn");
  RawlogWriterOptions o;
  o.in_place = true;
  std::uintmax_t two_frames = 0;
  {
    RawlogWriter w(dir + "/rec.rawlog", o);
    w.write(frames[0]);
    w.write(frames[1]);
    two_frames = fs::file_size(dir + "/rec.rawlog");
    w.write(frames[2]);
    w.commit();
  }
  const std::string bytes = fileBytes(dir + "/rec.rawlog");
  ASSERT_GT(bytes.size(), two_frames + 100);
  fs::create_directory_symlink(dir + "/rec_Images", dir + "/cut_Images");
  const std::string cut = dir + "/cut.rawlog";
  for (std::size_t at = two_frames + 1; at < bytes.size(); ++at) {
    SCOPED_TRACE("ends at byte " + std::to_string(at) + " of " + std::to_string(bytes.size()));
    std::ofstream(cut, std::ios::binary | std::ios::trunc) << bytes.substr(0, at);
    RawlogSource src(cut, {});
    Frame f;
    std::size_t n = 0;
    bool cut_short = false;
    try {
      while (src.next(f)) ++n;
    } catch (const RecordingCutShort& e) {
      cut_short = true;
      EXPECT_EQ(e.problem().rfind("truncated rawlog (ends inside entry ", 0), 0u) << e.what();
    }
    // The last record is the third frame's entry and its ground truth's: ending between the two reads
    // three frames to a clean end, anywhere else two or three frames and where the file ends.
    EXPECT_GE(n, 2u);
    EXPECT_TRUE(cut_short || n == 3u) << n << " frames read to a clean end";
  }
}

// Damage is not a cut: a bad end flag on the last entry, or a length field that reads on past the end
// of the file from an entry in the middle, is "corrupt", with the frames before it read.
TEST(Rawlog, InPlaceRecordingDamagedInsideIsCorruptNotTruncated) {
  const auto frames = simFrames(5);
  const std::string dir = test::tempDir("rawlog_damaged");
  RawlogWriterOptions o;
  o.in_place = true;
  writeRawlog(dir + "/rec.rawlog", frames, o);
  const std::string bytes = fileBytes(dir + "/rec.rawlog");
  fs::create_directory_symlink(dir + "/rec_Images", dir + "/bad_Images");
  // The third frame's colour image name, stored as a 32-bit length and its characters.
  const std::size_t name = bytes.find("KINECT_000002_");
  ASSERT_NE(name, std::string::npos);
  std::uint32_t length = 0;
  std::memcpy(&length, bytes.data() + name - 4, 4);
  ASSERT_GT(length, 14u);
  ASSERT_LT(length, 200u);
  std::string long_name = bytes;
  const std::uint32_t past_the_end = std::uint32_t(bytes.size());
  std::memcpy(long_name.data() + name - 4, &past_the_end, 4);
  std::string bad_flag = bytes;
  bad_flag.back() = char(bad_flag.back() ^ 0x5a);
  for (const auto& [what, damaged, frames_before] :
       {std::tuple{"a length past the end", long_name, 2u}, std::tuple{"the last end flag", bad_flag, 5u}}) {
    SCOPED_TRACE(what);
    const std::string bad = dir + "/bad.rawlog";
    std::ofstream(bad, std::ios::binary | std::ios::trunc) << damaged;
    RawlogSource src(bad, {});
    Frame f;
    std::size_t n = 0;
    try {
      while (src.next(f)) ++n;
      FAIL() << "read to a clean end";
    } catch (const RecordingCutShort& e) {
      EXPECT_EQ(e.problem().rfind("corrupt or truncated rawlog at entry ", 0), 0u) << e.what();
    }
    EXPECT_EQ(n, frames_before);
  }
}

// A frame already recorded (vofusion-grab's recording, then poses.rawlog) gets hard links to the
// recording's images rather than the same images written again; a range image at other units is
// written anew. Either rawlog reads back the frames.
TEST(Rawlog, RecordedFramesLinkTheRecordingsImages) {
  auto frames = simFrames(2);
  const std::string dir = test::tempDir("rawlog_linked");
  RawlogWriterOptions in_place;
  in_place.in_place = true;
  RawlogWriter recording(dir + "/grab.rawlog", in_place);
  for (Frame& f : frames) {
    const std::optional<RecordedFiles> files = recording.write(f);
    ASSERT_TRUE(files);
    EXPECT_TRUE(files->colour.recorded && files->depth.recorded);
    EXPECT_EQ(files->depth.size, fs::file_size(files->depth.path));
    f.colour_file = files->colour, f.depth_file = files->depth;
  }
  recording.commit();
  for (const double units : {2e-4, 1e-3}) {
    SCOPED_TRACE(units);
    RawlogWriterOptions o;
    o.range_units = units;
    const std::string path = dir + "/poses" + std::to_string(int(units * 1e4)) + ".rawlog";
    writeRawlog(path, frames, o);
    const std::string images = RawlogWriter::imagesDirFor(path);
    std::size_t linked_colour = 0, linked_depth = 0;
    for (const Frame& f : frames) {
      for (const auto& e : fs::directory_iterator(images)) {
        const bool colour = e.path().string().find("_INTENSITY.png") != std::string::npos;
        if (fs::equivalent(e.path(), colour ? f.colour_file->path : f.depth_file->path)) ++(colour ? linked_colour : linked_depth);
      }
    }
    EXPECT_EQ(linked_colour, 2u);
    EXPECT_EQ(linked_depth, units == 2e-4 ? 2u : 0u);
    RawlogSource src(path, {});
    expectSameFrames(frames, src, units / 2 + 1e-6);
  }
  // The links hold the bytes the writer writes for the frames it does not know recorded.
  auto unrecorded = frames;
  for (Frame& f : unrecorded) f.colour_file.reset(), f.depth_file.reset();
  const std::string plain = RawlogWriter::imagesDirFor(writeRawlog(dir + "/plain.rawlog", unrecorded, {}));
  std::size_t compared = 0;
  for (const auto& e : fs::directory_iterator(plain)) {
    EXPECT_EQ(fileBytes(e.path()), fileBytes(dir + "/poses2_Images/" + e.path().filename().string())) << e.path();
    ++compared;
  }
  EXPECT_EQ(compared, 4u);
  // Frame 0's colour file gone, frame 1's range image no longer the one recorded (its CRC-32; a file
  // of the same size): those two are written instead.
  fs::remove(frames[0].colour_file->path);
  {
    std::string b = fileBytes(frames[1].depth_file->path);
    b[b.size() - 8] ^= 1;
    std::ofstream(frames[1].depth_file->path, std::ios::binary) << b;
  }
  const std::string after = writeRawlog(dir + "/after.rawlog", frames, {});
  for (const auto& e : fs::directory_iterator(RawlogWriter::imagesDirFor(after))) {
    const std::string name = e.path().filename().string();
    const bool written = (name.find("000000_") != std::string::npos && e.path().extension() == ".png") ||
                         (name.find("000001_") != std::string::npos && e.path().extension() == ".bin");
    EXPECT_EQ(fs::hard_link_count(e.path()) == 1, written) << e.path();
  }
  RawlogSource src(after, {});
  expectSameFrames(frames, src, 1e-4 + 1e-6);
}

TEST(Rawlog, ObservationsFormatRejectsActions) {
  const std::string dir = test::tempDir("rawlog_noact");
  RawlogWriter w(dir + "/x.rawlog");
  EXPECT_THROW(w.writeAction(makeOdometryAction({}, 0.0)), std::logic_error);
}

namespace {
// The external file (".png" colour, ".bin" range) of frame 1 in a rawlog dir/e.rawlog; empty if none.
std::string secondFramesFile(const std::string& dir, const std::string& extension) {
  for (const auto& e : fs::directory_iterator(dir + "/e_Images"))
    if (e.path().string().find("000001") != std::string::npos && e.path().extension() == extension) return e.path();
  return {};
}

void expectInputError(const std::string& path, const std::string& needle, const SourceOptions& so = {}) {
  try {
    RawlogSource src(path, so);
    Frame f;
    while (src.next(f)) {
    }
    FAIL() << "no error for " << path;
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find(needle), std::string::npos) << msg;
    EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
  }
}
}  // namespace

TEST(RawlogBadInput, NoThreeDObservations) {
  const std::string dir = test::tempDir("rawlog_bad_empty");
  const std::string path = dir + "/odo.rawlog";
  {
    mrpt::io::CFileGZOutputStream out(path);
    auto arch = mrpt::serialization::archiveFrom(out);
    mrpt::obs::CObservationOdometry odo;
    odo.timestamp = mrpt::Clock::fromDouble(1.0);
    arch << odo << odo;
  }
  expectInputError(path, path + ": contains no CObservation3DRangeScan");
}

TEST(RawlogBadInput, TruncatedAndGarbage) {
  const auto frames = simFrames(3);
  const std::string dir = test::tempDir("rawlog_bad_trunc");
  RawlogWriterOptions o;
  o.external_images = false;
  const std::string full = writeRawlog(dir + "/full.rawlog", frames, o);
  std::ifstream in(full, std::ios::binary);
  std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string cut = dir + "/cut.rawlog";
  std::ofstream(cut, std::ios::binary) << bytes.substr(0, bytes.size() * 2 / 3);
  expectInputError(cut, cut + ": ");
  const std::string junk = dir + "/junk.rawlog";
  std::ofstream(junk) << "this is not a rawlog\n";
  expectInputError(junk, junk + ": ");
  const std::string empty = dir + "/empty.rawlog";
  std::ofstream(empty).flush();
  expectInputError(empty, empty + ": contains no");
  expectInputError(dir + "/missing.rawlog", "missing.rawlog: no such file");
}

// An external image or range file that exists but cannot be opened (its permissions) names the
// system's reason: it was "missing or corrupt".
TEST(RawlogBadInput, AnUnreadableExternalFileSaysWhyNotCorrupt) {
  const auto frames = simFrames(2);
  for (const std::string kind : {".png", ".bin"}) {
    const std::string dir = test::tempDir("rawlog_unreadable_ext" + kind);
    const std::string path = writeRawlog(dir + "/e.rawlog", frames, {});
    const std::string victim = secondFramesFile(dir, kind);
    ASSERT_FALSE(victim.empty()) << kind;
    fs::permissions(victim, fs::perms::none);
    const std::string said = test::errorWithoutPrivileges([&] {
      RawlogSource src(path, {});
      Frame f;
      while (src.next(f)) {
      }
    });
    EXPECT_NE(said.find(victim + ": cannot load "), std::string::npos) << said;
    EXPECT_NE(said.find("(Permission denied)"), std::string::npos) << said;
  }
}

// An external colour image that is a JPEG with a marker inside its image data (a byte turned into
// 0xFF): libjpeg decodes it to smeared blocks and MRPT's CImage handed them on as the frame's colour.
TEST(RawlogBadInput, ACorruptButCompleteExternalJpegNamesItsDamage) {
  const auto frames = simFrames(2);
  const std::string dir = test::tempDir("rawlog_corrupt_jpeg");
  const std::string path = writeRawlog(dir + "/e.rawlog", frames, {});
  const std::string victim = secondFramesFile(dir, ".png");
  ASSERT_FALSE(victim.empty());
  std::vector<std::uint8_t> jpeg;
  ASSERT_TRUE(cv::imencode(".jpg", cv::imread(victim), jpeg));
  jpeg = test::jpegWithMarkerInside(jpeg);
  ASSERT_FALSE(cv::imdecode(jpeg, cv::IMREAD_COLOR).empty());  // what CImage passed on
  std::ofstream(victim, std::ios::binary | std::ios::trunc).write(reinterpret_cast<const char*>(jpeg.data()), std::streamsize(jpeg.size()));
  expectInputError(path, victim + ": cannot load intensity image (Corrupt JPEG data: ");
}

TEST(RawlogBadInput, MissingExternalImageNamesTheImage) {
  const auto frames = simFrames(2);
  const std::string dir = test::tempDir("rawlog_bad_ext");
  const std::string path = writeRawlog(dir + "/e.rawlog", frames, {});
  const std::string victim = secondFramesFile(dir, ".png");
  ASSERT_FALSE(victim.empty());
  fs::remove(victim);
  expectInputError(path, fs::path(victim).filename().string());
}
