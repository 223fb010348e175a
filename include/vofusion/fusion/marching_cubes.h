#pragma once
// Marching cubes (Lorensen & Cline 1987) over a sparse set of TSDF bricks: one indexed mesh with
// shared vertices (each grid edge crossing becomes exactly one vertex), vertex colours and
// area-weighted vertex normals. Cells touching unobserved or fully truncated voxels are skipped.
#include <array>
#include <cstdint>
#include <cstring>
#include <functional>
#include <unordered_map>
#include <vector>

#include "vofusion/fusion/voxel_brick.h"
#include "vofusion/core/triangle_mesh.h"

namespace vofusion::fusion {

// voxel_size in metres; voxel (i,j,k) sits at world (i,j,k) * voxel_size. min_weight: frames.
TriangleMesh marchingCubes(const std::vector<BrickRef>& bricks, float voxel_size, int min_weight = 1);

// One region's part of the mesh: the triangles of the cells in its bricks.
struct RegionMesh {
  Eigen::Vector3i region;             // brick coordinates / region_bricks (rounded down)
  TriangleMesh mesh;                  // normals from this region's faces only
  std::vector<std::uint8_t> on_seam;  // per vertex, 1: a neighbouring region's mesh has it too
  std::size_t ordinal = 0, regions = 0;  // this is region `ordinal` (0-based) of `regions` with bricks
};

// A vertex position hashed by its exact bits: seam vertices come out bit-identical in every region
// sharing them (same voxels, same arithmetic), so they are welded by exact position.
struct ExactPositionHash {
  std::size_t operator()(const std::array<float, 3>& p) const {
    std::size_t h = 1469598103934665603ull;
    for (float f : p) {
      std::uint32_t b;
      std::memcpy(&b, &f, 4);
      h = (h ^ b) * 1099511628211ull;
    }
    return h;
  }
};
inline std::array<float, 3> exactPosition(const Eigen::Vector3f& p) { return {p.x(), p.y(), p.z()}; }

// Appends region meshes into one index space: a region's seam vertices get the index the first
// region having them gave them, every other vertex a new one. Only seam vertices are remembered.
class SeamWelder {
 public:
  // Index of each of the part's vertices; `emit(v)` is called for each of them that is new.
  template <typename Emit>
  std::vector<std::uint32_t> add(const TriangleMesh& part, const std::vector<std::uint8_t>& seam, Emit&& emit) {
    std::vector<std::uint32_t> index(part.vertices.size());
    for (std::size_t v = 0; v < part.vertices.size(); ++v) {
      if (seam[v]) {
        const auto [it, fresh] = seam_index_.emplace(exactPosition(part.vertices[v]), next_);
        index[v] = it->second;
        if (!fresh) continue;
      } else {
        index[v] = next_;
      }
      ++next_;
      emit(v);
    }
    return index;
  }
  std::uint32_t vertices() const { return next_; }

 private:
  std::unordered_map<std::array<float, 3>, std::uint32_t, ExactPositionHash> seam_index_;
  std::uint32_t next_ = 0;
};

// The same mesh as marchingCubes, one block of region_bricks^3 bricks at a time (so the whole mesh
// never has to exist at once): `sink` receives each non-empty region in a fixed order. Seam vertices
// are computed from the same voxels by the same arithmetic in both regions, so they are bit-identical
// and weld exactly; together the regions hold every vertex and face of marchingCubes once (seam
// vertices once per region using them).
void marchingCubesByRegion(const std::vector<BrickRef>& bricks, float voxel_size, int min_weight, int region_bricks,
                           const std::function<void(RegionMesh&)>& sink);

// The brick at a world brick coordinate: a pointer to one kept elsewhere, or `scratch` filled in.
// Called on several threads at once, each with its own coordinate and scratch brick.
using BrickFetch = std::function<const Brick*(const Eigen::Vector3i& coord, Brick& scratch)>;
// The same mesh as marchingCubes over all `coords`, built region by region (region_bricks^3 bricks
// each, plus their +1 neighbours): only one region's bricks are fetched at a time, so a world model
// on disk never has to be in RAM whole. Vertices on region borders are welded.
TriangleMesh marchingCubesStreamed(const std::vector<Eigen::Vector3i>& coords, const BrickFetch& fetch,
                                   float voxel_size, int min_weight = 1, int region_bricks = 16);
// Region `region`'s mesh (as marchingCubesByRegion makes it; ordinal and regions left 0): its own
// bricks `own` and those of their +1 neighbours that `present` says exist, fetched into `scratch`
// (grown as needed, kept by the caller from region to region) where fetch needs it.
RegionMesh marchRegion(const Eigen::Vector3i& region, std::vector<Eigen::Vector3i> own,
                       const std::function<bool(const Eigen::Vector3i&)>& present, const BrickFetch& fetch,
                       float voxel_size, int min_weight, int region_bricks, std::vector<Brick>& scratch);
// The region (block of region_bricks^3 bricks) holding a world brick coordinate.
Eigen::Vector3i regionOf(const Eigen::Vector3i& brick, int region_bricks);
// marchingCubesByRegion over bricks fetched one region at a time (what both of the above use).
void marchingCubesStreamedByRegion(const std::vector<Eigen::Vector3i>& coords, const BrickFetch& fetch, float voxel_size,
                                   int min_weight, int region_bricks, const std::function<void(RegionMesh&)>& sink);

}  // namespace vofusion::fusion
