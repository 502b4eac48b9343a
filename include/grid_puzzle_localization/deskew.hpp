// Motion compensation of a LiDAR sweep ("deskew"): points measured at different times while the sensor
// moves are brought into the one sensor frame at the scan stamp. No ROS.
#pragma once

#include <Eigen/Geometry>
#include <functional>
#include <utility>
#include <vector>

#include "grid_puzzle_localization/point_cloud.hpp"
#include "grid_puzzle_localization/pose_prediction.hpp"

namespace grid_puzzle_localization {

/// Per-point capture times [s] relative to the scan stamp (index i belongs to point i).
using PointTimes = std::vector<float>;

/// The sensor's motion over one sweep, sensor(stamp)_T_sensor(stamp + t) for t in [t_begin, t_end] [s],
/// sampled at evenly spaced nodes and linearly interpolated between them. The nodes are dense enough that
/// the rotation between two of them is at most kMaxNodeRotation, so the interpolation error is below float
/// precision for ranges up to a few hundred metres. Immutable once built.
class SweepMotion {
 public:
  static constexpr double kMaxNodeRotation = 2e-4;  ///< [rad] between neighbouring nodes
  static constexpr int kMaxNodes = 4096;

  /// `base_motion(t)` is base(stamp)_T_base(stamp + t); `base_T_sensor` the mounting. The motion is sampled
  /// over [t_begin, t_end] [s]; `max_rate` [rad/s] bounds the angular rate and sets the node spacing.
  SweepMotion(const std::function<Eigen::Isometry3d(double)>& base_motion, const Eigen::Isometry3d& base_T_sensor,
              double t_begin, double t_end, double max_rate);

  /// A body moving with the constant `twist` (base frame, [m/s, rad/s]), as PosePredictor models it.
  static SweepMotion fromTwist(const Twist& twist, const Eigen::Isometry3d& base_T_sensor, double t_begin,
                               double t_end);

  /// sensor(stamp)_T_sensor(stamp + t); t is clamped to the sampled interval.
  Eigen::Isometry3f at(double t) const;

  /// Moves every point i, measured at times[i] in the sensor frame of that moment, into the sensor frame at
  /// the stamp. A point with a non-finite time is left as it is. Throws std::invalid_argument when the sizes
  /// differ.
  void apply(PointCloud& points, const PointTimes& times) const;

 private:
  double t_begin_;
  double step_;  ///< [s] between nodes; 0 with a single node
  std::vector<Eigen::Matrix<float, 3, 4>> nodes_;
};

/// Smallest and largest finite time in `times` [s]; (0, 0) when there is none.
std::pair<double, double> timeSpan(const PointTimes& times);

}  // namespace grid_puzzle_localization
