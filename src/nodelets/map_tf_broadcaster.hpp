// The localizer's pose on TF: map -> odom once someone publishes odom -> base_link (then for good, so a
// late odometry source does not make the tree switch back), map -> base_link otherwise.
#pragma once

#include <ros/time.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_broadcaster.h>

#include <Eigen/Geometry>
#include <string>

namespace grid_puzzle_localization {

class MapTfBroadcaster {
 public:
  /// `buffer` (kept by reference) answers odom -> base; an empty `odom_frame` always sends map -> base.
  /// `log_name` names the logger (the nodelet's name).
  MapTfBroadcaster(const tf2_ros::Buffer& buffer, std::string map_frame, std::string odom_frame, std::string base_frame,
                   std::string log_name);

  /// Sends map_T_base at `stamp` as above; without odom -> base at `stamp`, sends nothing and warns.
  void send(const Eigen::Isometry3d& map_T_base, const ros::Time& stamp);

 private:
  const tf2_ros::Buffer& buffer_;
  tf2_ros::TransformBroadcaster broadcaster_;
  std::string map_frame_, odom_frame_, base_frame_, log_name_;
  bool odom_published_by_others_ = false;
};

}  // namespace grid_puzzle_localization
