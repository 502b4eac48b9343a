// Roll, pitch and yaw as users see them: ROS's fixed-axis convention, R = Rz(yaw) * Ry(pitch) * Rx(roll)
// (rotation about the fixed X axis first, then Y, then Z), as tf2's Quaternion::setRPY. No ROS.
#pragma once

#include <Eigen/Geometry>
#include <cmath>

namespace grid_puzzle_localization {

using XyzRpy = Eigen::Matrix<double, 6, 1>;  ///< x y z [m], roll pitch yaw [rad]

inline Eigen::Matrix3d rotationFromRpy(double roll, double pitch, double yaw) {
  return (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()))
      .toRotationMatrix();
}

inline Eigen::Isometry3d poseFromXyzRpy(const XyzRpy& v) {
  Eigen::Isometry3d t = Eigen::Isometry3d::Identity();
  t.translation() = v.head<3>();
  t.linear() = rotationFromRpy(v(3), v(4), v(5));
  return t;
}

/// Inverse of rotationFromRpy with pitch in [-pi/2, pi/2], roll and yaw in (-pi, pi].
inline Eigen::Vector3d rpyFromRotation(const Eigen::Matrix3d& r) {
  const double pitch = std::asin(std::max(-1.0, std::min(1.0, -r(2, 0))));
  const double roll = std::atan2(r(2, 1), r(2, 2));
  const double yaw = std::atan2(r(1, 0), r(0, 0));
  return {roll, pitch, yaw};
}

inline XyzRpy xyzRpyFromPose(const Eigen::Isometry3d& t) {
  XyzRpy v;
  v.head<3>() = t.translation();
  v.tail<3>() = rpyFromRotation(t.rotation());
  return v;
}

}  // namespace grid_puzzle_localization
