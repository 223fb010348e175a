// A rawlog whose colour camera is not its depth camera (another pose, other intrinsics, another
// size): colour is re-projected into the depth camera, not resized onto it.
#include <cmath>
#include <fstream>
#include <vector>

#include <mrpt/img/CImage.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "support.h"
#include "vofusion/core/errors.h"
#include "vofusion/io/colour_registration.h"
#include "vofusion/io/rawlog.h"
#include "vofusion/live/live_source.h"

using namespace vofusion;
using mrpt::poses::CPose3D;

namespace {

// A checkerboard of 10 cm cells painted on the world (depth camera coordinates).
cv::Vec3b paint(double x, double y) {
  const bool odd = (int(std::floor(x / 0.1)) + int(std::floor(y / 0.1))) & 1;
  return odd ? cv::Vec3b(30, 40, 220) : cv::Vec3b(220, 180, 20);
}
bool nearEdge(double x, double y) {
  const double fx = x / 0.1 - std::floor(x / 0.1), fy = y / 0.1 - std::floor(y / 0.1);
  return std::min(fx, 1 - fx) < 0.04 || std::min(fy, 1 - fy) < 0.04;
}

constexpr double kWall = 2.0;  // m: a wall facing the depth camera

struct Rig {
  CameraIntrinsics depth_cam, colour_cam;
  Eigen::Isometry3d T_depth_colour = Eigen::Isometry3d::Identity();  // colour camera in depth coordinates
};

// The observation a sensor with this rig records of the wall.
mrpt::obs::CObservation3DRangeScan::Ptr observe(const Rig& rig) {
  Frame f;
  f.camera = rig.depth_cam;
  f.depth = cv::Mat(rig.depth_cam.height, rig.depth_cam.width, CV_32F, cv::Scalar(kWall));
  cv::Mat colour(rig.colour_cam.height, rig.colour_cam.width, CV_8UC3);
  const CameraIntrinsics& c = rig.colour_cam;
  for (int v = 0; v < colour.rows; ++v)
    for (int u = 0; u < colour.cols; ++u) {
      const Eigen::Vector3d o = rig.T_depth_colour.translation();
      const Eigen::Vector3d d = rig.T_depth_colour.linear() * Eigen::Vector3d((u - c.cx) / c.fx, (v - c.cy) / c.fy, 1);
      const Eigen::Vector3d p = o + (kWall - o.z()) / d.z() * d;
      colour.at<cv::Vec3b>(v, u) = paint(p.x(), p.y());
    }
  f.rgb = cv::Mat(f.depth.size(), CV_8UC3);  // replaced below: the observation carries the colour camera's own image
  auto obs = observationFromFrame(f);
  obs->intensityImage = mrpt::img::CImage(colour, mrpt::img::DEEP_COPY);
  obs->cameraParamsIntensity = rig.colour_cam.toMrpt();
  CPose3D pose_in_depth;
  mrpt::math::CMatrixDouble44 M;
  M.asEigen() = rig.T_depth_colour.matrix();
  pose_in_depth = CPose3D(M);
  obs->relativePoseIntensityWRTDepth = CPose3D(0, 0, 0, -M_PI / 2, 0, -M_PI / 2) + pose_in_depth;
  return obs;
}

// What the frame's colour says of the wall, over the depth pixels away from the paint's cell edges:
// `coloured` of `wall` were given a colour at all, `right` of those the wall's own there.
struct WallColour {
  int wall = 0, coloured = 0, right = 0;
};
WallColour wallColour(const Frame& f, const Rig& rig) {
  const CameraIntrinsics& d = rig.depth_cam;
  WallColour c;
  for (int v = 0; v < f.rgb.rows; ++v)
    for (int u = 0; u < f.rgb.cols; ++u) {
      const double x = (u - d.cx) * kWall / d.fx, y = (v - d.cy) * kWall / d.fy;
      if (nearEdge(x, y)) continue;
      ++c.wall;
      const cv::Vec3b got = f.rgb.at<cv::Vec3b>(v, u);
      if (got == cv::Vec3b(0, 0, 0)) continue;
      ++c.coloured;
      const cv::Vec3b want = paint(x, y);
      c.right += std::abs(got[0] - want[0]) + std::abs(got[1] - want[1]) + std::abs(got[2] - want[2]) < 30;
    }
  return c;
}

// Share of the coloured wall pixels whose colour is the wall's there.
double agreement(const Frame& f, const Rig& rig) {
  const WallColour c = wallColour(f, rig);
  return c.coloured > 0 ? double(c.right) / c.coloured : 0.0;
}

// Share of the wall's pixels given a colour at all: agreement() judges only those, so a reprojection
// leaving most of the image black would pass it.
double coverage(const Frame& f, const Rig& rig) {
  const WallColour c = wallColour(f, rig);
  return c.wall > 0 ? double(c.coloured) / c.wall : 0.0;
}

}  // namespace

