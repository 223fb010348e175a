#pragma once
// Small text inputs (TUM lists and trajectories, intrinsics.txt): whole-file reads and the data lines
// of a '#'-commented format, with line numbers for error messages.
#include <string>
#include <vector>

namespace vofusion {

// The whole file; throws InputError(path, ...) when it cannot be opened or is over 256 MiB.
std::string readTextFile(const std::string& path);

struct TextLine {
  int number = 0;    // 1-based line number in the text
  std::string text;  // the line as written (may end with '\r')
};
// The lines that are neither blank nor comments (first non-blank character '#').
std::vector<TextLine> dataLines(const std::string& text);

}  // namespace vofusion
