#include "vofusion/registration/icp_association.h"

#include <algorithm>
#include <cmath>
#include <immintrin.h>

#include "vofusion/core/cpu_features.h"

#include "lane_sums.h"

namespace vofusion::fusion {

namespace {

using Setup = IcpAssociator::Setup;

// Per-lane double sums of one row: the 21 entries of J^T J, the 6 of -J^T r, then r^2, min(r^2, trunc^2)
// and the squared distance from the camera centre.
constexpr int kEntries = 30;
constexpr int kB = 21, kR2 = 27, kR2Truncated = 28, kD2 = 29;

struct LaneSums : lanes::LaneSums<kEntries, double> {
  int n = 0, valid = 0, in_view = 0;
};

using lanes::dot3;

void pixelScalar(const Setup& s, const float* vc, const float* nc, int lane, LaneSums& L) {
  if (std::isnan(vc[0]) || std::isnan(nc[0])) return;
  ++L.valid;
  const float vgx = dot3(s.R, vc[0], vc[1], vc[2]) + s.t[0];
  const float vgy = dot3(s.R + 3, vc[0], vc[1], vc[2]) + s.t[1];
  const float vgz = dot3(s.R + 6, vc[0], vc[1], vc[2]) + s.t[2];
  const float pmx = dot3(s.Rm, vgx, vgy, vgz) + s.tm[0];
  const float pmy = dot3(s.Rm + 3, vgx, vgy, vgz) + s.tm[1];
  const float pmz = dot3(s.Rm + 6, vgx, vgy, vgz) + s.tm[2];
  if (pmz <= 0.f) return;
  const float uf = s.fx * pmx / pmz + s.cx, vf = s.fy * pmy / pmz + s.cy;
  if (!(uf > -0.5f && vf > -0.5f && uf < s.mw - 0.5f && vf < s.mh - 0.5f)) return;
  const int u = static_cast<int>(uf + 0.5f), v = static_cast<int>(vf + 0.5f);
  const float* m = s.model_vertices + 3 * (v * s.mw + u);
  const float* n = s.model_normals + 3 * (v * s.mw + u);
  if (std::isnan(m[0]) || std::isnan(n[0])) return;
  ++L.in_view;
  const float dx = vgx - m[0], dy = vgy - m[1], dz = vgz - m[2];
  if ((dx * dx + dy * dy) + dz * dz > s.max_d2) return;
  const float ngx = dot3(s.R, nc[0], nc[1], nc[2]);
  const float ngy = dot3(s.R + 3, nc[0], nc[1], nc[2]);
  const float ngz = dot3(s.R + 6, nc[0], nc[1], nc[2]);
  if ((ngx * n[0] + ngy * n[1]) + ngz * n[2] < s.min_cos) return;
  ++L.n;
  const float r = (n[0] * dx + n[1] * dy) + n[2] * dz;
  const float pcx = vgx - s.t[0], pcy = vgy - s.t[1], pcz = vgz - s.t[2];
  const float J[6] = {pcy * n[2] - pcz * n[1], pcz * n[0] - pcx * n[2], pcx * n[1] - pcy * n[0], n[0], n[1], n[2]};
  int k = 0;
  for (int i = 0; i < 6; ++i) {
    for (int j = i; j < 6; ++j) L.s[k++][lane] += double(J[i]) * double(J[j]);
    L.s[kB + i][lane] -= double(J[i]) * double(r);
  }
  L.s[kR2][lane] += double(r) * double(r);
  L.s[kR2Truncated][lane] += double(std::min(r * r, s.trunc2));
  L.s[kD2][lane] += double((pcx * pcx + pcy * pcy) + pcz * pcz);
}

void fold(const LaneSums& L, IcpRowSums& out) {
  for (int e = 0; e < kB; ++e) out.eq.A[e] = L.folded(e);
  for (int i = 0; i < 6; ++i) out.eq.b[i] = L.folded(kB + i);
  out.r2 = L.folded(kR2);
  out.r2_truncated = L.folded(kR2Truncated);
  out.d2 = L.folded(kD2);
  out.n = L.n;
  out.valid = L.valid;
  out.in_view = L.in_view;
}

struct V3 {
  __m256 x, y, z;
};

__attribute__((target("avx2"))) inline V3 affine(const float* R, const float* t, const V3& p) {
  return {_mm256_add_ps(dot3(R, p.x, p.y, p.z), _mm256_set1_ps(t[0])),
          _mm256_add_ps(dot3(R + 3, p.x, p.y, p.z), _mm256_set1_ps(t[1])),
          _mm256_add_ps(dot3(R + 6, p.x, p.y, p.z), _mm256_set1_ps(t[2]))};
}
__attribute__((target("avx2"))) inline __m256 dotv(const V3& a, const V3& b) {
  return _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(a.x, b.x), _mm256_mul_ps(a.y, b.y)), _mm256_mul_ps(a.z, b.z));
}