TEST(ColourRegistration, OffsetColourCameraIsReprojectedIntoTheDepthCamera) {
  Rig rig;
  rig.depth_cam = CameraIntrinsics{}.scaled(0.5);  // 320x240, f = 262.5
  rig.colour_cam = CameraIntrinsics{};              // 640x480, f = 525, shifted principal point
  rig.colour_cam.fx = 560, rig.colour_cam.fy = 558, rig.colour_cam.cx = 330, rig.colour_cam.cy = 236;
  rig.T_depth_colour.translation() = Eigen::Vector3d(0.052, -0.01, 0.004);  // a Kinect's baseline, roughly
  rig.T_depth_colour.linear() = Eigen::AngleAxisd(2.0 * M_PI / 180, Eigen::Vector3d::UnitY()).toRotationMatrix();
  const auto obs = observe(rig);
  EXPECT_FALSE(colourRegisteredToDepth(*obs));
  const Frame f = frameFromObservation(*obs, "offset.rawlog");
  ASSERT_EQ(f.rgb.size(), cv::Size(320, 240));
  const double registered = agreement(f, rig);
  EXPECT_GT(registered, 0.99);
  // The colour camera's narrower view (f 560 against the depth's 525 at 640 px) and its offset cover
  // 87 % of the depth image's wall: what it does not see stays black, and no more.
  EXPECT_GT(coverage(f, rig), 0.85);
  // What resizing the colour image onto the depth image (the former reading) gives: far off.
  Frame resized = f;
  cv::resize(obs->intensityImage.asCvMat<cv::Mat>(mrpt::img::SHALLOW_COPY), resized.rgb, cv::Size(320, 240), 0, 0,
             cv::INTER_AREA);
  EXPECT_LT(agreement(resized, rig), 0.8);
  std::printf("colour agreement: re-projected %.4f, resized %.4f\n", registered, agreement(resized, rig));
  // The depth camera's intrinsics given by hand (--intrinsics on a rawlog): the colour camera is still
  // its own, and re-projected (the override made it be taken as registered, and resized).
  const Frame given = frameFromObservation(*obs, "offset.rawlog", rig.depth_cam);
  EXPECT_GT(agreement(given, rig), 0.99);
}

// Where the colour camera's view ends, a depth pixel is black (no colour) or the colour seen there,
// never a blend of the image's edge with black: a grey wall gave a dark rim along the view's border,
// which fusion painted into the map.
TEST(ColourRegistration, BeyondTheColourImageIsNoColourNotADarkerOne) {
  const CameraIntrinsics depth_cam = CameraIntrinsics{}.scaled(0.5);
  CameraIntrinsics colour_cam = CameraIntrinsics{};
  colour_cam.fx = colour_cam.fy = 600;  // narrower: the depth image's border is beyond it
  const cv::Mat colour(colour_cam.height, colour_cam.width, CV_8UC3, cv::Scalar(200, 200, 200));
  const cv::Mat depth(depth_cam.height, depth_cam.width, CV_32F, cv::Scalar(2.0f));
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(-0.0237, 0.0113, 0);  // not on whole pixels
  const cv::Mat out = colourInDepthCamera(colour, depth, depth_cam, colour_cam, T);
  int black = 0, grey = 0, between = 0;
  for (int v = 0; v < out.rows; ++v)
    for (int u = 0; u < out.cols; ++u) {
      const int b = out.at<cv::Vec3b>(v, u)[0];
      (b == 0 ? black : b == 200 ? grey : between) += 1;
    }
  EXPECT_GT(black, 1000);
  EXPECT_GT(grey, 50000);
  EXPECT_EQ(between, 0);
}

