// TUM-layout folders from other sensors: the depth unit (--depth-scale, a camera file), intrinsics
// from intrinsics.txt / camera.yaml, a guess only for 640x480 and then announced, sizes checked.
#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>

#include <opencv2/imgcodecs.hpp>

#include "support.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/trajectory.h"
#include "vofusion/io/tum_source.h"

using namespace vofusion;
namespace fs = std::filesystem;

namespace {

// A one-frame TUM-layout folder of the given size: a grey image and a flat depth of `raw` units.
std::string oneFrameFolder(const std::string& dir, int w, int h, uint16_t raw) {
  fs::create_directories(dir + "/rgb");
  fs::create_directories(dir + "/depth");
  cv::imwrite(dir + "/rgb/0.000000.png", cv::Mat(h, w, CV_8UC3, cv::Scalar(90, 120, 150)));
  cv::imwrite(dir + "/depth/0.000000.png", cv::Mat(h, w, CV_16UC1, cv::Scalar(raw)));
  std::ofstream(dir + "/rgb.txt") << "0.000000 rgb/0.000000.png\n";
  std::ofstream(dir + "/depth.txt") << "0.000000 depth/0.000000.png\n";
  return dir;
}

std::string errorOf(const std::string& folder, const SourceOptions& so = {}) {
  try {
    TumFolderSource src(folder, so);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

}  // namespace

// --intrinsics for a camera larger than 640x480: its centre lies where the recording's size puts it,
// which the source checks once it knows that size. Checked against 640x480 at parsing, a 1280x720
// camera's centre was refused.
TEST(CameraFiles, IntrinsicsOfALargerCameraParseAndAreCheckedAgainstItsSize) {
  CameraIntrinsics c;
  EXPECT_NO_THROW(c = CameraIntrinsics::parse("915,915,640.3,360.1"));
  EXPECT_DOUBLE_EQ(c.cx, 640.3);
  EXPECT_EQ(c.width, 0);  // four numbers state no size: they are the recording's, never scaled
  CameraIntrinsics sized;
  EXPECT_NO_THROW(sized = c.forImage(1280, 720, "--intrinsics"));
  EXPECT_DOUBLE_EQ(sized.fx, 915);
  EXPECT_DOUBLE_EQ(sized.cx, 640.3);
  EXPECT_EQ(sized.width, 1280);
  EXPECT_THROW(c.forImage(640, 480, "--intrinsics"), InputError);
  EXPECT_THROW(CameraIntrinsics::parse("915,915,-3,360.1"), InputError);  // negative: outside any image
}

// A preset is a 640x480 calibration. Given a recording of the same shape at another size, it is
// scaled (pixel centres kept); left as it was, `ros` on a 320x240 shake put the principal point in
// the image's corner and tracked at 0.146 m ATE against 0.013. Another shape is refused, named.
TEST(CameraFiles, APresetIsScaledToARecordingOfItsShape) {
  const CameraIntrinsics half = CameraIntrinsics::parse("ros").forImage(320, 240, "--intrinsics");
  EXPECT_DOUBLE_EQ(half.fx, 262.5);
  EXPECT_DOUBLE_EQ(half.fy, 262.5);
  EXPECT_DOUBLE_EQ(half.cx, 159.5);
  EXPECT_DOUBLE_EQ(half.cy, 119.5);
  const CameraIntrinsics fr1 = CameraIntrinsics::parse("fr1"), fr1_vga = fr1.forImage(640, 480, "--intrinsics");
  EXPECT_DOUBLE_EQ(fr1_vga.fx, fr1.fx);
  EXPECT_DOUBLE_EQ(fr1_vga.cy, fr1.cy);
  EXPECT_EQ(fr1.forImage(1280, 960, "--intrinsics").dist, fr1.dist);  // distortion is in normalised coordinates
  try {
    fr1.forImage(1280, 720, "--intrinsics");
    ADD_FAILURE() << "a 640x480 preset was taken for 1280x720 images";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "--intrinsics: a calibration of 640x480 images, this recording's are 1280x720 "
                                     "(another shape): give its camera as fx,fy,cx,cy");
  }
  // Through a TUM folder, as `vofusion --intrinsics ros` reads one.
  const std::string dir = oneFrameFolder(test::tempDir("cam_preset_scaled") + "/seq", 320, 240, 1200);
  SourceOptions given;
  given.intrinsics = "ros";
  TumFolderSource src(dir, given);
  EXPECT_DOUBLE_EQ(src.camera().fx, 262.5);
  EXPECT_DOUBLE_EQ(src.camera().cx, 159.5);
  EXPECT_EQ(src.camera().width, 320);
}

// A focal length under a pixel became 0 in the float maths (1e-50: vofusion's ray cast never ended);
// one of 1e300 tracked nothing (every pose the identity, exit 0). Both are refused, naming the file.
TEST(CameraFiles, ImplausibleFocalLengthsAreRefused) {
  const std::string dir = oneFrameFolder(test::tempDir("cam_focal") + "/seq", 160, 120, 1500);
  for (const char* focal : {"1e-50", "0.5", "1e300", "16001"}) {
    SCOPED_TRACE(focal);
    std::ofstream(dir + "/intrinsics.txt") << focal << " " << focal << " 79.5 59.5\n";
    EXPECT_NE(errorOf(dir).find("intrinsics.txt: inconsistent intrinsics: focal length must be between 1 and 16000 pixels"),
              std::string::npos) << errorOf(dir);
  }
  std::ofstream(dir + "/intrinsics.txt") << "16000 16000 79.5 59.5\n";  // a 0.6 degree field of view: the limit
  EXPECT_EQ(errorOf(dir), "");
}

TEST(CameraFiles, IntrinsicsTxtWithSizeAndDepthScale) {
  const std::string dir = oneFrameFolder(test::tempDir("cam_txt") + "/seq", 320, 240, 1500);
  std::ofstream(dir + "/intrinsics.txt") << "# from a RealSense\n300 301 160.5 119.5 0.1 -0.2 0 0 0.05\nsize 320 240\n"
                                            "depth_scale 1000\n";
  TumFolderSource src(dir, {});
  EXPECT_DOUBLE_EQ(src.camera().fx, 300);
  EXPECT_DOUBLE_EQ(src.camera().cy, 119.5);
  EXPECT_DOUBLE_EQ(src.camera().dist[4], 0.05);
  EXPECT_DOUBLE_EQ(src.depthScale(), 1000);
  EXPECT_NEAR(src.read(0).depth.at<float>(10, 10), 1.5f, 1e-6);
  SourceOptions so;
  so.depth_scale = 5000;  // the command line wins over the file
  EXPECT_NEAR(TumFolderSource(dir, so).read(0).depth.at<float>(10, 10), 0.3f, 1e-6);
  // A file for another image size is an error naming the file.
  std::ofstream(dir + "/intrinsics.txt") << "300 300 160 120\nsize 640 480\n";
  EXPECT_NE(errorOf(dir).find("intrinsics.txt: intrinsics are for 640x480 images, this recording's are 320x240"),
            std::string::npos) << errorOf(dir);
  std::ofstream(dir + "/intrinsics.txt") << "300 300 160 120\ndepth_unit 1000\n";
  EXPECT_NE(errorOf(dir).find("line 2"), std::string::npos) << errorOf(dir);
}

TEST(CameraFiles, CameraYamlAsOpenCvWritesIt) {
  const std::string dir = oneFrameFolder(test::tempDir("cam_yaml") + "/seq", 320, 240, 1200);
  {
    cv::FileStorage fs(dir + "/camera.yaml", cv::FileStorage::WRITE);
    fs << "image_width" << 320 << "image_height" << 240;
    fs << "camera_matrix" << (cv::Mat_<double>(3, 3) << 310, 0, 158, 0, 309, 121, 0, 0, 1);
    fs << "distortion_coefficients" << (cv::Mat_<double>(1, 5) << 0.01, 0.02, 0, 0, 0);
    fs << "depth_scale" << 1000.0;
  }
  TumFolderSource src(dir, {});
  EXPECT_DOUBLE_EQ(src.camera().fx, 310);
  EXPECT_DOUBLE_EQ(src.camera().cx, 158);
  EXPECT_DOUBLE_EQ(src.camera().dist[1], 0.02);
  EXPECT_NEAR(src.read(0).depth.at<float>(5, 5), 1.2f, 1e-6);
  std::ofstream(dir + "/camera.yaml") << "%YAML:1.0\nimage_width: 320\n";
  EXPECT_NE(errorOf(dir).find("camera.yaml: camera_matrix must be a 3x3 matrix"), std::string::npos) << errorOf(dir);
  // --intrinsics (another tool's camera.yaml in the folder): the file is not the camera, and a file this
  // reader cannot take does not stop the run: it is said and left (with --depth-scale, not read at all).
  SourceOptions given;
  given.intrinsics = "310,309,158,121";
  testing::internal::CaptureStderr();
  EXPECT_EQ(errorOf(dir, given), "");
  const std::string said = testing::internal::GetCapturedStderr();
  EXPECT_NE(said.find("camera.yaml: camera_matrix must be a 3x3 matrix"), std::string::npos) << said;
  given.strict = true;  // --strict: what cannot be read stops the run
  EXPECT_NE(errorOf(dir, given).find("camera.yaml: camera_matrix must be a 3x3 matrix"), std::string::npos);
  given.strict = false;
  given.depth_scale = 1000;
  testing::internal::CaptureStderr();
  EXPECT_EQ(errorOf(dir, given), "");
  EXPECT_EQ(testing::internal::GetCapturedStderr(), "");
}

// A camera.yaml without distortion_coefficients (an undistorted camera's) is a camera without
// distortion: it stopped every app with SIGFPE.
TEST(CameraFiles, CameraYamlWithoutDistortionHasNone) {
  const std::string dir = oneFrameFolder(test::tempDir("cam_nodist") + "/seq", 320, 240, 1200);
  std::ofstream(dir + "/camera.yaml") << "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [310, 0, 158, 0, 309, 121, 0, 0, 1]\n";
  TumFolderSource src(dir, {});
  EXPECT_DOUBLE_EQ(src.camera().fx, 310);
  for (int i = 0; i < 5; ++i) EXPECT_EQ(src.camera().dist[i], 0.0);
}

// ROS's camera_info YAML (camera_calibration writes it: no %YAML line, matrices as rows, cols, data) is
// read as it is; a matrix OpenCV cannot read is one line naming the file, not OpenCV's assertion.
TEST(CameraFiles, CameraYamlAsRosWritesIt) {
  const std::string dir = oneFrameFolder(test::tempDir("cam_ros") + "/seq", 320, 240, 1200);
  std::ofstream(dir + "/camera.yaml") << "image_width: 320\nimage_height: 240\ncamera_name: xtion\n"
                                         "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [310, 0, 158, 0, 309, 121, 0, 0, 1]\n"
                                         "distortion_model: plumb_bob\n"
                                         "distortion_coefficients:\n  rows: 1\n  cols: 5\n  data: [0.01, 0.02, 0, 0, 0]\n";
  TumFolderSource src(dir, {});
  EXPECT_DOUBLE_EQ(src.camera().fx, 310);
  EXPECT_DOUBLE_EQ(src.camera().fy, 309);
  EXPECT_DOUBLE_EQ(src.camera().cy, 121);
  EXPECT_DOUBLE_EQ(src.camera().dist[1], 0.02);
  // A fisheye (equidistant) model is not k1 k2 p1 p2 k3: refused, not misread.
  std::ofstream(dir + "/camera.yaml") << "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [310, 0, 158, 0, 309, 121, 0, 0, 1]\n"
                                         "distortion_model: equidistant\n"
                                         "distortion_coefficients:\n  rows: 1\n  cols: 4\n  data: [0.1, 0.01, 0, 0]\n";
  EXPECT_EQ(errorOf(dir), dir + "/camera.yaml: distortion 'equidistant' with 4 coefficients: only k1 k2 p1 p2 k3 (plumb_bob) "
                                "can be used");
  // Eight coefficients and no model named (OpenCV's own calibration file): k4..k6 are not zero.
  std::ofstream(dir + "/camera.yaml") << "camera_matrix:\n  rows: 3\n  cols: 3\n  data: [310, 0, 158, 0, 309, 121, 0, 0, 1]\n"
                                         "distortion_coefficients:\n  rows: 1\n  cols: 8\n  data: [0.1, 0.01, 0, 0, 0, 0.2, 0, 0]\n";
  EXPECT_EQ(errorOf(dir), dir + "/camera.yaml: distortion with 8 coefficients, some beyond k3 not zero: only k1 k2 p1 p2 k3 "
                                "(plumb_bob) can be used");
  std::ofstream(dir + "/camera.yaml") << "%YAML:1.0\ncamera_matrix: [310, 0, 158, 0, 309, 121, 0, 0, 1]\n";
  EXPECT_EQ(errorOf(dir), dir + "/camera.yaml: camera_matrix must be a matrix (OpenCV's rows, cols, dt, data or ROS's rows, "
                                "cols, data)");
}

// The image size is the first readable colour image's: a missing first one costs its frame, not the
// run (it used to make the size 640x480, so a 320x240 camera file was refused as for other images).
TEST(CameraFiles, AMissingFirstColourImageDoesNotDecideTheSize) {
  const std::string dir = oneFrameFolder(test::tempDir("cam_first") + "/seq", 320, 240, 1200);
  cv::imwrite(dir + "/rgb/0.033333.png", cv::Mat(240, 320, CV_8UC3, cv::Scalar(90, 120, 150)));
  cv::imwrite(dir + "/depth/0.033333.png", cv::Mat(240, 320, CV_16UC1, cv::Scalar(1200)));
  std::ofstream(dir + "/rgb.txt") << "0.000000 rgb/0.000000.png\n0.033333 rgb/0.033333.png\n";
  std::ofstream(dir + "/depth.txt") << "0.000000 depth/0.000000.png\n0.033333 depth/0.033333.png\n";
  std::ofstream(dir + "/intrinsics.txt") << "300 300 160 120\nsize 320 240\n";
  fs::remove(dir + "/rgb/0.000000.png");
  TumFolderSource src(dir, {});
  EXPECT_EQ(src.camera().width, 320);
  EXPECT_THROW(src.read(0), InputError);
  EXPECT_EQ(src.read(1).rgb.cols, 320);
  // None readable: one line naming the first, not a size made up.
  fs::remove(dir + "/rgb/0.033333.png");
  EXPECT_EQ(errorOf(dir), dir + "/rgb/0.000000.png: colour image cannot be read, nor can any of the first 2 listed in rgb.txt");
}

// A damaged groundtruth.txt costs the evaluation, in one line naming it, not the run; --strict stops.
TEST(CameraFiles, ADamagedGroundTruthCostsTheEvaluation) {
  const std::string dir = oneFrameFolder(test::tempDir("cam_gt") + "/seq", 640, 480, 1200);
  std::ofstream(dir + "/groundtruth.txt") << "0.2 1 0 0 0 0 0 1\n0.1 1 0 0 0 0 0 1\n";
  SourceOptions so;
  so.intrinsics = "fr1";
  testing::internal::CaptureStderr();
  TumFolderSource src(dir, so);
  const std::string log = testing::internal::GetCapturedStderr();
  EXPECT_TRUE(src.groundTruth().empty());
  EXPECT_NE(log.find(dir + "/groundtruth.txt: "), std::string::npos) << log;
  EXPECT_NE(log.find("(read without ground truth: nothing is evaluated or converted from it)"), std::string::npos) << log;
  so.strict = true;
  EXPECT_NE(errorOf(dir, so).find(dir + "/groundtruth.txt: "), std::string::npos);
  // An empty one is said too (it was taken silently as no ground truth).
  std::ofstream(dir + "/groundtruth.txt", std::ios::trunc) << "# timestamp tx ty tz qx qy qz qw\n";
  so.strict = false;
  testing::internal::CaptureStderr();
  TumFolderSource empty(dir, so);
  EXPECT_EQ(testing::internal::GetCapturedStderr(),
            "warning: " + dir + "/groundtruth.txt: holds no poses (read without ground truth: nothing is evaluated or converted from it)\n");
}

// The TUM camera is guessed from the folder's own name: a parent's name (a folder of runs called
// freiburg1_runs) said fr1 for a freiburg3 recording, and a recording opened as "." got no guess.
TEST(CameraFiles, TheFreiburgCameraIsTheFoldersOwn) {
  EXPECT_DOUBLE_EQ(CameraIntrinsics::forTumFolder("/d/freiburg1_runs/rgbd_dataset_freiburg3_long_office").fx, 535.4);
  EXPECT_DOUBLE_EQ(CameraIntrinsics::forTumFolder("/d/freiburg2_exports/my_realsense_take/").fx, 525.0);
  EXPECT_DOUBLE_EQ(CameraIntrinsics::forTumFolder("/d/rgbd_dataset_freiburg1_xyz/").fx, 517.3);
  EXPECT_FALSE(CameraIntrinsics::namesAFreiburgCamera("/d/freiburg1_runs/take"));
  // "freiburg" without 1, 2 or 3 names no camera forTumFolder knows: its guess of the ROS default is said.
  EXPECT_FALSE(CameraIntrinsics::namesAFreiburgCamera("/d/my_freiburg_take"));
  const std::string dir = test::tempDir("cam_own_name") + "/rgbd_dataset_freiburg1_t";
  fs::create_directories(dir);
  const fs::path before = fs::current_path();
  fs::current_path(dir);
  const double fx = CameraIntrinsics::forTumFolder(".").fx;
  const bool named = CameraIntrinsics::namesAFreiburgCamera(".");
  fs::current_path(before);
  EXPECT_DOUBLE_EQ(fx, 517.3);
  EXPECT_TRUE(named);
  // A half-size copy of a TUM recording keeps its camera, halved (as --intrinsics fr1 would); another
  // shape is still no guess.
  const std::string half = oneFrameFolder(test::tempDir("cam_own_half") + "/rgbd_dataset_freiburg1_half", 320, 240, 5000);
  TumFolderSource src(half, {});
  EXPECT_DOUBLE_EQ(src.camera().fx, 517.3 / 2);
  EXPECT_DOUBLE_EQ(src.camera().cx, (318.6 + 0.5) / 2 - 0.5);
  const std::string wide = oneFrameFolder(test::tempDir("cam_own_wide") + "/rgbd_dataset_freiburg1_wide", 1280, 720, 5000);
  EXPECT_NE(errorOf(wide).find("no intrinsics for its 1280x720 images"), std::string::npos) << errorOf(wide);
}

// Without a camera file, only a 640x480 recording gets a guess, and the guess is said; another size
// is an error that says what to do.
TEST(CameraFiles, GuessOnlyFor640x480AndAnnounced) {
  const std::string base = test::tempDir("cam_guess");
  const std::string big = oneFrameFolder(base + "/hd", 1280, 720, 7000);
  EXPECT_NE(errorOf(big).find("no intrinsics for its 1280x720 images: give --intrinsics"), std::string::npos) << errorOf(big);
  SourceOptions so;
  so.intrinsics = "910,910,639.5,359.5";
  EXPECT_EQ(errorOf(big, so), "");
  oneFrameFolder(base + "/vga", 640, 480, 7000);
  std::string log;
  EXPECT_EQ(test::run(test::app("vofusion") + " " + base + "/vga --mode kinfu --out " + base + "/out", &log), 0) << log;
  EXPECT_NE(log.find("warning: " + base + "/vga: no intrinsics.txt or camera.yaml and no --intrinsics: assuming fx = fy = 525"),
            std::string::npos)
      << log;
  // Millimetres read as TUM's units: a fifth of the distance, announced; at 0.28 m no reading is in
  // range, and a run that tracks no frame fails in one line.
  oneFrameFolder(base + "/mm", 640, 480, 1400);
  ASSERT_EQ(test::run(test::app("vofusion") + " " + base + "/mm --intrinsics ros --mode kinfu --out " + base + "/out2", &log), 2)
      << log;
  EXPECT_NE(log.find("median depth 0.28 m at 5000 depth units per metre: another unit?"), std::string::npos) << log;
  EXPECT_NE(log.find("no frame was tracked, all 1 lost (no depth reading in [min_depth, max_depth])"), std::string::npos) << log;
}

// The check: a depth-in-mm copy of a shared TUM sequence (converted here, never stored in the
// project) gives the original's trajectory within 1 mm with --depth-scale 1000.
TEST(CameraFiles, MillimetreCopyOfTumGivesTheSameTrajectory) {
  const std::string tum = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(tum);
  const std::string dir = test::tempDir("cam_mm");
  const std::string mm = dir + "/mm";
  fs::create_directories(mm + "/depth");
  fs::create_symlink(fs::absolute(fs::path(tum) / "rgb"), mm + "/rgb");
  fs::copy_file(fs::path(tum) / "rgb.txt", mm + "/rgb.txt");
  const auto depth = readTumList(tum + "/depth.txt");
  std::ofstream list(mm + "/depth.txt");
  const std::size_t frames = 40;
  for (std::size_t i = 0; i < frames + 2 && i < depth.size(); ++i) {
    const cv::Mat raw = cv::imread(tum + "/" + depth[i].file, cv::IMREAD_UNCHANGED);
    ASSERT_EQ(raw.type(), CV_16UC1);
    cv::Mat millimetres;
    raw.convertTo(millimetres, CV_16U, 1000.0 / 5000.0);  // rounds to the millimetre, as such sensors store it
    ASSERT_TRUE(cv::imwrite(mm + "/" + depth[i].file, millimetres));
    list << std::fixed << depth[i].timestamp << " " << depth[i].file << "\n";
  }
  list.close();
  auto run = [&](const std::string& input, const std::string& extra, const std::string& out) {
    std::string log;
    EXPECT_EQ(test::run(test::app("vofusion") + " " + input + " --max-frames " + std::to_string(frames) +
                            " --intrinsics fr1 --out " + out + " " + extra,
                        &log),
              0)
        << log;
    return readTumTrajectory(out + "/trajectory.txt");
  };
  const Trajectory a = run(tum, "", dir + "/a"), b = run(mm, "--depth-scale 1000", dir + "/b");
  ASSERT_EQ(a.size(), frames);
  ASSERT_EQ(b.size(), frames);
  double worst = 0, sum2 = 0;
  for (std::size_t i = 0; i < frames; ++i) {
    const double d = (a[i].pose.translation() - b[i].pose.translation()).norm();
    worst = std::max(worst, d);
    sum2 += d * d;
  }
  const double rms = std::sqrt(sum2 / frames);
  std::printf("mm copy vs original, %zu frames: position difference RMS %.5f m, largest %.5f m\n", frames, rms, worst);
  EXPECT_LT(rms, 0.001);
  EXPECT_LT(worst, 0.003);  // millimetre steps instead of 0.2 mm ones move single frames a little
}

// "Up" from TUM's accelerometer.txt: turned into the world by the ground truth, it points along the
// ground truth's z (its up) on both shared sequences, the slow and the fast one: a few degrees per
// frame (the camera's own accelerations add to gravity) and ~4 deg averaged over the recording as the
// run outputs use it, on both (the same offset on both: the mocap frame's z and the accelerometer).
TEST(CameraFiles, AccelerometerUpMatchesGroundTruthUp) {
  for (const std::string name : {"rgbd_dataset_freiburg1_xyz_first300", "rgbd_dataset_freiburg1_rpy_first100"}) {
    const std::string folder = (fs::path(test::tumFirst300()).parent_path() / name).string();
    VOFUSION_REQUIRE_DATA(folder);
    TumFolderSource src(folder, {});
    double worst = 0, sum = 0;
    int n = 0;
    Eigen::Vector3d mean_up = Eigen::Vector3d::Zero();
    for (std::size_t i = 0; i < src.size(); i += 5) {
      const Frame f = src.read(i);
      ASSERT_TRUE(f.up.has_value()) << name << " frame " << i;
      ASSERT_TRUE(f.groundTruth.has_value());
      const Eigen::Vector3d up_world = f.groundTruth->getRotationMatrix().asEigen() * *f.up;
      const double deg = std::acos(std::clamp(up_world.z(), -1.0, 1.0)) * 180 / M_PI;
      worst = std::max(worst, deg);
      sum += deg;
      mean_up += up_world;
      ++n;
    }
    const double mean_deg = std::acos(std::clamp(mean_up.normalized().z(), -1.0, 1.0)) * 180 / M_PI;
    std::printf("%s: accelerometer up vs ground truth: %.2f deg averaged; per frame mean %.2f, worst %.2f deg (%d frames)\n",
                name.c_str(), mean_deg, sum / n, worst, n);
    EXPECT_LT(mean_deg, 6.0) << name;
    EXPECT_LT(sum / n, 8.0) << name;
    EXPECT_LT(worst, 20.0) << name;
  }
}

namespace {
// A TUM folder of 8 frames at 30 Hz, 320x240: depth line i names depth_file(i) (written), and a colour
// frame at the same stamp when with_colour(i). Returns the frames its source pairs, and what it printed.
template <class DepthFile, class WithColour>
std::pair<std::size_t, std::string> openEightFrames(const std::string& dir, DepthFile depth_file, WithColour with_colour) {
  fs::create_directories(dir + "/rgb");
  fs::create_directories(dir + "/depth");
  std::ofstream rgb(dir + "/rgb.txt"), depth(dir + "/depth.txt");
  for (int i = 0; i < 8; ++i) {
    const std::string t = cv::format("%.6f", i / 30.0), file = depth_file(i, t);
    cv::imwrite(dir + "/" + file, cv::Mat(240, 320, CV_16UC1, cv::Scalar(5000)));
    depth << t << " " << file << "\n";
    if (!with_colour(i)) continue;
    cv::imwrite(dir + "/rgb/" + t + ".png", cv::Mat(240, 320, CV_8UC3, cv::Scalar(90, 120, 150)));
    rgb << t << " rgb/" << t << ".png\n";
  }
  rgb.close(), depth.close();
  SourceOptions so;
  so.intrinsics = "262.5,262.5,159.5,119.5";
  testing::internal::CaptureStderr();
  const TumFolderSource src(dir, so);
  return {src.size(), testing::internal::GetCapturedStderr()};
}
}  // namespace

// Depth frames no colour frame pairs with are not used, which is said when they are many: a colour
// camera at 15 Hz beside depth at 30 Hz halved the frames tracked without a word.
TEST(CameraFiles, DepthFramesLeftUnpairedAreSaid) {
  const std::string dir = test::tempDir("cam_rates") + "/seq";
  const auto [frames, said] = openEightFrames(
      dir, [](int, const std::string& t) { return "depth/" + t + ".png"; }, [](int i) { return i % 2 == 0; });
  EXPECT_EQ(frames, 4u);
  EXPECT_NE(said.find(dir + "/depth.txt: 4 of its 8 depth frames have no colour frame within 0.02 s and are not used"),
            std::string::npos)
      << said;
}

// A driver that repeats a frame lists one depth file at two stamps; both are paired (each depth line is
// a frame) and none is said to be unused (counted by file name, 4 of 8 were).
TEST(CameraFiles, ADepthFileListedTwiceIsTwoPairedFrames) {
  const auto [frames, said] = openEightFrames(
      test::tempDir("cam_repeated") + "/seq", [](int i, const std::string&) { return cv::format("depth/%d.png", i / 2); },
      [](int) { return true; });
  EXPECT_EQ(frames, 8u);
  EXPECT_EQ(said.find("are not used"), std::string::npos) << said;
}
