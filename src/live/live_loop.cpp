#include "vofusion/live/live_loop.h"

#include <chrono>
#include <condition_variable>
#include <deque>
#include <mutex>
#include <optional>
#include <thread>

#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/thread_name.h"

namespace vofusion {

std::vector<ConfigSection> withGrabSection(std::vector<ConfigSection> ours) {
  static const LiveOptions defaults;
  ours.push_back({"vofusion-grab", &defaults});
  return ours;
}

void LiveOptions::loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& s) {
  const double queue = readNumber(cfg, s, "queue_capacity", double(queue_capacity), true);
  sensor_timeout = readNumber(cfg, s, "sensor_timeout", sensor_timeout);
  replay_speed = readNumber(cfg, s, "replay_speed", replay_speed);
  const double most = readNumber(cfg, s, "max_frames", double(max_frames), true);
  if (!(queue >= 1 && queue <= kMostQueued)) throw InputError("[" + s + "] queue_capacity", "must be in [1, 1000] frames");
  if (!(most >= 0 && most <= 1e15)) throw InputError("[" + s + "] max_frames", "must be in [0, 1e15] frames (0 = all)");
  queue_capacity = std::size_t(queue);
  max_frames = std::size_t(most);
  if (!(sensor_timeout > 0 && sensor_timeout <= 3600)) throw InputError("[" + s + "] sensor_timeout", "must be in (0, 3600] s");
  if (!replaySpeedInRange(replay_speed))
    throw InputError("[" + s + "] replay_speed", "must be 0 (as fast as possible) or in [0.001, 1000]");
}

void LiveOptions::saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& s) const {
  cfg.write(s, "queue_capacity", uint64_t(queue_capacity));
  cfg.write(s, "sensor_timeout", sensor_timeout);
  cfg.write(s, "replay_speed", replay_speed);
  cfg.write(s, "max_frames", uint64_t(max_frames));
}

std::string stopReasonName(StopReason r) {
  switch (r) {
    case StopReason::EndOfStream: return "end of stream";
    case StopReason::MaxFrames: return "max frames reached";
    case StopReason::Interrupted: return "interrupted";
    case StopReason::SourceError: return "sensor error";
    case StopReason::RecorderError: return "recording error";
    case StopReason::ConsumerError: return "processing error";
  }
  return "?";
}

namespace {

struct Shared {
  std::mutex m;
  std::condition_variable cv;
  std::deque<Frame> queue;
  bool producer_done = false;
  std::atomic<bool> stop{false};  // consumer -> producer: stop grabbing
  LiveStats stats;                // played/dropped/max_queue/stop/error written under m
};

bool externalStop(const LiveHooks& h) { return h.stop && h.stop->load(); }

// In a catch block: what the exception in flight says, on one line (LiveStats::error is one line of
// grab-summary.txt; OpenCV's and MRPT's messages span several) and never empty (an empty error is a run
// that went fine).
std::string currentExceptionText() {
  try {
    throw;
  } catch (const std::exception& e) {
    return oneLineMessage(e);
  } catch (...) {
    return "unknown exception";
  }
}

// In a catch block: whether the exception in flight is a FrameDoneError.
bool frameWasDone() {
  try {
    throw;
  } catch (const FrameDoneError&) {
    return true;
  } catch (...) {
    return false;
  }
}

void produce(LiveSource& source, const LiveOptions& opt, const LiveHooks& hooks, Shared& sh) {
  nameThisThread("vof-grab");
  StopReason reason = StopReason::EndOfStream;
  std::string error;
  try {
    for (std::size_t n = 0;; ++n) {
      if (opt.max_frames > 0 && n >= opt.max_frames) {
        reason = StopReason::MaxFrames;
        break;
      }
      Frame frame;
      mrpt::obs::CObservation3DRangeScan::Ptr raw;
      // A stop asked for (Ctrl-C) ends the recording here, not once the consumer is done with the frame
      // in hand (only it copied the request into sh.stop: a 4 s frame recorded 75 more); a frame that
      // arrives after it is not recorded.
      if (externalStop(hooks)) sh.stop = true;
      if (!source.grab(frame, raw, sh.stop) || externalStop(hooks)) break;
      frame.index = n;
      if (hooks.on_grabbed) {
        try {
          hooks.on_grabbed(frame, raw);
        } catch (...) {
          reason = StopReason::RecorderError;
          error = currentExceptionText();
          // This frame was played but will never reach the consumer.
          std::lock_guard<std::mutex> lk(sh.m);
          ++sh.stats.played;
          ++sh.stats.dropped;
          break;
        }
      }
      std::lock_guard<std::mutex> lk(sh.m);
      ++sh.stats.played;
      if (sh.queue.size() >= opt.queue_capacity) {
        sh.queue.pop_front();  // drop the oldest: the consumer should see the freshest frame
        ++sh.stats.dropped;
      }
      sh.queue.push_back(std::move(frame));
      sh.stats.max_queue = std::max(sh.stats.max_queue, sh.queue.size());
      sh.cv.notify_one();
    }
  } catch (const std::exception& e) {
    reason = StopReason::SourceError;
    error = oneLineMessage(e);
  } catch (...) {  // not to end the process on this thread
    reason = StopReason::SourceError;
    error = "the source failed with an unknown exception";
  }
  std::lock_guard<std::mutex> lk(sh.m);
  if (externalStop(hooks)) sh.stop = true;
  if (sh.stop && reason == StopReason::EndOfStream) reason = StopReason::Interrupted;
  if (sh.stats.error.empty()) {  // a consumer error set first wins
    if (sh.stats.stop != StopReason::ConsumerError) sh.stats.stop = reason;
    sh.stats.error = error;
  }
  sh.producer_done = true;
  sh.cv.notify_one();
}

}  // namespace

