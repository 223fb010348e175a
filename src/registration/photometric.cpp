#include "vofusion/registration/photometric.h"

#include <cmath>
#include <limits>

#include <opencv2/imgproc.hpp>

#include "vofusion/core/parallel.h"
#include "vofusion/registration/normal_equations.h"
#include "vofusion/registration/photometric_association.h"

#include "lane_sums.h"

namespace vofusion::fusion {

namespace {

// Levels below this many pixels run on one thread (as ICP's).
constexpr std::size_t kParallelMinPixels = 30000;
constexpr std::size_t kStridedMinPixels = 30000;

IntensityLevel withGradients(cv::Mat grey) {
  IntensityLevel l;
  l.grey = std::move(grey);
  // Sobel / 8: grey levels per pixel, smoothed across the derivative as DVO's and Kintinuous' gradients.
  cv::Sobel(l.grey, l.dx, CV_32F, 1, 0, 3, 1.0 / 8.0, 0, cv::BORDER_REPLICATE);
  cv::Sobel(l.grey, l.dy, CV_32F, 0, 1, 3, 1.0 / 8.0, 0, cv::BORDER_REPLICATE);
  return l;
}

// Bilinear sample of a continuous float image (lane_sums.h's, which the association uses too).
inline float sample(const cv::Mat& m, float x, float y) { return lanes::sample(m.ptr<float>(), m.cols, x, y); }

// An empty image (no colour) gives max_x < 0: every pixel falls outside it.
bool continuousFloats(const cv::Mat& m) { return m.empty() || (m.type() == CV_32F && m.isContinuous()); }

// A level's sums: its rows' (photometric_association.h).
using Sums = PhotometricRowSums;

void addSums(Sums& t, const Sums& s) { t += s; }

}  // namespace

std::vector<IntensityLevel> intensityPyramid(const cv::Mat& bgr, cv::Size size, int levels) {
  std::vector<IntensityLevel> out;
  // 8-bit BGR, BGRA (a camera's with alpha) or grey, as the odometry reads them: the term was dropped
  // without a word for any but BGR.
  const int type = bgr.type();
  if (bgr.empty() || (type != CV_8UC3 && type != CV_8UC4 && type != CV_8UC1) || levels < 1) return out;
  cv::Mat grey8, grey;
  if (type == CV_8UC1) grey8 = bgr;
  else cv::cvtColor(bgr, grey8, type == CV_8UC4 ? cv::COLOR_BGRA2GRAY : cv::COLOR_BGR2GRAY);
  grey8.convertTo(grey, CV_32F);
  if (grey.size() != size) cv::resize(grey, grey, size, 0, 0, cv::INTER_AREA);
  out.push_back(withGradients(grey));
  for (int l = 1; l < levels; ++l) {
    if (out.back().grey.cols < 2 || out.back().grey.rows < 2) break;  // no half of it (a tiny image)
    // An odd last row or column is dropped, as the depth pyramid drops it: INTER_AREA over it would
    // stretch each 2x2 mean (53 rows to 26: a 2.04 scale, half a pixel off at the far edge).
    const cv::Mat& last = out.back().grey;
    const cv::Mat even = last(cv::Rect(0, 0, last.cols / 2 * 2, last.rows / 2 * 2));
    cv::Mat half;
    cv::resize(even, half, cv::Size(even.cols / 2, even.rows / 2), 0, 0, cv::INTER_AREA);
    out.push_back(withGradients(half));
  }
  return out;
}

IntensityLevel resampleAtModel(const IntensityLevel& image, const cv::Mat& model_vertices, const Eigen::Isometry3d& colour_pose,
                               const CameraIntrinsics& camera) {
  CV_Assert(continuousFloats(image.grey) && continuousFloats(image.dx) && continuousFloats(image.dy));
  IntensityLevel out;
  out.grey.create(model_vertices.size(), CV_32F);
  out.dx.create(model_vertices.size(), CV_32F);
  out.dy.create(model_vertices.size(), CV_32F);
  const Eigen::Isometry3f to_cam = colour_pose.inverse().cast<float>();
  const float max_x = image.grey.cols - 1.001f, max_y = image.grey.rows - 1.001f;
  const float nan = std::numeric_limits<float>::quiet_NaN();
  parallelFor(0, model_vertices.rows, [&](int y) {
    const cv::Vec3f* vrow = model_vertices.ptr<cv::Vec3f>(y);
    float* g = out.grey.ptr<float>(y);
    float* gx = out.dx.ptr<float>(y);
    float* gy = out.dy.ptr<float>(y);
    for (int x = 0; x < model_vertices.cols; ++x) {
      g[x] = nan, gx[x] = gy[x] = 0.f;
      const cv::Vec3f& m = vrow[x];
      if (std::isnan(m[0])) continue;
      const Eigen::Vector3f p = to_cam * Eigen::Vector3f(m[0], m[1], m[2]);
      if (!(p.z() > 0.f)) continue;
      const float u = camera.fx * p.x() / p.z() + camera.cx, v = camera.fy * p.y() / p.z() + camera.cy;
      if (!(u >= 0.f && v >= 0.f && u < max_x && v < max_y)) continue;
      g[x] = sample(image.grey, u, v);
      gx[x] = sample(image.dx, u, v);
      gy[x] = sample(image.dy, u, v);
    }
  }, 1, model_vertices.total() >= kParallelMinPixels);
  return out;
}

PhotometricSums accumulatePhotometric(const PhotometricLevel& level, const Eigen::Isometry3d& T,
                                      const PhotometricParams& params, double weight, const Eigen::Isometry3d& colour_motion) {
  PhotometricSums out;
  const cv::Mat& mv = *level.model_vertices;
  if (mv.size() != level.reference->grey.size() || !(params.sigma > 0)) return out;
  const PhotometricAssociator associator(level, T, params, colour_motion);
  // Large levels: every other pixel of every other row, each standing for the four (neighbouring
  // residuals are nearly the same measurement; a quarter of the cost).
  const int stride = mv.total() >= kStridedMinPixels ? 2 : 1;
  const Sums s = parallelReduce(
      0, (mv.rows + stride - 1) / stride, Sums{},
      [&](int row, Sums& acc) {
        acc += associator.sumRow(row * stride, (row & 1) * (stride - 1), stride);
      },
      addSums, 16, mv.total() >= kParallelMinPixels);
  const double inv_sigma = 1.0 / params.sigma;
  s.eq.unpack(inv_sigma * inv_sigma * weight * stride * stride, out.A, out.b);
  out.residuals = s.n;
  out.r2 = s.r2;
  return out;
}

}  // namespace vofusion::fusion
