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

// Throws InputError(path, "line N: ...") on a malformed line; '#' comments and blank lines skipped.
Trajectory readTumTrajectory(const std::string& path);
Trajectory parseTumTrajectory(const std::string& text, const std::string& origin);
// Written whole or not at all (temporary file + rename).
void writeTumTrajectory(const std::string& path, const Trajectory& traj);

// Pose at time t by linear/slerp interpolation between the two nearest samples;
// false if t lies outside [first, last] by more than max_gap seconds, or the bracketing gap is larger.
bool interpolatePose(const Trajectory& traj, double t, double max_gap, mrpt::poses::CPose3D& out);

}  // namespace vofusion
