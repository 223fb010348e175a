#pragma once
// Wall-clock time per pipeline stage (and a thread's CPU time), for the per-stage breakdowns apps
// print and summary.json holds.
#include <chrono>
#include <ctime>
#include <map>
#include <string>

namespace vofusion {

struct StageTimes {
  std::map<std::string, double> seconds;  // stage name -> accumulated wall time (s)
  std::map<std::string, long> calls;      // stage name -> how many times it ran

  void add(const std::string& stage, double s) { seconds[stage] += s; ++calls[stage]; }
  void merge(const StageTimes& o) {
    for (const auto& [k, v] : o.seconds) seconds[k] += v;
    for (const auto& [k, v] : o.calls) calls[k] += v;
  }
};

// CPU seconds the calling thread has used (POSIX CLOCK_THREAD_CPUTIME_ID): what a background thread
// costs the cores, where its wall time also counts the time it waited for one.
inline double threadCpuSeconds() {
  timespec ts{};
  clock_gettime(CLOCK_THREAD_CPUTIME_ID, &ts);
  return double(ts.tv_sec) + 1e-9 * double(ts.tv_nsec);
}

// Seconds of wall time since `start`.
inline double secondsSince(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

// Seconds since this process started, from /proc (10 ms steps): its start-up included (loading the
// libraries). NaN without /proc.
double secondsSinceProcessStart();

// Adds the lifetime of this object to times[stage].
class ScopedStageTimer {
 public:
  ScopedStageTimer(StageTimes& times, std::string stage)
      : times_(times), stage_(std::move(stage)), start_(std::chrono::steady_clock::now()) {}
  ~ScopedStageTimer() {
    times_.add(stage_, secondsSince(start_));
  }

 private:
  StageTimes& times_;
  std::string stage_;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace vofusion
