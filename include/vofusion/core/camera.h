#pragma once
// Pinhole intrinsics of the (registered) depth + colour camera.
#include <array>
#include <cstdint>
#include <string>

#include <mrpt/img/TCamera.h>

namespace vofusion {

struct CameraIntrinsics {
  int width = 640, height = 480;     // pixels
  double fx = 525.0, fy = 525.0;     // pixels
  double cx = 319.5, cy = 239.5;     // pixels
  std::array<double, 5> dist{};      // k1 k2 p1 p2 k3 (informative: TUM depth is already registered)

  // "fr1", "fr2", "fr3", "ros" (fx=fy=525) or "fx,fy,cx,cy". Throws InputError(origin, ...) if unknown.
  // A preset states the size it was calibrated at (640x480); four numbers state none (width = height
  // = 0): they are the recording's own. forImage() then fits either to the recording.
  static CameraIntrinsics parse(const std::string& spec, const std::string& origin = "--intrinsics");
  // These intrinsics for the recording's cols x rows images, validated against that size: a stated size
  // other than the recording's is scaled to it when the shape is the same (a 320x240 copy of a TUM
  // recording keeps its camera, halved), refused when it is not; no stated size is the recording's.
  // Throws InputError(origin, ...).
  CameraIntrinsics forImage(int cols, int rows, const std::string& origin) const;
  // Whether the size these state (none counts as any) has the shape of cols x rows: forImage fits them.
  bool fitsShapeOf(int cols, int rows) const {
    return width <= 0 || height <= 0 || std::int64_t(cols) * height == std::int64_t(rows) * width;
  }
  // The TUM preset matching the folder's own name containing "freiburg1/2/3", else the ROS default.
  static CameraIntrinsics forTumFolder(const std::string& folder);
  // Whether the folder's own name (not a parent's: /data/freiburg1_runs/my_take is no TUM recording)
  // names a TUM camera (freiburg1, 2 or 3), as rgbd_dataset_freiburg3_long_office does. "." and a trailing '/' name the
  // folder they stand for.
  static bool namesAFreiburgCamera(const std::string& folder);

  // Scaled to another resolution (pyramids, reduced-resolution detectors).
  CameraIntrinsics scaled(double s) const;
  // For an image of cols x rows, each axis scaled from the size these state (pixel centres kept).
  CameraIntrinsics resizedTo(int cols, int rows) const;
  // Whether these intrinsics were written for an image of cols x rows, whatever size they state: their
  // principal point lies nearer that image's centre than their stated size's (a writer that filled in
  // only the intrinsics left MRPT's default 640x480), or they state that size.
  bool writtenFor(int cols, int rows) const;
  // Sanity check (focal lengths from 1 pixel to kMaxFocalInImages times the image's longer side,
  // principal point inside the image, fx/fy within 1.5); throws InputError.
  void validate(const std::string& origin) const;
  static constexpr double kMaxFocalInImages = 100.0;  // a Kinect's is 0.8; a 0.6 degree field of view

  mrpt::img::TCamera toMrpt() const;
  static CameraIntrinsics fromMrpt(const mrpt::img::TCamera& c);
};

}  // namespace vofusion
