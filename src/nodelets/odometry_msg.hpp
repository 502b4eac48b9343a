// Core LocalizerOutput -> nav_msgs/Odometry (the odom topic).
#pragma once

#include <nav_msgs/Odometry.h>

#include <string>

#include "grid_puzzle_localization/localizer.hpp"

namespace grid_puzzle_localization {

/// The pose (map_frame -> base_frame) and twist of one scan at `stamp`, with their covariances in ROS's order.
nav_msgs::Odometry toOdometryMsg(const LocalizerOutput& out, const ros::Time& stamp, const std::string& map_frame,
                                 const std::string& base_frame);

}  // namespace grid_puzzle_localization
