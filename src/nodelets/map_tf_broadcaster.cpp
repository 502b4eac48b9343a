#include "map_tf_broadcaster.hpp"

#include <ros/console.h>
#include <tf2_eigen/tf2_eigen.h>

#include <utility>

namespace grid_puzzle_localization {

MapTfBroadcaster::MapTfBroadcaster(const tf2_ros::Buffer& buffer, std::string map_frame, std::string odom_frame,
                                   std::string base_frame, std::string log_name)
    : buffer_(buffer),
      map_frame_(std::move(map_frame)),
      odom_frame_(std::move(odom_frame)),
      base_frame_(std::move(base_frame)),
      log_name_(std::move(log_name)) {}

void MapTfBroadcaster::send(const Eigen::Isometry3d& map_T_base, const ros::Time& stamp) {
  geometry_msgs::TransformStamped t;
  t.header.stamp = stamp;
  t.header.frame_id = map_frame_;
  if (!odom_frame_.empty() && !odom_published_by_others_)
    odom_published_by_others_ = buffer_.canTransform(odom_frame_, base_frame_, ros::Time(0));
  if (!odom_published_by_others_) {
    t.child_frame_id = base_frame_;
    t.transform = tf2::eigenToTransform(map_T_base).transform;
    broadcaster_.sendTransform(t);
    return;
  }
  try {
    const Eigen::Isometry3d odom_T_base =
        tf2::transformToEigen(buffer_.lookupTransform(odom_frame_, base_frame_, stamp));
    t.child_frame_id = odom_frame_;
    t.transform = tf2::eigenToTransform(map_T_base * odom_T_base.inverse()).transform;
    broadcaster_.sendTransform(t);
  } catch (const tf2::TransformException& e) {
    ROS_WARN_THROTTLE_NAMED(5.0, log_name_,
                            "no '%s' -> '%s' at the scan time (%s); map -> %s not published for this scan",
                            odom_frame_.c_str(), base_frame_.c_str(), e.what(), odom_frame_.c_str());
  }
}

}  // namespace grid_puzzle_localization
