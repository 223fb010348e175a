#include "vofusion/registration/preprocess.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <vector>

#include <immintrin.h>

#include <opencv2/imgproc.hpp>

#include "vofusion/core/cpu_features.h"
#include "vofusion/core/parallel.h"
#include "vofusion/registration/projective_icp.h"

namespace vofusion::fusion {

namespace {
const float kNaN = std::numeric_limits<float>::quiet_NaN();
// Below this many pixels a loop runs on one thread: at tracking resolution (320x240) the loops take
// well under a millisecond each, about what handing rows to the pool costs on a loaded machine.
constexpr std::size_t kParallelMinPixels = 100000;
}

cv::Mat clipDepth(const cv::Mat& depth, float min_depth, float max_depth) {
  CV_Assert(depth.type() == CV_32FC1);
  cv::Mat out(depth.size(), CV_32FC1);
  parallelFor(0, depth.rows, [&](int y) {
    const float* s = depth.ptr<float>(y);
    float* d = out.ptr<float>(y);
    for (int x = 0; x < depth.cols; ++x) {
      const float z = s[x];
      d[x] = (z >= min_depth && z <= max_depth) ? z : 0.f;  // NaN fails both tests
    }
  }, 1, depth.total() >= kParallelMinPixels);
  return out;
}

namespace {

// The bilateral filter's weights: a round window's offsets with their spatial weights, and the range
// weight by |dz| in steps of sigma/64 up to 4 sigma (beyond: e^-8, left out).
struct BilateralWeights {
  static constexpr int kBins = 256;
  int r = 1;
  std::vector<cv::Point> offsets;
  std::vector<float> spatial;
  float inv_bin = 0.f;
  float range[kBins + 1];

