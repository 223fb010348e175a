#include "vofusion/core/config.h"

#include <algorithm>
#include <filesystem>
#include <fstream>
#include <sstream>

#include "vofusion/core/errors.h"

namespace vofusion {

mrpt::config::CConfigFileMemory loadConfig(const std::string& path) {
  mrpt::config::CConfigFileMemory cfg;
  if (path.empty()) return cfg;
  if (!std::filesystem::is_regular_file(path)) throw InputError(path, "config file not found");
  std::ifstream f(path);
  if (!f) throw InputError(path, "cannot read config file");
  std::ostringstream ss;
  ss << f.rdbuf();
  cfg.setContent(ss.str());
  return cfg;
}

static mrpt::config::CConfigFileMemory defaultsOf(const std::vector<ConfigSection>& known) {
  mrpt::config::CConfigFileMemory mem;
  for (const auto& [section, params] : known) params->saveToConfigFile(mem, section);
  return mem;
}

void checkConfigKeys(const mrpt::config::CConfigFileBase& user, const std::string& origin,
                     const std::vector<ConfigSection>& known) {
  const auto defaults = defaultsOf(known);
  std::vector<std::string> sections;
  user.getAllSections(sections);
  for (const auto& s : sections) {
    std::vector<std::string> keys;
    user.getAllKeys(s, keys);
    if (keys.empty()) continue;
    if (!defaults.sectionExists(s)) throw InputError(origin, "unknown section [" + s + "]");
    std::vector<std::string> valid;
    defaults.getAllKeys(s, valid);
    for (const auto& k : keys)
      if (std::find(valid.begin(), valid.end(), k) == valid.end())
        throw InputError(origin, "unknown key '" + k + "' in section [" + s + "]");
  }
}

std::string dumpConfig(const std::vector<ConfigSection>& known) { return defaultsOf(known).getContent(); }

}  // namespace vofusion
