#pragma once
// What tracking reads from the map and hands back to it. The map sits above tracking (a frame flows
// io -> odometry -> tracking -> fusion): fusion's KinFu implements ModelSource and fuses FrameToFuse,
// and tracking never includes it.
#include <utility>
#include <vector>

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include "vofusion/core/frame.h"
#include "vofusion/core/timing.h"
#include "vofusion/registration/photometric.h"

namespace vofusion {

// What the map predicts for tracking the next frame: the model ray-cast from `pose` after the last
// fusion, one vertex and normal map per tracking level (NaN where no surface), and, when asked for,
// the intensity of the frame fused last resampled at the model's points (the photometric term's
// reference).
struct ModelPrediction {
  std::vector<cv::Mat> vertices, normals;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  std::vector<fusion::IntensityLevel> intensity;
};

// A tracked frame as the map takes it. The images must stay unchanged until the map's fuse() returns.
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

// The map as the tracker reads it while it tracks a frame.
class ModelSource {
 public:
  // A frame was fused (or a map resumed): there is a model to track against.
  virtual bool hasModel() const = 0;
  virtual const ModelPrediction& model() const = 0;
  // After a map was resumed or the camera placed anew: the model ray cast (unhinted) from `pose` at the
  // tracking resolution `track_cam`, once; otherwise nothing.
  virtual void predictIfStale(const Eigen::Isometry3d& pose, const CameraIntrinsics& track_cam, StageTimes& times) = 0;
  // The depths it fuses, m (min, max): a first frame with no reading there would start an empty model.
  virtual std::pair<float, float> fusedDepthRange() const = 0;

 protected:
  ~ModelSource() = default;
};

}  // namespace vofusion
