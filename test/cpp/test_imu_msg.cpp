#include <gtest/gtest.h>

#include "imu_msg.hpp"

namespace gpl = grid_puzzle_localization;

TEST(ImuMsg, RatesForceAndVariancesFromTheMessage) {
  sensor_msgs::Imu msg;
  msg.header.stamp = ros::Time(1700000000, 250000000);
  msg.angular_velocity.x = 0.1;
  msg.angular_velocity.y = -0.2;
  msg.angular_velocity.z = 0.3;
  msg.linear_acceleration.z = 9.81;
  msg.angular_velocity_covariance = {1e-6, 0, 0, 0, 2e-6, 0, 0, 0, 3e-6};
  msg.linear_acceleration_covariance = {4e-4, 0, 0, 0, 4e-4, 0, 0, 0, 4e-4};
  const gpl::ImuSample s = gpl::imuSampleFromMsg(msg);
  EXPECT_DOUBLE_EQ(s.stamp, 1700000000.25);
  EXPECT_EQ(s.gyro, Eigen::Vector3d(0.1, -0.2, 0.3));
  EXPECT_EQ(s.accel, Eigen::Vector3d(0.0, 0.0, 9.81));
  EXPECT_DOUBLE_EQ(s.gyro_variance, 2e-6);
  EXPECT_DOUBLE_EQ(s.accel_variance, 4e-4);
}

TEST(ImuMsg, UnknownCovarianceGivesNegativeVariance) {
  sensor_msgs::Imu msg;  // all-zero covariances: unknown
  EXPECT_LT(gpl::imuSampleFromMsg(msg).gyro_variance, 0.0);
  EXPECT_LT(gpl::imuSampleFromMsg(msg).accel_variance, 0.0);
  msg.angular_velocity_covariance[0] = -1.0;  // "no estimate"
  msg.linear_acceleration_covariance = {1e-4, 0, 0, 0, 1e-4, 0, 0, 0, 1e-4};
  const gpl::ImuSample s = gpl::imuSampleFromMsg(msg);
  EXPECT_LT(s.gyro_variance, 0.0);
  EXPECT_DOUBLE_EQ(s.accel_variance, 1e-4);
}

// sensor_msgs/Imu: element 0 at -1 means no estimate at all. Without a specific force or rates the window cannot
// run on the IMU; all zeros only means the covariance is unknown.
TEST(ImuMsg, NoAccelerationOrRateEstimateIsMarked) {
  sensor_msgs::Imu msg;
  EXPECT_TRUE(gpl::imuSampleFromMsg(msg).has_accel);
  msg.linear_acceleration_covariance[0] = -1.0;
  EXPECT_FALSE(gpl::imuSampleFromMsg(msg).has_accel);
  EXPECT_TRUE(gpl::imuSampleFromMsg(msg).has_gyro);
  msg.angular_velocity_covariance[0] = -1.0;
  EXPECT_FALSE(gpl::imuSampleFromMsg(msg).has_gyro);
}
