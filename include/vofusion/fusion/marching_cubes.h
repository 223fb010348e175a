#pragma once
// Marching cubes (Lorensen & Cline 1987) over a sparse set of TSDF bricks: one indexed mesh with
// shared vertices (each grid edge crossing becomes exactly one vertex), vertex colours and
// area-weighted vertex normals. Cells touching unobserved or fully truncated voxels are skipped.
#include <functional>
#include <vector>

#include "vofusion/fusion/voxel_brick.h"
#include "vofusion/mesh/triangle_mesh.h"

namespace vofusion::fusion {

// voxel_size in metres; voxel (i,j,k) sits at world (i,j,k) * voxel_size. min_weight: frames.
TriangleMesh marchingCubes(const std::vector<BrickRef>& bricks, float voxel_size, int min_weight = 1);

// The brick at a world brick coordinate: a pointer to one kept elsewhere, or `scratch` filled in.
using BrickFetch = std::function<const Brick*(const Eigen::Vector3i& coord, Brick& scratch)>;
// The same mesh as marchingCubes over all `coords`, built region by region (region_bricks^3 bricks
// each, plus their +1 neighbours): only one region's bricks are fetched at a time, so a world model
// on disk never has to be in RAM whole. Vertices on region borders are welded.
TriangleMesh marchingCubesStreamed(const std::vector<Eigen::Vector3i>& coords, const BrickFetch& fetch,
                                   float voxel_size, int min_weight = 1, int region_bricks = 16);

}  // namespace vofusion::fusion
