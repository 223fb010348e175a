// Unknown keys and sections in user configs are errors, checked against the stages' own defaults.
#include <filesystem>
#include <fstream>
#include <tuple>

#include <mrpt/config/CConfigFileBase.h>
#include <mrpt/config/CConfigFileMemory.h>

#include "support.h"
#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"

using namespace vofusion;
namespace fs = std::filesystem;

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

// MRPT reads keys whatever their case ("Voxel" is voxel's value): the check takes them as MRPT does. It
// refused them as unknown keys, a typo's message for a key that is read.
TEST(Config, KeysInAnotherCaseAreTheKeysMrptReads) {
  const std::string dir = test::tempDir("config_case");
  EXPECT_EQ(refusal(dir + "/a.ini", "[kinfu]\nVoxel = 0.02\nWEIGHT_CAP = 9\n", "kinfu"), "");
  DemoParams p;
  p.loadFromConfigFile(loadConfig(dir + "/a.ini"), "kinfu");
  EXPECT_DOUBLE_EQ(p.voxel, 0.02);
  EXPECT_EQ(p.weight_cap, 9);
  EXPECT_EQ(refusal(dir + "/b.ini", "[kinfu]\nVoxl = 0.01\n", "kinfu"), dir + "/b.ini: unknown key 'Voxl' in section [kinfu]");
}

// Parameters that save a section beside their own, as [odometry] saves [star], [narf] and [motion].
struct NestedParams : DemoParams {
  int iterations = 500;
  void loadFromConfigFile(const mrpt::config::CConfigFileBase& c, const std::string& s) override {
    DemoParams::loadFromConfigFile(c, s);
    iterations = c.read_int("motion", "iterations", iterations);
  }
  void saveToConfigFile(mrpt::config::CConfigFileBase& c, const std::string& s) const override {
    DemoParams::saveToConfigFile(c, s);
    c.write("motion", "iterations", iterations);
  }
};

// A grabber's config is checked in our sections only, and those are all the sections our stages read:
// a typo in one a stage reads beside its own (vofusion-grab's [motion]) is refused like one in its own.
TEST(Config, KnownSectionsAreEverySectionTheStagesRead) {
  const std::string dir = test::tempDir("config_known_sections");
  const std::string path = dir + "/grab.ini";
  NestedParams p;
  std::ofstream(path) << "[OPENNI2]\ndriver = COpenNI2Sensor\nanything = 1\n[kinfu]\nvoxel = 0.01\n[motion]\niterations = 9\n";
  EXPECT_NO_THROW(checkKnownSections(loadConfig(path), path, {{"kinfu", &p}}));
  std::ofstream(path, std::ios::app) << "[motion]\niteratons = 9\n";
  try {
    checkKnownSections(loadConfig(path), path, {{"kinfu", &p}});
    ADD_FAILURE() << "a typo in [motion] passed";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), path + ": unknown key 'iteratons' in section [motion]");
  }
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
  // Retired on 2026-12-05: keys with no effect on a default run.
  for (const auto& [section, key, doc] : {std::tuple{"kinfu", "integrate_filtered", "tracking"}, std::tuple{"kinfu", "mark_step", "tracking"},
                                          std::tuple{"narf", "recursive_scale_reduction", "odometry"}})
    EXPECT_EQ(refusal(dir + "/d.ini", std::string("[") + section + "]\n" + key + " = 1\n", section),
              dir + "/d.ini: '" + key + "' in section [" + section + "] is no longer a key: its value is fixed in code (docs/" + doc +
                  ".md gives the figures); remove the line");
  // The same name in another section is an ordinary unknown key.
  EXPECT_EQ(refusal(dir + "/b.ini", "[kinfu]\nmax_loop_chi2 = 22.5\n", "kinfu"),
            dir + "/b.ini: unknown key 'max_loop_chi2' in section [kinfu]");
}

TEST(Config, MissingFileIsError) { EXPECT_THROW(loadConfig("/nonexistent/x.ini"), InputError); }

