#pragma once
// Sources that deliver frames in real time: a sensor through MRPT's hwdrivers, or any recorded
// FrameSource replayed at its recorded rate. Both feed the very same live loop (live_loop.h).
#include <atomic>
#include <chrono>
#include <stdexcept>
#include <memory>
#include <string>

#include <mrpt/config/CConfigFileBase.h>
#include <mrpt/hwdrivers/CGenericSensor.h>
#include <mrpt/obs/CObservation3DRangeScan.h>

#include "vofusion/core/frame.h"
#include "vofusion/io/frame_source.h"

namespace vofusion {

// The sensor failed while running (unplugged, USB error, silent for too long). One line.
class SensorError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

class LiveSource {
 public:
  virtual ~LiveSource() = default;
  // Blocks until the next frame is due; false at the end of the stream or once `stop` is set.
  // `raw` receives the sensor's own observation when there is one (recorded as delivered),
  // else null. Throws SensorError when the device fails mid-run.
  virtual bool grab(Frame& frame, mrpt::obs::CObservation3DRangeScan::Ptr& raw, const std::atomic<bool>& stop) = 0;
  virtual std::string name() const = 0;
  // Frames this source will deliver if known (a replay), else 0.
  virtual std::size_t size() const { return 0; }
};

// Plays a FrameSource (TUM folder, rawlog, ...) at the pace of its frame timestamps, times
// `speed` (2 = twice as fast; 0 = as fast as frames can be read). A replay that cannot read
// frames fast enough runs late rather than skipping: it plays every frame.
class ReplaySource : public LiveSource {
 public:
  ReplaySource(std::unique_ptr<FrameSource> source, double speed);
  bool grab(Frame& frame, mrpt::obs::CObservation3DRangeScan::Ptr& raw, const std::atomic<bool>& stop) override;
  std::string name() const override { return "replay of " + source_->name(); }
  std::size_t size() const override { return source_->size(); }

 private:
  std::unique_ptr<FrameSource> source_;
  double speed_;
  bool started_ = false;
  double first_stamp_ = 0.0, last_stamp_ = 0.0;
  double cut_ = 0.0;  // s of recorded time not played: the part of clock jumps beyond kLongestGap
  std::chrono::steady_clock::time_point wall_start_;
};

// An RGB-D sensor created by class name from an INI section exactly as rawlog-grabber does:
// `driver = COpenNI2Sensor` (or any mrpt::hwdrivers class producing CObservation3DRangeScan)
// plus that class's own keys, then loadConfig() + initialize(). The constructor throws
// InputError(origin, one line) when the driver is unknown or no device can be opened, with a
// diagnosis for OpenNI2 (nothing on USB / no OpenNI2 driver for a Kinect / USB permissions).
class SensorSource : public LiveSource {
 public:
  SensorSource(const mrpt::config::CConfigFileBase& cfg, const std::string& section, double timeout_s,
               const std::string& origin, bool verbose = false);
  ~SensorSource() override;
  bool grab(Frame& frame, mrpt::obs::CObservation3DRangeScan::Ptr& raw, const std::atomic<bool>& stop) override;
  std::string name() const override { return driver_ + " [" + section_ + "]"; }

 private:
  mrpt::hwdrivers::CGenericSensor::Ptr sensor_;
  std::string section_, driver_, origin_;
  double timeout_s_;
  mrpt::hwdrivers::CGenericSensor::TListObservations pending_;
};

// The section of cfg that names a sensor (has a `driver` key): `wanted` if given, else the only one.
// Throws InputError(origin, ...) when there is none, several, or `wanted` has no driver.
std::string findSensorSection(const mrpt::config::CConfigFileBase& cfg, const std::string& wanted,
                              const std::string& origin);

// A sensor's observation as a Frame (via the io stage's frameFromObservation), with the colour
// camera's intrinsics since the depth is registered to it. Throws SensorError when the sensor
// delivers no colour, no depth, or unregistered depth.
Frame sensorObservationToFrame(const mrpt::obs::CObservation3DRangeScan& obs, const std::string& origin);

// Why OpenNI2 sees no device, from the USB bus and the OpenNI2 driver folder (one line).
std::string diagnoseOpenNI2();

}  // namespace vofusion
