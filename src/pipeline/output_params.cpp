// [output] INI section: one table lists every key, so loading and saving can never disagree.
// Also the list of a vofusion config's sections, [output] among them.
#include <mrpt/config/CConfigFileBase.h>

#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"
#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/pipeline/run_outputs.h"

namespace vofusion {

namespace {
// Every [output] key, once: loading and saving both walk this list.
std::vector<ConfigKey> outputKeys(OutputParams& p) {
  return {
      {"write_rawlog", &p.write_rawlog, "poses.rawlog: observations + odometry actions + fused poses"},
      {"mesh", &p.write_mesh, "mesh.ply, mesh.png, the mesh in scene.3Dscene; false: path and summary only (benchmarks)"},
      {"save_raw_mesh", &p.save_raw_mesh, "also mesh_raw.ply (marching cubes before CGAL post-processing)"},
      {"clean_mesh", &p.clean_mesh, "CGAL post-processing with the [mesh] parameters"},
      {"save_full_mesh", &p.save_full_mesh, "also mesh_full.ply (post-processed but not simplified)"},
      {"frustum_every", &p.frustum_every, "frames between camera frustums in scene.3Dscene", 1.0, 100000.0},
      {"image_width", &p.image_width, "px, mesh.png (trajectory.png has its own fixed panels)", 64.0, 8192.0},
      {"image_height", &p.image_height, "px", 64.0, 8192.0},
      {"rpe_delta", &p.rpe_delta, "s, pose-pair spacing of the relative pose error in summary.json", 0.01, 100.0},
  };
}
}  // namespace

void OutputParams::loadFromConfigFile(const mrpt::config::CConfigFileBase& c, const std::string& s) {
  loadKeys(c, s, outputKeys(*this));  // the table's ranges are the ones checked (and the ones --dump-config shows)
  // A mesh file asked for beside no mesh at all was left out without a word.
  for (const auto& [key, on] : {std::pair{"save_raw_mesh", save_raw_mesh}, std::pair{"save_full_mesh", save_full_mesh}})
    if (on && !write_mesh) throw InputError("[" + s + "] " + key, "takes effect with mesh = true only (mesh = false writes no mesh)");
}

void OutputParams::saveToConfigFile(mrpt::config::CConfigFileBase& c, const std::string& s) const {
  saveKeys(c, s, outputKeys(const_cast<OutputParams&>(*this)));
}

std::vector<ConfigSection> vofusionConfigSections() {
  static const MeshCleanParams mesh;
  static const OutputParams output;
  auto sections = reconstructionConfigSections();
  sections.push_back({"mesh", &mesh});
  sections.push_back({"output", &output});
  return sections;
}

}  // namespace vofusion
