#pragma once
// Brute-force Hamming matching with cross-check, the paper's matcher: the same matches as
// cv::BFMatcher(NORM_HAMMING, crossCheck = true), ties to the earlier row as it does, but each
// descriptor pair's distance is computed once for both directions (BFMatcher walks the distance
// matrix twice) and the current frame's descriptors can arrive in parts: the STAR ones are matched
// while NARF still runs.
#include <cstdint>
#include <vector>

#include <opencv2/core.hpp>

namespace vofusion {

class CrossCheckedHammingMatcher {
 public:
  // The distance loop's builds, all giving the same matches: AVX-512's popcount, AVX2's table
  // lookup (both eight reference rows at a time) or the scalar popcount. Fastest: the first of these
  // this CPU has. The others are for tests; Avx512 and Avx2 throw std::invalid_argument where the CPU
  // lacks them (available() says).
  enum class Build { Fastest, Avx512, Avx2, Scalar };
  explicit CrossCheckedHammingMatcher(Build build = Build::Fastest);
  static bool available(Build build);
  // Matches the rows of `cur` not seen yet (cur grows between calls; the first rows must stay the
  // same) against `ref`, which must be the same at every call (a reference of another size throws
  // cv::Exception: the words kept from the first would be read past). CV_8U descriptors, any width.
  void add(const cv::Mat& cur, const cv::Mat& ref);
  // queryIdx = row of cur, trainIdx = row of ref; each the other's nearest, in cur's row order.
  std::vector<cv::DMatch> crossChecked() const;
  int rowsMatched() const { return rows_; }

 private:
  std::vector<cv::DMatch> forward_;   // per current row: nearest reference row
  std::vector<cv::DMatch> backward_;  // per reference row: nearest current row so far
  std::vector<std::uint64_t> ref_words_;  // the reference as 64-bit words, in the layout build_ reads
  cv::Size ref_size_;                     // of the reference ref_words_ holds
  int rows_ = 0;
  Build build_;
};

}  // namespace vofusion
