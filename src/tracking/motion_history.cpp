#include "vofusion/tracking/motion_history.h"

#include <algorithm>
#include <stdexcept>

namespace vofusion {

Eigen::Isometry3d scaledMotion(const Eigen::Isometry3d& m, double s) {
  const Eigen::AngleAxisd rot(m.linear());
  Eigen::Isometry3d step = Eigen::Isometry3d::Identity();
  step.linear() = Eigen::AngleAxisd(s * rot.angle(), rot.axis()).toRotationMatrix();
  step.translation() = s * m.translation();
  return step;
}

const Eigen::Isometry3d* MotionHistory::poseOf(std::size_t index) const {
  for (const auto& [i, T] : recent_)
    if (i == index) return &T;
  return nullptr;
}

Eigen::Isometry3d MotionHistory::constantVelocity(double timestamp) const {
  if (!(last_motion_dt_ > 0)) return pose_;
  return pose_ * scaledMotion(last_motion_, std::clamp((timestamp - last_timestamp_) / last_motion_dt_, 0.0, 3.0));
}

Eigen::Isometry3d MotionHistory::motionOver(double offset) const {
  if (!(last_motion_dt_ > 0) || offset == 0.0) return Eigen::Isometry3d::Identity();
  return scaledMotion(last_motion_, std::clamp(offset / last_motion_dt_, -3.0, 3.0));
}

void MotionHistory::remember(std::size_t index, double timestamp, const Eigen::Isometry3d& T, bool measured) {
  if (measured && have_measured_ && timestamp > measured_timestamp_) {
    last_motion_ = measured_pose_.inverse() * T;
    last_motion_dt_ = std::max(timestamp - measured_timestamp_, kShortestFrameInterval);
  }
  if (measured) {
    measured_pose_ = T;
    measured_timestamp_ = timestamp;
    have_measured_ = true;
  }
  pose_ = T;
  last_timestamp_ = timestamp;
  have_last_ = true;
  recent_.emplace_back(index, T);
  forgetOld();
}

void MotionHistory::hold(std::vector<std::size_t> frames) {
  if (frames.size() > kHeld) frames.resize(kHeld);
  held_ = std::move(frames);  // the next remember() forgets by it: this frame's prior may name a frame it no longer holds
}

// Those before the last kRecent, except the held frames.
void MotionHistory::forgetOld() {
  const std::size_t older = recent_.size() > kRecent ? recent_.size() - kRecent : 0;
  auto it = recent_.begin();
  for (std::size_t i = 0; i < older; ++i) {
    const bool held = std::find(held_.begin(), held_.end(), it->first) != held_.end();
    it = held ? std::next(it) : recent_.erase(it);
  }
}

void MotionHistory::restart(const Eigen::Isometry3d& T) {
  pose_ = T;
  have_last_ = have_measured_ = false;
  last_motion_dt_ = 0.0;
  recent_.clear();
}

void MotionHistory::saveState(state::Archive& a) const {
  state::write(a, pose_);
  a << uint64_t(recent_.size());
  for (const auto& [i, T] : recent_) {
    a << uint64_t(i);
    state::write(a, T);
  }
  state::write(a, last_motion_);
  a << last_motion_dt_ << last_timestamp_ << have_last_;
  state::write(a, measured_pose_);
  a << measured_timestamp_ << have_measured_;
}

void MotionHistory::loadState(state::Archive& a) {
  state::read(a, pose_);
  uint64_t n = 0;
  a >> n;
  if (n > kRecent + kHeld) throw std::runtime_error("checkpoint: bad motion history");
  recent_.clear();
  for (uint64_t k = 0; k < n; ++k) {
    uint64_t i = 0;
    a >> i;
    Eigen::Isometry3d T;
    state::read(a, T);
    recent_.emplace_back(i, T);
  }
  state::read(a, last_motion_);
  a >> last_motion_dt_ >> last_timestamp_ >> have_last_;
  state::read(a, measured_pose_);
  a >> measured_timestamp_ >> have_measured_;
}

}  // namespace vofusion
