#include "vofusion/features/brand.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>

#include <mrpt/config/CConfigFileBase.h>

#include "vofusion/core/config.h"
#include <opencv2/imgproc.hpp>

#include "vofusion/core/parallel.h"

namespace vofusion {

namespace {
// Every key of the section, once: loading and saving both walk this list.
std::vector<ConfigKey> brandKeys(BrandParams& p) {
  return {
      {"patch_size", &p.patch_size, "pixels at depth <= 2 m", 8.0, 256.0},
      {"smoothing_sigma", &p.smoothing_sigma, "pixels, Gaussian on intensity (0 = none)", 0.0, 20.0},
      {"normal_angle", &p.normal_angle, "degrees, geometric test threshold", 0.0, 180.0},
      {"normal_window", &p.normal_window, "pixels, half-size of normal boxes", 1.0, 32.0},
      {"max_depth_step", &p.max_depth_step, "m, no normals across larger jumps", 0.001, 10.0},
      {"use_intensity", &p.use_intensity, "intensity tests on/off"},
      {"use_geometry", &p.use_geometry, "normal/convexity tests on/off; on, the odometry's point and normal maps are also the tracking levels (modes joint, paper-handoff, odometry)"},
      {"oriented", &p.oriented, "rotate to canonical orientation"},
  };
}
}  // namespace

void BrandParams::loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& s) {
  loadKeys(cfg, s, brandKeys(*this));
}

void BrandParams::saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& s) const {
  saveKeys(cfg, s, brandKeys(const_cast<BrandParams&>(*this)));
}


BrandExtractor::BrandExtractor(const BrandParams& params) : params_(params) {
  // BRIEF's best sampling (isotropic Gaussian, sigma = S/5) for 256 pairs, fixed seed so every
  // descriptor uses the same tests.
  std::mt19937 rng(0x42a4d);
  std::uniform_real_distribution<double> uni(0.0, 1.0);
  pattern_.reserve(512);
  while (pattern_.size() < 512) {
    const double r = std::sqrt(-2.0 * std::log(std::max(1e-12, uni(rng)))), a = 2 * M_PI * uni(rng);
    const double px = 0.2 * r * std::cos(a), py = 0.2 * r * std::sin(a);
    if (std::abs(px) > 0.5 || std::abs(py) > 0.5) continue;
    pattern_.emplace_back(float(px), float(py));
  }
  // Every patch radius R = max(2, int(S / 2)) there is: S is at most patch_size (the depth scale at most 1).
  const int max_radius = std::max(2, params_.patch_size / 2);
  orientation_taps_.resize(max_radius + 1);
  for (int R = 2; R <= max_radius; ++R) orientation_taps_[R] = orientationTaps(R);
}

std::vector<BrandExtractor::OrientationTap> BrandExtractor::orientationTaps(int R) {
  std::vector<OrientationTap> taps;
  const int step = std::max(1, R / 8);
  const float inv2s2 = 1.f / (2.f * (0.5f * R) * (0.5f * R));
  for (int dy = -R; dy <= R; dy += step)
    for (int dx = -R; dx <= R; dx += step)
      if (dx * dx + dy * dy <= R * R) taps.push_back({dx, dy, std::exp(-(dx * dx + dy * dy) * inv2s2)});
  return taps;
}

double BrandExtractor::scaleForDepth(double d) { return std::max(0.2, (3.8 - 0.4 * std::max(2.0, d)) / 3.0); }

cv::Mat BrandExtractor::smooth(const cv::Mat& gray) const {
  if (!(params_.smoothing_sigma > 0)) return gray;  // 0: the intensity tests read the raw image
  cv::Mat out;
  cv::GaussianBlur(gray, out, cv::Size(0, 0), params_.smoothing_sigma);
  return out;
}

void BrandExtractor::compute(const cv::Mat& gray, const cv::Mat& points, const cv::Mat& normals,
                             std::vector<cv::KeyPoint>& keypoints, cv::Mat& descriptors) const {
  computeSmoothed(smooth(gray), points, normals, keypoints, descriptors);
}

