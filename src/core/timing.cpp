#include "vofusion/core/timing.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>
#include <string>

namespace vofusion {

double secondsSinceProcessStart() {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  // /proc/self/stat: field 22 is the start time in clock ticks since boot. The command name (field 2,
  // in parentheses) may hold spaces: count the fields after its closing parenthesis.
  std::ifstream stat_file("/proc/self/stat");
  const std::string stat((std::istreambuf_iterator<char>(stat_file)), std::istreambuf_iterator<char>());
  const std::size_t name_end = stat.rfind(')');
  if (name_end == std::string::npos) return nan;
  std::istringstream fields(stat.substr(name_end + 1));
  std::string field;
  for (int i = 3; i <= 22 && fields >> field; ++i)
    if (i == 22) {
      double uptime = 0.0;
      std::ifstream uptime_file("/proc/uptime");
      const long ticks = sysconf(_SC_CLK_TCK);
      if (!(uptime_file >> uptime) || ticks <= 0) return nan;
      return std::max(0.0, uptime - std::stod(field) / double(ticks));
    }
  return nan;
}

}  // namespace vofusion
