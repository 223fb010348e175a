#include <Eigen/Dense>
// The 7-Scenes folder source: hand-made frames with known depth and poses, detection by
// openFrameSource, bad pose files, and a real TUM excerpt converted to the 7-Scenes layout.
#include <cmath>
#include <filesystem>
#include <fstream>

#include <mrpt/math/CMatrixFixed.h>
#include <opencv2/imgcodecs.hpp>

#include "support.h"
#include "vofusion/core/errors.h"
#include "vofusion/io/seven_scenes_source.h"
#include "vofusion/io/tum_source.h"
#include "vofusion/sim/any_source.h"

using namespace vofusion;
namespace fs = std::filesystem;

namespace {

std::string stem(const std::string& dir, int n) {
  char b[32];
  std::snprintf(b, sizeof b, "frame-%06d", n);
  return (fs::path(dir) / b).string();
}

void writePose(const std::string& path, const mrpt::poses::CPose3D& p) {
  const auto m = p.getHomogeneousMatrixVal<mrpt::math::CMatrixDouble44>();
  std::ofstream f(path);
  f.precision(9);
  for (int r = 0; r < 4; ++r) {
    for (int c = 0; c < 4; ++c) f << m(r, c) << (c < 3 ? "\t" : "\n");
  }
}

// Frame n: colour (n*10, 0, 0), depth (1000 + n) mm except pixel (0,0) = 65535 (no reading).
void writeFrame(const std::string& dir, int n, const mrpt::poses::CPose3D& pose, bool jpg = false) {
  cv::Mat rgb(48, 64, CV_8UC3, cv::Scalar(n * 10, 0, 0));
  cv::Mat depth(48, 64, CV_16UC1, cv::Scalar(1000 + n));
  depth.at<uint16_t>(0, 0) = 65535;
  ASSERT_TRUE(cv::imwrite(stem(dir, n) + (jpg ? ".color.jpg" : ".color.png"), rgb));
  ASSERT_TRUE(cv::imwrite(stem(dir, n) + ".depth.png", depth));
  writePose(stem(dir, n) + ".pose.txt", pose);
}

mrpt::poses::CPose3D poseOf(int n) { return mrpt::poses::CPose3D(0.1 * n, -0.05 * n, 0.02, 0.1 * n, -0.2, 0.05 * n); }

}  // namespace

TEST(SevenScenes, ReadsFramesDepthPosesAndStamps) {
  const std::string dir = test::tempDir("sevenscenes_basic");
  // Written out of order and with a gap: the source sorts by frame number.
  for (int n : {2, 0, 1, 5}) writeFrame(dir, n, poseOf(n), n == 5);
  auto src = openFrameSource(dir);
  ASSERT_NE(dynamic_cast<SevenScenesSource*>(src.get()), nullptr);
  ASSERT_EQ(src->size(), 4u);
  Frame f;
  const int expect[] = {0, 1, 2, 5};
  for (int n : expect) {
    ASSERT_TRUE(src->next(f));
    EXPECT_DOUBLE_EQ(f.timestamp, n / 30.0);
    EXPECT_EQ(f.rgb.type(), CV_8UC3);
    EXPECT_EQ(f.depth.type(), CV_32FC1);
    EXPECT_FLOAT_EQ(f.depth.at<float>(10, 10), (1000 + n) * 1e-3f);
    EXPECT_EQ(f.depth.at<float>(0, 0), 0.0f);
    if (n != 5) {
      EXPECT_EQ(f.rgb.at<cv::Vec3b>(5, 5)[0], n * 10);  // JPEG is lossy: frame 5 not exact
    }
    EXPECT_EQ(f.camera.width, 64);
    EXPECT_EQ(f.camera.height, 48);
    // The 640x480 defaults (fx 585, cx 320) scaled to the 64x48 images.
    EXPECT_NEAR(f.camera.fx, 58.5, 1e-9);
    EXPECT_NEAR(f.camera.cx, 320.5 * 0.1 - 0.5, 1e-9);
    ASSERT_TRUE(f.groundTruth.has_value());
    EXPECT_LT((f.groundTruth->asVectorVal() - poseOf(n).asVectorVal()).norm(), 1e-6);
  }
  EXPECT_FALSE(src->next(f));
  src->rewind();
  ASSERT_TRUE(src->next(f));
  EXPECT_DOUBLE_EQ(f.timestamp, 0.0);
}

