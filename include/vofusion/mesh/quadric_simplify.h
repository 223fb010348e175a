#pragma once
// Quadric edge collapse (Garland-Heckbert) by meshoptimizer: rpy_first100's regions in 0.9 s of CPU,
// where CGAL's edge_collapse took 16.8 s (docs/mesh.md).
#include <cstdint>
#include <vector>

#include "vofusion/core/triangle_mesh.h"

namespace vofusion {

// Collapses edges of `mesh` while the next collapse moves the surface by at most `max_error` m
// (meshoptimizer's error: the kept vertex's area-weighted RMS distance to the planes of the faces merged
// into it), and while more than `target_faces` faces are left (0: no face budget). Every collapse
// keeps one of its two vertices where it was: positions, colours and normals are the input's.
// Vertices flagged in `locked` (one flag per vertex, or empty) are neither moved nor removed; other
// border vertices move only along their border. The result's vertices are compacted and `locked`
// follows them. Returns false, with `mesh` and `locked` untouched, when a locked vertex would be lost;
// throws std::invalid_argument for a face naming a vertex past the end (mesh untouched).
bool simplifyByQuadrics(TriangleMesh& mesh, double max_error, std::size_t target_faces, std::vector<std::uint8_t>& locked);

}  // namespace vofusion
