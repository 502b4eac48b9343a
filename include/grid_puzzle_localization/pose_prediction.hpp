// Motion prediction between scans: a constant body-twist model, optionally with the rotation
// integrated from gyro samples. No ROS.
#pragma once

#include <Eigen/Geometry>
#include <deque>
#include <string>

#include "grid_puzzle_localization/pose_search.hpp"

namespace grid_puzzle_localization {

/// 6-vector twist in the body frame: (vx, vy, vz) [m/s], (wx, wy, wz) [rad/s].
using Twist = Eigen::Matrix<double, 6, 1>;

/// se(3) exponential of a body twist applied for `dt` seconds: the exact pose change of a body that
/// moves with a constant body-frame velocity (a car on a circular arc, for example).
Eigen::Isometry3d expTwist(const Twist& twist, double dt);

/// Inverse of expTwist for dt = 1: the body twist that moves identity to `delta` in one second.
Twist logTwist(const Eigen::Isometry3d& delta);

/// Rotation accumulated from angular-velocity samples (base frame, rad/s). Samples are linearly
/// interpolated in time (trapezoidal rule), so a rate that is linear in time about a fixed axis
/// integrates exactly.
class GyroIntegrator {
 public:
  /// Adds a sample at `stamp` [s]. Samples must arrive in time order; an older one clears the buffer
  /// (a bag loop) and starts over.
  void add(double stamp, const Eigen::Vector3d& angular_velocity);

  /// True when samples cover [t0, t1] (the first sample at or before t0, the last at or after t1,
  /// with a tolerance of `max_gap` [s] at each end, where the rate is held).
  bool covers(double t0, double t1, double max_gap) const;

  /// Rotation of the body from t0 to t1 (R(t0)^-1 R(t1)). Outside the sampled span the nearest rate is
  /// held. Identity when there are no samples.
  Eigen::Quaterniond integrate(double t0, double t1) const;

  /// Drops samples that are not needed to integrate from `stamp` on.
  void dropBefore(double stamp);

  void clear() { samples_.clear(); }
  std::size_t size() const { return samples_.size(); }

 private:
  struct Sample {
    double stamp;
    Eigen::Vector3d rate;
  };
  Eigen::Vector3d rateAt(double t) const;
  std::deque<Sample> samples_;
};

/// Constant-velocity predictor. It holds the last pose (map frame) and the body twist estimated from
/// the last two poses.
class PosePredictor {
 public:
  /// Forgets the motion history and starts from `pose` at `stamp` [s] with zero velocity.
  void reset(const Eigen::Isometry3d& pose, double stamp);

  bool initialized() const { return initialized_; }
  double stamp() const { return stamp_; }
  const Eigen::Isometry3d& pose() const { return pose_; }
  const Twist& twist() const { return twist_; }
  /// The twist low-pass filtered with time constant `smoothing` [s] (see update); the first twist measured
  /// after a reset is taken as is. Zero after a reset.
  const Twist& smoothedTwist() const { return smoothed_twist_; }
  /// A twist has been measured (two poses recorded) since the last reset.
  bool twistMeasured() const { return twist_measured_; }

  /// Pose at `stamp` [s]: the last pose moved by the constant body twist. When `gyro_rotation` is
  /// given it replaces the rotation part of the motion (the translation still follows the twist).
  Eigen::Isometry3d predict(double stamp, const Eigen::Quaterniond* gyro_rotation = nullptr) const;

  /// Records the estimated pose at `stamp` [s] and re-estimates the twist from the previous pose.
  /// A non-positive time step keeps the twist. `smoothing` [s] >= 0 is the time constant of smoothedTwist
  /// (0: no smoothing).
  void update(const Eigen::Isometry3d& pose, double stamp, double smoothing = 0.0);

 private:
  bool initialized_ = false;
  double stamp_ = 0.0;
  Eigen::Isometry3d pose_ = Eigen::Isometry3d::Identity();
  Twist twist_ = Twist::Zero();
  Twist smoothed_twist_ = Twist::Zero();
  bool twist_measured_ = false;  ///< a twist has been measured since the reset
};

/// How far the constant-velocity prediction is trusted, and where to search when it is not.
struct PredictionConfig {
  /// [s] > 0: past this time since the last accepted match the velocity is no longer extrapolated (a gap, a
  /// stop, a loss); the pose is searched around the last accepted one instead.
  double max_extrapolation = 2.0;
  /// [m/s] > 0: speed bound before a speed has been measured (the first scans after an initial pose).
  double max_speed = 15.0;
  /// [rad/s] > 0: yaw-rate bound before one has been measured, when no gyro covers the interval. Each 0.1 rad
  /// of yaw range multiplies the search's candidates; a hand-held sensor without IMU may need 1.5.
  double max_yaw_rate = 0.5;
  /// >= 1: the highest speed and yaw rate measured since the initial pose are multiplied by this.
  double margin = 1.5;
  double min_radius = 1.0;     ///< [m] >= 0, search radius at zero elapsed time
  double max_radius = 100.0;   ///< [m] >= min_radius (the global search covers 200 m x 200 m in about a second)
  double min_yaw_range = 0.0;  ///< [rad] >= 0, yaw searched at least this far when rotation is uncertain

  std::string validate() const;
};

/// The fastest motion measured so far (speed [m/s], yaw rate [rad/s]); unset before the first measurement.
struct MotionBounds {
  bool measured = false;
  double speed = 0.0;
  double yaw_rate = 0.0;
  void add(const Twist& twist);
};

/// The region to search `elapsed` [s] after the last accepted pose `last`: a disc of radius
/// min_radius + speed_bound * elapsed (at most max_radius) and, when `rotation_known` is false (no gyro),
/// yaws within min_yaw_range + yaw_rate_bound * elapsed (at most pi); the bounds are margin times the
/// fastest motion seen, or max_speed / max_yaw_rate before any was measured.
SearchRegion boundedSearchRegion(const Eigen::Isometry3d& last, double elapsed, const MotionBounds& seen,
                                 bool rotation_known, const PredictionConfig& config);

}  // namespace grid_puzzle_localization
