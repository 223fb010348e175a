#include "vofusion/fusion/voxel_update.h"

#include <algorithm>
#include <array>
#include <cstdint>
#include <immintrin.h>

#include "vofusion/core/cpu_features.h"

namespace vofusion::fusion {

namespace {

using Setup = VoxelUpdater::Setup;

bool isNoColour(const cv::Vec3b& c) { return (c[0] | c[1] | c[2]) == 0; }

// 1 / (weight + 1) for every weight a voxel can hold: the running average without a division.
const std::array<float, 256>& inverseCounts() {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) t[i] = 1.f / (i + 1);
    return t;
  }();
  return table;
}

int updateScalar(const Setup& s, const VoxelRowSamples& row, Voxel* vox) {
  const std::array<float, 256>& inv_count = inverseCounts();
  int updated = 0;
  for (int x = 0; x < kBrickEdge; ++x) {
    if (row.pixel[x] < 0) continue;
    const float sdf = row.depth[x] - row.z[x];
    if (sdf < -s.truncation) continue;
    const float f = std::min(1.f, sdf * s.inv_truncation);
    Voxel& vx = vox[x];
    const int wold = vx.weight;
    // Running average in tsdf units (no division, no libm rounding call): tsdf in [-1, 1]
    // times 32767, rounded half away from zero as lround did.
    const float fnew = (vx.tsdf * static_cast<float>(wold) + f * kTsdfScale) * inv_count[wold];
    vx.tsdf = static_cast<std::int16_t>(fnew + (fnew >= 0.f ? 0.5f : -0.5f));
    vx.weight = static_cast<std::uint8_t>(std::min(wold + 1, s.max_weight));
    // Black (0, 0, 0) is no colour: a depth pixel the colour camera did not see (colour_registration.h).
    if (s.colours && sdf < s.truncation && !isNoColour(s.colours[row.pixel[x]])) {
      // Same running average, rounded; a multiply instead of three integer divisions per voxel. The
      // weight counts free-space updates too, which bring no colour: a voxel still black (never
      // painted) takes its first colour whole, or it would start at c / (weight + 1), a dark fringe.
      const cv::Vec3b& c = s.colours[row.pixel[x]];
      const bool unpainted = (vx.r | vx.g | vx.b) == 0;
      const float k = unpainted ? 1.f : inv_count[wold], fw = unpainted ? 0.f : static_cast<float>(wold);
      vx.r = static_cast<std::uint8_t>((vx.r * fw + c[2]) * k + 0.5f);
      vx.g = static_cast<std::uint8_t>((vx.g * fw + c[1]) * k + 0.5f);
      vx.b = static_cast<std::uint8_t>((vx.b * fw + c[0]) * k + 0.5f);
    }
    ++updated;
  }
  return updated;
}

// The 8 voxels of a row are 48 bytes, 6 per voxel: tsdf (2), weight, r, g, b. A field's 8 values
// (bytes `width` each) come out of the row's three 16-byte chunks by one byte shuffle per chunk, and go
// back in by the inverse shuffles. pick[field][chunk]: for each byte of the field's vector, its byte
// in that chunk, or 0x80 (zero) when it is in another chunk; place[field][chunk] the other way round.
static_assert(kBrickEdge == 8 && sizeof(Voxel) == 6, "the AVX2 build updates a brick row of 8 six-byte voxels");
constexpr int kFieldOffset[5] = {0, 2, 3, 4, 5}, kFieldWidth[5] = {2, 1, 1, 1, 1};

struct ShuffleTables {
  alignas(16) std::int8_t pick[5][3][16];   // chunk -> field
  alignas(16) std::int8_t place[5][3][16];  // field -> chunk
};

constexpr ShuffleTables makeTables() {
  ShuffleTables t{};
  for (int f = 0; f < 5; ++f)
    for (int c = 0; c < 3; ++c)
      for (int j = 0; j < 16; ++j) t.pick[f][c][j] = t.place[f][c][j] = std::int8_t(0x80);
  for (int f = 0; f < 5; ++f)
    for (int j = 0; j < 8 * kFieldWidth[f]; ++j) {
      const int voxel = j / kFieldWidth[f], byte = 6 * voxel + kFieldOffset[f] + j % kFieldWidth[f];
      t.pick[f][byte / 16][j] = std::int8_t(byte % 16);
      t.place[f][byte / 16][byte % 16] = std::int8_t(j);
    }
  return t;
}
constexpr ShuffleTables kTables = makeTables();

__attribute__((target("avx2"))) __m128i shuffle(__m128i v, const std::int8_t* table) {
  return _mm_shuffle_epi8(v, _mm_load_si128(reinterpret_cast<const __m128i*>(table)));
}

