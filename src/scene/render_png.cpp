// Off-screen rendering of the mesh with MRPT's CFBORender (EGL; works without a display).
#include <algorithm>
#include <cmath>
#include <map>
#include <system_error>
#include <vector>

#include <Eigen/Dense>
#include <mrpt/img/CImage.h>
#include <mrpt/opengl/CFBORender.h>
#include <mrpt/opengl/CSetOfTriangles.h>
#include <opencv2/imgcodecs.hpp>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/errors.h"
#include "vofusion/scene/scene_export.h"

namespace vofusion {

// The picture looks in from above, so a ceiling goes, as in a dollhouse view. Drawn from above it
// shows only its back side, which the scene culls, and what is left (faces whose normals noise
// turned up, the fringe where it meets the walls) shows as specks over the room. The ceiling: the
// height above the highest camera where the most downward-facing area lies (5 cm bins), if that is
// at least 0.5 m^2; everything from 10 cm below it up is left out of the picture.
std::optional<TriangleMesh> withoutCeiling(const TriangleMesh& mesh, const Trajectory& path, const mrpt::poses::CPose3D& up) {
  if (path.empty() || mesh.faces.empty()) return std::nullopt;
  const Eigen::Matrix3d R = up.getRotationMatrix().asEigen();
  const Eigen::Vector3d z = R.row(2).transpose();  // the display's up axis in the map's frame
  double top = -1e30;
  for (const auto& p : path) top = std::max(top, z.dot(Eigen::Vector3d(p.pose.x(), p.pose.y(), p.pose.z())));
  constexpr double kBin = 0.05;
  std::map<long, double> down_area;  // per height bin above the cameras
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3d a = mesh.vertices[f[0]].cast<double>(), b = mesh.vertices[f[1]].cast<double>(),
                          c = mesh.vertices[f[2]].cast<double>();
    const Eigen::Vector3d n = (b - a).cross(c - a);  // |n| = twice the area
    const double h = z.dot(a + b + c) / 3;
    if (h > top && z.dot(n) < -0.7 * n.norm()) down_area[std::lround(std::floor(h / kBin))] += 0.5 * n.norm();
  }
  const auto ceiling = std::max_element(down_area.begin(), down_area.end(),
                                        [](const auto& x, const auto& y) { return x.second < y.second; });
  if (ceiling == down_area.end() || ceiling->second < 0.5) return std::nullopt;
  const double cut = double(ceiling->first) * kBin - 0.1;
  TriangleMesh out;
  out.vertices = mesh.vertices;  // faces left out keep their vertices: unused ones draw nothing
  out.normals = mesh.normals;
  out.colors = mesh.colors;
  double removed = 0.0, removed_down = 0.0;
  for (const auto& f : mesh.faces) {
    bool below = true;
    for (std::uint32_t i : f) below = below && z.dot(mesh.vertices[i].cast<double>()) < cut;
    if (below) {
      out.faces.push_back(f);
      continue;
    }
    const Eigen::Vector3d n = (mesh.vertices[f[1]] - mesh.vertices[f[0]]).cross(mesh.vertices[f[2]] - mesh.vertices[f[0]]).cast<double>();
    removed += 0.5 * n.norm();
    if (z.dot(n) < -0.7 * n.norm()) removed_down += 0.5 * n.norm();
  }
  // A ceiling takes itself and a fringe of wall: what a cut leaves out is mostly facing down. A table
  // above a robot's low camera (no ceiling seen) took most of the walls out of the picture.
  if (removed_down < 0.5 * removed) return std::nullopt;
  return out;
}

