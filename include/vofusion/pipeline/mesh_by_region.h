#pragma once
// The default mesh without a whole-world peak (issue 15): marching cubes, repair and simplification
// one region (block of bricks) at a time with the seams kept, then the remaining cleaning steps on
// the welded, simplified mesh (about a tenth of the raw faces).
#include <functional>
#include <string>

#include "vofusion/fusion/marching_cubes.h"
#include "vofusion/mesh/mesh_clean.h"

namespace vofusion {

// Calls its argument once per region (as fusion::marchingCubesByRegion does).
using RegionSource = std::function<void(const std::function<void(fusion::RegionMesh&)>&)>;

struct RegionMeshResult {
  TriangleMesh mesh;                 // cleaned (params' steps), simplified
  MeshCleanReport report;            // steps: "regions" (all regions' repair, components and
                                     // simplification), then cleanMesh's on the welded mesh
  std::size_t regions = 0;
  std::size_t raw_vertices = 0, raw_faces = 0;  // the marching-cubes mesh (seam vertices once)
};

// Told after each region: pass 1 finds fragments (marching cubes only), pass 2 simplifies.
using MeshProgress = std::function<void(int pass, std::size_t done, std::size_t regions)>;

// raw_ply non-empty: the raw marching-cubes mesh is also streamed there (vertices shared across
// seams, welded by exact position: seam vertices that coincide, crossings exactly at a voxel, become
// one; a seam vertex's normal is its first region's). Throws on I/O errors; a region CGAL fails on
// is kept unsimplified (counted in report.failure).
// `regions_done` runs once the last region was read, before the welded mesh is cleaned: the caller
// can free what the regions came from.
RegionMeshResult meshByRegion(const RegionSource& regions, const MeshCleanParams& params, const std::string& raw_ply = "",
                              const MeshProgress& progress = {}, const std::function<void()>& regions_done = {});

}  // namespace vofusion
