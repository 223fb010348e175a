#include "vofusion/features/hamming_matcher.h"

#include <cstdint>
#include <cstring>
#include <limits>

namespace vofusion {

namespace {

// Distance between two descriptors of `words` 64-bit words (zero-padded copies).
// Two builds, chosen when the program loads: with the POPCNT instruction where the CPU has it.
__attribute__((target_clones("popcnt", "default")))
void distances(const std::uint64_t* cur, int n_cur, const std::uint64_t* ref, int n_ref, int words,
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

// Rows as zero-padded 64-bit words (rows of a cv::Mat need not be 8-byte aligned).
std::vector<std::uint64_t> asWords(const cv::Mat& m, int first_row, int words) {
  std::vector<std::uint64_t> out(std::size_t(m.rows - first_row) * words, 0);
  for (int r = first_row; r < m.rows; ++r)
    std::memcpy(&out[std::size_t(r - first_row) * words], m.ptr(r), m.cols);
  return out;
}

}  // namespace

void CrossCheckedHammingMatcher::add(const cv::Mat& cur, const cv::Mat& ref) {
  if (cur.rows <= rows_ || ref.empty()) return;
  CV_Assert(cur.type() == CV_8UC1 && ref.type() == CV_8UC1 && cur.cols == ref.cols);
  const int words = (cur.cols + 7) / 8, n = cur.rows - rows_;
  const auto a = asWords(cur, rows_, words), b = asWords(ref, 0, words);
  std::vector<int> fwd_idx(n), fwd_d(n), bwd_idx(ref.rows, -1), bwd_d(ref.rows, std::numeric_limits<int>::max());
  distances(a.data(), n, b.data(), ref.rows, words, fwd_idx.data(), fwd_d.data(), bwd_idx.data(), bwd_d.data());
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
