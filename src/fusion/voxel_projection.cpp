#include "vofusion/fusion/voxel_projection.h"

#include <algorithm>
#include <cmath>
#include <immintrin.h>

#include "vofusion/core/cpu_features.h"

namespace vofusion::fusion {

namespace {

using Setup = VoxelProjector::Setup;

void sampleScalar(const Setup& s, const float* first, const float* step, VoxelRowSamples& out) {
  for (int x = 0; x < 8; ++x) {
    const float fxl = static_cast<float>(x);
    const float px = first[0] + step[0] * fxl, py = first[1] + step[1] * fxl, pz = first[2] + step[2] * fxl;
    out.z[x] = pz;
    out.pixel[x] = -1;
    if (!(pz > 0.f)) continue;
    const float iz = 1.f / pz;
    const float uf = s.fx * px * iz + s.cx, vf = s.fy * py * iz + s.cy;
    if (!(uf > -0.5f && vf > -0.5f && uf < s.w - 0.5f && vf < s.h - 0.5f)) continue;
    const int u = static_cast<int>(uf + 0.5f), v = static_cast<int>(vf + 0.5f);
    float d = s.depth[v * s.w + u];
    if (!(d >= s.zmin && d <= s.zmax)) continue;
    // Bilinear depth where the 4 neighbours agree: with voxels about as small as a pixel's
    // footprint, the nearest reading alone fuses a staircase into the TSDF (noisy normals).
    const int u0 = static_cast<int>(uf), v0 = static_cast<int>(vf);
    if (uf >= 0.f && vf >= 0.f && u0 + 1 < s.w && v0 + 1 < s.h) {
      const float* r0 = s.depth + v0 * s.w;
      const float* r1 = r0 + s.w;
      const float d00 = r0[u0], d01 = r0[u0 + 1], d10 = r1[u0], d11 = r1[u0 + 1];
      const float lo = std::min(std::min(d00, d01), std::min(d10, d11));
      const float hi = std::max(std::max(d00, d01), std::max(d10, d11));
      if (lo > 0.f && hi - lo < s.agree) {
        const float a = uf - u0, b = vf - v0;
        const float blend = (d00 * (1 - a) + d01 * a) * (1 - b) + (d10 * (1 - a) + d11 * a) * b;
        // A NaN neighbour passes lo and hi (std::min / max drop it) but not the blend.
        if (!std::isnan(blend)) d = blend;
      }
    }
    out.depth[x] = d;
    out.pixel[x] = v * s.w + u;
  }
}

// The same steps on 8 lanes. std::min(a, b) is (b < a ? b : a), i.e. _mm256_min_ps(b, a), and
// std::max(a, b) is _mm256_max_ps(b, a): the same results, NaN included. No FMA: target avx2 only, and the file is built with
// -ffp-contract=off so that a -march=native build does not fuse the scalar loop either.
__attribute__((target("avx2"))) void sampleAvx2(const Setup& s, const float* first, const float* step,
                                                VoxelRowSamples& out) {
  const __m256 lane = _mm256_setr_ps(0, 1, 2, 3, 4, 5, 6, 7);
  const __m256 px = _mm256_add_ps(_mm256_set1_ps(first[0]), _mm256_mul_ps(_mm256_set1_ps(step[0]), lane));
  const __m256 py = _mm256_add_ps(_mm256_set1_ps(first[1]), _mm256_mul_ps(_mm256_set1_ps(step[1]), lane));
  const __m256 pz = _mm256_add_ps(_mm256_set1_ps(first[2]), _mm256_mul_ps(_mm256_set1_ps(step[2]), lane));
  _mm256_storeu_ps(out.z, pz);
  const __m256 zero = _mm256_setzero_ps(), one = _mm256_set1_ps(1.f), half = _mm256_set1_ps(0.5f);
  __m256 ok = _mm256_cmp_ps(pz, zero, _CMP_GT_OQ);
  const __m256 iz = _mm256_div_ps(one, pz);
  const __m256 uf = _mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(s.fx), px), iz), _mm256_set1_ps(s.cx));
  const __m256 vf = _mm256_add_ps(_mm256_mul_ps(_mm256_mul_ps(_mm256_set1_ps(s.fy), py), iz), _mm256_set1_ps(s.cy));
  const __m256 wf = _mm256_set1_ps(static_cast<float>(s.w)), hf = _mm256_set1_ps(static_cast<float>(s.h));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(uf, _mm256_set1_ps(-0.5f), _CMP_GT_OQ));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(vf, _mm256_set1_ps(-0.5f), _CMP_GT_OQ));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(uf, _mm256_sub_ps(wf, half), _CMP_LT_OQ));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(vf, _mm256_sub_ps(hf, half), _CMP_LT_OQ));
  if (_mm256_movemask_ps(ok) == 0) {
    _mm256_storeu_si256(reinterpret_cast<__m256i*>(out.pixel), _mm256_set1_epi32(-1));
    return;
  }
  const __m256i wi = _mm256_set1_epi32(s.w);
  // Lanes that failed hold garbage coordinates: clamp them to pixel 0 so every gather stays inside.
  const __m256i u = _mm256_and_si256(_mm256_cvttps_epi32(_mm256_add_ps(uf, half)), _mm256_castps_si256(ok));
  const __m256i v = _mm256_and_si256(_mm256_cvttps_epi32(_mm256_add_ps(vf, half)), _mm256_castps_si256(ok));
  const __m256i pix = _mm256_add_epi32(_mm256_mullo_epi32(v, wi), u);
  __m256 d = _mm256_i32gather_ps(s.depth, pix, 4);
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(d, _mm256_set1_ps(s.zmin), _CMP_GE_OQ));
  ok = _mm256_and_ps(ok, _mm256_cmp_ps(d, _mm256_set1_ps(s.zmax), _CMP_LE_OQ));

  const __m256i u0 = _mm256_cvttps_epi32(uf), v0 = _mm256_cvttps_epi32(vf);
  __m256 bil = _mm256_and_ps(ok, _mm256_cmp_ps(uf, zero, _CMP_GE_OQ));
  bil = _mm256_and_ps(bil, _mm256_cmp_ps(vf, zero, _CMP_GE_OQ));
  bil = _mm256_and_ps(bil, _mm256_castsi256_ps(_mm256_cmpgt_epi32(wi, _mm256_add_epi32(u0, _mm256_set1_epi32(1)))));
  bil = _mm256_and_ps(bil, _mm256_castsi256_ps(_mm256_cmpgt_epi32(_mm256_set1_epi32(s.h), _mm256_add_epi32(v0, _mm256_set1_epi32(1)))));
  if (_mm256_movemask_ps(bil) != 0) {
    const __m256i p00 = _mm256_and_si256(_mm256_add_epi32(_mm256_mullo_epi32(v0, wi), u0), _mm256_castps_si256(bil));
    const __m256 d00 = _mm256_i32gather_ps(s.depth, p00, 4);
    const __m256 d01 = _mm256_i32gather_ps(s.depth + 1, p00, 4);
    const __m256 d10 = _mm256_i32gather_ps(s.depth + s.w, p00, 4);
    const __m256 d11 = _mm256_i32gather_ps(s.depth + s.w + 1, p00, 4);
    const __m256 lo = _mm256_min_ps(_mm256_min_ps(d11, d10), _mm256_min_ps(d01, d00));
    const __m256 hi = _mm256_max_ps(_mm256_max_ps(d11, d10), _mm256_max_ps(d01, d00));
    bil = _mm256_and_ps(bil, _mm256_cmp_ps(lo, zero, _CMP_GT_OQ));
    bil = _mm256_and_ps(bil, _mm256_cmp_ps(_mm256_sub_ps(hi, lo), _mm256_set1_ps(s.agree), _CMP_LT_OQ));
    const __m256 a = _mm256_sub_ps(uf, _mm256_cvtepi32_ps(u0)), b = _mm256_sub_ps(vf, _mm256_cvtepi32_ps(v0));
    const __m256 na = _mm256_sub_ps(one, a), nb = _mm256_sub_ps(one, b);
    const __m256 top = _mm256_add_ps(_mm256_mul_ps(d00, na), _mm256_mul_ps(d01, a));
    const __m256 bottom = _mm256_add_ps(_mm256_mul_ps(d10, na), _mm256_mul_ps(d11, a));
    const __m256 interp = _mm256_add_ps(_mm256_mul_ps(top, nb), _mm256_mul_ps(bottom, b));
    bil = _mm256_and_ps(bil, _mm256_cmp_ps(interp, interp, _CMP_ORD_Q));
    d = _mm256_blendv_ps(d, interp, bil);
  }
  _mm256_storeu_ps(out.depth, d);
  _mm256_storeu_si256(reinterpret_cast<__m256i*>(out.pixel),
                      _mm256_blendv_epi8(_mm256_set1_epi32(-1), pix, _mm256_castps_si256(ok)));
}

}  // namespace

VoxelProjector::VoxelProjector(const cv::Mat& depth, const CameraIntrinsics& cam, float min_depth, float max_depth,
                               float agree, bool simd)
    : s_{depth.ptr<float>(), depth.cols, depth.rows, float(cam.fx), float(cam.fy), float(cam.cx), float(cam.cy),
         min_depth, max_depth, agree},
      avx2_(simd && cpuHasAvx2()) {
  CV_Assert(depth.type() == CV_32FC1 && depth.isContinuous());
}

bool VoxelProjector::usesAvx2() { return cpuHasAvx2(); }

void VoxelProjector::sampleRow(const Eigen::Vector3f& first, const Eigen::Vector3f& step, VoxelRowSamples& out) const {
  if (avx2_) sampleAvx2(s_, first.data(), step.data(), out);
  else sampleScalar(s_, first.data(), step.data(), out);
}

}  // namespace vofusion::fusion
