// Unknown keys and sections in user configs are errors, checked against the stages' own defaults.
#include <fstream>

#include <mrpt/config/CConfigFileBase.h>

#include "support.h"
#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"

using namespace vofusion;

namespace {
struct DemoParams : mrpt::config::CLoadableOptions {
  double voxel = 0.006;  // m
  int weight_cap = 64;   // frames
  void loadFromConfigFile(const mrpt::config::CConfigFileBase& c, const std::string& s) override {
    voxel = c.read_double(s, "voxel", voxel);
    weight_cap = c.read_int(s, "weight_cap", weight_cap);
  }
  void saveToConfigFile(mrpt::config::CConfigFileBase& c, const std::string& s) const override {
    c.write(s, "voxel", voxel);
    c.write(s, "weight_cap", weight_cap);
  }
};
}  // namespace

TEST(Config, KnownKeysPassAndLoad) {
  const std::string dir = test::tempDir("config_ok");
  std::ofstream(dir + "/a.ini") << "[kinfu]\nvoxel = 0.01\n";
  const auto cfg = loadConfig(dir + "/a.ini");
  DemoParams p;
  EXPECT_NO_THROW(checkConfigKeys(cfg, dir + "/a.ini", {{"kinfu", &p}}));
  p.loadFromConfigFile(cfg, "kinfu");
  EXPECT_DOUBLE_EQ(p.voxel, 0.01);
  EXPECT_EQ(p.weight_cap, 64);
}

// The message checkConfigKeys refuses `ini` with (empty: accepted).
std::string refusal(const std::string& path, const std::string& ini, const std::string& section) {
  std::ofstream(path) << ini;
  DemoParams p;
  try {
    checkConfigKeys(loadConfig(path), path, {{section, &p}});
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(Config, UnknownKeyNamesFileSectionAndKey) {
  const std::string dir = test::tempDir("config_bad");
  EXPECT_EQ(refusal(dir + "/a.ini", "[kinfu]\nvoxl = 0.01\n", "kinfu"), dir + "/a.ini: unknown key 'voxl' in section [kinfu]");
  EXPECT_NE(refusal(dir + "/b.ini", "[kinfoo]\nvoxel = 0.01\n", "kinfu"), "");
}

// An old config's retired key is refused, but says why and where the figures are.
TEST(Config, RetiredKeySaysItsValueIsFixedInCode) {
  const std::string dir = test::tempDir("config_retired");
  EXPECT_EQ(refusal(dir + "/a.ini", "[loop]\nmax_loop_chi2 = 22.5\n", "loop"),
            dir + "/a.ini: 'max_loop_chi2' in section [loop] is no longer a key: its value is fixed in code "
                  "(docs/loop-closure.md gives the figures); remove the line");
  EXPECT_EQ(refusal(dir + "/c.ini", "[kinfu]\nguess_margin = 0.8\n", "kinfu"),
            dir + "/c.ini: 'guess_margin' in section [kinfu] is no longer a key: its value is fixed in code "
                  "(docs/tracking.md gives the figures); remove the line");
  // The same name in another section is an ordinary unknown key.
  EXPECT_EQ(refusal(dir + "/b.ini", "[kinfu]\nmax_loop_chi2 = 22.5\n", "kinfu"),
            dir + "/b.ini: unknown key 'max_loop_chi2' in section [kinfu]");
}

TEST(Config, MissingFileIsError) { EXPECT_THROW(loadConfig("/nonexistent/x.ini"), InputError); }

TEST(Config, DumpHoldsEveryKey) {
  DemoParams p;
  const std::string text = dumpConfig({{"kinfu", &p}});
  EXPECT_NE(text.find("voxel"), std::string::npos);
  EXPECT_NE(text.find("weight_cap"), std::string::npos);
}
