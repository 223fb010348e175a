#pragma once
// STAR / CenSurE keypoints (Agrawal, Konolige & Blas, ECCV 2008), behaving as OpenCV's
// xfeatures2d::StarDetector: bi-level "star" filters (upright box + 45-degree box, both from
// integral images) at 9 scales, the strongest |response| across scale kept per pixel, non-maximum
// suppression over position, and line-like responses rejected with a scale-adapted Harris test.
#include <string>
#include <vector>

#include <mrpt/config/CLoadableOptions.h>
#include <opencv2/core.hpp>

namespace vofusion {

struct StarParams : public mrpt::config::CLoadableOptions {
  int max_size = 45;                  // pixels; largest filter size (OpenCV: 4..128)
  int response_threshold = 30;        // grey levels; minimum |filter response|
  int line_threshold_projected = 10;  // ratio; Harris trace^2/det limit on the responses
  int line_threshold_binarized = 8;   // ratio; the same on the binarised scale map
  int suppress_nonmax_size = 5;       // pixels; non-maximum suppression window
  bool subpixel = true;               // positions refined to the parabola vertex of the response peak

  void loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& section) override;
  void saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& section) const override;
};

// gray: CV_8UC1. Keypoint size = the scale (outer filter size), response = filter response.
std::vector<cv::KeyPoint> detectStar(const cv::Mat& gray, const StarParams& params = {});

}  // namespace vofusion