namespace {

// Axis-aligned box in the z-up display frame.
struct Bounds {
  Eigen::Vector3d lo, hi;
};

// Frame the bulk of the mesh (2nd to 98th percentile per axis), not its stray fragments, and the
// camera path; the path alone when there is no mesh.
Bounds framedBounds(const TriangleMesh& mesh, const Trajectory& traj, const mrpt::poses::CPose3D& up) {
  std::vector<double> axis[3];
  const auto add = [&](double x, double y, double z) {
    double g[3];
    up.composePoint(x, y, z, g[0], g[1], g[2]);
    for (int k = 0; k < 3; ++k) axis[k].push_back(g[k]);
  };
  for (const auto& v : mesh.vertices) add(v.x(), v.y(), v.z());
  if (mesh.vertices.empty())
    for (const auto& p : traj) add(p.pose.x(), p.pose.y(), p.pose.z());
  Eigen::Vector3d lo = Eigen::Vector3d::Zero(), hi = Eigen::Vector3d::Zero();
  for (int k = 0; k < 3 && !axis[k].empty(); ++k) {
    auto& a = axis[k];
    const auto at = [&a](double q) {
      auto it = a.begin() + std::ptrdiff_t(q * double(a.size() - 1));
      std::nth_element(a.begin(), it, a.end());
      return *it;
    };
    lo[k] = at(0.02);
    hi[k] = at(0.98);
  }
  if (!mesh.vertices.empty())  // keep the camera path in the picture too
    for (const auto& p : traj) {
      double g[3];
      up.composePoint(p.pose.x(), p.pose.y(), p.pose.z(), g[0], g[1], g[2]);
      lo = lo.cwiseMin(Eigen::Vector3d(g[0], g[1], g[2]));
      hi = hi.cwiseMax(Eigen::Vector3d(g[0], g[1], g[2]));
    }
  return {lo, hi};
}

// The cameras' mean viewing direction projected on the ground (display frame), unit length;
// diagonal when there are no cameras or they look straight down.
Eigen::Vector2d meanGroundForward(const Trajectory& traj, const mrpt::poses::CPose3D& up) {
  Eigen::Vector2d forward(1, 1);
  if (!traj.empty()) {
    Eigen::Vector3d f = Eigen::Vector3d::Zero();
    for (const auto& p : traj) {
      const auto R = (up + p.pose).getRotationMatrix();
      f += Eigen::Vector3d(R(0, 2), R(1, 2), R(2, 2));  // optical axis in the display frame
    }
    if (f.head<2>().norm() > 1e-6) forward = f.head<2>();
  }
  forward.normalize();
  return forward;
}

// Looks at the centre of `b` from 40 deg above and behind the cameras, far enough back for all of
// it to fit a width x height picture.
void aimCamera(mrpt::opengl::COpenGLScene& scene, const Bounds& b, const Eigen::Vector2d& forward, int width,
               int height) {
  const Eigen::Vector3d centre = 0.5 * (b.lo + b.hi);
  const double radius = std::max(0.05, 0.5 * (b.hi - b.lo).norm());
  const float fov_deg = 45.f;
  auto& cam = scene.getViewport()->getCamera();
  cam.setProjectiveFOVdeg(fov_deg);
  cam.setPointingAt(float(centre.x()), float(centre.y()), float(centre.z()));
  // The eye sits opposite to where the cameras look (azimuth is measured from the target to the eye).
  cam.setAzimuthDegrees(float(std::atan2(-forward.y(), -forward.x()) * 180 / M_PI));
  cam.setElevationDegrees(40.f);
  const double aspect = std::min(1.0, double(width) / height);
  const double distance = 0.85 * radius / std::sin(0.5 * fov_deg * M_PI / 180) / aspect;
  cam.setZoomDistance(float(distance));
  // Tight clip planes: the default near plane (1 cm) leaves too little depth resolution at a few
  // metres and lets the grid under the floor show through it.
  scene.getViewport()->setViewportClipDistances(float(std::max(0.05, 0.1 * distance)), float(distance + 20 * radius));
}

// Renders the scene off-screen through its viewport's camera and writes it to `png`.
void writeRenderedPng(const std::string& png, mrpt::opengl::COpenGLScene& scene, int width, int height) {
  const auto& cam = scene.getViewport()->getCamera();
  // CFBORender reads the pixels back at OpenGL's default row alignment (4 bytes) into an image with
  // packed rows: a width whose 3 bytes a pixel are not a multiple of 4 came out sheared, and its last
  // rows were written past the image. Rendered a few columns wider (the field of view is vertical:
  // they only add at the sides) and cut back to the width asked for, centred.
  const int rendered_width = (width + 3) / 4 * 4;
  mrpt::img::CImage img;
  try {
    mrpt::opengl::CFBORender fbo(static_cast<unsigned>(rendered_width), static_cast<unsigned>(height));
    fbo.setCamera(scene, cam);
    fbo.render_RGB(scene, img);
  } catch (const std::exception& e) {
    throw InputError(png, "off-screen rendering failed (no OpenGL device?): " + oneLineMessage(e));
  }
  cv::Mat m = img.asCvMat<cv::Mat>(mrpt::img::SHALLOW_COPY);
  if (m.cols == rendered_width && m.rows == height) m = m(cv::Rect((rendered_width - width) / 2, 0, width, height));
  std::vector<uchar> bytes;
  if (m.cols != width || m.rows != height || !cv::imencode(".png", m, bytes))
    throw InputError(png, "cannot encode the rendered image");
  writeFileAtomically(png, std::string(bytes.begin(), bytes.end()));
}

}  // namespace

