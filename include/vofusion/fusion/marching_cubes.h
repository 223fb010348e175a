#pragma once
// Marching cubes (Lorensen & Cline 1987) over a sparse set of TSDF bricks: one indexed mesh with
// shared vertices (each grid edge crossing becomes exactly one vertex), vertex colours and
// area-weighted vertex normals. Cells touching unobserved or fully truncated voxels are skipped.
#include <cstdint>
#include <functional>
#include <vector>

#include "vofusion/fusion/voxel_brick.h"
#include "vofusion/mesh/triangle_mesh.h"

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

// The same mesh as marchingCubes, one block of region_bricks^3 bricks at a time (so the whole mesh
// never has to exist at once): `sink` receives each non-empty region in a fixed order. Seam vertices
// are computed from the same voxels by the same arithmetic in both regions, so they are bit-identical
// and weld exactly; together the regions hold every vertex and face of marchingCubes once (seam
// vertices once per region using them).
void marchingCubesByRegion(const std::vector<BrickRef>& bricks, float voxel_size, int min_weight, int region_bricks,
                           const std::function<void(RegionMesh&)>& sink);

// The brick at a world brick coordinate: a pointer to one kept elsewhere, or `scratch` filled in.
using BrickFetch = std::function<const Brick*(const Eigen::Vector3i& coord, Brick& scratch)>;
// The same mesh as marchingCubes over all `coords`, built region by region (region_bricks^3 bricks
// each, plus their +1 neighbours): only one region's bricks are fetched at a time, so a world model
// on disk never has to be in RAM whole. Vertices on region borders are welded.
TriangleMesh marchingCubesStreamed(const std::vector<Eigen::Vector3i>& coords, const BrickFetch& fetch,
                                   float voxel_size, int min_weight = 1, int region_bricks = 16);
// marchingCubesByRegion over bricks fetched one region at a time (what both of the above use).
void marchingCubesStreamedByRegion(const std::vector<Eigen::Vector3i>& coords, const BrickFetch& fetch, float voxel_size,
                                   int min_weight, int region_bricks, const std::function<void(RegionMesh&)>& sink);

}  // namespace vofusion::fusion
