#include "grid_puzzle_localization/pose_covariance.hpp"

#include <Eigen/Eigenvalues>
#include <sstream>

namespace grid_puzzle_localization {
namespace {

Vector6d squared(double t, double r) {
  Vector6d v;
  v << t * t, t * t, t * t, r * r, r * r, r * r;
  return v;
}

}  // namespace

std::string CovarianceConfig::validate() const {
  std::ostringstream err;
  if (!(scale > 0.0)) err << "covariance/scale must be > 0 (got " << scale << "); ";
  if (!(min_translation_std >= 0.0)) err << "covariance/min_translation_std must be >= 0 m; ";
  if (!(min_rotation_std >= 0.0)) err << "covariance/min_rotation_std must be >= 0 rad; ";
  if (!(max_translation_std > min_translation_std))
    err << "covariance/max_translation_std must be > min_translation_std; ";
  if (!(max_rotation_std > min_rotation_std)) err << "covariance/max_rotation_std must be > min_rotation_std; ";
  return err.str();
}

Matrix6d predictionCovariance(const CovarianceConfig& config) {
  return squared(config.max_translation_std, config.max_rotation_std).asDiagonal();
}

Matrix6d covarianceFromHessian(const Matrix6d& hessian, const CovarianceConfig& config) {
  if (!hessian.allFinite()) return predictionCovariance(config);
  const Matrix6d h = 0.5 * (hessian + hessian.transpose());
  const Eigen::SelfAdjointEigenSolver<Matrix6d> eig(h);
  if (eig.info() != Eigen::Success) return predictionCovariance(config);
  const Vector6d lambda = eig.eigenvalues();
  const double lambda_max = lambda.cwiseAbs().maxCoeff();
  const Vector6d max_var = squared(config.max_translation_std, config.max_rotation_std);
  // Curvatures below this are round-off or a flat direction: no information there.
  const double floor = std::max(lambda_max * 1e-12, 1e-300);
  // A flat direction carries no information: it gets the max variance projected onto it.
  Matrix6d cov = Matrix6d::Zero();
  for (int i = 0; i < 6; ++i) {
    const Vector6d v = eig.eigenvectors().col(i);
    const double var = lambda(i) > floor ? config.scale / lambda(i) : v.dot(max_var.cwiseProduct(v));
    cov += var * v * v.transpose();
  }
  // Clamp each parameter's variance to its max: rescale rows and columns so the correlations stay.
  Vector6d s = Vector6d::Ones();
  for (int i = 0; i < 6; ++i)
    if (cov(i, i) > max_var(i)) s(i) = std::sqrt(max_var(i) / cov(i, i));
  cov = s.asDiagonal() * cov * s.asDiagonal();
  const Vector6d min_var = squared(config.min_translation_std, config.min_rotation_std);
  cov += min_var.asDiagonal();
  cov = 0.5 * (cov + cov.transpose());
  if (!cov.allFinite()) return predictionCovariance(config);
  return cov;
}

Matrix6d fixedAxisCovariance(const Matrix6d& cov, double roll, double pitch) {
  const Eigen::Matrix3d rx = Eigen::AngleAxisd(roll, Eigen::Vector3d::UnitX()).toRotationMatrix();
  const Eigen::Matrix3d ry = Eigen::AngleAxisd(pitch, Eigen::Vector3d::UnitY()).toRotationMatrix();
  Matrix6d j = Matrix6d::Identity();
  j.block<3, 1>(3, 3) = Eigen::Vector3d::UnitX();
  j.block<3, 1>(3, 4) = rx * Eigen::Vector3d::UnitY();
  j.block<3, 1>(3, 5) = rx * ry * Eigen::Vector3d::UnitZ();
  const Matrix6d out = j * cov * j.transpose();
  return 0.5 * (out + out.transpose());
}

Matrix6d bodyFrameCovariance(const Matrix6d& cov, const Eigen::Matrix3d& parent_R_body) {
  Matrix6d r = Matrix6d::Zero();
  r.topLeftCorner<3, 3>() = parent_R_body.transpose();
  r.bottomRightCorner<3, 3>() = parent_R_body.transpose();
  const Matrix6d out = r * cov * r.transpose();
  return 0.5 * (out + out.transpose());
}

}  // namespace grid_puzzle_localization
