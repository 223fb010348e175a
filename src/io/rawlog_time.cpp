#include "vofusion/io/rawlog_time.h"

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <stdexcept>

namespace vofusion {

namespace {
constexpr std::uint64_t kTicksTo1970 = UINT64_C(116444736) * UINT64_C(1000000000);  // 100 ns ticks, 1601 to 1970
}  // namespace

mrpt::Clock::time_point rawlogTime(double seconds) {
  if (!rawlogCanHold(seconds)) {
    char text[160];
    std::snprintf(text, sizeof text,
                  "timestamp %.10g s is beyond what a rawlog's clock holds (Unix time in seconds, %.4g to %.4g)", seconds,
                  kEarliestRawlogSeconds, kLatestRawlogSeconds);
    throw std::out_of_range(text);
  }
  // MRPT's own arithmetic from 0 s on (truncated to the tick), mirrored below it; but a value within a
  // thousandth of a tick below a whole one is that tick: a stamp read from a rawlog (rawlogSeconds) lies
  // just under its tick as often as over it, and truncated it lost one (3 % of 30 Hz stamps from 0).
  const double t = std::abs(seconds) * 10000000.0, whole = std::ceil(t);
  const std::uint64_t n = std::uint64_t(whole - t < 1e-3 ? whole : t);
  const std::uint64_t ticks = seconds >= 0 ? kTicksTo1970 + n : kTicksTo1970 - n;
  return mrpt::Clock::time_point(mrpt::Clock::duration(mrpt::Clock::rep(ticks)));
}

double rawlogSeconds(mrpt::Clock::time_point t) {
  const std::uint64_t ticks = std::uint64_t(t.time_since_epoch().count());
  if (ticks == 0) return 0.0;
  return ticks >= kTicksTo1970 ? double(ticks - kTicksTo1970) / 10000000.0 : -(double(kTicksTo1970 - ticks) / 10000000.0);
}

}  // namespace vofusion
