// vofusion-mesh: clean up any triangle mesh PLY with the [mesh] post-processing of vofusion.
#include <cstdio>
#include <iostream>
#include <string>
#include <vector>

#include <mrpt/config/CConfigFileMemory.h>

#include "vofusion/core/atomic_file.h"
#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"
#include "vofusion/mesh/mesh_clean.h"
#include "vofusion/mesh/triangle_mesh.h"

using namespace vofusion;

static const char* kUsage =
    "usage: vofusion-mesh <in.ply> <out.ply> [--config f.ini] [--report r.json]\n"
    "       vofusion-mesh --dump-config      (print the [mesh] defaults)\n"
    "Repairs the mesh, removes small fragments, fills small holes and optionally simplifies and\n"
    "smooths it (CGAL), keeping vertex colours. Parameters: section [mesh] (see share/mesh.ini).\n";

struct UsageError : std::runtime_error {
  using std::runtime_error::runtime_error;
};

int main(int argc, char** argv) {
  try {
    std::vector<std::string> pos;
    std::string config, report_path;
    MeshCleanParams params;
    for (int i = 1; i < argc; ++i) {
      const std::string a = argv[i];
      const auto value = [&]() -> std::string {
        if (i + 1 >= argc) throw UsageError(a + " needs a value");
        return argv[++i];
      };
      if (a == "--config") config = value();
      else if (a == "--report") report_path = value();
      else if (a == "--dump-config") { std::cout << dumpConfig({{"mesh", &params}}); return 0; }
      else if (a == "-h" || a == "--help") { std::cout << kUsage; return 0; }
      else if (!a.empty() && a[0] == '-') throw UsageError("unknown option " + a);
      else pos.push_back(a);
    }
    if (pos.size() != 2) throw UsageError("expected <in.ply> <out.ply>");

    if (!config.empty()) {
      const auto cfg = loadConfig(config);
      // A full vofusion config is fine here: only [mesh] is read, and checked for unknown keys.
      mrpt::config::CConfigFileMemory mesh_only;
      std::vector<std::string> keys;
      cfg.getAllKeys("mesh", keys);
      for (const auto& k : keys) mesh_only.write("mesh", k, cfg.read_string("mesh", k, ""));
      checkConfigKeys(mesh_only, config, {{"mesh", &params}});
      params.loadFromConfigFile(cfg, "mesh");
    }

    TriangleMesh mesh = readPly(pos[0]);
    const std::size_t v0 = mesh.vertices.size(), f0 = mesh.faces.size();
    const MeshCleanReport report = cleanMesh(mesh, params);
    if (!report_path.empty()) writeFileAtomically(report_path, report.toJson() + "\n");
    if (!report.success) throw InputError(pos[0], "mesh post-processing failed: " + report.failure);
    writePly(pos[1], mesh);
    std::fprintf(stderr,
                 "%zu vertices / %zu faces -> %zu / %zu; %zu fragments removed, %zu holes filled (%zu left), "
                 "%s, %s\n",
                 v0, f0, mesh.vertices.size(), mesh.faces.size(), report.components_removed, report.holes_filled,
                 report.holes_left, report.closed ? "closed" : "open", report.manifold ? "manifold" : "NOT manifold");
    return 0;
  } catch (const UsageError& e) {
    std::cerr << "vofusion-mesh: " << e.what() << "\n" << kUsage;
    return 2;
  } catch (const InputError& e) {
    std::cerr << e.what() << "\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "vofusion-mesh: " << e.what() << "\n";
    return 1;
  }
}
