#pragma once
// Results as an MRPT 3D scene (.3Dscene, opened by SceneViewer3D) and as an off-screen rendered PNG.
//
// The scene is shown z-up: everything sits in one CSetOfObjects named "world" whose pose rotates the
// reconstruction's frame so that its "up" direction becomes +z. Children of "world", by name:
//   "mesh"          CSetOfTriangles, per-vertex colours (grey if the mesh has none); past
//                   SceneOptions::triangles_per_object faces, more of them: "mesh.1", "mesh.2", ...
//   "path"          CSetOfLines, the estimated camera centres joined in order (blue)
//   "ground_truth"  CSetOfLines, the ground-truth camera centres (green), when given
//   "frustums"      CSetOfObjects of CFrustum, one every k frames of the estimated path
//   "keyframes"     CPointCloud of the loop-closure keyframes' camera centres (orange), when given
//   "loop_edges"    CSetOfLines joining the keyframes of each accepted loop (red), when given
//   "grid"          CGridPlaneXY under the reconstruction (a child of the scene, outside "world")
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include <mrpt/opengl/COpenGLScene.h>
#include <mrpt/poses/CPose3D.h>

#include "vofusion/core/camera.h"
#include "vofusion/core/trajectory.h"
#include "vofusion/core/triangle_mesh.h"

namespace vofusion {

struct SceneOptions {
  enum class Up { Auto, PlusZ, MinusY };
  // Auto: when the path starts unrotated (a run in the first camera's optical frame, y down),
  // the normal of the mesh's dominant roughly-horizontal surface (floor, table) found near the
  // camera's -y, or -y itself without a mesh; +z otherwise (TUM ground truth, mocap frame).
  Up up = Up::Auto;
  // Measured "up" in the reconstruction's frame (e.g. from an accelerometer): wins over `up`.
  std::optional<Eigen::Vector3d> up_vector;
  int frustum_every_k = 30;          // frames; 0: no frustums
  double frustum_depth = 0.15;       // m, distance of the frustum's far plane
  // With a path given: draw only the side of the surface that faces the cameras (decided by an
  // area-weighted vote of the faces; a mesh wound away from them is turned to face them), so a room
  // scanned from inside can be seen into from outside: in mesh.png and a scene drawn in this process.
  // A saved .3Dscene loads with both sides drawn (MRPT 2.5's CSetOfTriangles does not store its
  // culling); its faces still face the cameras.
  bool cull_hidden_side = true;
  // Faces per MRPT object: one sizes its GL buffer in an int of bytes (108 a face), which 19.9 M faces
  // overflow; more faces are drawn as several objects ("mesh", "mesh.1", ...).
  std::size_t triangles_per_object = 16'000'000;
  bool grid = true;
  double grid_spacing = 0.5;         // m
  // Loop closure: keyframe poses (camera-to-world) and the pairs of poses each accepted loop joins.
  std::vector<mrpt::poses::CPose3D> keyframes;
  std::vector<std::pair<mrpt::poses::CPose3D, mrpt::poses::CPose3D>> loop_edges;
};

// The rotation (a pure rotation CPose3D) applied to the reconstruction so that its up axis is +z.
mrpt::poses::CPose3D sceneUpRotation(const Trajectory& path, const TriangleMesh* mesh, SceneOptions::Up up,
                                     const std::optional<Eigen::Vector3d>& up_vector = std::nullopt);

// What mesh.png draws: the mesh without its ceiling (a dollhouse view; the picture looks in from
// above). The ceiling is the height above the highest camera of `path` (along `up`'s z axis, as
// sceneUpRotation gives it) with the most downward-facing area, at least 0.5 m^2; faces reaching
// 10 cm below it or higher are left out. No path, no such ceiling, or a cut whose faces left out are
// mostly not facing down (not a ceiling: a table above a low camera): nullopt (draw the mesh as it is).
std::optional<TriangleMesh> withoutCeiling(const TriangleMesh& mesh, const Trajectory& path, const mrpt::poses::CPose3D& up);

// The camera frustum pose for a camera-to-world optical pose (x right, y down, z forward):
// CFrustum looks along +x with z up, so this is pose * (optical <- MRPT body) rotation.
mrpt::poses::CPose3D frustumPose(const mrpt::poses::CPose3D& camera_to_world);

std::shared_ptr<mrpt::opengl::COpenGLScene> buildScene(const TriangleMesh& mesh, const Trajectory& path_est,
                                                        const Trajectory* ground_truth, const CameraIntrinsics& cam,
                                                        const SceneOptions& opt = {});

// Writes the scene (a gzip-compressed .3Dscene, as COpenGLScene::saveToFile writes it, compressed on
// every core: core/gzip_members.h) whole or not at all;
// throws InputError(path, ...) when it cannot be written.
void exportScene(const std::string& path, const TriangleMesh& mesh, const Trajectory& path_est,
                 const Trajectory* ground_truth, const CameraIntrinsics& cam, const SceneOptions& opt = {});

// Off-screen rendering (mrpt::opengl::CFBORender, EGL; no display needed) of the mesh and, when
// given, the camera path, seen from above and behind the cameras, looking at the mesh's centre.
// Written atomically as PNG; throws InputError(png, ...) on failure (including no EGL device).
void renderMeshPng(const std::string& png, const TriangleMesh& mesh, const Trajectory* path, int width = 1024,
                   int height = 768, const std::optional<Eigen::Vector3d>& up_vector = std::nullopt);

// The first off-screen render of a process loads the OpenGL driver (Mesa's llvmpipe: libLLVM) and
// compiles its shaders, ~0.1 s; later ones find both done. This does that on a thread of its own with a
// throwaway 16x16 render, to be started where a core is idle (vofusion: during the welded mesh's
// one-core repair) before renderMeshPng. The destructor waits for it. Failures are ignored: the real
// render reports them.
class OffscreenRenderWarmUp {
 public:
  OffscreenRenderWarmUp();
  ~OffscreenRenderWarmUp();
  OffscreenRenderWarmUp(const OffscreenRenderWarmUp&) = delete;
  OffscreenRenderWarmUp& operator=(const OffscreenRenderWarmUp&) = delete;

 private:
  std::thread thread_;
};

}  // namespace vofusion
