// sensor_msgs/PointCloud2 <-> core PointCloud (Debian has no pcl_conversions).
#pragma once

#include <sensor_msgs/PointCloud2.h>

#include <optional>
#include <string>

#include "grid_puzzle_localization/deskew.hpp"
#include "grid_puzzle_localization/point_cloud.hpp"

namespace grid_puzzle_localization {

/// Reads x y z (FLOAT32 or FLOAT64, any offsets, any other fields, either endianness of the host)
/// from `msg`. Throws std::invalid_argument naming the topic-free problem when x, y or z is missing
/// or the buffer is shorter than width * height * point_step.
PointCloud fromMsg(const sensor_msgs::PointCloud2& msg);

/// Reads the per-point capture times [s after header.stamp] from the field `name`: FLOAT32 or FLOAT64 in
/// seconds (Velodyne, our simulator), or UINT32 in nanoseconds (Ouster's "t"). Returns nullopt when the
/// field is absent; throws std::invalid_argument when it has another type. Same point order as fromMsg.
std::optional<PointTimes> timesFromMsg(const sensor_msgs::PointCloud2& msg, const std::string& name);

/// Packs `cloud` as a dense x y z FLOAT32 PointCloud2 with the given header.
sensor_msgs::PointCloud2 toMsg(const PointCloud& cloud, const std_msgs::Header& header);

}  // namespace grid_puzzle_localization
