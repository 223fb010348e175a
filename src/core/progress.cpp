#include "vofusion/core/progress.h"

#include <unistd.h>

#include <algorithm>
#include <cstdio>
#include <mutex>
#include <set>

namespace vofusion {

Progress::Progress(std::string label, std::size_t total, std::string unit)
    : label_(std::move(label)), unit_(std::move(unit)), rate_unit_(unit_ == "frames" ? "fps" : unit_ + "/s"),
      total_(total), start_(std::chrono::steady_clock::now()), last_print_(start_ - std::chrono::hours(1)), tty_(::isatty(STDERR_FILENO) != 0) {}

double Progress::elapsedSeconds() const {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
}

void Progress::startAt(std::size_t done) { done_ = start_done_ = done; }

double Progress::fps() const {
  const double t = elapsedSeconds();
  return t > 0 ? (done_ - std::min(done_, start_done_)) / t : 0.0;
}

static std::string formatDuration(double s) {
  char buf[32];
  if (!(s < 1e8)) return "?";  // an hour count past int's range (and no ETA anyone waits for)
  if (s >= 3600) std::snprintf(buf, sizeof buf, "%dh%02dm", int(s / 3600), int(s / 60) % 60);
  else if (s >= 60) std::snprintf(buf, sizeof buf, "%dm%02ds", int(s / 60), int(s) % 60);
  else std::snprintf(buf, sizeof buf, "%.0fs", s);
  return buf;
}

void Progress::update(std::size_t done, const std::string& extra) {
  done_ = done;
  const auto now = std::chrono::steady_clock::now();
  const double since = std::chrono::duration<double>(now - last_print_).count();
  // The last item is said at once, once: a caller ticking on while nothing moves (a live session
  // waiting for its sensor, total unknown: 0 of 0) printed a line per tick into a log.
  const bool at_end = total_ > 0 && done == total_ && last_printed_ != done;
  if (since < (tty_ ? 0.2 : 2.0) && !at_end) return;
  last_print_ = now;
  last_printed_ = done;
  // No rate (nor ETA) from less than a second: the first item may have been done before the clock started.
  const double rate = elapsedSeconds() >= 1.0 ? fps() : 0.0;
  char rate_text[48] = "-";
  if (rate > 0) std::snprintf(rate_text, sizeof rate_text, "%.1f", rate);
  std::string eta = "?";
  if (total_ > 0 && rate > 0) eta = formatDuration((total_ - std::min(done, total_)) / rate);
  if (total_ > 0)
    std::fprintf(stderr, "%s%s %zu/%zu %s  %s %s  ETA %s  %s%s", tty_ ? "\r\033[K" : "", label_.c_str(), done,
                 total_, unit_.c_str(), rate_text, rate_unit_.c_str(), eta.c_str(), extra.c_str(), tty_ ? "" : "\n");
  else
    std::fprintf(stderr, "%s%s %zu %s  %s %s  %s%s", tty_ ? "\r\033[K" : "", label_.c_str(), done, unit_.c_str(),
                 rate_text, rate_unit_.c_str(), extra.c_str(), tty_ ? "" : "\n");
  std::fflush(stderr);
}

void Progress::finish(const std::string& extra) {
  std::fprintf(stderr, "%s%s %zu %s in %s (%.1f %s)  %s\n", tty_ ? "\r\033[K" : "", label_.c_str(), done_,
               unit_.c_str(), formatDuration(elapsedSeconds()).c_str(), fps(), rate_unit_.c_str(), extra.c_str());
}

void printAboveProgress(const std::string& line) {
  std::fprintf(stderr, "%s%s\n", ::isatty(STDERR_FILENO) ? "\r\033[K" : "", line.c_str());
}

// Once per process: a recording opened a second time (the re-fusion) has nothing new to say.
void printWarning(const std::string& line) {
  static std::mutex mutex;
  static std::set<std::string> said;
  {
    const std::lock_guard<std::mutex> lock(mutex);
    if (!said.insert(line).second) return;
  }
  printAboveProgress("warning: " + line);
}

}  // namespace vofusion
