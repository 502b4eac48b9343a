#include "provider_map_cloud.hpp"

#include <ros/console.h>

#include <chrono>

#include "grid_puzzle_localization/pcd_reader.hpp"
#include "point_cloud_msg.hpp"

namespace grid_puzzle_localization {

ProviderMapCloud::ProviderMapCloud(ros::NodeHandle& nh, std::string frame, double period)
    : frame_(std::move(frame)), period_(period) {
  // A new subscriber gets the current window: the latched message may be older than the last change.
  pub_ = nh.advertise<sensor_msgs::PointCloud2>(
      "map_cloud", 1,
      [this](const ros::SingleSubscriberPublisher&) {
        {
          std::lock_guard<std::mutex> lock(mutex_);
          dirty_ = dirty_ || !paths_.empty();
        }
        wake_.notify_one();
      },
      ros::SubscriberStatusCallback(), ros::VoidConstPtr(), true);
  thread_ = std::thread(&ProviderMapCloud::run, this);
}

ProviderMapCloud::~ProviderMapCloud() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_.notify_all();
  thread_.join();
}

void ProviderMapCloud::changed(std::vector<std::string> paths, const ros::Time& stamp) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    paths_ = std::move(paths);
    stamp_ = stamp;
    dirty_ = true;
  }
  wake_.notify_one();
}

void ProviderMapCloud::run() {
  while (true) {
    std::vector<std::string> paths;
    std_msgs::Header header;
    header.frame_id = frame_;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      wake_.wait(lock, [this] { return stop_ || dirty_; });
      if (stop_) return;
      if (pub_.getNumSubscribers() == 0) {
        dirty_ = false;  // the next subscriber's connection marks it again
        continue;
      }
      paths = paths_;
      header.stamp = stamp_;
      dirty_ = false;
    }
    PointCloud merged;
    for (const std::string& path : paths) {
      try {
        const PointCloud tile = readPcdXyz(path);
        merged.insert(merged.end(), tile.begin(), tile.end());
      } catch (const std::exception& e) {
        ROS_ERROR_THROTTLE(5.0, "map_cloud: tile %s skipped: %s", path.c_str(), e.what());
      }
    }
    pub_.publish(toMsg(merged, header));
    std::unique_lock<std::mutex> lock(mutex_);
    wake_.wait_for(lock, std::chrono::duration<double>(period_), [this] { return stop_; });
  }
}

}  // namespace grid_puzzle_localization
