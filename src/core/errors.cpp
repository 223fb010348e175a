#include "vofusion/core/errors.h"

namespace vofusion {

std::string oneLineMessage(const std::exception& e) {
  std::string s = e.what();
  const auto m = s.find("Message:");
  if (m != std::string::npos) {
    s = s.substr(m + 8);
    const auto end = s.find('\n');
    if (end != std::string::npos) s = s.substr(0, end);
  }
  for (char& c : s)
    if (c == '\n' || c == '\r') c = ' ';
  const auto a = s.find_first_not_of(' '), b = s.find_last_not_of(' ');
  return a == std::string::npos ? "unknown error" : s.substr(a, b - a + 1);
}

}  // namespace vofusion