TEST(ColourRegistration, RegisteredCamerasKeepTheirPixels) {
  Rig rig;
  rig.depth_cam = rig.colour_cam = CameraIntrinsics{}.scaled(0.5);
  const auto obs = observe(rig);
  EXPECT_TRUE(colourRegisteredToDepth(*obs));
  const Frame same = frameFromObservation(*obs, "registered.rawlog");
  EXPECT_GT(agreement(same, rig), 0.99);
  EXPECT_GT(coverage(same, rig), 0.99);
  // A driver that filled in the camera for these images but left MRPT's default size (640x480): the
  // camera is the images' own, never scaled again (only an --intrinsics preset is fitted to the images).
  const auto stale = observe(rig);
  stale->cameraParamsIntensity.ncols = 640;
  stale->cameraParamsIntensity.nrows = 480;
  const CameraIntrinsics as_given = sensorObservationToFrame(*stale, "sensor").camera;
  EXPECT_NEAR(as_given.fx, rig.depth_cam.fx, 1e-9);
  EXPECT_NEAR(as_given.cx, rig.depth_cam.cx, 1e-9);
  EXPECT_EQ(as_given.width, rig.depth_cam.width);
  // The same camera at twice the resolution (a registered 640x480 colour over 320x240 depth). A sensor
  // takes the colour camera's parameters for the depth too: scaled to the depth image (they were taken
  // at twice its focal length).
  rig.colour_cam = CameraIntrinsics{};
  EXPECT_TRUE(colourRegisteredToDepth(*observe(rig)));
  const CameraIntrinsics sensed = sensorObservationToFrame(*observe(rig), "sensor").camera;
  EXPECT_NEAR(sensed.fx, rig.depth_cam.fx, 1e-9);
  EXPECT_NEAR(sensed.cx, rig.depth_cam.cx, 1e-9);
  EXPECT_EQ(sensed.width, rig.depth_cam.width);
  // Each axis scales on its own (a driver computes both focal lengths from the fields of view: Kinect's
  // 1280x1024 colour over 640x480 depth counts as registered): the depth gets its own, fy too.
  const CameraIntrinsics wide = rig.depth_cam.resizedTo(640, 512);
  Rig other = rig;
  other.colour_cam = wide;
  ASSERT_TRUE(colourRegisteredToDepth(*observe(other)));
  const CameraIntrinsics per_axis = sensorObservationToFrame(*observe(other), "sensor").camera;
  EXPECT_NEAR(per_axis.fy, rig.depth_cam.fy, 1e-9);
  EXPECT_NEAR(per_axis.cy, rig.depth_cam.cy, 1e-9);
  // Rows of another aspect (640x512 over 320x240, f twice the depth's): resized, a row went up to 8
  // pixels off at the top and bottom. Re-projected, every pixel is the wall's.
  rig.colour_cam.height = 512, rig.colour_cam.cy = 255.5;
  const auto taller = observe(rig);
  EXPECT_FALSE(colourRegisteredToDepth(*taller));
  EXPECT_GT(agreement(frameFromObservation(*taller, "taller.rawlog"), rig), 0.99);
}

