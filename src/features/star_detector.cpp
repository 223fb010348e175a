#include "vofusion/features/star_detector.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <vector>

#include <mrpt/config/CConfigFileBase.h>

#include "vofusion/core/config.h"
#include <opencv2/imgproc.hpp>

#include "vofusion/core/parallel.h"

namespace vofusion {

namespace {
// Every key of the section, once: loading and saving both walk this list.
std::vector<ConfigKey> starKeys(StarParams& p) {
  return {
      {"max_size", &p.max_size, "largest filter size, pixels (4: only unlocalised scales, nothing found)", 5.0, 128.0},
      {"response_threshold", &p.response_threshold, "minimum |response|, grey levels", 0.0, 100000.0},
      {"line_threshold_projected", &p.line_threshold_projected, "Harris trace^2/det limit (<= 4: every point a line)", 5.0, 1000.0},
      {"line_threshold_binarized", &p.line_threshold_binarized, "same, on the scale map", 5.0, 1000.0},
      {"suppress_nonmax_size", &p.suppress_nonmax_size, "non-max window, pixels", 1.0, 31.0},
      {"subpixel", &p.subpixel, "refine positions to the response peak"},
  };
}
}  // namespace

void StarParams::loadFromConfigFile(const mrpt::config::CConfigFileBase& cfg, const std::string& s) {
  loadKeys(cfg, s, starKeys(*this));
}

void StarParams::saveToConfigFile(mrpt::config::CConfigFileBase& cfg, const std::string& s) const {
  saveKeys(cfg, s, starKeys(const_cast<StarParams&>(*this)));
}

namespace {

// Filter half-sizes n: the upright box is (2n+1)^2, the 45-degree box ("diamond") |dx|+|dy| <= n + n/2.
// Patterns pair an outer and an inner filter (indices into kSizes), as OpenCV's StarDetector.
constexpr int kSizes[] = {1, 2, 3, 4, 6, 8, 11, 12, 16, 22, 23, 32, 45, 46, 64, 90, 128};
constexpr int kPairs[][2] = {{1, 0}, {3, 1}, {4, 2}, {5, 3}, {7, 4}, {8, 5}, {9, 6},
                             {11, 8}, {13, 10}, {14, 11}, {15, 12}, {16, 14}};
constexpr int kNumPairs = sizeof(kPairs) / sizeof(kPairs[0]);
constexpr int kMaxFilters = sizeof(kSizes) / sizeof(kSizes[0]);

// Integral images in 45-degree coordinates u = x + y, v = y - x. With Q(a, b) = sum of pixels having
// u <= a and v <= b, a diamond is Q(box) by inclusion-exclusion. Q(a, b) with a - b even is the
// upward cone with apex pixel (x, y): T(x, y) = Q(x + y, y - x); with a - b odd the apex is a pixel
// pair: F(x, y) = Q(x + y, y - x + 1) (apex pixels x-1 and x of row y). Both are stored padded
// horizontally by `pad` columns and vertically by 2 rows so the recurrences need no special cases.
struct TiltedIntegrals {
  int pad = 0, stride = 0;
  std::unique_ptr<int32_t[]> t, f;  // not zeroed on allocation: computeTilted writes every entry
  const int32_t* T(int x, int y) const { return &t[(y + 2) * stride + x + pad]; }
  const int32_t* F(int x, int y) const { return &f[(y + 2) * stride + x + pad]; }
};

void computeTilted(const cv::Mat& img, TiltedIntegrals& ti) {
  const int rows = img.rows, cols = img.cols;
  ti.pad = rows + 2;
  ti.stride = cols + 2 * ti.pad;
  // Each image row is written whole below (the cones' reach, then copies out to the padding); only
  // the two zero rows above the image are read first. Zeroing all of it (6 MB a 640x480 frame) cost
  // ~0.7 % of the CPU of a run (xyz_first300: user CPU 24.30 -> 24.13 s without it, same output).
  const std::size_t size = std::size_t(rows + 2) * ti.stride;
  ti.t.reset(new int32_t[size]);
  ti.f.reset(new int32_t[size]);
  std::fill_n(ti.t.get(), 2 * ti.stride, 0);
  std::fill_n(ti.f.get(), 2 * ti.stride, 0);
  const int s = ti.stride;
  for (int y = 0; y < rows; ++y) {
    const uint8_t* I = img.ptr<uint8_t>(y);
    const uint8_t* Iup = y > 0 ? img.ptr<uint8_t>(y - 1) : nullptr;
    int32_t* T = &ti.t[(y + 2) * s + ti.pad];
    int32_t* F = &ti.f[(y + 2) * s + ti.pad];
    // The cones reach at most y+1 columns sideways of the image.
    const int x0 = -(y + 2), x1 = cols + y + 1;
    for (int x = x0; x <= x1; ++x) {
      const bool in = x >= 0 && x < cols;
      const int ixy = in ? I[x] : 0;
      const int ixy_up = (in && Iup) ? Iup[x] : 0;
      const int ixm = (x - 1 >= 0 && x - 1 < cols) ? I[x - 1] : 0;
      T[x] = T[x - 1 - s] + T[x + 1 - s] - T[x - 2 * s] + ixy + ixy_up;
      F[x] = F[x - 1 - s] + F[x + 1 - s] - F[x - 2 * s] + ixy + ixm;
    }
    // Beyond the reach, cones hold the whole rows above (constant on each side): extend by copy.
    for (int x = -ti.pad; x < x0; ++x) T[x] = T[x0], F[x] = F[x0];
    for (int x = x1 + 1; x < cols + ti.pad; ++x) T[x] = T[x1], F[x] = F[x1];
  }
}

// The row loops, in two builds chosen when the program loads: AVX2 (8 lanes) where the CPU has it.
// Integer sums and the same float operations (AVX2 brings no FMA): the same responses either way.
// v = one filter's box plus diamond sums along a row, from the 8 integral-image corners.
__attribute__((target_clones("avx2", "default")))
void filterSums(int n, const int32_t* B0, const int32_t* B1, const int32_t* B2, const int32_t* B3, const int32_t* T0,
                const int32_t* T1, const int32_t* F0, const int32_t* F1, int* v) {
  for (int x = 0; x < n; ++x) v[x] = B0[x] - B1[x] - B2[x] + B3[x] + T0[x] + T1[x] - F0[x] - F1[x];
}

// One pattern's response (inner mean minus ring mean) along a row, kept where it is the strongest so far.
__attribute__((target_clones("avx2", "default")))
void keepStronger(int n, const int* vin, const int* vout, float inv_inner, float inv_outer, int tag, float* best,
                  int* best_size) {
  for (int x = 0; x < n; ++x) {
    const int inner = vin[x], outer = vout[x] - inner;
    const float resp = inner * inv_inner - outer * inv_outer;
    const bool better = std::fabs(resp) > std::fabs(best[x]);
    best[x] = better ? resp : best[x];
    best_size[x] = better ? tag : best_size[x];
  }
}

// How many patterns an image takes: the next one while its border leaves a response inside the image
// (responses need rows and cols above twice the border). OpenCV's test (border < min(rows, cols)) took
// patterns whose border left none: an image of 138 px or less on a side gave no keypoint at all (160x120).
int patternsFor(int rows, int cols, int max_size) {
  int npatterns = 0;
  while (npatterns < kNumPairs - 1 && !(kSizes[kPairs[npatterns][0]] >= max_size ||
                                        2 * (kSizes[kPairs[npatterns + 1][0]] + kSizes[kPairs[npatterns + 1][0]] / 2) >=
                                            std::min(rows, cols)))
    ++npatterns;
  return npatterns + 1;  // the pattern that reaches max_size is included
}

// What the row loop needs of the filters and patterns: each filter's size tag, each pattern's inverse
// inner and ring areas.
struct Patterns {
  int count = 0, max_idx = 0;
  int size_tag[kMaxFilters];
  float inv_outer[kNumPairs], inv_inner[kNumPairs];

