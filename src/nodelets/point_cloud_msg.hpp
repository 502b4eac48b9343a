// sensor_msgs/PointCloud2 <-> core PointCloud (Debian has no pcl_conversions).
#pragma once

#include <sensor_msgs/PointCloud2.h>

#include <string>

#include "grid_puzzle_localization/point_cloud.hpp"

namespace grid_puzzle_localization {

/// Reads x y z (FLOAT32 or FLOAT64, any offsets, any other fields, either endianness of the host)
/// from `msg`. Throws std::invalid_argument naming the topic-free problem when x, y or z is missing
/// or the buffer is shorter than width * height * point_step.
PointCloud fromMsg(const sensor_msgs::PointCloud2& msg);

/// Packs `cloud` as a dense x y z FLOAT32 PointCloud2 with the given header.
sensor_msgs::PointCloud2 toMsg(const PointCloud& cloud, const std_msgs::Header& header);

}  // namespace grid_puzzle_localization
