#include "vofusion/tracking/tracking_mode.h"

#include "vofusion/core/errors.h"

namespace vofusion {

TrackingMode parseTrackingMode(const std::string& s, const std::string& origin) {
  if (s == "joint") return TrackingMode::Joint;
  if (s == "paper-handoff" || s == "paper") return TrackingMode::PaperHandoff;
  if (s == "kinfu") return TrackingMode::KinFu;
  if (s == "odometry") return TrackingMode::Odometry;
  throw InputError(origin, "unknown mode '" + s + "' (expected joint, paper-handoff, kinfu or odometry)");
}

std::string toString(TrackingMode m) {
  switch (m) {
    case TrackingMode::Joint: return "joint";
    case TrackingMode::PaperHandoff: return "paper-handoff";
    case TrackingMode::KinFu: return "kinfu";
    case TrackingMode::Odometry: return "odometry";
  }
  return "?";
}

std::string toString(InitialGuess g) {
  switch (g) {
    case InitialGuess::Prior: return "prior";
    case InitialGuess::ConstantVelocity: return "constant velocity";
    case InitialGuess::LastPose: return "last pose";
  }
  return "?";
}

std::string toString(Rejection r) {
  switch (r) {
    case Rejection::None: return "";
    case Rejection::NoDepth: return "no depth image";
    case Rejection::NotSolvable: return "ICP system not solvable";
    case Rejection::TooFewInliers: return "too few ICP inliers";
    case Rejection::IllConditioned: return "ill-conditioned ICP";
    case Rejection::JumpedFromPrior: return "ICP jumped from the prior";
    case Rejection::NoPrior: return "no motion prior";
    case Rejection::PriorReferenceUnknown: return "prior's reference frame has no pose";
    case Rejection::NotRelocalised: return "lost, not relocalised";
    case Rejection::NoReadingInRange: return "no depth reading in [min_depth, max_depth]";
    case Rejection::NoReadingFused: return "no depth reading in [integrate_min_depth, integrate_max_depth] to start the map";
  }
  return "?";
}

}  // namespace vofusion
