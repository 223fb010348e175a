// The reconstruction as an MRPT COpenGLScene: coloured mesh, camera paths, frustums, ground grid.
#include "vofusion/scene/scene_export.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Dense>
#include <mrpt/math/CMatrixFixed.h>
#include <mrpt/opengl/CFrustum.h>
#include <mrpt/opengl/CGridPlaneXY.h>
#include <mrpt/opengl/CSetOfLines.h>
#include <mrpt/opengl/CSetOfObjects.h>
#include <mrpt/opengl/CSetOfTriangles.h>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/errors.h"

namespace vofusion {

using mrpt::poses::CPose3D;

mrpt::poses::CPose3D sceneUpRotation(const Trajectory& path, SceneOptions::Up up) {
  if (up == SceneOptions::Up::Auto) {
    up = SceneOptions::Up::PlusZ;
    if (!path.empty()) {
      const auto v = path.front().pose.asVectorVal();  // x y z yaw pitch roll
      if (v.norm() < 1e-6) up = SceneOptions::Up::MinusY;
    }
  }
  // A roll of -90 deg about x takes -y to +z (and the camera's forward z to +y).
  return up == SceneOptions::Up::MinusY ? CPose3D(0, 0, 0, 0, 0, -M_PI / 2) : CPose3D();
}

mrpt::poses::CPose3D frustumPose(const mrpt::poses::CPose3D& camera_to_world) {
  // Columns: the frustum's axes (x forward, y left, z up) in the optical frame (x right, y down, z forward).
  mrpt::math::CMatrixDouble44 body_in_optical;
  body_in_optical.setZero();
  body_in_optical(0, 1) = -1;
  body_in_optical(1, 2) = -1;
  body_in_optical(2, 0) = 1;
  body_in_optical(3, 3) = 1;
  return camera_to_world + CPose3D::FromHomogeneousMatrix(body_in_optical);
}

static mrpt::opengl::CSetOfLines::Ptr pathLines(const Trajectory& t, const std::string& name,
                                                mrpt::img::TColor colour) {
  auto lines = mrpt::opengl::CSetOfLines::Create();
  lines->setName(name);
  lines->setColor_u8(colour);
  lines->setLineWidth(2.5f);
  for (std::size_t i = 1; i < t.size(); ++i) {
    const auto& a = t[i - 1].pose;
    const auto& b = t[i].pose;
    lines->appendLine(a.x(), a.y(), a.z(), b.x(), b.y(), b.z());
  }
  return lines;
}

static mrpt::opengl::CSetOfTriangles::Ptr meshTriangles(const TriangleMesh& mesh) {
  std::vector<mrpt::opengl::TTriangle> tris(mesh.faces.size());
  const bool colours = mesh.colors.size() == mesh.vertices.size();
  const bool normals = mesh.normals.size() == mesh.vertices.size();
#pragma omp parallel for schedule(static)
  for (std::ptrdiff_t f = 0; f < std::ptrdiff_t(mesh.faces.size()); ++f) {
    auto& t = tris[f];
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t i = mesh.faces[f][k];
      const auto& p = mesh.vertices[i];
      t.vertex(k) = mrpt::math::TPoint3Df(p.x(), p.y(), p.z());
      t.vertices[k].setColor(colours ? mrpt::img::TColor(mesh.colors[i][0], mesh.colors[i][1], mesh.colors[i][2])
                                     : mrpt::img::TColor(170, 170, 170));
    }
    if (normals)
      for (int k = 0; k < 3; ++k) {
        const auto& n = mesh.normals[mesh.faces[f][k]];
        t.vertices[k].normal = mrpt::math::TVector3Df(n.x(), n.y(), n.z());
      }
    else
      t.computeNormals();
  }
  auto obj = mrpt::opengl::CSetOfTriangles::Create();
  obj->setName("mesh");
  obj->insertTriangles(tris.begin(), tris.end());
  return obj;
}

// +1 when the faces (counter-clockwise = front) mostly face the cameras, -1 when they mostly face
// away, 0 when undecided. Each face votes with its area for the nearest of up to 32 camera centres.
static int frontFacesCameras(const TriangleMesh& mesh, const Trajectory& path) {
  if (path.empty() || mesh.faces.empty()) return 0;
  std::vector<Eigen::Vector3f> cams;
  const std::size_t step = std::max<std::size_t>(1, path.size() / 32);
  for (std::size_t i = 0; i < path.size(); i += step)
    cams.emplace_back(float(path[i].pose.x()), float(path[i].pose.y()), float(path[i].pose.z()));
  double vote = 0, total = 0;
#pragma omp parallel for reduction(+ : vote, total) schedule(static)
  for (std::ptrdiff_t f = 0; f < std::ptrdiff_t(mesh.faces.size()); ++f) {
    const auto& a = mesh.vertices[mesh.faces[f][0]];
    const auto& b = mesh.vertices[mesh.faces[f][1]];
    const auto& c = mesh.vertices[mesh.faces[f][2]];
    const Eigen::Vector3f n = (b - a).cross(c - a);  // length = 2 * area
    const Eigen::Vector3f centre = (a + b + c) / 3;
    const Eigen::Vector3f* best = &cams[0];
    for (const auto& cam : cams)
      if ((cam - centre).squaredNorm() < (*best - centre).squaredNorm()) best = &cam;
    const Eigen::Vector3f to_cam = *best - centre;
    vote += n.dot(to_cam) > 0 ? n.norm() : -n.norm();
    total += n.norm();
  }
  if (total <= 0 || std::abs(vote) < 0.2 * total) return 0;
  return vote > 0 ? 1 : -1;
}

