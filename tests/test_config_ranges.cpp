// Every numeric key of every INI section has a checked range (from the key tables: the dumped defaults
// carry it), and no value a user may type, in range or not, crashes or poisons a run: a sweep sets
// every numeric key to 0, to a negative value and to a huge one and runs the pipeline on a few
// synthetic frames. Each case either runs with finite poses or stops at loading with the one-line
// config error.
#include <cmath>
#include <regex>
#include <sstream>
#include <tuple>

#include <mrpt/config/CConfigFileMemory.h>

#include "support.h"
#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"
#include "vofusion/mesh/mesh_clean.h"
#include "vofusion/pipeline/reconstruction.h"
#include "vofusion/pipeline/run_outputs.h"
#include "vofusion/sim/synthetic_sequence.h"

using namespace vofusion;

namespace {

struct NumericKey {
  std::string section, key, value, comment;
};

std::vector<ConfigSection> allSections() { return vofusionConfigSections(); }

// The numeric keys of the dumped defaults ("key = value // comment").
std::vector<NumericKey> numericKeys() {
  std::istringstream in(dumpConfig(allSections()));
  static const std::regex section(R"(^\[(.+)\]\s*$)"), line(R"(^\s*(\w+)\s*=\s*(\S+)\s*//\s*(.*)$)");
  static const std::regex number(R"(^[-+]?[0-9.]+(e[-+]?[0-9]+)?$)");
  std::vector<NumericKey> keys;
  std::string current, l;
  std::smatch m;
  while (std::getline(in, l)) {
    if (std::regex_match(l, m, section)) current = m[1];
    else if (std::regex_match(l, m, line) && std::regex_match(std::string(m[2]), number))
      keys.push_back({current, m[1], m[2], m[3]});
  }
  return keys;
}

}  // namespace

TEST(ConfigRanges, EveryNumericKeyCarriesItsRange) {
  const auto keys = numericKeys();
  EXPECT_GT(keys.size(), 70u);
  for (const auto& k : keys)
    EXPECT_NE(k.comment.find("; range ["), std::string::npos) << "[" << k.section << "] " << k.key << " has no range";
}

// Every other key is a switch (true/false) or names one of a few choices, listed in its comment.
TEST(ConfigRanges, EveryStringKeyListsItsChoices) {
  std::istringstream in(dumpConfig(allSections()));
  static const std::regex line(R"(^\s*(\w+)\s*=\s*(\S+)\s*//\s*(.*)$)"), number(R"(^[-+]?[0-9.]+(e[-+]?[0-9]+)?$)");
  std::smatch m;
  std::string l;
  int strings = 0;
  while (std::getline(in, l)) {
    if (!std::regex_match(l, m, line)) continue;
    const std::string value = m[2];
    if (std::regex_match(value, number) || value == "true" || value == "false") continue;
    if (m[1] == "work_dir") continue;  // a folder's path ("auto": beside the outputs), checked when opened
    ++strings;
    const std::string comment = m[3];
    EXPECT_NE(comment.find("; one of "), std::string::npos) << m[1] << " = " << value << " lists no choices";
    EXPECT_NE(comment.find(value), std::string::npos) << m[1] << ": its default is not among its choices";
  }
  EXPECT_GE(strings, 4);
}

TEST(ConfigRanges, UnknownChoiceIsOneLineNamingSectionAndKey) {
  for (const auto& [section, key, msg] : std::vector<std::tuple<std::string, std::string, std::string>>{
           {"odometry", "keypoints", "[odometry] keypoints: must be one of union | star | narf, got 'orb'"},
           {"odometry", "motion_method", "[odometry] motion_method: must be one of paper | robust, got 'orb'"},
           {"odometry", "depth_mode", "[odometry] depth_mode: must be one of median | min, got 'orb'"},
           {"narf", "implementation", "[narf] implementation: must be one of fast | pcl, got 'orb'"}}) {
    mrpt::config::CConfigFileMemory cfg;
    cfg.write(section, key, std::string("orb"));
    try {
      Reconstruction rec(cfg, TrackingMode::Joint);
      ADD_FAILURE() << section << "." << key << " = orb accepted";
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()), msg);
    }
  }
  // Set in code, past the INI: refused when the odometry is built.
  OdometryParams p;
  p.keypoints = "orb";
  EXPECT_THROW(RgbdOdometry{p}, InputError);
}

TEST(ConfigRanges, OutOfRangeIsOneLineNamingSectionAndKey) {
  mrpt::config::CConfigFileMemory cfg;
  cfg.write("kinfu", "bilateral_sigma_spatial", 0);
  try {
    Reconstruction rec(cfg, TrackingMode::Joint);
    FAIL() << "accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "[kinfu] bilateral_sigma_spatial: must be in [0.1, 50], got 0");
  }
}

// No ICP iteration at the finest level left its statistics (inliers, overlap) at 0, and every ICP was
// rejected as "too few ICP inliers (0 of 0)": mode kinfu lost every frame.
TEST(ConfigRanges, ICPJudgedOnAFinestLevelNeedsAnIterationThere) {
  mrpt::config::CConfigFileMemory cfg;
  cfg.write("kinfu", "icp_iterations_l0", 0);
  try {
    Reconstruction rec(cfg, TrackingMode::KinFu);
    FAIL() << "accepted";
  } catch (const InputError& e) {
    EXPECT_EQ(std::string(e.what()), "[kinfu] icp_iterations_l0: must be in [1, 100], got 0");
  }
}

