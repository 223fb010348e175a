// The live loop (bounded queue, drops, stops) on synthetic sources, and on the replay of the TUM
// sequence through the very same code path, including recording into a rawlog read back after.
#include <atomic>
#include <chrono>
#include <filesystem>
#include <thread>
#include <vector>

#include <mrpt/config/CConfigFileMemory.h>
#include <mrpt/hwdrivers/CGenericSensor.h>
#include <mrpt/obs/CObservationIMU.h>

#include "support.h"
#include "vofusion/core/errors.h"
#include "vofusion/io/frame_source.h"
#include "vofusion/io/rawlog.h"
#include "vofusion/live/live_loop.h"
#include "vofusion/live/live_source.h"
#include "vofusion/sim/any_source.h"

namespace vofusion_test {
// A driver that keeps delivering observations, none of them a 3D scan (an IMU's section chosen as the
// sensor, a camera without depth).
class ImuOnlySensor : public mrpt::hwdrivers::CGenericSensor {
  DEFINE_GENERIC_SENSOR(ImuOnlySensor)
 public:
  void doProcess() override {
    auto o = mrpt::obs::CObservationIMU::Create();
    o->timestamp = mrpt::Clock::now();
    appendObservation(o);
  }
  void initialize() override { m_state = ssWorking; }

 protected:
  void loadConfig_sensorSpecific(const mrpt::config::CConfigFileBase&, const std::string&) override {}
};

// A driver that fails to initialise and then throws from its destructor, as COpenNI2Sensor does for a
// device_number past the devices plugged in (it closes that device): destroyed, it ends the program.
class UnopenableSensor : public mrpt::hwdrivers::CGenericSensor {
  DEFINE_GENERIC_SENSOR(UnopenableSensor)
 public:
  void doProcess() override {}
  void initialize() override { throw std::runtime_error("Sensor index is higher than the number of connected devices."); }
  ~UnopenableSensor() override { close(); }

 protected:
  void loadConfig_sensorSpecific(const mrpt::config::CConfigFileBase&, const std::string&) override {}

 private:
  static void close() { throw std::runtime_error("close(): no such device"); }
};
}  // namespace vofusion_test
IMPLEMENTS_GENERIC_SENSOR(ImuOnlySensor, vofusion_test)
IMPLEMENTS_GENERIC_SENSOR(UnopenableSensor, vofusion_test)

using namespace vofusion;
namespace fs = std::filesystem;

namespace {

// n tiny frames, one every period_ms, stamped 0, 0.1, 0.2 ...; optionally fails after fail_after.
class FakeSource : public LiveSource {
 public:
  FakeSource(std::size_t n, int period_ms, std::size_t fail_after = 0)
      : n_(n), period_ms_(period_ms), fail_after_(fail_after) {}
  bool grab(Frame& f, mrpt::obs::CObservation3DRangeScan::Ptr& raw, const std::atomic<bool>& stop) override {
    raw.reset();
    if (stop || i_ >= n_) return false;
    if (fail_after_ > 0 && i_ == fail_after_) throw SensorError("fake: unplugged");
    if (period_ms_ > 0) std::this_thread::sleep_for(std::chrono::milliseconds(period_ms_));
    f.timestamp = 0.1 * i_;
    f.rgb = cv::Mat(4, 4, CV_8UC3, cv::Scalar::all(double(i_ % 256)));
    f.depth = cv::Mat(4, 4, CV_32F, cv::Scalar(1.0));
    ++i_;
    return true;
  }
  std::string name() const override { return "fake"; }
  std::size_t size() const override { return n_; }

 private:
  std::size_t n_, i_ = 0;
  int period_ms_;
  std::size_t fail_after_;
};

LiveOptions queueOf(std::size_t capacity) {
  LiveOptions o;
  o.queue_capacity = capacity;
  return o;
}

}  // namespace

TEST(LiveLoop, FastConsumerProcessesEveryFrameInOrder) {
  FakeSource src(50, 1);
  std::vector<std::size_t> seen;
  // A queue that holds the whole play: no frame is ever dropped, however the threads are scheduled,
  // so every frame must come through once and in order.
  const LiveStats s = runLive(src, [&](const Frame& f) { seen.push_back(f.index); }, queueOf(64));
  EXPECT_TRUE(s.ok()) << s.error;
  EXPECT_EQ(s.stop, StopReason::EndOfStream);
  EXPECT_EQ(s.played, 50u);
  EXPECT_EQ(s.dropped, 0u);
  EXPECT_EQ(s.processed, 50u);
  ASSERT_EQ(seen.size(), 50u);
  for (std::size_t i = 0; i < seen.size(); ++i) EXPECT_EQ(seen[i], i);
}

