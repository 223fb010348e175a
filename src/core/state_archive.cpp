#include "vofusion/core/state_archive.h"

#include <cstdint>
#include <stdexcept>
#include <string>

namespace vofusion::state {

void tag(Archive& a, const std::string& name) { a << name; }

void expectTag(Archive& a, const std::string& name) {
  std::string got;
  a >> got;
  if (got != name) throw std::runtime_error("checkpoint section '" + name + "' expected, found '" + got.substr(0, 40) + "'");
}

namespace {
// An image a checkpoint holds: one row a keypoint (2^24, as their own list allows) or an image's, at
// most 1 GiB, of a type OpenCV makes. Written and read by the same rule: a frame of over 65536 keypoints
// was written whole and refused at --resume, after the run that made it.
bool storable(std::int64_t rows, std::int64_t cols, int type) {
  constexpr std::int64_t kMostSide = std::int64_t(1) << 24, kMostBytes = std::int64_t(1) << 30;
  if (rows < 0 || cols < 0 || rows > kMostSide || cols > kMostSide) return false;
  if (CV_MAT_DEPTH(type) > CV_16F || CV_MAT_CN(type) > 4 || type != CV_MAT_TYPE(type)) return false;
  return rows * cols * std::int64_t(CV_ELEM_SIZE(type)) <= kMostBytes;
}
}  // namespace

void write(Archive& a, const cv::Mat& m) {
  if (!storable(m.rows, m.cols, m.type()))
    throw NotStorable("an image of " + std::to_string(m.rows) + "x" + std::to_string(m.cols) + " is more than a checkpoint holds");
  const cv::Mat c = m.isContinuous() ? m : m.clone();
  a << static_cast<int32_t>(c.rows) << static_cast<int32_t>(c.cols) << static_cast<int32_t>(c.type());
  if (!c.empty()) a.WriteBuffer(c.data, c.total() * c.elemSize());
}

void read(Archive& a, cv::Mat& m) {
  int32_t rows = 0, cols = 0, type = 0;
  a >> rows >> cols >> type;
  if (!storable(rows, cols, type)) throw std::runtime_error("checkpoint: bad image size");
  if (rows == 0 || cols == 0) {
    m = cv::Mat();
    return;
  }
  m.create(rows, cols, type);
  a.ReadBufferFixEndianness(m.data, m.total() * m.elemSize());
}

void write(Archive& a, const std::vector<cv::Mat>& v) {
  a << static_cast<uint64_t>(v.size());
  for (const cv::Mat& m : v) write(a, m);
}

void read(Archive& a, std::vector<cv::Mat>& v) {
  uint64_t n = 0;
  a >> n;
  if (n > 64) throw std::runtime_error("checkpoint: bad image list");
  v.resize(n);
  for (cv::Mat& m : v) read(a, m);
}

void write(Archive& a, const Eigen::Isometry3d& T) { a.WriteBuffer(T.matrix().data(), sizeof(double) * 16); }

void read(Archive& a, Eigen::Isometry3d& T) {
  Eigen::Matrix4d M;
  a.ReadBufferFixEndianness(M.data(), 16);
  if (!M.allFinite()) throw std::runtime_error("checkpoint: bad pose");
  T.matrix() = M;
}

void write(Archive& a, const Eigen::Vector3d& v) { a.WriteBuffer(v.data(), sizeof(double) * 3); }
void read(Archive& a, Eigen::Vector3d& v) { a.ReadBufferFixEndianness(v.data(), 3); }

void write(Archive& a, const Points3& p) {
  a << static_cast<uint64_t>(p.size());
  for (const Eigen::Vector3d& v : p) write(a, v);
}

void read(Archive& a, Points3& p) {
  uint64_t n = 0;
  a >> n;
  if (n > (1u << 24)) throw std::runtime_error("checkpoint: bad point count");
  p.resize(n);
  for (Eigen::Vector3d& v : p) read(a, v);
}

void write(Archive& a, const std::vector<cv::KeyPoint>& k) {
  a << static_cast<uint64_t>(k.size());
  for (const cv::KeyPoint& p : k)
    a << p.pt.x << p.pt.y << p.size << p.angle << p.response << static_cast<int32_t>(p.octave) << static_cast<int32_t>(p.class_id);
}

void read(Archive& a, std::vector<cv::KeyPoint>& k) {
  uint64_t n = 0;
  a >> n;
  if (n > (1u << 24)) throw std::runtime_error("checkpoint: bad keypoint count");
  k.resize(n);
  for (cv::KeyPoint& p : k) {
    int32_t octave = 0, class_id = 0;
    a >> p.pt.x >> p.pt.y >> p.size >> p.angle >> p.response >> octave >> class_id;
    p.octave = octave;
    p.class_id = class_id;
  }
}

void write(Archive& a, const std::vector<cv::Point2f>& p) {
  a << static_cast<uint64_t>(p.size());
  for (const cv::Point2f& q : p) a << q.x << q.y;
}

void read(Archive& a, std::vector<cv::Point2f>& p) {
  uint64_t n = 0;
  a >> n;
  if (n > (1u << 24)) throw std::runtime_error("checkpoint: bad pixel count");
  p.resize(n);
  for (cv::Point2f& q : p) a >> q.x >> q.y;
}

void write(Archive& a, const CameraIntrinsics& c) {
  a << static_cast<int32_t>(c.width) << static_cast<int32_t>(c.height) << c.fx << c.fy << c.cx << c.cy;
  for (double d : c.dist) a << d;
}

void read(Archive& a, CameraIntrinsics& c) {
  int32_t w = 0, h = 0;
  a >> w >> h >> c.fx >> c.fy >> c.cx >> c.cy;
  c.width = w;
  c.height = h;
  for (double& d : c.dist) a >> d;
}

void write(Archive& a, const StageTimes& t) {
  a << t.seconds;
  std::map<std::string, int64_t> calls(t.calls.begin(), t.calls.end());
  a << calls;
}

void read(Archive& a, StageTimes& t) {
  a >> t.seconds;
  std::map<std::string, int64_t> calls;
  a >> calls;
  t.calls.clear();
  for (const auto& [k, v] : calls) t.calls[k] = static_cast<long>(v);
}

}  // namespace vofusion::state
