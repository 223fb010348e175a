#include "vofusion/io/rawlog.h"
#include "vofusion/io/colour_registration.h"
#include "vofusion/io/external_files.h"
#include "vofusion/io/jpeg_decode.h"
#include "vofusion/io/png_decode.h"
#include "vofusion/io/png_encode.h"
#include "vofusion/io/rawlog_time.h"
#include "record_file.h"

#include <algorithm>
#include <cerrno>
#include <cstdint>
#include <cmath>
#include <limits>
#include <cstdio>
#include <cstring>
#include <deque>
#include <filesystem>
#include <map>
#include <optional>
#include <stdexcept>

#include <mrpt/core/Clock.h>
#include <mrpt/img/CImage.h>
#include <mrpt/io/CFileGZInputStream.h>
#include <mrpt/io/CFileGZOutputStream.h>
#include <mrpt/obs/CActionCollection.h>
#include <mrpt/obs/CObservationRawDAQ.h>
#include <mrpt/obs/CObservationRobotPose.h>
#include <mrpt/obs/CSensoryFrame.h>
#include <mrpt/serialization/CArchive.h>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "vofusion/core/allocation_limit.h"
#include "vofusion/core/errors.h"
#include "vofusion/core/gzip_members.h"
#include "vofusion/core/progress.h"
#include "vofusion/core/text_file.h"

namespace fs = std::filesystem;
using mrpt::obs::CObservation3DRangeScan;

namespace vofusion {

namespace {
constexpr const char* kGroundTruthLabel = "GROUND_TRUTH";
// A frame whose colour image was taken off its depth's time (TUM fr1: up to 20 ms) is followed by an
// observation so labelled, stamped at the colour image's time (an observation holds one time): an empty
// CObservationRawDAQ, which MRPT's CRawlog keeps as it is (a CObservationComment it folds into the
// rawlog's one comment, so RawLogViewer would keep only the last).
constexpr const char* kColourTimeLabel = "COLOUR_TIME";

// What one rawlog entry may allocate while it is deserialised. MRPT sizes (and zero-fills) strings,
// vectors, deques and matrices from the archive's length fields before reading the data, so without
// a bound one corrupt field costs up to 4 GiB per buffer (16 GiB for a point cloud's five vectors, or
// 4 GiB in 512-byte deque blocks for an action count). Per buffer, 64 MiB is twice the largest real
// per-pixel buffer: a 4K (3840x2160) depth sensor's float point vector is 33 MB, its range image
// 17 MB. In all, 256 MiB holds such a frame with its point cloud (150 MB); colour pixels are
// OpenCV's, not counted. A corrupt entry then touches at most 256 MiB before the read fails (plus up
// to 192 MiB that MRPT's point-cloud destructor re-allocates while unwinding, for its buffer pool).
constexpr std::size_t kMaxEntryBuffer = std::size_t(64) << 20;
constexpr std::size_t kMaxEntryTotal = std::size_t(256) << 20;

std::string mebibytes(std::size_t n) { return std::to_string((n + (1u << 20) - 1) >> 20) + " MiB"; }

// The frame's colour image as a PNG at `path` (`shown` names it in errors: its final name): the file
// it came from when that can be reused (even our encoder takes ~6 ms of CPU a frame), else encoded.
void writeColourPng(const Frame& frame, const std::string& path, const std::string& shown) {
  if (frame.colour_file && reuseColourFile(*frame.colour_file, frame.rgb.cols, frame.rgb.rows, path, shown)) return;
  writeExternalFile(path, encodeRgb8Png(frame.rgb), shown, "image");  // in memory first: a full disk is our one line
}

std::string truncatedAt(std::size_t entry) { return "truncated rawlog (ends inside entry " + std::to_string(entry) + ")"; }

// Counts delivered bytes, so a clean end of file (EOF before an object starts) can be told apart
// from a truncated one (EOF inside an object).
class CountingStream : public mrpt::io::CStream {
 public:
  explicit CountingStream(mrpt::io::CStream& in) : in_(in) {}
  size_t Read(void* buf, size_t n) override {
    const size_t got = in_.Read(buf, n);
    count_ += got;
    if (got < n) ended_ = true;
    return got;
  }
  bool ended() const { return ended_; }  // a read came up short: the file has ended
  size_t Write(const void*, size_t) override { throw std::logic_error("read-only stream"); }
  uint64_t Seek(int64_t, TSeekOrigin) override { throw std::logic_error("stream cannot seek"); }
  uint64_t getTotalBytesCount() const override { return in_.getTotalBytesCount(); }
  uint64_t getPosition() const override { return count_; }

