// ROS parameters `map_store/*` -> core MapStoreConfig (defaults and checks live there): the settings of a tile
// directory given by URL (docs/map_store.md).
#pragma once

#include <ros/node_handle.h>

#include "grid_puzzle_localization/map_store/map_store.hpp"

namespace grid_puzzle_localization {

/// The checked config from the private parameters `map_store/*`; throws std::invalid_argument naming a parameter of
/// the wrong type or out of range.
MapStoreConfig loadMapStoreConfig(const ros::NodeHandle& pnh);

}  // namespace grid_puzzle_localization
