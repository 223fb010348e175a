#include <fcntl.h>
#include <unistd.h>

#include <cstdio>
#include <filesystem>
#include <fstream>
#include <cmath>
#include <iostream>
#include <thread>
#include <vector>

#include <mrpt/hwdrivers/COpenNI2Generic.h>
#include <mrpt/hwdrivers/registerAllClasses.h>

#include "vofusion/core/errors.h"
#include "vofusion/live/live_source.h"
#include "vofusion/io/rawlog.h"

namespace fs = std::filesystem;

namespace vofusion {

namespace {

// MRPT drivers chat on stdout/stderr while loading and opening (config dumps, backtraces of
// ignored calibration warnings): silenced, since we report what went wrong ourselves in one line.
class QuietStdio {
 public:
  explicit QuietStdio(bool active) : active_(active) {
    if (!active_) return;
    std::cout.flush();
    std::cerr.flush();
    std::fflush(nullptr);
    out_ = ::dup(1);
    err_ = ::dup(2);
    const int null = ::open("/dev/null", O_WRONLY);
    if (null >= 0) {
      ::dup2(null, 1);
      ::dup2(null, 2);
      ::close(null);
    }
  }
  ~QuietStdio() {
    if (!active_) return;
    std::cout.flush();
    std::cerr.flush();
    std::fflush(nullptr);
    if (out_ >= 0) ::dup2(out_, 1), ::close(out_);
    if (err_ >= 0) ::dup2(err_, 2), ::close(err_);
  }