TEST(SevenScenes, IntrinsicsOverrideMaxFramesAndUnknownPose) {
  const std::string dir = test::tempDir("sevenscenes_opts");
  for (int n = 0; n < 3; ++n) writeFrame(dir, n, poseOf(n));
  { std::ofstream(stem(dir, 1) + ".pose.txt") << "-inf -inf -inf -inf\n-inf -inf -inf -inf\n-inf -inf -inf -inf\n-inf -inf -inf -inf\n"; }
  SourceOptions o;
  o.intrinsics = "30,31,32,23";
  o.max_frames = 2;
  SevenScenesSource src(dir, o);
  EXPECT_EQ(src.size(), 2u);
  EXPECT_EQ(src.groundTruth().size(), 1u);  // frame 1's pose is the "unknown" marker
  Frame f;
  ASSERT_TRUE(src.next(f));
  EXPECT_DOUBLE_EQ(f.camera.fy, 31.0);
  EXPECT_TRUE(f.groundTruth.has_value());
  ASSERT_TRUE(src.next(f));
  EXPECT_FALSE(f.groundTruth.has_value());
}

// A damaged pose file costs that frame's evaluation, in one line naming the file, not the run.
TEST(SevenScenes, BadPoseFileNamesTheFileAndCostsItsFrame) {
  const std::string dir = test::tempDir("sevenscenes_badpose");
  for (int n = 0; n < 3; ++n) writeFrame(dir, n, poseOf(n));
  { std::ofstream(stem(dir, 0) + ".pose.txt") << "1 0 0 0\n0 1 0 0\n0 0 1 0\n"; }
  { std::ofstream(stem(dir, 2) + ".pose.txt") << "2 0 0 0\n0 1 0 0\n0 0 1 0\n0 0 0 1\n"; }  // not a rotation
  // A pose file that never ends (it grew without bound) is a damaged one.
  for (int n = 3; n < 5; ++n) writeFrame(dir, n, poseOf(n));
  std::filesystem::remove(stem(dir, 3) + ".pose.txt");
  std::filesystem::create_symlink("/dev/zero", stem(dir, 3) + ".pose.txt");
  testing::internal::CaptureStderr();
  SevenScenesSource src(dir, {});
  const std::string log = testing::internal::GetCapturedStderr();
  EXPECT_EQ(src.groundTruth().size(), 2u);
  EXPECT_NE(log.find(stem(dir, 3) + ".pose.txt: goes on past 64 KiB"), std::string::npos) << log;
  EXPECT_NE(log.find(stem(dir, 0) + ".pose.txt: holds 12 numbers, expected 16 (4x4 matrix) (frame not evaluated)"),
            std::string::npos) << log;
  EXPECT_NE(log.find(stem(dir, 2) + ".pose.txt: not a rigid camera-to-world transform"), std::string::npos) << log;
  EXPECT_FALSE(src.read(0).groundTruth.has_value());
  EXPECT_TRUE(src.read(1).groundTruth.has_value());
  mrpt::poses::CPose3D p;
  EXPECT_THROW(parseSevenScenesPose("1 0 0 x 0 1 0 0 0 0 1 0 0 0 0 1", "p.txt", p), InputError);
}

