#pragma once
// Minimal command-line parsing for the thin apps: "--name value" (or "--name=value"), "--flag",
// positionals; "-h" means "--help" when the app knows --help, other "-x" are unknown options.
// Every problem is an InputError("usage", ...) so apps report it as one line and exit 2.
#include <limits>
#include <optional>
#include <set>
#include <string>
#include <vector>

namespace vofusion {

class CommandLine {
 public:
  // value_options: options that take a value (e.g. "--out"); flag_options: options that don't.
  CommandLine(int argc, char** argv, std::set<std::string> value_options, std::set<std::string> flag_options);

  std::optional<std::string> value(const std::string& name) const;
  std::string value(const std::string& name, const std::string& fallback) const;
  // Every occurrence in order, for repeatable options such as "--set k=v".
  std::vector<std::string> values(const std::string& name) const;
  std::size_t count(const std::string& name, std::size_t fallback, std::size_t min = 0) const;  // integer >= min
  double number(const std::string& name, double fallback) const;
  // A number with above < x <= at_most.
  double number(const std::string& name, double fallback, double above,
                double at_most = std::numeric_limits<double>::infinity()) const;
  // A number with at_least <= x <= at_most (a zero that means "off" among positive values).
  double numberFrom(const std::string& name, double fallback, double at_least, double at_most) const;
  bool flag(const std::string& name) const;
  const std::vector<std::string>& positional() const { return positional_; }

 private:
  // A number from low (included or not) to at_most; the message names the range.
  double numberIn(const std::string& name, double fallback, double low, bool low_included, double at_most) const;
  std::vector<std::pair<std::string, std::string>> values_;
  std::set<std::string> flags_;
  std::vector<std::string> positional_;
};

// Runs an app's body, turning any exception into one line on stderr and exit code 2
// (InputError: bad input or usage) or 1 (anything else). The line is "<app_name>: error: <what>",
// or just "<what>" when app_name is null. Also sets up the allocator for frame-sized buffers.
int runApp(const char* app_name, int (*body)(int, char**), int argc, char** argv);

}  // namespace vofusion