 private:
  bool active_;
  int out_ = -1, err_ = -1;
};

std::string readSmall(const fs::path& p) {
  std::ifstream f(p);
  std::string s;
  f >> s;
  return s;
}

struct UsbId {
  std::string vendor, product;
};

std::vector<UsbId> usbDevices() {
  std::vector<UsbId> ids;
  std::error_code ec;
  for (const auto& e : fs::directory_iterator("/sys/bus/usb/devices", ec)) {
    const auto v = readSmall(e.path() / "idVendor"), p = readSmall(e.path() / "idProduct");
    if (!v.empty()) ids.push_back({v, p});
  }
  return ids;
}

std::vector<std::string> openni2Drivers(std::string* dir_out) {
  std::vector<std::string> libs;
  std::error_code ec;
  for (const auto& lib : fs::directory_iterator("/usr/lib", ec)) {
    const fs::path d = lib.path() / "OpenNI2" / "Drivers";
    if (!fs::is_directory(d, ec)) continue;
    *dir_out = d.string();
    for (const auto& f : fs::directory_iterator(d, ec)) libs.push_back(f.path().filename().string());
  }
  return libs;
}

// ~COpenNI2Sensor() throws when no device was found (it closes a device that does not exist),
// which would terminate the program: a sensor in that state is never destroyed.
void abandonSensor(mrpt::hwdrivers::CGenericSensor::Ptr sensor) {
  static auto* never_destroyed = new std::vector<mrpt::hwdrivers::CGenericSensor::Ptr>();
  never_destroyed->push_back(std::move(sensor));
}

}  // namespace

Frame sensorObservationToFrame(const mrpt::obs::CObservation3DRangeScan& obs, const std::string& origin) {
  if (!obs.hasRangeImage) throw SensorError(origin + ": no depth image (set grab_depth = true)");
  if (!obs.hasIntensityImage) throw SensorError(origin + ": no colour image (set grab_image = true)");
  // Depth registered to colour (OpenNI2 registers in hardware): the colour camera's intrinsics describe
  // the depth image too, whatever the depth camera's own are. Otherwise the colour is re-projected into
  // the depth camera (frameFromObservation), as for a rawlog.
  std::optional<CameraIntrinsics> camera;
  if (obs.cameraParamsIntensity.fx() > 0 && colourRegisteredToDepth(obs)) {
    camera = CameraIntrinsics::fromMrpt(obs.cameraParamsIntensity);
    // Registered at another resolution (1280x960 colour over 640x480 depth): the same camera scaled to
    // the depth image, axis by axis; taken as it was, the depth was tracked at twice its focal length.
    const int cols = static_cast<int>(obs.rangeImage.cols()), rows = static_cast<int>(obs.rangeImage.rows());
    if (!camera->writtenFor(cols, rows)) camera = camera->resizedTo(cols, rows);
    // Now the camera of these images, whatever size the driver left in it (forImage scales only a
    // stated size that is not the images').
    camera->width = cols;
    camera->height = rows;
  }
  try {
    return frameFromObservation(obs, origin, camera);
  } catch (const std::exception& e) {
    throw SensorError(oneLineMessage(e));
  }
}

std::string diagnoseOpenNI2() {
  bool kinect1 = false, primesense = false;
  for (const auto& id : usbDevices()) {
    if (id.vendor == "045e" && (id.product == "02ae" || id.product == "02bf" || id.product == "02c2")) kinect1 = true;
    if (id.vendor == "1d27") primesense = true;
  }
  std::string dir = "/usr/lib/<arch>/OpenNI2/Drivers";
  const auto drivers = openni2Drivers(&dir);
  auto has = [&](const std::string& stem) {
    for (const auto& d : drivers)
      if (d.rfind(stem, 0) == 0) return true;
    return false;
  };
  if (drivers.empty()) return "no OpenNI2 drivers in " + dir + " (install the Debian package libopenni2-0)";
  if (!kinect1 && !primesense)
    return "no RGB-D sensor found on USB (no Kinect 045e:02ae, no PrimeSense/Xtion 1d27:*): is it plugged in and powered?";
  if (kinect1 && !primesense && !has("libFreenectDriver"))
    return "a Kinect v1 is connected but OpenNI2 has no driver for it: install libFreenectDriver.so (libfreenect's "
           "OpenNI2 driver) into " + dir;
  if (primesense && !has("libPS1080"))
    return "a PrimeSense/Xtion sensor is connected but " + dir + " lacks libPS1080.so (reinstall libopenni2-0)";
  return "the sensor is on USB but OpenNI2 cannot open it: check permissions (udev rules, log out and in after "
         "joining group plugdev/video) and that no other program uses it";
}

std::string findSensorSection(const mrpt::config::CConfigFileBase& cfg, const std::string& wanted,
                              const std::string& origin) {
  if (!wanted.empty()) {
    if (cfg.read_string(wanted, "driver", "").empty())
      throw InputError(origin, "section [" + wanted + "] has no 'driver' key (e.g. driver = COpenNI2Sensor)");
    return wanted;
  }
  std::vector<std::string> sections, found;
  cfg.getAllSections(sections);
  for (const auto& s : sections)
    if (!cfg.read_string(s, "driver", "").empty()) found.push_back(s);
  if (found.empty()) throw InputError(origin, "no sensor section (a section with 'driver = COpenNI2Sensor')");
  if (found.size() > 1)
    throw InputError(origin, "several sensor sections ([" + found[0] + "], [" + found[1] + "], ...): choose one with --sensor");
  return found[0];
}

SensorSource::SensorSource(const mrpt::config::CConfigFileBase& cfg, const std::string& section, double timeout_s,
                           const std::string& origin, bool verbose)
    : section_(section), origin_(origin), timeout_s_(timeout_s) {
  static const bool registered = [] {
    mrpt::hwdrivers::registerAllClasses_mrpt_hwdrivers();
    return true;
  }();
  (void)registered;
  driver_ = cfg.read_string(section, "driver", "");
  const std::string where = origin + " [" + section + "]";
  try {
    QuietStdio quiet(!verbose);
    sensor_ = mrpt::hwdrivers::CGenericSensor::createSensorPtr(driver_);
    if (!sensor_) throw InputError(where, "unknown sensor driver '" + driver_ + "' (not a class of mrpt::hwdrivers)");
    sensor_->loadConfig(cfg, section);
    sensor_->initialize();
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    // A driver that failed to initialise may throw again from its destructor (COpenNI2Sensor closes the
    // device it was asked for, there or not: device_number past the devices plugged in), which ends the
    // program: it is never destroyed.
    if (sensor_) abandonSensor(std::move(sensor_));
    const bool openni2 = driver_.find("OpenNI2") != std::string::npos;
    throw InputError(where, driver_ + ": " + oneLineMessage(e) + (openni2 ? " (" + diagnoseOpenNI2() + ")" : ""));
  }
  // COpenNI2Sensor::initialize() returns quietly when no device is found (and its doProcess()
  // then aborts the program on an assertion): check here and say why.
  if (auto* oni = dynamic_cast<mrpt::hwdrivers::COpenNI2Generic*>(sensor_.get())) {
    int device = cfg.read_int(section, "device_number", 0);
    // Chosen by serial number, the device is the one with that serial, whatever device_number says.
    const int serial = cfg.read_int(section, "serial_number", 0);
    if (int id = 0; serial != 0 && oni->getDeviceIDFromSerialNum(unsigned(serial), id)) device = id;
    if (oni->getNumDevices() <= 0) {
      abandonSensor(std::move(sensor_));
      throw InputError(where, "OpenNI2 found no device: " + diagnoseOpenNI2());
    }
    if (!oni->isOpen(unsigned(device))) {
      const int n = oni->getNumDevices();
      abandonSensor(std::move(sensor_));
      throw InputError(where, "cannot open OpenNI2 device " + std::to_string(device) + " of " + std::to_string(n) +
                                  ": " + diagnoseOpenNI2());
    }
  }
  if (sensor_->getState() == mrpt::hwdrivers::CGenericSensor::ssError) {
    abandonSensor(std::move(sensor_));  // as above: its destructor may throw
    throw InputError(where, driver_ + " reported an error while initialising");
  }
}

SensorSource::~SensorSource() = default;

bool SensorSource::grab(Frame& frame, mrpt::obs::CObservation3DRangeScan::Ptr& raw, const std::atomic<bool>& stop) {
  const auto start = std::chrono::steady_clock::now();
  while (!stop) {
    while (!pending_.empty()) {
      auto obj = pending_.begin()->second;
      pending_.erase(pending_.begin());
      auto obs = std::dynamic_pointer_cast<mrpt::obs::CObservation3DRangeScan>(obj);
      if (!obs) continue;  // IMU and other side observations
      frame = sensorObservationToFrame(*obs, name());
      raw = obs;
      return true;
    }
    // Timed on every pass, not only when the driver gives nothing: a driver giving only other
    // observations (an IMU's section, a camera without depth) is no RGB-D frame either.
    const double waited = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    if (waited > timeout_s_) {
      char why[96];
      std::snprintf(why, sizeof why, ": no frame for %g s (sensor unplugged?)", timeout_s_);
      throw SensorError(name() + why);
    }
    try {
      sensor_->doProcess();
    } catch (const std::exception& e) {
      throw SensorError(name() + ": " + oneLineMessage(e) + " (unplugged?)");
    }
    if (sensor_->getState() == mrpt::hwdrivers::CGenericSensor::ssError)
      throw SensorError(name() + ": the sensor reported an error (unplugged?)");
    sensor_->getObservations(pending_);
    if (pending_.empty()) std::this_thread::sleep_for(std::chrono::milliseconds(2));
  }
  return false;
}

}  // namespace vofusion
