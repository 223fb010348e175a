// IndexedFrameSource: next() walks read(0..size()-1) once, rewind() starts over; used by the TUM,
// 7-Scenes and synthetic sources.
#include <gtest/gtest.h>

#include <vector>

#include "vofusion/io/frame_source.h"
#include "vofusion/sim/synthetic_source.h"

using namespace vofusion;

namespace {
// Frame i is stamped i * 10 and counts the reads.
class Counting : public IndexedFrameSource {
 public:
  explicit Counting(std::size_t n) : n_(n) {}
  Frame read(std::size_t i) const override {
    reads.push_back(i);
    Frame f;
    f.index = i;
    f.timestamp = 10.0 * double(i);
    return f;
  }
  std::size_t size() const override { return n_; }
  std::string name() const override { return "counting"; }
  mutable std::vector<std::size_t> reads;

 private:
  std::size_t n_;
};
}  // namespace

TEST(IndexedFrameSource, NextWalksEveryIndexOnceAndRewindStartsOver) {
  Counting src(3);
  Frame f;
  for (std::size_t i = 0; i < 3; ++i) {
    ASSERT_TRUE(src.next(f));
    EXPECT_EQ(f.timestamp, 10.0 * double(i));
  }
  EXPECT_FALSE(src.next(f));
  EXPECT_FALSE(src.next(f));  // stays at the end
  EXPECT_EQ(src.reads, (std::vector<std::size_t>{0, 1, 2}));
  src.rewind();
  ASSERT_TRUE(src.next(f));
  EXPECT_EQ(f.timestamp, 0.0);
  Counting empty(0);
  EXPECT_FALSE(empty.next(f));
  EXPECT_TRUE(empty.reads.empty());
}

TEST(IndexedFrameSource, SyntheticSourceNextMatchesRead) {
  sim::SimOptions o;
  o.frames = 3;
  o.camera = o.camera.scaled(0.25);
  sim::SyntheticSource src(o);
  Frame f;
  for (std::size_t i = 0; i < 3; ++i) {
    ASSERT_TRUE(src.next(f));
    const Frame r = src.read(i);
    EXPECT_EQ(f.timestamp, r.timestamp);
    EXPECT_EQ(cv::norm(f.depth, r.depth, cv::NORM_INF), 0.0);
  }
  EXPECT_FALSE(src.next(f));
  src.rewind();
  ASSERT_TRUE(src.next(f));
  EXPECT_EQ(f.timestamp, src.read(0).timestamp);
}
