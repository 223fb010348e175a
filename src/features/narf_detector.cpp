// PCL before any MRPT header: MRPT's headers hide PCL's RAD2DEG macro.
#include <algorithm>
#include <numeric>

#include <pcl/features/range_image_border_extractor.h>
#include <pcl/keypoints/narf_keypoint.h>
#include <pcl/range_image/range_image_planar.h>
#include <mrpt/config/CConfigFileBase.h>

#include "vofusion/core/config.h"
#include "vofusion/core/errors.h"

#include "vofusion/features/narf_detector.h"
#include "vofusion/features/narf_fast.h"

namespace vofusion {

namespace {
// Every key of the section, once: loading and saving both walk this list.
std::vector<ConfigKey> narfKeys(NarfParams& p) {
  return {
      {"support_size", &p.support_size, "m, area covered by a keypoint", 0.01, 10.0},
      {"downsample", &p.downsample, "factor on the depth image (1 = full res)", 1.0, 20.0},
      {"max_points", &p.max_points, "strongest kept, 0 = all", 0.0, 100000.0},
      {"min_interest_value", &p.min_interest_value, "[0,1]", 0.0, 1.0},
      {"threads", &p.threads, "OpenMP threads of PCL's border extraction (implementation pcl)", 1.0, 64.0},
      ConfigKey::oneOf("implementation", &p.implementation, "fast = PCL's steps on flat arrays; pcl = pcl::NarfKeypoint",
                       {"fast", "pcl"}),
  };
}
}  // namespace

void NarfParams::loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& s) {
  loadKeys(cfg, s, narfKeys(*this));
  downsample = std::max(1, downsample);
  threads = std::max(1, threads);
  if (!(support_size > 0.0)) throw InputError("[" + s + "] support_size", "must be positive");
}

void NarfParams::saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& s) const {
  saveKeys(cfg, s, narfKeys(const_cast<NarfParams&>(*this)));
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

namespace {
// The reference: pcl::NarfKeypoint with pcl::RangeImageBorderExtractor on a RangeImagePlanar.
std::vector<int> pclInterestPoints(const cv::Mat& d, const CameraIntrinsics& cam, const NarfParams& p,
                                   std::vector<float>& interest) {
  pcl::RangeImagePlanar range;
  range.setDepthImage(d.ptr<float>(), d.cols, d.rows, float(cam.cx), float(cam.cy), float(cam.fx), float(cam.fy));
  range.setUnseenToMaxRange();

  pcl::RangeImageBorderExtractor border;
  pcl::NarfKeypoint narf(&border);
  narf.setRangeImage(&range);
  // Border descriptions and surface changes are per-pixel results: computed here on `threads`
  // threads (PCL caches them). The interest search that follows runs on one thread: PCL's sparse
  // interest image lets each seed pixel write its neighbours' interest values and skips pixels already
  // written, so with more threads which seed computes a pixel (from its own neighbourhood) depends on
  // the threads' interleaving, and the keypoints vary run to run (about one fr1_xyz frame in ten).
  border.getParameters().max_no_of_threads = p.threads;
  border.getBorderDescriptions();
  border.getSurfaceChangeScores();
  auto& np = narf.getParameters();
  np.support_size = float(p.support_size);
  np.min_interest_value = float(p.min_interest_value);
  np.max_no_of_threads = 1;
  np.use_recursive_scale_reduction = false;  // PCL 1.13 ignores it with the sparse interest image it uses
  np.max_no_of_interest_points = p.max_points > 0 ? p.max_points : -1;
  pcl::PointCloud<int> indices;
  narf.compute(indices);
  const float* image = narf.getInterestImage();
  if (image)
    interest.assign(image, image + d.total());
  else
    interest.assign(d.total(), 1.0f);
  return {indices.points.begin(), indices.points.end()};
}
}  // namespace

NarfPrepared prepareNarf(const cv::Mat& depth, const CameraIntrinsics& camera, const NarfParams& p) {
  NarfPrepared out;
  const int f = std::max(1, p.downsample);
  const cv::Mat small = downsampleDepth(depth, f);
  out.params = p;
  out.camera = camera;
  out.reduced_camera = f > 1 ? camera.scaled(1.0 / f) : camera;
  out.reduced_camera.width = small.cols;  // whole blocks only: a partial last one is dropped, not rounded up
  out.reduced_camera.height = small.rows;
  out.reduced = small.isContinuous() ? small : small.clone();
  if (p.implementation == "fast") {
    out.range.emplace(out.reduced, out.reduced_camera);
    out.borders = narf::extractBorders(*out.range);
  }
  return out;
}

std::vector<cv::KeyPoint> detectNarf(const NarfPrepared& prep) {
  const NarfParams& p = prep.params;
  const cv::Mat& d = prep.reduced;  // read only: the prepared input may be searched again
  std::vector<float> interest;
  std::vector<int> indices;
  if (prep.range) {
    const narf::KeypointParams kp{float(p.support_size), float(p.min_interest_value), p.max_points};
    indices = narf::interestPoints(*prep.range, prep.borders, kp, interest);
  } else {
    indices = pclInterestPoints(d, prep.reduced_camera, p, interest);
  }

  std::vector<cv::KeyPoint> out;
  out.reserve(indices.size());
  const float scale = float(std::max(1, p.downsample));
  for (int idx : indices) {
    const int x = idx % d.cols, y = idx / d.cols;
    const float z = d.at<float>(y, x);
    if (!(z > 0.f)) continue;
    // Back to full-resolution pixel centres: the block's centre. At the pixel of the block's reading
    // (where BRAND would find the keypoint's own depth) shake and rpy came out worse:
    // bench/results/2026-12-05-narf-keypoint-pixel.md.
    const float u = (x + 0.5f) * scale - 0.5f, v = (y + 0.5f) * scale - 0.5f;
    const float size_px = float(p.support_size * prep.camera.fx / z);
    out.emplace_back(u, v, size_px, -1.f, interest[idx], 0, 1 /*class: NARF*/);
  }
  return out;
}

std::vector<cv::KeyPoint> detectNarf(const cv::Mat& depth, const CameraIntrinsics& camera, const NarfParams& p) {
  return detectNarf(prepareNarf(depth, camera, p));
}

float narfBlockDepth(const cv::Mat& depth, cv::Point2f centre, int factor) {
  // The block's first pixel is (factor - 1) / 2 before its centre: for an even factor the centre falls
  // between pixels, and the window about the rounded centre (half to even) took a row and a column of a
  // neighbouring block: the next one's for 4 and 8, the previous one's for 2 and 6 (across a depth
  // border, a nearer surface's reading).
  const int x0 = cvRound(centre.x - 0.5f * float(factor - 1)), y0 = cvRound(centre.y - 0.5f * float(factor - 1));
  float nearest = 0.f;
  for (int y = std::max(0, y0); y < std::min(depth.rows, y0 + factor); ++y) {
    const float* d = depth.ptr<float>(y);
    for (int x = std::max(0, x0); x < std::min(depth.cols, x0 + factor); ++x)
      if (d[x] > 0.f && (nearest == 0.f || d[x] < nearest)) nearest = d[x];
  }
  return nearest;
}

}  // namespace vofusion
