#pragma once
// poses.rawlog: the input observations, the odometry as actions and each frame's tracked pose, written
// on a thread of its own (PNG encoding must not slow the frame loop down). Private to src/pipeline/.
#include <condition_variable>
#include <deque>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>

#include <mrpt/obs/CObservationRobotPose.h>

#include "vofusion/core/errors.h"
#include "vofusion/core/frame.h"
#include "vofusion/core/thread_name.h"
#include "vofusion/core/trajectory.h"
#include "vofusion/io/rawlog.h"
#include "vofusion/io/rawlog_time.h"
#include "vofusion/pipeline/reconstruction.h"

namespace vofusion {

class PosesRawlog {
 public:
  explicit PosesRawlog(const std::string& path)
      : writer_(path, rawlogOptions()), thread_([this] { loop(); }) {}
  ~PosesRawlog() { stop(); }

  void push(const Frame& f, const FrameReport& r) {
    std::unique_lock<std::mutex> lock(mu_);
    // Bounded: the offline loop waits rather than piling frames up in memory.
    space_.wait(lock, [&] { return queue_.size() < 8 || error_; });
    if (error_) return;
    queue_.push_back({f, r});
    ready_.notify_one();
  }
  // Waits for the queue to drain; returns the writer's error, if any.
  std::optional<InputError> stop() {
    {
      std::lock_guard<std::mutex> lock(mu_);
      done_ = true;
    }
    ready_.notify_all();
    if (thread_.joinable()) thread_.join();
    return error_;
  }
  // The writer's error, once a write failed (frames pushed after it are dropped).
  std::optional<InputError> error() {
    std::lock_guard<std::mutex> lock(mu_);
    return error_;
  }
  RawlogWriter& writer() { return writer_; }
  // Drains the queue, then the ground truth and, with loop closure, the corrected pose of every frame
  // ("VOFUSION_POSE_OPTIMISED", in one last sensory frame). Throws InputError(path, ...) when a write failed.
  void finish(const Reconstruction& rec, const Trajectory& ground_truth);

 private:
  static RawlogWriterOptions rawlogOptions() {
    RawlogWriterOptions o;
    o.format = RawlogWriterOptions::Format::ActionsSensoryFrames;  // odometry actions need it
    return o;
  }
  void loop() {
    nameThisThread("vof-rawlog");
    for (;;) {
      std::pair<Frame, FrameReport> item;
      {
        std::unique_lock<std::mutex> lock(mu_);
        ready_.wait(lock, [&] { return !queue_.empty() || done_; });
        if (queue_.empty()) return;
        item = std::move(queue_.front());
        queue_.pop_front();
      }
      space_.notify_one();
      try {
        write(item.first, item.second);
      } catch (const std::exception& e) {
        std::lock_guard<std::mutex> lock(mu_);
        // One line naming the file: an InputError names the one it could not write (the rawlog or an
        // image beside it), anything else (MRPT's serialisation) is the rawlog's.
        const auto* named = dynamic_cast<const InputError*>(&e);
        error_ = named ? InputError(named->file(), named->problem()) : InputError(writer_.path(), oneLineMessage(e));
        queue_.clear();
        space_.notify_all();
        return;
      }
    }
  }
  void write(const Frame& f, const FrameReport& r) {
    if (r.odometry.success)
      writer_.writeAction(makeOdometryAction(r.odometry.motion, f.timestamp, &r.odometry.covariance));
    mrpt::obs::CObservationRobotPose pose;
    pose.sensorLabel = "VOFUSION_POSE";
    pose.timestamp = rawlogTime(f.timestamp);
    pose.pose.mean = r.pose;
    writer_.writeObservation(pose);
    writer_.write(f);
  }

  RawlogWriter writer_;
  std::mutex mu_;
  std::condition_variable ready_, space_;
  std::deque<std::pair<Frame, FrameReport>> queue_;
  bool done_ = false;
  std::optional<InputError> error_;
  std::thread thread_;
};


}  // namespace vofusion
