// MRPT 3D scene export (.3Dscene round trip) and the off-screen mesh rendering.
#include <future>
#include <set>
#include <Eigen/Dense>
#include <climits>
#include <cmath>
#include <filesystem>

#include <mrpt/img/CImage.h>
#include <mrpt/opengl/CFrustum.h>
#include <mrpt/opengl/CGridPlaneXY.h>
#include <mrpt/opengl/COpenGLScene.h>
#include <mrpt/opengl/CSetOfLines.h>
#include <mrpt/opengl/CSetOfObjects.h>
#include <mrpt/opengl/CSetOfTriangles.h>
#include <opencv2/imgcodecs.hpp>

#include "support.h"
#include "test_mesh_fixtures.h"
#include "vofusion/core/errors.h"
#include "vofusion/scene/scene_export.h"

using namespace vofusion;
using mrpt::poses::CPose3D;

namespace {

// A camera walking along +x inside the room at 1.4 m height, looking at the wall y = -1.5
// (optical z along -y world, y down along -z world: a z-up world as in TUM ground truth).
Trajectory roomPath(int n) {
  Trajectory t;
  for (int i = 0; i < n; ++i) {
    mrpt::math::CMatrixDouble44 T;
    T.setIdentity();
    // Columns: optical x, y, z axes in world.
    const Eigen::Matrix3d R = (Eigen::Matrix3d() << -1, 0, 0, 0, 0, -1, 0, -1, 0).finished();
    for (int r = 0; r < 3; ++r)
      for (int c = 0; c < 3; ++c) T(r, c) = R(r, c);
    T(0, 3) = -1.0 + 2.0 * i / std::max(1, n - 1);
    T(1, 3) = 0.5;
    T(2, 3) = 1.4;
    t.push_back({1000.0 + 0.033 * i, CPose3D::FromHomogeneousMatrix(T)});
  }
  return t;
}

template <typename T>
typename T::Ptr child(const mrpt::opengl::CSetOfObjects::Ptr& set, const std::string& name) {
  return std::dynamic_pointer_cast<T>(set->getByName(name));
}

}  // namespace

TEST(Scene, FrustumLooksAlongTheOpticalAxis) {
  const Trajectory t = roomPath(2);
  const CPose3D fp = frustumPose(t[0].pose);
  // The frustum's +x (its viewing direction) must be the camera's +z, its +z the camera's -y.
  double x, y, z;
  fp.composePoint(1, 0, 0, x, y, z);
  double ex, ey, ez;
  t[0].pose.composePoint(0, 0, 1, ex, ey, ez);
  EXPECT_NEAR(x, ex, 1e-9);
  EXPECT_NEAR(y, ey, 1e-9);
  EXPECT_NEAR(z, ez, 1e-9);
  fp.composePoint(0, 0, 1, x, y, z);
  t[0].pose.composePoint(0, -1, 0, ex, ey, ez);
  EXPECT_NEAR(x, ex, 1e-9);
  EXPECT_NEAR(y, ey, 1e-9);
  EXPECT_NEAR(z, ez, 1e-9);
  EXPECT_NEAR(z - t[0].pose.z(), 1.0, 1e-9);  // the camera's up is world up here
}

TEST(Scene, UpAxisFollowsThePath) {
  // An odometry path starting at the identity lives in the first optical frame: -y is up.
  Trajectory odo{{0.0, CPose3D()}, {1.0, CPose3D(0.1, 0, 0, 0, 0, 0)}};
  double x, y, z;
  sceneUpRotation(odo, nullptr, SceneOptions::Up::Auto).composePoint(0, -1, 0, x, y, z);
  EXPECT_NEAR(z, 1.0, 1e-9);
  sceneUpRotation(roomPath(3), nullptr, SceneOptions::Up::Auto).composePoint(0, 0, 1, x, y, z);
  EXPECT_NEAR(z, 1.0, 1e-9);
  // A run's smoothed path: the first centre moved by 0.2 mm, its orientation as tracked.
  Trajectory smoothed = odo;
  smoothed.front().pose = CPose3D(-0.000067, 0.000174, -0.000123, 0, 0, 0);
  sceneUpRotation(smoothed, nullptr, SceneOptions::Up::Auto).composePoint(0, -1, 0, x, y, z);
  EXPECT_NEAR(z, 1.0, 1e-9) << "a path in the first camera's frame whose start the smoother moved";
  // With a mesh, the floor decides: a room whose up is the first camera's (0, -cos 40, -sin 40)
  // (a camera pitched 40 deg down at the floor) is put upright.
  TriangleMesh room = test::boxRoom(4, 3, 2.5, 6);
  const Eigen::Vector3f true_up(0.f, -std::cos(0.698f), -std::sin(0.698f));
  const Eigen::Matrix3f R = Eigen::Quaternionf::FromTwoVectors(Eigen::Vector3f::UnitZ(), true_up).toRotationMatrix();
  for (auto& v : room.vertices) v = R * v;
  const CPose3D upr = sceneUpRotation(odo, &room, SceneOptions::Up::Auto);
  upr.composePoint(true_up.x(), true_up.y(), true_up.z(), x, y, z);
  EXPECT_NEAR(z, 1.0, 1e-4);
}

