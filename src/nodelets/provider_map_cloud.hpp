// The provider's optional latched `map_cloud`: the window's tiles merged into one PointCloud2 by a thread of its
// own, read only while the topic has subscribers and at most once per period (always the latest window), so the
// tile deltas are never held up by it and nobody subscribed costs nothing.
#pragma once

#include <ros/node_handle.h>
#include <ros/publisher.h>

#include <condition_variable>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace grid_puzzle_localization {

class ProviderMapCloud {
 public:
  /// `period` [s] >= 0: at most one cloud per period (0 = on every change).
  ProviderMapCloud(ros::NodeHandle& nh, std::string frame, double period);
  ~ProviderMapCloud();
  /// The window's tile files after a change of the window, stamped `stamp`.
  void changed(std::vector<std::string> paths, const ros::Time& stamp);

 private:
  void run();

  std::string frame_;
  double period_;
  ros::Publisher pub_;
  std::mutex mutex_;
  std::condition_variable wake_;
  std::vector<std::string> paths_;
  ros::Time stamp_;
  bool dirty_ = false, stop_ = false;
  std::thread thread_;
};

}  // namespace grid_puzzle_localization
