// What ICP's and the photometric term's associations (icp_association.cpp, photometric_association.cpp)
// share: per-lane sums of a row (float, or double sums of exact float products), and the 3-term dot
// product both builds compute in the same order, with its AVX2 twin. Both files are built with
// -ffp-contract=off, so neither build fuses a multiply-add.
// Included only by the registration stage's own sources.
#pragma once

#include <immintrin.h>

#include <Eigen/Core>

namespace vofusion::fusion::lanes {
// Internal linkage: each including file (all built with -ffp-contract=off) keeps its own copies, so a
// file built otherwise could never lend the linker a fused one.
namespace {

// `Entries` sums of one row, 8 lanes each (the row's k-th pixel goes to lane k % 8), starting at +0: a
// rejected pixel's lane in the AVX2 build adds +0, which leaves the sum as the scalar build's skip does.
template <int Entries, class T = float>
struct alignas(32) LaneSums {
  T s[Entries][8] = {};

  // Entry e's 8 lanes added in double, in lane order.
  double folded(int e) const {
    double sum = 0.0;
    for (int lane = 0; lane < 8; ++lane) sum += double(s[e][lane]);
    return sum;
  }
};

// The matrix's entries, row by row, as floats (the builds' inputs).
template <class Derived>
void storeRowMajor(const Eigen::MatrixBase<Derived>& m, float* out) {
  for (int i = 0; i < m.rows(); ++i)
    for (int j = 0; j < m.cols(); ++j) out[m.cols() * i + j] = static_cast<float>(m(i, j));
}

// Bilinear sample of a row-major float image at (u, v), which the caller keeps inside
// [0, cols-1) x [0, rows-1).
inline float sample(const float* image, int cols, float u, float v) {
  const int x0 = static_cast<int>(u), y0 = static_cast<int>(v);
  const float ax = u - static_cast<float>(x0), ay = v - static_cast<float>(y0);
  const float* r0 = image + y0 * cols + x0;
  const float* r1 = r0 + cols;
  return (1.f - ay) * ((1.f - ax) * r0[0] + ax * r0[1]) + ay * ((1.f - ax) * r1[0] + ax * r1[1]);
}

// ((m0 x + m1 y) + m2 z), in this order in both builds.
inline float dot3(const float* m, float x, float y, float z) { return (m[0] * x + m[1] * y) + m[2] * z; }

__attribute__((target("avx2"))) inline __m256 dot3(const float* m, __m256 x, __m256 y, __m256 z) {
  return _mm256_add_ps(_mm256_add_ps(_mm256_mul_ps(_mm256_set1_ps(m[0]), x), _mm256_mul_ps(_mm256_set1_ps(m[1]), y)),
                       _mm256_mul_ps(_mm256_set1_ps(m[2]), z));
}
// sum += value (or -= value) in the lanes of `mask`; +0 (no change) in the others.
__attribute__((target("avx2"))) inline void add(float* sum, __m256 value, __m256 mask) {
  _mm256_store_ps(sum, _mm256_add_ps(_mm256_load_ps(sum), _mm256_and_ps(value, mask)));
}
__attribute__((target("avx2"))) inline void subtract(float* sum, __m256 value, __m256 mask) {
  _mm256_store_ps(sum, _mm256_sub_ps(_mm256_load_ps(sum), _mm256_and_ps(value, mask)));
}
// Double lanes (sum: 8 doubles): sum += double(a) * double(b), or -=, or += double(v). A product of two
// floats is exact in double, so these sums round only where they add. Rejected lanes must hold +0 in a
// or b (and both finite) or in v.
__attribute__((target("avx2"))) inline void addProducts(double* sum, __m256 a, __m256 b) {
  const __m256d lo = _mm256_mul_pd(_mm256_cvtps_pd(_mm256_castps256_ps128(a)), _mm256_cvtps_pd(_mm256_castps256_ps128(b)));
  const __m256d hi = _mm256_mul_pd(_mm256_cvtps_pd(_mm256_extractf128_ps(a, 1)), _mm256_cvtps_pd(_mm256_extractf128_ps(b, 1)));
  _mm256_store_pd(sum, _mm256_add_pd(_mm256_load_pd(sum), lo));
  _mm256_store_pd(sum + 4, _mm256_add_pd(_mm256_load_pd(sum + 4), hi));
}
__attribute__((target("avx2"))) inline void subtractProducts(double* sum, __m256 a, __m256 b) {
  const __m256d lo = _mm256_mul_pd(_mm256_cvtps_pd(_mm256_castps256_ps128(a)), _mm256_cvtps_pd(_mm256_castps256_ps128(b)));
  const __m256d hi = _mm256_mul_pd(_mm256_cvtps_pd(_mm256_extractf128_ps(a, 1)), _mm256_cvtps_pd(_mm256_extractf128_ps(b, 1)));
  _mm256_store_pd(sum, _mm256_sub_pd(_mm256_load_pd(sum), lo));
  _mm256_store_pd(sum + 4, _mm256_sub_pd(_mm256_load_pd(sum + 4), hi));
}
__attribute__((target("avx2"))) inline void addValues(double* sum, __m256 v) {
  _mm256_store_pd(sum, _mm256_add_pd(_mm256_load_pd(sum), _mm256_cvtps_pd(_mm256_castps256_ps128(v))));
  _mm256_store_pd(sum + 4, _mm256_add_pd(_mm256_load_pd(sum + 4), _mm256_cvtps_pd(_mm256_extractf128_ps(v, 1))));
}
__attribute__((target("avx2"))) inline int count(__m256 mask) { return __builtin_popcount(_mm256_movemask_ps(mask)); }

}  // namespace
}  // namespace vofusion::fusion::lanes