__attribute__((target("avx2"))) __m128i pickField(const __m128i chunk[3], int f) {
  return _mm_or_si128(_mm_or_si128(shuffle(chunk[0], kTables.pick[f][0]), shuffle(chunk[1], kTables.pick[f][1])),
                      shuffle(chunk[2], kTables.pick[f][2]));
}

// 8 floats (integer valued, in [0, 255]) truncated to bytes, in the low 8 bytes.
__attribute__((target("avx2"))) __m128i toBytes(__m256 v) {
  const __m256i i = _mm256_cvttps_epi32(v);
  const __m128i words = _mm_packus_epi32(_mm256_castsi256_si128(i), _mm256_extracti128_si256(i, 1));
  return _mm_packus_epi16(words, words);
}

__attribute__((target("avx2"))) __m256 bytesToFloats(__m128i bytes) {
  return _mm256_cvtepi32_ps(_mm256_cvtepu8_epi32(bytes));
}

// Lane masks (all ones or zero per 32-bit lane) as 16-bit and 8-bit vectors: lane i is word i, byte i.
__attribute__((target("avx2"))) void narrow(__m256 mask, __m128i& m16, __m128i& m8) {
  const __m256i m = _mm256_castps_si256(mask);
  m16 = _mm_packs_epi32(_mm256_castsi256_si128(m), _mm256_extracti128_si256(m, 1));
  m8 = _mm_packs_epi16(m16, m16);
}

// A colour channel's running average: (old * w + c) * k + 0.5, truncated to a byte.
__attribute__((target("avx2"))) __m128i averageColour(__m128i old8, __m256 c, __m256 fw, __m256 k) {
  const __m256 sum = _mm256_add_ps(_mm256_mul_ps(bytesToFloats(old8), fw), c);
  return toBytes(_mm256_add_ps(_mm256_mul_ps(sum, k), _mm256_set1_ps(0.5f)));
}

