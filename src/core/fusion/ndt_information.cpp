// NDT covariance (in the matcher's Euler parameters) -> information in the window's pose tangent.
#include <cmath>

#include "grid_puzzle_localization/fusion/sliding_window.hpp"
#include "grid_puzzle_localization/fusion/so3.hpp"
#include "grid_puzzle_localization/ndt.hpp"

namespace grid_puzzle_localization {

Matrix6d ndtInformation(const Eigen::Isometry3d& pose, const Matrix6d& ndt_covariance) {
  // J = d(NDT parameters)/d(tangent) by central differences: the Euler map is smooth away from pitch = 90 deg,
  // and a step of 1e-6 gives J to ~1e-9, far below the covariance's own accuracy.
  constexpr double h = 1e-6;
  Matrix6d J;
  for (int k = 0; k < 6; ++k) {
    Vector6d d = Vector6d::Zero();
    d[k] = h;
    auto moved = [&pose](const Vector6d& delta) {
      Eigen::Isometry3d t = pose;
      t.translation() += delta.head<3>();
      t.linear() = pose.linear() * quatExp(Eigen::Vector3d(delta.tail<3>())).toRotationMatrix();
      return matrixToPose(t.matrix());
    };
    Vector6d diff = moved(d) - moved(-d);
    for (int a = 3; a < 6; ++a) diff[a] = std::remainder(diff[a], 2.0 * M_PI);
    J.col(k) = diff / (2.0 * h);
  }
  const Matrix6d sym = 0.5 * (ndt_covariance + ndt_covariance.transpose());
  return J.transpose() * sym.inverse() * J;
}

}  // namespace grid_puzzle_localization
