#pragma once
// summary.json's parts: the run's counts, times and fusion statistics, error statistics, stage times,
// loop closure and each loop, mesh simplification. Private to src/pipeline/.
#include <cstddef>

#include <nlohmann/json.hpp>

#include "vofusion/core/triangle_mesh.h"
#include "vofusion/eval/trajectory_eval.h"
#include "vofusion/mesh/mesh_clean.h"
#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/pipeline/run_outputs.h"

namespace vofusion {

nlohmann::json statsJson(const ErrorStats& s);
nlohmann::json timesJson(const StageTimes& t, std::size_t frames);
nlohmann::json meshJson(const TriangleMesh& m);
// summary.json "loops": one entry per accepted loop; with ground truth, how far the loop's measured
// relative pose is from the truth's (what a loop is worth, whatever the tracker did).
nlohmann::json loopsJson(const loop::LoopCloser& lc, const Trajectory& ground_truth);
nlohmann::json pathSmoothingJson(const Reconstruction& rec);
nlohmann::json loopClosureJson(const loop::LoopCloser& lc, const Reconstruction& rec, std::size_t frames);
// Faces against the marching-cubes mesh; distances against the mesh just before simplification.
nlohmann::json simplificationJson(const MeshSimplification& s, std::size_t raw_faces);
// The run's counts, times and fusion statistics (the start of summary.json).
nlohmann::json runSummary(const Reconstruction& rec, const RunInfo& info);

}  // namespace vofusion
