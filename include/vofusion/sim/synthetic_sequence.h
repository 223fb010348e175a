#pragma once
// A synthetic RGB-D sequence of a textured indoor scene with exact ground truth (rgbd-simulate).
// CONTRACT used by the tests of every stage; implemented in src/sim/.
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>

#include <mrpt/poses/CPose3D.h>

#include "vofusion/core/camera.h"
#include "vofusion/core/frame.h"

namespace vofusion::sim {

struct SimOptions {
  std::string scene = "room";   // "room" (walls, floor, boxes), "corridor" (long, for volume shifting),
                                // "bare_wall" (camera sliding along a flat textured wall: geometry
                                // gives ICP nothing, colour gives odometry plenty)
  std::size_t frames = 300;
  double fps = 30.0;            // Hz; timestamps start at 0
  CameraIntrinsics camera;      // default 640x480, fx=fy=525
  bool noise = true;            // Kinect-like depth: disparity quantisation, noise growing with range, holes
  double max_range = 4.5;       // m; farther surfaces read 0
  std::uint32_t seed = 1;
};

class SyntheticSequence {
 public:
  explicit SyntheticSequence(const SimOptions& opts);
  std::size_t size() const;
  Frame render(std::size_t i) const;                   // rgb, depth and groundTruth filled
  mrpt::poses::CPose3D groundTruth(std::size_t i) const;  // camera-to-world
  const SimOptions& options() const;
 private:
  struct Impl;
  std::shared_ptr<const Impl> impl_;
};

}  // namespace vofusion::sim
