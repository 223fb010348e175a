#pragma once
// NARF interest points (Steder et al., ICRA 2011) on the depth image, as pcl::NarfKeypoint finds them
// on a pcl::RangeImagePlanar built from the depth map and the intrinsics: by default with our own
// implementation of PCL's steps (narf_fast.h, same keypoints in half the time), or by PCL itself.
// NARF costs seconds per frame at 640x480, so it runs on a depth image reduced by `downsample` and
// keypoints are mapped back.
#include <optional>
#include <string>
#include <vector>

#include <mrpt/config/CLoadableOptions.h>
#include <opencv2/core.hpp>

#include "vofusion/core/camera.h"
#include "vofusion/features/narf_fast.h"

namespace vofusion {

struct NarfParams : public mrpt::config::CLoadableOptions {
  double support_size = 0.2;        // m; area covered by an interest point (the NARF paper's value)
  int downsample = 5;               // factor; 1 = full resolution (seconds per frame)
  int max_points = 0;               // keypoints kept, strongest first; 0 = all
  double min_interest_value = 0.45; // [0, 1]; PCL default
  int threads = 2;                  // implementation pcl: OpenMP threads of PCL's border extraction; the
                                    // interest search always runs on one (more makes the keypoints vary)
  std::string implementation = "fast";     // "fast": narf_fast.h, PCL's steps on flat arrays;
                                           // "pcl": pcl::NarfKeypoint itself (the reference)

  void loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& section) override;
  void saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& section) const override;
};

// depth: CV_32F metres (0 = no reading), camera: its intrinsics. Keypoint positions are in full
// resolution pixels; size = support size in pixels at the point's depth, response = interest value.
std::vector<cv::KeyPoint> detectNarf(const cv::Mat& depth, const CameraIntrinsics& camera,
                                     const NarfParams& params = {});

// The same in two steps, for a caller with other work (the odometry): prepareNarf does the part that
// runs on every core (the reduced depth, the range image, the border extraction: about half the CPU);
// detectNarf(prepared) the interest search, which runs on one, beside that other work. Same keypoints.
struct NarfPrepared {
  NarfParams params;
  CameraIntrinsics camera;          // full resolution
  cv::Mat reduced;                  // the reduced depth, continuous
  CameraIntrinsics reduced_camera;
  std::optional<narf::RangeImage> range;  // implementation fast (pcl builds its own in the search)
  narf::Borders borders;
};
NarfPrepared prepareNarf(const cv::Mat& depth, const CameraIntrinsics& camera, const NarfParams& params = {});
std::vector<cv::KeyPoint> detectNarf(const NarfPrepared& prepared);

// Depth image reduced by an integer factor, each output pixel the nearest valid reading of its block
// (not an average: averaging across an occlusion boundary invents surfaces).
cv::Mat downsampleDepth(const cv::Mat& depth, int factor);

// The reading a NARF keypoint at `centre` stands for (detectNarf places it at its block's centre, in
// full-resolution pixels; the centre may have moved since, by the image motion): the nearest one in the
// factor x factor pixels about it, as downsampleDepth took it; 0 if none. factor in [1, 21].
float narfBlockDepth(const cv::Mat& depth, cv::Point2f centre, int factor);

}  // namespace vofusion