// An external JPEG colour image of another size than its own camera's is refused by its header, in the
// line an image decoded at that size gets (a 19 KB JPEG claiming 32768x32768 was decoded first: 3.2 GB
// and 11 s).
TEST(ColourRegistration, AnExternalJpegOfAnotherSizeThanItsCameraIsRefusedByItsHeader) {
  Rig rig;
  rig.depth_cam = CameraIntrinsics{}.scaled(0.5);
  rig.colour_cam = CameraIntrinsics{};
  rig.T_depth_colour.translation() = Eigen::Vector3d(0.052, 0, 0);
  const auto obs = observe(rig);
  ASSERT_FALSE(colourRegisteredToDepth(*obs));
  const std::string dir = test::tempDir("colour_jpeg_size");
  cv::Mat colour = obs->intensityImage.asCvMat<cv::Mat>(mrpt::img::DEEP_COPY);
  ASSERT_TRUE(cv::imwrite(dir + "/whole.jpg", colour));
  // Its frame header claiming 40000x40000 pixels (past OpenCV's limit: it would be refused as damage
  // after the header's size, not as the camera's mismatch).
  std::vector<std::uint8_t> jpeg;
  ASSERT_TRUE(cv::imencode(".jpg", colour, jpeg));
  const std::size_t sof = std::string(jpeg.begin(), jpeg.end()).find("\xFF\xC0");
  ASSERT_NE(sof, std::string::npos);
  for (const std::size_t k : {sof + 5, sof + 7}) jpeg[k] = 0x9C, jpeg[k + 1] = 0x40;  // height, width
  std::ofstream(dir + "/huge.jpg", std::ios::binary).write(reinterpret_cast<const char*>(jpeg.data()), std::streamsize(jpeg.size()));
  // Of the right size it gives the frame OpenCV's decoding of the file gives.
  auto in_memory = observe(rig);
  in_memory->intensityImage = mrpt::img::CImage(cv::imread(dir + "/whole.jpg"), mrpt::img::DEEP_COPY);
  const Frame expected = frameFromObservation(*in_memory, "jpeg.rawlog");
  obs->intensityImage.setExternalStorage(dir + "/whole.jpg");
  const Frame got = frameFromObservation(*obs, "jpeg.rawlog");
  EXPECT_EQ(cv::norm(got.rgb, expected.rgb, cv::NORM_INF), 0.0);
  EXPECT_GT(agreement(got, rig), 0.85);  // JPEG's chroma at the paint's edges
  obs->intensityImage.setExternalStorage(dir + "/huge.jpg");
  try {
    frameFromObservation(*obs, "jpeg.rawlog");
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), dir + "/huge.jpg: colour image is 40000x40000, its camera parameters say 640x480");
  }
}

// A registered external colour image may be a larger sensor's (up to 16 times the depth image's pixels,
// or 4 megapixels); beyond that its header refuses it before it is decoded, naming the file (a 3 MB PNG
// stating 32768x32768 was two 3.2 GB buffers a frame, and a failed allocation ended the run).
TEST(ColourRegistration, ARegisteredExternalColourImageIsBoundedByTheDepthImage) {
  Rig rig;
  rig.depth_cam = rig.colour_cam = CameraIntrinsics{}.scaled(0.5);
  const auto obs = observe(rig);
  ASSERT_TRUE(colourRegisteredToDepth(*obs));
  const std::string dir = test::tempDir("colour_png_bound");
  const cv::Mat colour = obs->intensityImage.asCvMat<cv::Mat>(mrpt::img::DEEP_COPY);
  for (const int scale : {2, 6, 9}) {
    cv::Mat larger;
    cv::resize(colour, larger, colour.size() * scale, 0, 0, cv::INTER_NEAREST);
    const std::string file = dir + "/x" + std::to_string(scale) + ".png";
    ASSERT_TRUE(cv::imwrite(file, larger));
    obs->intensityImage.setExternalStorage(file);
    if (scale <= 6) {  // 1920x1440: 2.8 megapixels
      EXPECT_GT(agreement(frameFromObservation(*obs, "registered.rawlog"), rig), 0.99) << scale;
      continue;
    }
    try {
      frameFromObservation(*obs, "registered.rawlog");
      FAIL() << "no error";
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()), file + ": colour image is 2880x2160: more pixels than a colour image registered to a "
                                              "320x240 depth image may have (4194304)");
    }
  }
}
