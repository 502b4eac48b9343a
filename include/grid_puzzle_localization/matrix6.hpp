// Six-vectors and 6x6 matrices over x y z roll pitch yaw: NDT derivatives, pose covariances, fusion information.
#pragma once

#include <Eigen/Core>

namespace grid_puzzle_localization {

using Vector6d = Eigen::Matrix<double, 6, 1>;
using Matrix6d = Eigen::Matrix<double, 6, 6>;

}  // namespace grid_puzzle_localization
