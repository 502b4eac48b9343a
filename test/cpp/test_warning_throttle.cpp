#include <gtest/gtest.h>

#include "warning_throttle.hpp"

namespace gpl = grid_puzzle_localization;

TEST(WarningThrottle, EachKindAtMostOncePerPeriod) {
  gpl::WarningThrottle throttle(5.0);
  EXPECT_TRUE(throttle.pass("IMU gap of 0.31 s", 100.0));
  EXPECT_FALSE(throttle.pass("IMU gap of 0.52 s", 101.0));  // same kind: only the numbers differ
  EXPECT_TRUE(throttle.pass("odometry ignored", 101.0));    // another kind is not hidden
  EXPECT_FALSE(throttle.pass("IMU gap of 7.25 s", 104.999));
  EXPECT_TRUE(throttle.pass("IMU gap of 7.25 s", 105.0));  // a whole period after the first
  EXPECT_FALSE(throttle.pass("IMU gap of 8.5 s", 109.9));  // the period starts again at the last one let through
  EXPECT_TRUE(throttle.pass("IMU gap of 8.5 s", 110.0));
  EXPECT_TRUE(throttle.pass("odometry ignored", 106.0));
}
