#include "vofusion/core/errors.h"

namespace vofusion {

std::string oneLineMessage(const std::exception& e) {
  std::string s = e.what();
  const auto m = s.find("Message:");
  if (m != std::string::npos) {
    // MRPT's message up to its location or call stack, its lines joined: an assertion's values follow
    // it on lines of their own ("ASSERT_LT_(p.deviceIndexToUse,numDevices) failed with
    // p.deviceIndexToUse=0 numDevices=0").
    s = s.substr(m + 8);
    for (const char* end : {"\nLocation:", "\nCall stack", "\n\n"}) s = s.substr(0, s.find(end));
  }
  std::string out;
  for (char c : s) {
    if (c == '\n' || c == '\r' || c == '\t') c = ' ';
    if (c != ' ' || (!out.empty() && out.back() != ' ')) out += c;
  }
  while (!out.empty() && out.back() == ' ') out.pop_back();
  return out.empty() ? "unknown error" : out;
}

}  // namespace vofusion