TEST(Scene, SavedSceneLoadsBackWithMeshPathsFrustumsAndGrid) {
  const TriangleMesh mesh = test::boxRoom(4, 3, 2.5, 6);
  const Trajectory est = roomPath(95);
  Trajectory gt = est;
  for (auto& p : gt) p.pose.x_incr(0.05);
  const std::string dir = test::tempDir("scene_export");
  const std::string file = dir + "/scene.3Dscene";
  SceneOptions opt;
  opt.frustum_every_k = 30;
  exportScene(file, mesh, est, &gt, CameraIntrinsics{}, opt);
  ASSERT_TRUE(std::filesystem::exists(file));
  EXPECT_EQ(std::distance(std::filesystem::directory_iterator(dir), {}), 1);  // no temporaries left

  mrpt::opengl::COpenGLScene loaded;
  ASSERT_TRUE(loaded.loadFromFile(file));
  auto world = std::dynamic_pointer_cast<mrpt::opengl::CSetOfObjects>(loaded.getByName("world"));
  ASSERT_TRUE(world);
  auto tris = child<mrpt::opengl::CSetOfTriangles>(world, "mesh");
  ASSERT_TRUE(tris);
  ASSERT_EQ(tris->getTrianglesCount(), mesh.faces.size());
  // Geometry and per-vertex colour of a triangle survive.
  mrpt::opengl::TTriangle t;
  tris->getTriangle(7, t);
  for (int k = 0; k < 3; ++k) {
    const auto& v = mesh.vertices[mesh.faces[7][k]];
    EXPECT_NEAR(t.x(k), v.x(), 1e-6);
    EXPECT_NEAR(t.z(k), v.z(), 1e-6);
    EXPECT_EQ(t.r(k), mesh.colors[mesh.faces[7][k]][0]);
    EXPECT_EQ(t.b(k), mesh.colors[mesh.faces[7][k]][2]);
  }
  auto path = child<mrpt::opengl::CSetOfLines>(world, "path");
  ASSERT_TRUE(path);
  ASSERT_EQ(path->getLineCount(), est.size() - 1);
  double x0, y0, z0, x1, y1, z1;
  path->getLineByIndex(10, x0, y0, z0, x1, y1, z1);
  EXPECT_NEAR(x0, est[10].pose.x(), 1e-5);
  EXPECT_NEAR(x1, est[11].pose.x(), 1e-5);
  EXPECT_NEAR(z1, est[11].pose.z(), 1e-5);
  auto gtl = child<mrpt::opengl::CSetOfLines>(world, "ground_truth");
  ASSERT_TRUE(gtl);
  EXPECT_EQ(gtl->getLineCount(), gt.size() - 1);
  auto frustums = child<mrpt::opengl::CSetOfObjects>(world, "frustums");
  ASSERT_TRUE(frustums);
  EXPECT_EQ(std::distance(frustums->begin(), frustums->end()), 4);  // frames 0, 30, 60, 90
  auto f0 = std::dynamic_pointer_cast<mrpt::opengl::CFrustum>(*frustums->begin());
  ASSERT_TRUE(f0);
  EXPECT_NEAR(f0->getPose().x, est[0].pose.x(), 1e-6);
  auto grid = std::dynamic_pointer_cast<mrpt::opengl::CGridPlaneXY>(loaded.getByName("grid"));
  ASSERT_TRUE(grid);
}

