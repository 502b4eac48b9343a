// Standalone scan preprocessing (range crop, NaN/origin removal, voxel filter) as a nodelet, so the
// localizer's filter can run in a driver's manager or be inspected in rviz.
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>

#include <pluginlib/class_list_macros.hpp>

#include "grid_puzzle_localization/preprocess.hpp"
#include "point_cloud_msg.hpp"

namespace grid_puzzle_localization {

class PointsPreprocessorNodelet : public nodelet::Nodelet {
 private:
  void onInit() override {
    ros::NodeHandle& nh = getNodeHandle();
    ros::NodeHandle& pnh = getPrivateNodeHandle();
    pnh.param("min_range", config_.min_range, config_.min_range);
    pnh.param("max_range", config_.max_range, config_.max_range);
    pnh.param("voxel_size", config_.voxel_size, config_.voxel_size);
    const std::string problem = config_.validate();
    if (!problem.empty()) {
      NODELET_FATAL("%s: bad parameters: %s fix them in the launch file or YAML", getName().c_str(), problem.c_str());
      throw std::invalid_argument(problem);
    }
    pub_ = nh.advertise<sensor_msgs::PointCloud2>("points_filtered", 5);
    sub_ = nh.subscribe("points", 5, &PointsPreprocessorNodelet::onPoints, this);
  }

  void onPoints(const sensor_msgs::PointCloud2::ConstPtr& msg) {
    try {
      pub_.publish(toMsg(preprocess(fromMsg(*msg), config_), msg->header));
    } catch (const std::invalid_argument& e) {
      NODELET_ERROR_THROTTLE(5.0, "points (frame '%s'): %s", msg->header.frame_id.c_str(), e.what());
    }
  }

  PreprocessConfig config_;
  ros::Publisher pub_;
  ros::Subscriber sub_;
};

}  // namespace grid_puzzle_localization

PLUGINLIB_EXPORT_CLASS(grid_puzzle_localization::PointsPreprocessorNodelet, nodelet::Nodelet)
