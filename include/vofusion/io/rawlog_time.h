#pragma once
// Timestamps in seconds (Unix time, as TUM lists and Frame::timestamp give them) to and from MRPT's.
// mrpt::Clock counts 100 ns ticks since 1601 in a 64-bit number, but converts through unsigned ones:
// Clock::fromDouble is undefined below 0 s and above ~1.84e12 s (a nanosecond stamp came back as 0), and
// Clock::toDouble wraps a time before 1970 to ~1.8e12 s (a colour image taken 5 ms before a first frame
// at 0 s). These convert the whole range a rawlog holds, the same as MRPT's from 0 s on, except that a
// value within a thousandth of a tick below a whole tick is that tick (MRPT truncates it to the one
// before: a stamp read back from a rawlog lost 100 ns when written again).
#include <mrpt/core/Clock.h>

namespace vofusion {

// Unix time in seconds that a rawlog holds: from 1601 to about the year 30000 (a signed 64-bit count of
// 100 ns ticks). A stamp beyond it is in another unit (nanoseconds since 1970 are ~1.7e18).
constexpr double kEarliestRawlogSeconds = -11644473600.0;
constexpr double kLatestRawlogSeconds = 9.0e11;
inline bool rawlogCanHold(double seconds) {
  return seconds > kEarliestRawlogSeconds && seconds <= kLatestRawlogSeconds;  // 1601 itself is the unset stamp
}

// std::out_of_range (naming the stamp) for what rawlogCanHold refuses, NaN included.
mrpt::Clock::time_point rawlogTime(double seconds);
// 0 for an unset stamp, as MRPT's toDouble.
double rawlogSeconds(mrpt::Clock::time_point t);

}  // namespace vofusion