float BrandExtractor::orientationAt(const cv::Mat& img, int kx, int ky, float S) const {
  const int R = std::max(2, int(S * 0.5f));
  double gx = 0, gy = 0;
  const std::size_t stride = img.step;
  for (const OrientationTap& t : orientation_taps_.at(R)) {
    const uint8_t* p = img.ptr<uint8_t>(ky + t.dy) + kx + t.dx;
    gx += t.weight * (int(p[1]) - int(p[-1]));
    gy += t.weight * (int(p[stride]) - int(p[-std::ptrdiff_t(stride)]));
  }
  return float(std::atan2(gy, gx));
}

void BrandExtractor::describe(const cv::Mat& img, const cv::Mat& points, const cv::Mat& normals, int kx, int ky,
                              float S, float angle, std::uint8_t* d) const {
  const float cos_thr = float(std::cos(params_.normal_angle * M_PI / 180.0));
  const float ca = std::cos(angle) * S, sa = std::sin(angle) * S;
  for (int i = 0; i < 256; ++i) {
    const cv::Point2f& a = pattern_[2 * i];
    const cv::Point2f& b = pattern_[2 * i + 1];
    const int ax = kx + cvRound(ca * a.x - sa * a.y), ay = ky + cvRound(sa * a.x + ca * a.y);
    const int bx = kx + cvRound(ca * b.x - sa * b.y), by = ky + cvRound(sa * b.x + ca * b.y);
    bool bit = params_.use_intensity && img.at<uint8_t>(ay, ax) < img.at<uint8_t>(by, bx);
    if (!bit && params_.use_geometry) {
      const cv::Vec3f& na = normals.at<cv::Vec3f>(ay, ax);
      const cv::Vec3f& nb = normals.at<cv::Vec3f>(by, bx);
      if (std::isfinite(na[0]) && std::isfinite(nb[0]) && na.dot(nb) < cos_thr) {
        const cv::Vec3f dp = points.at<cv::Vec3f>(ay, ax) - points.at<cv::Vec3f>(by, bx);
        bit = dp.dot(na - nb) > 0.f;  // convex between the two samples
      }
    }
    if (bit) d[i >> 3] |= uint8_t(1u << (i & 7));
  }
}

void BrandExtractor::computeSmoothed(const cv::Mat& img, const cv::Mat& points, const cv::Mat& normals,
                                     std::vector<cv::KeyPoint>& keypoints, cv::Mat& descriptors) const {
  CV_Assert(img.type() == CV_8UC1 && points.type() == CV_32FC3 && normals.type() == CV_32FC3);
  CV_Assert(points.size() == img.size() && normals.size() == img.size());  // read at the image's pixels
  const int rows = img.rows, cols = img.cols;
  std::vector<cv::KeyPoint> kept(keypoints.size());
  std::vector<char> ok(keypoints.size(), 0);
  cv::Mat desc(int(keypoints.size()), 32, CV_8U, cv::Scalar(0));

  parallelFor(0, int(keypoints.size()), [&](int k) {
    cv::KeyPoint kp = keypoints[k];
    const int kx = cvRound(kp.pt.x), ky = cvRound(kp.pt.y);
    if (kx < 0 || ky < 0 || kx >= cols || ky >= rows) return;
    const float z = points.at<cv::Vec3f>(ky, kx)[2];
    if (!std::isfinite(z)) return;
    const float S = float(params_.patch_size * scaleForDepth(z));
    const float reach = S * 0.5f * 1.4143f + 1.f;  // rotated patch corner
    if (kx - reach < 1 || ky - reach < 1 || kx + reach > cols - 2 || ky + reach > rows - 2) return;
    const float angle = params_.oriented ? orientationAt(img, kx, ky, S) : 0.f;
    describe(img, points, normals, kx, ky, S, angle, desc.ptr<uint8_t>(k));
    kp.angle = float(angle * 180.0 / M_PI);
    if (kp.angle < 0) kp.angle += 360.f;
    kept[k] = kp;
    ok[k] = 1;
  }, 16);
  std::vector<cv::KeyPoint> out;
  cv::Mat out_desc(0, 32, CV_8U);
  out.reserve(keypoints.size());
  for (std::size_t k = 0; k < keypoints.size(); ++k)
    if (ok[k]) {
      out.push_back(kept[k]);
      out_desc.push_back(desc.row(int(k)));
    }
  keypoints.swap(out);
  descriptors = out_desc;
}

}  // namespace vofusion
