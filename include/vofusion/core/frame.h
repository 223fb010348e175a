#pragma once
// The unit that flows through the pipeline: one associated colour + depth pair.
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>

#include <Eigen/Core>
#include <mrpt/poses/CPose3D.h>
#include <opencv2/core.hpp>

#include "vofusion/core/camera.h"

namespace vofusion {

// The files a frame's images were read from, or recorded to: a rawlog writer reuses them instead of
// encoding the images again (RawlogWriter::write). A file of our own recording (`recorded`) is
// hard-linked; another (a TUM folder's PNG, a rawlog input's images) is copied once it is checked to
// hold the image still. Reset one when its image changes.

// A PNG of the frame's colour image (8-bit RGB, rgb's size: checked before a copy).
struct ColourFile {
  std::string path;
  bool recorded = false;
};

// A range-image file (MRPT's gzip .bin) of the frame's depth in `units` metres per unit, with what
// tells its content: its size and its gzip trailer (CRC-32 and length of the readings). It is reused
// only at the same units, and only while it still is that file.
struct DepthFile {
  std::string path;
  double units = 0.0;
  std::uint64_t size = 0, trailer = 0;
  bool recorded = false;
};

struct Frame {
  std::size_t index = 0;      // 0-based position in its source
  double timestamp = 0.0;     // seconds (UNIX time for real data); when the depth image was taken
  double colour_offset = 0.0; // seconds; colour capture time minus `timestamp` (TUM fr1: within +-20 ms)
  cv::Mat rgb;                // CV_8UC3, BGR order (OpenCV convention), registered to depth
  std::optional<ColourFile> colour_file;  // rgb's file, unchanged (none if none). Reset it when rgb changes.
  cv::Mat depth;              // CV_32FC1, metres along the optical axis, 0 = no reading
  std::optional<DepthFile> depth_file;    // depth's file, unchanged (none if none). Reset it when depth changes.
  CameraIntrinsics camera;
  std::optional<mrpt::poses::CPose3D> groundTruth;  // camera-to-world, when the source knows it
  std::optional<Eigen::Vector3d> up;  // unit "up" (against gravity) in the camera frame, from the
                                      // recording's accelerometer when it has one (TUM accelerometer.txt)

  bool valid() const { return !rgb.empty() && !depth.empty(); }
};

}  // namespace vofusion
