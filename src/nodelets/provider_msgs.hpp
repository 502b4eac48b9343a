// Messages of the grid puzzle provider nodelet: poses in (as core PoseSamples), tile deltas and status out (built
// from the core window and tile keys). Tile deltas carry tiles by reference (names and their directory), never points.
#pragma once

#include <geometry_msgs/Pose.h>
#include <geometry_msgs/Twist.h>
#include <ros/time.h>

#include <string>
#include <vector>

#include "grid_puzzle_localization/ProviderStatus.h"
#include "grid_puzzle_localization/TileDelta.h"
#include "grid_puzzle_localization/provider/window.hpp"
#include "grid_puzzle_localization/voxel_map.hpp"

namespace grid_puzzle_localization {

/// PoseSample of a pose; the yaw is unset when the orientation is all zeros (not set), and a body-frame `twist`
/// (when given, with a yaw) becomes a map-frame velocity.
PoseSample poseSampleOf(const geometry_msgs::Pose& pose, const ros::Time& stamp, const geometry_msgs::Twist* twist);

/// A TileDelta by reference: the localizer reads `tile_dir`/<id>.pcd itself.
TileDelta::Ptr makeTileDelta(const ros::Time& stamp, const std::string& frame, std::uint32_t revision, bool reset,
                             double s, const Window& window, const std::string& tile_dir,
                             const std::string& index_revision, const std::vector<TileKey>& added,
                             const std::vector<TileKey>& removed, const std::vector<TileKey>& prefetch);

ProviderStatus providerStatusMsg(const TileDelta& delta, const Window& window, std::size_t tiles_loaded,
                                 double update_ms);

}  // namespace grid_puzzle_localization
