#include "vofusion/core/config.h"

#include <algorithm>
#include <cctype>
#include <charconv>
#include <cmath>
#include <filesystem>
#include <optional>
#include <sstream>

#include "vofusion/core/errors.h"
#include "vofusion/core/text_file.h"

namespace vofusion {

namespace {

// A text as shown in an error: at most `longest` characters, anything unprintable as '?'.
std::string shown(const std::string& text, std::size_t longest = 40) {
  std::string s = text.substr(0, longest);
  for (char& c : s)
    if (!std::isprint(static_cast<unsigned char>(c))) c = '?';
  return text.size() > longest ? s + "..." : s;
}

// MRPT's INI reader passes over any line it cannot read: "references 99" (no '='), "@include x.ini"
// (no such directive in MRPT 2.5) or a binary file given as --config ran with the defaults. Each line is
// a comment, a [section], key = value or MRPT's "@define NAME VALUE"; anything else is a one-line error.
// A line ending in '\' goes on on the next one, as MRPT joins them.
void checkIniLines(const std::string& text, const std::string& path) {
  std::istringstream in(text.rfind("\xEF\xBB\xBF", 0) == 0 ? text.substr(3) : text);  // a UTF-8 byte order mark
  std::size_t number = 0;
  bool continued = false;
  for (std::string line; std::getline(in, line);) {
    ++number;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    const bool continues = continued;
    continued = !line.empty() && line.back() == '\\';
    if (continues) continue;  // the rest of the line before
    const auto b = line.find_first_not_of(" \t");
    if (b == std::string::npos) continue;
    const std::string t = line.substr(b);
    const bool comment = t[0] == ';' || t[0] == '#' || t.rfind("//", 0) == 0;
    // MRPT joins a line ending in '\' to the next before it sees comments: the next line's key would
    // be part of the comment, silently (a Windows path "D:\rec\" in a comment).
    if (comment && continued)
      throw InputError(path, "line " + std::to_string(number) + ": a comment ends in '\\', which joins line " +
                                 std::to_string(number + 1) + " to it (MRPT would not read that line)");
    // MRPT takes the name of "[kinfu] voxel_size = 0.004" and drops the rest of the line (a comment
    // after it, ';', '#' or MRPT's own '//', is dropped as meant).
    const std::size_t close = t.find(']');
    if (t[0] == '[' && close != std::string::npos) {
      const auto rest = t.find_first_not_of(" \t", close + 1);
      if (rest != std::string::npos && t[rest] != ';' && t[rest] != '#' && t.compare(rest, 2, "//") != 0)
        throw InputError(path, "line " + std::to_string(number) + ": text after the section name ('" +
                                   shown(t.substr(rest)) + "' would be dropped): put a key on a line of its own");
    }
    const bool section = t[0] == '[' && close != std::string::npos;
    const bool define = t.rfind("@define", 0) == 0 && t.size() > 7 && std::isspace(static_cast<unsigned char>(t[7]));
    const bool key = t[0] != '@' && t[0] != '=' && t.find('=') != std::string::npos;
    const bool text_only = std::none_of(line.begin(), line.end(), [](char c) { return c == '\0'; });
    if (!text_only || !(comment || section || define || key))
      throw InputError(path, "line " + std::to_string(number) + ": expected key = value, a [section] or a comment, got '" +
                                 shown(t) + "'");
  }
}

}  // namespace

mrpt::config::CConfigFileMemory loadConfig(const std::string& path) {
  mrpt::config::CConfigFileMemory cfg;
  if (path.empty()) return cfg;
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw InputError(path, "is a folder, expected a config file");
  if (!std::filesystem::exists(path, ec)) throw InputError(path, "config file not found");
  if (!std::filesystem::is_regular_file(path, ec)) throw InputError(path, "is not a regular file, expected a config file");
  const std::string text = readTextFile(path);
  checkIniLines(text, path);
  try {
    cfg.setContent(text);  // MRPT's preprocessor: @define, ${NAME}, $env{NAME}, $eval{...}
  } catch (const std::exception& e) {
    // "Line 2: Unknown variable `${X}`"; an MRPT exception's message after its banner line ($eval{((}).
    throw InputError(path, shown(oneLineMessage(e), 160));
  }
  return cfg;
}

// MRPT pads key names when writing aligned INI text; compare names, not layout.
static std::string trimmed(const std::string& s) {
  const auto b = s.find_first_not_of(" \t");
  const auto e = s.find_last_not_of(" \t");
  return b == std::string::npos ? std::string() : s.substr(b, e - b + 1);
}

// A key as MRPT looks it up: its INI reader ignores case ("Voxel_Size" is voxel_size's value).
static std::string keyName(const std::string& s) {
  std::string k = trimmed(s);
  std::transform(k.begin(), k.end(), k.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  return k;
}

Setting parseSetting(const std::string& text) {
  const auto dot = text.find('.'), eq = text.find('=');
  if (dot == std::string::npos || eq == std::string::npos || eq < dot) throw InputError("--set " + text, "expected section.key=value");
  return {trimmed(text.substr(0, dot)), trimmed(text.substr(dot + 1, eq - dot - 1)), trimmed(text.substr(eq + 1))};
}

static mrpt::config::CConfigFileMemory defaultsOf(const std::vector<ConfigSection>& known) {
  mrpt::config::CConfigFileMemory mem;
  for (const auto& [section, params] : known) params->saveToConfigFile(mem, section);
  return mem;
}

// Keys earlier versions read whose values are now fixed in code, each with where the figures that
// fixed it are. An old config naming one is still refused (the value would silently do nothing), but
// not as a typo. From the history of share/*.ini.
namespace {
struct RetiredKey {
  const char* section;
  const char* key;
  const char* figures;
};
constexpr RetiredKey kRetiredKeys[] = {
    {"kinfu", "guess_margin", "docs/tracking.md"},
    {"kinfu", "integrate_filtered", "docs/tracking.md"},
    {"kinfu", "joint_match_cauchy", "docs/tracking.md"},
    {"kinfu", "joint_photometric_huber", "docs/tracking.md"},
    {"kinfu", "joint_photometric_min_gradient", "docs/tracking.md"},
    {"kinfu", "mark_step", "docs/tracking.md"},
    {"kinfu", "min_condition", "docs/tracking.md"},
    {"kinfu", "tracking_downsample", "docs/tracking.md"},
    {"loop", "loop_sigma_rotation", "docs/loop-closure.md"},
    {"loop", "loop_sigma_translation", "docs/loop-closure.md"},
    {"loop", "max_chain_chi2", "docs/loop-closure.md"},
    {"loop", "max_loop_chi2", "docs/loop-closure.md"},
    {"loop", "odometry_sigma_floor", "docs/loop-closure.md"},
    {"loop", "odometry_sigma_rate", "docs/loop-closure.md"},
    {"loop", "poor_tracking_sigma_scale", "docs/loop-closure.md"},
    {"loop", "strain_rms_ratio", "docs/loop-closure.md"},
    {"narf", "recursive_scale_reduction", "docs/odometry.md"},
};
}  // namespace

static std::string unknownKeyMessage(const std::string& section, const std::string& key) {
  for (const RetiredKey& r : kRetiredKeys)
    if (keyName(section) == r.section && keyName(key) == r.key)
      return "'" + key + "' in section [" + section + "] is no longer a key: its value is fixed in code (" + r.figures +
             " gives the figures); remove the line";
  return "unknown key '" + key + "' in section [" + section + "]";
}

// The sections that hold keys, with their keys (a section named but empty is nobody's concern).
static std::vector<std::pair<std::string, std::vector<std::string>>> sectionsWithKeys(
    const mrpt::config::CConfigFileBase& user) {
  std::vector<std::string> sections;
  user.getAllSections(sections);
  std::vector<std::pair<std::string, std::vector<std::string>>> out;
  for (const auto& s : sections) {
    std::vector<std::string> keys;
    user.getAllKeys(s, keys);
    if (!keys.empty()) out.emplace_back(s, std::move(keys));
  }
  return out;
}

void checkConfigKeys(const mrpt::config::CConfigFileBase& user, const std::string& origin,
                     const std::vector<ConfigSection>& known) {
  const auto defaults = defaultsOf(known);
  for (const auto& [s, keys] : sectionsWithKeys(user)) {
    if (!defaults.sectionExists(s)) throw InputError(origin, "unknown section [" + s + "]");
    std::vector<std::string> valid;
    defaults.getAllKeys(s, valid);
    for (auto& v : valid) v = keyName(v);
    for (const auto& key : keys) {
      // rawlog-grabber's own, read in every section (share/grab-openni2.ini's [vofusion-grab] has it).
      if (keyName(key) == "rawlog-grabber-ignore") continue;
      if (std::find(valid.begin(), valid.end(), keyName(key)) == valid.end())
        throw InputError(origin, unknownKeyMessage(s, trimmed(key)));
    }
  }
}

void checkKnownSections(const mrpt::config::CConfigFileBase& user, const std::string& origin,
                        const std::vector<ConfigSection>& known) {
  // Every section the stages read, the ones a section's parameters save beside their own included
  // ([odometry] writes [star], [narf], [brand], [matching] and [motion]).
  std::vector<std::string> sections;
  defaultsOf(known).getAllSections(sections);
  mrpt::config::CConfigFileMemory ours;
  for (const auto& section : sections) {
    std::vector<std::string> keys;
    user.getAllKeys(section, keys);
    for (const auto& k : keys)
      if (keyName(k) != "rawlog-grabber-ignore") ours.write(section, k, user.read_string(section, k, ""));
  }
  checkConfigKeys(ours, origin, known);
}

void checkConfigFile(const mrpt::config::CConfigFileBase& user, const std::string& origin,
                     const std::vector<ConfigSection>& known) {
  if (isGrabberConfig(user)) checkKnownSections(user, origin, known);
  else checkConfigKeys(user, origin, known);
}

bool isGrabberConfig(const mrpt::config::CConfigFileBase& user) {
  for (const auto& [s, keys] : sectionsWithKeys(user)) {
    if (keyName(s) == "global") return true;
    for (const auto& k : keys)
      if (keyName(k) == "driver") return true;
  }
  return false;
}

std::string dumpConfig(const std::vector<ConfigSection>& known) { return defaultsOf(known).getContent(); }

}  // namespace vofusion

namespace vofusion {

static std::string choicesText(const std::vector<std::string>& choices) {
  std::string t;
  for (const std::string& c : choices) t += (t.empty() ? "" : " | ") + c;
  return t;
}

void checkChoice(const std::string& section, const char* key, const std::string& value,
                 const std::vector<std::string>& choices) {
  if (std::find(choices.begin(), choices.end(), value) == choices.end())
    throw InputError("[" + section + "] " + key, "must be one of " + choicesText(choices) + ", got '" + value + "'");
}

static std::string rangeText(const ConfigKey& k) {
  std::ostringstream r;
  r << "[" << k.lo << ", " << k.hi << "]";
  return r.str();
}

namespace {
// A value as the user typed it (MRPT has already cut a trailing "// comment"), or nullopt when absent.
std::optional<std::string> valueText(const mrpt::config::CConfigFileBase& cfg, const std::string& section, const char* key) {
  if (!cfg.keyExists(section, key)) return std::nullopt;
  return trimmed(cfg.read_string(section, key, ""));
}

// The whole text as a number, or nullopt. MRPT's own readers are atoi/atof, which take "1cm" as 1,
// "0,3" as 0 and "true # on" as false without a word; a value is either all number or refused.
std::optional<double> parseNumber(std::string text) {
  if (!text.empty() && text[0] == '+') {
    text.erase(0, 1);
    if (!text.empty() && (text[0] == '+' || text[0] == '-')) return std::nullopt;  // "+-5", "++5"
  }
  double x = 0.0;
  const char* end = text.data() + text.size();
  const auto [ptr, ec] = std::from_chars(text.data(), end, x);
  if (text.empty() || ec != std::errc() || ptr != end) return std::nullopt;
  return x;
}

// true / false as MRPT writes them, and the usual spellings of a switch.
std::optional<bool> parseSwitch(std::string text) {
  std::transform(text.begin(), text.end(), text.begin(), [](unsigned char c) { return char(std::tolower(c)); });
  if (text == "true" || text == "yes" || text == "on" || text == "1") return true;
  if (text == "false" || text == "no" || text == "off" || text == "0") return false;
  return std::nullopt;
}

std::string keyName(const std::string& section, const char* key) { return "[" + section + "] " + key; }
}  // namespace

double readNumber(const mrpt::config::CConfigFileBase& cfg, const std::string& section, const char* key, double fallback,
                  bool integer) {
  const auto text = valueText(cfg, section, key);
  if (!text) return fallback;
  const auto x = parseNumber(*text);
  if (!x || (integer && (!std::isfinite(*x) || std::floor(*x) != *x)))
    throw InputError(keyName(section, key), "'" + *text + "' is not " + (integer ? "an integer" : "a number"));
  return *x;
}

void loadKeys(const mrpt::config::CConfigFileBase& cfg, const std::string& section, const std::vector<ConfigKey>& keys) {
  for (const ConfigKey& k : keys)
    std::visit(
        [&](auto* v) {
          using T = std::remove_pointer_t<decltype(v)>;
          if constexpr (std::is_same_v<T, bool>) {
            const auto text = valueText(cfg, section, k.name);
            if (!text) return;
            const auto on = parseSwitch(*text);
            if (!on) throw InputError(keyName(section, k.name), "'" + *text + "' is not true or false");
            *v = *on;
          } else if constexpr (std::is_same_v<T, std::string>) {
            *v = cfg.read_string(section, k.name, *v);
            if (!k.choices.empty()) checkChoice(section, k.name, *v, k.choices);
          } else {
            // The range is checked on the value as typed, before it is narrowed to the key's type.
            const double x = readNumber(cfg, section, k.name, double(*v), std::is_same_v<T, int>);
            if (!std::isnan(k.lo) && !(x >= k.lo && x <= k.hi)) {
              std::ostringstream got;
              got << x;
              throw InputError(keyName(section, k.name), "must be in " + rangeText(k) + ", got " + got.str());
            }
            *v = static_cast<T>(x);
          }
        },
        k.value);
}

namespace {
// Whether `text` parses to exactly v at v's own precision (a float key is read into a float).
template <typename T>
bool readsBackAs(std::string text, T v) {
  text.erase(0, text.find_first_not_of(" \t"));
  text.erase(text.find_last_not_of(" \t\r") + 1);
  T back{};
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), back);
  return ec == std::errc() && end == text.data() + text.size() && (back == v || (std::isnan(back) && std::isnan(v)));
}

// The fewest digits that read back as v.
template <typename T>
std::string shortestText(T v) {
  char buf[64];
  const auto [end, ec] = std::to_chars(buf, buf + sizeof buf, v);
  return ec == std::errc() ? std::string(buf, end) : std::to_string(v);
}
}  // namespace