 private:
  mrpt::io::CStream& in_;
  uint64_t count_ = 0;
  bool ended_ = false;
};

// "<scale> metres per unit" made exact for the usual decimal units (1e-3, 2e-4 = 1/5000): the float
// stored in the rawlog is not exactly 2e-4, but TUM depth read back must equal the TUM loader's. Only a
// float's own error (~6e-8) away from 1/n: 0.0019 taken as 1/526 quantised depth at 1/526 m under
// rangeUnits 0.0019, which MRPT's readers (RawLogViewer, rawlog-edit) read 0.1 % short.
double exactUnits(float units) {
  const double inv = 1.0 / double(units);
  const double r = std::round(inv);
  return (r >= 1 && std::abs(inv - r) < 1e-6 * r) ? 1.0 / r : double(units);
}

std::string stripRawlogExtension(const std::string& path) {
  const fs::path p(path);
  return p.extension() == ".rawlog" ? (p.parent_path() / p.stem()).string() : path;
}

}  // namespace

// ------------------------------------------------------------------------------------------------
// Reading

// MRPT gives the colour camera's pose in the depth sensor's frame (x forward, y left, z up), its
// rotation included: CPose3D(0, 0, 0, -90 deg, 0, -90 deg) is "both cameras coincide".
static const mrpt::poses::CPose3D kCoincide(0, 0, 0, -M_PI / 2, 0, -M_PI / 2);

Eigen::Isometry3d colourFromDepth(const mrpt::obs::CObservation3DRangeScan& obs) {
  // depth optical -> sensor (kCoincide), sensor -> colour optical (the colour pose, inverted).
  const mrpt::poses::CPose3D T = -obs.relativePoseIntensityWRTDepth + kCoincide;
  Eigen::Isometry3d E;
  E.matrix() = T.getHomogeneousMatrixVal<mrpt::math::CMatrixDouble44>().asEigen();
  return E;
}

bool colourRegisteredToDepth(const mrpt::obs::CObservation3DRangeScan& obs) {
  const mrpt::img::TCamera &d = obs.cameraParams, &c = obs.cameraParamsIntensity;
  if (!(c.fx() > 0)) return true;  // no colour camera given: taken as the depth camera
  const Eigen::Isometry3d T = colourFromDepth(obs);
  const bool same_pose = T.translation().norm() < 1e-4 && Eigen::AngleAxisd(T.linear()).angle() < 1e-5;
  auto close = [](double a, double b) { return std::abs(a - b) <= 1e-6 * std::max(1.0, std::abs(a)); };
  const bool same_camera = close(d.fx(), c.fx()) && close(d.fy(), c.fy()) && close(d.cx(), c.cx()) && close(d.cy(), c.cy());
  // The same camera at another resolution (intrinsics scaled with the image, in both directions) is
  // registered too: a resize maps its pixels. Rows of another aspect (Kinect's 1280x1024 over 640x480)
  // are not: resized, a row went up to 16 depth pixels off; they are re-projected.
  const bool scaled = d.ncols > 0 && c.ncols > 0 && d.nrows > 0 && c.nrows > 0 &&
                      close(c.fx() / c.ncols, d.fx() / d.ncols) && close(c.fy() / c.nrows, d.fy() / d.nrows) &&
                      close((c.cx() + 0.5) / c.ncols, (d.cx() + 0.5) / d.ncols) &&
                      close((c.cy() + 0.5) / c.nrows, (d.cy() + 0.5) / d.nrows);
  return same_pose && (same_camera || scaled);
}

namespace {
// The observation's colour as 8-bit BGR pixels of the frame's own. An external 8-bit RGB PNG (what
// rawlogs hold) is decoded by io/png_decode, as a TUM folder's (libpng and zlib were 6 % of a kinfu
// run's CPU in the reader: bench/results/2026-12-04-rawlog-input-speed.md); an external JPEG by
// io/jpeg_decode, whose corrupt data is damage (CImage, through cv::imread, passes its smeared picture
// on); anything else goes through MRPT's CImage, after the damage check (libpng prints its own line for
// a file cut short or damaged).
// `plain`: whether the pixels are exactly the plain PNG's (its bytes can stand for them).
std::string colourSizeMismatch(cv::Size got, const CameraIntrinsics& colour_cam) {
  return "colour image is " + std::to_string(got.width) + "x" + std::to_string(got.height) + ", its camera parameters say " +
         std::to_string(colour_cam.width) + "x" + std::to_string(colour_cam.height);
}

// A registered colour image has at most this many times the depth image's pixels (1280x960 over
// 320x240), or kMostColourPixels where that is more (1280x720 over a 224x171 time-of-flight camera).
constexpr int kMostColourPixelsPerDepthPixel = 16;
constexpr double kMostColourPixels = double(1 << 22);

// The most pixels a colour image registered to a depth image of size `depth` may have.
double mostRegisteredColourPixels(cv::Size depth) {
  return std::max(kMostColourPixels, double(kMostColourPixelsPerDepthPixel) * depth.area());
}

// Refuses a colour file's stated size unless it is its own camera's, or, registered, within the bound
// above. The decoders refuse such a header before they allocate its pixels: a crafted 3 MB PNG stating
// 32768x32768 was two 3.2 GB buffers a frame, and a failed allocation ended the run naming no file.
void refuseColourSize(const std::string& file, cv::Size stated, const CameraIntrinsics* colour_cam, cv::Size depth) {
  if (stated.empty()) return;
  if (colour_cam && stated != cv::Size(colour_cam->width, colour_cam->height))
    throw InputError(file, colourSizeMismatch(stated, *colour_cam));
  const double most = mostRegisteredColourPixels(depth);
  if (!colour_cam && double(stated.area()) > most)
    throw InputError(file, "colour image is " + std::to_string(stated.width) + "x" + std::to_string(stated.height) +
                               ": more pixels than a colour image registered to a " + std::to_string(depth.width) + "x" +
                               std::to_string(depth.height) + " depth image may have (" + cv::format("%.0f", most) + ")");
}

// `colour_cam`: the colour camera the image must fit (not registered to the depth), else nullptr;
// `depth`: the depth image's size, which a registered image has but for a larger sensor's colour.
cv::Mat colourOf(const CObservation3DRangeScan& obs, const std::string& origin, const CameraIntrinsics* colour_cam,
                 cv::Size depth, bool& plain) {
  const bool external = obs.intensityImage.isExternallyStored();
  const std::string file = external ? obs.intensityImage.getExternalStorageFileAbsolutePath() : origin;
  plain = false;
  if (external) {
    // Decoded only at a size it may have: its camera's, or a registered image's bound.
    const cv::Size expect = colour_cam ? cv::Size(colour_cam->width, colour_cam->height) : cv::Size();
    const double most = colour_cam ? 0.0 : mostRegisteredColourPixels(depth);
    cv::Size stated;
    const cv::Mat decoded = readPlainPng(file, expect, &stated, most);
    refuseColourSize(file, stated, colour_cam, depth);
    if (decoded.type() == CV_8UC3) {
      plain = true;
      return decoded;
    }
    // Only where the plain decoder got nothing: a file that cannot be opened says why.
    if (const std::string why = whyUnreadable(file); !why.empty())
      throw InputError(file, "cannot load intensity image (" + why + ")");
    if (const std::string damage = imageFileDamage(file); !damage.empty())
      throw InputError(file, "cannot load intensity image (" + damage + ")");
    const JpegDecode jpeg = readJpeg(file, expect, most);
    refuseColourSize(file, jpeg.header, colour_cam, depth);
    if (!jpeg.damage.empty()) throw InputError(file, "cannot load intensity image (" + jpeg.damage + ")");
    if (!jpeg.image.empty()) return asBgr8(jpeg.image);
  }
  cv::Mat img;
  try {
    img = obs.intensityImage.asCvMat<cv::Mat>(mrpt::img::DEEP_COPY);  // the frame's own pixels
  } catch (const std::exception&) {
  }
  if (img.empty()) throw InputError(file, "cannot load intensity image (missing or corrupt)");
  return asBgr8(img);
}
}  // namespace

namespace {
// The depth camera's parameters for the range image's own size (cols x rows). They state the size they
// were calibrated at: a range image of another size with the same aspect (a 320x240 stream of a camera
// calibrated at 640x480) takes them scaled; taken as they were, the focal length was twice the image's.
// Unless they were written for the stored image whatever size they state (CameraIntrinsics::writtenFor).
CameraIntrinsics depthCameraOf(const CObservation3DRangeScan& obs, int cols, int rows, const std::string& origin) {
  CameraIntrinsics c = CameraIntrinsics::fromMrpt(obs.cameraParams);
  if (!c.writtenFor(cols, rows)) {
    if (std::abs(c.height * double(cols) / c.width - rows) > 0.5)
      throw InputError(origin, "the depth camera's parameters are for " + std::to_string(c.width) + "x" +
                                   std::to_string(c.height) + " images, the range image is " + std::to_string(cols) +
                                   "x" + std::to_string(rows) + " (another aspect: give --intrinsics)");
    c = c.resizedTo(cols, rows);
  }
  c.width = cols;
  c.height = rows;
  return c;
}
}  // namespace

namespace {
// The observation's external images into memory; a file that cannot be read is named.
void loadImages(const CObservation3DRangeScan& obs, const std::string& origin) {
  try {
    const ScopedAllocationLimit limit(kMaxEntryBuffer, kMaxEntryTotal);  // external files have length fields too
    obs.load();
  } catch (const std::exception& e) {
    if (!obs.rangeImage_isExternallyStored()) throw InputError(origin, "cannot load external range image (missing or corrupt)");
    const std::string file = obs.rangeImage_getExternalStorageFileAbsolutePath("");
    const std::string why = whyUnreadable(file);
    throw InputError(file, "cannot load external range image (" + (why.empty() ? std::string("corrupt") : why) + ")");
  }
}

// The range image in metres as depth along the optical axis, converted as the TUM loader converts
// (16-bit -> float by cv::convertTo), so converted data reads back bit-identical.
cv::Mat depthInMetres(const CObservation3DRangeScan& obs, const CameraIntrinsics& k, const std::string& origin) {
  const int rows = int(obs.rangeImage.rows()), cols = int(obs.rangeImage.cols());
  cv::Mat raw(rows, cols, CV_16U);
  for (int r = 0; r < rows; ++r) {
    uint16_t* out = raw.ptr<uint16_t>(r);
    for (int c = 0; c < cols; ++c) out[c] = obs.rangeImage(r, c);
  }
  if (!(obs.rangeUnits > 0.f) || !std::isfinite(obs.rangeUnits))
    throw InputError(origin, "depth units of " + std::to_string(obs.rangeUnits) + " m (expected a positive number)");
  cv::Mat depth;
  raw.convertTo(depth, CV_32F, exactUnits(obs.rangeUnits));
  if (!obs.range_is_depth) {
    // Ranges along the pixel ray -> depth along the optical axis.
    for (int r = 0; r < rows; ++r) {
      float* out = depth.ptr<float>(r);
      for (int c = 0; c < cols; ++c) {
        const double x = (c - k.cx) / k.fx, y = (r - k.cy) / k.fy;
        out[c] = float(out[c] / std::sqrt(1 + x * x + y * y));
      }
    }
  }
  return depth;
}

// The frame's colour in its depth camera's pixels (grey when the observation has none).
void setColour(const CObservation3DRangeScan& obs, const std::string& origin, Frame& f) {
  const int rows = f.depth.rows, cols = f.depth.cols;
  if (obs.hasIntensityImage) {
    // A colour camera of its own (another pose or other intrinsics): its colour is re-projected into the
    // depth camera. A registered one at another resolution (e.g. 1280x960 over 640x480) is resized.
    // Decided by the observation's own cameras, whatever the depth camera's given intrinsics (a sensor
    // registered in hardware passes its colour camera's, and registered it is).
    const bool registered = colourRegisteredToDepth(obs);
    std::optional<CameraIntrinsics> colour_cam;
    if (!registered) {
      colour_cam = CameraIntrinsics::fromMrpt(obs.cameraParamsIntensity);
      colour_cam->validate(origin + " (colour camera)");
    }
    bool plain = false;
    f.rgb = colourOf(obs, origin, colour_cam ? &*colour_cam : nullptr, cv::Size(cols, rows), plain);
    if (colour_cam) {
      if (colour_cam->width != f.rgb.cols || colour_cam->height != f.rgb.rows)
        throw InputError(origin, colourSizeMismatch(f.rgb.size(), *colour_cam));
      f.rgb = colourInDepthCamera(f.rgb, f.depth, f.camera, *colour_cam, colourFromDepth(obs));
    } else if (f.rgb.cols != cols || f.rgb.rows != rows) {
      cv::resize(f.rgb, f.rgb, cv::Size(cols, rows), 0, 0, cv::INTER_AREA);
    } else if (plain) {
      // The pixels as the file holds them: a rawlog written from the frame copies its bytes (encoding
      // them again with OpenCV's encoder was a quarter of a kinfu run's CPU on a rawlog input).
      f.colour_file = ColourFile{obs.intensityImage.getExternalStorageFileAbsolutePath()};
    }
    obs.intensityImage.unload();
  } else {
    f.rgb = cv::Mat(rows, cols, CV_8UC3, cv::Scalar(128, 128, 128));
  }
}
}  // namespace

Frame frameFromObservation(const CObservation3DRangeScan& obs, const std::string& origin,
                           const std::optional<CameraIntrinsics>& override_camera) {
  loadImages(obs, origin);
  if (!obs.hasRangeImage || obs.rangeImage.rows() == 0)
    throw InputError(origin, "3D observation without a range image");
  const int rows = int(obs.rangeImage.rows()), cols = int(obs.rangeImage.cols());
  Frame f;
  f.timestamp = rawlogSeconds(obs.timestamp);
  // A stamp no rawlog can be written with (a damaged record's): the frame's problem, as a TUM list's
  // line is. It ended rgbd-odometry's whole run at its rawlog output, with a message naming no file.
  if (!rawlogCanHold(f.timestamp))
    throw InputError(origin, "timestamp " + cv::format("%.10g", f.timestamp) + " s is beyond any sensor's clock (a damaged record?)");
  f.camera = override_camera ? override_camera->forImage(cols, rows, "--intrinsics") : depthCameraOf(obs, cols, rows, origin);
  f.camera.width = cols;
  f.camera.height = rows;
  f.camera.validate(override_camera ? "--intrinsics" : origin);
  f.depth = depthInMetres(obs, f.camera, origin);
  setColour(obs, origin, f);
  obs.unload();
  return f;
}

struct RawlogSource::Reader {
  mrpt::io::CFileGZInputStream gz;
  std::unique_ptr<CountingStream> counter;
  std::unique_ptr<mrpt::serialization::CArchive> arch;
  std::deque<mrpt::obs::CObservation::Ptr> pending;  // observations of the current sensory frame
  std::size_t objects = 0;
  uint64_t largest_entry = 0;  // bytes
  std::string path;
  double last_scan_time = std::numeric_limits<double>::quiet_NaN();  // s, of the scan next3D gave last
  std::size_t scans = 0;  // scans next3D gave
  // The camera read: the first scan's label unless set. Scans of other cameras, read as this one's,
  // were frames from cameras facing elsewhere tracked as one path.
  std::optional<std::string> camera;
  std::map<std::string, std::size_t> other_cameras;  // scans left out, by label

