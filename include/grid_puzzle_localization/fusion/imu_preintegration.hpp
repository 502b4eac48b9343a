// On-manifold IMU preintegration (Forster et al., "On-Manifold Preintegration for Real-Time Visual-Inertial
// Odometry", T-RO 2017): the relative rotation, velocity and position change between two states, expressed in
// the first state's body frame and independent of its pose, with its covariance and first-order Jacobians
// w.r.t. the biases so a bias change corrects the deltas without re-integration. No ROS.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace grid_puzzle_localization {

using Matrix9d = Eigen::Matrix<double, 9, 9>;

/// Gyro and accelerometer biases [rad/s, m/s^2] at which the deltas are integrated.
struct ImuBias {
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();
  Eigen::Vector3d accel = Eigen::Vector3d::Zero();
};

class ImuPreintegration {
 public:
  explicit ImuPreintegration(const ImuBias& bias = ImuBias()) : bias_(bias) {}

  /// Integrates one measurement held constant for `dt` [s] > 0: `gyro` [rad/s] and `accel` (specific force,
  /// [m/s^2]) in the body frame. `gyro_variance` [rad^2/s^2] and `accel_variance` [m^2/s^4] are the per-axis
  /// variances of the measurement noise averaged over dt (a continuous noise density sigma gives sigma^2 / dt).
  void integrate(double dt, const Eigen::Vector3d& gyro, const Eigen::Vector3d& accel, double gyro_variance,
                 double accel_variance);

  double duration() const { return duration_; }  ///< [s] integrated so far
  const ImuBias& bias() const { return bias_; }
  const Eigen::Quaterniond& deltaRotation() const { return delta_rotation_; }  ///< R_i^T R_j
  const Eigen::Vector3d& deltaVelocity() const { return delta_velocity_; }     ///< [m/s], frame i, no gravity
  const Eigen::Vector3d& deltaPosition() const { return delta_position_; }     ///< [m], frame i, no gravity
  /// Covariance of the errors (rotation [rad], velocity [m/s], position [m]), in that order.
  const Matrix9d& covariance() const { return covariance_; }

  const Eigen::Matrix3d& rotationByGyroBias() const { return d_rotation_d_bg_; }
  const Eigen::Matrix3d& velocityByGyroBias() const { return d_velocity_d_bg_; }
  const Eigen::Matrix3d& velocityByAccelBias() const { return d_velocity_d_ba_; }
  const Eigen::Matrix3d& positionByGyroBias() const { return d_position_d_bg_; }
  const Eigen::Matrix3d& positionByAccelBias() const { return d_position_d_ba_; }

  /// The deltas for biases `bias` (first order around the integration bias, Forster eq. 44).
  Eigen::Quaterniond correctedRotation(const ImuBias& bias) const;
  Eigen::Vector3d correctedVelocity(const ImuBias& bias) const;
  Eigen::Vector3d correctedPosition(const ImuBias& bias) const;

 private:
  ImuBias bias_;
  double duration_ = 0.0;
  Eigen::Quaterniond delta_rotation_ = Eigen::Quaterniond::Identity();
  Eigen::Vector3d delta_velocity_ = Eigen::Vector3d::Zero();
  Eigen::Vector3d delta_position_ = Eigen::Vector3d::Zero();
  Matrix9d covariance_ = Matrix9d::Zero();
  Eigen::Matrix3d d_rotation_d_bg_ = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d d_velocity_d_bg_ = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d d_velocity_d_ba_ = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d d_position_d_bg_ = Eigen::Matrix3d::Zero();
  Eigen::Matrix3d d_position_d_ba_ = Eigen::Matrix3d::Zero();
};

}  // namespace grid_puzzle_localization
