#include "vofusion/io/seven_scenes_source.h"

#include <Eigen/Dense>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <map>
#include <regex>
#include <sstream>

#include <mrpt/math/CMatrixFixed.h>
#include <opencv2/imgcodecs.hpp>

#include "vofusion/core/errors.h"
#include "vofusion/core/progress.h"
#include "vofusion/core/text_file.h"
#include "vofusion/io/tum_source.h"

namespace fs = std::filesystem;

namespace vofusion {

namespace {

const std::regex kDepthName(R"(frame-(\d{1,9})\.depth\.png)");  // 7-Scenes: 6 digits; more than an int holds is no frame
// A frame's images: a frame is listed by either, so one whose depth image is missing is a damaged frame,
// skipped and counted (listed by its depth image alone, it vanished unsaid). A pose alone is no frame (a
// sequence thinned by deleting images keeps its small pose files).
const std::regex kFrameFile(R"(frame-(\d{1,9})\.(depth\.png|color\.png|color\.jpg))");

// Colour image beside a frame stem: PNG first, then JPEG (both occur in 7-Scenes mirrors).
std::string colourFor(const std::string& stem) {
  std::error_code ec;  // one that cannot be stat'ed (a symlink loop) is that frame's damage, found when it is read
  for (const char* ext : {".color.png", ".color.jpg"})
    if (fs::exists(stem + ext, ec)) return stem + ext;
  return {};
}

cv::Mat loadMillimetreDepth(const std::string& path, int w, int h) {
  cv::Mat raw = loadRawDepthPng(path, w, h, " (millimetres)");
  raw.setTo(0, raw == 65535);  // the dataset's "no reading" marker
  cv::Mat depth;
  raw.convertTo(depth, CV_32F, 1e-3);
  return depth;
}

}  // namespace

CameraIntrinsics SevenScenesSource::defaultIntrinsics() {
  CameraIntrinsics c;
  c.fx = c.fy = 585.0;
  c.cx = 320.0;
  c.cy = 240.0;
  return c;
}

bool SevenScenesSource::looksLike(const std::string& folder) {
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(folder, ec)) {
    const std::string n = e.path().filename().string();
    if (std::regex_match(n, kDepthName) && !colourFor((e.path().parent_path() / n.substr(0, n.find('.'))).string()).empty())
      return true;
  }
  return false;
}

bool parseSevenScenesPose(const std::string& text, const std::string& origin, mrpt::poses::CPose3D& pose) {
  std::istringstream in(text);
  std::vector<double> v;
  std::string tok;
  while (in >> tok) {
    if (v.size() == 16) throw InputError(origin, "more than 16 numbers (expected a 4x4 matrix)");
    char* end = nullptr;
    const double d = std::strtod(tok.c_str(), &end);
    if (end == tok.c_str() || *end) throw InputError(origin, "'" + tok + "' is not a number (expected a 4x4 matrix)");
    v.push_back(d);
  }
  if (v.size() != 16) throw InputError(origin, "holds " + std::to_string(v.size()) + " numbers, expected 16 (4x4 matrix)");
  if (!std::all_of(v.begin(), v.end(), [](double d) { return std::isfinite(d); })) return false;
  Eigen::Matrix4d m;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) m(r, c) = v[std::size_t(4 * r + c)];
  const Eigen::Matrix3d R = m.topLeftCorner<3, 3>();
  if ((R.transpose() * R - Eigen::Matrix3d::Identity()).norm() > 1e-2 || std::abs(R.determinant() - 1.0) > 1e-2 ||
      (m.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).norm() > 1e-6)
    throw InputError(origin, "not a rigid camera-to-world transform");
  // Re-orthonormalise the rotation (the files carry 6-7 significant digits).
  Eigen::JacobiSVD<Eigen::Matrix3d> svd(R, Eigen::ComputeFullU | Eigen::ComputeFullV);
  Eigen::Matrix4d clean = m;
  clean.topLeftCorner<3, 3>() = svd.matrixU() * svd.matrixV().transpose();
  pose = mrpt::poses::CPose3D(mrpt::math::CMatrixDouble44(clean));
  return true;
}

SevenScenesSource::SevenScenesSource(const std::string& folder, const SourceOptions& opts) : folder_(folder) {
  std::error_code ec;
  if (!fs::is_directory(folder, ec)) throw InputError(folder, "no such folder");
  listFrames(opts);
  // The first frames' colour images give the size (recordingImageSize; a damaged one is its own frame's problem).
  std::vector<std::string> colours;
  for (std::size_t i = 0; i < std::min(frames_.size(), kFramesForImageSize); ++i) colours.push_back(frames_[i].colour);
  const auto size = recordingImageSize(colours);
  if (!size)
    throw InputError(colours.front().empty() ? frames_.front().stem + ".color.png" : colours.front(),
                     "colour image cannot be read, nor can any of the first " + std::to_string(colours.size()) + " frames'");
  // The published intrinsics are for 640x480; resized copies of the dataset get them scaled.
  camera_ = opts.intrinsics ? CameraIntrinsics::parse(*opts.intrinsics).forImage(size->width, size->height, "--intrinsics")
                            : defaultIntrinsics().scaled(size->width / 640.0);
  camera_.width = size->width;
  camera_.height = size->height;
  camera_.validate(opts.intrinsics ? "--intrinsics" : folder);
  readPoses(opts);
}