TEST(LiveLoop, SlowConsumerDropsOldestAndNeverQueuesMoreThanCapacity) {
  FakeSource src(60, 2);  // ~500 fps producer
  std::vector<std::size_t> seen;
  const LiveStats s = runLive(src,
                              [&](const Frame& f) {
                                seen.push_back(f.index);
                                std::this_thread::sleep_for(std::chrono::milliseconds(20));
                              },
                              queueOf(3));
  EXPECT_TRUE(s.ok()) << s.error;
  EXPECT_EQ(s.played, 60u);
  EXPECT_GT(s.dropped, 0u);
  EXPECT_EQ(s.processed + s.dropped, s.played);
  EXPECT_LE(s.max_queue, 3u);
  // Drop-oldest keeps the freshest frames: the last frame played is always processed (drained).
  ASSERT_FALSE(seen.empty());
  EXPECT_EQ(seen.back(), 59u);
  for (std::size_t i = 1; i < seen.size(); ++i) EXPECT_LT(seen[i - 1], seen[i]);
}

TEST(LiveLoop, MaxFramesStopsThePlay) {
  FakeSource src(100, 0);
  LiveOptions o = queueOf(2);
  o.max_frames = 17;
  std::size_t recorded = 0;
  LiveHooks h;
  h.on_grabbed = [&](Frame&, const mrpt::obs::CObservation3DRangeScan::Ptr&) { ++recorded; };
  const LiveStats s = runLive(src, [](const Frame&) {}, o, h);
  EXPECT_EQ(s.stop, StopReason::MaxFrames);
  EXPECT_EQ(s.played, 17u);
  EXPECT_EQ(recorded, 17u);  // the tap sees every played frame, drops or not
  EXPECT_EQ(s.processed + s.dropped, s.played);
}

TEST(LiveLoop, SensorErrorMidRunIsACleanStop) {
  FakeSource src(100, 1, 30);
  std::size_t recorded = 0;
  LiveHooks h;
  h.on_grabbed = [&](Frame&, const mrpt::obs::CObservation3DRangeScan::Ptr&) { ++recorded; };
  const LiveStats s = runLive(src, [](const Frame&) {}, queueOf(2), h);
  EXPECT_EQ(s.stop, StopReason::SourceError);
  EXPECT_NE(s.error.find("unplugged"), std::string::npos) << s.error;
  EXPECT_EQ(s.played, 30u);
  EXPECT_EQ(recorded, 30u);
  EXPECT_EQ(s.processed + s.dropped, s.played);
}

TEST(LiveLoop, ConsumerExceptionStopsWithoutLosingCount) {
  // Long enough that a late consumer still stops it before its end (1000 frames were a second: a
  // consumer thread started later than that on a loaded machine failed the test).
  FakeSource src(100000, 1);
  const LiveStats s = runLive(src,
                              [](const Frame& f) {
                                // From frame 10 on: frame 10 itself may be dropped when this thread is late.
                                if (f.index >= 10) throw std::runtime_error("boom");
                              },
                              queueOf(2));
  EXPECT_EQ(s.stop, StopReason::ConsumerError);
  EXPECT_EQ(s.error, "boom");
  EXPECT_LT(s.played, 100000u);
  EXPECT_EQ(s.processed + s.dropped, s.played);
}

// An error is one line (grab-summary.txt's "error:" field; OpenCV's and MRPT's messages span several)
// and never empty: an exception with an empty message left the run "ok" (exit 0) though it stopped it.
TEST(LiveLoop, AnErrorIsOneLineAndNeverEmpty) {
  for (const auto& [thrown, said] : std::vector<std::pair<std::string, std::string>>{{"OpenCV(4.6.0) x.cpp:1: error:\n> bad\n", "OpenCV(4.6.0) x.cpp:1: error: > bad"},
                                                                                    {"", "unknown error"}}) {
    FakeSource src(100, 1);
    const LiveStats s = runLive(src, [&](const Frame&) { throw std::runtime_error(thrown); }, queueOf(2));
    EXPECT_EQ(s.stop, StopReason::ConsumerError);
    EXPECT_EQ(s.error, said);
    EXPECT_FALSE(s.ok());
  }
}

