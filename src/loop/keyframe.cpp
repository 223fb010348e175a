#include "vofusion/loop/keyframe.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include <opencv2/imgproc.hpp>

namespace vofusion::loop {

Keyframe makeKeyframe(std::size_t id, const Frame& frame, const Eigen::Isometry3d& tracked, double path_length,
                      std::shared_ptr<const DescribedKeypoints> features, int downsample) {
  Keyframe k;
  k.id = id;
  k.frame_index = frame.index;
  k.timestamp = frame.timestamp;
  k.tracked = tracked;
  k.path_length = path_length;
  k.features = std::move(features);
  const int n = std::max(1, downsample);
  k.camera = frame.camera;
  k.camera.width = frame.depth.cols / n;
  k.camera.height = frame.depth.rows / n;
  // INTER_NEAREST keeps pixel (n x, n y) as (x, y): coordinates simply scale by 1/n.
  k.camera.fx /= n;
  k.camera.fy /= n;
  k.camera.cx /= n;
  k.camera.cy /= n;
  k.camera.dist = {};
  cv::Mat reduced;
  if (n == 1) reduced = frame.depth;
  else cv::resize(frame.depth, reduced, cv::Size(k.camera.width, k.camera.height), 0, 0, cv::INTER_NEAREST);
  // Readings beyond 16 bits (> 13 m) or not finite become "no reading".
  cv::Mat clean = reduced.clone();
  clean.setTo(0.0f, (reduced != reduced) | (reduced * Keyframe::kDepthUnitsPerMetre > 65535.0));
  clean.convertTo(k.depth, CV_16U, Keyframe::kDepthUnitsPerMetre);
  return k;
}

cv::Mat Keyframe::depthMetres() const {
  cv::Mat m;
  depth.convertTo(m, CV_32F, 1.0 / kDepthUnitsPerMetre);
  return m;
}

bool KeyframeSelector::next(const Eigen::Isometry3d& pose, bool well_tracked, bool strained) {
  // A pose that is not a number (a library caller's) is no place: added to the path it made the path
  // NaN, no keyframe ever joined the place index again, and its keyframe's NaN spread down the chain.
  if (!pose.matrix().allFinite()) {
    recovering_ = have_keyframe_;
    return false;
  }
  if (have_pose_) path_ += (pose.translation() - last_pose_.translation()).norm();
  last_pose_ = pose;
  have_pose_ = true;
  if (!well_tracked) {
    recovering_ = have_keyframe_;
    return false;
  }
  strained_since_keyframe_ |= strained && have_keyframe_;
  const Eigen::Isometry3d d = last_keyframe_.inverse() * pose;
  const double turned = Eigen::AngleAxisd(d.linear()).angle() * 180.0 / M_PI;
  if (have_keyframe_ && !recovering_ && d.translation().norm() < params_.keyframe_translation &&
      turned < params_.keyframe_rotation)
    return false;
  last_keyframe_ = pose;
  last_after_poor_ = recovering_ || strained_since_keyframe_;
  have_keyframe_ = true;
  recovering_ = strained_since_keyframe_ = false;
  return true;
}

void KeyframeSelector::saveState(state::Archive& a) const {
  state::write(a, last_keyframe_);
  state::write(a, last_pose_);
  a << have_keyframe_ << have_pose_ << recovering_ << last_after_poor_ << strained_since_keyframe_ << path_;
}

void KeyframeSelector::loadState(state::Archive& a) {
  state::read(a, last_keyframe_);
  state::read(a, last_pose_);
  a >> have_keyframe_ >> have_pose_ >> recovering_ >> last_after_poor_ >> strained_since_keyframe_ >> path_;
}

}  // namespace vofusion::loop
