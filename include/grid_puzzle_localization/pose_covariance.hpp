// Pose covariance from the NDT Hessian (Laplace approximation), made safe to publish. No ROS.
#pragma once

#include <Eigen/Core>
#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <string>

#include "grid_puzzle_localization/matrix6.hpp"

namespace grid_puzzle_localization {

struct CovarianceConfig {
  /// Multiplies inv(H). The NDT score is a robust sum over points, not a calibrated log-likelihood,
  /// so inv(H) alone is over-confident; the scale is the knob that calibrates it (dimensionless, > 0).
  double scale = 1.0;
  double min_translation_std = 0.01;  ///< [m] floor added to x y z (matching is never perfect)
  double min_rotation_std = 0.001;    ///< [rad] floor added to roll pitch yaw
  double max_translation_std = 10.0;  ///< [m] reported along unconstrained directions
  double max_rotation_std = 3.14;     ///< [rad] reported along unconstrained directions

  std::string validate() const;
};

/// Covariance of (x, y, z, roll, pitch, yaw) from `hessian`, the Hessian of the matching cost that is
/// minimised (positive semi-definite at a minimum), in the same parameter order. Directions whose
/// curvature is not positive (degenerate scene, failed match) get the max std projected on them; non-finite input gives
/// the max-std diagonal. The result is symmetric, positive definite and finite.
Matrix6d covarianceFromHessian(const Matrix6d& hessian, const CovarianceConfig& config);

/// `cov` of (x y z roll pitch yaw) in the NDT's parametrisation T = t * Rx(roll) Ry(pitch) Rz(yaw), at the
/// angles `roll` and `pitch` of the pose, -> ROS's order and frame: (x y z, rotation about the fixed X Y Z
/// axes of the parent frame), the perturbation R' = exp([dtheta]x) R, by the first-order map
/// dtheta = dR R^T = roll' X + pitch' Rx(roll) Y + yaw' Rx(roll) Ry(pitch) Z.
Matrix6d fixedAxisCovariance(const Matrix6d& cov, double roll, double pitch);

/// A pose covariance in the parent frame (ROS order, translation and rotation perturbations about the
/// parent's axes) expressed in the body frame of the pose with rotation `parent_R_body`.
Matrix6d bodyFrameCovariance(const Matrix6d& cov, const Eigen::Matrix3d& parent_R_body);

/// Covariance to report with a prediction (no accepted match): the max-std diagonal, an honest
/// statement that the pose was not measured.
Matrix6d predictionCovariance(const CovarianceConfig& config);

}  // namespace grid_puzzle_localization
