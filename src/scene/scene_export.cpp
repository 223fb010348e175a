// The reconstruction as an MRPT COpenGLScene: coloured mesh, camera paths, frustums, ground grid.
#include "vofusion/scene/scene_export.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Dense>
#include <mrpt/math/CMatrixFixed.h>
#include <mrpt/opengl/CFrustum.h>
#include <mrpt/opengl/CGridPlaneXY.h>
#include <mrpt/opengl/CPointCloud.h>
#include <mrpt/opengl/CSetOfLines.h>
#include <mrpt/opengl/CSetOfObjects.h>
#include <mrpt/opengl/CSetOfTriangles.h>
#include <mrpt/serialization/CArchive.h>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/parallel.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/gzip_members.h"

namespace vofusion {

using mrpt::poses::CPose3D;

// A path in the first camera's optical frame starts with its orientation (a run's map is that frame).
// 1e-4 rad: well above trajectory.txt's rounding, far below any mocap frame's chance alignment.
static bool startsUnrotated(const CPose3D& first) {
  return Eigen::AngleAxisd(Eigen::Matrix3d(first.getRotationMatrix().asEigen())).angle() < 1e-4;
}

// The normal of the largest surface facing within 60 deg of `up` (faces face the cameras, so a
// floor's or table's normal points up): among a sample of face normals, the one with the most face
// area within 10 deg of it, then refined by the area-weighted mean of all normals within 10 deg.
static Eigen::Vector3d dominantPlaneNormal(const TriangleMesh& mesh, const Eigen::Vector3d& up) {
  struct Sample {
    Eigen::Vector3d n;  // unit
    double area;
  };
  const auto normalOf = [&mesh](std::size_t f) {
    const auto& a = mesh.vertices[mesh.faces[f][0]];
    return Eigen::Vector3d(
        (mesh.vertices[mesh.faces[f][1]] - a).cross(mesh.vertices[mesh.faces[f][2]] - a).cast<double>());
  };
  const double cos_cone = std::cos(60.0 * M_PI / 180), cos_near = std::cos(10.0 * M_PI / 180);
  std::vector<Sample> samples;
  const std::size_t step = std::max<std::size_t>(1, mesh.faces.size() / 4000);
  for (std::size_t f = 0; f < mesh.faces.size(); f += step) {
    const Eigen::Vector3d n = normalOf(f);
    const double len = n.norm();
    if (len > 0 && n.dot(up) > cos_cone * len) samples.push_back({n / len, 0.5 * len});
  }
  if (samples.empty()) return up;
  std::vector<double> score(samples.size(), 0.0);
  parallelFor(0, int(samples.size()), [&](int i) {
    for (const auto& s : samples)
      if (s.n.dot(samples[i].n) > cos_near) score[i] += s.area;
  }, 64);
  Eigen::Vector3d best = samples[std::max_element(score.begin(), score.end()) - score.begin()].n;
  for (int it = 0; it < 3; ++it) {
    const Eigen::Vector3d m = parallelReduce(
        0, int(mesh.faces.size()), Eigen::Vector3d(Eigen::Vector3d::Zero()),
        [&](int f, Eigen::Vector3d& sum) {
          const Eigen::Vector3d n = normalOf(std::size_t(f));  // length = 2 * area: area-weighted
          if (n.dot(best) > cos_near * n.norm()) sum += n;
        },
        [](Eigen::Vector3d& a, const Eigen::Vector3d& b) { a += b; }, 4096);
    if (m.norm() > 0) best = m.normalized();
  }
  return best;
}

mrpt::poses::CPose3D sceneUpRotation(const Trajectory& path, const TriangleMesh* mesh, SceneOptions::Up up,
                                     const std::optional<Eigen::Vector3d>& up_vector) {
  bool camera_frame = up == SceneOptions::Up::MinusY;
  // Judged by the first orientation alone: the path smoother moves every centre, the first included
  // (by ~0.2 mm), and keeps the orientations as tracked.
  if (up == SceneOptions::Up::Auto) camera_frame = !path.empty() && startsUnrotated(path.front().pose);
  if (!camera_frame && !up_vector) return CPose3D();
  Eigen::Vector3d u(0, -1, 0);
  if (up_vector && up_vector->norm() > 0) u = up_vector->normalized();
  else if (up == SceneOptions::Up::Auto && mesh && !mesh->faces.empty()) u = dominantPlaneNormal(*mesh, u);
  // The smallest rotation taking u to +z.
  const Eigen::Quaterniond q = Eigen::Quaterniond::FromTwoVectors(u, Eigen::Vector3d::UnitZ());
  mrpt::math::CMatrixDouble44 T;
  T.setIdentity();
  const Eigen::Matrix3d R = q.toRotationMatrix();
  for (int r = 0; r < 3; ++r)
    for (int c = 0; c < 3; ++c) T(r, c) = R(r, c);
  return CPose3D::FromHomogeneousMatrix(T);
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

// The mesh as MRPT triangles, faces [begin, end); `flip`: each face wound the other way, its normals
// reversed (MRPT's shader lights the side a normal points to only).
static mrpt::opengl::CSetOfTriangles::Ptr meshTriangles(const TriangleMesh& mesh, std::size_t begin, std::size_t end,
                                                        bool flip) {
  std::vector<mrpt::opengl::TTriangle> tris(end - begin);
  const bool colours = mesh.colors.size() == mesh.vertices.size();
  const bool normals = mesh.normals.size() == mesh.vertices.size();
  const int order[3] = {0, flip ? 2 : 1, flip ? 1 : 2};
  const float sign = flip ? -1.f : 1.f;
  parallelFor(0, int(tris.size()), [&](int f) {
    auto& t = tris[f];
    const auto& face = mesh.faces[begin + std::size_t(f)];
    for (int k = 0; k < 3; ++k) {
      const std::uint32_t i = face[order[k]];
      const auto& p = mesh.vertices[i];
      t.vertex(k) = mrpt::math::TPoint3Df(p.x(), p.y(), p.z());
      t.vertices[k].setColor(colours ? mrpt::img::TColor(mesh.colors[i][0], mesh.colors[i][1], mesh.colors[i][2])
                                     : mrpt::img::TColor(170, 170, 170));
      if (normals) {
        const auto& n = mesh.normals[i];
        t.vertices[k].normal = mrpt::math::TVector3Df(sign * n.x(), sign * n.y(), sign * n.z());
      }
    }
    if (!normals) t.computeNormals();
  }, 1024);
  auto obj = mrpt::opengl::CSetOfTriangles::Create();
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
  struct Votes {
    double vote = 0, total = 0;
  };
  const Votes v = parallelReduce(0, int(mesh.faces.size()), Votes{}, [&](int f, Votes& acc) {
    const auto& a = mesh.vertices[mesh.faces[f][0]];
    const auto& b = mesh.vertices[mesh.faces[f][1]];
    const auto& c = mesh.vertices[mesh.faces[f][2]];
    const Eigen::Vector3f n = (b - a).cross(c - a);  // length = 2 * area
    const Eigen::Vector3f centre = (a + b + c) / 3;
    const Eigen::Vector3f* best = &cams[0];
    for (const auto& cam : cams)
      if ((cam - centre).squaredNorm() < (*best - centre).squaredNorm()) best = &cam;
    const Eigen::Vector3f to_cam = *best - centre;
    acc.vote += n.dot(to_cam) > 0 ? n.norm() : -n.norm();
    acc.total += n.norm();
  }, [](Votes& a, const Votes& b) { a.vote += b.vote, a.total += b.total; }, 4096);
  const double vote = v.vote, total = v.total;
  if (total <= 0 || std::abs(vote) < 0.2 * total) return 0;
  return vote > 0 ? 1 : -1;
}

namespace {

// The mesh, its hidden side culled when asked, lit softly when its colours carry the shading.
void insertMesh(mrpt::opengl::COpenGLScene& scene, mrpt::opengl::CSetOfObjects& world, const TriangleMesh& mesh,
                const Trajectory& path_est, const SceneOptions& opt) {
  // A mesh wound away from the cameras is turned to face them (culling its front left the side shown
  // unlit), then its back is culled.
  const int side = opt.cull_hidden_side ? frontFacesCameras(mesh, path_est) : 0;
  // MRPT sizes an object's GL buffer in an int of bytes: a mesh of more faces than one holds is drawn
  // as several objects, "mesh", "mesh.1", ...
  const std::size_t per_object = std::max<std::size_t>(1, opt.triangles_per_object);
  for (std::size_t begin = 0, part = 0; begin < mesh.faces.size(); begin += per_object, ++part) {
    auto tris = meshTriangles(mesh, begin, std::min(mesh.faces.size(), begin + per_object), side < 0);
    tris->setName(part == 0 ? "mesh" : "mesh." + std::to_string(part));
    if (side != 0) tris->cullFaces(mrpt::opengl::TCullFace::BACK);
    world.insert(tris);
  }
  if (!mesh.colors.empty()) {
    // The colours already carry the scene's shading: light softly so they read true.
    auto& light = scene.getViewport()->lightParameters();
    light.ambient = mrpt::img::TColorf(0.6f, 0.6f, 0.6f, 1.f);
    light.diffuse = mrpt::img::TColorf(0.5f, 0.5f, 0.5f, 1.f);
    light.specular = mrpt::img::TColorf(0.f, 0.f, 0.f, 1.f);
  }
}

// A camera frustum every opt.frustum_every_k poses of the path.
mrpt::opengl::CSetOfObjects::Ptr frustumMarkers(const Trajectory& path_est, const CameraIntrinsics& cam,
                                                const SceneOptions& opt) {
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
  return frustums;
}

mrpt::opengl::CPointCloud::Ptr keyframeMarkers(const SceneOptions& opt) {
  auto kf = mrpt::opengl::CPointCloud::Create();
  kf->setName("keyframes");
  kf->setColor_u8(mrpt::img::TColor(250, 150, 20));
  kf->setPointSize(6.f);
  for (const auto& k : opt.keyframes) kf->insertPoint(float(k.x()), float(k.y()), float(k.z()));
  return kf;
}

mrpt::opengl::CSetOfLines::Ptr loopEdgeLines(const SceneOptions& opt) {
  auto lines = mrpt::opengl::CSetOfLines::Create();
  lines->setName("loop_edges");
  lines->setColor_u8(mrpt::img::TColor(220, 20, 20));
  lines->setLineWidth(3.f);
  for (const auto& [a, b] : opt.loop_edges) lines->appendLine(a.x(), a.y(), a.z(), b.x(), b.y(), b.z());
  return lines;
}

// Axis-aligned box, in the z-up display frame.
struct Extent {
  Eigen::Vector3d lo, hi;
};

// Extent of everything in the z-up display frame, for the grid and the default camera.
Extent displayExtent(const CPose3D& up, const TriangleMesh& mesh, const Trajectory& path_est,
                     const Trajectory* ground_truth) {
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
  return {lo, hi};
}

// A ground grid under everything, one cell margin around it; at most kMaxGridCells a side, its spacing
// ten times wider where the extent needs it (a path in a survey frame, 1e6 m: 4 million lines).
constexpr double kMaxGridCells = 1000;
mrpt::opengl::CGridPlaneXY::Ptr groundGrid(const Extent& e, const SceneOptions& opt) {
  const Eigen::Vector3d& lo = e.lo;
  const Eigen::Vector3d& hi = e.hi;
  double s = opt.grid_spacing > 0 ? opt.grid_spacing : 0.5;
  while ((hi - lo).head<2>().maxCoeff() / s > kMaxGridCells) s *= 10;
  // MRPT steps along the lines in float: far from the origin (a survey frame, 9e6 m) a step under the
  // float's resolution there never moved, and the grid's lines filled the memory.
  const float far = float(std::max(lo.head<2>().cwiseAbs().maxCoeff(), hi.head<2>().cwiseAbs().maxCoeff()));
  while (std::isfinite(far) && std::nextafter(far, INFINITY) - far > 0.25f * float(s)) s *= 10;
  const auto down = [s](double v) { return std::floor(v / s) * s - s; };
  const auto upr = [s](double v) { return std::ceil(v / s) * s + s; };
  auto grid = mrpt::opengl::CGridPlaneXY::Create(float(down(lo.x())), float(upr(hi.x())), float(down(lo.y())),
                                                 float(upr(hi.y())), float(lo.z() - 0.02 - 0.01 * (hi - lo).norm()),
                                                 float(s), 1.0f);
  grid->setName("grid");
  grid->setColor_u8(mrpt::img::TColor(150, 150, 150, 160));
  return grid;
}

// The default view: the whole extent, seen obliquely from above.
void aimDefaultCamera(mrpt::opengl::COpenGLScene& scene, const Extent& e) {
  auto& camera = scene.getViewport()->getCamera();
  const Eigen::Vector3d centre = 0.5 * (e.lo + e.hi);
  camera.setPointingAt(float(centre.x()), float(centre.y()), float(centre.z()));
  camera.setZoomDistance(float(std::max(1.0, 1.8 * (e.hi - e.lo).norm())));
  camera.setAzimuthDegrees(-135.f);
  camera.setElevationDegrees(35.f);
}

}  // namespace

std::shared_ptr<mrpt::opengl::COpenGLScene> buildScene(const TriangleMesh& mesh, const Trajectory& path_est,
                                                        const Trajectory* ground_truth, const CameraIntrinsics& cam,
                                                        const SceneOptions& opt) {
  auto scene = std::make_shared<mrpt::opengl::COpenGLScene>();
  const CPose3D up = sceneUpRotation(path_est.empty() && ground_truth ? *ground_truth : path_est, &mesh, opt.up, opt.up_vector);

  auto world = mrpt::opengl::CSetOfObjects::Create();
  world->setName("world");
  world->setPose(up);
  if (!mesh.empty()) insertMesh(*scene, *world, mesh, path_est, opt);
  if (!path_est.empty()) world->insert(pathLines(path_est, "path", mrpt::img::TColor(20, 60, 230)));
  if (ground_truth && !ground_truth->empty())
    world->insert(pathLines(*ground_truth, "ground_truth", mrpt::img::TColor(20, 170, 40)));
  if (opt.frustum_every_k > 0 && !path_est.empty()) world->insert(frustumMarkers(path_est, cam, opt));
  if (!opt.keyframes.empty()) world->insert(keyframeMarkers(opt));
  if (!opt.loop_edges.empty()) world->insert(loopEdgeLines(opt));
  scene->insert(world);

  const Extent extent = displayExtent(up, mesh, path_est, ground_truth);
  if (opt.grid) scene->insert(groundGrid(extent, opt));
  aimDefaultCamera(*scene, extent);
  return scene;
}

void exportScene(const std::string& path, const TriangleMesh& mesh, const Trajectory& path_est,
                 const Trajectory* ground_truth, const CameraIntrinsics& cam, const SceneOptions& opt) {
  const auto scene = buildScene(mesh, path_est, ground_truth, cam, opt);
  AtomicPath out(path);
  // What COpenGLScene::saveToFile writes (a gzip file of the serialised scene, which loadFromFile and
  // SceneViewer3D read), compressed on every core: zlib on one took 2.7 s of the loop scene's tail.
  try {
    GzipMembersFile file(out.tmp());
    mrpt::serialization::archiveFrom(file) << *scene;
    file.close();
  } catch (const InputError& e) {
    throw InputError(path, "cannot write the 3D scene: " + e.problem());  // the file asked for, not its temporary
  } catch (const std::exception& e) {
    throw InputError(path, "cannot write the 3D scene: " + oneLineMessage(e));
  }
  out.commit();
}

}  // namespace vofusion
