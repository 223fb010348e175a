#include "vofusion/io/tum_source.h"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <sstream>

#include <opencv2/imgcodecs.hpp>

#include "vofusion/core/errors.h"
#include "vofusion/core/text_file.h"

namespace fs = std::filesystem;

namespace vofusion {

// A PNG that does not end with its IEND chunk is truncated. Caught before OpenCV sees the file,
// because libpng prints its own "libpng error" line to stderr before OpenCV gives up.
bool isTruncatedPng(const std::string& path) {
  std::ifstream f(path, std::ios::binary);
  char sig[8] = {};
  if (!f.read(sig, 8) || std::string(sig, 8) != "\x89PNG\r\n\x1a\n") return false;  // not a PNG: OpenCV decides
  f.seekg(0, std::ios::end);
  const auto size = static_cast<long long>(f.tellg());
  if (size < 8 + 12) return true;
  char tail[8] = {};
  f.seekg(size - 8);
  return !f.read(tail, 8) || std::string(tail, 4) != "IEND";
}

std::vector<TumEntry> parseTumList(const std::string& text, const std::string& origin) {
  std::vector<TumEntry> out;
  for (const auto& [n, line] : dataLines(text)) {
    std::istringstream ls(line);
    TumEntry e;
    if (!(ls >> e.timestamp) || !std::isfinite(e.timestamp) || !(ls >> e.file))
      throw InputError(origin, "line " + std::to_string(n) + ": expected 'timestamp filename'");
    std::string extra;
    if (ls >> extra) throw InputError(origin, "line " + std::to_string(n) + ": unexpected extra field '" + extra + "'");
    if (!out.empty() && e.timestamp <= out.back().timestamp)
      throw InputError(origin, "line " + std::to_string(n) + ": timestamp " + std::to_string(e.timestamp) +
                                   " is out of order or duplicated");
    out.push_back(std::move(e));
  }
  return out;
}

std::vector<TumEntry> readTumList(const std::string& path) { return parseTumList(readTextFile(path), path); }

std::vector<TumAssociation> associate(const std::vector<TumEntry>& rgb, const std::vector<TumEntry>& depth,
                                      double max_diff, bool one_to_one) {
  // Candidate pairs within max_diff, best first; each stamp used once (as associate.py does).
  struct Cand { double dt; std::size_t i, j; };
  std::vector<Cand> cands;
  for (std::size_t i = 0; i < rgb.size(); ++i) {
    auto lo = std::lower_bound(depth.begin(), depth.end(), rgb[i].timestamp - max_diff,
                               [](const TumEntry& e, double t) { return e.timestamp < t; });
    for (auto it = lo; it != depth.end() && it->timestamp <= rgb[i].timestamp + max_diff; ++it)
      cands.push_back({std::abs(it->timestamp - rgb[i].timestamp), i, std::size_t(it - depth.begin())});
  }
  std::sort(cands.begin(), cands.end(), [](const Cand& a, const Cand& b) { return a.dt < b.dt; });
  if (!one_to_one) {
    // Best first, so the first candidate seen for a depth frame is its nearest colour frame.
    std::vector<long> nearest(depth.size(), -1);
    for (const Cand& c : cands)
      if (nearest[c.j] < 0) nearest[c.j] = long(c.i);
    std::vector<TumAssociation> out;
    for (std::size_t j = 0; j < depth.size(); ++j)
      if (nearest[j] >= 0) out.push_back({rgb[std::size_t(nearest[j])], depth[j]});
    return out;
  }
  std::vector<char> used_rgb(rgb.size(), 0), used_depth(depth.size(), 0);
  std::vector<std::pair<std::size_t, std::size_t>> pairs;
  for (const Cand& c : cands) {
    if (used_rgb[c.i] || used_depth[c.j]) continue;
    used_rgb[c.i] = used_depth[c.j] = 1;
    pairs.emplace_back(c.i, c.j);
  }
  std::sort(pairs.begin(), pairs.end());
  std::vector<TumAssociation> out;
  out.reserve(pairs.size());
  for (auto [i, j] : pairs) out.push_back({rgb[i], depth[j]});
  return out;
}

cv::Mat loadRawDepthPng(const std::string& path, int expect_w, int expect_h, const std::string& unit_note) {
  if (!fs::exists(path)) throw InputError(path, "depth image is missing");
  if (isTruncatedPng(path)) throw InputError(path, "cannot decode depth image (truncated PNG)");
  cv::Mat raw = cv::imread(path, cv::IMREAD_ANYDEPTH | cv::IMREAD_ANYCOLOR);
  if (raw.empty()) throw InputError(path, "cannot decode depth image (corrupt or truncated PNG?)");
  if (raw.type() != CV_16UC1) throw InputError(path, "depth image must be 16-bit single channel" + unit_note);
  if (raw.cols != expect_w || raw.rows != expect_h)
    throw InputError(path, "depth image is " + std::to_string(raw.cols) + "x" + std::to_string(raw.rows) +
                               ", expected " + std::to_string(expect_w) + "x" + std::to_string(expect_h));
  return raw;
}

cv::Mat loadTumDepth(const std::string& path, int expect_w, int expect_h) {
  cv::Mat depth;
  loadRawDepthPng(path, expect_w, expect_h).convertTo(depth, CV_32F, 1.0 / 5000.0);  // TUM: 5000/m, 0 = no reading
  return depth;
}

cv::Mat loadColour(const std::string& path, int expect_w, int expect_h) {
  if (!fs::exists(path)) throw InputError(path, "colour image is missing");
  if (isTruncatedPng(path)) throw InputError(path, "cannot decode colour image (truncated PNG)");
  cv::Mat img = cv::imread(path, cv::IMREAD_COLOR);
  if (img.empty()) throw InputError(path, "cannot decode colour image (corrupt or truncated?)");
  if (img.cols != expect_w || img.rows != expect_h)
    throw InputError(path, "colour image is " + std::to_string(img.cols) + "x" + std::to_string(img.rows) +
                               ", expected " + std::to_string(expect_w) + "x" + std::to_string(expect_h));
  return img;
}

CameraIntrinsics readIntrinsicsFile(const std::string& path) {
  const auto lines = dataLines(readTextFile(path));
  if (lines.empty()) throw InputError(path, "no 'fx fy cx cy' line");
  std::istringstream ls(lines[0].text);
  double v[4];
  std::string extra;
  if (!(ls >> v[0] >> v[1] >> v[2] >> v[3]) || (ls >> extra))
    throw InputError(path, "line " + std::to_string(lines[0].number) + ": expected 'fx fy cx cy'");
  CameraIntrinsics c;
  c.fx = v[0]; c.fy = v[1]; c.cx = v[2]; c.cy = v[3];
  return c;
}

TumFolderSource::TumFolderSource(const std::string& folder, const SourceOptions& opts) : folder_(folder) {
  if (!fs::is_directory(folder)) throw InputError(folder, "no such folder");
  const std::string rgb_list = (fs::path(folder) / "rgb.txt").string();
  const std::string depth_list = (fs::path(folder) / "depth.txt").string();
  for (const auto& f : {rgb_list, depth_list})
    if (!fs::exists(f)) throw InputError(f, "missing (not a TUM RGB-D folder?)");
  const auto rgb = readTumList(rgb_list);
  const auto depth = readTumList(depth_list);
  if (rgb.empty()) throw InputError(rgb_list, "lists no frames");
  if (depth.empty()) throw InputError(depth_list, "lists no frames");
  pairs_ = associate(rgb, depth, opts.max_time_diff, opts.unique_depth);
  if (pairs_.empty())
    throw InputError(folder, "no colour frame has a depth frame within " + std::to_string(opts.max_time_diff) + " s");
  if (opts.max_frames > 0 && pairs_.size() > opts.max_frames) pairs_.resize(opts.max_frames);

  const std::string intrinsics_file = (fs::path(folder) / "intrinsics.txt").string();
  if (opts.intrinsics) camera_ = CameraIntrinsics::parse(*opts.intrinsics);
  else if (fs::exists(intrinsics_file)) camera_ = readIntrinsicsFile(intrinsics_file);
  else camera_ = CameraIntrinsics::forTumFolder(folder);
  // Image size comes from the data itself; the first colour frame sets it for the whole sequence.
  const std::string first_path = (fs::path(folder) / pairs_[0].rgb.file).string();
  const cv::Mat first = isTruncatedPng(first_path) ? cv::Mat() : cv::imread(first_path, cv::IMREAD_COLOR);
  if (!first.empty()) {
    camera_.width = first.cols;
    camera_.height = first.rows;
  }
  camera_.validate(opts.intrinsics ? "--intrinsics" : fs::exists(intrinsics_file) ? intrinsics_file : folder);

  const std::string gt = (fs::path(folder) / "groundtruth.txt").string();
  if (fs::exists(gt)) gt_ = readTumTrajectory(gt);
}

Frame TumFolderSource::read(std::size_t i) const {
  const TumAssociation& a = pairs_.at(i);
  Frame f;
  f.index = i;
  // The pose a frame yields is where the camera was when the depth image was taken: ICP and the TSDF
  // see only depth, and colour may be up to max_time_diff away.
  f.timestamp = a.depth.timestamp;
  f.colour_offset = a.rgb.timestamp - a.depth.timestamp;  // the odometry's keypoint bearings come from colour
  f.camera = camera_;
  f.colour_file = (fs::path(folder_) / a.rgb.file).string();
  f.rgb = loadColour(f.colour_file, camera_.width, camera_.height);
  f.depth = loadTumDepth((fs::path(folder_) / a.depth.file).string(), camera_.width, camera_.height);
  mrpt::poses::CPose3D gt;
  if (interpolatePose(gt_, f.timestamp, 0.05, gt)) f.groundTruth = gt;
  return f;
}

}  // namespace vofusion