// The scalar loop on 8 lanes, the same operations in the same order (no FMA: target avx2 only, and the
// file is built with -ffp-contract=off). std::min(1.f, x) is (x < 1 ? x : 1), i.e. _mm256_min_ps(x, 1).
__attribute__((target("avx2"))) int updateAvx2(const Setup& s, const VoxelRowSamples& row, Voxel* vox) {
  const __m256i pixel = _mm256_loadu_si256(reinterpret_cast<const __m256i*>(row.pixel));
  const __m256 sdf = _mm256_sub_ps(_mm256_loadu_ps(row.depth), _mm256_loadu_ps(row.z));
  // Updated: a reading (pixel >= 0) and not (sdf < -truncation), NaN included as in the scalar test.
  const __m256 seen = _mm256_castsi256_ps(_mm256_cmpgt_epi32(pixel, _mm256_set1_epi32(-1)));
  const __m256 update = _mm256_and_ps(seen, _mm256_cmp_ps(sdf, _mm256_set1_ps(-s.truncation), _CMP_NLT_UQ));
  const int lanes = _mm256_movemask_ps(update);
  if (lanes == 0) return 0;
  const __m256 paint = _mm256_and_ps(update, _mm256_cmp_ps(sdf, _mm256_set1_ps(s.truncation), _CMP_LT_OQ));
  // A painted voxel on pixel 0 (the image's corner) has no byte before its colour to gather from.
  if (s.colours && _mm256_movemask_ps(_mm256_and_ps(paint, _mm256_castsi256_ps(_mm256_cmpeq_epi32(pixel, _mm256_setzero_si256())))))
    return updateScalar(s, row, vox);

  std::uint8_t* bytes = reinterpret_cast<std::uint8_t*>(vox);
  __m128i chunk[3];
  for (int c = 0; c < 3; ++c) chunk[c] = _mm_loadu_si128(reinterpret_cast<const __m128i*>(bytes + 16 * c));
  const __m128i tsdf16 = pickField(chunk, 0), weight8 = pickField(chunk, 1);

  const __m256 one = _mm256_set1_ps(1.f), half = _mm256_set1_ps(0.5f);
  const __m256i wold = _mm256_cvtepu8_epi32(weight8);
  const __m256 fw = _mm256_cvtepi32_ps(wold);
  const __m256 k = _mm256_div_ps(one, _mm256_cvtepi32_ps(_mm256_add_epi32(wold, _mm256_set1_epi32(1))));  // 1.f / (i + 1)
  const __m256 f = _mm256_min_ps(_mm256_mul_ps(sdf, _mm256_set1_ps(s.inv_truncation)), one);
  const __m256 tsdf = _mm256_cvtepi32_ps(_mm256_cvtepi16_epi32(tsdf16));
  const __m256 fnew = _mm256_mul_ps(_mm256_add_ps(_mm256_mul_ps(tsdf, fw), _mm256_mul_ps(f, _mm256_set1_ps(kTsdfScale))), k);
  const __m256 away = _mm256_blendv_ps(_mm256_set1_ps(-0.5f), half, _mm256_cmp_ps(fnew, _mm256_setzero_ps(), _CMP_GE_OQ));
  const __m256i rounded = _mm256_cvttps_epi32(_mm256_add_ps(fnew, away));
  const __m128i tsdf_new = _mm_packs_epi32(_mm256_castsi256_si128(rounded), _mm256_extracti128_si256(rounded, 1));
  const __m256i wnew = _mm256_min_epi32(_mm256_add_epi32(wold, _mm256_set1_epi32(1)), _mm256_set1_epi32(s.max_weight));
  const __m128i wnew16 = _mm_packus_epi32(_mm256_castsi256_si128(wnew), _mm256_extracti128_si256(wnew, 1));

  __m128i up16, up8;
  narrow(update, up16, up8);
  __m128i field[5];
  field[0] = _mm_blendv_epi8(tsdf16, tsdf_new, up16);
  field[1] = _mm_blendv_epi8(weight8, _mm_packus_epi16(wnew16, wnew16), up8);
  for (int ch = 2; ch < 5; ++ch) field[ch] = pickField(chunk, ch);
  if (s.colours && _mm256_movemask_ps(paint)) {
    // Each lane's pixel as the 4 bytes ending with it (the byte before is the previous pixel's red,
    // discarded), so no read passes the image's last byte.
    const __m256i offset = _mm256_sub_epi32(_mm256_mullo_epi32(pixel, _mm256_set1_epi32(3)), _mm256_set1_epi32(1));
    const __m256i bgr = _mm256_mask_i32gather_epi32(_mm256_setzero_si256(), reinterpret_cast<const int*>(s.colours), offset,
                                                    _mm256_castps_si256(paint), 1);
    const __m256i byte_mask = _mm256_set1_epi32(0xff);
    // The voxel's r takes the pixel's red (c[2]), g its green, b its blue (c[0]).
    const __m256 c_b = _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32(bgr, 8), byte_mask));
    const __m256 c_g = _mm256_cvtepi32_ps(_mm256_and_si256(_mm256_srli_epi32(bgr, 16), byte_mask));
    const __m256 c_r = _mm256_cvtepi32_ps(_mm256_srli_epi32(bgr, 24));
    // Black (0, 0, 0) is no colour, as in the scalar loop: those lanes are not painted.
    const __m256 coloured = _mm256_andnot_ps(
        _mm256_castsi256_ps(_mm256_cmpeq_epi32(_mm256_srli_epi32(bgr, 8), _mm256_setzero_si256())), paint);
    __m128i paint16, paint8;
    narrow(coloured, paint16, paint8);
    // A voxel still black takes its first colour whole, as in the scalar loop.
    const __m256i rgb = _mm256_cvtepu8_epi32(_mm_or_si128(_mm_or_si128(field[2], field[3]), field[4]));
    const __m256 unpainted = _mm256_castsi256_ps(_mm256_cmpeq_epi32(rgb, _mm256_setzero_si256()));
    const __m256 cfw = _mm256_blendv_ps(fw, _mm256_setzero_ps(), unpainted), ck = _mm256_blendv_ps(k, one, unpainted);
    field[2] = _mm_blendv_epi8(field[2], averageColour(field[2], c_r, cfw, ck), paint8);
    field[3] = _mm_blendv_epi8(field[3], averageColour(field[3], c_g, cfw, ck), paint8);
    field[4] = _mm_blendv_epi8(field[4], averageColour(field[4], c_b, cfw, ck), paint8);
  }
  for (int c = 0; c < 3; ++c) {
    __m128i out = shuffle(field[0], kTables.place[0][c]);
    for (int f = 1; f < 5; ++f) out = _mm_or_si128(out, shuffle(field[f], kTables.place[f][c]));
    _mm_storeu_si128(reinterpret_cast<__m128i*>(bytes + 16 * c), out);
  }
  return __builtin_popcount(static_cast<unsigned>(lanes));
}

}  // namespace

VoxelUpdater::VoxelUpdater(float truncation, int max_weight, const cv::Vec3b* colours, bool simd)
    : s_{truncation, 1.f / truncation, max_weight, colours}, avx2_(simd && cpuHasAvx2()) {}

int VoxelUpdater::updateRow(const VoxelRowSamples& row, Voxel* voxels) const {
  return avx2_ ? updateAvx2(s_, row, voxels) : updateScalar(s_, row, voxels);
}

}  // namespace vofusion::fusion
