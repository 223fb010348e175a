#pragma once
// The TSDF volume of KinectFusion as a cyclic buffer that follows the camera (KinFu Large Scale):
// a grid of N^3 brick slots addressed by world brick coordinate modulo N. Only bricks the truncation
// band of some depth reading has touched are allocated. When the volume shifts, bricks that leave it
// are handed to the world model (world_model.h: a RAM cache bounded by world_cache_mib, the rest
// compressed on disk) and bricks that re-enter are taken back from it.
#include <cstdint>
#include <functional>
#include <iosfwd>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "vofusion/core/camera.h"
#include "vofusion/fusion/marching_cubes.h"
#include "vofusion/fusion/brick_arena.h"
#include "vofusion/fusion/voxel_brick.h"
#include "vofusion/fusion/world_model.h"
#include "vofusion/core/triangle_mesh.h"

namespace vofusion::fusion {

struct TsdfParams {
  int volume_voxels = 512;      // voxels per volume edge (multiple of 8)
  float voxel_size = 0.006f;    // m
  float truncation = 0.03f;     // m, half width of the band around each depth reading
  int max_weight = 64;          // frames: the running average becomes a moving average (<= 255)
  float min_depth = 0.3f;       // m, readings used for integration
  float max_depth = 3.5f;       // m
  int mark_step = 4;            // pixels between depth readings used to find the touched bricks
  int world_cache_mib = 64;     // MiB of world-model bricks kept in RAM; the rest spill to disk
  std::string work_dir = "auto";  // folder of the spill file ("auto" or "": the system's temporary folder)
};

// Ray-cast surface seen from a camera: world-frame maps, NaN in x where no surface was hit.
struct RaycastMaps {
  cv::Mat vertices;  // CV_32FC3, m, world frame
  cv::Mat normals;   // CV_32FC3, unit, world frame, from the TSDF gradient
  cv::Mat colours;   // CV_8UC3 BGR (only when asked for)
  cv::Mat depth;     // CV_32FC1, m along the optical axis, 0 where the ray found no surface
};

class TsdfVolume {
 public:
  // centre: world position (m) the volume starts centred on (snapped to the brick grid); one beyond the
  // world model's keys (kKeyReach bricks from the world's origin: 50 km at 6 mm voxels) or not finite
  // throws std::invalid_argument.
  TsdfVolume(const TsdfParams& params, const Eigen::Vector3f& centre);

  // Fuses one depth (+ optional BGR colour) frame seen from cam_to_world. Returns voxels updated.
  std::size_t integrate(const cv::Mat& depth, const cv::Mat& bgr, const CameraIntrinsics& cam,
                        const Eigen::Isometry3f& cam_to_world);

  // depth_hint (optional, CV_32F, same size): where the surface is expected along each ray (the depth
  // frame last fused from this pose, holes filled from the previous ray cast); rays then start just
  // before it instead of marching from min_depth (and fall back to that when it is inconsistent).
  // hinted_only: rays without a hint are not cast, and none marches past its hint's band: for
  // tracking, where only model pixels close to readings find partners.
  RaycastMaps raycast(const Eigen::Isometry3f& cam_to_world, const CameraIntrinsics& cam,
                      const cv::Mat* depth_hint = nullptr, bool with_colour = false, bool hinted_only = false) const;

  // Re-centres the volume on `point` if it is farther than `threshold` (m) from the centre.
  bool shiftIfNeeded(const Eigen::Vector3f& point, float threshold);
  // Moves the volume so its centre is the brick-grid point nearest `point`.
  void shiftTo(const Eigen::Vector3f& point);

  // Marching cubes over world model + current volume, region by region (world-model bricks are read
  // from the store a region at a time, never all at once).
  TriangleMesh extractMesh() const;
  // The same, one block of region_bricks^3 bricks at a time (seam vertices flagged): bricks are read
  // from the world model a region at a time.
  void extractMeshByRegion(int region_bricks, const std::function<void(RegionMesh&)>& sink) const;
  // The allocated bricks of the volume (not the world model).
  std::vector<BrickRef> volumeBricks() const;

  // The whole map (volume origin, every brick of volume and world model) to a binary stream, and back
  // into a volume of the same TSDF geometry (voxel_size, volume_voxels, truncation); load() throws
  // std::runtime_error naming what is wrong for a truncated or corrupt stream.
  void save(std::ostream& os) const;
  void load(std::istream& is);

  // TSDF at a world point by trilinear interpolation, in metres; false when unobserved.
  bool sdfAt(const Eigen::Vector3f& p, float& sdf_m) const;

  Eigen::Vector3f centre() const;
  Eigen::Vector3f minCorner() const;  // world position of the volume's first voxel
  float edgeLength() const { return params_.volume_voxels * params_.voxel_size; }
  std::size_t bricksInVolume() const;
  std::vector<Eigen::Vector3i> allCoords() const;  // every allocated brick, volume and world model
  BrickFetch fetcher() const;                      // reads a brick from the volume or the world model
  std::size_t bricksInWorldModel() const { return world_->size(); }
  const WorldModel& worldModel() const { return *world_; }
  std::size_t memoryBytes() const;
  const TsdfParams& params() const { return params_; }
  // The volume's box of bricks: its first brick (world brick coordinates) and bricks per side.
  const Eigen::Vector3i& originBrick() const { return origin_; }
  int bricksPerSide() const { return n_; }