  explicit Reader(const std::string& p) : path(p) {
    std::string err;
    if (!gz.open(p, err)) throw InputError(p, "cannot open rawlog: " + err);
    counter = std::make_unique<CountingStream>(gz);
    arch = std::make_unique<mrpt::serialization::CArchiveStreamBase<CountingStream>>(*counter);
  }

  // Next observation of any kind; nullptr at a clean end. Throws InputError when truncated/corrupt.
  mrpt::obs::CObservation::Ptr nextObservation() {
    while (pending.empty()) {
      const uint64_t before = counter->getPosition();
      mrpt::serialization::CSerializable::Ptr obj;
      const ScopedAllocationLimit limit(kMaxEntryBuffer, kMaxEntryTotal);
      try {
        *arch >> obj;
      } catch (const mrpt::serialization::CExceptionEOF&) {
        if (counter->getPosition() == before) return nullptr;
        throw InputError(path, truncatedAt(objects + 1));
      } catch (const std::exception&) {
        // MRPT wraps an end of file met inside an object's fields in its own exceptions. An entry that
        // ran into the end no longer than the largest whole one before it was cut short (a recorder
        // killed mid-write); a longer one read on past a damaged length field. A guess from sizes:
        // a cut entry larger than all before it reads as corrupt, a damaged length that stays within
        // that size as cut short. Either way the frames before it are read.
        const bool cut_short = counter->ended() && objects > 0 && counter->getPosition() - before <= largest_entry;
        if (!limit.refusedRequest() && !limit.totalExceeded() && cut_short) throw InputError(path, truncatedAt(objects + 1));
        // Refused requests surface as bad_alloc or as MRPT's wrapper around it.
        const std::string why =
            limit.refusedRequest() ? " (asks for a buffer of " + mebibytes(limit.refusedRequest()) +
                                         ", more than the " + mebibytes(kMaxEntryBuffer) + " an entry may use)"
            : limit.totalExceeded() ? " (needs more than the " + mebibytes(kMaxEntryTotal) + " an entry may use)"
            : objects == 0          ? " (not an MRPT rawlog?)"
                                    : "";
        throw InputError(path, "corrupt or truncated rawlog at entry " + std::to_string(objects + 1) + why);
      }
      ++objects;
      largest_entry = std::max(largest_entry, counter->getPosition() - before);
      if (!obj) continue;
      if (auto o = std::dynamic_pointer_cast<mrpt::obs::CObservation>(obj)) return o;
      if (auto sf = std::dynamic_pointer_cast<mrpt::obs::CSensoryFrame>(obj))
        for (const auto& o : *sf)
          if (o) pending.push_back(o);
      // CActionCollection and anything else: not needed for frames.
    }
    auto o = pending.front();
    pending.pop_front();
    return o;
  }

