#include "vofusion/core/text_file.h"

#include <filesystem>
#include <fstream>
#include <sstream>

#include "vofusion/core/errors.h"

namespace vofusion {

std::string readTextFile(const std::string& path) {
  std::error_code ec;
  if (std::filesystem::is_directory(path, ec)) throw InputError(path, "is a folder, expected a file");
  std::ifstream f(path, std::ios::binary);
  if (!f) throw InputError(path, "cannot open file");
  std::ostringstream ss;
  ss << f.rdbuf();
  return ss.str();
}

std::vector<TextLine> dataLines(const std::string& text) {
  std::vector<TextLine> lines;
  // A UTF-8 byte order mark (an editor's, e.g. Notepad's) is no part of the first line, as the config
  // reader takes it; it made a header comment line 1's data.
  std::istringstream in(text.rfind("\xEF\xBB\xBF", 0) == 0 ? text.substr(3) : text);
  std::string line;
  for (int n = 1; std::getline(in, line); ++n) {
    const auto first = line.find_first_not_of(" \t\r");
    if (first == std::string::npos || line[first] == '#') continue;
    lines.push_back({n, std::move(line)});
  }
  return lines;
}

}  // namespace vofusion