// A missing colour image costs its frame (the source used to refuse the whole folder), and so does a
// damaged first one, whose size the next readable image gives instead.
TEST(SevenScenes, AMissingOrDamagedColourImageCostsItsFrame) {
  const std::string dir = test::tempDir("sevenscenes_colour");
  for (int n = 0; n < 4; ++n) writeFrame(dir, n, poseOf(n));
  std::filesystem::remove(stem(dir, 2) + ".color.png");
  { std::ofstream(stem(dir, 0) + ".color.png", std::ios::trunc) << "\x89PNG\r\n\x1a\n"; }  // cut short
  SevenScenesSource src(dir, {});
  EXPECT_EQ(src.size(), 4u);
  EXPECT_EQ(src.read(1).camera.width, src.read(1).rgb.cols);
  EXPECT_THROW(src.read(0), InputError);
  EXPECT_THROW(src.read(2), InputError);
  EXPECT_NO_THROW(src.read(3));
  // A JPEG cut short: libjpeg would fill its missing rows with grey.
  writeFrame(dir, 3, poseOf(3), true);
  std::filesystem::remove(stem(dir, 3) + ".color.png");
  const std::string jpg = stem(dir, 3) + ".color.jpg";
  std::string bytes;
  {
    std::ifstream in(jpg, std::ios::binary);
    bytes.assign(std::istreambuf_iterator<char>(in), {});
  }
  ASSERT_GT(bytes.size(), 200u);
  EXPECT_NO_THROW(SevenScenesSource(dir, {}).read(3));
  { std::ofstream(jpg, std::ios::binary | std::ios::trunc) << bytes.substr(0, bytes.size() - 100); }
  try {
    SevenScenesSource(dir, {}).read(3);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), jpg + ": cannot decode colour image (truncated JPEG)");
  }
  std::filesystem::remove(jpg);
  // More digits than a frame number has is no frame (std::stoi threw out_of_range, unnamed).
  writeFrame(dir, 4, poseOf(4));
  std::filesystem::rename(stem(dir, 4) + ".depth.png", dir + "/frame-99999999999.depth.png");
  // Frame 4 is still listed by its colour image and pose: its missing depth image costs it, named (listed
  // by depth images alone, it vanished unsaid).
  const SevenScenesSource listed(dir, {});
  ASSERT_EQ(listed.size(), 5u);
  try {
    listed.read(4);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), stem(dir, 4) + ".depth.png: depth image is missing");
  }
  // A pose alone is no frame.
  std::filesystem::remove(stem(dir, 4) + ".color.png");
  EXPECT_EQ(SevenScenesSource(dir, {}).size(), 4u);
  std::filesystem::remove(stem(dir, 4) + ".pose.txt");
  // No colour image to take the size from: one line naming the first.
  for (int n : {1, 3}) std::filesystem::remove(stem(dir, n) + ".color.png");
  try {
    SevenScenesSource none(dir, {});
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), stem(dir, 0) + ".color.png: colour image cannot be read, nor can any of the first 4 frames'");
  }
}

TEST(SevenScenes, NotASequenceFolder) {
  const std::string dir = test::tempDir("sevenscenes_empty");
  EXPECT_FALSE(SevenScenesSource::looksLike(dir));
  EXPECT_THROW(SevenScenesSource(dir, {}), InputError);
  { std::ofstream(dir + "/frame-000000.depth.png") << "x"; }  // depth without colour
  EXPECT_FALSE(SevenScenesSource::looksLike(dir));
  EXPECT_THROW(openFrameSource(dir), InputError);
}

// frame-3 beside frame-000003 is one frame number twice: refused, naming both (the frame was read twice,
// at one time, and the trajectory held it twice).
TEST(SevenScenes, OneFrameNumberTwiceIsRefused) {
  const std::string dir = test::tempDir("sevenscenes_twice");
  for (const std::string& s : {stem(dir, 3), dir + "/frame-3", stem(dir, 4)}) {
    cv::imwrite(s + ".color.png", cv::Mat(48, 64, CV_8UC3, cv::Scalar(10, 20, 30)));
    cv::imwrite(s + ".depth.png", cv::Mat(48, 64, CV_16UC1, cv::Scalar(1000)));
  }
  try {
    SevenScenesSource(dir, {});
    ADD_FAILURE() << "read";
  } catch (const InputError& e) {
    const std::string said = e.what();
    EXPECT_NE(said.find(dir + ": frames frame-"), std::string::npos) << said;
    EXPECT_NE(said.find("have one number: which is frame 3?"), std::string::npos) << said;
  }
}

