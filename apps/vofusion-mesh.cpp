// vofusion-mesh: clean up any triangle mesh PLY with the [mesh] post-processing of vofusion.
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include <mrpt/config/CConfigFileMemory.h>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/cli.h"
#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/trajectory.h"
#include "vofusion/mesh/mesh_clean.h"
#include "vofusion/mesh/triangle_mesh.h"
#include "vofusion/scene/scene_export.h"

using namespace vofusion;

namespace {

const char* kUsage =
    "usage: vofusion-mesh <in.ply> <out.ply> [--config f.ini] [--report r.json]\n"
    "                     [--png view.png] [--scene view.3Dscene] [--trajectory traj.txt]\n"
    "       vofusion-mesh --dump-config      (print the [mesh] defaults)\n"
    "Repairs the mesh, removes small fragments, fills small holes and optionally simplifies and\n"
    "smooths it (CGAL), keeping vertex colours. Parameters: section [mesh] (see share/mesh.ini).\n"
    "--png renders the result off-screen, --scene writes an MRPT scene for SceneViewer3D; both show\n"
    "the camera path of --trajectory (TUM format, camera-to-world) when given.\n";

int body(int argc, char** argv) {
  const CommandLine cl(argc, argv, {"--config", "--report", "--png", "--scene", "--trajectory"}, {"--dump-config", "--help"});
  MeshCleanParams params;
  if (cl.flag("--help")) { std::cout << kUsage; return 0; }
  if (cl.flag("--dump-config")) { std::cout << dumpConfig({{"mesh", &params}}); return 0; }
  if (cl.positional().size() != 2) throw InputError("usage", "expected <in.ply> <out.ply> (see --help)");
  const std::string in = cl.positional()[0], out = cl.positional()[1];

  if (const auto config = cl.value("--config")) {
    const auto cfg = loadConfig(*config);
    // A full vofusion config is fine here: only [mesh] is read, and checked for unknown keys.
    mrpt::config::CConfigFileMemory mesh_only;
    std::vector<std::string> keys;
    cfg.getAllKeys("mesh", keys);
    for (const auto& k : keys) mesh_only.write("mesh", k, cfg.read_string("mesh", k, ""));
    checkConfigKeys(mesh_only, *config, {{"mesh", &params}});
    params.loadFromConfigFile(cfg, "mesh");
  }

  Trajectory traj;
  if (const auto t = cl.value("--trajectory")) traj = readTumTrajectory(*t);

  TriangleMesh mesh = readPly(in);
  const std::size_t v0 = mesh.vertices.size(), f0 = mesh.faces.size();
  const MeshCleanReport report = cleanMesh(mesh, params);
  if (const auto rp = cl.value("--report")) writeFileAtomically(*rp, report.toJson() + "\n");
  if (!report.success) throw std::runtime_error(in + ": mesh post-processing failed: " + report.failure);
  writePly(out, mesh);
  if (const auto png = cl.value("--png")) renderMeshPng(*png, mesh, traj.empty() ? nullptr : &traj);
  if (const auto scene = cl.value("--scene")) exportScene(*scene, mesh, traj, nullptr, CameraIntrinsics{});
  double seconds = 0;
  for (const auto& s : report.steps) seconds += s.seconds;
  std::fprintf(stderr,
               "%zu vertices / %zu faces -> %zu / %zu in %.2f s; %zu fragments removed, %zu holes filled (%zu left), "
               "%s, %s\n",
               v0, f0, mesh.vertices.size(), mesh.faces.size(), seconds, report.components_removed,
               report.holes_filled, report.holes_left, report.closed ? "closed" : "open",
               report.manifold ? "manifold" : "NOT manifold");
  return 0;
}

}  // namespace

int main(int argc, char** argv) { return runApp("vofusion-mesh", body, argc, argv); }
