// Scan-to-scan odometry: the motion of the base between consecutive scans, by NDT of each scan against the one
// before it. The localizer carries a given start with it while the map around the start is still arriving (a slow
// map store), so that the start is matched where the vehicle is when its map comes, not where it was given.
#pragma once

#include <Eigen/Geometry>
#include <optional>

#include "grid_puzzle_localization/ndt.hpp"
#include "grid_puzzle_localization/point_cloud.hpp"
#include "grid_puzzle_localization/pose_prediction.hpp"
#include "grid_puzzle_localization/voxel_map.hpp"

namespace grid_puzzle_localization {

/// What one scan gave the odometry.
enum class OdometryStep {
  kFirst,     ///< no scan before it (the start, or after reset): nothing moved yet
  kMeasured,  ///< the match against the scan before passed the gate
  kGuessed,   ///< the match failed: the motion is the last measured velocity over the interval (zero before any)
};

class ScanOdometry {
 public:
  /// `ndt`: the matching (its resolution must give a voxel a few of the scan's downsampled points); a step is
  /// measured when its NVTL >= `min_nvtl` and it moves no faster than `max_speed` [m/s].
  ScanOdometry(const NdtConfig& ndt, double min_nvtl, double max_speed);

  /// The base's motion from the scan given before to this one (prev_T_this), for `base_points` (base frame) taken at
  /// `stamp` [s]; `step` says how it was found. A scan not newer than the one before starts over (kFirst).
  Eigen::Isometry3d add(double stamp, const PointCloud& base_points, OdometryStep* step);
  /// The body twist [m/s, rad/s] of the last measured step (or the one reset() was given).
  const Twist& velocity() const { return velocity_; }
  /// The motion from the last scan given to `stamp` [s] at the last measured velocity (identity before any).
  Eigen::Isometry3d motionTo(double stamp) const;
  /// Forgets the scans; the next steps are guessed from `velocity` (body twist [m/s, rad/s]) until one is measured.
  void reset(const Twist& velocity = Twist::Zero());

 private:
  NdtAligner aligner_;
  NdtTarget previous_;  // the scan given before, as the target of the next
  double min_nvtl_;
  double max_speed_;
  std::optional<double> previous_stamp_;
  Twist velocity_ = Twist::Zero();  // body twist of the last measured step [m/s, rad/s]
};

}  // namespace grid_puzzle_localization
