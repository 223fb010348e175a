#pragma once
// A TUM RGB-D benchmark folder: rgb.txt, depth.txt, rgb/, depth/ (16-bit PNG, value/scale = m,
// scale 5000 as TUM's), optional groundtruth.txt. Colour frames are associated with the nearest depth
// frame. The same layout from other sensors (RealSense, Azure Kinect, Open3D's recorder) stores
// millimetres: SourceOptions::depth_scale or a camera file says so.
// The camera, first found wins:
//   SourceOptions::intrinsics (--intrinsics); a camera file in the folder is then read for its depth
//     scale only (not at all with SourceOptions::depth_scale), and one that cannot be read is said and
//     left (an error with SourceOptions::strict);
//   intrinsics.txt in the folder: a line "fx fy cx cy [k1 k2 p1 p2 k3]", optional lines
//     "size W H" and "depth_scale S", '#' comments (rgbd-simulate writes one);
//   camera.yaml in the folder (OpenCV FileStorage, as OpenCV's calibration writes it, or ROS's camera_info
//     YAML): camera_matrix, optional distortion_coefficients (k1 k2 p1 p2 k3), image_width, image_height,
//     depth_scale;
//   a guess, announced on stderr: TUM's preset for a folder named freiburg1/2/3, else fx = fy = 525,
//   c = (319.5, 239.5), both only for 640x480 images (anything else is an error).
// Intrinsics that do not fit the images (another size, principal point outside) are an error, and a
// depth scale under which the first frame's median reading is beyond 5 m or within 0.4 m is announced.
// accelerometer.txt ("timestamp ax ay az", the Kinect's accelerometer), when present, gives each frame
// its "up" (Frame::up): the mean reading within 0.1 s, its x and y axes turned into the optical frame's.
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "vofusion/core/trajectory.h"
#include "vofusion/io/frame_source.h"

namespace vofusion {

struct TumEntry {
  double timestamp = 0.0;
  std::string file;  // relative to the folder
};
// A list's lines that could not be taken: "line N: why" each, of `lines` data lines.
struct TumListDamage {
  std::size_t lines = 0;
  std::vector<std::string> problems;
};
// Parses rgb.txt/depth.txt ("timestamp filename", '#' comments). Throws InputError(path, "line N: ...")
// at the first damaged line (no stamp or name, an extra field, a stamp out of order or not in seconds);
// given `damage`, such a line is left out and described there instead. Out of order: off the longest run
// of rising stamps (one stamp damaged forward costs its own line, not every line after it).
std::vector<TumEntry> readTumList(const std::string& path);
std::vector<TumEntry> parseTumList(const std::string& text, const std::string& origin, TumListDamage* damage = nullptr);

struct TumAssociation {
  TumEntry rgb, depth;
};
// Colour and depth frames paired within max_diff, in time order.
// one_to_one = true is the benchmark's associate.py (greedy by |dt|, each frame used once);
// false (the default for sources) gives every depth frame its nearest colour frame, so every depth
// image is used once and a frame is stamped at its depth capture (fr1_xyz first300: 300 pairs; the
// one-to-one rule keeps 294).
std::vector<TumAssociation> associate(const std::vector<TumEntry>& rgb, const std::vector<TumEntry>& depth,
                                      double max_diff, bool one_to_one = true);

class TumFolderSource : public IndexedFrameSource {
 public:
  TumFolderSource(const std::string& folder, const SourceOptions& opts);
  std::size_t size() const override { return pairs_.size(); }
  std::string name() const override { return folder_; }

  const Trajectory& groundTruth() const { return gt_; }
  const Trajectory* recordedGroundTruth() const override { return gt_.empty() ? nullptr : &gt_; }
  const std::vector<TumAssociation>& pairs() const { return pairs_; }
  double depthScale() const { return depth_scale_; }
  const CameraIntrinsics& camera() const { return camera_; }
  Frame read(std::size_t i) const override;

 private:
  std::string folder_;
  CameraIntrinsics camera_;
  double depth_scale_ = 5000.0;
  std::vector<std::pair<double, Eigen::Vector3d>> accel_;  // accelerometer.txt: time, up in the camera frame
  std::vector<TumAssociation> pairs_;
  Trajectory gt_;
};

// Loads a TUM depth PNG (16-bit, `scale` units per metre) as CV_32F metres; throws InputError on any problem.
cv::Mat loadTumDepth(const std::string& path, int expect_w, int expect_h, double scale = 5000.0);
// A 16-bit single-channel depth PNG of the expected size, in its raw units (CV_16UC1); throws
// InputError(path, ...) when it is missing, undecodable, of another type (message + unit_note) or size.
cv::Mat loadRawDepthPng(const std::string& path, int expect_w, int expect_h, const std::string& unit_note = "");
// The colour images' size: the one most of `paths`' PNG headers state (nothing decoded, so one odd or
// crafted image neither sets the recording's size nor is decoded: a crafted 30000x30000 first image
// was a 1.8 GB decode); with no PNG among them (JPEG), the size of the first that can be read (missing,
// cut short or undecodable ones are passed over: each is its own frame's problem); nullopt when none
// can. Sources look at this many of their first frames' images for it.
constexpr std::size_t kFramesForImageSize = 30;
std::optional<cv::Size> recordingImageSize(const std::vector<std::string>& paths);
// A camera description read from a file: intrinsics, and what else the file says.
struct CameraFile {
  CameraIntrinsics camera;
  bool has_size = false;    // camera.width/height come from the file
  double depth_scale = 0;   // units per metre, 0 = not given
};
// intrinsics.txt: "fx fy cx cy [k1 k2 p1 p2 k3]" (first non-comment line), then optional "size W H",
// "depth_scale S"; throws InputError(path, ...).
CameraFile readIntrinsicsFile(const std::string& path);
// camera.yaml (OpenCV FileStorage, or ROS camera_info YAML): camera_matrix, [distortion_coefficients,
// image_width, image_height, depth_scale]; throws InputError(path, ...).
CameraFile readCameraYaml(const std::string& path);
cv::Mat loadColour(const std::string& path, int expect_w, int expect_h);

}  // namespace vofusion
