// Sliding-window factor graph over scan states (pose, velocity, gyro and accelerometer biases), solved with
// Ceres: NDT pose factors, IMU preintegration factors between consecutive states, optional wheel-odometry
// relative-pose factors, zero-velocity factors while standing still, and the prior left by marginalizing
// the states that leave the window (the block map paper, section III-D). No ROS.
#pragma once

#include <Eigen/Geometry>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "grid_puzzle_localization/fusion/imu_preintegration.hpp"
#include "grid_puzzle_localization/pose_covariance.hpp"

// Ceres stays out of this header (sliding_window.cpp includes fusion/factors.hpp): the localizer's header
// includes this one, and Ceres's headers would more than double the compile time of everything that includes it.
namespace ceres {
class CostFunction;
}

namespace grid_puzzle_localization {

class PoseManifold;

struct SlidingWindowConfig {
  double gravity = 9.80665;  ///< [m/s^2] magnitude; gravity points along -z of the map frame (REP 103)
  /// IMU noise (continuous time, Kalibr convention); defaults are an ADIS16448-class MEMS.
  double gyro_noise_density = 1.7e-4;   ///< [rad/s/sqrt(Hz)] > 0
  double accel_noise_density = 2.0e-3;  ///< [m/s^2/sqrt(Hz)] > 0
  double gyro_random_walk = 2.0e-5;     ///< [rad/s^2/sqrt(Hz)] > 0
  double accel_random_walk = 3.0e-3;    ///< [m/s^3/sqrt(Hz)] > 0
  /// Pose of the IMU in base_link. Samples are moved to base_link (rotation, plus the lever arm's
  /// centripetal and tangential acceleration).
  Eigen::Isometry3d base_T_imu = Eigen::Isometry3d::Identity();
  int max_states = 20;   ///< N_a >= 2: states kept while the map source stays the same
  int reset_states = 5;  ///< N_r in [1, max_states]: states kept after a block switch (shrink())
  /// [s] > 0: a sample is held at most this long; a longer hole is an IMU dropout, bridged by a
  /// constant-velocity model with the gap noise below.
  double max_imu_gap = 0.05;
  double gap_accel_density = 1.0;       ///< [m/s^2/sqrt(Hz)] > 0, unmodelled acceleration over a dropout
  double gap_gyro_density = 0.1;        ///< [rad/s/sqrt(Hz)] > 0, unmodelled turn rate over a dropout
  double initial_velocity_std = 10.0;   ///< [m/s] > 0, prior on the first state's velocity (zero mean)
  double initial_gyro_bias_std = 0.01;  ///< [rad/s] > 0, prior on the first state's gyro bias
  double initial_accel_bias_std = 0.1;  ///< [m/s^2] > 0, prior on the first state's accelerometer bias
  /// Zero-velocity update: between two states whose IMU samples all turn slower than zupt_max_gyro and whose
  /// specific force varies less than zupt_max_accel_std and whose mean is within zupt_max_accel_std of gravity
  /// alone (at the earlier state's attitude and bias), with the earlier state slower than zupt_max_speed, the
  /// robot is held still (velocity zero with zupt_velocity_std, no relative motion with zupt_pose_std).
  double zupt_max_speed = 0.1;         ///< [m/s] >= 0 (0 disables zero-velocity updates)
  double zupt_max_gyro = 0.02;         ///< [rad/s] > 0
  double zupt_max_accel_std = 0.1;     ///< [m/s^2] > 0
  double zupt_velocity_std = 0.01;     ///< [m/s] > 0
  double zupt_pose_std = 0.005;        ///< [m] and [rad] > 0
  double odom_translation_std = 0.05;  ///< [m] > 0 per factor (relative pose between two states)
  double odom_rotation_std = 0.01;     ///< [rad] > 0 per factor
  double odom_max_offset = 0.05;       ///< [s] >= 0: an odometry sample this close to a state's stamp is used
  int max_iterations = 10;             ///< >= 1, Ceres iterations per update

