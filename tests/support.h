#pragma once
// Shared helpers for the test suite.
#include <cstddef>
#include <cstdint>
#include <chrono>
#include <functional>
#include <future>
#include <memory>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include <gtest/gtest.h>
#include <mrpt/config/CConfigFileMemory.h>

#include "vofusion/sim/synthetic_sequence.h"

namespace vofusion::test {

// The checkout's root and its share/ folder, and the build's bin/ folder.
std::string sourceDir();
std::string shareDir();
std::string binDir();
// The real TUM sequence shipped beside the project (../shared/data/tum/...).
std::string tumFirst300();
// Skips the test when shared data is missing; fails with a clear message under CI (CI=true).
#define VOFUSION_REQUIRE_DATA(path)                                                          \
  do {                                                                                       \
    if (!vofusion::test::dataPresent(path)) {                                                \
      if (vofusion::test::inCi()) FAIL() << "shared test data missing in CI: " << (path);     \
      GTEST_SKIP() << "shared test data missing: " << (path);                                \
    }                                                                                        \
  } while (0)
bool dataPresent(const std::string& path);
bool inCi();

// A fresh empty directory under the build tree, in a folder of the running test case's own (ctest runs
// cases in parallel); removed at process exit is not promised.
std::string tempDir(const std::string& name);
// The descriptors of the spill files (core/spill_file.h, unlinked once made) this process holds in
// `dir`; spillFileIn: the first, or -1. A test damages or cuts them as a failing disk would.
std::vector<int> spillFilesIn(const std::string& dir);
int spillFileIn(const std::string& dir);
// Path of an app built by this project (build/bin/<name>).
std::string app(const std::string& name);
// Runs a shell command; returns its exit code and fills output (stdout+stderr).
int run(const std::string& cmd, std::string* output = nullptr);
// A command stopped by a signal in the middle of its work, as a user's Ctrl-C would: run in the
// background with its stdout+stderr in `log_path`; `signal` (kill's name: INT, TERM) is sent once a
// progress line in `watch_path` (the log itself when empty) shows "N/<total> frames" with
// from <= N < total, or once it has ended, or after two minutes without one.
struct SignalledRun {
  int exit_code = -1;               // the shell's: 128 + the signal's number for a run it stopped
  // false: not signalled at a count: a machine that finished first (exit 0), or a command that failed
  // or showed no count in two minutes (then stopped; the caller's test fails: ASSERT_EQ(exit_code, 0)
  // before it skips). A command that has ended is never signalled (its pid may be another's by then).
  bool signalled_at_a_count = false;
  std::string log;                  // what the command wrote to log_path
};
SignalledRun runSignalledMidway(const std::string& command, const std::string& log_path, int total_frames,
                                const std::string& signal, int from = 3, const std::string& watch_path = "");
// The lines of a text, without their newlines.
std::vector<std::string> lines(const std::string& text);

// A tmpfs of `size` (mount's option, e.g. "300k") on dir while the object lives: a disk that fills up.
// mounted() is false where this machine does not allow it (not root): the test then skips.
class ScopedTmpfs {
 public:
  ScopedTmpfs(const std::string& dir, const std::string& size);
  ~ScopedTmpfs();
  ScopedTmpfs(const ScopedTmpfs&) = delete;
  ScopedTmpfs& operator=(const ScopedTmpfs&) = delete;
  bool mounted() const { return mounted_; }

 private:
  std::string dir_;
  bool mounted_ = false;
};
// What fn throws (its what()), "no error" if nothing, called in a child process that runs as user
// nobody when this one is root: a file made unreadable (chmod 000) is unreadable there too, where root
// reads any file. Empty if the child could not be made or could not drop its rights.
std::string errorWithoutPrivileges(const std::function<void()>& fn);
// Where a JPEG's first scan's entropy-coded data starts (after its SOS segment); size() if none.
std::size_t jpegScanStart(const std::vector<std::uint8_t>& jpeg);
// The JPEG with a restart marker (RST3) written over two bytes in the middle of its scan, where the
// file has no restart intervals: damage libjpeg always notices ("premature end of data segment"), and
// cv::imdecode still gives a picture.
std::vector<std::uint8_t> jpegWithMarkerInside(std::vector<std::uint8_t> jpeg);
// A synthetic sequence's options at 320x240, which keeps the suite quick.
sim::SimOptions quickSim(const std::string& scene, std::size_t frames, const std::string& trajectory = "smooth");
// The first `count` frames of seq (all by default), rendered once, for a test that runs the same frames
// more than once: rendering a 320x240 shake frame (blurred colour) takes longer than reconstructing it.
// 90 frames at 320x240: 48 MB; 80 at 640x480: 170 MB.
std::vector<Frame> renderFrames(const sim::SyntheticSequence& seq, std::size_t count = std::size_t(-1));
// The frame with images of its own (a copied cv::Mat shares its pixels): one run cannot change another's.
Frame deepCopy(const Frame& frame);
// The pipeline's settings for quickSim's room: 1 cm voxels in a 2.56 m volume, the odometry on STAR
// keypoints only (PCL's NARF is not the question).
mrpt::config::CConfigFileMemory quickRoomConfig();

// What fn returns, if it returns within `seconds`; nullopt if it does not (it runs on a thread of its
// own, left behind when it blocks for good: a reader waiting for a FIFO's writer).
template <class T>
std::optional<T> resultWithin(double seconds, std::function<T()> fn) {
  auto promise = std::make_shared<std::promise<T>>();
  auto result = promise->get_future();
  std::thread([promise, fn = std::move(fn)] { promise->set_value(fn()); }).detach();
  if (result.wait_for(std::chrono::duration<double>(seconds)) != std::future_status::ready) return std::nullopt;
  return result.get();
}

}  // namespace vofusion::test