// A path in a survey frame (a million metres across) gets a grid of at most a thousand cells a side,
// not four million lines.
TEST(Scene, TheGroundGridStaysSmallUnderAHugeExtent) {
  Trajectory far;
  for (int i = 0; i < 3; ++i) far.push_back({double(i), mrpt::poses::CPose3D(-1e6 + 1e6 * i, 2e5 * i, 0, 0, 0, 0)});
  const auto scene = buildScene(TriangleMesh{}, far, nullptr, CameraIntrinsics{});
  const auto grid = std::dynamic_pointer_cast<mrpt::opengl::CGridPlaneXY>(scene->getByName("grid"));
  ASSERT_TRUE(grid);
  float x0, x1, y0, y1;
  grid->getPlaneLimits(x0, x1, y0, y1);
  EXPECT_LE((x1 - x0) / grid->getGridFrequency(), 1002.f);
  EXPECT_LE((y1 - y0) / grid->getGridFrequency(), 1002.f);
  // A few metres of path 9e6 m out (a survey frame's easting): a float there moves in steps of 1 m, so a
  // 0.5 m grid step never moved MRPT's line loop.
  Trajectory north;
  for (int i = 0; i < 3; ++i) north.push_back({double(i), mrpt::poses::CPose3D(9e6 + 3.0 * i, 0, 0, 0, 0, 0)});
  const auto northern = std::dynamic_pointer_cast<mrpt::opengl::CGridPlaneXY>(
      buildScene(TriangleMesh{}, north, nullptr, CameraIntrinsics{})->getByName("grid"));
  ASSERT_TRUE(northern);
  northern->getPlaneLimits(x0, x1, y0, y1);
  ASSERT_GT(std::max(std::abs(x0), std::abs(y0)), 8e6f) << "the grid is not where the test means it";
  EXPECT_GT(x0 + northern->getGridFrequency(), x0) << "a step that does not move the line loop";
  EXPECT_GE(northern->getGridFrequency(), 4 * (std::nextafter(9e6f, INFINITY) - 9e6f));
}

TEST(Scene, CullsTheSideFacingAwayFromTheCameras) {
  TriangleMesh mesh = test::boxRoom(4, 3, 2.5, 6);  // faces point inwards, where the cameras are
  const auto cull = [](const TriangleMesh& m, const Trajectory& t) {
    auto scene = buildScene(m, t, nullptr, CameraIntrinsics{});
    auto world = std::dynamic_pointer_cast<mrpt::opengl::CSetOfObjects>(scene->getByName("world"));
    return child<mrpt::opengl::CSetOfTriangles>(world, "mesh")->cullFaces();
  };
  EXPECT_EQ(cull(mesh, roomPath(20)), mrpt::opengl::TCullFace::BACK);
  EXPECT_EQ(cull(mesh, Trajectory{}), mrpt::opengl::TCullFace::NONE);
  // Wound away from the cameras (another tool's PLY): turned to face them, lit on the side shown (MRPT's
  // shader lights the side a normal points to; culling the front left the floor dark).
  for (auto& f : mesh.faces) std::swap(f[1], f[2]);
  EXPECT_EQ(cull(mesh, roomPath(20)), mrpt::opengl::TCullFace::BACK);
  auto world = std::dynamic_pointer_cast<mrpt::opengl::CSetOfObjects>(
      buildScene(mesh, roomPath(20), nullptr, CameraIntrinsics{})->getByName("world"));
  const auto tris = child<mrpt::opengl::CSetOfTriangles>(world, "mesh");
  ASSERT_EQ(tris->getTrianglesCount(), mesh.faces.size());
  std::size_t floor = 0;
  for (std::size_t i = 0; i < tris->getTrianglesCount(); ++i) {
    mrpt::opengl::TTriangle t;
    tris->getTriangle(i, t);
    if (std::max({t.z(0), t.z(1), t.z(2)}) > 1e-6f) continue;
    ++floor;
    const mrpt::math::TVector3Df e1 = t.vertex(1) - t.vertex(0), e2 = t.vertex(2) - t.vertex(0);
    EXPECT_GT(e1.x * e2.y - e1.y * e2.x, 0.f) << "floor face " << i << " wound to face down";
    for (int k = 0; k < 3; ++k) EXPECT_GT(t.vertices[k].normal.z, 0.f) << "floor face " << i;  // up, to the cameras
  }
  EXPECT_GT(floor, 10u);
}

// A mesh of more faces than one MRPT object's GL buffer holds (its size an int of bytes: 19.9 M faces)
// is drawn as several objects, every face in one of them.
TEST(Scene, AMeshOfManyFacesIsDrawnAsSeveralObjects) {
  EXPECT_LE(SceneOptions{}.triangles_per_object * sizeof(mrpt::opengl::TTriangle), std::size_t(INT_MAX));
  const TriangleMesh mesh = test::boxRoom(4, 3, 2.5, 6);  // 360 faces
  SceneOptions opt;
  opt.triangles_per_object = 100;
  auto world = std::dynamic_pointer_cast<mrpt::opengl::CSetOfObjects>(
      buildScene(mesh, roomPath(20), nullptr, CameraIntrinsics{}, opt)->getByName("world"));
  std::size_t faces = 0;
  for (const char* name : {"mesh", "mesh.1", "mesh.2", "mesh.3"}) {
    const auto part = child<mrpt::opengl::CSetOfTriangles>(world, name);
    ASSERT_TRUE(part) << name;
    EXPECT_LE(part->getTrianglesCount(), 100u) << name;
    EXPECT_EQ(part->cullFaces(), mrpt::opengl::TCullFace::BACK) << name;
    faces += part->getTrianglesCount();
  }
  EXPECT_EQ(faces, mesh.faces.size());
  EXPECT_FALSE(world->getByName("mesh.4"));
}

