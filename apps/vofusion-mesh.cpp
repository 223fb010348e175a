// vofusion-mesh: clean up any triangle mesh PLY with the [mesh] post-processing of vofusion.
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/cli.h"
#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/progress.h"
#include "vofusion/core/trajectory.h"
#include "vofusion/mesh/mesh_clean.h"
#include "vofusion/mesh/mesh_io.h"
#include "vofusion/pipeline/run_outputs.h"
#include "vofusion/scene/scene_export.h"

using namespace vofusion;

namespace {

const char* kUsage =
    "usage: vofusion-mesh <in.ply> <out.ply|out.obj|out.stl> [--config f.ini] [--report r.json]\n"
    "                     [--png view.png] [--scene view.3Dscene] [--trajectory traj.txt]\n"
    "                     [--full full.ply] [--distance-to ref.ply]\n"
    "       vofusion-mesh --dump-config      (print the [mesh] defaults)\n"
    "Repairs the mesh, removes small fragments, fills small holes, simplifies it to an error target\n"
    "(quadric edge collapse: max_simplify_error is aimed at, not a bound on every point) and optionally\n"
    "smooths it (CGAL), keeping vertex colours. Parameters: section [mesh] (see\n"
    "share/mesh.ini). The output format follows the extension: PLY, OBJ (colours as \"v x y z r g b\")\n"
    "or binary STL (no colours). --full also writes the mesh before simplification; --distance-to\n"
    "prints the mean and max distance from the result to another mesh (e.g. the raw one).\n"
    "--png renders the result off-screen, --scene writes an MRPT scene for SceneViewer3D; both show\n"
    "the camera path of --trajectory (TUM format, camera-to-world) when given.\n";

// Each output a file of its own, checked before the cleaning: one named twice would be written over.
void requireDistinctOutputs(const CommandLine& cl, const std::string& out) {
  std::vector<std::string> seen = {out};
  for (const char* option : {"--full", "--report", "--png", "--scene"}) {
    const auto path = cl.value(option);
    if (!path) continue;
    for (const std::string& earlier : seen)
      if (samePath(earlier, *path)) throw InputError(*path, "named twice as an output");
    seen.push_back(*path);
  }
}

// out.ply and the asked-for --full, --png, --scene and --report, all or none (an output that cannot be
// written leaves the earlier ones as they were).
void writeOutputs(const CommandLine& cl, const std::string& out, const TriangleMesh& mesh, const TriangleMesh& full,
                  const Trajectory& traj, const MeshCleanReport& report) {
  AtomicFileSet outputs;
  outputs.write(out, [&](const std::string& tmp) { writeMesh(tmp, mesh, meshFormatOf(out)); });
  if (const auto f = cl.value("--full"))
    outputs.write(*f, [&](const std::string& tmp) { writeMesh(tmp, full, meshFormatOf(*f)); });
  if (const auto png = cl.value("--png"))
    outputs.write(*png, [&](const std::string& tmp) { renderMeshPng(tmp, mesh, traj.empty() ? nullptr : &traj); });
  if (const auto scene = cl.value("--scene"))
    outputs.write(*scene, [&](const std::string& tmp) { exportScene(tmp, mesh, traj, nullptr, CameraIntrinsics{}); });
  // With the outputs it describes: a scene that could not be written left a report of success beside
  // the earlier out.ply.
  if (const auto rp = cl.value("--report"))
    outputs.write(*rp, [&](const std::string& tmp) { writeFileAtomically(tmp, report.toJson() + "\n"); });
  outputs.commit();
}

// What the cleaning did, in a line (and one for the simplification).
void printCleaning(std::size_t vertices_before, std::size_t faces_before, const TriangleMesh& mesh, const MeshCleanReport& report) {
  double seconds = 0;
  for (const auto& s : report.steps) seconds += s.seconds;
  std::fprintf(stderr,
               "%zu vertices / %zu faces -> %zu / %zu in %.2f s; %zu fragments removed, %zu holes filled (%zu left), "
               "%s, %s\n",
               vertices_before, faces_before, mesh.vertices.size(), mesh.faces.size(), seconds, report.components_removed,
               report.holes_filled, report.holes_left, report.closed ? "closed" : "open",
               report.manifold ? "manifold" : "NOT manifold");
  if (const auto& s = report.simplification; s.ran)
    std::fprintf(stderr, "simplified %zu -> %zu faces (%.1f %%) in %.2f s; distance to the unsimplified mesh mean %.4f m, max %.4f m\n",
                 s.faces_before, s.faces_after, s.faces_before ? 100.0 * s.faces_after / s.faces_before : 0.0, s.seconds,
                 s.distance.mean, s.distance.max);
}

int body(int argc, char** argv) {
  const CommandLine cl(argc, argv, {"--config", "--report", "--png", "--scene", "--trajectory", "--full", "--distance-to"}, {"--dump-config", "--help"});
  MeshCleanParams params;
  if (cl.flag("--help")) { std::cout << kUsage; return 0; }
  if (cl.flag("--dump-config")) { std::cout << dumpConfig({{"mesh", &params}}); return 0; }
  if (cl.positional().size() != 2) throw InputError("usage", "expected <in.ply> <out.ply> (see --help)");
  const std::string in = cl.positional()[0], out = cl.positional()[1];
  meshFormatOf(out);  // a bad extension fails now, not after the cleaning
  if (const auto full = cl.value("--full")) meshFormatOf(*full);
  requireDistinctOutputs(cl, out);

  if (const auto config = cl.value("--config")) {
    const auto cfg = loadConfig(*config);
    // Only [mesh] is read. The keys of vofusion's other sections are checked for typos; other sections
    // (a vofusion-grab config's sensor sections) are not this app's, so a misspelt section name passes.
    checkKnownSections(cfg, *config, vofusionConfigSections());
    loadNamingOrigin(*config, [&] { params.loadFromConfigFile(cfg, "mesh"); });
  }

  if (cl.value("--trajectory") && !cl.value("--png") && !cl.value("--scene"))
    throw InputError("usage", "--trajectory is drawn in --png or --scene: give one of them");
  Trajectory traj;
  if (const auto t = cl.value("--trajectory")) traj = readTumTrajectory(*t, StampOrder::AsWritten);

  TriangleMesh mesh = readPly(in);
  if (mesh.faces.empty()) throw InputError(in, "holds no faces (a point cloud?): nothing to clean");
  const auto ref_path = cl.value("--distance-to");
  const TriangleMesh ref = ref_path ? readPly(*ref_path) : TriangleMesh();
  if (ref_path && ref.faces.empty())
    throw InputError(*ref_path, "holds no faces (a point cloud?): no surface to measure the distance to");
  const std::size_t v0 = mesh.vertices.size(), f0 = mesh.faces.size();
  TriangleMesh full;
  const MeshCleanReport report = cleanMesh(mesh, params, cl.value("--full") ? &full : nullptr);
  const auto rp = cl.value("--report");
  if (!report.success) {
    if (rp) writeFileAtomically(*rp, report.toJson() + "\n");  // why it failed, where nothing else is written
    throw std::runtime_error(in + ": mesh post-processing failed: " + report.failure);
  }
  if (mesh.faces.empty()) {
    const std::string why = "no face is left (fragments below [mesh] min_component_faces / min_component_area, "
                            "degenerate or duplicate faces)";
    // Cleaned in place (out is in): an empty result would have replaced the only copy of the mesh.
    if (samePath(in, out)) throw InputError(in, why + "; the input is kept, not replaced by an empty mesh");
    printWarning(in + ": " + why + "; " + out + " is empty");
  }
  writeOutputs(cl, out, mesh, full, traj, report);
  printCleaning(v0, f0, mesh, report);
  if (ref_path) {
    const MeshDistance d = meshDistance(mesh, ref);
    if (d.samples == 0)  // no face left to sample (or none of area): no distance, not a perfect match
      std::printf("distance to %s: none (the result has no face to measure from)\n", ref_path->c_str());
    else
      std::printf("distance to %s: mean %.6f m, max %.6f m (%zu samples)\n", ref_path->c_str(), d.mean, d.max, d.samples);
  }
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  return runApp("vofusion-mesh", body, argc, argv);
}
