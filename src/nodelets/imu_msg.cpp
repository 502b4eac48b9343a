#include "imu_msg.hpp"

#include <algorithm>

namespace grid_puzzle_localization {
namespace {

double meanVariance(const boost::array<double, 9>& covariance) {
  const bool unknown =
      covariance[0] < 0.0 || std::all_of(covariance.begin(), covariance.end(), [](double v) { return v == 0.0; });
  return unknown ? -1.0 : (covariance[0] + covariance[4] + covariance[8]) / 3.0;
}

}  // namespace

ImuSample imuSampleFromMsg(const sensor_msgs::Imu& msg) {
  ImuSample s;
  s.stamp = msg.header.stamp.toSec();
  s.gyro = {msg.angular_velocity.x, msg.angular_velocity.y, msg.angular_velocity.z};
  s.accel = {msg.linear_acceleration.x, msg.linear_acceleration.y, msg.linear_acceleration.z};
  s.gyro_variance = meanVariance(msg.angular_velocity_covariance);
  s.accel_variance = meanVariance(msg.linear_acceleration_covariance);
  s.has_accel = msg.linear_acceleration_covariance[0] != -1.0;
  s.has_gyro = msg.angular_velocity_covariance[0] != -1.0;
  return s;
}

}  // namespace grid_puzzle_localization