// What no std::exception describes stops the run as well, on either thread, and a hook that throws
// leaves runLive with its exception once the producer has stopped: a joinable std::thread's destructor
// used to end the process.
TEST(LiveLoop, AnyExceptionStopsTheRunAndAThrowingHookLeavesWithIt) {
  {
    FakeSource src(1000, 1);
    const LiveStats s = runLive(src, [](const Frame& f) { if (f.index >= 3) throw 42; }, queueOf(2));
    EXPECT_EQ(s.stop, StopReason::ConsumerError);
    EXPECT_EQ(s.error, "unknown exception");
  }
  {
    FakeSource src(1000, 1);
    LiveHooks hooks;
    hooks.on_grabbed = [](Frame& f, const mrpt::obs::CObservation3DRangeScan::Ptr&) { if (f.index == 5) throw 7; };
    const LiveStats s = runLive(src, [](const Frame&) {}, queueOf(2), hooks);
    EXPECT_EQ(s.stop, StopReason::RecorderError);
    EXPECT_EQ(s.error, "unknown exception");
  }
  FakeSource src(1000, 1);
  LiveHooks hooks;
  hooks.on_tick = [](const LiveStats&) { throw std::runtime_error("window gone"); };
  EXPECT_THROW(runLive(src, [](const Frame&) {}, queueOf(2), hooks), std::runtime_error);
}

// The first error is the one reported: the recorder failed (a full disk), then the frame in hand's
// checkpoint did too; "processing error: checkpoint" hid the cause.
TEST(LiveLoop, TheFirstErrorWins) {
  FakeSource src(1000, 1);
  std::atomic<bool> recorder_failed{false}, consumer_holding{false};
  LiveHooks hooks;
  hooks.on_grabbed = [&](Frame& f, const mrpt::obs::CObservation3DRangeScan::Ptr&) {
    // Once the consumer holds a frame (on a busy machine it may start late: the recorder's error then
    // stopped the run before it took any).
    if (f.index >= 5 && consumer_holding && !recorder_failed) {
      recorder_failed = true;
      throw std::runtime_error("grab.rawlog: disk full");
    }
  };
  std::atomic<bool> consumer_threw{false};
  const LiveStats s = runLive(
      src,
      [&](const Frame&) {  // the first frame it sees (frame 0 may have been dropped: a late thread)
        if (consumer_threw) return;
        consumer_holding = true;
        for (int ms = 0; !recorder_failed && ms < 20000; ++ms) std::this_thread::sleep_for(std::chrono::milliseconds(1));
        std::this_thread::sleep_for(std::chrono::milliseconds(300));  // the recorder's error is in (TSAN: slow)
        consumer_threw = true;
        throw std::runtime_error("checkpoint: disk full");
      },
      queueOf(2), hooks);
  ASSERT_TRUE(consumer_threw) << "the second error never came: nothing to win against";
  EXPECT_EQ(s.stop, StopReason::RecorderError);
  EXPECT_EQ(s.error, "grab.rawlog: disk full");
}

// A consumer that finished its frame and then failed (vofusion-grab's checkpoint on a full disk, its
// window): the frame counts as processed, as the reconstruction holds it; the run stops.
TEST(LiveLoop, AFailureAfterTheFrameCountsItProcessed) {
  for (const bool done : {false, true}) {
    SCOPED_TRACE(done);
    FakeSource src(100, 1);
    std::size_t seen = 0;
    const LiveStats s = runLive(src,
                                [&](const Frame& f) {
                                  ++seen;
                                  if (f.index < 10) return;
                                  if (done) throw FrameDoneError("checkpoint: disk full");
                                  throw std::runtime_error("boom");
                                },
                                queueOf(2));
    EXPECT_EQ(s.stop, StopReason::ConsumerError);
    EXPECT_EQ(s.error, done ? "checkpoint: disk full" : "boom");
    EXPECT_EQ(s.processed, done ? seen : seen - 1);
    EXPECT_EQ(s.processed + s.dropped, s.played);
  }
}

