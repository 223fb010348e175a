#include "vofusion/features/hamming_matcher.h"

#include <algorithm>
#include <cstdint>
#include <cstring>
#include <limits>
#include <stdexcept>
#include <utility>

#include <immintrin.h>

#include "vofusion/core/cpu_features.h"

namespace vofusion {

namespace {

// Distance between two descriptors of `words` 64-bit words (zero-padded copies); rows of `ref`
// one after the other. Two builds, chosen when the program loads: with the POPCNT instruction
// where the CPU has it.
__attribute__((target_clones("popcnt", "default")))
void distancesScalar(const std::uint64_t* cur, int n_cur, const std::uint64_t* ref, int n_ref, int words,
                     int* fwd_idx, int* fwd_d, int* bwd_idx, int* bwd_d) {
  for (int i = 0; i < n_cur; ++i) {
    const std::uint64_t* a = cur + std::size_t(i) * words;
    int best = std::numeric_limits<int>::max(), best_j = -1;
    for (int j = 0; j < n_ref; ++j) {
      const std::uint64_t* b = ref + std::size_t(j) * words;
      int d = 0;
      for (int k = 0; k < words; ++k) d += __builtin_popcountll(a[k] ^ b[k]);
      if (d < best) best = d, best_j = j;  // strict: ties keep the earlier row
      if (d < bwd_d[j]) bwd_d[j] = d, bwd_idx[j] = i;
    }
    fwd_idx[i] = best_j;
    fwd_d[i] = best;
  }
}

// Of eight lanes' nearest rows (distance, row; row -1 where a lane saw none), the nearest: among
// equal distances the earliest row, as a row-by-row search finds it.
__attribute__((target("avx2"), always_inline)) inline std::pair<int, int> nearestLane(__m256i distance, __m256i row) {
  alignas(32) int d[8], j[8];
  _mm256_store_si256(reinterpret_cast<__m256i*>(d), distance);
  _mm256_store_si256(reinterpret_cast<__m256i*>(j), row);
  int best = std::numeric_limits<int>::max(), best_j = -1;
  for (int l = 0; l < 8; ++l)
    if (j[l] >= 0 && (d[l] < best || (d[l] == best && j[l] < best_j))) best = d[l], best_j = j[l];
  return {best, best_j};
}

// The same, eight reference rows at a time with AVX-512's 64-bit popcount (Ice Lake, Zen 4 and
// later). `ref_t` holds the reference word-major: word k of row j at k * stride + j, stride a
// multiple of 8. Each lane keeps its own nearest row with a strict <, so among equal distances the
// earliest row wins, as above.
__attribute__((target("avx512f,avx512vl,avx512vpopcntdq")))
void distancesAvx512(const std::uint64_t* cur, int n_cur, const std::uint64_t* ref_t, int n_ref, int stride, int words,
                     int* fwd_idx, int* fwd_d, int* bwd_idx, int* bwd_d) {
  const __m256i eight = _mm256_set1_epi32(8);
  for (int i = 0; i < n_cur; ++i) {
    const std::uint64_t* a = cur + std::size_t(i) * words;
    __m256i best = _mm256_set1_epi32(std::numeric_limits<int>::max()), best_j = _mm256_set1_epi32(-1);
    __m256i j_lanes = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
    const __m256i row = _mm256_set1_epi32(i);
    for (int j0 = 0; j0 < n_ref; j0 += 8) {
      const __mmask8 valid = n_ref - j0 >= 8 ? __mmask8(0xff) : __mmask8((1u << (n_ref - j0)) - 1);
      __m512i sum = _mm512_setzero_si512();
      for (int k = 0; k < words; ++k) {
        const __m512i b = _mm512_loadu_si512(ref_t + std::size_t(k) * stride + j0);
        sum = _mm512_add_epi64(sum, _mm512_popcnt_epi64(_mm512_xor_si512(b, _mm512_set1_epi64(std::int64_t(a[k])))));
      }
      const __m256i d = _mm512_maskz_cvtepi64_epi32(0xff, sum);  // not the unmasked form: GCC 12 warns of its undefined operand
      const __m256i bd = _mm256_maskz_loadu_epi32(valid, bwd_d + j0);
      const __mmask8 nearer = _mm256_mask_cmplt_epi32_mask(valid, d, bd);
      _mm256_mask_storeu_epi32(bwd_d + j0, nearer, d);
      _mm256_mask_storeu_epi32(bwd_idx + j0, nearer, row);
      const __mmask8 better = _mm256_mask_cmplt_epi32_mask(valid, d, best);
      best = _mm256_mask_mov_epi32(best, better, d);
      best_j = _mm256_mask_mov_epi32(best_j, better, j_lanes);
      j_lanes = _mm256_add_epi32(j_lanes, eight);
    }
    const auto [b, b_j] = nearestLane(best, best_j);
    fwd_idx[i] = b_j;
    fwd_d[i] = b;
  }
}

// Each byte's set bits: `nibble_bits` holds the count of each 4-bit value.
__attribute__((target("avx2"), always_inline)) inline __m256i bitsPerByte(__m256i nibble_bits, __m256i low_nibble, __m256i x) {
  return _mm256_add_epi8(_mm256_shuffle_epi8(nibble_bits, _mm256_and_si256(x, low_nibble)),
                         _mm256_shuffle_epi8(nibble_bits, _mm256_and_si256(_mm256_srli_epi16(x, 4), low_nibble)));
}

// The same with AVX2, which has no popcount instruction for vectors: bytes counted by table lookup
// (vpshufb on each nibble), summed over the words in bytes and then per 64-bit lane (vpsadbw). Eight
// reference rows at a time, two vectors of four; `ref_t` as for distancesAvx512. On an AMD EPYC
// without AVX-512, 1.8x fewer perf samples than the scalar build in whole runs (loop scene, xyz).
// Details in bench/results/2026-11-29-hamming-avx2.md.
__attribute__((target("avx2")))
void distancesAvx2(const std::uint64_t* cur, int n_cur, const std::uint64_t* ref_t, int n_ref, int stride, int words,
                   int* fwd_idx, int* fwd_d, int* bwd_idx, int* bwd_d) {
  const __m256i nibble_bits = _mm256_setr_epi8(0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4,  //
                                               0, 1, 1, 2, 1, 2, 2, 3, 1, 2, 2, 3, 2, 3, 3, 4);
  const __m256i low_nibble = _mm256_set1_epi8(0x0f), zero = _mm256_setzero_si256(), eight = _mm256_set1_epi32(8);
  const __m256i lane_index = _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7);
  // The two vectors' four 64-bit sums interleaved as 32-bit lanes, put back in row order.
  const __m256i row_order = _mm256_setr_epi32(0, 2, 4, 6, 1, 3, 5, 7);
  // A byte's count grows by at most 8 a word: after 31 words it is at most 248, so the bytes are
  // summed into the 64-bit lanes every 31 words.
  constexpr int kWordsPerByteSum = 31;
  for (int i = 0; i < n_cur; ++i) {
    const std::uint64_t* a = cur + std::size_t(i) * words;
    __m256i best = _mm256_set1_epi32(std::numeric_limits<int>::max()), best_j = _mm256_set1_epi32(-1);
    __m256i j_lanes = lane_index;
    const __m256i row = _mm256_set1_epi32(i);
    for (int j0 = 0; j0 < n_ref; j0 += 8) {
      __m256i sum0 = zero, sum1 = zero;
      for (int k0 = 0; k0 < words; k0 += kWordsPerByteSum) {
        __m256i bytes0 = zero, bytes1 = zero;
        for (int k = k0; k < std::min(words, k0 + kWordsPerByteSum); ++k) {
          const __m256i ak = _mm256_set1_epi64x(std::int64_t(a[k]));
          const std::uint64_t* b = ref_t + std::size_t(k) * stride + j0;
          bytes0 = _mm256_add_epi8(bytes0, bitsPerByte(nibble_bits, low_nibble, _mm256_xor_si256(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(b)), ak)));
          bytes1 = _mm256_add_epi8(bytes1, bitsPerByte(nibble_bits, low_nibble, _mm256_xor_si256(_mm256_loadu_si256(reinterpret_cast<const __m256i*>(b + 4)), ak)));
        }
        sum0 = _mm256_add_epi64(sum0, _mm256_sad_epu8(bytes0, zero));
        sum1 = _mm256_add_epi64(sum1, _mm256_sad_epu8(bytes1, zero));
      }
      const __m256i d = _mm256_permutevar8x32_epi32(_mm256_or_si256(sum0, _mm256_slli_epi64(sum1, 32)), row_order);
      const __m256i valid = _mm256_cmpgt_epi32(_mm256_set1_epi32(n_ref - j0), lane_index);
      const __m256i bd = _mm256_maskload_epi32(bwd_d + j0, valid);
      const __m256i nearer = _mm256_and_si256(valid, _mm256_cmpgt_epi32(bd, d));
      _mm256_maskstore_epi32(bwd_d + j0, nearer, d);
      _mm256_maskstore_epi32(bwd_idx + j0, nearer, row);
      const __m256i better = _mm256_and_si256(valid, _mm256_cmpgt_epi32(best, d));
      best = _mm256_blendv_epi8(best, d, better);
      best_j = _mm256_blendv_epi8(best_j, j_lanes, better);
      j_lanes = _mm256_add_epi32(j_lanes, eight);
    }
    const auto [b, b_j] = nearestLane(best, best_j);
    fwd_idx[i] = b_j;
    fwd_d[i] = b;
  }
}