// A folder that cannot be listed or searched says so: it was "not a TUM RGB-D sequence nor a 7-Scenes
// one", sending the user to look at the folder's layout.
TEST(SevenScenes, AnUnreadableFolderSaysWhy) {
  const std::string dir = test::tempDir("sevenscenes_unreadable");
  cv::imwrite(stem(dir, 0) + ".color.png", cv::Mat(48, 64, CV_8UC3, cv::Scalar(10, 20, 30)));
  cv::imwrite(stem(dir, 0) + ".depth.png", cv::Mat(48, 64, CV_16UC1, cv::Scalar(1000)));
  ASSERT_TRUE(SevenScenesSource::looksLike(dir));
  // Searchable but not listable, then listable but not searchable (the test runs as nobody: "others").
  for (const fs::perms p : {fs::perms::owner_exec | fs::perms::others_exec, fs::perms::owner_read | fs::perms::others_read}) {
    fs::permissions(dir, p);
    const std::string said = test::errorWithoutPrivileges([&] { openFrameSource(dir); });
    // The source on its own, as a library user makes it: a folder it cannot list said a bare
    // filesystem_error ("directory iterator cannot open directory").
    const std::string unlisted = test::errorWithoutPrivileges([&] { SevenScenesSource(dir, {}); });
    fs::permissions(dir, fs::perms::owner_all);
    EXPECT_EQ(said, dir + ": folder cannot be read (Permission denied)");
    if ((p & fs::perms::others_read) == fs::perms::none) EXPECT_EQ(unlisted, dir + ": folder cannot be read (Permission denied)");
  }
}

// The real TUM excerpt rewritten in the 7-Scenes layout (depth in mm, ground-truth pose per frame)
// reads back as the TUM source does, to the millimetre.
TEST(SevenScenes, MatchesTumSourceOnConvertedRealFrames) {
  const std::string tum = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(tum);
  const std::string dir = test::tempDir("sevenscenes_tum");
  TumFolderSource ref(tum, {});
  const int n = 10;
  std::vector<Frame> frames;
  for (int i = 0; i < n; ++i) {
    frames.push_back(ref.read(std::size_t(i)));
    const Frame& f = frames.back();
    cv::Mat mm;
    f.depth.convertTo(mm, CV_16U, 1000.0);
    ASSERT_TRUE(cv::imwrite(stem(dir, i) + ".color.png", f.rgb));
    ASSERT_TRUE(cv::imwrite(stem(dir, i) + ".depth.png", mm));
    ASSERT_TRUE(f.groundTruth.has_value());
    writePose(stem(dir, i) + ".pose.txt", *f.groundTruth);
  }
  SourceOptions o;
  o.intrinsics = "fr1";
  auto src = openFrameSource(dir, o);
  ASSERT_EQ(src->size(), std::size_t(n));
  Frame f;
  for (int i = 0; i < n; ++i) {
    ASSERT_TRUE(src->next(f));
    EXPECT_EQ(cv::norm(f.rgb, frames[i].rgb, cv::NORM_INF), 0.0);
    EXPECT_LE(cv::norm(f.depth, frames[i].depth, cv::NORM_INF), 0.5e-3 + 1e-6);
    EXPECT_EQ(cv::countNonZero(f.depth > 0), cv::countNonZero(frames[i].depth > 0));
    EXPECT_DOUBLE_EQ(f.camera.fx, 517.3);
    ASSERT_TRUE(f.groundTruth.has_value());
    EXPECT_LT((f.groundTruth->asVectorVal() - frames[i].groundTruth->asVectorVal()).norm(), 1e-5);
  }
}
