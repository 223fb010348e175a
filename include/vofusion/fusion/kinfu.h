#pragma once
// KinectFusion on the CPU (Figueroa et al. §3.2, after Newcombe et al. 2011 and KinFu Large Scale):
// depth preprocessing, frame-to-model ICP weighed together with a motion prior (the 6D RGB-D
// odometry's matches), weighted TSDF with a weight cap and colour, ray casting, a cyclic volume that
// follows the camera, marching cubes.
//
//   KinFu kf(params, TrackingMode::Joint);
//   for each frame: FusionResult r = kf.process(frame, have_prior ? &prior : nullptr);
//   TriangleMesh m = kf.extractMesh();
#include <memory>
#include <string>

#include <mrpt/config/CLoadableOptions.h>
#include <mrpt/poses/CPose3D.h>
#include <opencv2/core.hpp>

#include "vofusion/core/frame.h"
#include "vofusion/core/timing.h"
#include "vofusion/registration/motion_prior.h"
#include "vofusion/registration/preprocess.h"
#include "vofusion/registration/projective_icp.h"
#include "vofusion/fusion/tsdf_volume.h"
#include "vofusion/core/triangle_mesh.h"

namespace vofusion {

// INI section [kinfu]; every key in share/kinfu.ini.
struct KinFuParams : public mrpt::config::CLoadableOptions {
  fusion::TsdfParams tsdf;            // volume_voxels, voxel_size, truncation, max_weight,
                                      // integrate_min_depth/max_depth, mark_step
  fusion::PreprocessParams preprocess;  // bilateral_*, min_depth, max_depth, max_normal_jump
  fusion::IcpParams icp;              // icp_iterations_l0..l2, icp_max_distance, icp_max_angle

  int tracking_downsample = 2;        // 1 or 2: preprocessing, ray casting and ICP at full or half
                                      // resolution (integration always fuses the full-resolution depth)
  float shift_threshold = 0.3f;       // m, distance focus point <-> volume centre that triggers a shift
  float focus_distance = 1.2f;        // m, the volume follows the point this far along the optical axis
  // Tracking failure (divergence, degeneracy) detection:
  float min_inlier_ratio = 0.10f;     // inliers / valid pixels at full resolution
  double min_condition = 1e-6;        // smallest/largest eigenvalue of the (depth-scaled) ICP system
                                      // below which the whole ICP is rejected; weaker directions
                                      // are handled by icp.degenerate_ratio (kept from the prediction)
  float max_jump_translation = 0.05f; // m, ICP pose vs the prior's prediction (modes joint, paper-handoff)
  float max_jump_rotation = 5.0f;     // degrees, same
  bool integrate_on_fallback = true;  // fuse frames whose pose came from the odometry fallback
  bool integrate_filtered = false;    // fuse the bilateral-filtered depth instead of the raw one
                                      // (with tracking_downsample 1 only)
  bool overlap_fusion = true;         // pipeline (Reconstruction): integrate + ray cast frame k on
                                      // another thread while the odometry of frame k+1 runs; same poses
  // Mode joint: one Gauss-Newton over the ICP residuals and the prior's point matches.
  double joint_icp_sigma = 0.005;     // m, noise of one finest-level point-to-plane residual (smaller:
                                      // geometry outweighs the matches more)
  double joint_rolling_shutter = 0.05;  // s, mode joint: readout time of the depth camera; a residual's
                                      // noise grows by this x the turn rate x the scene depth (rows are
                                      // captured at different times, so fast turns bend the frame)
  double joint_match_cauchy = 1.5;    // sigmas, Cauchy kernel on the matches' whitened residuals
  double motion_sigma_translation = 0.002;  // m per 1/30 s, mode joint: how far the camera centre may
                                      // depart from the constant-velocity prediction (0 = no motion model)
  double motion_sigma_rotation = 0.0;  // degrees per 1/30 s, same for the rotation (0 = none)
  float guess_margin = 0.8f;          // another initial guess replaces the prior's only when its
                                      // alignment cost is below this fraction of the prior's
  // Mode joint, the photometric term (registration/photometric.h): each textured pixel of the last frame keeps
  // its intensity in this one.
  double joint_photometric_sigma = 40.0;  // grey levels, noise of one finest-level residual (0 = no term)
  double joint_photometric_huber = 0.3;  // sigmas, Huber kernel on the whitened residual
  double joint_photometric_min_gradient = 4.0;  // grey levels per pixel, weaker reference pixels unused
  bool joint_photometric_rotation_only = true;  // the term informs the rotation only (its translation
                                      // part marginalised): on xyz_first300 it moved the path, not the turns
  bool joint_photometric_colour_time = true;  // each colour image placed at its capture (Frame::colour_offset)

