#include "odometry_msg.hpp"

#include <tf2_eigen/tf2_eigen.h>

namespace grid_puzzle_localization {

nav_msgs::Odometry toOdometryMsg(const LocalizerOutput& out, const ros::Time& stamp, const std::string& map_frame,
                                 const std::string& base_frame) {
  nav_msgs::Odometry odom;
  odom.header.stamp = stamp;
  odom.header.frame_id = map_frame;
  odom.child_frame_id = base_frame;
  odom.pose.pose = tf2::toMsg(out.pose);
  odom.twist.twist = tf2::toMsg(Eigen::Matrix<double, 6, 1>(out.twist));
  for (int r = 0; r < 6; ++r)
    for (int c = 0; c < 6; ++c) {
      odom.pose.covariance[6 * r + c] = out.covariance(r, c);
      odom.twist.covariance[6 * r + c] = out.twist_covariance(r, c);
    }
  return odom;
}

}  // namespace grid_puzzle_localization