TEST(LiveLoop, ExternalStopFlagInterrupts) {
  FakeSource src(100000, 1);
  std::atomic<bool> stop{false};
  LiveHooks h;
  h.stop = &stop;
  std::thread stopper([&] {
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    stop = true;
  });
  const LiveStats s = runLive(src, [](const Frame&) { std::this_thread::sleep_for(std::chrono::milliseconds(5)); },
                              queueOf(2), h);
  stopper.join();
  EXPECT_EQ(s.stop, StopReason::Interrupted);
  EXPECT_TRUE(s.ok());
  EXPECT_GT(s.played, 0u);
  EXPECT_LT(s.played, 100000u);
  EXPECT_EQ(s.processed + s.dropped, s.played);
}

// Ctrl-C stops the recording at once, not once the frame in hand is done: the grab thread went on
// recording while the consumer was inside one frame (a checkpoint, a slow first frame), 75 frames of a
// 30 Hz replay after the Ctrl-C with a 4 s frame (a review's run).
TEST(LiveLoop, AStopEndsTheRecordingWhileAFrameIsInHand) {
  FakeSource src(100000, 2);
  std::atomic<bool> stop{false};
  std::atomic<std::size_t> recorded{0}, recorded_at_stop{0};
  LiveHooks h;
  h.stop = &stop;
  h.on_grabbed = [&](Frame&, const mrpt::obs::CObservation3DRangeScan::Ptr&) { ++recorded; };
  const LiveStats s = runLive(src,
                              [&](const Frame&) {
                                std::this_thread::sleep_for(std::chrono::milliseconds(50));
                                stop = true;  // asked during the frame, which takes 300 ms more
                                // At most a frame already past its check when the stop came is recorded after it.
                                recorded_at_stop = recorded.load();
                                std::this_thread::sleep_for(std::chrono::milliseconds(300));
                              },
                              queueOf(2), h);
  EXPECT_EQ(s.stop, StopReason::Interrupted);
  EXPECT_LE(recorded.load(), recorded_at_stop.load() + 1) << "recorded after the stop";
  EXPECT_EQ(s.played, recorded.load());
  EXPECT_EQ(s.processed + s.dropped, s.played);
}

// A stop after the play reached --max-frames, while frames still wait, costs them: an interruption, not
// "max frames reached" (summary.json said interrupted: false with 58 of 60 frames dropped).
TEST(LiveLoop, AStopWhileTheLastFramesWaitIsAnInterruption) {
  FakeSource src(100, 0);
  LiveOptions o = queueOf(8);
  o.max_frames = 8;
  std::atomic<bool> stop{false};
  std::atomic<std::size_t> grabbed{0};
  LiveHooks h;
  h.stop = &stop;
  h.on_grabbed = [&](Frame&, const mrpt::obs::CObservation3DRangeScan::Ptr&) { ++grabbed; };
  const LiveStats s = runLive(src,
                              [&](const Frame&) {
                                // Asked once the play is over (however slow the grab thread is), frames waiting.
                                while (grabbed < 8) std::this_thread::sleep_for(std::chrono::milliseconds(1));
                                stop = true;
                              },
                              o, h);
  EXPECT_EQ(s.stop, StopReason::Interrupted);
  EXPECT_EQ(s.played, 8u);
  EXPECT_GT(s.dropped, 0u);
  EXPECT_EQ(s.processed + s.dropped, s.played);
}

TEST(LiveOptions, SaveWritesEveryKeyItLoads) {
  LiveOptions a;
  a.queue_capacity = 5;
  a.sensor_timeout = 2.5;
  a.replay_speed = 0;
  a.max_frames = 42;
  mrpt::config::CConfigFileMemory m;
  a.saveToConfigFile(m, "g");
  LiveOptions b;
  b.loadFromConfigFile(m, "g");
  EXPECT_EQ(b.queue_capacity, 5u);
  EXPECT_DOUBLE_EQ(b.sensor_timeout, 2.5);
  EXPECT_DOUBLE_EQ(b.replay_speed, 0.0);
  EXPECT_EQ(b.max_frames, 42u);
  m.write("g", "queue_capacity", 0);
  EXPECT_THROW(b.loadFromConfigFile(m, "g"), std::exception);
  // A speed so slow that a frame's wait overflows the clock's nanoseconds (1e-12: 3e19 ns) is refused.
  m.write("g", "queue_capacity", 2);
  m.write("g", "replay_speed", 1e-12);
  EXPECT_THROW(b.loadFromConfigFile(m, "g"), InputError);
  m.write("g", "replay_speed", 0.001);
  EXPECT_NO_THROW(b.loadFromConfigFile(m, "g"));
}