// Rows as zero-padded 64-bit words (rows of a cv::Mat need not be 8-byte aligned).
std::vector<std::uint64_t> asWords(const cv::Mat& m, int first_row, int words) {
  std::vector<std::uint64_t> out(std::size_t(m.rows - first_row) * words, 0);
  for (int r = first_row; r < m.rows; ++r)
    std::memcpy(&out[std::size_t(r - first_row) * words], m.ptr(r), m.cols);
  return out;
}

// The same words, word-major with `stride` (a multiple of 8) rows per word.
std::vector<std::uint64_t> transposed(const std::vector<std::uint64_t>& rows, int n, int words, int stride) {
  std::vector<std::uint64_t> out(std::size_t(stride) * words, 0);
  for (int j = 0; j < n; ++j)
    for (int k = 0; k < words; ++k) out[std::size_t(k) * stride + j] = rows[std::size_t(j) * words + k];
  return out;
}

}  // namespace

CrossCheckedHammingMatcher::CrossCheckedHammingMatcher(Build build) : build_(build) {
  if (build_ == Build::Fastest) build_ = cpuHasAvx512Popcount() ? Build::Avx512 : cpuHasAvx2() ? Build::Avx2 : Build::Scalar;
  if (!available(build_)) throw std::invalid_argument("CrossCheckedHammingMatcher: this CPU cannot run the build asked for");
}

