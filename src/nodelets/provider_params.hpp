// ROS parameters of the grid puzzle provider nodelet -> core ProviderConfig (defaults and checks live there).
#pragma once

#include <ros/node_handle.h>

#include "grid_puzzle_localization/provider/provider_config.hpp"

namespace grid_puzzle_localization {

/// The checked config from the private parameters; throws std::invalid_argument naming a parameter of the wrong
/// type or out of range.
ProviderConfig loadProviderConfig(const ros::NodeHandle& pnh);

}  // namespace grid_puzzle_localization
