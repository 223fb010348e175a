// PCL before any MRPT header: MRPT's headers hide PCL's RAD2DEG macro.
#include <algorithm>
#include <numeric>

#include <pcl/features/range_image_border_extractor.h>
#include <pcl/keypoints/narf_keypoint.h>
#include <pcl/range_image/range_image_planar.h>
#include <mrpt/config/CConfigFileBase.h>

#include "vofusion/features/narf_detector.h"

namespace vofusion {

void NarfParams::loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& s) {
  support_size = cfg.read_double(s, "support_size", support_size);
  downsample = std::max(1, cfg.read_int(s, "downsample", downsample));
  max_points = cfg.read_int(s, "max_points", max_points);
  min_interest_value = cfg.read_double(s, "min_interest_value", min_interest_value);
  threads = std::max(1, cfg.read_int(s, "threads", threads));
  recursive_scale_reduction = cfg.read_bool(s, "recursive_scale_reduction", recursive_scale_reduction);
}

void NarfParams::saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& s) const {
  cfg.write(s, "support_size", support_size, -1, -1, "m, area covered by a keypoint");
  cfg.write(s, "downsample", downsample, -1, -1, "factor on the depth image (1 = full res)");
  cfg.write(s, "max_points", max_points, -1, -1, "strongest kept, 0 = all");
  cfg.write(s, "min_interest_value", min_interest_value, -1, -1, "[0,1]");
  cfg.write(s, "threads", threads, -1, -1, "OpenMP threads inside PCL's NARF");
  cfg.write(s, "recursive_scale_reduction", recursive_scale_reduction, -1, -1, "PCL speed-up on near surfaces");
}

cv::Mat downsampleDepth(const cv::Mat& depth, int factor) {
  CV_Assert(depth.type() == CV_32FC1);
  if (factor <= 1) return depth;
  cv::Mat out(depth.rows / factor, depth.cols / factor, CV_32F);
  for (int y = 0; y < out.rows; ++y)
    for (int x = 0; x < out.cols; ++x) {
      float best = 0.f;
      for (int dy = 0; dy < factor; ++dy) {
        const float* d = depth.ptr<float>(y * factor + dy) + x * factor;
        for (int dx = 0; dx < factor; ++dx)
          if (d[dx] > 0.f && (best == 0.f || d[dx] < best)) best = d[dx];
      }
      out.at<float>(y, x) = best;
    }
  return out;
}

std::vector<cv::KeyPoint> detectNarf(const cv::Mat& depth, const CameraIntrinsics& camera, const NarfParams& p) {
  const int f = std::max(1, p.downsample);
  const cv::Mat small = downsampleDepth(depth, f);
  const CameraIntrinsics cam = f > 1 ? camera.scaled(1.0 / f) : camera;
  cv::Mat d = small.isContinuous() ? small : small.clone();

  pcl::RangeImagePlanar range;
  range.setDepthImage(d.ptr<float>(), d.cols, d.rows, float(cam.cx), float(cam.cy), float(cam.fx), float(cam.fy));
  range.setUnseenToMaxRange();

  pcl::RangeImageBorderExtractor border;
  border.getParameters().max_no_of_threads = p.threads;
  pcl::NarfKeypoint narf(&border);
  narf.setRangeImage(&range);
  auto& np = narf.getParameters();
  np.support_size = float(p.support_size);
  np.min_interest_value = float(p.min_interest_value);
  np.max_no_of_threads = p.threads;
  np.use_recursive_scale_reduction = p.recursive_scale_reduction;
  np.max_no_of_interest_points = p.max_points > 0 ? p.max_points : -1;
  pcl::PointCloud<int> indices;
  narf.compute(indices);

  const float* interest = narf.getInterestImage();
  std::vector<cv::KeyPoint> out;
  out.reserve(indices.size());
  const float scale = float(f);
  for (int idx : indices.points) {
    const int x = idx % int(range.width), y = idx / int(range.width);
    const float z = d.at<float>(y, x);
    if (!(z > 0.f)) continue;
    // Back to full-resolution pixel centres.
    const float u = (x + 0.5f) * scale - 0.5f, v = (y + 0.5f) * scale - 0.5f;
    const float size_px = float(p.support_size * camera.fx / z);
    out.emplace_back(u, v, size_px, -1.f, interest ? interest[idx] : 1.f, 0, 1 /*class: NARF*/);
  }
  return out;
}

}  // namespace vofusion
