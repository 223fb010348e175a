// IndexedFrameSource: next() walks read(0..size()-1) once, rewind() starts over; used by the TUM,
// 7-Scenes and synthetic sources.
#include <gtest/gtest.h>

#include <unistd.h>

#include <new>
#include <set>
#include <vector>

#include <opencv2/core.hpp>

#include "vofusion/core/errors.h"
#include "vofusion/io/frame_source.h"
#include "vofusion/io/prefetching_source.h"
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

// A frame whose images need more memory than there is, or that OpenCV cannot decode (a TUM list naming
// a huge TIFF), costs that frame as any damage does, named by its source and index: it ended the run
// with a message naming no file. The next frame is read as usual.
TEST(IndexedFrameSource, OutOfMemoryOrAnOpenCvErrorCostsTheFrameOnly) {
  class Failing : public Counting {
   public:
    Failing() : Counting(3) {}
    Frame read(std::size_t i) const override {
      if (i == 0) throw std::bad_alloc();
      if (i == 1) cv::error(cv::Error::StsBadArg, "no decoder", "read", "here", 1);
      return Counting::read(i);
    }
  } src;
  Frame f;
  try {
    src.next(f);
    FAIL() << "no error";
  } catch (const DamagedFrame& e) {
    EXPECT_EQ(std::string(e.what()), "counting: frame 0: its images need more memory than there is");
  }
  try {
    src.next(f);
    FAIL() << "no error";
  } catch (const DamagedFrame& e) {
    EXPECT_NE(std::string(e.what()).find("counting: frame 1: its images cannot be decoded ("), std::string::npos) << e.what();
  }
  ASSERT_TRUE(src.next(f));
  EXPECT_EQ(f.timestamp, 20.0);
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

namespace {
// Throws InputError when frame `bad` is read.
class FailsAt : public Counting {
 public:
  FailsAt(std::size_t n, std::size_t bad) : Counting(n), bad_(bad) {}
  Frame read(std::size_t i) const override {
    if (i == bad_) throw InputError("frame " + std::to_string(i), "unreadable");
    return Counting::read(i);
  }

 private:
  std::size_t bad_;
};
}  // namespace

TEST(PrefetchingSource, HandsOutTheSameFramesInOrderAndRewinds) {
  PrefetchingSource src(std::make_unique<Counting>(4));
  EXPECT_EQ(src.size(), 4u);
  EXPECT_EQ(src.name(), "counting");
  for (int pass = 0; pass < 2; ++pass) {
    Frame f;
    for (std::size_t i = 0; i < 4; ++i) {
      ASSERT_TRUE(src.next(f));
      EXPECT_EQ(f.index, i);
      EXPECT_EQ(f.timestamp, 10.0 * double(i));
    }
    EXPECT_FALSE(src.next(f));
    EXPECT_FALSE(src.next(f));  // stays at the end
    src.rewind();
  }
}

TEST(PrefetchingSource, AnErrorSurfacesWithTheFrameThatCausedIt) {
  PrefetchingSource src(std::make_unique<FailsAt>(5, 2));
  Frame f;
  ASSERT_TRUE(src.next(f));
  ASSERT_TRUE(src.next(f));  // frame 2 is already being read (and failing) in the background
  EXPECT_EQ(f.index, 1u);
  try {
    src.next(f);
    FAIL() << "frame 2 should throw";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("frame 2"), std::string::npos);
  }
}

namespace {
// Records the thread each frame is read on, by the kernel's id (a pthread id is reused by the next
// thread as soon as one ends, and would not tell a thread per frame from one thread).
class ThreadRecording : public Counting {
 public:
  using Counting::Counting;
  Frame read(std::size_t i) const override {
    threads.insert(::gettid());
    return Counting::read(i);
  }
  mutable std::set<pid_t> threads;
};
}  // namespace

// Every frame is read ahead on one thread, the same from first to last and after a rewind: the readers'
// per-thread buffers (a frame's PNG bytes and inflated rows) are kept for the next frame. A thread per
// frame (std::async) made them fresh pages each time.
TEST(PrefetchingSource, ReadsEveryFrameOnOneThread) {
  auto inner = std::make_unique<ThreadRecording>(6);
  const ThreadRecording& recording = *inner;
  PrefetchingSource src(std::move(inner));
  Frame f;
  for (int pass = 0; pass < 2; ++pass) {
    while (src.next(f)) {
    }
    src.rewind();
  }
  EXPECT_EQ(recording.reads.size(), 12u);
  EXPECT_EQ(recording.threads.size(), 1u);
  EXPECT_EQ(recording.threads.count(::gettid()), 0u) << "read on the caller's thread";
}