  // The next scan with a range image; on the way, ground-truth poses into gt and each scan's colour
  // offset (its COLOUR_TIME entry, after it) into colour_offsets at the scan's place among the scans.
  CObservation3DRangeScan::Ptr next3D(Trajectory* gt, std::vector<double>* colour_offsets = nullptr) {
    while (auto o = nextObservation()) {
      if (auto s = std::dynamic_pointer_cast<CObservation3DRangeScan>(o)) {
        if (!s->hasRangeImage) continue;
        if (!camera) camera = s->sensorLabel;
        if (s->sensorLabel != *camera) {
          ++other_cameras[s->sensorLabel];
          continue;
        }
        last_scan_time = rawlogSeconds(s->timestamp);
        ++scans;
        return s;
      }
      if (o->sensorLabel == kColourTimeLabel && std::dynamic_pointer_cast<mrpt::obs::CObservationRawDAQ>(o)) {
        const double offset = rawlogSeconds(o->timestamp) - last_scan_time;
        if (colour_offsets && scans > 0 && std::isfinite(offset) && std::abs(offset) < 1.0) {
          if (colour_offsets->size() < scans) colour_offsets->resize(scans, 0.0);
          (*colour_offsets)[scans - 1] = offset;
        }
      } else if (gt && o->sensorLabel == kGroundTruthLabel) {
        // A pose that is no pose (NaN, infinite: mocap lost the camera) is unknown, as in 7-Scenes.
        if (auto rp = std::dynamic_pointer_cast<mrpt::obs::CObservationRobotPose>(o);
            rp && rp->pose.mean.asVectorVal().asEigen().allFinite())
          gt->push_back({rawlogSeconds(rp->timestamp), rp->pose.mean});
      }
    }
    return nullptr;
  }
};

RawlogSource::RawlogSource(const std::string& path, const SourceOptions& opts) : path_(path), opts_(opts) {
  std::error_code ec;  // a link to nowhere or to itself: no such file
  if (!fs::exists(path, ec)) throw InputError(path, "no such file");
  if (fs::is_directory(path, ec)) throw InputError(path, "is a folder, expected a .rawlog file");
  images_dir_ = RawlogWriter::imagesDirFor(path);
  if (!fs::is_directory(images_dir_, ec)) {
    // MRPT also accepts "_images" / "_IMAGES", and a folder "Images" beside the rawlog
    // (CRawlog::detectImagesDirectory), which RawLogViewer opens.
    for (const char* alt : {"_images", "_IMAGES"})
      if (fs::is_directory(stripRawlogExtension(path) + alt, ec)) images_dir_ = stripRawlogExtension(path) + alt;
    const std::string beside = (fs::path(path).parent_path() / "Images").string();
    if (!fs::is_directory(images_dir_, ec) && fs::is_directory(beside, ec)) images_dir_ = beside;
  }
  if (opts.intrinsics) CameraIntrinsics::parse(*opts.intrinsics);  // fail early on a bad preset

  // One pass to count the frames and collect embedded ground truth (no image decoding needed).
  Reader scan(path);
  Trajectory embedded_gt;
  try {
    while (scan.next3D(&embedded_gt, &colour_offsets_)) {
      ++count_;
      if (opts.max_frames > 0 && count_ >= opts.max_frames) {
        // The writer puts a frame's GROUND_TRUTH entry after its scan: read on to the next scan for the
        // last frame's pose. Damage past the frames asked for is none of this run's business.
        try {
          scan.next3D(&embedded_gt, &colour_offsets_);
        } catch (const InputError&) {
        }
        break;
      }
    }
  } catch (const InputError& e) {
    // A recording cut off (a crash while recording) or damaged from some entry on: its frames up to
    // there are good. The format has no markers to find the next whole entry after a damaged one.
    if (count_ == 0) throw;
    cut_short_ = e.problem();
  }
  if (count_ == 0)
    throw InputError(path, "contains no CObservation3DRangeScan with a range image (" +
                               std::to_string(scan.objects) + " entries read)");
  camera_ = scan.camera.value_or("");
  if (!scan.other_cameras.empty()) {
    std::string others;
    for (const auto& [label, n] : scan.other_cameras)
      others += (others.empty() ? "" : ", ") + ("'" + label + "': " + std::to_string(n));
    printWarning(path + ": scans of other cameras left out (" + others + "); the frames are those of '" + camera_ +
                 "', the first camera in the file");
  }
  std::sort(embedded_gt.begin(), embedded_gt.end(),
            [](const StampedPose& a, const StampedPose& b) { return a.timestamp < b.timestamp; });
  const std::string gt_file = RawlogWriter::groundTruthPathFor(path);
  // The file beside the rawlog wins when it gives poses.
  gt_ = entryExists(gt_file) ? readGroundTruthFile(gt_file, opts, std::move(embedded_gt)) : std::move(embedded_gt);
  rewind();
}

RawlogSource::~RawlogSource() = default;

void RawlogSource::rewind() {
  reader_ = std::make_unique<Reader>(path_);
  reader_->camera = camera_;
  pos_ = 0;
}

bool RawlogSource::next(Frame& frame) {
  if (pos_ >= count_) {
    if (!cut_short_.empty()) throw RecordingCutShort(path_, cut_short_);
    return false;
  }
  auto obs = reader_->next3D(nullptr);
  if (!obs) return false;
  // External images and range matrices are named relative to the rawlog's "_Images" folder: made
  // absolute here, never through MRPT's process-wide images folder (io/external_files.h).
  resolveExternalFiles(*obs, images_dir_);
  // No frame uses the point cloud: one stored beside the rawlog (rawlog-edit --externalize's _3D.bin)
  // is not loaded. Missing, it cost its frame as a "missing or corrupt" range image; present, it was
  // decoded for nothing (3.7 MB a frame).
  if (obs->points3D_isExternallyStored()) {
    obs->points3D_overrideExternalStoredFlag(false);
    obs->hasPoints3D = false;
  }
  std::optional<CameraIntrinsics> cam;
  if (opts_.intrinsics) cam = CameraIntrinsics::parse(*opts_.intrinsics);
  const std::size_t index = pos_++;
  try {
    const std::optional<DepthFile> range_file = loadExternalRangeImage(*obs);
    frame = frameFromObservation(*obs, path_, cam);
    if (obs->range_is_depth) frame.depth_file = range_file;  // ranges along the rays are not the depth a writer stores
  } catch (const InputError& e) {
    throw DamagedFrame(e);  // this record's images; the next record is read as usual
  } catch (const std::bad_alloc&) {
    // An image no check above bounds (another format, decoded by MRPT's CImage): its frame, not the run.
    throw DamagedFrame(InputError(path_, "frame " + std::to_string(index) + ": its images need more memory than there is"));
  } catch (const cv::Exception& e) {
    throw DamagedFrame(InputError(path_, "frame " + std::to_string(index) + ": its images cannot be decoded (" + e.err + ")"));
  }
  frame.index = index;
  if (index < colour_offsets_.size()) frame.colour_offset = colour_offsets_[index];
  mrpt::poses::CPose3D gt;
  if (interpolatePose(gt_, frame.timestamp, 0.05, gt)) frame.groundTruth = gt;
  return true;
}

// ------------------------------------------------------------------------------------------------
// Writing

namespace {
// observationFromFrame without the pixels: a writer that stores the images externally never needs
// the colour copy, nor the range image when it links a recording's.
CObservation3DRangeScan::Ptr observationWithoutPixels(const Frame& f, double range_units, const std::string& sensor_label) {
  if (!f.valid()) throw std::invalid_argument("observationFromFrame: frame without colour or depth");
  if (!(range_units > 0)) throw std::invalid_argument("observationFromFrame: range_units must be positive");
  auto obs = std::make_shared<CObservation3DRangeScan>();
  obs->sensorLabel = sensor_label;
  obs->timestamp = rawlogTime(f.timestamp);
  obs->hasRangeImage = true;
  obs->range_is_depth = true;
  obs->rangeUnits = float(range_units);
  const double scale = 1.0 / exactUnits(float(range_units));
  obs->maxRange = float(65535.0 / scale);
  obs->hasIntensityImage = true;
  obs->intensityImageChannel = CObservation3DRangeScan::CH_VISIBLE;
  CameraIntrinsics cam = f.camera;
  cam.width = f.depth.cols;
  cam.height = f.depth.rows;
  obs->cameraParams = cam.toMrpt();
  obs->cameraParamsIntensity = obs->cameraParams;  // registered: one camera
  obs->relativePoseIntensityWRTDepth = mrpt::poses::CPose3D(0, 0, 0, -M_PI / 2, 0, -M_PI / 2);  // coincide
  return obs;
}

// The depth (metres) as the observation's range image, in its rangeUnits; returns how many readings
// lie beyond what 16 bits of those units hold. They become "no reading": clipped to the largest value,
// they were surfaces at the wrong distance (--range-units 1e-9 turned a whole recording into a wall at
// 65 um).
std::size_t setRangeImage(CObservation3DRangeScan& obs, const cv::Mat& depth) {
  const double scale = 1.0 / exactUnits(obs.rangeUnits);
  obs.rangeImage_setSize(depth.rows, depth.cols);
  std::size_t beyond = 0;
  for (int r = 0; r < depth.rows; ++r) {
    const float* in = depth.ptr<float>(r);
    std::uint16_t* out = obs.rangeImage.data() + std::size_t(r) * std::size_t(depth.cols);  // row-major rows
    for (int c = 0; c < depth.cols; ++c) {
      const double x = double(in[c]) * scale;
      if (!(x > 0) || std::isinf(x)) {  // no reading (0, negative, NaN or infinite)
        out[c] = 0;
      } else if (x >= 65535.5) {  // rounds beyond 16 bits
        out[c] = 0, ++beyond;
      } else {
        // std::round without its libm call (plain x86-64 has no rounding instruction): x - trunc(x) is
        // exact, so ">= 0.5" rounds halves away from zero as std::round does.
        const std::uint32_t t = std::uint32_t(x);
        out[c] = std::uint16_t(t + (x - double(t) >= 0.5));
      }
    }
  }
  return beyond;
}

// observationFromFrame, adding to `beyond` the readings too far for the range units.
CObservation3DRangeScan::Ptr observationWithPixels(const Frame& f, double range_units, const std::string& sensor_label,
                                                   std::size_t& beyond) {
  auto obs = observationWithoutPixels(f, range_units, sensor_label);
  beyond += setRangeImage(*obs, f.depth);
  obs->intensityImage = mrpt::img::CImage(f.rgb, mrpt::img::DEEP_COPY);
  return obs;
}
}  // namespace

CObservation3DRangeScan::Ptr observationFromFrame(const Frame& f, double range_units, const std::string& sensor_label) {
  std::size_t beyond = 0;
  return observationWithPixels(f, range_units, sensor_label, beyond);
}

mrpt::obs::CActionRobotMovement3D makeOdometryAction(const mrpt::poses::CPose3D& delta, double timestamp,
                                                     const mrpt::math::CMatrixDouble66* cov) {
  mrpt::obs::CActionRobotMovement3D a;
  a.estimationMethod = mrpt::obs::CActionRobotMovement3D::emVisualOdometry;
  a.poseChange.mean = delta;
  if (cov) a.poseChange.cov = *cov;
  else a.poseChange.cov.setZero();
  a.rawOdometryIncrementReading = delta;
  a.timestamp = rawlogTime(timestamp);
  return a;
}

std::string RawlogWriter::imagesDirFor(const std::string& rawlog_path) {
  return stripRawlogExtension(rawlog_path) + "_Images";
}
std::string RawlogWriter::groundTruthPathFor(const std::string& rawlog_path) {
  return stripRawlogExtension(rawlog_path) + ".groundtruth.txt";
}

struct RawlogWriter::Impl {
  std::optional<AtomicPath> rawlog, images;  // unless in place
  std::string rawlog_file, images_dir;       // where the bytes go
  mrpt::io::CFileGZOutputStream gz;
  std::unique_ptr<RecordFile> records;       // in place
  std::unique_ptr<mrpt::serialization::CArchive> arch;
  mrpt::obs::CActionCollection pending_actions;
  std::vector<mrpt::obs::CObservation::Ptr> pending_obs;
  std::optional<Trajectory> gt;
  bool gt_written = false;  // in place: beside the recording since its first frame
  bool images_used = false;