void SevenScenesSource::listFrames(const SourceOptions& opts) {
  std::map<std::string, Entry> by_stem;
  try {
    for (const auto& e : fs::directory_iterator(folder_)) {
      const std::string n = e.path().filename().string();
      std::smatch m;
      if (!std::regex_match(n, m, kFrameFile)) continue;
      const std::string stem = (fs::path(folder_) / n.substr(0, n.find('.'))).string();
      Entry& en = by_stem[stem];
      en.stem = stem;
      en.number = std::stoi(m[1].str());
      en.has_depth = en.has_depth || m[2].str() == "depth.png";
    }
  } catch (const fs::filesystem_error& e) {  // a folder that can be stat'ed but not listed
    throw InputError(folder_, "folder cannot be read (" + e.code().message() + ")");
  }
  const bool any_depth = std::any_of(by_stem.begin(), by_stem.end(), [](const auto& kv) { return kv.second.has_depth; });
  if (any_depth) {
    for (auto& [stem, en] : by_stem) {
      en.colour = colourFor(en.stem);  // empty: missing, that frame's problem when it is read
      frames_.push_back(std::move(en));
    }
  }
  if (frames_.empty()) throw InputError(folder_, "folder holds no 7-Scenes frames (frame-XXXXXX.depth.png)");
  std::sort(frames_.begin(), frames_.end(), [](const Entry& a, const Entry& b) { return a.number < b.number; });
  // frame-3 beside frame-000003: one frame twice, at one time (the trajectory held it twice).
  const auto twin = std::adjacent_find(frames_.begin(), frames_.end(), [](const Entry& a, const Entry& b) { return a.number == b.number; });
  if (twin != frames_.end())
    throw InputError(folder_, "frames " + fs::path(twin->stem).filename().string() + " and " +
                                  fs::path(std::next(twin)->stem).filename().string() + " have one number: which is frame " +
                                  std::to_string(twin->number) + "?");
  if (opts.max_frames > 0 && frames_.size() > opts.max_frames) frames_.resize(opts.max_frames);
}

void SevenScenesSource::readPoses(const SourceOptions& opts) {
  gt_index_.assign(frames_.size(), -1);
  std::size_t damaged_poses = 0;  // a damaged pose costs that frame's evaluation, not the run
  constexpr std::size_t kPoseLines = 3;
  for (std::size_t i = 0; i < frames_.size(); ++i) {
    const std::string pose_file = frames_[i].stem + ".pose.txt";
    std::ifstream f(pose_file);
    if (!f) continue;  // no pose: the frame is simply not evaluated
    mrpt::poses::CPose3D p;
    try {
      // A 4x4 matrix is under 1 kB: a link to /dev/zero grew without bound.
      const std::string text = readCapped(f, pose_file, std::size_t(64) << 10, "64 KiB", "a 7-Scenes pose file");
      if (!parseSevenScenesPose(text, pose_file, p)) continue;
    } catch (const InputError& e) {
      if (opts.strict) throw;
      if (++damaged_poses <= kPoseLines) printWarning(std::string(e.what()) + " (frame not evaluated)");
      continue;
    }
    gt_index_[i] = int(gt_.size());
    gt_.push_back({frames_[i].number / kFps, p});
  }
  if (damaged_poses > kPoseLines)
    printWarning(folder_ + ": " + std::to_string(damaged_poses) + " pose files in all are damaged (those frames are not evaluated)");
}

Frame SevenScenesSource::read(std::size_t i) const {
  const Entry& e = frames_.at(i);
  if (!e.has_depth) throw InputError(e.stem + ".depth.png", "depth image is missing");
  if (e.colour.empty()) throw InputError(e.stem + ".color.png", "colour image is missing");
  Frame f;
  f.index = i;
  f.timestamp = e.number / kFps;
  f.camera = camera_;
  f.rgb = loadColour(e.colour, camera_.width, camera_.height);
  f.colour_file = ColourFile{e.colour};
  f.depth = loadMillimetreDepth(e.stem + ".depth.png", camera_.width, camera_.height);
  if (gt_index_[i] >= 0) f.groundTruth = gt_[std::size_t(gt_index_[i])].pose;
  return f;
}

}  // namespace vofusion
