#pragma once
// The run's meshing stage. Private to src/pipeline/.
#include <functional>

#include <nlohmann/json.hpp>

#include "vofusion/core/triangle_mesh.h"
#include "vofusion/mesh/mesh_clean.h"
#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/pipeline/run_outputs.h"
#include "staged_outputs.h"

namespace vofusion {

class RegionPremesher;

// Whether writeMeshes meshes region by region (mesh.ply cleaned, regions on, no mesh_full.ply).
bool meshesByRegion(const OutputParams& params, const MeshCleanParams& mesh_params);

// Meshes the map (region by region unless mesh_full.ply is asked for), releases it, and writes
// mesh_raw.ply / mesh_full.ply / mesh.ply as asked; fills the mesh entries of s. Regions `premeshed`
// made during the run are taken where they are still what the map gives. `map_meshed` is called at most
// once, when the map is meshed and released, with the faces of the mesh about to be cleaned: before the
// welded mesh's one-core repair (region by region), or before the whole mesh's cleaning.
TriangleMesh writeMeshes(Reconstruction& rec, const OutputParams& params, const MeshCleanParams& mesh_params,
                         nlohmann::json& s, StagedOutputs& out, RegionPremesher* premeshed = nullptr,
                         const std::function<void(std::size_t faces)>& map_meshed = {});

}  // namespace vofusion
