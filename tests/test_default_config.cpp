// share/vofusion.ini documents every parameter of every stage: it must hold exactly the defaults.
#include <mrpt/config/CConfigFileMemory.h>

#include "support.h"
#include "vofusion/core/config.h"
#include "vofusion/mesh/mesh_clean.h"
#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/pipeline/run_outputs.h"

using namespace vofusion;

namespace {
std::string trim(const std::string& s) {
  const auto b = s.find_first_not_of(" \t");
  const auto e = s.find_last_not_of(" \t");
  return b == std::string::npos ? "" : s.substr(b, e - b + 1);
}
}  // namespace

TEST(DefaultConfig, ShareFileHoldsEveryKeyWithItsDefault) {
  const std::string path = test::shareDir() + "/vofusion.ini";
  const OutputParams out;
  const MeshCleanParams mesh;
  auto sections = reconstructionConfigSections();
  sections.push_back({"mesh", &mesh});
  sections.push_back({"output", &out});
  const auto file = loadConfig(path);
  EXPECT_NO_THROW(checkConfigKeys(file, path, sections));

  mrpt::config::CConfigFileMemory defaults;
  defaults.setContent(dumpConfig(sections));
  std::vector<std::string> names;
  defaults.getAllSections(names);
  int checked = 0;
  for (const auto& s : names) {
    std::vector<std::string> keys;
    defaults.getAllKeys(s, keys);
    for (const auto& k : keys) {
      const std::string want = trim(defaults.read_string(s, trim(k), "", false));
      const std::string have = trim(file.read_string(s, trim(k), "<missing>", false));
      EXPECT_EQ(have, want) << "[" << s << "] " << k << ": run scripts/update-default-config";
      ++checked;
    }
  }
  EXPECT_GT(checked, 40);
}
