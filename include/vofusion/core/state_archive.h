#pragma once
// A checkpoint's state <-> bytes (vofusion --checkpoint-every, --resume): MRPT's CArchive over a std
// stream for numbers, strings and STL containers, plus the types the stages keep that MRPT does not
// serialise (OpenCV images and keypoints, Eigen poses and points, stage times). Each stage writes and
// reads its own state with these, between named tags, so a checkpoint from another version or a
// damaged file fails at the first section that does not fit. A short or bad read throws: these
// functions' checks std::runtime_error, the archive's own reads MRPT's exception (a std::logic_error);
// the caller catches std::exception and names the file.
#include <istream>
#include <optional>
#include <ostream>
#include <stdexcept>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <mrpt/serialization/CArchive.h>
#include <mrpt/serialization/archiveFrom_std_streams.h>
#include <mrpt/serialization/stl_serialization.h>
#include <opencv2/core.hpp>

#include "vofusion/core/camera.h"
#include "vofusion/core/described_keypoints.h"
#include "vofusion/core/timing.h"

namespace vofusion::state {

using Archive = mrpt::serialization::CArchive;

// An archive over a std stream. MRPT's writes and reads straight through, so other writes to the
// stream (a TSDF volume's own format) may come between two archives' sections.
inline auto archiveOf(std::ostream& os) { return mrpt::serialization::archiveFrom<std::ostream>(os); }
inline auto archiveOf(std::istream& is) { return mrpt::serialization::archiveFrom<std::istream>(is); }

// A section starts with its name; expectTag throws when the next bytes are another one.
void tag(Archive& a, const std::string& name);
void expectTag(Archive& a, const std::string& name);

// What a checkpoint cannot hold (an image past the rule below): the checkpoint's failure, not the run's.
struct NotStorable : std::runtime_error {
  using std::runtime_error::runtime_error;
};
// Any OpenCV type (up to 4 channels), continuous or not, empty kept empty; up to 2^24 rows or columns
// and 1 GiB, written and read by the same rule (beyond: NotStorable when written).
void write(Archive& a, const cv::Mat& m);
void read(Archive& a, cv::Mat& m);
void write(Archive& a, const std::vector<cv::Mat>& v);
void read(Archive& a, std::vector<cv::Mat>& v);
void write(Archive& a, const Eigen::Isometry3d& T);  // the 4x4 matrix's doubles, bit for bit
void read(Archive& a, Eigen::Isometry3d& T);
void write(Archive& a, const Eigen::Vector3d& v);
void read(Archive& a, Eigen::Vector3d& v);
void write(Archive& a, const Points3& p);
void read(Archive& a, Points3& p);
void write(Archive& a, const std::vector<cv::KeyPoint>& k);
void read(Archive& a, std::vector<cv::KeyPoint>& k);
void write(Archive& a, const std::vector<cv::Point2f>& p);
void read(Archive& a, std::vector<cv::Point2f>& p);
void write(Archive& a, const CameraIntrinsics& c);
void read(Archive& a, CameraIntrinsics& c);
void write(Archive& a, const StageTimes& t);
void read(Archive& a, StageTimes& t);

// An optional value: a flag, then the value with the write/read above (or a lambda's).
template <class T, class F>
void writeOptional(Archive& a, const std::optional<T>& v, F&& writeValue) {
  a << v.has_value();
  if (v) writeValue(*v);
}
template <class T, class F>
void readOptional(Archive& a, std::optional<T>& v, F&& readValue) {
  bool has = false;
  a >> has;
  v.reset();
  if (!has) return;
  v.emplace();
  readValue(*v);
}

}  // namespace vofusion::state
