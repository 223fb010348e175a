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

TEST(Config, UnknownKeyNamesFileSectionAndKey) {
  const std::string dir = test::tempDir("config_bad");
  std::ofstream(dir + "/a.ini") << "[kinfu]\nvoxl = 0.01\n";
  DemoParams p;
  try {
    checkConfigKeys(loadConfig(dir + "/a.ini"), dir + "/a.ini", {{"kinfu", &p}});
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), dir + "/a.ini: unknown key 'voxl' in section [kinfu]");
  }
  std::ofstream(dir + "/b.ini") << "[kinfoo]\nvoxel = 0.01\n";
  EXPECT_THROW(checkConfigKeys(loadConfig(dir + "/b.ini"), "b.ini", {{"kinfu", &p}}), InputError);
}

// An old config's retired key is refused, but says why and where the figures are.
TEST(Config, RetiredKeySaysItsValueIsFixedInCode) {
  const std::string dir = test::tempDir("config_retired");
  std::ofstream(dir + "/a.ini") << "[loop]\nmax_loop_chi2 = 22.5\n";
  DemoParams p;
  try {
    checkConfigKeys(loadConfig(dir + "/a.ini"), dir + "/a.ini", {{"loop", &p}});
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), dir + "/a.ini: 'max_loop_chi2' in section [loop] is no longer a key: its value is "
                                           "fixed in code (docs/loop-closure.md gives the figures); remove the line");
  }
  // The same name in another section is an ordinary unknown key.
  std::ofstream(dir + "/b.ini") << "[kinfu]\nmax_loop_chi2 = 22.5\n";
  try {
    checkConfigKeys(loadConfig(dir + "/b.ini"), "b.ini", {{"kinfu", &p}});
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "b.ini: unknown key 'max_loop_chi2' in section [kinfu]");
  }
}

TEST(Config, MissingFileIsError) { EXPECT_THROW(loadConfig("/nonexistent/x.ini"), InputError); }

TEST(Config, DumpHoldsEveryKey) {
  DemoParams p;
  const std::string text = dumpConfig({{"kinfu", &p}});
  EXPECT_NE(text.find("voxel"), std::string::npos);
  EXPECT_NE(text.find("weight_cap"), std::string::npos);
}
