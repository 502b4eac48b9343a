#include <gtest/gtest.h>

#include "global_search_timer.hpp"

namespace gpl = grid_puzzle_localization;

TEST(GlobalSearchTimer, ZeroTimeoutNeverStartsASearch) {
  gpl::GlobalSearchTimer timer(0.0);
  for (double stamp : {0.0, 100.0, 1e9}) EXPECT_FALSE(timer.due(stamp));
}

TEST(GlobalSearchTimer, DueATimeoutAfterTheFirstWaitingScanThenAfterEachFailure) {
  gpl::GlobalSearchTimer timer(10.0);
  EXPECT_FALSE(timer.due(1000.0));  // the first scan that waits starts the clock
  EXPECT_FALSE(timer.due(1009.9));
  EXPECT_TRUE(timer.due(1010.0));
  timer.failed(1010.0);
  EXPECT_FALSE(timer.due(1015.0));
  EXPECT_TRUE(timer.due(1020.0));
  EXPECT_TRUE(timer.due(1020.1));  // not failed: due until a search fails or finds the pose
}