// The x, y, z of the 8 points at base + idx (floats), lanes outside `mask` zero and not read.
__attribute__((target("avx2"))) inline V3 gather3(const float* base, __m256i idx, __m256 mask) {
  const __m256 zero = _mm256_setzero_ps();
  return {_mm256_mask_i32gather_ps(zero, base, idx, mask, 4), _mm256_mask_i32gather_ps(zero, base + 1, idx, mask, 4),
          _mm256_mask_i32gather_ps(zero, base + 2, idx, mask, 4)};
}

__attribute__((target("avx2"))) inline __m256 keep(__m256 mask, __m256 x) { return _mm256_and_ps(x, mask); }

// The same steps on 8 pixels, a rejected pixel adding +0 to its lane. Comparisons are the scalar
// ones' negations with NaN taken as the scalar code takes it (e.g. `d2 > max` rejects, so a NaN
// distance is kept: _CMP_NGT_UQ).
__attribute__((target("avx2"))) void pixelsAvx2(const Setup& s, const float* vc, const float* nc, LaneSums& L) {
  const __m256i three = _mm256_setr_epi32(0, 3, 6, 9, 12, 15, 18, 21);
  const V3 v{_mm256_i32gather_ps(vc, three, 4), _mm256_i32gather_ps(vc + 1, three, 4), _mm256_i32gather_ps(vc + 2, three, 4)};
  const V3 nf{_mm256_i32gather_ps(nc, three, 4), _mm256_i32gather_ps(nc + 1, three, 4), _mm256_i32gather_ps(nc + 2, three, 4)};
  __m256 ok = _mm256_and_ps(_mm256_cmp_ps(v.x, v.x, _CMP_ORD_Q), _mm256_cmp_ps(nf.x, nf.x, _CMP_ORD_Q));
  if (_mm256_movemask_ps(ok) == 0) return;
  L.valid += lanes::count(ok);
  const V3 vg = affine(s.R, s.t, v);
  const V3 pm = affine(s.Rm, s.tm, vg);
  const __m256 zero = _mm256_setzero_ps(), half = _mm256_set1_ps(0.5f);
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(pm.z, zero, _CMP_NLE_UQ));
  const __m256 uf = _mm256_add_ps(_mm256_div_ps(_mm256_mul_ps(_mm256_set1_ps(s.fx), pm.x), pm.z), _mm256_set1_ps(s.cx));
  const __m256 vf = _mm256_add_ps(_mm256_div_ps(_mm256_mul_ps(_mm256_set1_ps(s.fy), pm.y), pm.z), _mm256_set1_ps(s.cy));
  const __m256 lo = _mm256_set1_ps(-0.5f);
  ok = _mm256_and_ps(ok, _mm256_and_ps(_mm256_cmp_ps(uf, lo, _CMP_GT_OQ), _mm256_cmp_ps(vf, lo, _CMP_GT_OQ)));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(uf, _mm256_set1_ps(s.mw - 0.5f), _CMP_LT_OQ));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(vf, _mm256_set1_ps(s.mh - 0.5f), _CMP_LT_OQ));
  if (_mm256_movemask_ps(ok) == 0) return;
  const __m256i u = _mm256_cvttps_epi32(_mm256_add_ps(uf, half));
  const __m256i row = _mm256_cvttps_epi32(_mm256_add_ps(vf, half));
  const __m256i idx = _mm256_mullo_epi32(_mm256_add_epi32(_mm256_mullo_epi32(row, _mm256_set1_epi32(s.mw)), u), _mm256_set1_epi32(3));
  const V3 m = gather3(s.model_vertices, idx, ok);
  const V3 n = gather3(s.model_normals, idx, ok);
  ok = _mm256_and_ps(ok, _mm256_and_ps(_mm256_cmp_ps(m.x, m.x, _CMP_ORD_Q), _mm256_cmp_ps(n.x, n.x, _CMP_ORD_Q)));
  L.in_view += lanes::count(ok);
  const V3 d{_mm256_sub_ps(vg.x, m.x), _mm256_sub_ps(vg.y, m.y), _mm256_sub_ps(vg.z, m.z)};
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(dotv(d, d), _mm256_set1_ps(s.max_d2), _CMP_NGT_UQ));
  const V3 ng{dot3(s.R, nf.x, nf.y, nf.z), dot3(s.R + 3, nf.x, nf.y, nf.z), dot3(s.R + 6, nf.x, nf.y, nf.z)};
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(dotv(ng, n), _mm256_set1_ps(s.min_cos), _CMP_NLT_UQ));
  if (_mm256_movemask_ps(ok) == 0) return;
  L.n += lanes::count(ok);
  const __m256 r = dotv(n, d);
  const V3 pc{_mm256_sub_ps(vg.x, _mm256_set1_ps(s.t[0])), _mm256_sub_ps(vg.y, _mm256_set1_ps(s.t[1])),
              _mm256_sub_ps(vg.z, _mm256_set1_ps(s.t[2]))};
  // Rejected lanes hold +0 from here on (their J or r may be NaN): their products and values add +0.
  const __m256 J[6] = {keep(ok, _mm256_sub_ps(_mm256_mul_ps(pc.y, n.z), _mm256_mul_ps(pc.z, n.y))),
                       keep(ok, _mm256_sub_ps(_mm256_mul_ps(pc.z, n.x), _mm256_mul_ps(pc.x, n.z))),
                       keep(ok, _mm256_sub_ps(_mm256_mul_ps(pc.x, n.y), _mm256_mul_ps(pc.y, n.x))),
                       keep(ok, n.x), keep(ok, n.y), keep(ok, n.z)};
  const __m256 rk = keep(ok, r);
  int k = 0;
  for (int i = 0; i < 6; ++i) {
    for (int j = i; j < 6; ++j) lanes::addProducts(L.s[k++], J[i], J[j]);
    lanes::subtractProducts(L.s[kB + i], J[i], rk);
  }
  lanes::addProducts(L.s[kR2], rk, rk);
  lanes::addValues(L.s[kR2Truncated], _mm256_min_ps(_mm256_set1_ps(s.trunc2), _mm256_mul_ps(rk, rk)));  // std::min(rr, trunc2)
  lanes::addValues(L.s[kD2], keep(ok, dotv(pc, pc)));
}

}  // namespace