// A depth of 0 is no reading: a minimum of 0 fused every hole as a surface at the camera (occupied
// blobs along the path, rays starting inside them). Refused.
TEST(ConfigRanges, AMinimumDepthOfZeroIsRefused) {
  for (const char* key : {"integrate_min_depth", "min_depth"}) {
    mrpt::config::CConfigFileMemory cfg;
    cfg.write("kinfu", key, 0);
    try {
      Reconstruction rec(cfg, TrackingMode::KinFu);
      FAIL() << key << " = 0 accepted";
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()), std::string("[kinfu] ") + key + ": must be in [0.001, 20], got 0");
    }
  }
}

// The range a key's table gives (and --dump-config shows) is the one checked: [output] refused
// frustum_every = 0 and images below 64 px with a message of its own while its table said [0, ...]
// and [16, ...].
TEST(ConfigRanges, TheRangeShownIsTheRangeChecked) {
  for (const auto& [key, below, lowest] : {std::tuple{"frustum_every", "0", "1"}, std::tuple{"image_width", "63", "64"}}) {
    mrpt::config::CConfigFileMemory cfg;
    cfg.write("output", key, std::string(below));
    OutputParams out;
    try {
      out.loadFromConfigFile(cfg, "output");
      ADD_FAILURE() << key << " = " << below << " accepted";
    } catch (const InputError& e) {
      EXPECT_EQ(std::string(e.what()).rfind(std::string("[output] ") + key + ": must be in [" + lowest + ", ", 0), 0u) << e.what();
    }
    cfg.write("output", key, std::string(lowest));
    EXPECT_NO_THROW(out.loadFromConfigFile(cfg, "output")) << key << " = " << lowest;
  }
}

// The sweep: every numeric key at 0, -1 and 1e9 (each alone, the rest default). A run uses 6 frames
// of the synthetic room at 160x120 with a small volume, so ~300 cases stay within a minute or two.
TEST(ConfigRanges, SweepNeverCrashesNorPoisonsARun) {
  sim::SimOptions o;
  o.frames = 6;
  o.camera = CameraIntrinsics{}.scaled(0.25);
  const std::vector<Frame> frames = test::renderFrames(sim::SyntheticSequence(o));
  // The [mesh] keys' cases clean this map's mesh: a value accepted at loading must not break the cleaning.
  const TriangleMesh raw = [&] {
    mrpt::config::CConfigFileMemory small;
    small.write("kinfu", "volume_voxels", 64);
    small.write("kinfu", "voxel_size", 0.04);
    small.write("kinfu", "truncation", 0.12);
    Reconstruction rec(small, TrackingMode::Joint);
    for (const Frame& f : frames) rec.process(test::deepCopy(f));
    rec.finish();
    return rec.extractMesh();
  }();
  ASSERT_GT(raw.faces.size(), 100u);
  int runs = 0, rejected = 0;
  for (const auto& k : numericKeys()) {
    for (const char* value : {"0", "-1", "1e9"}) {
      SCOPED_TRACE("[" + k.section + "] " + k.key + " = " + value);
      mrpt::config::CConfigFileMemory cfg;
      // A small volume unless the key under test is one of those.
      if (!(k.section == "kinfu" && (k.key == "volume_voxels" || k.key == "voxel_size" || k.key == "truncation"))) {
        cfg.write("kinfu", "volume_voxels", 64);
        cfg.write("kinfu", "voxel_size", 0.04);
        cfg.write("kinfu", "truncation", 0.12);
      }
      cfg.write(k.section, k.key, std::string(value));
      const std::vector<ConfigSection> sections = allSections();
      try {
        if (k.section == "mesh" || k.section == "output") {
          MeshCleanParams mesh;
          OutputParams out;
          mesh.loadFromConfigFile(cfg, "mesh");
          out.loadFromConfigFile(cfg, "output");
          if (k.section == "mesh") {
            TriangleMesh m = raw;
            const MeshCleanReport r = cleanMesh(m, mesh);
            for (const auto& v : m.vertices) ASSERT_TRUE(v.allFinite());
            for (const auto& f : m.faces)
              for (const auto i : f) ASSERT_LT(i, m.vertices.size());
            if (!r.success) EXPECT_FALSE(r.failure.empty());  // a failure says why
          }
          ++runs;
          continue;
        }
        Reconstruction rec(cfg, TrackingMode::Joint);
        for (const Frame& f : frames) rec.process(test::deepCopy(f));  // no run sees another's images
        ++runs;
        ASSERT_FALSE(rec.trajectory().empty());
        for (const auto& p : rec.trajectory()) ASSERT_TRUE(p.pose.asVectorVal().asEigen().allFinite());
      } catch (const InputError& e) {
        ++rejected;
        const std::string msg = e.what();
        EXPECT_EQ(msg.find('\n'), std::string::npos) << msg;
        EXPECT_NE(msg.find("[" + k.section + "]"), std::string::npos) << msg;
      } catch (const std::exception& e) {
        ADD_FAILURE() << "not a config error: " << e.what();
      }
    }
  }
  std::printf("config sweep: %d cases ran, %d rejected at loading\n", runs, rejected);
  EXPECT_GT(rejected, 100);
  EXPECT_GT(runs, 40);  // 52 of the values are accepted (2026-12-06): the runs are not vacuous
}