  explicit Patterns(int npatterns) : count(npatterns), max_idx(kPairs[npatterns - 1][0]) {
    int area[kMaxFilters];
    for (int i = 0; i <= max_idx; ++i) {
      const int n = kSizes[i], t = n + n / 2;
      area[i] = (2 * n + 1) * (2 * n + 1) + t * t + (t + 1) * (t + 1);
      size_tag[i] = n;
    }
    // Scales at the ends of the range are tagged negative: their extrema are not localised in scale.
    size_tag[0] = -size_tag[0];
    size_tag[1] = -size_tag[1];
    size_tag[max_idx] = -size_tag[max_idx];
    for (int p = 0; p < count; ++p) {
      const int inner = area[kPairs[p][1]], outer = area[kPairs[p][0]] - inner;
      inv_outer[p] = 1.f / outer;
      inv_inner[p] = 1.f / inner;
    }
  }
};

// Row y's strongest response in [x0, cols - x0) and its size tag, from the upright and tilted integrals.
void responseRow(const cv::Mat& sum, const TiltedIntegrals& ti, const Patterns& pat, int y, int x0, float* r, short* sz) {
  const int n = sum.cols - 1 - 2 * x0;
  // Whole row at a time, one filter, then one pattern after the other: contiguous loops the
  // compiler vectorises (per pixel over the filters it could not; same sums, same order).
  // The executing thread's buffers, kept from row to row: filterSums writes every value (zeroing
  // them for each row was a quarter of STAR's instructions under callgrind, xyz_first300).
  thread_local std::vector<int> vals, best_size;
  vals.resize(static_cast<std::size_t>(pat.max_idx + 1) * n);
  for (int i = 0; i <= pat.max_idx; ++i) {  // each filter's 8 integral-image corners along the row
    const int k = kSizes[i], t = k + k / 2;
    filterSums(n, sum.ptr<int32_t>(y + k + 1) + k + 1 + x0, sum.ptr<int32_t>(y - k) + k + 1 + x0,
               sum.ptr<int32_t>(y + k + 1) - k + x0, sum.ptr<int32_t>(y - k) - k + x0, ti.T(0, y + t) + x0,
               ti.T(0, y - t - 1) + x0, ti.F(-t, y - 1) + x0, ti.F(t + 1, y - 1) + x0,
               &vals[static_cast<std::size_t>(i) * n]);
  }
  float* best = r + x0;
  best_size.assign(n, 0);
  std::fill(best, best + n, 0.f);
  for (int p = 0; p < pat.count; ++p) {
    const int* vin = &vals[static_cast<std::size_t>(kPairs[p][1]) * n];
    const int* vout = &vals[static_cast<std::size_t>(kPairs[p][0]) * n];
    keepStronger(n, vin, vout, pat.inv_inner[p], pat.inv_outer[p], pat.size_tag[kPairs[p][0]], best, best_size.data());
  }
  for (int x = 0; x < n; ++x) sz[x0 + x] = static_cast<short>(best_size[x]);
}

// Per-pixel strongest response across scales and the (signed, see Patterns) scale that gave it.
int computeResponses(const cv::Mat& img, int max_size, cv::Mat& responses, cv::Mat& sizes) {
  const int rows = img.rows, cols = img.cols;
  const Patterns pat(patternsFor(rows, cols, max_size));
  const int border = kSizes[pat.max_idx] + kSizes[pat.max_idx] / 2;
  responses = cv::Mat::zeros(rows, cols, CV_32F);
  sizes = cv::Mat::zeros(rows, cols, CV_16S);
  if (rows <= 2 * border || cols <= 2 * border) return border;

  cv::Mat sum;
  cv::integral(img, sum, CV_32S);
  TiltedIntegrals ti;
  computeTilted(img, ti);
  parallelFor(border, rows - border,
              [&](int y) { responseRow(sum, ti, pat, y, border, responses.ptr<float>(y), sizes.ptr<short>(y)); });
  return border;
}

// Scale-adapted Harris test on the response map and on the binarised scale map: a line (edge)
// has one dominant gradient direction, i.e. a large trace^2/det.
bool isLineLike(const cv::Mat& responses, const cv::Mat& sizes, cv::Point pt, int thr_projected, int thr_binarized) {
  const int sz = sizes.at<short>(pt);
  const int delta = sz / 4, radius = delta * 4;
  float lxx = 0, lyy = 0, lxy = 0;
  for (int y = pt.y - radius; y <= pt.y + radius; y += delta) {
    const float* r = responses.ptr<float>(y);
    const float* ru = responses.ptr<float>(y - 1);
    const float* rd = responses.ptr<float>(y + 1);
    for (int x = pt.x - radius; x <= pt.x + radius; x += delta) {
      const float lx = r[x + 1] - r[x - 1], ly = rd[x] - ru[x];
      lxx += lx * lx; lyy += ly * ly; lxy += lx * ly;
    }
  }
  if ((lxx + lyy) * (lxx + lyy) >= thr_projected * (lxx * lyy - lxy * lxy)) return true;
  int bxx = 0, byy = 0, bxy = 0;
  for (int y = pt.y - radius; y <= pt.y + radius; y += delta) {
    const short* s = sizes.ptr<short>(y);
    const short* su = sizes.ptr<short>(y - 1);
    const short* sd = sizes.ptr<short>(y + 1);
    for (int x = pt.x - radius; x <= pt.x + radius; x += delta) {
      const int lx = (s[x + 1] == sz) - (s[x - 1] == sz), ly = (sd[x] == sz) - (su[x] == sz);
      bxx += lx * lx; byy += ly * ly; bxy += lx * ly;
    }
  }
  return (bxx + byy) * (bxx + byy) >= thr_binarized * (bxx * byy - bxy * bxy);
}

// Is `pt` the strict extremum (max if sign>0, min if sign<0) of its (2d+1)^2 neighbourhood?
bool isExtremum(const cv::Mat& responses, cv::Point pt, int d, float value, int sign) {
  for (int y = pt.y - d; y <= pt.y + d; ++y) {
    const float* r = responses.ptr<float>(y);
    for (int x = pt.x - d; x <= pt.x + d; ++x) {
      if (x == pt.x && y == pt.y) continue;
      if (sign > 0 ? r[x] >= value : r[x] <= value) return false;
    }
  }
  return true;
}

// Sub-pixel position of a response extremum: the vertex of the parabola through it and its two
// neighbours, along x and along y (the extremum is strict, so the offset is within half a pixel).
cv::Point2f refinePeak(const cv::Mat& responses, cv::Point pt) {
  auto offset = [](float a, float b, float c) {
    const float curv = a - 2.f * b + c;
    return curv != 0.f ? std::clamp(0.5f * (a - c) / curv, -0.5f, 0.5f) : 0.f;
  };
  const float* r = responses.ptr<float>(pt.y);
  const float dx = offset(r[pt.x - 1], r[pt.x], r[pt.x + 1]);
  const float dy = offset(responses.at<float>(pt.y - 1, pt.x), r[pt.x], responses.at<float>(pt.y + 1, pt.x));
  return {pt.x + dx, pt.y + dy};
}

}  // namespace

std::vector<cv::KeyPoint> detectStar(const cv::Mat& gray, const StarParams& p) {
  CV_Assert(gray.type() == CV_8UC1);
  cv::Mat responses, sizes;
  const int d = p.suppress_nonmax_size / 2;
  // The non-maximum window reaches d pixels around a candidate: keep it inside the image too.
  const int border = std::max(computeResponses(gray, p.max_size, responses, sizes), d);
  const int rows = gray.rows, cols = gray.cols;

  // Tiles of (d+1)^2 pixels: each proposes its strongest positive and negative response, kept if
  // it is the extremum of the (2d+1)^2 window around it, at an interior scale and not line-like.
  std::vector<std::vector<cv::KeyPoint>> per_row(std::max(0, rows));
  const int tile = d + 1, tile_rows = std::max(0, (rows - 2 * border + d) / tile);
  parallelFor(0, tile_rows, [&](int ty) {
    const int y = border + ty * tile;
    auto& out = per_row[y];
    for (int x = border; x < cols - border; x += d + 1) {
      float max_r = float(p.response_threshold), min_r = -float(p.response_threshold);
      cv::Point max_pt(-1, -1), min_pt(-1, -1);
      const int ye = std::min(y + d, rows - border - 1), xe = std::min(x + d, cols - border - 1);
      for (int y1 = y; y1 <= ye; ++y1) {
        const float* r = responses.ptr<float>(y1);
        for (int x1 = x; x1 <= xe; ++x1) {
          if (r[x1] > max_r) max_r = r[x1], max_pt = {x1, y1};
          else if (r[x1] < min_r) min_r = r[x1], min_pt = {x1, y1};
        }
      }
      for (int sign : {1, -1}) {
        const cv::Point pt = sign > 0 ? max_pt : min_pt;
        const float val = sign > 0 ? max_r : min_r;
        if (pt.x < 0 || !isExtremum(responses, pt, d, val, sign)) continue;
        const int size = sizes.at<short>(pt);
        if (size < 4) continue;
        if (isLineLike(responses, sizes, pt, p.line_threshold_projected, p.line_threshold_binarized)) continue;
        out.emplace_back(float(pt.x), float(pt.y), float(size), -1.f, val);
      }
    }
  }, 4);
  std::vector<cv::KeyPoint> keypoints;
  for (auto& r : per_row) keypoints.insert(keypoints.end(), r.begin(), r.end());
  if (p.subpixel)
    for (auto& k : keypoints) k.pt = refinePeak(responses, cv::Point(cvRound(k.pt.x), cvRound(k.pt.y)));
  return keypoints;
}

}  // namespace vofusion
