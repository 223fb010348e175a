#pragma once
// Trajectories in the TUM RGB-D format: "timestamp tx ty tz qx qy qz qw", camera-to-world.
#include <string>
#include <vector>

#include <mrpt/poses/CPose3D.h>

namespace vofusion {

struct StampedPose {
  double timestamp = 0.0;     // seconds
  mrpt::poses::CPose3D pose;  // camera-to-world
};
using Trajectory = std::vector<StampedPose>;

// Whether a file's stamps must increase line by line. A ground truth must (a line out of order is a
// damaged file); an estimate is taken as written: a run writes its frames in their order, and a
// recording's clock may step back (a rawlog's stamps come as recorded).
enum class StampOrder { Increasing, AsWritten };

// Throws InputError(path, "line N: ...") on a malformed line; '#' comments and blank lines skipped.
Trajectory readTumTrajectory(const std::string& path, StampOrder order = StampOrder::Increasing);
Trajectory parseTumTrajectory(const std::string& text, const std::string& origin, StampOrder order = StampOrder::Increasing);
// Written whole or not at all (temporary file + rename).
void writeTumTrajectory(const std::string& path, const Trajectory& traj);

// Pose at time t by linear/slerp interpolation between the two nearest samples; false where the
// bracketing gap is over 2 * max_gap and t more than max_gap from both its ends (a dropout of the
// ground truth: near an end the interpolation is that end's pose within the motion of max_gap), and
// for a t that is no number. Outside [first, last] the end pose is held, and a held
// pose stands for t only within kHeldPoseWithin (the TUM benchmark's association tolerance): 0.05 s
// beyond the end of a ground truth at 1 m/s put a 5 cm error into the frame's evaluation.
constexpr double kHeldPoseWithin = 0.02;  // s
// traj in time order (sortedByTime).
bool interpolatePose(const Trajectory& traj, double t, double max_gap, mrpt::poses::CPose3D& out);

// t's poses in time order, equal stamps in their order in t.
Trajectory sortedByTime(const Trajectory& t);
// t's poses, one per stamp: of those sharing a stamp the last in t, as TUM's scripts read a file (a
// dict by stamp); the others in t's order. An evaluation counted a repeated stamp twice.
Trajectory onePosePerStamp(const Trajectory& t);

}  // namespace vofusion
