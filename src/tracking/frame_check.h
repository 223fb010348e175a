#pragma once
// Mode joint's check of the model against the last frame: where the map comes back into view from an
// earlier pass a few centimetres off (the lap's end before its loop is closed), ICP against the model
// pulls the frame onto the old surface, away from where the frame-to-frame estimates agree. Private
// to src/tracking/.
#include <optional>
#include <vector>

#include <Eigen/Geometry>

#include "vofusion/core/state_archive.h"
#include "vofusion/tracking/tracker_params.h"
#include "vofusion/registration/preprocess.h"
#include "vofusion/registration/projective_icp.h"

namespace vofusion::tracking {

// The last tracked frame's own depth maps (its camera's coordinates) and its pose: a reference that
// does not depend on the map.
struct ReferenceFrame {
  std::vector<fusion::DepthLevel> levels;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  // camera-to-world
};

// Checkpoints: the reference (or none), bit for bit, so a resumed run checks the next frame as the
// saved one would have.
void write(state::Archive& a, const std::optional<ReferenceFrame>& ref);
void read(state::Archive& a, std::optional<ReferenceFrame>& ref);

// Whether the joint estimate left the odometry's pose by more than one residual's noise
// (joint_icp_sigma): only then is a second estimate worth its ICP.
bool worthChecking(const TrackerParams& P, const Eigen::Isometry3d& joint, const Eigen::Isometry3d& prior_pose);

// The frame's depth against the reference's instead of the model's, from the odometry's pose and held
// by it only where the geometry is weak.
fusion::IcpResult trackAgainstFrame(const ReferenceFrame& ref, const std::vector<fusion::DepthLevel>& levels,
                                    const Eigen::Isometry3d& prior_pose, const fusion::IcpParams& ip);

// Whether the model pulled the frame away from two estimates that do not see it: the frame-to-frame
// ICP and the odometry agree, and the joint estimate is farther from them than both one residual's
// noise and several times their own disagreement.
bool modelPulledAway(const TrackerParams& P, const Eigen::Isometry3d& joint, const Eigen::Isometry3d& frame_to_frame,
                     const Eigen::Isometry3d& prior_pose);

}  // namespace vofusion::tracking