  void loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& section) override;
  void saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& section) const override;
};

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

struct FusionResult {
  bool tracked = false;       // a pose was obtained for this frame (ICP, the prior, or a prediction)
  bool fell_back = false;     // ICP rejected, pose taken from the prior
  bool predicted = false;     // neither ICP nor a prior: pose from the constant-velocity prediction
  InitialGuess guess = InitialGuess::LastPose;
  bool integrated = false;    // the frame was fused into the TSDF
  std::string reason;         // why ICP was rejected / tracking lost ("" when ICP was accepted)
  mrpt::poses::CPose3D pose;  // camera-to-world after this frame (unchanged when lost)
  int icp_inliers = 0;
  double icp_rms = 0.0;       // m
  double condition = 0.0;     // of the ICP normal matrix (0 when no ICP ran)
  int degenerate_dims = 0;    // ICP directions too weak to solve, kept from the prediction
  int match_inliers = 0;      // prior matches within 3 sigmas of the joint estimate
  double icp_sigma = 0.0;     // m, mode joint: the noise the ICP residuals were weighed with
  bool shifted = false;       // the volume moved this frame
  StageTimes times;           // preprocess, icp, integrate, raycast, shift
};

struct KinFuStats {
  std::size_t frames = 0, tracked = 0, fell_back = 0, predicted = 0, lost = 0, shifts = 0;
  std::size_t guess_prior = 0, guess_velocity = 0, guess_last = 0;  // initial guesses chosen (ICP modes)
  std::size_t degenerate = 0;    // frames whose ICP left some direction at the prediction
  std::size_t bricks_in_volume = 0, bricks_in_world_model = 0;
  std::size_t memory_bytes = 0;  // TSDF storage in RAM (volume + the world model's cache)
  fusion::WorldModelStats world;  // the world model: cache, spill file, time spent spilling
  StageTimes times;              // accumulated over all frames
};

class KinFu {
 public:
  // initial_pose: camera-to-world of the first frame (world = first camera frame by default).
  KinFu(const KinFuParams& params, TrackingMode mode,
        const mrpt::poses::CPose3D& initial_pose = mrpt::poses::CPose3D());
  ~KinFu();

  // prior: the motion from an earlier frame (by Frame::index) to this one, nullptr when there is none.
  // geometry: the frame's point and normal maps when another stage computed them (the odometry, for
  // BRAND): ICP then reads them instead of filtering the depth again; nullptr: KinectFusion's own
  // bilateral filter and pyramid.
  FusionResult process(const Frame& frame, const fusion::MotionPrior* prior, const FrameGeometry* geometry = nullptr);

  // process() in two halves, for a caller that overlaps fusing frame k with the odometry of frame
  // k+1: track() estimates the frame's pose (it needs the previous frame's fuse() done); fuse()
  // integrates that frame and ray-casts the model for the next one, adding its stage times to res.
  // The frame's images must stay unchanged until fuse() returns.
  FusionResult track(const Frame& frame, const fusion::MotionPrior* prior, const FrameGeometry* geometry = nullptr);
  void fuse(FusionResult& res);

  // Fuses a frame at a pose known from elsewhere (re-integration with loop-closed poses): the volume
  // follows the camera as in tracking; no ICP, no ray cast.
  void integrateAt(const Frame& frame, const mrpt::poses::CPose3D& cam_to_world);

  mrpt::poses::CPose3D pose() const;
  // The map (volume + world model) and the camera pose to one file, atomically (KinFu LS's world
  // save); a later run resumes from it with resume().
  void save(const std::string& path) const;
  // Replaces the map and the pose by a saved one: the next frame is tracked from the saved pose
  // against the saved map, in its frame. Throws InputError(path, ...) for a bad or truncated file.
  void resume(const std::string& path);
  // Whole world model + current volume.
  TriangleMesh extractMesh() const;
  // Shaded (Lambert, light at the camera) ray-cast image of the model from a pose (BGR).
  cv::Mat renderView(const mrpt::poses::CPose3D& cam_to_world, const CameraIntrinsics& cam,
                     bool coloured = false) const;
  KinFuStats stats() const;
  const fusion::TsdfVolume& volume() const;
  const KinFuParams& params() const;
  TrackingMode mode() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vofusion
