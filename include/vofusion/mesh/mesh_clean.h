#pragma once
// Mesh post-processing with CGAL Polygon Mesh Processing: repair, drop small fragments, fill small
// holes, optionally simplify and smooth. Vertex colours survive every step (new vertices take the
// colours of their neighbours). INI section [mesh]; defaults documented in share/mesh.ini.
#include <cstdint>
#include <string>
#include <vector>

#include <mrpt/config/CLoadableOptions.h>

#include "vofusion/core/triangle_mesh.h"

namespace vofusion {

struct MeshCleanParams : public mrpt::config::CLoadableOptions {
  // Repair: weld vertices, drop degenerate/duplicate faces, stitch borders, make it manifold.
  bool repair = true;
  double weld_distance = 0.0;          // m; vertices closer than this are merged (0: exact duplicates only)
  // Connected components smaller than EITHER threshold are removed (0 disables that test).
  int min_component_faces = 50;        // faces
  double min_component_area = 0.0;     // m^2
  // Holes whose border is at most this long AND has at most this many edges are filled.
  double max_hole_perimeter = 0.3;     // m (0: fill no holes)
  int max_hole_edges = 200;            // edges
  bool hole_fairing = true;            // smooth (fair) the patch; falls back to a flat refined patch
  // Simplification by edge collapse (0 disables each stop criterion; all 0: no simplification).
  // max_simplify_error > 0: quadric collapse by meshoptimizer (quadric_simplify.h), stopping before the
  // first collapse whose error exceeds it, or at target_faces if that comes first. Otherwise shortest
  // edges first (CGAL), stopping at target_faces or target_edge_length (length order only).
  double max_simplify_error = 0.003;   // m: half a 6 mm voxel (share/mesh.ini)
  int target_faces = 0;                // faces
  double target_edge_length = 0.0;     // m; stop when no edge is shorter than this
  // Smoothing: curvature-flow shape smoothing, then tangential relaxation (triangle quality).
  int smooth_iterations = 0;           // iterations of PMP::smooth_shape (0: off)
  double smooth_time = 1e-4;           // s-like step of the mean-curvature flow per iteration
  int relax_iterations = 0;            // iterations of PMP::tangential_relaxation (0: off)
  // If the result is closed, orient every component outward: off, since marching cubes already faces
  // the free space the cameras saw, which for a room scanned all round is its inside.
  bool orient_closed_outward = false;
  bool recompute_normals = true;       // write fresh area-weighted vertex normals
  // vofusion only: marching cubes, repair and simplification one block of region_bricks^3 bricks at
  // a time (seams kept), the other steps on the welded result; 0: the whole world at once.
  int region_bricks = 32;              // bricks (8 voxels each) per region edge (measured: share/mesh.ini)

  void loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& section) override;
  void saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& section) const override;
};

struct MeshCleanStep {
  std::string name;                    // "repair", "components", "holes", "simplify", "smooth"
  std::size_t vertices_before = 0, faces_before = 0;
  std::size_t vertices_after = 0, faces_after = 0;
  double seconds = 0.0;                // wall time
};

// Distance from points sampled on one mesh to the surface of another.
struct MeshDistance {
  std::size_t samples = 0;
  double mean = 0.0, max = 0.0;        // m
};

// What the simplify step did (ran = false when no simplification was asked for).
struct MeshSimplification {
  bool ran = false;
  std::size_t faces_before = 0, faces_after = 0;
  MeshDistance distance;               // simplified -> the mesh just before simplification
  double seconds = 0.0;                // simplification plus the distance measurement
};

struct MeshCleanReport {
  bool success = false;
  std::string failure;                 // why, when !success (the mesh is then left as it was given)
  std::string warning;                 // a part left undone while the rest succeeded (regions unsimplified)
  std::vector<MeshCleanStep> steps;
  std::size_t duplicate_vertices_merged = 0;
  std::size_t degenerate_faces_removed = 0;  // combinatorial (repeated vertex) + geometric (zero area)
  std::size_t duplicate_faces_removed = 0;
  std::size_t border_edges_stitched = 0;
  std::size_t non_manifold_vertices_split = 0;
  std::size_t components_removed = 0, components_kept = 0;
  std::size_t holes_filled = 0, holes_left = 0;  // left: larger than the bounds, a small piece's outline, or filling failed
  std::size_t holes_not_faired = 0;              // filled flat: fairing failed (hole_fairing on)
  std::size_t border_cycles_after = 0;           // remaining boundary loops (0: closed)
  bool closed = false;                 // watertight (no border edges)
  bool manifold = false;               // no non-manifold vertex
  double area = 0.0;                   // m^2, final surface area
  MeshSimplification simplification;

  std::string toJson() const;          // one JSON object
};

// Cleans `mesh` in place. On failure (e.g. an internal CGAL error) returns success=false and leaves
// `mesh` unchanged. `unsimplified`, when given, receives the mesh as it was just before
// simplification (repaired, fragments removed, holes filled; not smoothed).
MeshCleanReport cleanMesh(TriangleMesh& mesh, const MeshCleanParams& params, TriangleMesh* unsimplified = nullptr);

// cleanMesh for regions that simplifyRegion repaired each on its own, welded at their seams and
// oriented alike (marching cubes orients every region by the TSDF's sign): the mesh is valid but
// where regions meet, so the repair adds its faces one by one instead of through a polygon soup
// (loop scene: 1.6 M faces repaired in a third of the time, the run's peak ~200 MiB lower). A repeated
// face is dropped; one that would make an edge or vertex non-manifold gets corners of its own,
// joined back by stitching where the mesh stays manifold. With repair off or weld_distance > 0 this
// is cleanMesh.
MeshCleanReport cleanWeldedRegions(TriangleMesh& mesh, const MeshCleanParams& params);

// The first half of cleanMesh for one region of a mesh built region by region: repair, removal of
// small components that touch no seam (those continuing into a neighbour are judged whole, after
// welding), then simplification. Vertices flagged in `seam` (shared with a neighbouring region) are
// neither moved nor removed, so the simplified regions weld exactly; `seam` is updated to the
// result's vertices. The distance is measured on faces/8 samples (the regions together about as
// many as cleanMesh takes). No holes, smoothing or normals: cleanMesh does those on the welded mesh.
MeshCleanReport simplifyRegion(TriangleMesh& mesh, std::vector<std::uint8_t>& seam, const MeshCleanParams& params);

// Mean and max distance from `samples` points spread over `from` by area (a fixed seed: the same
// meshes give the same figures) to the surface of `to`.
MeshDistance meshDistance(const TriangleMesh& from, const TriangleMesh& to, std::size_t samples = 100000);

}  // namespace vofusion
