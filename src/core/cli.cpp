#include "vofusion/core/cli.h"

#include <cctype>
#include <cmath>
#include <cstdio>
#include <exception>

#include "vofusion/core/errors.h"
#include "vofusion/core/heap.h"

namespace vofusion {

namespace {
std::string fmt(double x) {
  char b[32];
  std::snprintf(b, sizeof b, "%g", x);
  return b;
}
}  // namespace

CommandLine::CommandLine(int argc, char** argv, std::set<std::string> value_options,
                         std::set<std::string> flag_options) {
  // One of this program's options, with or without "=value".
  const auto isOption = [&](const std::string& a) {
    const std::string name = a.substr(0, a.find('='));
    return value_options.count(name) || flag_options.count(name);
  };
  bool options_end = false;  // after "--" every argument is positional (a path starting with '-')
  for (int i = 1; i < argc; ++i) {
    std::string a = argv[i];
    if (options_end) {
      positional_.push_back(a);
      continue;
    }
    if (a == "--") {
      options_end = true;
      continue;
    }
    if (a == "-h" && flag_options.count("--help")) a = "--help";
    if (a.size() > 1 && a[0] == '-' && a[1] != '-') throw InputError("usage", "unknown option " + a);
    if (a.size() > 2 && a.rfind("--", 0) == 0) {
      std::string name = a, val;
      const auto eq = a.find('=');
      const bool inline_value = eq != std::string::npos;
      if (inline_value) name = a.substr(0, eq), val = a.substr(eq + 1);
      if (value_options.count(name)) {
        if (!inline_value) {
          // "--out --max-frames 100" is a forgotten value, not an output folder named "--max-frames".
          if (i + 1 >= argc || isOption(argv[i + 1])) throw InputError("usage", "option " + name + " needs a value");
          val = argv[++i];
        }
        // "--config \"$UNSET\"": an empty value ran on the defaults (or in the temporary folder) without a word.
        if (val.empty()) throw InputError("usage", "option " + name + " needs a value (it is empty)");
        values_.emplace_back(name, val);
      } else if (flag_options.count(name)) {
        if (inline_value) throw InputError("usage", "option " + name + " takes no value");
        flags_.insert(name);
      } else {
        throw InputError("usage", "unknown option " + name);
      }
    } else {
      positional_.push_back(a);
    }
  }
}

std::optional<std::string> CommandLine::value(const std::string& name) const {
  std::optional<std::string> v;
  for (const auto& [k, x] : values_)
    if (k == name) v = x;  // the last occurrence wins, as usual
  return v;
}

std::string CommandLine::value(const std::string& name, const std::string& fallback) const {
  return value(name).value_or(fallback);
}

std::vector<std::string> CommandLine::values(const std::string& name) const {
  std::vector<std::string> all;
  for (const auto& [k, x] : values_)
    if (k == name) all.push_back(x);
  return all;
}

std::size_t CommandLine::count(const std::string& name, std::size_t fallback, std::size_t min) const {
  const auto v = value(name);
  if (!v) return fallback;
  std::size_t used = 0;
  long long n = -1;
  try {
    n = std::stoll(*v, &used);
  } catch (const std::exception&) {
  }
  // std::stoll skips leading blanks: " 5" is not how a count is written (a quoting slip).
  if (n < 0 || used != v->size() || std::isspace(static_cast<unsigned char>(v->front())) || static_cast<std::size_t>(n) < min)
    throw InputError("usage", name + " expects " +
                                  (min == 0 ? std::string("a non-negative integer")
                                            : "an integer >= " + std::to_string(min)) +
                                  ", got '" + *v + "'");
  return static_cast<std::size_t>(n);
}

double CommandLine::number(const std::string& name, double fallback) const {
  const auto v = value(name);
  if (!v) return fallback;
  std::size_t used = 0;
  double x = 0;
  try {
    x = std::stod(*v, &used);
  } catch (const std::exception&) {
    used = 0;
  }
  // std::stod also takes "inf", "nan" and hex floats: none is an option's value (--max-dt inf paired every pose).
  if (used == 0 || used != v->size() || !std::isfinite(x) || v->find_first_of("xXpP") != std::string::npos ||
      std::isspace(static_cast<unsigned char>(v->front())))
    throw InputError("usage", name + " expects a number, got '" + *v + "'");
  return x;
}

double CommandLine::numberIn(const std::string& name, double fallback, double low, bool low_included,
                             double at_most) const {
  const double x = number(name, fallback);
  if (!((low_included ? x >= low : x > low) && x <= at_most)) {
    std::string range = std::string("a number ") + (low_included ? ">= " : "> ") + fmt(low);
    if (std::isfinite(at_most)) range += " and <= " + fmt(at_most);
    throw InputError("usage", name + " expects " + range + ", got '" + value(name, fmt(x)) + "'");
  }
  return x;
}

double CommandLine::number(const std::string& name, double fallback, double above, double at_most) const {
  return numberIn(name, fallback, above, false, at_most);
}

double CommandLine::numberFrom(const std::string& name, double fallback, double at_least, double at_most) const {
  return numberIn(name, fallback, at_least, true, at_most);
}

bool CommandLine::flag(const std::string& name) const { return flags_.count(name) > 0; }

namespace {
// One line whatever threw (OpenCV's and MRPT's messages span several).
void report(const char* app_name, const std::exception& e) {
  const std::string line = oneLineMessage(e);
  if (app_name) std::fprintf(stderr, "%s: error: %s\n", app_name, line.c_str());
  else std::fprintf(stderr, "%s\n", line.c_str());
}
}  // namespace

int runApp(const char* app_name, int (*body)(int, char**), int argc, char** argv) {
  keepFreedHeapForFrames();
  try {
    return body(argc, argv);
  } catch (const InputError& e) {
    report(app_name, e);
    return 2;
  } catch (const std::exception& e) {
    report(app_name, e);
    return 1;
  }
}

}  // namespace vofusion