// mesh.png looks in from above: the ceiling is left out (seen from above only its culled back side
// and a few noisy faces would show, as specks), walls and floor stay.
TEST(Scene, PictureLeavesOutTheCeilingOnly) {
  TriangleMesh room = test::boxRoom(4, 3, 2.5, 6);  // floor z = 0, walls up to 2.5 m, cameras at 1.4 m
  const auto base = std::uint32_t(room.vertices.size());  // and a ceiling at 2.5 m, facing down
  for (int j = 0; j <= 6; ++j)
    for (int i = 0; i <= 6; ++i) room.vertices.emplace_back(-2.f + 4.f * float(j) / 6, -1.5f + 3.f * float(i) / 6, 2.5f);
  room.colors.resize(room.vertices.size(), room.colors.front());
  for (std::uint32_t j = 0; j < 6; ++j)
    for (std::uint32_t i = 0; i < 6; ++i) {
      const std::uint32_t a = base + j * 7 + i, b = a + 1, c = a + 7, d = c + 1;
      room.faces.push_back({a, b, d});
      room.faces.push_back({a, d, c});
    }
  const auto top = [](const TriangleMesh& m, const std::array<std::uint32_t, 3>& f) {
    return std::max({m.vertices[f[0]].z(), m.vertices[f[1]].z(), m.vertices[f[2]].z()});
  };
  const auto bottom = [](const TriangleMesh& m, const std::array<std::uint32_t, 3>& f) {
    return std::min({m.vertices[f[0]].z(), m.vertices[f[1]].z(), m.vertices[f[2]].z()});
  };
  const std::optional<TriangleMesh> cut = withoutCeiling(room, roomPath(20), CPose3D());
  ASSERT_TRUE(cut.has_value());
  const TriangleMesh& shown = *cut;
  std::size_t low = 0, ceiling = 0;
  for (const auto& f : room.faces) low += top(room, f) < 2.0f, ceiling += bottom(room, f) > 2.49f;
  ASSERT_GT(ceiling, 10u);
  std::size_t shown_low = 0;
  for (const auto& f : shown.faces) {
    EXPECT_LT(top(shown, f), 2.45f);
    shown_low += top(shown, f) < 2.0f;
  }
  EXPECT_EQ(shown_low, low);  // everything below 2 m stays
  // No path, or no ceiling above the cameras: nothing is left out.
  EXPECT_FALSE(withoutCeiling(room, Trajectory{}, CPose3D()).has_value());
  TriangleMesh open_top = room;
  open_top.faces.clear();
  for (const auto& f : room.faces)
    if (bottom(room, f) < 2.49f) open_top.faces.push_back(f);
  EXPECT_FALSE(withoutCeiling(open_top, roomPath(20), CPose3D()).has_value());
  // A robot's low camera (0.3 m) under a table (1 m^2 facing down at 0.7 m), no ceiling seen: the
  // table is no ceiling, and cutting there left out most of the walls. A cut that leaves out mostly
  // faces not facing down is none.
  Trajectory low_path = roomPath(20);
  for (auto& p : low_path) p.pose.z(0.3);
  const auto table = std::uint32_t(open_top.vertices.size());
  for (int j = 0; j <= 4; ++j)
    for (int i = 0; i <= 4; ++i) open_top.vertices.emplace_back(-0.5f + 0.25f * float(j), -0.5f + 0.25f * float(i), 0.7f);
  open_top.colors.resize(open_top.vertices.size(), open_top.colors.front());
  for (std::uint32_t j = 0; j < 4; ++j)
    for (std::uint32_t i = 0; i < 4; ++i) {
      const std::uint32_t a = table + j * 5 + i, b = a + 1, c = a + 5, d = c + 1;
      open_top.faces.push_back({a, b, d});  // facing down, as the ceiling's
      open_top.faces.push_back({a, d, c});
    }
  EXPECT_FALSE(withoutCeiling(open_top, low_path, CPose3D()).has_value());
}

