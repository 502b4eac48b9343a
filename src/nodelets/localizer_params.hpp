// ROS parameters of the NDT localizer nodelet -> core LocalizerConfig. Defaults live in the core structs;
// a value that does not validate is replaced by the default and logged.
#pragma once

#include <ros/node_handle.h>

#include <Eigen/Geometry>
#include <optional>
#include <string>

#include "grid_puzzle_localization/localizer.hpp"

namespace grid_puzzle_localization {

struct LocalizerRosParams {
  LocalizerConfig core;
  std::string map_source = "cloud";  ///< cloud | tiles | pcd
  std::string pcd_path;              ///< pcd mode: global map file
  std::string map_frame = "map";
  std::string odom_frame = "odom";  ///< empty: always publish map -> base_link
  std::string base_frame = "base_link";
  bool publish_tf = true;
  bool publish_aligned_points = false;
  std::string resend_service = "tile_provider/resend";  ///< tiles mode: std_srvs/Trigger on a revision gap
  /// tiles mode by reference: byte budget of the read-ahead cache [MiB], >= 0 (0 = no prefetch).
  double tile_cache_mb = MapUpdateWorker::kDefaultTileCacheMb;
  std::optional<Eigen::Isometry3d> initial_pose;  ///< from ~initial_pose [x y z roll pitch yaw]
  /// Per-point time field of the scans: FLOAT32/FLOAT64 [s] or UINT32 [ns] after header.stamp.
  std::string time_field = "time";
};

/// Reads every parameter from `pnh`. Bad values of numeric parameters fall back to the default with a
/// warning naming the parameter; unusable ones (unknown map_source or search method, pcd mode without a
/// file, malformed initial_pose) throw std::invalid_argument with a message that says what to fix.
LocalizerRosParams loadLocalizerParams(const ros::NodeHandle& pnh, const std::string& log_name);

}  // namespace grid_puzzle_localization
