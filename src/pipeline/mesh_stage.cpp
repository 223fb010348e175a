#include "mesh_stage.h"

#include <functional>
#include <memory>

#include "run_summary.h"
#include "vofusion/core/heap.h"
#include "vofusion/core/progress.h"
#include "vofusion/mesh/mesh_io.h"
#include "vofusion/pipeline/mesh_by_region.h"
#include "vofusion/pipeline/region_premesher.h"

using nlohmann::json;

namespace vofusion {

namespace {
// What the post-processing left undone, in one line beside summary.json's mesh_clean.
void sayWhatCleaningLeft(const MeshCleanReport& r) {
  if (!r.success) printWarning("mesh post-processing failed (the mesh is written as it was before): " + r.failure);
  if (!r.warning.empty()) printWarning("mesh post-processing: " + r.warning);
}
// One progress bar per pass of the meshing by region ("finding fragments", then "repair, simplify").
class PassProgress {
 public:
  void operator()(int pass, std::size_t done, std::size_t regions) {
    if (pass != pass_) {
      finish();
      shown_ = std::make_unique<Progress>(pass == 1 ? "meshing [finding fragments]" : "meshing [repair, simplify]", regions,
                                          "regions");
      pass_ = pass;
    }
    shown_->update(done);
  }
  void finish() {
    if (shown_) shown_->finish();
  }

 private:
  std::unique_ptr<Progress> shown_;
  int pass_ = 0;
};

// The map meshed, repaired and simplified one region at a time (mesh_by_region.h), its statistics into
// the summary; `streamed_raw`: mesh_raw.ply's line, when it was streamed.
TriangleMesh meshRegionByRegion(Reconstruction& rec, const OutputParams& p, const MeshCleanParams& mesh_params, json& s,
                                StagedOutputs& out, RegionPremesher* premeshed, const std::function<void(std::size_t)>& release_map,
                                std::string& streamed_raw) {
  const auto source = [&](const std::function<void(fusion::RegionMesh&)>& sink) {
    rec.extractMeshByRegion(mesh_params.region_bricks, sink);
  };
  PassProgress progress;
  RegionMeshResult r = meshByRegion(source, mesh_params, p.save_raw_mesh ? out.path("mesh_raw.ply") : "", std::ref(progress),
                                    release_map, premeshed ? premeshed->lookup() : PremeshedLookup());
  if (premeshed)
    s["mesh_while_tracking"] = {{"regions_meshed", premeshed->regionsMeshed()},
                                {"regions_reused", r.regions_premeshed},
                                {"regions_failed", premeshed->regionsFailed()}};
  if (premeshed && premeshed->stoppedWithoutMemory()) s["mesh_while_tracking"]["stopped"] = "no memory to follow the volume";
  progress.finish();
  s["mesh_raw"] = {{"vertices", r.raw_vertices}, {"faces", r.raw_faces}, {"regions", r.regions}};
  if (p.save_raw_mesh) streamed_raw = std::to_string(r.raw_faces) + " faces, streamed region by region";
  s["mesh_clean"] = json::parse(r.report.toJson());
  sayWhatCleaningLeft(r.report);
  if (r.report.simplification.ran) s["mesh_simplification"] = simplificationJson(r.report.simplification, r.raw_faces);
  return std::move(r.mesh);
}
}  // namespace

bool meshesByRegion(const OutputParams& p, const MeshCleanParams& mesh_params) {
  return p.write_mesh && p.clean_mesh && mesh_params.region_bricks > 0 && !p.save_full_mesh;
}

TriangleMesh writeMeshes(Reconstruction& rec, const OutputParams& p, const MeshCleanParams& mesh_params, json& s,
                         StagedOutputs& out, RegionPremesher* premeshed,
                         const std::function<void(std::size_t)>& map_meshed) {
  // Once meshed the map goes, before the welded mesh's repair, the scene and the pictures.
  const auto release_map = [&](std::size_t faces) {
    if (premeshed) premeshed->discard();  // the regions not taken: none is used after this
    if (rec.mapReleased()) return;
    rec.releaseMap();
    returnFreedHeap();
    if (map_meshed) map_meshed(faces);
  };
  TriangleMesh mesh;
  std::string streamed_raw;  // logged after mesh.ply, whose line then carries the meshing time
  // Region by region unless the unsimplified whole (mesh_full.ply) is asked for.
  const bool by_region = meshesByRegion(p, mesh_params);
  if (by_region) {
    mesh = meshRegionByRegion(rec, p, mesh_params, s, out, premeshed, release_map, streamed_raw);
  } else {
    mesh = rec.extractMesh();
    s["mesh_raw"] = meshJson(mesh);
  }
  release_map(mesh.faces.size());
  if (!by_region && p.save_raw_mesh) {
    writePly(out.path("mesh_raw.ply"), mesh);
    out.wrote("mesh_raw.ply", std::to_string(mesh.faces.size()) + " faces");
  }
  TriangleMesh full;  // post-processed, not simplified
  bool full_made = false;
  if (!by_region && p.clean_mesh && !mesh.empty()) {
    const std::size_t raw_faces = mesh.faces.size();
    const MeshCleanReport report = cleanMesh(mesh, mesh_params, p.save_full_mesh ? &full : nullptr);
    s["mesh_clean"] = json::parse(report.toJson());
    sayWhatCleaningLeft(report);
    if (report.simplification.ran) s["mesh_simplification"] = simplificationJson(report.simplification, raw_faces);
    full_made = report.success;
  }
  if (p.save_full_mesh) {
    // Not post-processed (clean_mesh off, nothing meshed, or post-processing failed): the mesh as it
    // came, as mesh.ply is (it was written empty, or not at all).
    const TriangleMesh& before = full_made ? full : mesh;
    writePly(out.path("mesh_full.ply"), before);
    out.wrote("mesh_full.ply", std::to_string(before.faces.size()) + " faces" + (full_made ? "" : ", not post-processed"));
  }
  s["mesh"] = meshJson(mesh);
  writePly(out.path("mesh.ply"), mesh);
  out.wrote("mesh.ply", std::to_string(mesh.faces.size()) + " faces");
  if (!streamed_raw.empty()) out.wrote("mesh_raw.ply", streamed_raw);
  return mesh;
}

}  // namespace vofusion
