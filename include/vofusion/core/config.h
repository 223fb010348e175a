#pragma once
// INI configuration the MRPT way: each stage's parameters are a CLoadableOptions reading its own
// section. What a stage's saveToConfigFile() writes is, by definition, the set of keys it knows, so
// a user's file can be checked for typos ("unknown key") against the defaults themselves.
#include <limits>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include <mrpt/config/CConfigFileMemory.h>
#include <mrpt/config/CLoadableOptions.h>

#include "vofusion/core/errors.h"

namespace vofusion {

// One stage's parameters and the section they live in.
using ConfigSection = std::pair<std::string, const mrpt::config::CLoadableOptions*>;

// Reads an INI file into memory; throws InputError(path, ...) when missing or unreadable.
// An empty path gives an empty configuration (all defaults).
mrpt::config::CConfigFileMemory loadConfig(const std::string& path);

// Throws InputError(origin, "unknown key 'x' in section [s]" / "unknown section [s]") for the first
// key or section of `user` that none of `known` writes (rawlog-grabber-ignore, which rawlog-grabber
// reads in every section, is one of every known section's). A key an earlier version read and whose value
// is now fixed in code is refused as such ("'k' in section [s] is no longer a key: ..."), not as a typo.
void checkConfigKeys(const mrpt::config::CConfigFileBase& user, const std::string& origin,
                     const std::vector<ConfigSection>& known);

// checkConfigKeys over our sections alone (those of `known` and those their parameters read beside
// their own, as [odometry]'s [star] or [motion]): a file that also holds other programs' sections (a
// vofusion-grab config's sensor sections, read by MRPT's drivers) is checked in ours. The key
// rawlog-grabber-ignore, which rawlog-grabber reads in every section, is accepted in ours.
void checkKnownSections(const mrpt::config::CConfigFileBase& user, const std::string& origin,
                        const std::vector<ConfigSection>& known);

// A config file as the apps that read vofusion-grab's check it: a rawlog-grabber configuration
// (isGrabberConfig) in our sections (checkKnownSections: its sensor sections are MRPT's drivers'), any
// other whole (checkConfigKeys).
void checkConfigFile(const mrpt::config::CConfigFileBase& user, const std::string& origin,
                     const std::vector<ConfigSection>& known);
// True for a rawlog-grabber configuration such as vofusion-grab's --config: it has rawlog-grabber's
// [global] section or a sensor section (one with a `driver` key).
bool isGrabberConfig(const mrpt::config::CConfigFileBase& user);
// A free-text value as the config file gives it (a folder: [kinfu] work_dir): MRPT's INI reader keeps
// quotes, and a '#' or ';' comment after a value, as part of the value (only ' //' starts a comment
// there), so a folder named '"/tmp/x"  # scratch' would be made. InputError naming the key. Only for a
// file's values: a folder given on the command line (--out "take #2") may hold any character.
void checkBareValue(const mrpt::config::CConfigFileBase& file, const std::string& section, const std::string& key);

// The defaults of all given stages as INI text (for --dump-config and the documented share/ file).
std::string dumpConfig(const std::vector<ConfigSection>& known);

}  // namespace vofusion

namespace vofusion {

// One INI key bound to a parameter field. A stage lists its keys once and both loading and saving
// walk that list, so the two can never disagree. A numeric key carries its valid range (inclusive):
// loading a value outside it is a one-line error, saving writes it into the comment, and a test
// (tests/test_config_ranges.cpp) fails for any numeric key without one. A string key names one of a
// few choices (oneOf): any other value is the same kind of one-line error.
struct ConfigKey {
  const char* name;
  std::variant<int*, float*, double*, bool*, std::string*> value;
  const char* comment;  // unit and meaning, written next to the value
  double lo = std::numeric_limits<double>::quiet_NaN(), hi = std::numeric_limits<double>::quiet_NaN();
  std::vector<std::string> choices = {};  // string keys: the values allowed

  static ConfigKey oneOf(const char* name, std::string* value, const char* comment, std::vector<std::string> choices) {
    ConfigKey k{name, value, comment};
    k.choices = std::move(choices);
    return k;
  }
};
// Runs load(), which reads a configuration whose text came from origin (a file, "--set"): a bad
// value's InputError("[s] key", ...) comes out as InputError(origin, "[s] key: ..."). With an empty
// origin (the defaults alone) the error is left as it is.
template <class Load>
void loadNamingOrigin(const std::string& origin, Load&& load) {
  try {
    load();
  } catch (const InputError& e) {
    if (origin.empty()) throw;
    throw InputError(origin, e.what());
  }
}

// One command-line override, "section.key=value" (spaces around each part dropped); throws
// InputError("--set <text>", "expected section.key=value") when it is not one.
struct Setting {
  std::string section, key, value;
};
Setting parseSetting(const std::string& text);

// Throws InputError("[section] key", "must be one of a | b, got 'x'") unless value is one of choices.
void checkChoice(const std::string& section, const char* key, const std::string& value,
                 const std::vector<std::string>& choices);
// Loads each key that cfg has; a value that is not wholly a number (int keys: an integer; bool keys: true
// / false, yes / no, on / off, 1 / 0) or is out of range throws InputError("[section] key", ...).
void loadKeys(const mrpt::config::CConfigFileBase& cfg, const std::string& section, const std::vector<ConfigKey>& keys);
// One numeric value read as loadKeys reads it (fallback when the key is absent), for a stage without a
// key table; throws InputError("[section] key", "'1cm' is not a number") (or "not an integer").
double readNumber(const mrpt::config::CConfigFileBase& cfg, const std::string& section, const char* key, double fallback,
                  bool integer = false);
// Each key with its comment. A number as MRPT writes it (6 decimals, or 7 digits) where that reads back
// as the same value, else in the fewest digits that do: a checkpoint's origin and --dump-config keep
// 0.0030004 (written as 0.003000, it matched a run with 0.0030001).
void saveKeys(mrpt::config::CConfigFileBase& cfg, const std::string& section, const std::vector<ConfigKey>& keys);

}  // namespace vofusion
