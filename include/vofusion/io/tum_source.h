#pragma once
// A TUM RGB-D benchmark folder: rgb.txt, depth.txt, rgb/, depth/ (16-bit PNG, value/5000 = m),
// optional groundtruth.txt. Colour frames are associated with the nearest depth frame.
// Intrinsics: SourceOptions::intrinsics, else an optional intrinsics.txt in the folder (one line
// "fx fy cx cy", '#' comments; written by rgbd-simulate), else the preset from the folder name.
#include <string>
#include <vector>

#include "vofusion/core/trajectory.h"
#include "vofusion/io/frame_source.h"

namespace vofusion {

struct TumEntry {
  double timestamp = 0.0;
  std::string file;  // relative to the folder
};
// Parses rgb.txt/depth.txt ("timestamp filename", '#' comments). Throws InputError(path, "line N: ...").
std::vector<TumEntry> readTumList(const std::string& path);
std::vector<TumEntry> parseTumList(const std::string& text, const std::string& origin);

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
  const std::vector<TumAssociation>& pairs() const { return pairs_; }
  Frame read(std::size_t i) const override;

 private:
  std::string folder_;
  CameraIntrinsics camera_;
  std::vector<TumAssociation> pairs_;
  Trajectory gt_;
};

// Loads a TUM depth PNG (16-bit, scale 5000/m) as CV_32F metres; throws InputError on any problem.
cv::Mat loadTumDepth(const std::string& path, int expect_w, int expect_h);
// A 16-bit single-channel depth PNG of the expected size, in its raw units (CV_16UC1); throws
// InputError(path, ...) when it is missing, undecodable, of another type (message + unit_note) or size.
cv::Mat loadRawDepthPng(const std::string& path, int expect_w, int expect_h, const std::string& unit_note = "");
// True for a PNG cut short (no IEND chunk at the end). Checked before decoding, because libpng
// prints its own line to stderr for such a file.
bool isTruncatedPng(const std::string& path);
// Reads "fx fy cx cy" (first non-comment line); throws InputError(path, ...).
CameraIntrinsics readIntrinsicsFile(const std::string& path);
cv::Mat loadColour(const std::string& path, int expect_w, int expect_h);

}  // namespace vofusion
