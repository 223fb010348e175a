#include "vofusion/registration/photometric_association.h"

#include <cmath>
#include <immintrin.h>

#include "vofusion/core/cpu_features.h"

#include "lane_sums.h"

namespace vofusion::fusion {

namespace {

using Setup = PhotometricAssociator::Setup;

// Per-lane float sums of one row: the 21 entries of J^T W J, the 6 of -J^T W r, then r^2.
constexpr int kEntries = 28;
constexpr int kB = 21, kR2 = 27;

struct LaneSums : lanes::LaneSums<kEntries> {
  int n = 0;
};

// The reference row's inputs.
struct RefRow {
  const float *grey, *dx, *dy, *vertices;
};

using lanes::dot3;
using lanes::sample;
using lanes::storeRowMajor;

void pixelScalar(const Setup& s, const RefRow& ref, int x, int lane, LaneSums& L) {
  const float gxr = ref.dx[x], gyr = ref.dy[x];
  if (gxr * gxr + gyr * gyr < s.g2 || std::isnan(ref.grey[x])) return;
  const float* m = ref.vertices + 3 * x;
  if (std::isnan(m[0])) return;
  const float ax = m[0] - s.c[0], ay = m[1] - s.c[1], az = m[2] - s.c[2];  // model point about the camera centre
  const float qx = dot3(s.Rt, ax, ay, az), qy = dot3(s.Rt + 3, ax, ay, az), qz = dot3(s.Rt + 6, ax, ay, az);
  const float px = dot3(s.M, qx, qy, qz) + s.Mt[0], py = dot3(s.M + 3, qx, qy, qz) + s.Mt[1],
              pz = dot3(s.M + 6, qx, qy, qz) + s.Mt[2];  // in the current colour camera
  if (!(pz > 0.f)) return;
  const float iz = 1.f / pz;
  const float u = (s.fx * px) * iz + s.cx, v = (s.fy * py) * iz + s.cy;
  if (!(u >= 0.f && v >= 0.f && u < s.max_x && v < s.max_y)) return;
  const float r = sample(s.cur_grey, s.cur_cols, u, v) - ref.grey[x];
  const float fgx = sample(s.cur_dx, s.cur_cols, u, v) * s.fx, fgy = sample(s.cur_dy, s.cur_cols, u, v) * s.fy;
  // d r / d p (current camera) = grad^T d pi / d p, then to the world frame.
  const float dp0 = fgx * iz, dp1 = fgy * iz, dp2 = (-(fgx * px + fgy * py) * iz) * iz;
  const float wx = dot3(s.R, dp0, dp1, dp2), wy = dot3(s.R + 3, dp0, dp1, dp2), wz = dot3(s.R + 6, dp0, dp1, dp2);
  const float J[6] = {wy * az - wz * ay, wz * ax - wx * az, wx * ay - wy * ax, -wx, -wy, -wz};
  const float e = std::fabs(r) * s.inv_sigma;
  const float wt = e > s.huber ? s.huber / e : 1.f;
  int k = 0;
  for (int i = 0; i < 6; ++i) {
    const float wj = wt * J[i];
    for (int j = i; j < 6; ++j) L.s[k++][lane] += wj * J[j];
    L.s[kB + i][lane] -= wj * r;
  }
  L.s[kR2][lane] += r * r;
  ++L.n;
}

__attribute__((target("avx2"))) inline __m256 gatherMasked(const float* base, __m256i idx, __m256 mask) {
  return _mm256_mask_i32gather_ps(_mm256_setzero_ps(), base, idx, mask, 4);
}

// Bilinear samples of `image` at the lanes' (x0 + ax, y0 + ay), cell index idx = y0 * cols + x0.
__attribute__((target("avx2"))) inline __m256 sampleV(const float* image, int cols, __m256i idx, __m256 ax, __m256 ay,
                                                      __m256 mask) {
  const __m256 one = _mm256_set1_ps(1.f);
  const __m256 r00 = gatherMasked(image, idx, mask), r01 = gatherMasked(image + 1, idx, mask);
  const __m256 r10 = gatherMasked(image + cols, idx, mask), r11 = gatherMasked(image + cols + 1, idx, mask);
  const __m256 bx = _mm256_sub_ps(one, ax), by = _mm256_sub_ps(one, ay);
  const __m256 top = _mm256_add_ps(_mm256_mul_ps(bx, r00), _mm256_mul_ps(ax, r01));
  const __m256 bottom = _mm256_add_ps(_mm256_mul_ps(bx, r10), _mm256_mul_ps(ax, r11));
  return _mm256_add_ps(_mm256_mul_ps(by, top), _mm256_mul_ps(ay, bottom));
}

// The same steps on 8 pixels (x, x + stride, ...), a rejected pixel adding +0 to its lane; comparisons
// as the scalar ones take NaN.
__attribute__((target("avx2"))) void pixelsAvx2(const Setup& s, const RefRow& ref, int x, int stride, LaneSums& L) {
  const __m256i lane = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  const __m256i at = _mm256_mullo_epi32(lane, _mm256_set1_epi32(stride));  // the pixels, from x
  const __m256i at3 = _mm256_mullo_epi32(at, _mm256_set1_epi32(3));
  const __m256 gxr = _mm256_i32gather_ps(ref.dx + x, at, 4), gyr = _mm256_i32gather_ps(ref.dy + x, at, 4);
  const __m256 grey = _mm256_i32gather_ps(ref.grey + x, at, 4);
  const float* mv = ref.vertices + 3 * x;
  const __m256 mx = _mm256_i32gather_ps(mv, at3, 4);
  // `gradient^2 < g2` rejects, so a NaN gradient is kept (_CMP_NLT_UQ).
  const __m256 g2 = _mm256_add_ps(_mm256_mul_ps(gxr, gxr), _mm256_mul_ps(gyr, gyr));
  __m256 ok = _mm256_and_ps(_mm256_cmp_ps(g2, _mm256_set1_ps(s.g2), _CMP_NLT_UQ), _mm256_cmp_ps(grey, grey, _CMP_ORD_Q));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(mx, mx, _CMP_ORD_Q));
  if (_mm256_movemask_ps(ok) == 0) return;
  const __m256 my = _mm256_i32gather_ps(mv + 1, at3, 4), mz = _mm256_i32gather_ps(mv + 2, at3, 4);
  const __m256 ax = _mm256_sub_ps(mx, _mm256_set1_ps(s.c[0])), ay = _mm256_sub_ps(my, _mm256_set1_ps(s.c[1])),
               az = _mm256_sub_ps(mz, _mm256_set1_ps(s.c[2]));
  const __m256 qx = dot3(s.Rt, ax, ay, az), qy = dot3(s.Rt + 3, ax, ay, az), qz = dot3(s.Rt + 6, ax, ay, az);
  const __m256 px = _mm256_add_ps(dot3(s.M, qx, qy, qz), _mm256_set1_ps(s.Mt[0]));
  const __m256 py = _mm256_add_ps(dot3(s.M + 3, qx, qy, qz), _mm256_set1_ps(s.Mt[1]));
  const __m256 pz = _mm256_add_ps(dot3(s.M + 6, qx, qy, qz), _mm256_set1_ps(s.Mt[2]));
  const __m256 zero = _mm256_setzero_ps();
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(pz, zero, _CMP_GT_OQ));
  const __m256 iz = _mm256_div_ps(_mm256_set1_ps(1.f), pz);
  const __m256 u = _mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(s.fx), px), iz), _mm256_set1_ps(s.cx));
  const __m256 v = _mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(s.fy), py), iz), _mm256_set1_ps(s.cy));
  ok = _mm256_and_ps(ok, _mm256_and_ps(_mm256_cmp_ps(u, zero, _CMP_GE_OQ), _mm256_cmp_ps(v, zero, _CMP_GE_OQ)));
  ok = _mm256_and_ps(ok, _mm256_and_ps(_mm256_cmp_ps(u, _mm256_set1_ps(s.max_x), _CMP_LT_OQ),
                                       _mm256_cmp_ps(v, _mm256_set1_ps(s.max_y), _CMP_LT_OQ)));
  if (_mm256_movemask_ps(ok) == 0) return;
  const __m256i x0 = _mm256_cvttps_epi32(u), y0 = _mm256_cvttps_epi32(v);
  const __m256 fu = _mm256_sub_ps(u, _mm256_cvtepi32_ps(x0)), fv = _mm256_sub_ps(v, _mm256_cvtepi32_ps(y0));
  const __m256i idx = _mm256_add_epi32(_mm256_mullo_epi32(y0, _mm256_set1_epi32(s.cur_cols)), x0);
  const __m256 r = _mm256_sub_ps(sampleV(s.cur_grey, s.cur_cols, idx, fu, fv, ok), grey);
  const __m256 fgx = _mm256_mul_ps(sampleV(s.cur_dx, s.cur_cols, idx, fu, fv, ok), _mm256_set1_ps(s.fx));
  const __m256 fgy = _mm256_mul_ps(sampleV(s.cur_dy, s.cur_cols, idx, fu, fv, ok), _mm256_set1_ps(s.fy));
  const __m256 sign = _mm256_set1_ps(-0.f);
  const __m256 dp0 = _mm256_mul_ps(fgx, iz), dp1 = _mm256_mul_ps(fgy, iz);
  const __m256 dp2 = _mm256_mul_ps(
      _mm256_mul_ps(_mm256_xor_ps(_mm256_add_ps(_mm256_mul_ps(fgx, px), _mm256_mul_ps(fgy, py)), sign), iz), iz);
  const __m256 wx = dot3(s.R, dp0, dp1, dp2), wy = dot3(s.R + 3, dp0, dp1, dp2), wz = dot3(s.R + 6, dp0, dp1, dp2);
  const __m256 J[6] = {_mm256_sub_ps(_mm256_mul_ps(wy, az), _mm256_mul_ps(wz, ay)),
                       _mm256_sub_ps(_mm256_mul_ps(wz, ax), _mm256_mul_ps(wx, az)),
                       _mm256_sub_ps(_mm256_mul_ps(wx, ay), _mm256_mul_ps(wy, ax)),
                       _mm256_xor_ps(wx, sign), _mm256_xor_ps(wy, sign), _mm256_xor_ps(wz, sign)};
  const __m256 e = _mm256_mul_ps(_mm256_andnot_ps(sign, r), _mm256_set1_ps(s.inv_sigma));
  const __m256 huber = _mm256_set1_ps(s.huber);
  const __m256 wt = _mm256_blendv_ps(_mm256_set1_ps(1.f), _mm256_div_ps(huber, e), _mm256_cmp_ps(e, huber, _CMP_GT_OQ));
  L.n += lanes::count(ok);
  int k = 0;
  for (int i = 0; i < 6; ++i) {
    const __m256 wj = _mm256_mul_ps(wt, J[i]);
    for (int j = i; j < 6; ++j) lanes::add(L.s[k++], _mm256_mul_ps(wj, J[j]), ok);
    lanes::subtract(L.s[kB + i], _mm256_mul_ps(wj, r), ok);
  }
  lanes::add(L.s[kR2], _mm256_mul_ps(r, r), ok);
}

