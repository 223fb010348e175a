#pragma once
// KinectFusion's map on the CPU (Figueroa et al. §3.2, after Newcombe et al. 2011 and KinFu Large Scale):
// a weighted TSDF with a weight cap and colour in a cyclic volume that follows the camera (a world
// model keeps what it left), the model ray-cast from the last fused pose for the next frame's tracking,
// marching cubes. Which pose a frame gets is the tracker's (vofusion/tracking/tracker.h, a layer below):
// it reads the predicted model (ModelSource) and hands back each tracked frame to fuse().
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
#include "vofusion/core/triangle_mesh.h"
#include "vofusion/fusion/tsdf_volume.h"
#include "vofusion/tracking/model_prediction.h"
#include "vofusion/tracking/tracker_params.h"

namespace vofusion {

// INI section [kinfu]: the map's keys here, the tracker's in the base (vofusion/tracking/tracker_params.h);
// one table loads and saves both (kinfu_params.cpp), every key in share/kinfu.ini.
struct KinFuParams : public TrackerParams, public mrpt::config::CLoadableOptions {
  fusion::TsdfParams tsdf;            // volume_voxels, voxel_size, truncation, max_weight,
                                      // integrate_min_depth/max_depth (mark_step: fixed, docs/tracking.md)
  float shift_threshold = 0.3f;       // m, distance focus point <-> volume centre that triggers a shift
  float focus_distance = 1.2f;        // m, the volume follows the point this far along the optical axis
  bool overlap_fusion = true;         // pipeline (Reconstruction): integrate + ray cast frame k on
                                      // another thread while the odometry of frame k+1 runs; same poses

  void loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& section) override;
  void saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& section) const override;
};

struct MapStats {
  std::size_t bricks_in_volume = 0, bricks_in_world_model = 0;
  std::size_t memory_bytes = 0;  // TSDF storage in RAM (volume + the world model's cache)
  fusion::WorldModelStats world;  // the world model: cache, spill file, time spent spilling
};

class KinFu final : public ModelSource {
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

  // ModelSource: a frame was fused (or a map resumed): there is a model to track against.
  bool hasModel() const override;
  std::pair<float, float> fusedDepthRange() const override;
  const ModelPrediction& model() const override;
  // The camera was placed anew at `pose` (relocalisation): the volume moves there and the model is ray
  // cast again (unhinted) before the next frame is tracked.
  void predictAgain(const Eigen::Isometry3d& pose);
  // After resume() or predictAgain(): the model ray cast (unhinted) from `pose` at the tracking resolution, once.
  void predictIfStale(const Eigen::Isometry3d& pose, const CameraIntrinsics& track_cam, StageTimes& times) override;
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
  // What resume() would find wrong with the file before loading it ("" when nothing): it cannot be
  // opened, is no map, or its checksum fails (a map of the first format has none).
  static std::string savedMapProblem(const std::string& path);
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
