// ROS parameters of the NDT localizer nodelet -> core LocalizerConfig. Defaults live in the core structs
// (and, for the ROS-only ones, below); a value out of range stops the start-up with an error naming it.
#pragma once

#include <ros/node_handle.h>

#include <Eigen/Geometry>
#include <cmath>
#include <optional>
#include <string>

#include "grid_puzzle_localization/localizer.hpp"

namespace grid_puzzle_localization {

/// Global localization by search (~global_localize and the automatic start).
struct GlobalLocalizationParams {
  /// [s] >= 0: with no initial pose this long after the first scan, search by itself (0 = never).
  double auto_start_timeout = 0.0;
  /// [m] coarse position when no hint is known (initialpose_hint, else the saved ~last_pose); unset: the map
  std::optional<Eigen::Vector2d> center;
  double size = 40.0;       ///< [m] > 0, side of the square searched
  double yaw_range = M_PI;  ///< [rad] in (0, pi], half-width of the yaw range searched
};

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
  /// [Hz] >= 0: how often the newest published pose is written to ~last_pose on the parameter server (0 = never).
  double save_pose_rate = 0.5;
  /// From ~last_pose/pose [x y z roll pitch yaw], as an earlier process of this nodelet saved it (a respawn):
  /// the centre of the automatic global search, never an initial pose (the vehicle moved on meanwhile).
  std::optional<Eigen::Isometry3d> last_pose;
  /// Per-point time field of the scans: FLOAT32/FLOAT64 [s] or UINT32 [ns] after header.stamp.
  std::string time_field = "time";
  GlobalLocalizationParams global_localization;
  /// The IMU's pose in base_link comes from TF (the IMU messages' frame) unless ~fusion/window/base_T_imu is set.
  bool imu_extrinsic_from_tf = true;
};

/// Reads every parameter from `pnh`. A value out of range or unusable (unknown map_source or search method,
/// pcd mode without a file, malformed initial_pose) throws std::invalid_argument with a message that names the
/// parameter and says what to fix. A malformed ~last_pose (state, not a setting) is logged and ignored.
LocalizerRosParams loadLocalizerParams(const ros::NodeHandle& pnh, const std::string& log_name);

}  // namespace grid_puzzle_localization