TEST(LiveReplay, PlaysAtTheRecordedRate) {
  const std::string tum = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(tum);
  SourceOptions so;
  so.max_frames = 31;
  auto fs_src = openFrameSource(tum, so);
  const double span = [&] {
    Frame f, last;
    fs_src->next(f);
    const double t0 = f.timestamp;
    while (fs_src->next(last)) {}
    return last.timestamp - t0;
  }();
  fs_src->rewind();
  ReplaySource src(std::move(fs_src), 2.0);  // twice as fast as recorded
  const LiveStats s = runLive(src, [](const Frame&) {}, queueOf(2));
  EXPECT_EQ(s.played, 31u);
  // Never earlier than the timestamps allow (sleeping cannot be early); lateness is load-dependent
  // here (each frame's PNGs are decoded on the playing thread): bounded below, with frames that cost
  // nothing to read.
  EXPECT_GE(s.seconds, span / 2.0 - 0.01);
}

namespace {
// Frames at the given timestamps, blank.
class StampedFrames : public FrameSource {
 public:
  explicit StampedFrames(std::vector<double> stamps) : stamps_(std::move(stamps)) {}
  bool next(Frame& f) override {
    if (i_ >= stamps_.size()) return false;
    f = Frame();
    f.index = i_;
    f.timestamp = stamps_[i_++];
    return true;
  }
  std::size_t size() const override { return stamps_.size(); }
  void rewind() override { i_ = 0; }
  std::string name() const override { return "stamps"; }

 private:
  std::vector<double> stamps_;
  std::size_t i_ = 0;
};
}  // namespace

// Plays the replay to its end (or the stop): frames delivered and the wall time it took.
std::pair<int, double> playToTheEnd(ReplaySource& src, const std::atomic<bool>& stop) {
  Frame f;
  mrpt::obs::CObservation3DRangeScan::Ptr raw;
  const auto start = std::chrono::steady_clock::now();
  int frames = 0;
  while (src.grab(f, raw, stop)) ++frames;
  return {frames, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count()};
}

// Frames that cost nothing to read play at the speed asked for: four times as fast takes a quarter of
// the recorded span (0.5 s of 2 s), and a replay that ignored the speed (the whole 2 s) is caught, with
// 1 s left for a loaded machine's late wake-ups (0.5 s was left of a 1 s span: ctest runs app tests
// beside this one). The play is scheduled against the first frame's time, so lateness does not add up.
TEST(LiveReplay, PlaysAtTheSpeedAskedFor) {
  std::vector<double> stamps;
  for (int i = 0; i < 61; ++i) stamps.push_back(i / 30.0);
  ReplaySource src(std::make_unique<StampedFrames>(stamps), 4.0);
  const std::atomic<bool> stop{false};
  const auto [frames, seconds] = playToTheEnd(src, stop);
  EXPECT_EQ(frames, 61);
  EXPECT_GE(seconds, 0.5 - 0.01);
  EXPECT_LT(seconds, 1.5);
}

