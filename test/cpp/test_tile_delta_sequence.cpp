#include <gtest/gtest.h>

#include "grid_puzzle_localization/tile_delta_sequence.hpp"

namespace gpl = grid_puzzle_localization;
using V = gpl::TileDeltaSequence::Verdict;

TEST(TileDeltaSequence, AppliesResetThenConsecutiveRevisions) {
  gpl::TileDeltaSequence seq;
  EXPECT_EQ(seq.accept(7, true), V::kApply);
  EXPECT_EQ(seq.accept(8, false), V::kApply);
  EXPECT_EQ(seq.accept(9, false), V::kApply);
  EXPECT_EQ(seq.accept(9, false), V::kIgnore);  // duplicate
  EXPECT_EQ(seq.accept(5, false), V::kIgnore);  // stale
  EXPECT_TRUE(seq.synchronised());
}

TEST(TileDeltaSequence, GapRequestsOneResendAndWaitsForTheReset) {
  gpl::TileDeltaSequence seq;
  EXPECT_EQ(seq.accept(3, false), V::kRequestResend);  // joined mid-stream without a reset
  EXPECT_EQ(seq.accept(4, false), V::kIgnore);         // resend pending: do not ask again
  EXPECT_EQ(seq.accept(5, true), V::kApply);
  EXPECT_EQ(seq.accept(7, false), V::kRequestResend);  // 6 was lost
  EXPECT_FALSE(seq.synchronised());
  EXPECT_EQ(seq.accept(8, false), V::kIgnore);
  seq.resendFailed();
  EXPECT_EQ(seq.accept(9, false), V::kRequestResend);  // the service was down: ask again
  EXPECT_EQ(seq.accept(10, true), V::kApply);
  EXPECT_EQ(seq.accept(11, false), V::kApply);
}

TEST(TileDeltaSequence, RevisionWrapAroundIsConsecutive) {
  gpl::TileDeltaSequence seq;
  EXPECT_EQ(seq.accept(0xffffffffu, true), V::kApply);
  EXPECT_EQ(seq.accept(0u, false), V::kApply);
}

TEST(TileDeltaSequence, DeltaNotAppliedRequestsTheWindowWithTheNextDelta) {
  gpl::TileDeltaSequence seq;
  EXPECT_EQ(seq.accept(1, true), V::kApply);
  EXPECT_EQ(seq.accept(2, false), V::kApply);
  seq.notApplied();  // e.g. the tile directory was gone
  EXPECT_FALSE(seq.synchronised());
  EXPECT_EQ(seq.accept(3, false), V::kRequestResend);
  EXPECT_EQ(seq.accept(4, false), V::kIgnore);
  EXPECT_EQ(seq.accept(5, true), V::kApply);
  EXPECT_TRUE(seq.synchronised());
}
