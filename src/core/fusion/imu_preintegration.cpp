#include "grid_puzzle_localization/fusion/imu_preintegration.hpp"

#include "grid_puzzle_localization/fusion/so3.hpp"
#include "grid_puzzle_localization/matrix6.hpp"

namespace grid_puzzle_localization {

void ImuPreintegration::integrate(double dt, const Eigen::Vector3d& gyro, const Eigen::Vector3d& accel,
                                  double gyro_variance, double accel_variance) {
  const Eigen::Vector3d w = gyro - bias_.gyro;
  const Eigen::Vector3d a = accel - bias_.accel;
  const Eigen::Vector3d phi = w * dt;
  const Eigen::Matrix3d step = quatExp(phi).toRotationMatrix();
  const Eigen::Matrix3d jr = rightJacobian(phi);
  const Eigen::Matrix3d r = delta_rotation_.toRotationMatrix();
  const Eigen::Matrix3d r_a = r * skew(a);
  const double dt2 = dt * dt;

  // Error-state transition (Forster eq. 62), errors ordered rotation, velocity, position.
  Matrix9d A = Matrix9d::Identity();
  A.block<3, 3>(0, 0) = step.transpose();
  A.block<3, 3>(3, 0) = -r_a * dt;
  A.block<3, 3>(6, 0) = -0.5 * r_a * dt2;
  A.block<3, 3>(6, 3) = Eigen::Matrix3d::Identity() * dt;
  Eigen::Matrix<double, 9, 6> B = Eigen::Matrix<double, 9, 6>::Zero();
  B.block<3, 3>(0, 0) = jr * dt;
  B.block<3, 3>(3, 3) = r * dt;
  B.block<3, 3>(6, 3) = 0.5 * r * dt2;
  Vector6d q;
  q << Eigen::Vector3d::Constant(gyro_variance), Eigen::Vector3d::Constant(accel_variance);
  covariance_ = A * covariance_ * A.transpose() + B * q.asDiagonal() * B.transpose();

  // Bias Jacobians (Forster appendix B), updated with the rotation before this step.
  d_position_d_ba_ += d_velocity_d_ba_ * dt - 0.5 * r * dt2;
  d_position_d_bg_ += d_velocity_d_bg_ * dt - 0.5 * r_a * d_rotation_d_bg_ * dt2;
  d_velocity_d_ba_ -= r * dt;
  d_velocity_d_bg_ -= r_a * d_rotation_d_bg_ * dt;
  d_rotation_d_bg_ = step.transpose() * d_rotation_d_bg_ - jr * dt;

  delta_position_ += delta_velocity_ * dt + 0.5 * r * a * dt2;
  delta_velocity_ += r * a * dt;
  delta_rotation_ = (delta_rotation_ * quatExp(phi)).normalized();
  duration_ += dt;
}

Eigen::Quaterniond ImuPreintegration::correctedRotation(const ImuBias& bias) const {
  return delta_rotation_ * quatExp(Eigen::Vector3d(d_rotation_d_bg_ * (bias.gyro - bias_.gyro)));
}

Eigen::Vector3d ImuPreintegration::correctedVelocity(const ImuBias& bias) const {
  return delta_velocity_ + d_velocity_d_bg_ * (bias.gyro - bias_.gyro) + d_velocity_d_ba_ * (bias.accel - bias_.accel);
}

Eigen::Vector3d ImuPreintegration::correctedPosition(const ImuBias& bias) const {
  return delta_position_ + d_position_d_bg_ * (bias.gyro - bias_.gyro) + d_position_d_ba_ * (bias.accel - bias_.accel);
}

}  // namespace grid_puzzle_localization
