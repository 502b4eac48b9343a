// Point cloud type shared by the ROS-free core. No ROS includes here.
#pragma once

#include <Eigen/Core>
#include <vector>

namespace grid_puzzle_localization {

/// A point in metres. Eigen::Vector3f is not a fixed-size vectorizable type, so a plain
/// std::vector needs no aligned allocator.
using Point = Eigen::Vector3f;

/// A cloud owns its points contiguously (x y z, float32), in the frame its user states.
using PointCloud = std::vector<Point>;

}  // namespace grid_puzzle_localization
