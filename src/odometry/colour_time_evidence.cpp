#include "vofusion/odometry/colour_time_evidence.h"

#include <cmath>

namespace vofusion {

double ColourTimeEvidence::z() const {
  // Under "neither correction fits better" the votes for capture are Binomial(n, 1/2).
  return compared_ == 0 ? 0.0 : (2.0 * capture_better_ - compared_) / std::sqrt(double(compared_));
}

bool ColourTimeEvidence::wantsVote() {
  const bool settled = compared_ >= kMinFrames && std::abs(z()) >= kSettledZ;
  if (!settled || ++skipped_ >= kSettledEvery) {
    skipped_ = 0;
    return true;
  }
  return false;
}

void ColourTimeEvidence::add(bool capture_fitted_better) {
  ++compared_;
  if (capture_fitted_better) ++capture_better_;
  if (compared_ < kMinFrames) return;
  if (z() > kSwitchZ) capture_ = true;
  else if (z() < -kSwitchZ) capture_ = false;
}

void ColourTimeEvidence::saveState(state::Archive& a) const {
  a << int32_t(compared_) << int32_t(capture_better_) << int32_t(skipped_) << capture_;
}

void ColourTimeEvidence::loadState(state::Archive& a) {
  int32_t compared = 0, better = 0, skipped = 0;
  a >> compared >> better >> skipped >> capture_;
  compared_ = compared, capture_better_ = better, skipped_ = skipped;
}

}  // namespace vofusion
