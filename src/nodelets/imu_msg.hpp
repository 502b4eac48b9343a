// sensor_msgs/Imu -> core ImuSample (the window's input).
#pragma once

#include <sensor_msgs/Imu.h>

#include "grid_puzzle_localization/fusion/sliding_window.hpp"

namespace grid_puzzle_localization {

/// The rates and specific force of `msg` in its own frame. The variances are the mean of each covariance's
/// diagonal; a covariance marked unknown (all zeros, or element 0 at -1, as sensor_msgs/Imu defines) gives a
/// negative variance, so the window uses its configured noise densities (and says so). A linear acceleration
/// covariance with element 0 at -1 also means the IMU gives no specific force (ImuSample::has_accel false); an
/// angular velocity covariance with element 0 at -1 means it gives no rates (ImuSample::has_gyro false).
ImuSample imuSampleFromMsg(const sensor_msgs::Imu& msg);

}  // namespace grid_puzzle_localization
