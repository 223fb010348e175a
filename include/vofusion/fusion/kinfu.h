#pragma once
// KinectFusion's map on the CPU (Figueroa et al. §3.2, after Newcombe et al. 2011 and KinFu Large Scale):
// a weighted TSDF with a weight cap and colour in a cyclic volume that follows the camera (a world
// model keeps what it left), the model ray-cast from the last fused pose for the next frame's tracking,
// marching cubes. Which pose a frame gets is the tracker's (vofusion/tracking/tracker.h): it reads the
// predicted model (model()) and hands back each tracked frame to fuse().
//
//   KinFu map(params, first_pose, {true, false});
//   per frame: track against map.model(), then map.fuse(frame_to_fuse, times);
//   TriangleMesh m = map.extractMesh();
#include <iosfwd>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Geometry>
#include <mrpt/config/CLoadableOptions.h>
#include <mrpt/poses/CPose3D.h>
#include <opencv2/core.hpp>

#include "vofusion/core/frame.h"
#include "vofusion/core/timing.h"
#include "vofusion/registration/photometric.h"
#include "vofusion/registration/preprocess.h"
#include "vofusion/registration/projective_icp.h"
#include "vofusion/fusion/tsdf_volume.h"
#include "vofusion/core/triangle_mesh.h"

namespace vofusion {

// INI section [kinfu]: the map's keys and the tracker's (vofusion/tracking/tracker.h); every key in
// share/kinfu.ini.
struct KinFuParams : public mrpt::config::CLoadableOptions {
  fusion::TsdfParams tsdf;            // volume_voxels, voxel_size, truncation, max_weight,
                                      // integrate_min_depth/max_depth, mark_step
  fusion::PreprocessParams preprocess;  // bilateral_*, min_depth, max_depth, max_normal_jump
  fusion::IcpParams icp;              // icp_iterations_l0..l2, icp_max_distance, icp_max_angle

  int tracking_downsample = 2;        // 1 or 2: preprocessing, ray casting and ICP at full or half
                                      // resolution (integration always fuses the full-resolution depth)
  float shift_threshold = 0.3f;       // m, distance focus point <-> volume centre that triggers a shift
  float focus_distance = 1.2f;        // m, the volume follows the point this far along the optical axis
  // Tracking failure (divergence, degeneracy) detection; the conditioning bound is fixed in code
  // (tracking::kMinCondition).
  float min_inlier_ratio = 0.10f;     // inliers / valid pixels at full resolution
  float max_jump_translation = 0.05f; // m, ICP pose vs the prior's prediction (modes joint, paper-handoff)
  float max_jump_rotation = 5.0f;     // degrees, same
  bool integrate_on_fallback = true;  // fuse frames whose pose came from the odometry fallback
  bool integrate_filtered = false;    // fuse the bilateral-filtered depth instead of the raw one
                                      // (with tracking_downsample 1 only)
  bool overlap_fusion = true;         // pipeline (Reconstruction): integrate + ray cast frame k on
                                      // another thread while the odometry of frame k+1 runs; same poses
  // Mode joint: one Gauss-Newton over the ICP residuals and the prior's point matches (its robust
  // kernels and the initial guess's margin are fixed in code: tracking/joint_policy.h).
  double joint_icp_sigma = 0.005;     // m, noise of one finest-level point-to-plane residual (smaller:
                                      // geometry outweighs the matches more)
  double joint_rolling_shutter = 0.05;  // s, mode joint: readout time of the depth camera; a residual's
                                      // noise grows by this x the turn rate x the scene depth (rows are
                                      // captured at different times, so fast turns bend the frame)
  double motion_sigma_translation = 0.002;  // m per 1/30 s, mode joint: how far the camera centre may
                                      // depart from the constant-velocity prediction (0 = no motion model)
  double motion_sigma_rotation = 0.0;  // degrees per 1/30 s, same for the rotation (0 = none)
  // Mode joint, the photometric term (registration/photometric.h): each textured pixel of the last frame keeps
  // its intensity in this one.
  double joint_photometric_sigma = 40.0;  // grey levels, noise of one finest-level residual (0 = no term)
  bool joint_photometric_rotation_only = true;  // the term informs the rotation only (its translation
                                      // part marginalised): on xyz_first300 it moved the path, not the turns
  bool joint_photometric_colour_time = true;  // each colour image placed at its capture (Frame::colour_offset)

  void loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& section) override;
  void saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& section) const override;
};