IcpAssociator::IcpAssociator(const cv::Mat& model_vertices, const cv::Mat& model_normals, const CameraIntrinsics& camera,
                             const Eigen::Isometry3f& model_inv, const Eigen::Isometry3f& pose, float max_distance,
                             float max_angle_deg, float truncation, bool simd)
    : avx2_(simd && usesAvx2()) {
  // An empty model (nothing ray cast yet) has no pixel to land on: every pixel is out of view.
  CV_Assert(model_vertices.empty() ||
            (model_vertices.type() == CV_32FC3 && model_normals.type() == CV_32FC3 && model_vertices.isContinuous() &&
             model_normals.isContinuous() && model_vertices.size() == model_normals.size()));
  lanes::storeRowMajor(pose.linear(), s_.R);
  lanes::storeRowMajor(pose.translation(), s_.t);
  lanes::storeRowMajor(model_inv.linear(), s_.Rm);
  lanes::storeRowMajor(model_inv.translation(), s_.tm);
  s_.fx = camera.fx, s_.fy = camera.fy, s_.cx = camera.cx, s_.cy = camera.cy;
  s_.max_d2 = max_distance * max_distance;
  s_.min_cos = static_cast<float>(std::cos(max_angle_deg * M_PI / 180.0));
  s_.trunc2 = truncation * truncation;
  s_.model_vertices = model_vertices.ptr<float>();
  s_.model_normals = model_normals.ptr<float>();
  s_.mw = model_vertices.cols;
  s_.mh = model_vertices.rows;
}

bool IcpAssociator::usesAvx2() { return cpuHasAvx2(); }

IcpRowSums IcpAssociator::sumRow(const cv::Vec3f* vertices, const cv::Vec3f* normals, int cols) const {
  LaneSums L;
  const float* v = vertices[0].val;
  const float* n = normals[0].val;
  int x = 0;
  if (avx2_)
    for (; x + 8 <= cols; x += 8) pixelsAvx2(s_, v + 3 * x, n + 3 * x, L);
  for (; x < cols; ++x) pixelScalar(s_, v + 3 * x, n + 3 * x, x % 8, L);
  IcpRowSums out;
  fold(L, out);
  return out;
}

}  // namespace vofusion::fusion
