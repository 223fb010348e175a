#pragma once
// Marching cubes (Lorensen & Cline 1987) over a sparse set of TSDF bricks: one indexed mesh with
// shared vertices (each grid edge crossing becomes exactly one vertex), vertex colours and
// area-weighted vertex normals. Cells touching unobserved or fully truncated voxels are skipped.
#include <vector>

#include "vofusion/fusion/voxel_brick.h"
#include "vofusion/mesh/triangle_mesh.h"

namespace vofusion::fusion {

// voxel_size in metres; voxel (i,j,k) sits at world (i,j,k) * voxel_size. min_weight: frames.
TriangleMesh marchingCubes(const std::vector<BrickRef>& bricks, float voxel_size, int min_weight = 1);

}  // namespace vofusion::fusion