std::shared_ptr<mrpt::opengl::COpenGLScene> buildScene(const TriangleMesh& mesh, const Trajectory& path_est,
                                                        const Trajectory* ground_truth, const CameraIntrinsics& cam,
                                                        const SceneOptions& opt) {
  auto scene = std::make_shared<mrpt::opengl::COpenGLScene>();
  const CPose3D up = sceneUpRotation(path_est.empty() && ground_truth ? *ground_truth : path_est, opt.up);

  auto world = mrpt::opengl::CSetOfObjects::Create();
  world->setName("world");
  world->setPose(up);
  if (!mesh.empty()) {
    auto tris = meshTriangles(mesh);
    if (opt.cull_hidden_side) {
      const int side = frontFacesCameras(mesh, path_est);
      if (side != 0) tris->cullFaces(side > 0 ? mrpt::opengl::TCullFace::BACK : mrpt::opengl::TCullFace::FRONT);
    }
    world->insert(tris);
    if (!mesh.colors.empty()) {
      // The colours already carry the scene's shading: light softly so they read true.
      auto& light = scene->getViewport()->lightParameters();
      light.ambient = mrpt::img::TColorf(0.6f, 0.6f, 0.6f, 1.f);
      light.diffuse = mrpt::img::TColorf(0.5f, 0.5f, 0.5f, 1.f);
      light.specular = mrpt::img::TColorf(0.f, 0.f, 0.f, 1.f);
    }
  }
  if (!path_est.empty()) world->insert(pathLines(path_est, "path", mrpt::img::TColor(20, 60, 230)));
  if (ground_truth && !ground_truth->empty())
    world->insert(pathLines(*ground_truth, "ground_truth", mrpt::img::TColor(20, 170, 40)));
  if (opt.frustum_every_k > 0 && !path_est.empty()) {
    auto frustums = mrpt::opengl::CSetOfObjects::Create();
    frustums->setName("frustums");
    const double hfov = 2 * std::atan(0.5 * cam.width / cam.fx) * 180 / M_PI;
    const double vfov = 2 * std::atan(0.5 * cam.height / cam.fy) * 180 / M_PI;
    for (std::size_t i = 0; i < path_est.size(); i += std::size_t(opt.frustum_every_k)) {
      auto f = mrpt::opengl::CFrustum::Create(0.005f, float(opt.frustum_depth), float(hfov), float(vfov), 1.5f, true,
                                              false);
      f->setColor_u8(mrpt::img::TColor(230, 60, 20));
      f->setPose(frustumPose(path_est[i].pose));
      frustums->insert(f);
    }
    world->insert(frustums);
  }
  scene->insert(world);

  // Extent of everything in the z-up display frame, for the grid and the default camera.
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(1e30), hi = -lo;
  const auto grow = [&](double x, double y, double z) {
    double gx, gy, gz;
    up.composePoint(x, y, z, gx, gy, gz);
    lo = lo.cwiseMin(Eigen::Vector3d(gx, gy, gz));
    hi = hi.cwiseMax(Eigen::Vector3d(gx, gy, gz));
  };
  for (const auto& v : mesh.vertices) grow(v.x(), v.y(), v.z());
  for (const auto& p : path_est) grow(p.pose.x(), p.pose.y(), p.pose.z());
  if (ground_truth)
    for (const auto& p : *ground_truth) grow(p.pose.x(), p.pose.y(), p.pose.z());
  if (lo.x() > hi.x()) lo = hi = Eigen::Vector3d::Zero();

  if (opt.grid) {
    const double s = opt.grid_spacing > 0 ? opt.grid_spacing : 0.5;
    const auto down = [s](double v) { return std::floor(v / s) * s - s; };
    const auto upr = [s](double v) { return std::ceil(v / s) * s + s; };
    auto grid = mrpt::opengl::CGridPlaneXY::Create(float(down(lo.x())), float(upr(hi.x())), float(down(lo.y())),
                                                   float(upr(hi.y())), float(lo.z() - 0.02 - 0.01 * (hi - lo).norm()), float(s), 1.0f);
    grid->setName("grid");
    grid->setColor_u8(mrpt::img::TColor(150, 150, 150, 160));
    scene->insert(grid);
  }

  auto& camera = scene->getViewport()->getCamera();
  const Eigen::Vector3d centre = 0.5 * (lo + hi);
  camera.setPointingAt(float(centre.x()), float(centre.y()), float(centre.z()));
  camera.setZoomDistance(float(std::max(1.0, 1.8 * (hi - lo).norm())));
  camera.setAzimuthDegrees(-135.f);
  camera.setElevationDegrees(35.f);
  return scene;
}

void exportScene(const std::string& path, const TriangleMesh& mesh, const Trajectory& path_est,
                 const Trajectory* ground_truth, const CameraIntrinsics& cam, const SceneOptions& opt) {
  const auto scene = buildScene(mesh, path_est, ground_truth, cam, opt);
  AtomicPath out(path);
  if (!scene->saveToFile(out.tmp())) throw InputError(path, "cannot write the 3D scene");
  out.commit();
}

}  // namespace vofusion
