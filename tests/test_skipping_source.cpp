// SkippingSource: a damaged frame costs that frame (reported once), a recording cut short ends at its
// last whole frame, strict mode stops at the first damage, and more than one frame in five damaged
// stops the run. Also through PrefetchingSource, as the apps read.
#include <gtest/gtest.h>

#include <set>
#include <vector>

#include "vofusion/io/prefetching_source.h"
#include "vofusion/io/skipping_source.h"
#include "vofusion/pipeline/run_outputs.h"

using namespace vofusion;

namespace {
// n frames; those in `damaged` throw as an unreadable image would; with `cut`, the recording ends with
// RecordingCutShort instead of its clean end.
class Damaged : public IndexedFrameSource {
 public:
  Damaged(std::size_t n, std::set<std::size_t> damaged, bool cut = false) : n_(n), damaged_(std::move(damaged)), cut_(cut) {}
  Frame read(std::size_t i) const override {
    if (damaged_.count(i)) throw InputError("depth/" + std::to_string(i) + ".png", "depth image is missing");
    Frame f;
    f.index = i;
    return f;
  }
  bool next(Frame& f) override {
    if (!IndexedFrameSource::next(f)) {
      if (cut_) throw RecordingCutShort("rec.rawlog", "truncated rawlog (ends inside entry 9)");
      return false;
    }
    return true;
  }
  std::size_t size() const override { return n_; }
  std::string name() const override { return "recording"; }

 private:
  std::size_t n_;
  std::set<std::size_t> damaged_;
  bool cut_;
};

std::vector<std::size_t> indicesRead(FrameSource& src) {
  std::vector<std::size_t> out;
  Frame f;
  while (src.next(f)) out.push_back(f.index);
  return out;
}
}  // namespace

TEST(SkippingSource, DamagedFramesAreSkippedAndReportedOnce) {
  std::vector<std::string> lines;
  auto skipping = std::make_unique<SkippingSource>(std::make_unique<Damaged>(10, std::set<std::size_t>{0, 4}), false,
                                                   [&](const std::string& l) { lines.push_back(l); });
  const SkippingSource& s = *skipping;
  PrefetchingSource src(std::move(skipping));
  EXPECT_EQ(indicesRead(src), (std::vector<std::size_t>{1, 2, 3, 5, 6, 7, 8, 9}));
  ASSERT_EQ(s.skipped().size(), 2u);
  EXPECT_EQ(s.skipped()[1].position, 4u);
  EXPECT_EQ(s.skipped()[1].file, "depth/4.png");
  EXPECT_EQ(s.skipped()[1].problem, "depth image is missing");
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[1], "depth/4.png: depth image is missing (frame 4 skipped)");
  EXPECT_TRUE(s.cutShort().empty());
}

TEST(SkippingSource, StrictStopsAtTheFirstDamage) {
  SkippingSource src(std::make_unique<Damaged>(10, std::set<std::size_t>{4}), true);
  Frame f;
  for (int i = 0; i < 4; ++i) ASSERT_TRUE(src.next(f));
  try {
    src.next(f);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_STREQ(e.what(), "depth/4.png: depth image is missing");
  }
}

TEST(SkippingSource, ARecordingCutShortEndsAtItsLastWholeFrame) {
  std::vector<std::string> lines;
  SkippingSource src(std::make_unique<Damaged>(6, std::set<std::size_t>{}, true), false,
                     [&](const std::string& l) { lines.push_back(l); });
  EXPECT_EQ(indicesRead(src).size(), 6u);
  EXPECT_EQ(src.cutShort(), "truncated rawlog (ends inside entry 9)");
  ASSERT_EQ(lines.size(), 1u);
  EXPECT_EQ(lines[0], "rec.rawlog: truncated rawlog (ends inside entry 9) (the 6 frames before it are read)");
  // The frames read, a skipped one not among them.
  lines.clear();
  SkippingSource with_skip(std::make_unique<Damaged>(6, std::set<std::size_t>{2}, true), false,
                           [&](const std::string& l) { lines.push_back(l); });
  EXPECT_EQ(indicesRead(with_skip).size(), 5u);
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[1], "rec.rawlog: truncated rawlog (ends inside entry 9) (the 5 frames before it are read, 1 skipped as damaged)");
  SkippingSource strict(std::make_unique<Damaged>(6, std::set<std::size_t>{}, true), true);
  Frame f;
  for (int i = 0; i < 6; ++i) ASSERT_TRUE(strict.next(f));
  EXPECT_THROW(strict.next(f), InputError);
}

TEST(SkippingSource, MoreThanOneFrameInFiveDamagedStopsTheRun) {
  // 2 of 10 damaged: one in five, not more.
  SkippingSource fine(std::make_unique<Damaged>(10, std::set<std::size_t>{2, 3}), false);
  EXPECT_EQ(indicesRead(fine).size(), 8u);
  SkippingSource bad(std::make_unique<Damaged>(10, std::set<std::size_t>{2, 3, 7}), false);
  try {
    indicesRead(bad);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_EQ(e.file(), "recording");
    EXPECT_NE(std::string(e.what()).find("3 of 10 frames are damaged"), std::string::npos) << e.what();
  }
}