 private:
  const Brick* brickAt(int bx, int by, int bz) const {
    const int s = slotOf(bx, by, bz);
    return s < 0 ? nullptr : slot_brick_[s];
  }
  // b - origin, wrapped: anything before the origin is past n_. In unsigned arithmetic, because a far
  // point's brick (cvFloor of a huge or NaN coordinate gives INT_MIN) overflowed int (undefined).
  static unsigned offset(int b, int origin) { return static_cast<unsigned>(b) - static_cast<unsigned>(origin); }
  // -1 outside the volume. Table lookups: no integer division on the ray caster's hot path.
  int slotOf(int bx, int by, int bz) const {
    const unsigned ux = offset(bx, origin_.x()), uy = offset(by, origin_.y()), uz = offset(bz, origin_.z());
    if (ux >= static_cast<unsigned>(n_) || uy >= static_cast<unsigned>(n_) || uz >= static_cast<unsigned>(n_)) return -1;
    return cyclic_[0][ux] + cyclic_[1][uy] + cyclic_[2][uz];
  }
  // False only when no brick of the 4x4x4-brick block holding world brick (bx,by,bz) is allocated:
  // the ray caster then skips the whole block. Outside the volume: true.
  bool blockOccupied(int bx, int by, int bz) const {
    const unsigned ux = offset(bx, origin_.x()), uy = offset(by, origin_.y()), uz = offset(bz, origin_.z());
    if (block_count_.empty() || ux >= static_cast<unsigned>(n_) || uy >= static_cast<unsigned>(n_) ||
        uz >= static_cast<unsigned>(n_))
      return true;
    return block_count_[block_cyclic_[0][ux] + block_cyclic_[1][uy] + block_cyclic_[2][uz]] != 0;
  }
  void updateCyclicTables();
  void setSlot(int slot, std::int32_t id);  // keeps slot_brick_ and block_count_ in step
  int blockOfSlot(int slot) const;
  bool cell(const Eigen::Vector3f& q, const Voxel* (&v)[8], float& a, float& b, float& c) const;
  bool trilinear(const Eigen::Vector3f& q, float& f) const;  // q in voxel units
  // TSDF gradient at q: the derivative of the trilinear interpolant inside q's cell (its 8 voxels;
  // central differences of trilinear samples read 48 and moved no figure of the benchmark).
  bool cellGradient(const Eigen::Vector3f& q, Eigen::Vector3f& g) const;
  void removeBrick(int slot);  // the slot's brick leaves the arena (another brick may change id)
  // integrate()'s three steps (tsdf_volume.cpp).
  void markTouchedBricks(const cv::Mat& depth, const CameraIntrinsics& cam, const Eigen::Isometry3f& cam_to_world);
  std::vector<std::int32_t> allocateTouchedBricks();
  std::size_t updateVoxels(const std::vector<std::int32_t>& touched, const cv::Mat& depth, const cv::Mat& bgr,
                           const CameraIntrinsics& cam, const Eigen::Isometry3f& cam_to_world);
  // Ray casting (raycast.cpp): one pixel's ray in voxel units, marched through the field.
  struct Ray;
  enum class March { Hit, Miss, Untrusted };
  struct Marcher;
  bool marchStep(Marcher& m) const;
  void marchSideBySide(Marcher* marches, bool* going, int n) const;
  float pastUnallocated(const Ray& ray, int ix, int iy, int iz, float z) const;
  // Rays marched side by side, a sample each in turn. 4 with cvFloor against one at a time with
  // std::floor: ray cast 8-21 % cheaper (mode joint, rpy_first100 and xyz_first300, two rounds each), the
  // same bytes out; 2, 4 and 8 within noise of each other (mode kinfu, before cvFloor).
  // bench/results/2026-11-28-raycast-side-by-side.md
  static constexpr int kRaysSideBySide = 4;
  struct PendingRay;
  void castRays(PendingRay* rays, int n, bool hinted_only, RaycastMaps& maps, int y) const;  // n <= kRaysSideBySide
  bool normalAt(PendingRay& r) const;
  void storeHits(PendingRay* rays, int n, RaycastMaps& maps, int y) const;
  cv::Vec3b colourAt(const Eigen::Vector3f& q) const;  // the nearest voxel's colour (BGR), black when none
  // The world model's keys hold bricks within kKeyReach of the world's origin (50 km at 6 mm voxels):
  // the origins (in bricks, each axis) whose far corner they hold too, as load() takes one back.
  long reachLo() const { return -WorldModel::kKeyReach; }
  long reachHi() const { return WorldModel::kKeyReach - n_ - 1; }
  // The origin on one axis that centres the volume on `metres` there, rounded in float as always (an
  // origin a brick off would change every later frame's fusion); past the reach when not finite or far.
  long centredOrigin(float metres) const;
  std::string reachText() const;  // "N km from the world's origin on each axis"

  TsdfParams params_;
  int n_;                        // bricks per edge
  Eigen::Vector3i origin_;       // world brick coordinate of the volume's first brick
  bool reach_warned_ = false;    // the camera went past the world model's keys (said once)
  std::vector<std::int32_t> slots_;                  // n^3 brick ids, -1 = none
  std::vector<const Brick*> slot_brick_;             // n^3, the brick of each slot (nullptr = none)
  std::vector<int> cyclic_[3];                       // per axis: (brick - origin) -> slot offset
  // Allocated bricks per cyclic 4x4x4-brick block (empty when the volume is not a multiple of 32
  // voxels); a block may also count bricks of the opposite volume end, which only makes it cautious.
  std::vector<std::uint16_t> block_count_;
  std::vector<int> block_cyclic_[3];                 // per axis: (brick - origin) -> block offset
  BrickArena bricks_;                                // brick id -> storage (ids dense, see brick_arena.h)
  std::unique_ptr<WorldModel> world_;                // bricks that left the volume
  std::vector<std::uint8_t> marks_;                  // per slot, scratch of integrate()
};

}  // namespace vofusion::fusion