  /// Empty when usable, else every bad value with its allowed range.
  std::string validate() const;
};

/// One IMU sample in the IMU frame. The variances come from the message's covariance (diagonal mean); a
/// negative value means the message had none and the configured noise density is used.
struct ImuSample {
  double stamp = 0.0;                               ///< [s]
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();   ///< angular velocity [rad/s]
  Eigen::Vector3d accel = Eigen::Vector3d::Zero();  ///< specific force [m/s^2]
  double gyro_variance = -1.0;                      ///< [rad^2/s^2] per axis of one sample
  double accel_variance = -1.0;                     ///< [m^2/s^4] per axis of one sample
  bool has_accel = true;  ///< false: the IMU gives no specific force (sensor_msgs/Imu: covariance element 0 at -1)
  bool has_gyro = true;   ///< false: the IMU gives no angular velocity (the same convention)
};

/// The estimate of one state.
struct FusedState {
  double stamp = 0.0;                                      ///< [s]
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  ///< map_T_base
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();      ///< [m/s], map frame
  ImuBias bias;
};

/// What the last update did (for status and the benchmark).
struct WindowUpdateReport {
  double solve_ms = 0.0;        ///< Ceres solve
  double marginalize_ms = 0.0;  ///< Schur complements of the states that left
  int iterations = 0;
  double imu_gap = 0.0;     ///< [s] of the last interval bridged without IMU samples
  bool stationary = false;  ///< a zero-velocity update was added
  bool odometry = false;    ///< an odometry factor was added
};

/// Information of an NDT match in the window's pose tangent, from the covariance of the NDT parameters
/// (x y z [m], roll pitch yaw [rad] of T = Translation Rx Ry Rz, see ndt.hpp) at `pose`.
Matrix6d ndtInformation(const Eigen::Isometry3d& pose, const Matrix6d& ndt_covariance);

class SlidingWindow {
 public:
  /// Throws std::invalid_argument naming the bad values when config.validate() is not empty.
  explicit SlidingWindow(const SlidingWindowConfig& config);
  ~SlidingWindow();
  const SlidingWindowConfig& config() const { return config_; }
  /// The IMU's pose in base_link for the samples added from now on (known once TF has the IMU frame).
  /// Throws std::invalid_argument when not finite.
  void setBaseTImu(const Eigen::Isometry3d& base_T_imu);

  /// Buffers a sample. A sample not newer than the last one (out of order, duplicated) or not finite is
  /// dropped with a warning; returns false then.
  bool addImu(const ImuSample& sample);
  /// Buffers a wheel-odometry pose (odom_T_base) at `stamp` [s]; out-of-order samples are dropped.
  void addOdometry(double stamp, const Eigen::Isometry3d& odom_T_base);

  /// Adds the state at `stamp` [s] with the NDT pose `measured` (map_T_base) and its `information` (pose
  /// tangent, see ndtInformation), or no measurement (nullptr: the match was rejected), solves the window and
  /// marginalizes states beyond max_states. A stamp not after the last state's is refused with a warning.
  /// Returns the newest state; nothing before the first measured state.
  std::optional<FusedState> addScan(double stamp, const Eigen::Isometry3d* measured, const Matrix6d& information);

  /// The newest state propagated with the buffered IMU samples to `stamp` [s] (>= its stamp): the initial
  /// guess and deskew motion of the next scan. Nothing while the window is empty.
  std::optional<FusedState> predict(double stamp) const;
  std::optional<FusedState> latest() const;
  std::size_t size() const { return states_.size(); }
  const WindowUpdateReport& lastReport() const { return report_; }

  /// The map source switched blocks: keep reset_states states, the rest becomes the prior.
  void shrink();
  /// Forgets everything (localizer reset, new initial pose).
  void reset();

  /// Warnings since the last call (dropouts, refused stamps, missing IMU covariance), each naming its input.
  std::vector<std::string> takeWarnings();

 private:
  struct State;
  struct Factor;
  struct Interval;
  struct BaseSample {
    double stamp;
    Eigen::Vector3d gyro, accel;  // base_link
    double gyro_variance, accel_variance;
  };

  Interval integrate(double t0, double t1, const State& from) const;
  void solve();
  void marginalizeOldest();
  void addFactor(ceres::CostFunction* cost, std::vector<double*> blocks);
  FusedState toFused(const State& s) const;
  void warn(const std::string& message);

  SlidingWindowConfig config_;
  Eigen::Vector3d gravity_;
  std::unique_ptr<PoseManifold> manifold_;
  std::deque<std::unique_ptr<State>> states_;
  std::vector<Factor> factors_;
  std::deque<BaseSample> imu_;
  std::deque<std::pair<double, Eigen::Isometry3d>> odometry_;
  std::vector<std::string> warnings_;
  bool warned_missing_covariance_ = false;
  WindowUpdateReport report_;
};

}  // namespace grid_puzzle_localization