namespace {
// n frames from `first_good` on readable, those before it all damaged the same way; `odd` frames after
// it damaged too.
class BadStart : public IndexedFrameSource {
 public:
  BadStart(std::size_t n, std::size_t first_good, bool odd = false) : n_(n), first_good_(first_good), odd_(odd) {}
  Frame read(std::size_t i) const override {
    if (i < first_good_ || (odd_ && i % 2 == 1))
      throw InputError("depth/" + std::to_string(i) + ".png", "depth image must be 16-bit single channel");
    Frame f;
    f.index = i;
    return f;
  }
  std::size_t size() const override { return n_; }
  std::string name() const override { return "recording"; }

 private:
  std::size_t n_, first_good_;
  bool odd_;
};

// The one line a source stops with, read to its end; "" when it did not stop.
std::string stopLine(SkippingSource& src) {
  try {
    indicesRead(src);
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}
}  // namespace

// A problem every frame has (8-bit depth PNGs, say) is one line naming the first file, not one line per
// frame until a fifth of a long recording is gone.
TEST(SkippingSource, TheSameProblemOnEveryFirstFrameIsOneLine) {
  std::vector<std::string> lines;
  SkippingSource src(std::make_unique<BadStart>(2000, 2000), false, [&](const std::string& l) { lines.push_back(l); });
  EXPECT_EQ(stopLine(src), "depth/0.png: depth image must be 16-bit single channel, and so is every one of the first 10 "
                          "frames: the recording needs looking at");
  EXPECT_TRUE(lines.empty());
  // A few damaged frames before the first good one are listed once it is read, as any others.
  lines.clear();
  SkippingSource late(std::make_unique<BadStart>(2000, 2), false, [&](const std::string& l) { lines.push_back(l); });
  Frame f;
  ASSERT_TRUE(late.next(f));
  EXPECT_EQ(f.index, 2u);
  ASSERT_EQ(lines.size(), 2u);
  EXPECT_EQ(lines[0], "depth/0.png: depth image must be 16-bit single channel (frame 0 skipped)");
}

// The recording's problem is one line even when another problem sits beside it (the first colour image
// missing as well), and in a recording too short to reach the tenth frame before a fifth is gone.
TEST(SkippingSource, TheRecordingsProblemIsOneLineBesideAnotherAndInAShortRecording) {
  class TwoProblems : public BadStart {
   public:
    using BadStart::BadStart;
    Frame read(std::size_t i) const override {
      if (i == 0) throw InputError("rgb/0.png", "cannot read the colour image");
      return BadStart::read(i);
    }
  };
  std::vector<std::string> lines;
  SkippingSource src(std::make_unique<TwoProblems>(2000, 2000), false, [&](const std::string& l) { lines.push_back(l); });
  EXPECT_EQ(stopLine(src), "depth/1.png: depth image must be 16-bit single channel, and so are 10 of the first 11 frames: "
                          "the recording needs looking at");
  EXPECT_TRUE(lines.empty());
  SkippingSource short_one(std::make_unique<BadStart>(20, 20), false, [&](const std::string& l) { lines.push_back(l); });
  EXPECT_EQ(stopLine(short_one), "depth/0.png: depth image must be 16-bit single channel, and so is every one of the first 5 "
                                 "frames: the recording needs looking at");
  EXPECT_TRUE(lines.empty());
}

// A problem met on many frames is listed for the first few, then one line says the rest are not.
TEST(SkippingSource, AProblemOnManyFramesIsListedAFewTimes) {
  std::vector<std::string> lines;
  SkippingSource src(std::make_unique<BadStart>(1000, 0, true), false, [&](const std::string& l) { lines.push_back(l); });
  Frame f;
  for (int i = 0; i < 30; ++i) ASSERT_TRUE(src.next(f));  // frames 0, 2, .., 58 read; 1, 3, .., 57 skipped
  EXPECT_EQ(src.skipped().size(), 29u);
  ASSERT_EQ(lines.size(), SkippingSource::kLinesPerProblem);
  EXPECT_EQ(lines.back(), "depth/5.png: depth image must be 16-bit single channel (frame 5 skipped); later frames with "
                          "this problem are counted, not listed");
}

// An interrupted run lists the damaged frames it met, not those the read ahead skipped past the frame
// it stopped at (frames 5-7 here, met reading frame 8 while the run stopped at frame 4), nor a cut
// short it never reached.
TEST(SkippingSource, AnInterruptedRunReportsTheFramesItMetOnly) {
  SkippingSource src(std::make_unique<Damaged>(40, std::set<std::size_t>{1, 5, 6, 7}, true), false);
  Frame f;
  std::vector<std::size_t> read;
  for (int i = 0; i < 5; ++i) {  // 0, 2, 3, 4 (1 skipped), then the read ahead: 8 (5-7 skipped)
    ASSERT_TRUE(src.next(f));
    read.push_back(f.index);
  }
  ASSERT_EQ(read, (std::vector<std::size_t>{0, 2, 3, 4, 8}));
  while (src.next(f)) {
  }  // to the cut
  RunInfo stopped;
  reportSkipped(src, stopped, 4);  // frame 4 read, not processed: the run stopped there
  EXPECT_EQ(stopped.extra["frames_skipped"], 1u);
  EXPECT_EQ(stopped.extra["skipped_frames"][0]["frame"], 1u);
  EXPECT_FALSE(stopped.extra.contains("recording_cut_short"));
  RunInfo whole;
  reportSkipped(src, whole);
  EXPECT_EQ(whole.extra["frames_skipped"], 4u);
  EXPECT_TRUE(whole.extra.contains("recording_cut_short"));
}