// A recording whose clock jumps (an NTP step mid-recording: a day here) or steps back is played on as
// if those frames were at most a second apart: the replay slept for the whole jump.
TEST(LiveReplay, AClockJumpInTheRecordingIsNoWait) {
  ReplaySource src(std::make_unique<StampedFrames>(std::vector<double>{0.0, 0.033, 86400.0, 86400.033, 86399.0, 86399.033}), 1.0);
  std::atomic<bool> stop{false};
  std::thread timeout([&] {  // a replay that waits for the jump is stopped, not waited for
    for (int i = 0; i < 100 && !stop; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    stop = true;
  });
  const auto [frames, seconds] = playToTheEnd(src, stop);
  stop = true;
  timeout.join();
  EXPECT_EQ(frames, 6);
  EXPECT_GE(seconds, 1.0 + 3 * 0.033 - 0.01);  // the jump played as a second, the other gaps as recorded
  EXPECT_LT(seconds, 4.0);
}

// The sensor timeout holds while the driver delivers observations that are no RGB-D frame: the grab
// used to wait for ever (vofusion-grab at "recording 0 frames" until Ctrl-C).
TEST(SensorSource, ADriverGivingNoDepthFrameTimesOut) {
  vofusion_test::ImuOnlySensor::doRegister();
  mrpt::config::CConfigFileMemory cfg;
  cfg.write("imu", "driver", "ImuOnlySensor");
  SensorSource src(cfg, "imu", 0.3, "grab.ini");
  std::atomic<bool> stop{false};
  std::thread timeout([&] {  // a grab that never times out is stopped, not waited for
    for (int i = 0; i < 60 && !stop; ++i) std::this_thread::sleep_for(std::chrono::milliseconds(50));
    stop = true;
  });
  Frame f;
  mrpt::obs::CObservation3DRangeScan::Ptr raw;
  std::string error;
  try {
    src.grab(f, raw, stop);
  } catch (const SensorError& e) {
    error = e.what();
  }
  const bool stopped = stop.exchange(true);
  timeout.join();
  EXPECT_FALSE(stopped) << "no timeout within 3 s";
  EXPECT_NE(error.find("no frame for 0.3 s (sensor unplugged?)"), std::string::npos) << error;
}

// A sensor that cannot be opened is one line naming the config and its section, not an abort (exit
// 134) from the failed driver's destructor.
TEST(SensorSource, ADriverThatCannotOpenIsOneLineNotAnAbort) {
  vofusion_test::UnopenableSensor::doRegister();
  mrpt::config::CConfigFileMemory cfg;
  cfg.write("cam", "driver", "UnopenableSensor");
  try {
    SensorSource src(cfg, "cam", 0.3, "grab.ini");
    ADD_FAILURE() << "opened";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("grab.ini [cam]: UnopenableSensor: Sensor index is higher"), std::string::npos)
        << e.what();
  }
}

TEST(LiveReplay, TumThroughTheLivePathWithSlowConsumerAndRecording) {
  const std::string tum = test::tumFirst300();
  VOFUSION_REQUIRE_DATA(tum);
  const std::string dir = test::tempDir("live_replay");
  const std::string rawlog = dir + "/grab.rawlog";
  SourceOptions so;
  so.max_frames = 45;  // 1.5 s at the recorded 30 Hz
  ReplaySource src(openFrameSource(tum, so), 1.0);
  RawlogWriter writer(rawlog);
  // A consumer slower than the sensor whatever the machine's load: it finishes frame k only once
  // the sensor has played k + 4 (or everything), so with a queue of 2 frames must be dropped.
  std::atomic<std::size_t> played{0};
  LiveHooks h;
  h.on_grabbed = [&](Frame& f, const mrpt::obs::CObservation3DRangeScan::Ptr&) {
    writer.write(f);
    ++played;
  };
  std::vector<double> processed_stamps;
  const LiveStats s = runLive(src,
                              [&](const Frame& f) {
                                processed_stamps.push_back(f.timestamp);
                                const std::size_t until = std::min<std::size_t>(f.index + 5, 45);
                                const auto t0 = std::chrono::steady_clock::now();
                                while (played < until && std::chrono::steady_clock::now() - t0 < std::chrono::seconds(20))
                                  std::this_thread::sleep_for(std::chrono::milliseconds(2));
                              },
                              queueOf(2), h);
  writer.commit();
  EXPECT_TRUE(s.ok()) << s.error;
  EXPECT_EQ(s.played, 45u);
  EXPECT_GT(s.dropped, 0u);
  EXPECT_EQ(s.processed + s.dropped, s.played);
  EXPECT_EQ(writer.framesWritten(), 45u);  // the recording has no drops

  // The recording reads back frame for frame, equal to the source.
  auto back = openFrameSource(rawlog);
  auto orig = openFrameSource(tum, so);
  std::size_t n = 0;
  Frame a, b;
  while (back->next(a)) {
    ASSERT_TRUE(orig->next(b));
    EXPECT_NEAR(a.timestamp, b.timestamp, 1e-5);
    EXPECT_EQ(cv::norm(a.rgb, b.rgb, cv::NORM_INF), 0.0);
    EXPECT_LE(cv::norm(a.depth, b.depth, cv::NORM_INF), 1e-4);
    ++n;
  }
  EXPECT_EQ(n, 45u);
}
