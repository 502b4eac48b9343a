// Parameters of the grid puzzle provider nodelet, the C++ twin of provider/config.py: the same names, defaults
// (test_provider_config holds them equal) and checks. config/grid_puzzle_map_provider.yaml documents each. No ROS.
#pragma once

#include <string>

#include "grid_puzzle_localization/provider/window.hpp"

namespace grid_puzzle_localization {

struct ProviderConfig {
  std::string tiles_dir;              ///< tiles/dir: tile directory written by `gpm tile` (required)
  double tiles_grid_size = 0.0;       ///< tiles/grid_size [m]: tile side s; 0 = from the index
  WindowConfig window;                ///< window/*
  double lost_max_half_side = 100.0;  ///< lost/max_half_side [m]: largest window while lost; 0 = never grows
  /// start/search_timeout [s]: with no pose and no hint this long after start-up, serve the whole map for the
  /// localizer's global search; 0 = never
  double start_search_timeout = 0.0;
  double start_max_area = 1.0e6;  ///< start/max_area [m^2]: a larger map is not served whole (it needs a pose or hint)
  std::string pose_source = "odom";  ///< odom (nav_msgs/Odometry on `odom`) | pose (on `pose`)
  bool publish_map_cloud = false;    ///< publish the merged window on the latched `map_cloud`
  double map_cloud_period = 1.0;     ///< [s] publish map_cloud at most this often; 0 = every change
  std::string map_frame = "map";     ///< frame of the tiles, the incoming poses and every published cloud
  double save_pose_rate = 0.5;       ///< [Hz] write the newest pose to ~last_pose (0 = never); read at start

  /// Throws std::invalid_argument naming the first bad parameter; returns the config with the window resolved.
  ProviderConfig checked() const;
};

}  // namespace grid_puzzle_localization
