#include <gtest/gtest.h>

#include <cmath>

#include "odometry_msg.hpp"

namespace gpl = grid_puzzle_localization;

TEST(OdometryMsg, PoseTwistAndCovariancesInRosOrder) {
  gpl::LocalizerOutput out;
  out.pose = Eigen::Translation3d(1.0, 2.0, 3.0) * Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ());
  out.twist << 0.1, 0.2, 0.3, 0.4, 0.5, 0.6;
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c) {
      out.covariance(r, c) = 10.0 * r + c;
      out.twist_covariance(r, c) = -(10.0 * r + c);
    }
  const nav_msgs::Odometry odom = gpl::toOdometryMsg(out, ros::Time(1700000000, 5), "map", "base_link");
  EXPECT_EQ(odom.header.stamp, ros::Time(1700000000, 5));
  EXPECT_EQ(odom.header.frame_id, "map");
  EXPECT_EQ(odom.child_frame_id, "base_link");
  EXPECT_DOUBLE_EQ(odom.pose.pose.position.x, 1.0);
  EXPECT_DOUBLE_EQ(odom.pose.pose.position.y, 2.0);
  EXPECT_DOUBLE_EQ(odom.pose.pose.position.z, 3.0);
  EXPECT_NEAR(odom.pose.pose.orientation.z, std::sin(0.25), 1e-15);  // yaw 0.5 rad about z
  EXPECT_NEAR(odom.pose.pose.orientation.w, std::cos(0.25), 1e-15);
  EXPECT_DOUBLE_EQ(odom.twist.twist.linear.x, 0.1);
  EXPECT_DOUBLE_EQ(odom.twist.twist.angular.z, 0.6);
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c) {
      EXPECT_DOUBLE_EQ(odom.pose.covariance[6 * r + c], 10.0 * r + c);  // row-major
      EXPECT_DOUBLE_EQ(odom.twist.covariance[6 * r + c], -(10.0 * r + c));
    }
}
