#pragma once
// The default mesh without a whole-world peak (issue 15): marching cubes, repair and simplification
// one region (block of bricks) at a time with the seams kept, then the remaining cleaning steps on
// the welded, simplified mesh (about a tenth of the raw faces).
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "vofusion/fusion/marching_cubes.h"
#include "vofusion/mesh/mesh_clean.h"

namespace vofusion {

// Calls its argument once per region (as fusion::marchingCubesByRegion does), made anew at each call:
// the argument may take the region it is given (move from it).
using RegionSource = std::function<void(const std::function<void(fusion::RegionMesh&)>&)>;

struct RegionMeshResult {
  TriangleMesh mesh;                 // cleaned (params' steps), simplified
  MeshCleanReport report;            // steps: "regions" (all regions' repair, components and
                                     // simplification), then cleanMesh's on the welded mesh
  std::size_t regions = 0;
  std::size_t regions_premeshed = 0;  // of them, simplified during the run (PremeshedLookup)
  std::size_t raw_vertices = 0, raw_faces = 0;  // the marching-cubes mesh (seam vertices once)
};

// A region simplified during the run (pipeline/region_premesher.h) and what simplifyRegion reported.
struct PremeshedRegion {
  std::uint64_t input_hash = 0;  // regionInputHash of what it was simplified from
  TriangleMesh mesh;
  std::vector<std::uint8_t> on_seam;
  MeshCleanReport report;
};
// The region simplified during the run from exactly what `r` holds (regionInputHash), handed over
// (moved: the run's copy is gone, so the end never holds a region twice), or nullopt.
using PremeshedLookup = std::function<std::optional<PremeshedRegion>(const fusion::RegionMesh& r)>;

// How meshByRegion prepares a region for simplifyRegion, for whoever simplifies one beforehand. Its
// connected components are judged as fragments (smallFragment: [mesh] min_component_faces / _area),
// those touching a seam by their whole across regions; the small ones' faces go (dropComponents),
// and the region is simplified with regionSimplifyParams.
struct RegionComponents {
  std::vector<std::uint32_t> of_vertex;  // per vertex, its component
  std::vector<std::uint64_t> faces;      // per component
  std::vector<double> area;              // per component, m^2
};
RegionComponents componentsOf(const TriangleMesh& m);
bool smallFragment(std::uint64_t faces, double area, int min_faces, double min_area);
void dropComponents(fusion::RegionMesh& r, const std::vector<std::uint32_t>& component_of_vertex,
                    const std::vector<std::uint8_t>& drop);
MeshCleanParams regionSimplifyParams(const MeshCleanParams& params);
// Every bit simplifyRegion reads of a region (positions, normals, colours, faces, seam flags, region).
std::uint64_t regionInputHash(const fusion::RegionMesh& r);

// Told after each region: pass 1 finds fragments (marching cubes only), pass 2 simplifies.
using MeshProgress = std::function<void(int pass, std::size_t done, std::size_t regions)>;

// Pass 1's raw regions kept for pass 2 up to this many allocated bytes, so that they are marched
// once: the shared sequences' raw meshes (20-40 MB) are; a long recording's (up to 6 M raw vertices,
// ~300 MB) is marched twice, so the mesh stage's peak grows by at most this, a tenth of the 700 MiB
// ceiling.
inline constexpr std::size_t kKeptRawRegionBytes = std::size_t(64) << 20;

// raw_ply non-empty: the raw marching-cubes mesh is also streamed there (vertices shared across
// seams, welded by exact position: seam vertices that coincide, crossings exactly at a voxel, become
// one; a seam vertex's normal is over the faces of every region using it, as for the whole mesh).
// Throws on I/O errors; a region CGAL fails on is kept unsimplified (counted and said in
// report.warning: report.success and report.failure are the welded mesh's cleaning's).
// `regions_done` runs once the last region was read, before the welded mesh is cleaned, told its faces
// (simplified): the caller can free what the regions came from. `premeshed`: a region it has, made
// from the same input, is taken instead of simplifying it again (the result is the same:
// simplifyRegion is deterministic). `keep_bytes`: when pass 1 runs (fragments judged, or a face
// budget), its regions are kept for pass 2 if all of them fit in this many bytes, and `regions` is
// called once; else (0: never) pass 2 calls it again. The mesh is the same either way.
RegionMeshResult meshByRegion(const RegionSource& regions, const MeshCleanParams& params, const std::string& raw_ply = "",
                              const MeshProgress& progress = {},
                              const std::function<void(std::size_t welded_faces)>& regions_done = {},
                              const PremeshedLookup& premeshed = {}, std::size_t keep_bytes = kKeptRawRegionBytes);

}  // namespace vofusion
