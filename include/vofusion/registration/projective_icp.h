#pragma once
// Frame-to-model tracking of KinectFusion (§3.5): projective data association against the ray-cast
// model and point-to-plane ICP linearised as in Low (2004), coarse to fine.
#include <array>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "vofusion/registration/photometric.h"
#include "vofusion/registration/preprocess.h"

namespace vofusion::fusion {

struct IcpParams {
  std::array<int, 3> iterations{6, 4, 3};  // per level, level 0 (full resolution) first
  float max_distance = 0.10f;    // m, correspondences farther apart are rejected
  float max_angle = 30.0f;       // degrees between normals
  // Directions of the 6x6 system (rotation scaled by the scene depth, so both are in metres) whose
  // eigenvalue is below this fraction of the largest are not solved: the pose keeps the initial
  // guess along them (the odometry prediction in mode paper, the last pose in mode kinfu); with
  // JointTerms, see there.
  double degenerate_ratio = 1e-2;
  // m; > 0 weighs every point-to-plane residual as a measurement of this noise at the finest level
  // (a coarser level's averaged pixel: 4x the weight per level), so the ICP term can be summed with
  // other terms (PointMatches). 0: unweighted, as KinectFusion.
  double point_to_plane_sigma = 0.0;
};

// 3D points of the current frame held to fixed world points beside the ICP residuals, in the same
// Gauss-Newton (joint tracking): camera_points[i] (current camera, m) should land on world_points[i].
struct PointMatches {
  std::vector<Eigen::Vector3d> camera_points, world_points;
  std::vector<Eigen::Matrix3d> information;  // per match, world frame, 1/m^2 (inverse noise covariance)
  double cauchy = 1.0;  // scale of the Cauchy kernel on the whitened residual (sigmas); 0 = none
};

struct IcpResult {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  // camera-to-world estimate
  int inliers = 0;             // correspondences at the last iteration of level 0
  int valid_pixels = 0;        // frame pixels with a vertex and normal at level 0
  int in_view = 0;             // of those, landing on a model pixel with a vertex and normal
  double rms = 0.0;            // m, point-to-plane residual over the inliers
  double condition = 0.0;      // smallest / largest eigenvalue of the depth-scaled 6x6 normal matrix
  int degenerate_dims = 0;     // directions left at the initial guess at the last level-0 iteration
                               // (with JointTerms: those decided for the frame under degenerate_ratio)
  bool solved = false;         // false when a linear system could not be solved
  int point_inliers = 0;       // PointMatches within 3 sigmas at the solution
};

// A Gaussian prior on the camera pose itself (a motion model's prediction): rotation and camera
// centre each with an isotropic standard deviation. Summed into every iteration's system.
struct PosePrior {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  // camera-to-world
  double sigma_rotation = 0.0;     // rad, 0 = no rotation term
  double sigma_translation = 0.0;  // m, 0 = no translation term
};

// How well a pose explains the frame at one level, for choosing an initial guess: point-to-plane
// residuals truncated at `truncation` (m) over the pixels that land on the model, those rejected
// (too far, normals disagree) counted as truncated.
struct AlignmentScore {
  int inliers = 0, valid = 0, in_view = 0;
  double cost = 0.0;  // mean truncated squared residual over the in-view pixels, m^2
};
AlignmentScore scoreAlignment(const DepthLevel& frame, const cv::Mat& model_vertices, const cv::Mat& model_normals,
                              const Eigen::Isometry3d& model_pose, const Eigen::Isometry3d& pose,
                              const IcpParams& params, double truncation);

// Mode joint's photometric term (registration/photometric.h), one level per tracking level.
struct PhotometricTerms {
  std::vector<PhotometricLevel> levels;  // per tracking level, level 0 first
  PhotometricParams params;
  Eigen::Isometry3d colour_motion = Eigen::Isometry3d::Identity();  // see accumulatePhotometric
  // The term informs the rotation only: its translation part is marginalised out (Schur complement),
  // so the camera centre comes from ICP, the matches and the motion model.
  bool rotation_only = false;
};

// What joint tracking adds to ICP. The geometry's well-constrained directions are solved from ICP,
// the matches, the motion model and the photometric term together (ICP residuals then need their
// weight, params.point_to_plane_sigma > 0); its weak directions (see degenerate_ratio) move to weak_anchor
// (the prior's pose) when given, else they keep the initial guess. The weak directions are decided
// once, at the frame's first iteration with 6 inliers (coarsest level, initial guess, as a rule; the
// finest level's first whatever its count, when none had 6), and kept: decided at each
// iterate, a direction left to the anchor looked weaker from there and stayed left, so the pose
// jumped when a frame's ratio crossed the cut. A direction between half and twice the ratio takes
// both steps mixed, on a log scale of its eigenvalue (half and half at the ratio).
struct JointTerms {
  const PointMatches* matches = nullptr;
  const PhotometricTerms* photometric = nullptr;
  const PosePrior* motion = nullptr;
  const Eigen::Isometry3d* weak_anchor = nullptr;  // camera-to-world
};

// model_vertices/normals: per level, world frame, ray-cast from model_pose (camera-to-world).
// frame: preprocessed current frame, same number of levels.
IcpResult projectiveIcp(const std::vector<DepthLevel>& frame, const std::vector<cv::Mat>& model_vertices,
                        const std::vector<cv::Mat>& model_normals, const Eigen::Isometry3d& model_pose,
                        const Eigen::Isometry3d& initial, const IcpParams& params, const JointTerms& joint = {});

// 2x2 block average of valid world-frame vertices/normals (for the model pyramid).
void downsampleMaps(const cv::Mat& vertices, const cv::Mat& normals, cv::Mat& vertices_out,
                    cv::Mat& normals_out);

}  // namespace vofusion::fusion
