#pragma once
// A one-line progress report for long jobs: "label 120/300 frames  28.4 fps  ETA 6s  <extra>".
#include <chrono>
#include <cstddef>
#include <optional>
#include <string>

namespace vofusion {

// One line on stderr of its own (a warning during a long job): on a terminal it first clears the
// progress line being redrawn, which the next update() draws again below it.
void printAboveProgress(const std::string& line);
// "warning: <line>" the same way, once per process for each line: something assumed or skipped, the
// run goes on.
void printWarning(const std::string& line);

class Progress {
 public:
  // total = 0 when unknown (no ETA). Output goes to stderr, redrawn at most every 0.2 s
  // (on a terminal with '\r', otherwise one line per ~2 s so logs stay short).
  // `unit` names what is counted ("frames": the rate is shown as fps, else as <unit>/s).
  Progress(std::string label, std::size_t total, std::string unit = "frames");
  void update(std::size_t done, const std::string& extra = "");
  // The job continues one done earlier (a resumed run): the count starts at `done`, the rate and the
  // ETA count only what this one does.
  void startAt(std::size_t done);
  void finish(const std::string& extra = "");
  double elapsedSeconds() const;
  double fps() const;

 private:
  std::string label_, unit_, rate_unit_;
  std::size_t total_, done_ = 0, start_done_ = 0;
  std::optional<std::size_t> last_printed_;  // the count last printed
  std::chrono::steady_clock::time_point start_, last_print_;
  bool tty_;
};

}  // namespace vofusion
