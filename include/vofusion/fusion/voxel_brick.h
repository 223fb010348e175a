#pragma once
// Storage of the TSDF: bricks of 8^3 voxels, 6 bytes per voxel (int16 tsdf, uint8 weight, RGB),
// contiguous so integration, ray casting and marching cubes walk memory in order.
#include <cstdint>

#include <Eigen/Core>

namespace vofusion::fusion {

constexpr int kBrickEdge = 8;                         // voxels
constexpr int kBrickVoxels = kBrickEdge * kBrickEdge * kBrickEdge;
constexpr float kTsdfScale = 32767.0f;                // int16 <-> [-1, 1]

struct Voxel {
  std::int16_t tsdf = 0;    // truncated signed distance / truncation * 32767 (+ = free space)
  std::uint8_t weight = 0;  // frames integrated, capped; 0 = never observed
  std::uint8_t r = 0, g = 0, b = 0;
};
static_assert(sizeof(Voxel) == 6, "voxel layout");

struct Brick {
  Voxel voxels[kBrickVoxels];  // x fastest, then y, then z
  Eigen::Vector3i coord{0, 0, 0};  // brick coordinates in the world grid (voxel index / 8)

  static int index(int x, int y, int z) { return x + kBrickEdge * (y + kBrickEdge * z); }
};

// A brick and where it lies, as the mesher consumes them.
struct BrickRef {
  Eigen::Vector3i coord;
  const Brick* brick;
};

}  // namespace vofusion::fusion