void renderMeshPng(const std::string& png, const TriangleMesh& mesh, const Trajectory* path, int width, int height,
                   const std::optional<Eigen::Vector3d>& up_vector) {
  if (width < 16 || height < 16 || width > 8192 || height > 8192)
    throw InputError(png, "unreasonable image size " + std::to_string(width) + "x" + std::to_string(height));
  const Trajectory empty;
  const Trajectory& traj = path ? *path : empty;
  SceneOptions opt;
  opt.frustum_every_k = 0;
  opt.up_vector = up_vector;
  // Look at the centre of the mesh (or of the path) from above and behind the cameras: azimuth
  // along the cameras' mean viewing direction projected on the ground, 40 deg elevation.
  const mrpt::poses::CPose3D up = sceneUpRotation(traj, &mesh, opt.up, opt.up_vector);
  // The scene is drawn with this "up": judged again on the mesh without its ceiling, it could differ
  // from the one the picture is framed and cut by (and the plane search ran twice).
  opt.up_vector = up.getRotationMatrix().asEigen().row(2).transpose();
  const std::optional<TriangleMesh> cut = withoutCeiling(mesh, traj, up);  // a copy only when there is a ceiling
  const auto scene = buildScene(cut ? *cut : mesh, traj, nullptr, CameraIntrinsics{}, opt);
  scene->getViewport()->setCustomBackgroundColor(mrpt::img::TColorf(1.f, 1.f, 1.f));
  const Bounds bounds = framedBounds(mesh, traj, up);
  const Eigen::Vector2d forward = meanGroundForward(traj, up);
  aimCamera(*scene, bounds, forward, width, height);
  writeRenderedPng(png, *scene, width, height);
}

namespace {
void renderOneTriangle() {
  try {
    mrpt::opengl::CFBORender fbo(16, 16);
    mrpt::opengl::COpenGLScene scene;
    auto triangle = mrpt::opengl::CSetOfTriangles::Create();
    mrpt::opengl::TTriangle t;
    t.vertex(1) = {1.f, 0.f, 0.f};
    t.vertex(2) = {0.f, 1.f, 0.f};
    triangle->insertTriangle(t);
    scene.insert(triangle);
    mrpt::img::CImage img;
    fbo.render_RGB(scene, img);
  } catch (...) {  // no OpenGL device: renderMeshPng says so
  }
}
}  // namespace

OffscreenRenderWarmUp::OffscreenRenderWarmUp() {
  try {
    thread_ = std::thread(renderOneTriangle);
  } catch (const std::system_error&) {  // no thread to be had: the picture starts cold, the run goes on
  }
}

OffscreenRenderWarmUp::~OffscreenRenderWarmUp() {
  if (thread_.joinable()) thread_.join();
}

}  // namespace vofusion
