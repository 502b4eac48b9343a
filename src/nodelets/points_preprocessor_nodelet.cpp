// Standalone scan preprocessing (range crop, NaN/origin removal, voxel filter) as a nodelet, so the
// localizer's filter can run in a driver's manager or be inspected in rviz.
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <sensor_msgs/PointCloud2.h>

#include <optional>
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
    preprocessor_.emplace(config_);
    pub_ = nh.advertise<sensor_msgs::PointCloud2>("points_filtered", 5);
    sub_ = nh.subscribe("points", 5, &PointsPreprocessorNodelet::onPoints, this);
  }

  void onPoints(const sensor_msgs::PointCloud2::ConstPtr& msg) {
    try {
      preprocessor_->apply(fromMsg(*msg), filtered_);
      pub_.publish(toMsg(filtered_, msg->header));
    } catch (const std::invalid_argument& e) {
      NODELET_ERROR_THROTTLE(5.0, "points (frame '%s'): %s", msg->header.frame_id.c_str(), e.what());
    }
  }

  PreprocessConfig config_;
  std::optional<Preprocessor> preprocessor_;  ///< built once the parameters are valid; reuses its buffers
  PointCloud filtered_;
  ros::Publisher pub_;
  ros::Subscriber sub_;
};

}  // namespace grid_puzzle_localization

PLUGINLIB_EXPORT_CLASS(grid_puzzle_localization::PointsPreprocessorNodelet, nodelet::Nodelet)
