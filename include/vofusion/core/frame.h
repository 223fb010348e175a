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

// Where a recording (vofusion-grab's RawlogWriter) wrote a frame's images: absolute paths of its colour
// PNG and its range-image file, which holds the depth in range_units metres per unit.
struct RecordedImages {
  std::string colour, depth;
  double range_units = 0.0;
};

// The range-image file a frame's depth was read from (MRPT's gzip .bin, read checked whole), in `units`
// metres per unit, with what tells its content: its size and its gzip trailer (CRC-32 and length of the
// readings). A rawlog writer at the same units copies the file, while it still is that file, instead of
// compressing the depth again.
struct DepthFile {
  std::string path;
  double units = 0.0;
  std::uint64_t size = 0, trailer = 0;
};

struct Frame {
  std::size_t index = 0;      // 0-based position in its source
  double timestamp = 0.0;     // seconds (UNIX time for real data); when the depth image was taken
  double colour_offset = 0.0; // seconds; colour capture time minus `timestamp` (TUM fr1: within +-20 ms)
  cv::Mat rgb;                // CV_8UC3, BGR order (OpenCV convention), registered to depth
  std::string colour_file;    // the image file rgb was decoded from, unchanged (empty if none): writers
                              // may copy its bytes instead of encoding rgb again. Clear it when rgb changes.
  cv::Mat depth;              // CV_32FC1, metres along the optical axis, 0 = no reading
  std::optional<DepthFile> depth_file;  // the file depth was read from, unchanged (none if it came from no file):
                                        // writers may copy it. Reset it when depth changes.
  CameraIntrinsics camera;
  std::optional<mrpt::poses::CPose3D> groundTruth;  // camera-to-world, when the source knows it
  std::optional<Eigen::Vector3d> up;  // unit "up" (against gravity) in the camera frame, from the
                                      // recording's accelerometer when it has one (TUM accelerometer.txt)
  // Set once the frame is recorded: a later writer of the frame links those files rather than
  // encoding, compressing and writing the same images again (RawlogWriter::write). Reset it when rgb
  // or depth change.
  std::optional<RecordedImages> recorded;

  bool valid() const { return !rgb.empty() && !depth.empty(); }
};

}  // namespace vofusion
