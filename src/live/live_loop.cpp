#include "vofusion/live/live_loop.h"

#include <condition_variable>
#include <deque>
#include <mutex>
#include <thread>

#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/thread_name.h"

namespace vofusion {

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
      if (!source.grab(frame, raw, sh.stop)) break;
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
  if (sh.stop && reason == StopReason::EndOfStream) reason = StopReason::Interrupted;
  if (sh.stats.error.empty()) {  // a consumer error set first wins
    if (sh.stats.stop != StopReason::ConsumerError) sh.stats.stop = reason;
    sh.stats.error = error;
  }
  sh.producer_done = true;
  sh.cv.notify_one();
}

}  // namespace

LiveStats runLive(LiveSource& source, const FrameConsumer& consumer, const LiveOptions& options,
                  const LiveHooks& hooks) {
  LiveOptions opt = options;
  if (opt.queue_capacity < 1) opt.queue_capacity = 1;
  Shared sh;
  const auto t0 = std::chrono::steady_clock::now();
  auto elapsed = [&] { return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(); };
  std::thread producer([&] { produce(source, opt, hooks, sh); });
  // Whatever leaves this function (an exception from a hook) stops and joins the producer first: a
  // joinable std::thread's destructor ends the process.
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
  } join_on_exit{sh, producer};

  auto last_tick = std::chrono::steady_clock::now();
  auto tick = [&](bool force) {
    if (!hooks.on_tick) return;
    const auto now = std::chrono::steady_clock::now();
    if (!force && now - last_tick < std::chrono::milliseconds(100)) return;
    last_tick = now;
    LiveStats snapshot;
    {
      std::lock_guard<std::mutex> lk(sh.m);
      snapshot = sh.stats;
    }
    snapshot.seconds = elapsed();
    hooks.on_tick(snapshot);
  };

  for (;;) {
    Frame frame;
    {
      std::unique_lock<std::mutex> lk(sh.m);
      if (externalStop(hooks)) sh.stop = true;
      if (sh.stop || !sh.stats.error.empty()) {
        // Stopping: wait for the producer to leave grab(); what is still queued counts as dropped.
        sh.stop = true;
        if (sh.cv.wait_for(lk, std::chrono::milliseconds(100), [&] { return sh.producer_done; })) break;
        lk.unlock();
        tick(false);
        continue;
      }
      sh.cv.wait_for(lk, std::chrono::milliseconds(100),
                     [&] { return !sh.queue.empty() || sh.producer_done || externalStop(hooks); });
      if (sh.queue.empty() || externalStop(hooks)) {
        if (sh.producer_done && sh.queue.empty()) break;
        lk.unlock();
        tick(false);
        continue;
      }
      frame = std::move(sh.queue.front());
      sh.queue.pop_front();
    }
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
      continue;
    }
    {
      std::lock_guard<std::mutex> lk(sh.m);
      ++sh.stats.processed;
    }
    tick(true);
  }
  producer.join();
  LiveStats out;
  {
    std::lock_guard<std::mutex> lk(sh.m);
    sh.stats.dropped += sh.queue.size();  // left behind by an interruption or an error
    sh.queue.clear();
    if (sh.stop && sh.stats.stop == StopReason::EndOfStream) sh.stats.stop = StopReason::Interrupted;
    out = sh.stats;
  }
  out.seconds = elapsed();
  if (hooks.on_tick) hooks.on_tick(out);
  return out;
}

}  // namespace vofusion