namespace {

// hooks.on_tick with the statistics so far and the seconds since the start: at most every 100 ms
// unless forced (after each processed frame).
class Ticker {
 public:
  Ticker(Shared& sh, const LiveHooks& hooks) : sh_(sh), hooks_(hooks) {}
  double seconds() const { return std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count(); }
  void operator()(bool force) {
    if (!hooks_.on_tick) return;
    const auto now = std::chrono::steady_clock::now();
    if (!force && now - last_ < std::chrono::milliseconds(100)) return;
    last_ = now;
    LiveStats snapshot;
    {
      std::lock_guard<std::mutex> lk(sh_.m);
      snapshot = sh_.stats;
    }
    snapshot.seconds = seconds();
    hooks_.on_tick(snapshot);
  }

 private:
  Shared& sh_;
  const LiveHooks& hooks_;
  const std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  std::chrono::steady_clock::time_point last_ = start_;
};

// The oldest queued frame, or std::nullopt once the run is over: the producer done and nothing queued,
// or, when stopping (asked to, or after an error), the producer out of grab(). Ticks every 100 ms
// while it waits.
std::optional<Frame> nextFrame(Shared& sh, const LiveHooks& hooks, Ticker& tick) {
  for (;;) {
    {
      std::unique_lock<std::mutex> lk(sh.m);
      if (externalStop(hooks)) sh.stop = true;
      if (sh.stop || !sh.stats.error.empty()) {
        // Stopping: wait for the producer to leave grab(); what is still queued counts as dropped (at
        // runLive's end).
        sh.stop = true;
        if (sh.cv.wait_for(lk, std::chrono::milliseconds(100), [&] { return sh.producer_done; })) return std::nullopt;
      } else {
        sh.cv.wait_for(lk, std::chrono::milliseconds(100),
                       [&] { return !sh.queue.empty() || sh.producer_done || externalStop(hooks); });
        if (!sh.queue.empty() && !externalStop(hooks)) {
          Frame frame = std::move(sh.queue.front());
          sh.queue.pop_front();
          return frame;
        }
        if (sh.producer_done && sh.queue.empty()) return std::nullopt;
      }
    }
    tick(false);
  }
}

// The consumer on one frame, counted as processed (true). What it throws stops the run (the first error
// is its cause) and is counted as dropped, unless the frame was done before a later step failed.
bool consume(Shared& sh, const FrameConsumer& consumer, Frame& frame) {
  try {
    consumer(frame);
  } catch (...) {
    std::lock_guard<std::mutex> lk(sh.m);
    // Not finished: counted as dropped so processed stays honest; finished, then a later step failed:
    // processed, as the reconstruction holds it.
    ++(frameWasDone() ? sh.stats.processed : sh.stats.dropped);
    if (sh.stats.error.empty()) {  // the first error is the cause (a full disk: the recorder's, first)
      sh.stats.stop = StopReason::ConsumerError;
      sh.stats.error = currentExceptionText();
    }
    sh.stop = true;
    return false;
  }
  std::lock_guard<std::mutex> lk(sh.m);
  ++sh.stats.processed;
  return true;
}

// Whatever leaves runLive (an exception from a hook) stops and joins the producer first: a joinable
// std::thread's destructor ends the process.
struct JoinOnExit {
  Shared& sh;
  std::thread& t;
  ~JoinOnExit() {
    if (!t.joinable()) return;
    {
      std::lock_guard<std::mutex> lk(sh.m);
      sh.stop = true;
    }
    t.join();
  }
};

}  // namespace

LiveStats runLive(LiveSource& source, const FrameConsumer& consumer, const LiveOptions& options,
                  const LiveHooks& hooks) {
  LiveOptions opt = options;
  if (opt.queue_capacity < 1) opt.queue_capacity = 1;
  Shared sh;
  Ticker tick(sh, hooks);
  std::thread producer([&] { produce(source, opt, hooks, sh); });
  const JoinOnExit join_on_exit{sh, producer};
  while (std::optional<Frame> frame = nextFrame(sh, hooks, tick)) {
    if (consume(sh, consumer, *frame)) tick(true);
  }
  producer.join();
  LiveStats out;
  {
    std::lock_guard<std::mutex> lk(sh.m);
    // A stop that left frames behind after the play reached max_frames cost them: an interruption.
    const bool cost_frames = !sh.queue.empty();
    sh.stats.dropped += sh.queue.size();  // left behind by an interruption or an error
    sh.queue.clear();
    if (sh.stop && (sh.stats.stop == StopReason::EndOfStream || (sh.stats.stop == StopReason::MaxFrames && cost_frames)))
      sh.stats.stop = StopReason::Interrupted;
    out = sh.stats;
  }
  out.seconds = tick.seconds();
  if (hooks.on_tick) hooks.on_tick(out);
  return out;
}

}  // namespace vofusion
