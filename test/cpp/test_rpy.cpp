#include <gtest/gtest.h>

#include <cmath>

#include "grid_puzzle_localization/rpy.hpp"

namespace gpl = grid_puzzle_localization;

// ROS's fixed-axis convention (tf2 Quaternion::setRPY): roll about the fixed X first, then pitch about the fixed
// Y, then yaw about the fixed Z. Closed form: the quaternion product q = qz(yaw) qy(pitch) qx(roll) written out.
TEST(Rpy, MatchesTheFixedAxisQuaternionClosedForm) {
  const double roll = 0.3, pitch = -0.5, yaw = 2.0;
  const double cr = std::cos(roll / 2), sr = std::sin(roll / 2);
  const double cp = std::cos(pitch / 2), sp = std::sin(pitch / 2);
  const double cy = std::cos(yaw / 2), sy = std::sin(yaw / 2);
  const Eigen::Quaterniond q(cr * cp * cy + sr * sp * sy, sr * cp * cy - cr * sp * sy, cr * sp * cy + sr * cp * sy,
                             cr * cp * sy - sr * sp * cy);
  EXPECT_LT((gpl::rotationFromRpy(roll, pitch, yaw) - q.toRotationMatrix()).norm(), 1e-12);
  // Rolling first about the fixed X: the body's y axis goes to (0, cos roll, sin roll) before pitch and yaw.
  const Eigen::Vector3d y_after_roll = gpl::rotationFromRpy(roll, 0.0, 0.0) * Eigen::Vector3d::UnitY();
  EXPECT_LT((y_after_roll - Eigen::Vector3d(0, std::cos(roll), std::sin(roll))).norm(), 1e-12);
}

TEST(Rpy, RoundTripsThroughAPose) {
  const gpl::XyzRpy v = (gpl::XyzRpy() << 1.0, -2.0, 0.5, -0.4, 1.2, -2.9).finished();
  EXPECT_LT((gpl::xyzRpyFromPose(gpl::poseFromXyzRpy(v)) - v).norm(), 1e-12);
}
