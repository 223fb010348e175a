#pragma once
// The live loop: a producer thread grabs frames from a LiveSource into a bounded queue; the
// calling thread takes them out and hands them to a consumer (the reconstruction, a recorder, a
// test's deliberately slow function). The sensor never waits for the consumer: when the queue is
// full the OLDEST queued frame is dropped, so the consumer always gets the freshest view (lowest
// latency for tracking). Every played frame is either processed or dropped, never lost silently:
// played == processed + dropped, whatever ends the run.
#include <atomic>
#include <cstddef>
#include <functional>
#include <stdexcept>
#include <string>
#include <vector>

#include <mrpt/config/CLoadableOptions.h>
#include <mrpt/obs/CObservation3DRangeScan.h>

#include "vofusion/core/config.h"
#include "vofusion/core/frame.h"
#include "vofusion/live/live_source.h"

namespace vofusion {

struct LiveOptions : public mrpt::config::CLoadableOptions {
  std::size_t queue_capacity = 2;  // frames waiting for the consumer (>= 1); more are dropped
  double sensor_timeout = 5.0;     // s without a frame from the sensor = sensor lost
  double replay_speed = 1.0;       // x recorded rate for --replay (0 = as fast as frames load)
  std::size_t max_frames = 0;      // frames to play, 0 = until the source ends or Ctrl-C

  // The ranges the config and vofusion-grab's --queue / --speed are held to: a queue holds ~2 MB a
  // frame (1000: 2 GB); at 1/1000 of its rate a replay waits 33 s for each 30 Hz frame (1e-12 overflowed
  // the wait's nanoseconds).
  static constexpr std::size_t kMostQueued = 1000;
  static constexpr double kSlowestReplay = 1e-3, kFastestReplay = 1000;
  static bool replaySpeedInRange(double x) { return x == 0 || (x >= kSlowestReplay && x <= kFastestReplay); }

  void loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& section) override;
  void saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& section) const override;
};

// `ours` and vofusion-grab's own section, [vofusion-grab] (LiveOptions' defaults): what vofusion-grab's
// --config holds of ours, which vofusion and rgbd-odometry read again (a live run resumed offline).
std::vector<ConfigSection> withGrabSection(std::vector<ConfigSection> ours);

enum class StopReason { EndOfStream, MaxFrames, Interrupted, SourceError, RecorderError, ConsumerError };
std::string stopReasonName(StopReason r);

struct LiveStats {
  std::size_t played = 0;     // frames the source delivered (and the recorder got)
  std::size_t processed = 0;  // frames the consumer finished
  std::size_t dropped = 0;    // frames discarded because the consumer was busy (or left at a stop)
  std::size_t max_queue = 0;  // highest queue occupancy seen
  double seconds = 0.0;       // wall time of the run
  StopReason stop = StopReason::EndOfStream;
  std::string error;          // one line, empty unless stop is an error

  bool ok() const { return error.empty(); }
  double playedFps() const { return seconds > 0 ? played / seconds : 0.0; }
  double processedFps() const { return seconds > 0 ? processed / seconds : 0.0; }
};

// Runs on the calling thread (GUI, reconstruction), may be slow. An exception stops the run; the frame
// counts as dropped, unless the consumer throws FrameDoneError: the frame was done, a step after it failed.
using FrameConsumer = std::function<void(const Frame&)>;
struct FrameDoneError : std::runtime_error {
  using std::runtime_error::runtime_error;
};
// Runs on the producer thread for EVERY played frame, before queueing (the rawlog recorder: a
// recording never has drops; it names in Frame::colour_file / depth_file the files it wrote). `raw` is the
// sensor's own observation, or null for a replay.
using FrameTap = std::function<void(Frame&, const mrpt::obs::CObservation3DRangeScan::Ptr& raw)>;
// Called on the calling thread about every 0.1 s and after each processed frame (progress, GUI).
using LiveTick = std::function<void(const LiveStats&)>;

struct LiveHooks {
  FrameTap on_grabbed;                       // optional
  LiveTick on_tick;                          // optional
  const std::atomic<bool>* stop = nullptr;   // optional: set (e.g. by SIGINT) to stop cleanly
};

// Never throws for failures during the run: a sensor error, a recorder error or a consumer
// exception stop the run and land in LiveStats::stop/error (everything recorded so far stays
// recorded). On an error or an interruption, frames still queued count as dropped; at the end of
// the stream or at max_frames the queue is drained (processed).
LiveStats runLive(LiveSource& source, const FrameConsumer& consumer, const LiveOptions& options,
                  const LiveHooks& hooks = {});

}  // namespace vofusion
