#pragma once
// A sequence folder of the Microsoft 7-Scenes dataset (Shotton et al. 2013), e.g. chess/seq-01:
//   frame-000000.color.png (or .jpg)  8-bit colour, 640x480
//   frame-000000.depth.png            16-bit depth in millimetres, 0 and 65535 = no reading
//   frame-000000.pose.txt             4x4 camera-to-world matrix (optical axes), row-major text
// The dataset has no timestamps: frame i is stamped i / fps seconds (30 Hz, Kinect v1).
// Intrinsics: SourceOptions::intrinsics, else the dataset's published depth camera
// (fx = fy = 585, cx = 320, cy = 240). 7-Scenes depth is not registered to colour; the small offset
// is ignored, as most pipelines evaluated on 7-Scenes do.
#include <string>
#include <vector>

#include "vofusion/core/trajectory.h"
#include "vofusion/io/frame_source.h"

namespace vofusion {

class SevenScenesSource : public IndexedFrameSource {
 public:
  static constexpr double kFps = 30.0;  // Hz, stamps of the synthetic timeline
  // The dataset's default intrinsics (depth camera).
  static CameraIntrinsics defaultIntrinsics();
  // True if the folder holds at least one frame-XXXXXX.depth.png with a colour image beside it.
  static bool looksLike(const std::string& folder);

  // Throws InputError(folder or file, problem) when the folder holds no frames or no readable colour image
  // among the first; a malformed pose file costs its frame's evaluation (one line, or the stop with
  // opts.strict), a missing colour image its frame (read() throws).
  SevenScenesSource(const std::string& folder, const SourceOptions& opts);
  std::size_t size() const override { return frames_.size(); }
  std::string name() const override { return folder_; }

  // Poses of every frame with a valid pose file (camera-to-world), stamped like the frames.
  const Trajectory& groundTruth() const { return gt_; }
  Frame read(std::size_t i) const override;

 private:
  struct Entry {
    std::string stem;    // "<folder>/frame-000000"
    std::string colour;  // ".color.png" or ".color.jpg" path
    int number = 0;      // the XXXXXX of the file name
    bool has_depth = false;  // its ".depth.png" is there (listed by either image)
  };
  void listFrames(const SourceOptions& opts);  // frames_ in number order (at most opts.max_frames)
  void readPoses(const SourceOptions& opts);   // gt_ and gt_index_ from the frames' pose files
  std::string folder_;
  CameraIntrinsics camera_;
  std::vector<Entry> frames_;
  Trajectory gt_;
  std::vector<int> gt_index_;  // frames_ index -> gt_ index, -1 when the pose is unknown
};

// Parses a 7-Scenes pose file's text (4x4, row-major). Throws InputError(origin, ...) if it is not
// 16 finite numbers with a rigid rotation block; returns false for the dataset's "unknown pose" marker
// (any non-finite value, e.g. "-inf").
bool parseSevenScenesPose(const std::string& text, const std::string& origin, mrpt::poses::CPose3D& pose);

}  // namespace vofusion