// The warm-up (the driver loaded and a throwaway render, on a thread of its own) changes nothing a
// render after it draws. As in a run (ctest runs each test in a process of its own), the warm-up is the
// process's first EGL start-up, and the picture is rendered on another thread after it: the same
// picture as a render after that one.
TEST(Scene, ARenderAfterTheWarmUpDrawsTheSamePicture) {
  const TriangleMesh mesh = test::boxRoom(4, 3, 2.5, 6);
  const Trajectory est = roomPath(40);
  const std::string dir = test::tempDir("scene_warm_up");
  { OffscreenRenderWarmUp warm_up; }
  std::async(std::launch::async, [&] { renderMeshPng(dir + "/after_warm_up.png", mesh, &est, 320, 240); }).get();
  renderMeshPng(dir + "/again.png", mesh, &est, 320, 240);
  const cv::Mat first = cv::imread(dir + "/after_warm_up.png", cv::IMREAD_COLOR);
  const cv::Mat again = cv::imread(dir + "/again.png", cv::IMREAD_COLOR);
  ASSERT_FALSE(first.empty());
  ASSERT_EQ(first.size(), again.size());
  EXPECT_EQ(cv::norm(first, again, cv::NORM_INF), 0.0);
  double lo, hi;
  cv::minMaxLoc(first.reshape(1), &lo, &hi);
  EXPECT_LT(lo, 150);  // the room drawn, not a blank picture twice
}

// OpenGL hands rows back padded to 4 bytes: at a width whose row is not (322 px: 966 bytes), the
// picture came out sheared. The field of view is vertical, so a picture 2 px wider is the narrower one
// with a column more on either side.
TEST(Scene, APictureOfAnyWidthIsTheSameViewWiderOrNarrower) {
  const TriangleMesh mesh = test::boxRoom(4, 3, 2.5, 6);
  const Trajectory est = roomPath(40);
  const std::string dir = test::tempDir("scene_odd_width");
  renderMeshPng(dir + "/320.png", mesh, &est, 320, 240);
  renderMeshPng(dir + "/322.png", mesh, &est, 322, 240);
  const cv::Mat narrow = cv::imread(dir + "/320.png", cv::IMREAD_COLOR);
  const cv::Mat wide = cv::imread(dir + "/322.png", cv::IMREAD_COLOR);
  ASSERT_EQ(narrow.size(), cv::Size(320, 240));
  ASSERT_EQ(wide.size(), cv::Size(322, 240));
  cv::Mat difference, differs;
  cv::absdiff(wide(cv::Rect(1, 0, 320, 240)), narrow, difference);
  cv::compare(difference.reshape(1), 24, differs, cv::CMP_GT);
  EXPECT_LT(cv::countNonZero(differs), 240 * 320 * 3 / 100);  // rasterisation ties at most
}

TEST(Scene, UnwritablePathIsAnInputErrorNamingIt) {
  const std::string path = "/nonexistent-dir/x/scene.3Dscene";
  try {
    exportScene(path, test::boxRoom(), roomPath(3), nullptr, CameraIntrinsics{});
    FAIL() << "wrote " << path;
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), path);  // not the temporary it was being written to
  }
}

TEST(Scene, RendersMeshToANonBlankPng) {
  const TriangleMesh mesh = test::boxRoom(4, 3, 2.5, 6);
  const Trajectory est = roomPath(40);
  const std::string dir = test::tempDir("scene_png");
  const std::string png = dir + "/mesh.png";
  renderMeshPng(png, mesh, &est, 320, 240);
  const cv::Mat img = cv::imread(png, cv::IMREAD_COLOR);
  ASSERT_FALSE(img.empty());
  EXPECT_EQ(img.cols, 320);
  EXPECT_EQ(img.rows, 240);
  // Background is white; the room must cover a good part of the picture, in several colours.
  int covered = 0;
  std::set<int> colours;  // of the covered pixels, 32 levels a channel apart
  for (int r = 0; r < img.rows; ++r)
    for (int c = 0; c < img.cols; ++c) {
      const cv::Vec3b p = img.at<cv::Vec3b>(r, c);
      if (p[0] < 235 || p[1] < 235 || p[2] < 235) {
        ++covered;
        colours.insert(p[0] / 32 * 64 + p[1] / 32 * 8 + p[2] / 32);
      }
    }
  EXPECT_GT(covered, img.rows * img.cols / 5);
  EXPECT_GE(colours.size(), 6u);  // the mesh's colours, not one shade of grey
  double mn, mx;
  cv::minMaxLoc(img.reshape(1), &mn, &mx);
  EXPECT_LT(mn, 150);  // not a flat image
}