// MRPT's reader passed over lines it could not read, and the run went on with the defaults: a key
// without '=', an @include (no such directive in MRPT 2.5), an unclosed section, a binary file given as
// the config. Each is now a one-line error naming the file and the line; an unknown ${NAME} too (it
// named neither). A byte order mark, CRLF line ends, comments and MRPT's @define still read.
TEST(Config, ALineTheReaderCannotReadIsAnErrorNamingFileAndLine) {
  const std::string dir = test::tempDir("config_lines");
  const auto error = [&](const std::string& text) -> std::string {
    std::ofstream(dir + "/c.ini", std::ios::binary | std::ios::trunc) << text;
    try {
      loadConfig(dir + "/c.ini");
      return "";
    } catch (const InputError& e) {
      return e.what();
    }
  };
  const std::string at = dir + "/c.ini: ";
  EXPECT_EQ(error("[odometry]\nreferences 99\n"),
            at + "line 2: expected key = value, a [section] or a comment, got 'references 99'");
  EXPECT_EQ(error("; settings\n@include other.ini\n"),
            at + "line 2: expected key = value, a [section] or a comment, got '@include other.ini'");
  EXPECT_EQ(error("[odometry\nreferences = 2\n"),
            at + "line 1: expected key = value, a [section] or a comment, got '[odometry'");
  EXPECT_EQ(error(std::string("\x7f" "ELF\x02\x01\x00\x00 = x", 12)),
            at + "line 1: expected key = value, a [section] or a comment, got '?ELF???? = x'");
  EXPECT_EQ(error("[odometry]\nkeypoints = ${NO_SUCH_NAME}\n"), at + "Line 2: Unknown variable `${NO_SUCH_NAME}`");
  // An expression MRPT cannot parse: its exception's first line is only a banner ("==== MRPT exception ====").
  const std::string bad_eval = error("[kinfu]\nvoxel_size = $eval{2*}\n");
  EXPECT_EQ(bad_eval.find(at), 0u) << bad_eval;
  EXPECT_EQ(bad_eval.find("MRPT exception"), std::string::npos) << bad_eval;
  EXPECT_NE(bad_eval.find("2*"), std::string::npos) << bad_eval;
  EXPECT_EQ(error("\xEF\xBB\xBF[odometry]\r\n# a comment\r\n// another\r\n@define\tKP star\r\nkeypoints = ${KP}\r\n\r\n"), "");
  EXPECT_EQ(loadConfig(dir + "/c.ini").read_string("odometry", "keypoints", ""), "star");
  // A value continued on the next line with a trailing '\', as MRPT reads it.
  EXPECT_EQ(error("[loop]\nnote = first part \\\n  second part\nrest = 1\n"), "");
  EXPECT_EQ(error("[loop]\nnote = first part \\\n  second part\nrest 1\n"),
            at + "line 4: expected key = value, a [section] or a comment, got 'rest 1'");
  // Two lines MRPT reads without a word but loses a key of: a comment ending in '\' (the next line
  // joins it), and a key after a section's name on its line.
  EXPECT_EQ(error("[kinfu]\n# recorded on D:\\rec\\\nvoxel_size = 0.004\n"),
            at + "line 2: a comment ends in '\\', which joins line 3 to it (MRPT would not read that line)");
  EXPECT_EQ(error("[kinfu] voxel_size = 0.004\n"),
            at + "line 1: text after the section name ('voxel_size = 0.004' would be dropped): put a key on a line of its own");
  EXPECT_EQ(error("[kinfu]  ; the map\n[loop] # loops\n[odometry] // MRPT's own comment\nkeypoints = star\n"), "");
  EXPECT_EQ(loadConfig(dir + "/c.ini").read_string("odometry", "keypoints", ""), "star");
  EXPECT_EQ(error("[kinfu] / 2\n"), at + "line 1: text after the section name ('/ 2' would be dropped): put a key on a line of its own");
  fs::create_directories(dir + "/folder.ini");
  EXPECT_THROW(
      {
        try {
          loadConfig(dir + "/folder.ini");
        } catch (const InputError& e) {
          EXPECT_EQ(std::string(e.what()), dir + "/folder.ini: is a folder, expected a config file");
          throw;
        }
      },
      InputError);
}

// A number is saved so that it reads back as the same value: as MRPT writes it (6 decimals) where that
// is exact, else in the fewest digits that are. 0.0030004 was saved as 0.003000, and a checkpoint's
// origin took a run with 0.0030001 for the same run.
TEST(Config, ANumberIsSavedSoThatItReadsBackTheSame) {
  double precise = 0.0030004, plain = 0.05, tiny = 2.5e-7;
  float single = 0.1234567f;
  const auto table = [](double& a, double& b, double& c, float& d) {
    return std::vector<ConfigKey>{{"precise", &a, "m", 0.0, 1.0}, {"plain", &b, "m", 0.0, 1.0},
                                  {"tiny", &c, "m", 0.0, 1.0}, {"single", &d, "m", 0.0, 1.0}};
  };
  mrpt::config::CConfigFileMemory cfg;
  saveKeys(cfg, "s", table(precise, plain, tiny, single));
  EXPECT_EQ(cfg.read_string("s", "precise", ""), "0.0030004");
  EXPECT_EQ(cfg.read_string("s", "plain", ""), "0.050000") << "as MRPT writes it, where that is exact";
  double a = 0, b = 0, c = 0;
  float d = 0;
  loadKeys(cfg, "s", table(a, b, c, d));
  EXPECT_EQ(a, precise);
  EXPECT_EQ(b, plain);
  EXPECT_EQ(c, tiny);
  EXPECT_EQ(d, single);
}

TEST(Config, DumpHoldsEveryKey) {
  DemoParams p;
  const std::string text = dumpConfig({{"kinfu", &p}});
  EXPECT_NE(text.find("voxel"), std::string::npos);
  EXPECT_NE(text.find("weight_cap"), std::string::npos);
}