  BilateralWeights(float sigma_depth, float sigma_spatial, int kernel) : r(std::max(1, kernel / 2)) {
    for (int dy = -r; dy <= r; ++dy)
      for (int dx = -r; dx <= r; ++dx)
        if (dx * dx + dy * dy <= r * r) {
          offsets.emplace_back(dx, dy);
          spatial.push_back(std::exp(-(dx * dx + dy * dy) / (2.f * sigma_spatial * sigma_spatial)));
        }
    const float bin = 4.f * sigma_depth / kBins;
    inv_bin = 1.f / bin;
    for (int i = 0; i <= kBins; ++i) range[i] = std::exp(-0.5f * (i * bin) * (i * bin) / (sigma_depth * sigma_depth));
  }
};

// One pixel; (x, y) near the border reads the border replicated.
float bilateralPixel(const cv::Mat& depth, const BilateralWeights& W, int x, int y, bool inner) {
  const float zc = depth.ptr<float>(y)[x];
  if (!(zc > 0.f)) return 0.f;
  float sum = 0.f, wsum = 0.f;
  for (std::size_t k = 0; k < W.offsets.size(); ++k) {
    int xx = x + W.offsets[k].x, yy = y + W.offsets[k].y;
    if (!inner) {
      xx = std::clamp(xx, 0, depth.cols - 1);
      yy = std::clamp(yy, 0, depth.rows - 1);
    }
    const float z = depth.ptr<float>(yy)[xx];
    if (!(z > 0.f)) continue;
    const float t = std::fabs(z - zc) * W.inv_bin;
    if (!(t < BilateralWeights::kBins)) continue;
    const int i = static_cast<int>(t);
    const float wr = W.range[i] + (t - i) * (W.range[i + 1] - W.range[i]);
    const float wk = W.spatial[k] * wr;
    sum += wk * z;
    wsum += wk;
  }
  return sum / wsum;  // the centre itself has weight 1
}

// Eight pixels of a row's inside at once, each lane the scalar pixel's steps in the same order, so the
// result is the same bytes (no FMA here, and this file is built with -ffp-contract=off so that a
// -march=native build does not fuse the scalar loop's products either). `at` points at the first pixel, `step` is
// the row stride in floats.
__attribute__((target("avx2"))) void bilateralEightAvx2(const float* at, std::ptrdiff_t step, const BilateralWeights& W,
                                                        float* out) {
  const __m256 zc = _mm256_loadu_ps(at), zero = _mm256_setzero_ps();
  const __m256 centre_ok = _mm256_cmp_ps(zc, zero, _CMP_GT_OQ);
  if (_mm256_movemask_ps(centre_ok) == 0) {
    _mm256_storeu_ps(out, zero);
    return;
  }
  const __m256 inv_bin = _mm256_set1_ps(W.inv_bin), bins = _mm256_set1_ps(float(BilateralWeights::kBins));
  const __m256 abs_mask = _mm256_castsi256_ps(_mm256_set1_epi32(0x7fffffff));
  __m256 sum = zero, wsum = zero;
  for (std::size_t k = 0; k < W.offsets.size(); ++k) {
    const __m256 z = _mm256_loadu_ps(at + W.offsets[k].y * step + W.offsets[k].x);
    const __m256 t = _mm256_mul_ps(_mm256_and_ps(_mm256_sub_ps(z, zc), abs_mask), inv_bin);
    const __m256 ok = _mm256_and_ps(_mm256_cmp_ps(z, zero, _CMP_GT_OQ), _mm256_cmp_ps(t, bins, _CMP_LT_OQ));
    if (_mm256_movemask_ps(ok) == 0) continue;
    // Lanes left out hold any index: point them at bin 0 so every gather stays inside the table.
    const __m256i i = _mm256_and_si256(_mm256_cvttps_epi32(t), _mm256_castps_si256(ok));
    const __m256 r0 = _mm256_i32gather_ps(W.range, i, 4), r1 = _mm256_i32gather_ps(W.range + 1, i, 4);
    const __m256 wr = _mm256_add_ps(r0, _mm256_mul_ps(_mm256_sub_ps(t, _mm256_cvtepi32_ps(i)), _mm256_sub_ps(r1, r0)));
    const __m256 wk = _mm256_mul_ps(_mm256_set1_ps(W.spatial[k]), wr);
    sum = _mm256_blendv_ps(sum, _mm256_add_ps(sum, _mm256_mul_ps(wk, z)), ok);
    wsum = _mm256_blendv_ps(wsum, _mm256_add_ps(wsum, wk), ok);
  }
  _mm256_storeu_ps(out, _mm256_and_ps(_mm256_div_ps(sum, wsum), centre_ok));
}

}  // namespace

cv::Mat bilateralFilterDepth(const cv::Mat& depth, float sigma_depth, float sigma_spatial, int kernel, bool simd) {
  CV_Assert(depth.type() == CV_32FC1);
  // By hand rather than cv::bilateralFilter, which would weigh invalid (0) readings in (and, when our
  // loops were OpenMP, fought them for the 2 cores: 134 vs 22 ms). Same weights: Gaussian in image distance (round window)
  // and in depth difference (table), invalid neighbours left out, invalid pixels stay 0.
  const BilateralWeights W(sigma_depth, sigma_spatial, kernel);
  const int w = depth.cols, h = depth.rows, r = W.r;
  const bool avx2 = simd && cpuHasAvx2();
  const std::ptrdiff_t step = static_cast<std::ptrdiff_t>(depth.step1());
  cv::Mat out(depth.size(), CV_32FC1);
  parallelFor(0, h, [&](int y) {
    float* d = out.ptr<float>(y);
    const bool inner_y = y >= r && y < h - r;
    int x = 0;
    const auto scalarUpTo = [&](int end) {
      for (; x < end; ++x) d[x] = bilateralPixel(depth, W, x, y, inner_y && x >= r && x < w - r);
    };
    if (avx2 && inner_y) {
      scalarUpTo(std::min(r, w));
      for (; x + 8 <= w - r; x += 8) bilateralEightAvx2(depth.ptr<float>(y) + x, step, W, d + x);
    }
    scalarUpTo(w);
  }, 1, depth.total() >= kParallelMinPixels);
  return out;
}

cv::Mat downsampleDepth(const cv::Mat& depth, float sigma_depth) {
  const int w = depth.cols / 2, h = depth.rows / 2;
  cv::Mat out(h, w, CV_32FC1);
  const float band = 3.f * sigma_depth;
  parallelFor(0, h, [&](int y) {
    const float* r0 = depth.ptr<float>(2 * y);
    const float* r1 = depth.ptr<float>(2 * y + 1);
    float* d = out.ptr<float>(y);
    for (int x = 0; x < w; ++x) {
      const float v[4] = {r0[2 * x], r0[2 * x + 1], r1[2 * x], r1[2 * x + 1]};
      float nearest = std::numeric_limits<float>::max();
      for (float z : v)
        if (z > 0.f && z < nearest) nearest = z;
      float sum = 0.f;
      int n = 0;
      for (float z : v)
        if (z > 0.f && z - nearest <= band) sum += z, ++n;
      d[x] = n ? sum / n : 0.f;
    }
  }, 1, depth.total() >= kParallelMinPixels);
  return out;
}

cv::Mat depthToVertices(const cv::Mat& depth, const CameraIntrinsics& cam) {
  cv::Mat out(depth.size(), CV_32FC3);
  const float ifx = 1.f / cam.fx, ify = 1.f / cam.fy, cx = cam.cx, cy = cam.cy;
  parallelFor(0, depth.rows, [&](int y) {
    const float* s = depth.ptr<float>(y);
    cv::Vec3f* d = out.ptr<cv::Vec3f>(y);
    const float ry = (y - cy) * ify;
    for (int x = 0; x < depth.cols; ++x) {
      const float z = s[x];
      d[x] = z > 0.f ? cv::Vec3f((x - cx) * ifx * z, ry * z, z) : cv::Vec3f(kNaN, kNaN, kNaN);
    }
  }, 1, depth.total() >= kParallelMinPixels);
  return out;
}

cv::Mat verticesToNormals(const cv::Mat& vertices, float max_jump) {
  cv::Mat out(vertices.size(), CV_32FC3, cv::Scalar::all(kNaN));
  const int w = vertices.cols, h = vertices.rows;
  parallelFor(1, h - 1, [&](int y) {
    const cv::Vec3f* up = vertices.ptr<cv::Vec3f>(y - 1);
    const cv::Vec3f* row = vertices.ptr<cv::Vec3f>(y);
    const cv::Vec3f* down = vertices.ptr<cv::Vec3f>(y + 1);
    cv::Vec3f* d = out.ptr<cv::Vec3f>(y);
    for (int x = 1; x < w - 1; ++x) {
      const cv::Vec3f& c = row[x];
      const cv::Vec3f &l = row[x - 1], &r = row[x + 1], &u = up[x], &b = down[x];
      if (std::isnan(c[0]) || std::isnan(l[0]) || std::isnan(r[0]) || std::isnan(u[0]) || std::isnan(b[0]))
        continue;
      const float jump = max_jump * c[2];
      if (std::fabs(l[2] - c[2]) > jump || std::fabs(r[2] - c[2]) > jump || std::fabs(u[2] - c[2]) > jump ||
          std::fabs(b[2] - c[2]) > jump)
        continue;
      cv::Vec3f n = (r - l).cross(b - u);
      const float len = std::sqrt(n.dot(n));
      if (!(len > 0.f)) continue;
      n *= 1.f / len;
      if (n.dot(c) > 0.f) n = -n;  // face the camera
      d[x] = n;
    }
  }, 1, vertices.total() >= kParallelMinPixels);
  return out;
}

std::vector<DepthLevel> preprocessDepth(const cv::Mat& depth, const CameraIntrinsics& cam,
                                        const PreprocessParams& p) {
  std::vector<DepthLevel> levels(std::max(1, p.levels));
  const cv::Mat clipped = clipDepth(depth, p.min_depth, p.max_depth);
  levels[0].depth = p.kernel > 1 ? bilateralFilterDepth(clipped, p.sigma_depth, p.sigma_spatial, p.kernel) : clipped;
  levels[0].camera = cam;
  levels[0].camera.width = depth.cols;
  levels[0].camera.height = depth.rows;
  for (std::size_t l = 1; l < levels.size(); ++l) {
    levels[l].depth = downsampleDepth(levels[l - 1].depth, p.sigma_depth);
    levels[l].camera = levels[l - 1].camera.scaled(0.5);
    levels[l].camera.width = levels[l].depth.cols;  // an odd row or column is dropped, not rounded up
    levels[l].camera.height = levels[l].depth.rows;
  }
  for (auto& lv : levels) {
    lv.vertices = depthToVertices(lv.depth, lv.camera);
    lv.normals = verticesToNormals(lv.vertices, p.max_normal_jump);
  }
  return levels;
}

std::vector<DepthLevel> levelsFromGeometry(const FrameGeometry& g, const cv::Mat& depth, const CameraIntrinsics& cam,
                                           int downsample, const PreprocessParams& p) {
  std::vector<DepthLevel> levels(std::max(1, p.levels));
  cv::Mat clipped = clipDepth(depth, p.min_depth, p.max_depth), vertices = g.points, normals = g.normals;
  CameraIntrinsics c = cam;
  c.width = depth.cols;
  c.height = depth.rows;
  for (int k = 1; k < downsample; ++k) {
    clipped = downsampleDepth(clipped, p.sigma_depth);
    cv::Mat v, n;
    downsampleMaps(vertices, normals, v, n);
    vertices = v, normals = n;
    c = c.scaled(0.5);
  }
  for (std::size_t l = 0; l < levels.size(); ++l) {
    if (l > 0) {
      clipped = downsampleDepth(clipped, p.sigma_depth);
      cv::Mat v, n;
      downsampleMaps(levels[l - 1].vertices, levels[l - 1].normals, v, n);
      vertices = v, normals = n;
      c = c.scaled(0.5);
    } else {
      vertices = vertices.clone(), normals = normals.clone();  // the shared maps stay as they are
    }
    // Only readings the tracker uses (the same depth range as preprocessDepth's clip).
    parallelFor(0, vertices.rows, [&](int y) {
      cv::Vec3f* v = vertices.ptr<cv::Vec3f>(y);
      cv::Vec3f* n = normals.ptr<cv::Vec3f>(y);
      for (int x = 0; x < vertices.cols; ++x)
        if (!(v[x][2] >= p.min_depth && v[x][2] <= p.max_depth)) v[x] = n[x] = cv::Vec3f(kNaN, kNaN, kNaN);
    }, 1, vertices.total() >= kParallelMinPixels);
    c.width = clipped.cols;  // an odd row or column is dropped by each halving, not rounded up
    c.height = clipped.rows;
    levels[l] = {clipped, vertices, normals, c};
  }
  return levels;
}

}  // namespace vofusion::fusion
