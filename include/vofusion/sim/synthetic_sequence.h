#pragma once
// A synthetic RGB-D sequence of a textured indoor scene with exact ground truth (rgbd-simulate).
// CONTRACT used by the tests of every stage; implemented in src/sim/.
//
// World frame: z up, metres. Camera poses are camera-to-world with the usual optical axes
// (x right, y down, z forward), as in TUM ground truth. Scenes (all surfaces carry a procedural,
// view-independent texture of rectangles, discs and checker patches at several scales):
//   room      5 x 4 x 3 m box x in [-2.5, 2.5], y in [-2, 2], z in [0, 3], five boxes on the floor;
//             the camera hovers near (0, 0, 1.4) sweeping its gaze around +x.
//   corridor  x in [-1, 12], y in [-1.1, 1.1], z in [0, 2.6], boxes along both walls; the camera
//             travels along +x (about 0.4 m/s, at most ~10 m over the whole sequence).
//   bare_wall one infinite plane y = kBareWallY facing the camera, which slides along x at ~1.5 m.
//   loop      a 2 m wide corridor around a 6 x 4 m block (outer walls x in [-5, 5], y in [-4, 4]);
//             the camera walks it once around (26 m) and 15 % further, facing along it (loop closure).
//   lookalike corridor x in [-1, 10], y in [-1.5, 1.5] whose walls and boxes repeat every 3 m; the
//             camera slides along x facing the +y wall for ~1.6 periods: places 3 m apart look the
//             same and must not be joined by loop closure.
// Depth (noise=true) follows a Kinect v1 model: Gaussian noise sigma(z) = 0.0012 + 0.0019 (z-0.4)^2 m,
// then disparity quantisation to 1/8 px with baseline 0.075 m (focal length normalised to a 640 px
// wide sensor), random dropout (~2 %), holes on the far side of depth discontinuities and at grazing
// angles, nothing nearer than 0.4 m or beyond max_range. noise=false gives exact depth (still 0
// beyond max_range / nearer than 0.4 m). Everything is a pure function of (options, frame index).
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include <mrpt/poses/CPose3D.h>

#include "vofusion/core/camera.h"
#include "vofusion/core/depth_noise.h"
#include "vofusion/core/frame.h"

namespace vofusion::sim {

constexpr double kBareWallY = 1.5;     // m, the bare_wall scene's plane (normal -y, towards the camera)
constexpr double kKinectMinRange = 0.4;  // m
constexpr double kKinectBaseline = 0.075;  // m
constexpr double kDisparitySubpixel = 8.0;  // steps per pixel

// Standard deviation of the simulated depth noise at range z (before quantisation), m.
inline double kinectNoiseSigma(double z) { return kinectAxialSigma(z); }

struct SimOptions {
  std::string scene = "room";   // "room" (walls, floor, boxes), "corridor" (long, for volume shifting),
                                // "bare_wall" (camera sliding along a flat textured wall: geometry
                                // gives ICP nothing, colour gives odometry plenty), "loop" (a corridor
                                // around a block, walked once around), "lookalike" (a corridor that repeats every 3 m),
                                // "longwalk" (a straight corridor walked at 1 m/s: 100 m = 3000 frames)
  std::string trajectory = "smooth";  // "smooth" (the scene's hand-held path, <= ~30 deg/s) or "shake":
                                // the same path with fast hand shake added (turns up to ~150 deg/s),
                                // colour exposed over `exposure` (motion blur) and taken up to
                                // +-colour_offset_max from the depth capture (Frame::colour_offset)
  double exposure = 0.012;        // s, colour exposure of the shake trajectory
  double colour_offset_max = 0.015;  // s
  double depth_readout = 0.0;     // s: depth rows read one after another over this time (rolling
                                  // shutter, top row first; Kinect v1 ~0.03); 0: all rows at once
  std::size_t frames = 300;
  double fps = 30.0;            // Hz; timestamps start at 0
  double pace = 1.0;            // the scene's path (shake included) played this many times as fast: at 2 the
                                // room turns up to ~37 deg/s and moves up to ~0.9 m/s (a brisk sweep); a
                                // corridor sized by the time walked is built for pace x frames / fps seconds
  CameraIntrinsics camera;      // default 640x480, fx=fy=525
  bool noise = true;            // Kinect-like depth: disparity quantisation, noise growing with range, holes
  bool textured = true;         // false: every surface one plain colour (only shading shows the geometry)
  double max_range = 4.5;       // m; farther surfaces read 0
  std::uint32_t seed = 1;
  // The camera covered (a hand over the lens) from blackout_start for blackout_seconds: no depth, black
  // colour, while the path goes on (relocalisation). blackout_seconds = 0: never.
  double blackout_start = 0.0, blackout_seconds = 0.0;
};

class SyntheticSequence {
 public:
  // Throws InputError("--scene", ...) for an unknown scene, InputError("--intrinsics", ...) for a bad camera.
  explicit SyntheticSequence(const SimOptions& opts);
  std::size_t size() const;
  Frame render(std::size_t i) const;                   // rgb, depth, colour_offset and groundTruth filled
  mrpt::poses::CPose3D groundTruth(std::size_t i) const;  // camera-to-world
  const SimOptions& options() const;
  // Exact depth (m, 0 = nothing hit) along pixel (u, v) of a camera at `pose`: the analytic value
  // without noise or range limits (tests and stage checks).
  double exactDepth(const mrpt::poses::CPose3D& pose, double u, double v) const;
  // Distance (m) from a point in the scene's frame to the nearest surface (a mesh checked against the
  // scene: a wall fused twice shows as vertices off every surface).
  double distanceToSurface(const Eigen::Vector3d& point) const;
 private:
  struct Impl;
  std::shared_ptr<const Impl> impl_;
};

}  // namespace vofusion::sim