// rgbd-odometry's --set section.key=value.
TEST(Config, ASettingIsSectionKeyAndValueWithoutTheSpacesAround) {
  const Setting s = parseSetting(" odometry . references = 2 ");
  EXPECT_EQ(s.section, "odometry");
  EXPECT_EQ(s.key, "references");
  EXPECT_EQ(s.value, "2");
  EXPECT_EQ(parseSetting("kinfu.work_dir=/tmp/a=b").value, "/tmp/a=b");  // the first '=' ends the key
  for (const char* bad : {"odometry", "odometry=2", "references=odometry.2"})
    EXPECT_THROW(parseSetting(bad), InputError) << bad;
}

// MRPT reads INI numbers with atoi / atof, so "1cm" was 1 and "true # on" false, without a word. A value
// is now either wholly a number (a switch: true / false, yes / no, on / off, 1 / 0) or a one-line error.
// MRPT keeps quotes and a '#' or ';' comment after a value as part of it: a free-text value (a folder)
// with them in a config file is refused, where it made a folder named '"/tmp/x"  # scratch'. ' //' is
// MRPT's comment; a '#' inside a name is the name's.
TEST(Config, AFreeTextValueInQuotesOrWithAHashCommentIsRefused) {
  auto message = [](const std::string& value) -> std::string {
    mrpt::config::CConfigFileMemory cfg;
    cfg.setContent("[s]\ndir = " + value + "\n");
    try {
      checkBareValue(cfg, "s", "dir");
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_EQ(message("\"/tmp/x\""), "[s] dir: '\"/tmp/x\"': MRPT's INI reader takes quotes as part of the value; write it bare, "
                                  "with any comment after ' //'");
  EXPECT_EQ(message("'/tmp/x'").find("[s] dir: ''/tmp/x'': MRPT's INI reader takes quotes"), 0u);
  EXPECT_EQ(message("/tmp/x  # scratch").find("[s] dir: '/tmp/x  # scratch': MRPT's INI reader takes a '#' or ';' comment"), 0u);
  EXPECT_NE(message("/tmp/x ; scratch"), "");
  EXPECT_EQ(message("/tmp/x // scratch"), "");
  EXPECT_EQ(message("/tmp/run#3"), "");
}

// A device or a pipe given as the config is named for what it is (it was "config file not found").
TEST(Config, ADeviceAsConfigIsNamedForWhatItIs) {
  try {
    loadConfig("/dev/zero");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "/dev/zero: is not a regular file, expected a config file");
  }
}

TEST(Config, ValueThatIsNotWhollyANumberIsRefused) {
  struct Keys {
    int cap = 64;
    double voxel = 0.006;
    bool enabled = false;
    std::vector<ConfigKey> table() {
      return {{"cap", &cap, "frames", 1, 1000}, {"voxel", &voxel, "m", 0.001, 1}, {"enabled", &enabled, "switch"}};
    }
  };
  auto message = [](const std::string& key, const std::string& value) -> std::string {
    mrpt::config::CConfigFileMemory cfg;
    cfg.setContent("[s]\n" + key + " = " + value + "\n");
    Keys k;
    try {
      loadKeys(cfg, "s", k.table());
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  };
  EXPECT_EQ(message("voxel", "1cm"), "[s] voxel: '1cm' is not a number");
  EXPECT_EQ(message("voxel", "0,3"), "[s] voxel: '0,3' is not a number");
  EXPECT_EQ(message("cap", "ten"), "[s] cap: 'ten' is not an integer");
  EXPECT_EQ(message("cap", "2.5"), "[s] cap: '2.5' is not an integer");
  EXPECT_EQ(message("cap", ""), "[s] cap: '' is not an integer");
  EXPECT_EQ(message("cap", "inf"), "[s] cap: 'inf' is not an integer");
  EXPECT_EQ(message("voxel", "+-0.01"), "[s] voxel: '+-0.01' is not a number");
  EXPECT_EQ(message("enabled", "true  # comment"), "[s] enabled: 'true  # comment' is not true or false");
  EXPECT_EQ(message("enabled", "maybe"), "[s] enabled: 'maybe' is not true or false");
  EXPECT_EQ(message("cap", "5e3"), "[s] cap: must be in [1, 1000], got 5000");  // the range sees the value as typed

  // What MRPT writes and people type still loads, a trailing "// comment" included (MRPT cuts it).
  mrpt::config::CConfigFileMemory cfg;
  cfg.setContent("[s]\ncap = +1e2 // frames\nvoxel =  2.5e-3\nenabled = On\n");
  Keys k;
  loadKeys(cfg, "s", k.table());
  EXPECT_EQ(k.cap, 100);
  EXPECT_DOUBLE_EQ(k.voxel, 0.0025);
  EXPECT_TRUE(k.enabled);
  for (const char* off : {"false", "no", "off", "0", "FALSE"}) {
    cfg.setContent(std::string("[s]\nenabled = ") + off + "\n");
    k.enabled = true;
    loadKeys(cfg, "s", k.table());
    EXPECT_FALSE(k.enabled) << off;
  }
}
