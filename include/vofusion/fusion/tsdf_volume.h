#pragma once
// The TSDF volume of KinectFusion as a cyclic buffer that follows the camera (KinFu Large Scale):
// a grid of N^3 brick slots addressed by world brick coordinate modulo N. Only bricks the truncation
// band of some depth reading has touched are allocated. When the volume shifts, bricks that leave it
// move to the world model (kept, meshed at the end) and bricks that re-enter are taken back.
#include <cstdint>
#include <memory>
#include <unordered_map>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "vofusion/core/camera.h"
#include "vofusion/fusion/voxel_brick.h"
#include "vofusion/mesh/triangle_mesh.h"

namespace vofusion::fusion {

struct TsdfParams {
  int volume_voxels = 512;      // voxels per volume edge (multiple of 8)
  float voxel_size = 0.006f;    // m
  float truncation = 0.03f;     // m, half width of the band around each depth reading
  int max_weight = 64;          // frames: the running average becomes a moving average (<= 255)
  float min_depth = 0.3f;       // m, readings used for integration
  float max_depth = 3.5f;       // m
  int mark_step = 4;            // pixels between depth readings used to find the touched bricks
};

// Ray-cast surface seen from a camera: world-frame maps, NaN in x where no surface was hit.
struct RaycastMaps {
  cv::Mat vertices;  // CV_32FC3, m, world frame
  cv::Mat normals;   // CV_32FC3, unit, world frame, from the TSDF gradient
  cv::Mat colours;   // CV_8UC3 BGR (only when asked for)
};

class TsdfVolume {
 public:
  // centre: world position (m) the volume starts centred on (snapped to the brick grid).
  TsdfVolume(const TsdfParams& params, const Eigen::Vector3f& centre);

  // Fuses one depth (+ optional BGR colour) frame seen from cam_to_world. Returns voxels updated.
  std::size_t integrate(const cv::Mat& depth, const cv::Mat& bgr, const CameraIntrinsics& cam,
                        const Eigen::Isometry3f& cam_to_world);

  // depth_hint (optional, CV_32F, same size): the depth frame last fused from this very pose; rays
  // then start just before it instead of marching from min_depth (falls back when inconsistent).
  RaycastMaps raycast(const Eigen::Isometry3f& cam_to_world, const CameraIntrinsics& cam,
                      const cv::Mat* depth_hint = nullptr, bool with_colour = false) const;

  // Re-centres the volume on `point` if it is farther than `threshold` (m) from the centre.
  bool shiftIfNeeded(const Eigen::Vector3f& point, float threshold);
  // Moves the volume so its centre is the brick-grid point nearest `point`.
  void shiftTo(const Eigen::Vector3f& point);

  // Marching cubes over world model + current volume.
  TriangleMesh extractMesh() const;
  // All allocated bricks, volume and world model.
  std::vector<BrickRef> allBricks() const;

  // TSDF at a world point by trilinear interpolation, in metres; false when unobserved.
  bool sdfAt(const Eigen::Vector3f& p, float& sdf_m) const;

  Eigen::Vector3f centre() const;
  Eigen::Vector3f minCorner() const;  // world position of the volume's first voxel
  float edgeLength() const { return params_.volume_voxels * params_.voxel_size; }
  std::size_t bricksInVolume() const;
  std::size_t bricksInWorldModel() const { return world_.size(); }
  std::size_t memoryBytes() const;
  const TsdfParams& params() const { return params_; }

 private:
  const Brick* brickAt(int bx, int by, int bz) const;
  int slotOf(int bx, int by, int bz) const;  // -1 outside the volume
  bool trilinear(const Eigen::Vector3f& q, float& f) const;  // q in voxel units
  bool gradient(const Eigen::Vector3f& q, Eigen::Vector3f& g) const;
  std::int32_t allocate(int bx, int by, int bz);
  static std::uint64_t key(int bx, int by, int bz);

  TsdfParams params_;
  int n_;                        // bricks per edge
  Eigen::Vector3i origin_;       // world brick coordinate of the volume's first brick
  std::vector<std::int32_t> slots_;                  // n^3 brick ids, -1 = none
  std::vector<std::unique_ptr<Brick>> pool_;         // brick id -> storage (never moved)
  std::unordered_map<std::uint64_t, std::int32_t> world_;  // bricks that left the volume
  std::vector<std::uint8_t> marks_;                  // per slot, scratch of integrate()
};

}  // namespace vofusion::fusion
