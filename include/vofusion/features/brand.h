#pragma once
// BRAND (Nascimento et al., IROS 2012): a 256-bit binary descriptor from colour and depth.
// Over a smoothed patch whose size follows the keypoint's depth, rotated to the patch's canonical
// orientation, each of 256 fixed point pairs (x, y) gives one bit:
//   intensity bit  I(x) < I(y)
//   geometric bit  <n_x, n_y> < cos(normal_angle)  AND  the surface is convex between them,
//                  <P_x - P_y, n_x - n_y> > 0
// and the descriptor bit is their OR (the paper's fusion). Normals come from the depth image.
#include <cstdint>
#include <string>
#include <vector>

#include <mrpt/config/CLoadableOptions.h>
#include <opencv2/core.hpp>

#include "vofusion/core/camera.h"
#include "vofusion/core/point_maps.h"

namespace vofusion {

struct BrandParams : public mrpt::config::CLoadableOptions {
  int patch_size = 48;            // pixels at depth <= 2 m (the paper's S); shrinks with depth
  double smoothing_sigma = 2.0;   // pixels; Gaussian smoothing of the intensity image
  double normal_angle = 45.0;     // degrees; normals differing more than this set the geometric bit
  int normal_window = 4;          // pixels; half-size of the boxes of the integral-image normals
  double max_depth_step = 0.05;   // m; normals are not computed across larger depth jumps
  bool use_intensity = true;      // include the intensity tests
  bool use_geometry = true;       // include the normal/convexity tests
  bool oriented = true;           // rotate the pattern to the canonical orientation

  void loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& section) override;
  void saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& section) const override;
};


class BrandExtractor {
 public:
  explicit BrandExtractor(const BrandParams& params = {});
  // gray CV_8UC1, points/normals as above. Keypoints without depth, or too close to the border, are
  // removed; descriptors gets one 32-byte row (CV_8U) per remaining keypoint. Keypoint angles are
  // set to the canonical orientation (degrees).
  void compute(const cv::Mat& gray, const cv::Mat& points, const cv::Mat& normals,
               std::vector<cv::KeyPoint>& keypoints, cv::Mat& descriptors) const;
  // The smoothed intensity the tests read (exposed so callers can share it).
  cv::Mat smooth(const cv::Mat& gray) const;
  void computeSmoothed(const cv::Mat& smoothed, const cv::Mat& points, const cv::Mat& normals,
                       std::vector<cv::KeyPoint>& keypoints, cv::Mat& descriptors) const;
  // Patch scale factor of the paper: max(0.2, (3.8 - 0.4 max(2, depth)) / 3).
  static double scaleForDepth(double depth_m);

 private:
  BrandParams params_;
  std::vector<cv::Point2f> pattern_;  // 256 pairs, unit patch size (coordinates in [-0.5, 0.5])
  // The orientation's gradient samples of a patch of radius R (index R), in the order they are summed:
  // their Gaussian weights computed once, not per keypoint (an exp per sample: 13 % of BRAND's CPU).
  struct OrientationTap {
    int dx, dy;
    float weight;
  };
  std::vector<std::vector<OrientationTap>> orientation_taps_;
  static std::vector<OrientationTap> orientationTaps(int R);
  // The patch's canonical orientation (radians) at pixel (kx, ky), patch size S: the direction of its
  // Gaussian-weighted intensity gradients.
  float orientationAt(const cv::Mat& img, int kx, int ky, float S) const;
  // The 256 tests of the patch at (kx, ky), size S, turned by `angle`, into the 32 bytes at d.
  void describe(const cv::Mat& img, const cv::Mat& points, const cv::Mat& normals, int kx, int ky, float S, float angle,
                std::uint8_t* d) const;
};

}  // namespace vofusion