bool CrossCheckedHammingMatcher::available(Build build) {
  switch (build) {
    case Build::Avx512: return cpuHasAvx512Popcount();
    case Build::Avx2: return cpuHasAvx2();
    default: return true;
  }
}

void CrossCheckedHammingMatcher::add(const cv::Mat& cur, const cv::Mat& ref) {
  if (cur.rows <= rows_ || ref.empty()) return;
  CV_Assert(cur.type() == CV_8UC1 && ref.type() == CV_8UC1 && cur.cols == ref.cols);
  CV_Assert(ref_words_.empty() || ref.size() == ref_size_);
  const int words = (cur.cols + 7) / 8, n = cur.rows - rows_;
  const bool eight_rows = build_ == Build::Avx512 || build_ == Build::Avx2;
  const int stride = (ref.rows + 7) / 8 * 8;
  // The reference is the same at every call: put in the build's layout once.
  if (ref_words_.empty()) {
    ref_size_ = ref.size();
    ref_words_ = asWords(ref, 0, words);
    if (eight_rows) ref_words_ = transposed(ref_words_, ref.rows, words, stride);
  }
  const auto a = asWords(cur, rows_, words);
  std::vector<int> fwd_idx(n), fwd_d(n), bwd_idx(ref.rows, -1), bwd_d(ref.rows, std::numeric_limits<int>::max());
  if (eight_rows) {
    const auto distances = build_ == Build::Avx512 ? distancesAvx512 : distancesAvx2;
    distances(a.data(), n, ref_words_.data(), ref.rows, stride, words, fwd_idx.data(), fwd_d.data(), bwd_idx.data(),
              bwd_d.data());
  } else {
    distancesScalar(a.data(), n, ref_words_.data(), ref.rows, words, fwd_idx.data(), fwd_d.data(), bwd_idx.data(),
                    bwd_d.data());
  }
  for (int i = 0; i < n; ++i) forward_.emplace_back(rows_ + i, fwd_idx[i], float(fwd_d[i]));
  backward_.resize(ref.rows, cv::DMatch(-1, -1, std::numeric_limits<float>::max()));
  // Earlier parts hold earlier rows: on a tie the part seen first keeps its row.
  for (int j = 0; j < ref.rows; ++j)
    if (bwd_idx[j] >= 0 && float(bwd_d[j]) < backward_[j].distance)
      backward_[j] = cv::DMatch(j, rows_ + bwd_idx[j], float(bwd_d[j]));
  rows_ = cur.rows;
}

std::vector<cv::DMatch> CrossCheckedHammingMatcher::crossChecked() const {
  std::vector<cv::DMatch> out;
  for (const auto& m : forward_)
    if (backward_[m.trainIdx].trainIdx == m.queryIdx) out.push_back(m);
  return out;
}

}  // namespace vofusion
