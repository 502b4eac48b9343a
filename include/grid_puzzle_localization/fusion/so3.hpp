// Rotation-group helpers shared by the IMU preintegration and the factor graph: exp / log maps templated so
// Ceres' automatic differentiation can run through them, and the right Jacobian of SO(3). No ROS.
#pragma once

#include <ceres/rotation.h>

#include <Eigen/Core>
#include <Eigen/Geometry>

namespace grid_puzzle_localization {

template <typename T>
Eigen::Matrix<T, 3, 3> skew(const Eigen::Matrix<T, 3, 1>& v) {
  Eigen::Matrix<T, 3, 3> m;
  m << T(0), -v.z(), v.y(), v.z(), T(0), -v.x(), -v.y(), v.x(), T(0);
  return m;
}

/// Exp: rotation vector [rad] -> unit quaternion (exact near zero, differentiable by Jets).
template <typename T>
Eigen::Quaternion<T> quatExp(const Eigen::Matrix<T, 3, 1>& rotation_vector) {
  T wxyz[4];
  ceres::AngleAxisToQuaternion(rotation_vector.data(), wxyz);
  return Eigen::Quaternion<T>(wxyz[0], wxyz[1], wxyz[2], wxyz[3]);
}

/// Log: unit quaternion -> rotation vector [rad] with angle in [0, pi] (q and -q give the same vector).
template <typename T>
Eigen::Matrix<T, 3, 1> quatLog(const Eigen::Quaternion<T>& q) {
  const T sign = q.w() < T(0) ? T(-1) : T(1);
  const T wxyz[4] = {sign * q.w(), sign * q.x(), sign * q.y(), sign * q.z()};
  Eigen::Matrix<T, 3, 1> v;
  ceres::QuaternionToAngleAxis(wxyz, v.data());
  return v;
}

/// Right Jacobian of SO(3): Exp(phi + d) ~= Exp(phi) Exp(Jr(phi) d) for small d.
inline Eigen::Matrix3d rightJacobian(const Eigen::Vector3d& phi) {
  const double angle = phi.norm();
  const Eigen::Matrix3d k = skew(phi);
  if (angle < 1e-6) return Eigen::Matrix3d::Identity() - 0.5 * k;
  const double a2 = angle * angle;
  return Eigen::Matrix3d::Identity() - (1.0 - std::cos(angle)) / a2 * k +
         (angle - std::sin(angle)) / (a2 * angle) * k * k;
}

}  // namespace grid_puzzle_localization
