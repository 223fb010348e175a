#include "vofusion/core/timing.h"

#include <unistd.h>

#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>
#include <string>

namespace vofusion {

double secondsSinceProcessStart() {
  const double nan = std::numeric_limits<double>::quiet_NaN();
  // /proc/self/stat: field 22 is the start time in clock ticks since boot. The command name (field 2,
  // in parentheses) may hold spaces: fields are counted from its closing parenthesis.
  std::ifstream stat_file("/proc/self/stat");
  const std::string stat((std::istreambuf_iterator<char>(stat_file)), std::istreambuf_iterator<char>());
  const std::size_t name_end = stat.rfind(')');
  if (name_end == std::string::npos) return nan;
  std::istringstream fields(stat.substr(name_end + 1));
  std::string skipped;
  for (int field = 3; field < 22; ++field) fields >> skipped;
  double start_ticks = 0.0, uptime = 0.0;
  std::ifstream uptime_file("/proc/uptime");
  const long ticks_per_second = sysconf(_SC_CLK_TCK);
  if (!(fields >> start_ticks) || !(uptime_file >> uptime) || ticks_per_second <= 0) return nan;
  const double seconds = uptime - start_ticks / double(ticks_per_second);
  // Negative where the two files disagree (an uptime virtualised for a container): unknown, not 0.
  return seconds >= 0.0 ? seconds : nan;
}

}  // namespace vofusion
