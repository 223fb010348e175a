// ColourTimeEvidence: the sign test that decides which velocity corrects a recording's colour offsets.
#include <gtest/gtest.h>

#include "vofusion/odometry/colour_time_evidence.h"

using namespace vofusion;

namespace {
// `capture` votes for capture among `capture + interval`, spread evenly.
void vote(ColourTimeEvidence& e, int capture, int interval) {
  const int n = capture + interval;
  for (int i = 0; i < n; ++i) e.add((i + 1) * capture / n > i * capture / n);
}
}  // namespace

TEST(ColourTimeEvidence, NoDecisionBeforeTenVotes) {
  ColourTimeEvidence e;
  vote(e, 9, 0);
  EXPECT_FALSE(e.captureFitsBetter());  // 9 of 9 is significant, but below the approximation's floor
  vote(e, 1, 0);
  EXPECT_TRUE(e.captureFitsBetter());
  EXPECT_EQ(e.compared(), 10);
  EXPECT_EQ(e.captureBetter(), 10);
}

TEST(ColourTimeEvidence, SwitchesOnASignificantMajorityOnly) {
  ColourTimeEvidence e;
  vote(e, 12, 8);  // 60 %: z = 0.89
  EXPECT_FALSE(e.captureFitsBetter());
  vote(e, 18, 2);  // 30 of 40: z = 3.16
  EXPECT_TRUE(e.captureFitsBetter());
  vote(e, 0, 12);  // 30 of 52: z = 1.11, neither way significant: the choice stays
  EXPECT_TRUE(e.captureFitsBetter());
  vote(e, 0, 20);  // 30 of 72: z = -1.41
  EXPECT_TRUE(e.captureFitsBetter());
  vote(e, 0, 10);  // 30 of 82: z = -2.43
  EXPECT_FALSE(e.captureFitsBetter());
}

TEST(ColourTimeEvidence, ArrivalLikeVotesNeverSwitch) {
  ColourTimeEvidence e;
  for (int i = 0; i < 300; ++i) e.add(i % 3 == 0);  // a third for capture (rpy_first100: 19 of 63)
  EXPECT_FALSE(e.captureFitsBetter());
}

TEST(ColourTimeEvidence, SettledTestVotesOnOneFrameInTen) {
  ColourTimeEvidence e;
  int votes = 0;
  for (int frame = 0; frame < 200; ++frame)
    if (e.wantsVote()) e.add(true), ++votes;
  // z >= 3.09 from 10 votes on (10 of 10: z = 3.16); then one frame in kSettledEvery.
  EXPECT_EQ(votes, 10 + 190 / ColourTimeEvidence::kSettledEvery);
  EXPECT_TRUE(e.captureFitsBetter());
  ColourTimeEvidence undecided;
  int all = 0;
  for (int frame = 0; frame < 100; ++frame)
    if (undecided.wantsVote()) undecided.add(frame % 2 == 0), ++all;
  EXPECT_EQ(all, 100);
}