// What the map predicts for tracking the next frame: the model ray-cast from `pose` after the last
// fusion, one vertex and normal map per tracking level (NaN where no surface), and, when asked for,
// the intensity of the frame fused last resampled at the model's points (the photometric term's
// reference).
struct ModelPrediction {
  std::vector<cv::Mat> vertices, normals;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  std::vector<fusion::IntensityLevel> intensity;
};

// A tracked frame as the map takes it. The images must stay unchanged until fuse() returns.
struct FrameToFuse {
  bool integrate = true;         // false: not fused (a fallback or predicted pose), the model only re-predicted
  cv::Mat depth, rgb;            // what is fused (full resolution)
  cv::Mat hint;                  // the finest tracking level's depth: where the next ray cast looks first
  CameraIntrinsics cam, track_cam;  // of depth, and of the tracking levels' finest
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  // camera-to-world
  std::vector<fusion::IntensityLevel> intensity;  // the frame's intensity pyramid (photometric reference)
  std::vector<CameraIntrinsics> level_cams;        // its levels' cameras
  Eigen::Isometry3d colour_pose = Eigen::Isometry3d::Identity();  // where its colour was captured
};

struct MapStats {
  std::size_t bricks_in_volume = 0, bricks_in_world_model = 0;
  std::size_t memory_bytes = 0;  // TSDF storage in RAM (volume + the world model's cache)
  fusion::WorldModelStats world;  // the world model: cache, spill file, time spent spilling
};

class KinFu {
 public:
  // What the map keeps predicting after each fusion: the model's surfaces (for ICP; not in mode
  // odometry, where nothing reads them) and the fused frame's intensity on them (photometric term).
  struct Prediction {
    bool surfaces = true;
    bool intensity = false;
  };
  // initial_pose: camera-to-world of the first frame; the volume is placed around it.
  KinFu(const KinFuParams& params, const Eigen::Isometry3d& initial_pose, Prediction predict);
  ~KinFu();

  // A frame was fused (or a map resumed): there is a model to track against.
  bool hasModel() const;
  const ModelPrediction& model() const;
  // The camera was placed anew at `pose` (relocalisation): the volume moves there and the model is ray
  // cast again (unhinted) before the next frame is tracked.
  void predictAgain(const Eigen::Isometry3d& pose);
  // After resume() or predictAgain(): the model ray cast (unhinted) from `pose` at the tracking resolution, once.
  void predictIfStale(const Eigen::Isometry3d& pose, const CameraIntrinsics& track_cam, StageTimes& times);
  // Fuses a tracked frame, moves the volume with the camera and predicts the model from its pose
  // (stage times "shift", "integrate", "raycast" into `times`). Returns whether the volume shifted.
  bool fuse(const FrameToFuse& frame, StageTimes& times);
  // Fuses a frame at a pose known from elsewhere (re-integration with loop-closed poses): the volume
  // follows the camera as in tracking; no ray cast. Returns whether the volume shifted.
  bool integrateAt(const Frame& frame, const Eigen::Isometry3d& cam_to_world, StageTimes& times);

  // The map and the camera pose to one file, atomically (KinFu LS's world save).
  void save(const std::string& path, const Eigen::Isometry3d& pose) const;
  // Replaces the map by a saved one and returns its camera pose; the model is predicted again before
  // the next frame is tracked (predictIfStale). Throws InputError(path, ...) for a bad or truncated file.
  Eigen::Isometry3d resume(const std::string& path);
  // Checkpoints: the map and the model last predicted from it (surfaces, intensity, the ray cast's
  // depth), so the next frame is tracked exactly as it would have been without the interruption.
  void saveState(std::ostream& os) const;
  void loadState(std::istream& is);
  // Whole world model + current volume.
  TriangleMesh extractMesh() const;
  // Shaded (Lambert, light at the camera) ray-cast image of the model from a pose (BGR).
  cv::Mat renderView(const mrpt::poses::CPose3D& cam_to_world, const CameraIntrinsics& cam,
                     bool coloured = false) const;
  MapStats stats() const;
  const fusion::TsdfVolume& volume() const;
  // Called on the thread that moves the volume (fusion; relocalisation's predictAgain) after each
  // shift, with the volume (moved) and its first brick before the shift; and once after a map was
  // loaded (loadState, resume) with no old origin: every brick outside the box is then as final as
  // one the volume left. One observer, set before the first frame and before a map is loaded
  // (setting it while frames are fused races with the call).
  using ShiftObserver =
      std::function<void(const fusion::TsdfVolume& volume, const std::optional<Eigen::Vector3i>& old_origin)>;
  void setShiftObserver(ShiftObserver observer);
  const KinFuParams& params() const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace vofusion