  void openAtomic(const std::string& path) {
    rawlog.emplace(path);
    images.emplace(imagesDirFor(path));
    rawlog_file = rawlog->tmp();
    images_dir = images->tmp();
    std::string err;
    if (!gz.open(rawlog_file, 1, err)) throw InputError(path, "cannot write: " + err);
    arch = std::make_unique<mrpt::serialization::CArchiveStreamBase<mrpt::io::CFileGZOutputStream>>(gz);
  }
  // An empty recording file with no images beside it (an empty folder or none), which no recorder
  // holds, is what a kill before the first frame leaves (or one before the folder was made): it holds
  // nothing and goes, rather than refuse the folder to every later recording. One another recorder
  // is making now holds its file's lock (RecordFile locks it before it appears) and stays.
  void removeEmptyRecording() const {
    RecordFile::removeIfAbandoned(rawlog_file, [&] {
      std::error_code ec;
      if (fs::exists(images_dir, ec) && !(fs::is_directory(images_dir, ec) && fs::is_empty(images_dir, ec))) return false;
      fs::remove(images_dir, ec);
      fs::remove(RawlogWriter::groundTruthPathFor(rawlog_file), ec);  // written with the first frame, before its record
      return true;
    });
  }
  void openInPlace(const std::string& path) {
    rawlog_file = path;
    images_dir = imagesDirFor(path);
    removeEmptyRecording();
    if (fs::exists(rawlog_file) || fs::exists(images_dir))
      throw InputError(path, "a recording is already there; recordings are never overwritten: choose another folder");
    // A ground truth beside no recording is an earlier one's: read as this recording's, it would
    // evaluate this run against another path.
    if (const std::string gt = RawlogWriter::groundTruthPathFor(path); fs::exists(gt))
      throw InputError(gt, "a ground truth without its recording is there (an earlier recording's?): move it away or "
                           "choose another folder");
    records = std::make_unique<RecordFile>(rawlog_file);
    arch = std::make_unique<mrpt::serialization::CArchiveStreamBase<RecordFile>>(*records);
  }
  // Format ActionsSensoryFrames: the pending actions and `first`, then the pending observations, as
  // one (CActionCollection, CSensoryFrame) pair; the pending ones are cleared. The caller ends the record.
  void writePair(const std::vector<mrpt::obs::CObservation::Ptr>& first = {}) {
    mrpt::obs::CSensoryFrame sf;
    for (const auto& o : first) sf.insert(o);
    for (const auto& o : pending_obs) sf.insert(o);
    *arch << pending_actions << sf;
    pending_actions.clear();
    pending_obs.clear();
  }
  // The record just serialised is complete (in place: appended to the file now).
  void endRecord() {
    if (records) records->endRecord();
  }
  void syncIfDue() {
    if (records) records->syncIfDue();
  }
  // The staged rawlog in place, with its images folder when it has one: the earlier folder is removed
  // only once this rawlog is in place (the writer's destructor), and put back if the rawlog cannot be.
  void commitRawlogWithImages(bool with_images) {
    if (with_images) images->commit();
    try {
      rawlog->commit();
    } catch (const InputError&) {
      if (with_images) {
        try {
          images->revert();
        } catch (const InputError& e) {  // the rawlog's own error is the one to report
          printWarning(e.what());
        }
      }
      throw;
    }
  }
};

RawlogWriter::RawlogWriter(const std::string& path, const RawlogWriterOptions& opts) : path_(path), opts_(opts) {
  const fs::path parent = fs::absolute(path).parent_path();
  ensureWritableDirectory(parent.string());
  if (fs::is_directory(path)) throw InputError(path, "output path is a folder, expected a .rawlog file name");
  // The ground truth beside it is the recording's too: commit replaces it (or removes it, writing none).
  if (!opts.in_place && !opts.replace)
    for (const std::string& part : {path, imagesDirFor(path), groundTruthPathFor(path)})
      if (fs::exists(part)) throw InputError(part, "already exists; not replaced (--overwrite replaces it)");
  impl_ = std::make_unique<Impl>();
  if (opts.in_place) impl_->openInPlace(path);
  else impl_->openAtomic(path);
  if (opts.external_images) {
    std::error_code ec;
    fs::create_directories(impl_->images_dir, ec);
    if (ec) throw InputError(imagesDirFor(path), "cannot create: " + ec.message());
  }
}

RawlogWriter::~RawlogWriter() {
  if (!impl_) return;
  if (!impl_->records) {
    impl_->gz.close();  // before AtomicPath removes the temporary
    return;
  }
  if (committed_ || frames_ > 0) return;
  impl_->arch.reset();
  impl_->records.reset();
  std::error_code ec;
  fs::remove(impl_->rawlog_file, ec);
  fs::remove_all(impl_->images_dir, ec);  // this writer made it (openInPlace refuses one already there); no record names its files
  if (impl_->gt_written) fs::remove(groundTruthPathFor(path_), ec);
}

void RawlogWriter::writeAction(const mrpt::obs::CAction& action) {
  if (opts_.format != RawlogWriterOptions::Format::ActionsSensoryFrames)
    throw std::logic_error("RawlogWriter::writeAction needs the ActionsSensoryFrames format");
  impl_->pending_actions.insert(const_cast<mrpt::obs::CAction&>(action));
}

void RawlogWriter::writeObservation(const mrpt::obs::CObservation& obs) {
  auto copy = std::dynamic_pointer_cast<mrpt::obs::CObservation>(obs.duplicateGetSmartPtr());
  if (opts_.format == RawlogWriterOptions::Format::Observations) {
    *impl_->arch << *copy;
    impl_->endRecord();
    impl_->syncIfDue();
  } else {
    impl_->pending_obs.push_back(copy);
    // Observations that follow no frame (a run's optimised poses, one per frame) go out in sensory
    // frames of at most this many: all in one, four hours' poses passed the 256 MiB a reader allows an
    // entry (kMaxEntryTotal).
    constexpr std::size_t kMaxObservationsPerEntry = 4096;
    if (impl_->pending_obs.size() >= kMaxObservationsPerEntry) {
      impl_->writePair();
      impl_->endRecord();
      impl_->syncIfDue();
    }
  }
}

void RawlogWriter::writeGroundTruth(const Trajectory& gt) { impl_->gt = gt; }

namespace {
// The frame's observation and what goes with it: its colour image's capture time (a reader takes
// offsets under 1 s) and its ground-truth pose.
std::vector<mrpt::obs::CObservation::Ptr> withCompanions(const Frame& frame, const CObservation3DRangeScan::Ptr& obs,
                                                         bool ground_truth_observations) {
  std::vector<mrpt::obs::CObservation::Ptr> list{obs};
  if (frame.colour_offset != 0.0 && std::abs(frame.colour_offset) < 1.0) {
    auto colour_time = std::make_shared<mrpt::obs::CObservationRawDAQ>();
    colour_time->sensorLabel = kColourTimeLabel;
    colour_time->timestamp = rawlogTime(frame.timestamp + frame.colour_offset);
    list.push_back(colour_time);
  }
  if (frame.groundTruth && ground_truth_observations) {
    auto gt = std::make_shared<mrpt::obs::CObservationRobotPose>();
    gt->sensorLabel = kGroundTruthLabel;
    gt->timestamp = obs->timestamp;
    gt->pose.mean = *frame.groundTruth;
    gt->pose.cov.setZero();
    list.push_back(gt);
  }
  return list;
}
}  // namespace

std::optional<RecordedFiles> RawlogWriter::writeImagesBeside(const Frame& frame, CObservation3DRangeScan& obs) {
  // Whole whatever the label's length: cut to a fixed buffer, a long label's frames shared one name and
  // each replaced the images of the frames recorded before it.
  char number_and_time[64];
  std::snprintf(number_and_time, sizeof number_and_time, "_%06zu_%.6f", frames_, frame.timestamp);
  const std::string stem = opts_.sensor_label + number_and_time;
  const std::string png = stem + "_INTENSITY.png", bin = stem + "_DEPTH.bin";
  const std::string dir = impl_->images_dir, shown = imagesDirFor(path_) + "/";
  // The files the frame came from (a recording's linked, others copied), else written.
  writeColourPng(frame, dir + "/" + png, shown + png);
  obs.intensityImage.setExternalStorage(png);
  std::optional<DepthFile> depth;
  if (frame.depth_file) depth = reuseRangeImageFile(*frame.depth_file, opts_.range_units, dir + "/" + bin, shown + bin);
  if (depth) {
    useExternalRangeImage(obs, bin);
  } else {
    readings_beyond_range_ += setRangeImage(obs, frame.depth);
    depth = writeRangeImageExternally(obs, bin, dir, shown + bin);
  }
  impl_->images_used = true;
  // Only a recording's files keep their names: a result's folder is renamed by commit().
  if (!opts_.in_place) return std::nullopt;
  depth->path = fs::absolute(dir + "/" + bin).string();
  depth->recorded = true;
  return RecordedFiles{ColourFile{fs::absolute(dir + "/" + png).string(), true}, *depth};
}

std::optional<RecordedFiles> RawlogWriter::write(const Frame& frame) {
  // A recording in place has its ground truth beside it from its first frame on: a run killed before
  // commit() (SIGKILL, a power cut) is finished offline from the recording, and evaluated against it.
  if (impl_->records && frames_ == 0 && impl_->gt && !impl_->gt_written) {
    writeTumTrajectory(groundTruthPathFor(path_), *impl_->gt);
    impl_->gt_written = true;
  }
  auto obs = opts_.external_images
                 ? observationWithoutPixels(frame, opts_.range_units, opts_.sensor_label)
                 : observationWithPixels(frame, opts_.range_units, opts_.sensor_label, readings_beyond_range_);
  std::optional<RecordedFiles> files;
  if (opts_.external_images) files = writeImagesBeside(frame, *obs);
  const std::vector<mrpt::obs::CObservation::Ptr> obs_list = withCompanions(frame, obs, opts_.ground_truth_observations);
  try {
    if (opts_.format == RawlogWriterOptions::Format::Observations) {
      for (const auto& o : obs_list) *impl_->arch << *o;
    } else {
      impl_->writePair(obs_list);
    }
    impl_->endRecord();  // images first, then the record that names them
  } catch (const InputError&) {
    throw;
  } catch (const std::exception& e) {
    throw InputError(path_, "write failed (disk full?)");
  }
  ++frames_;
  // After the count: a frame in the file is a frame recorded (and kept by commit), even when its sync
  // fails (it counted one frame too few, and a first frame's recording was removed).
  impl_->syncIfDue();
  return files;
}

void RawlogWriter::commit() {
  if (readings_beyond_range_ > 0) {
    char reach[64];
    std::snprintf(reach, sizeof reach, "%.3g m", 65535.0 * opts_.range_units);
    printWarning(path_ + ": " + std::to_string(readings_beyond_range_) + " depth readings beyond " + reach +
                 " (65535 range units) written as no reading; a larger --range-units keeps them");
  }
  if (opts_.format == RawlogWriterOptions::Format::ActionsSensoryFrames &&
      (impl_->pending_actions.size() > 0 || !impl_->pending_obs.empty())) {
    impl_->writePair();  // trailing actions/observations still need their pair
    impl_->endRecord();
  }
  if (impl_->records) {
    // No frame, no recording: the destructor removes the empty file and folder, so that they do not
    // block the next run's recording in this folder (a sensor that failed on its first frame).
    if (frames_ == 0) return;
    if (impl_->gt && !impl_->gt_written) writeTumTrajectory(groundTruthPathFor(path_), *impl_->gt);
    impl_->records->syncWithItsFolder();  // the images too: a record naming an empty file is a lost frame
    committed_ = true;
    return;
  }
  const std::uint64_t written = impl_->gz.getPosition();
  const std::string file = impl_->gz.filePathAtUse();
  impl_->gz.close();
  if (!gzipTrailerSays(file, written)) throw InputError(path_, "write failed while closing the rawlog (disk full?)");
  // The ground truth beside the rawlog is its own or none: RawlogSource reads that file before the
  // rawlog's GROUND_TRUTH entries, so an earlier conversion's left there would evaluate this one.
  const std::string gt_path = groundTruthPathFor(path_);
  std::optional<AtomicPath> gt;
  if (impl_->gt) {
    gt.emplace(gt_path);
    writeTumTrajectory(gt->tmp(), *impl_->gt);
  }
  // Every part's bytes on the disk before any replaces an earlier one (a ground truth that could not be
  // synced once the rawlog was in place left the new rawlog beside the earlier run's ground truth).
  if (gt) gt->prepare();
  impl_->rawlog->prepare();
  if (opts_.external_images) impl_->images->prepare();
  impl_->commitRawlogWithImages(opts_.external_images);  // the images folder and the rawlog change together
  if (gt) {
    gt->commit();
  } else {
    std::error_code ec;
    fs::remove(gt_path, ec);
  }
}

}  // namespace vofusion
