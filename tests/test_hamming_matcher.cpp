// The cross-checked Hamming matcher gives exactly cv::BFMatcher(NORM_HAMMING, crossCheck = true)'s
// matches, also when the current descriptors arrive in parts and when many distances tie, in the
// scalar build and (where the CPU has them) the AVX2 and AVX-512 ones.
#include <gtest/gtest.h>

#include <opencv2/features2d.hpp>

#include "vofusion/features/hamming_matcher.h"

using namespace vofusion;

namespace {
// Few distinct bit patterns: many equal distances, so tie-breaking is exercised.
cv::Mat randomDescriptors(int rows, int cols, cv::RNG& rng, int levels) {
  cv::Mat m(rows, cols, CV_8U);
  for (int r = 0; r < rows; ++r)
    for (int c = 0; c < cols; ++c) m.at<uchar>(r, c) = static_cast<uchar>(rng.uniform(0, levels));
  return m;
}

void expectSame(const std::vector<cv::DMatch>& got, const std::vector<cv::DMatch>& want) {
  ASSERT_EQ(got.size(), want.size());
  for (std::size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].queryIdx, want[i].queryIdx) << i;
    EXPECT_EQ(got[i].trainIdx, want[i].trainIdx) << i;
    EXPECT_EQ(got[i].distance, want[i].distance) << i;
  }
}
}  // namespace

namespace {
// Every build sees the same descriptors (the RNG starts again for each).
void expectSameAsBFMatcher(CrossCheckedHammingMatcher::Build build) {
  cv::RNG rng(7);
  for (const int cols : {32, 61}) {
    // 248 and 251 reference rows: a last block of eight rows full and part-full.
    for (const int levels : {2, 256}) {
      const cv::Mat cur = randomDescriptors(300, cols, rng, levels), ref = randomDescriptors(cols == 32 ? 248 : 251, cols, rng, levels);
      std::vector<cv::DMatch> want;
      cv::BFMatcher(cv::NORM_HAMMING, true).match(cur, ref, want);
      ASSERT_GT(want.size(), 20u);
      CrossCheckedHammingMatcher whole(build);
      whole.add(cur, ref);
      expectSame(whole.crossChecked(), want);
      // In parts, as the odometry feeds it (STAR rows first, NARF rows once they are described).
      CrossCheckedHammingMatcher parts(build);
      parts.add(cur.rowRange(0, 120), ref);
      parts.add(cur.rowRange(0, 121), ref);
      parts.add(cur, ref);
      parts.add(cur, ref);  // nothing new: no effect
      EXPECT_EQ(parts.rowsMatched(), cur.rows);
      expectSame(parts.crossChecked(), want);
    }
  }
  // Fewer reference rows than one block of eight.
  for (int n = 1; n < 8; ++n) {
    const cv::Mat cur = randomDescriptors(40, 32, rng, 4), ref = randomDescriptors(n, 32, rng, 4);
    std::vector<cv::DMatch> want;
    cv::BFMatcher(cv::NORM_HAMMING, true).match(cur, ref, want);
    CrossCheckedHammingMatcher m(build);
    m.add(cur, ref);
    expectSame(m.crossChecked(), want);
  }
}
}  // namespace

using Build = CrossCheckedHammingMatcher::Build;

TEST(HammingMatcher, SameAsBFMatcherCrossCheck) { expectSameAsBFMatcher(Build::Scalar); }

TEST(HammingMatcher, Avx2SameAsBFMatcherCrossCheck) {
  if (!CrossCheckedHammingMatcher::available(Build::Avx2)) GTEST_SKIP() << "no AVX2 on this CPU";
  expectSameAsBFMatcher(Build::Avx2);
}

TEST(HammingMatcher, Avx512SameAsBFMatcherCrossCheck) {
  if (!CrossCheckedHammingMatcher::available(Build::Avx512)) GTEST_SKIP() << "no AVX-512 popcount on this CPU";
  expectSameAsBFMatcher(Build::Avx512);
}

TEST(HammingMatcher, FastestSameAsBFMatcherCrossCheck) { expectSameAsBFMatcher(Build::Fastest); }

// 256-byte descriptors (32 64-bit words), some reference rows the complement of a current row: each
// byte of that pair counts 8 bits in every word, 256 in all, which a byte would hold as 0. The AVX2
// build sums its byte counts every 31 words, so those pairs stay the farthest, as BFMatcher has them.
// Every build the CPU runs.
TEST(HammingMatcher, LongDescriptorsSameAsBFMatcher) {
  cv::RNG rng(3);
  const cv::Mat cur = randomDescriptors(40, 256, rng, 256);
  cv::Mat ref;
  cv::vconcat(randomDescriptors(30, 256, rng, 256), ~cur.rowRange(0, 10), ref);
  std::vector<cv::DMatch> want;
  cv::BFMatcher(cv::NORM_HAMMING, true).match(cur, ref, want);
  for (const Build build : {Build::Scalar, Build::Avx2, Build::Avx512}) {
    if (!CrossCheckedHammingMatcher::available(build)) continue;
    SCOPED_TRACE(int(build));
    CrossCheckedHammingMatcher m(build);
    m.add(cur, ref);
    expectSame(m.crossChecked(), want);
  }
}

TEST(HammingMatcher, EmptyReferenceGivesNoMatches) {
  cv::RNG rng(1);
  CrossCheckedHammingMatcher m;
  m.add(randomDescriptors(10, 32, rng, 256), cv::Mat());
  EXPECT_TRUE(m.crossChecked().empty());
}

// The reference is put in the build's layout at the first call and kept: a reference of another size
// later is refused, where its rows were read past the words kept from the first.
TEST(HammingMatcher, AReferenceOfAnotherSizeIsRefused) {
  cv::RNG rng(4);
  const cv::Mat cur = randomDescriptors(20, 32, rng, 256);
  CrossCheckedHammingMatcher m;
  m.add(cur.rowRange(0, 10), randomDescriptors(5, 32, rng, 256));
  EXPECT_THROW(m.add(cur, randomDescriptors(40, 32, rng, 256)), cv::Exception);
}
