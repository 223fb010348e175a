#pragma once
// How a frame's pose is decided: the tracking mode, where the estimate started, and why ICP's estimate
// was not taken.
#include <string>

namespace vofusion {

enum class TrackingMode {
  Joint,         // ICP and the prior's matches in one estimate, from the best-scoring initial guess
  PaperHandoff,  // the paper: ICP seeded by the prior; the prior's pose when ICP fails
  KinFu,         // ICP alone from the previous pose (KinFu LS); a failure is a lost frame
  Odometry,      // no ICP: pose = the prior's
};
// "joint", "paper-handoff" (also "paper"), "kinfu", "odometry"; throws InputError(origin, ...) otherwise.
TrackingMode parseTrackingMode(const std::string& s, const std::string& origin = "--mode");
std::string toString(TrackingMode m);

// Where the tracker started from.
enum class InitialGuess { Prior, ConstantVelocity, LastPose };
std::string toString(InitialGuess g);

// Why a frame's ICP estimate was not taken (or, in mode odometry, why there was no prior's pose).
enum class Rejection {
  None,
  NoDepth,                 // the frame has no depth image
  NotSolvable,             // ICP's system could not be solved
  TooFewInliers,           // below min_inlier_ratio of the pixels judged
  IllConditioned,          // the ICP system's eigenvalue ratio below kMinCondition
  JumpedFromPrior,         // ICP's pose beyond max_jump_* from the prior's
  NoPrior,                 // mode odometry: no motion prior for this frame
  PriorReferenceUnknown,   // mode odometry: the prior's reference frame has no pose here
  NotRelocalised,          // tracking was lost and no keyframe matched this frame yet
  NoReadingInRange,        // the first frame's readings all lie outside [min_depth, max_depth]
  NoReadingFused,          // mode kinfu: none of the first frame's readings is fused (integrate_*_depth)
};  // new reasons go last: checkpoints store them as numbers
// The reason as summary.json counts it ("too few ICP inliers", ...); "" for None.
std::string toString(Rejection r);

}  // namespace vofusion