PhotometricRowSums fold(const LaneSums& L) {
  PhotometricRowSums out;
  for (int e = 0; e < kB; ++e) out.eq.A[e] = L.folded(e);
  for (int i = 0; i < 6; ++i) out.eq.b[i] = L.folded(kB + i);
  out.r2 = L.folded(kR2);
  out.n = L.n;
  return out;
}

// An empty image (no colour) gives max_x < 0: every pixel falls outside it.
const float* continuousFloats(const cv::Mat& m) {
  CV_Assert(m.empty() || (m.type() == CV_32F && m.isContinuous()));
  return m.ptr<float>();
}

}  // namespace

PhotometricAssociator::PhotometricAssociator(const PhotometricLevel& level, const Eigen::Isometry3d& T,
                                             const PhotometricParams& params, const Eigen::Isometry3d& colour_motion,
                                             bool simd)
    : level_(level), avx2_(simd && usesAvx2()) {
  const IntensityLevel& cur = *level.current;
  storeRowMajor(T.linear().transpose(), s_.Rt);
  const Eigen::Isometry3d M_inv = colour_motion.inverse();
  storeRowMajor(M_inv.linear(), s_.M);
  storeRowMajor(T.linear() * colour_motion.linear(), s_.R);
  for (int i = 0; i < 3; ++i) {
    s_.Mt[i] = static_cast<float>(M_inv.translation()[i]);
    s_.c[i] = static_cast<float>(T.translation()[i]);
  }
  s_.fx = level.camera.fx, s_.fy = level.camera.fy, s_.cx = level.camera.cx, s_.cy = level.camera.cy;
  s_.max_x = cur.grey.cols - 1.001f, s_.max_y = cur.grey.rows - 1.001f;
  s_.g2 = static_cast<float>(params.min_gradient * params.min_gradient);
  s_.inv_sigma = static_cast<float>(1.0 / params.sigma);
  s_.huber = static_cast<float>(params.huber);
  s_.cur_grey = continuousFloats(cur.grey);
  s_.cur_dx = continuousFloats(cur.dx);
  s_.cur_dy = continuousFloats(cur.dy);
  CV_Assert(cur.dx.size() == cur.grey.size() && cur.dy.size() == cur.grey.size());
  s_.cur_cols = cur.grey.cols;
}

bool PhotometricAssociator::usesAvx2() { return cpuHasAvx2(); }

PhotometricRowSums PhotometricAssociator::sumRow(int y, int first, int stride) const {
  const IntensityLevel& ref = *level_.reference;
  const RefRow row{ref.grey.ptr<float>(y), ref.dx.ptr<float>(y), ref.dy.ptr<float>(y),
                   level_.model_vertices->ptr<float>(y)};
  const int cols = level_.model_vertices->cols;
  LaneSums L;
  int x = first, k = 0;
  if (avx2_)
    for (; x + 7 * stride < cols; x += 8 * stride, k += 8) pixelsAvx2(s_, row, x, stride, L);
  for (; x < cols; x += stride, ++k) pixelScalar(s_, row, x, k % 8, L);
  return fold(L);
}

}  // namespace vofusion::fusion