void saveKeys(mrpt::config::CConfigFileBase& cfg, const std::string& section, const std::vector<ConfigKey>& keys) {
  for (const ConfigKey& k : keys) {
    std::string comment = std::isnan(k.lo) ? std::string(k.comment) : std::string(k.comment) + "; range " + rangeText(k);
    if (!k.choices.empty()) comment += "; one of " + choicesText(k.choices);
    std::visit(
        [&](auto* v) {
          using T = std::remove_pointer_t<decltype(v)>;
          if constexpr (std::is_same_v<T, bool>) cfg.write(section, k.name, std::string(*v ? "true" : "false"), -1, 1, comment);
          else if constexpr (std::is_same_v<T, float>) cfg.write(section, k.name, static_cast<double>(*v), -1, 1, comment);
          else cfg.write(section, k.name, *v, -1, 1, comment);
          if constexpr (std::is_floating_point_v<T>) {
            if (!readsBackAs(cfg.read_string(section, k.name, ""), *v))
              cfg.write(section, k.name, shortestText(*v), -1, 1, comment);
          }
        },
        k.value);
  }
}

void checkBareValue(const mrpt::config::CConfigFileBase& file, const std::string& section, const std::string& key) {
  const std::string v = file.read_string(section, key, "");
  const bool quoted = v.size() >= 2 && (v.front() == '"' || v.front() == '\'') && v.back() == v.front();
  bool comment = false;
  for (std::size_t i = 1; i < v.size(); ++i) comment |= (v[i] == '#' || v[i] == ';') && (v[i - 1] == ' ' || v[i - 1] == '\t');
  if (quoted || comment)
    throw InputError(keyName(section, key.c_str()), "'" + v + "': MRPT's INI reader takes " +
                                                        (quoted ? "quotes" : "a '#' or ';' comment") +
                                                        " as part of the value; write it bare, with any comment after ' //'");
}

}  // namespace vofusion
