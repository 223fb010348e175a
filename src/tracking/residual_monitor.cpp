#include "vofusion/tracking/residual_monitor.h"

#include <algorithm>

namespace vofusion {

bool ResidualMonitor::strained(double rms) {
  if (rms <= 0.0 || ratio_ <= 0.0) return false;
  bool out = false;
  if (recent_.size() >= kMinSamples) {
    sorted_.assign(recent_.begin(), recent_.end());
    std::nth_element(sorted_.begin(), sorted_.begin() + std::ptrdiff_t(sorted_.size() / 2), sorted_.end());
    out = rms > ratio_ * sorted_[sorted_.size() / 2];
  }
  recent_.push_back(rms);
  if (recent_.size() > kWindow) recent_.pop_front();
  return out;
}

}  // namespace vofusion
