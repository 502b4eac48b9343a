#include <gtest/gtest.h>

#include <Eigen/Eigenvalues>
#include <Eigen/LU>
#include <limits>

#include "grid_puzzle_localization/pose_covariance.hpp"

namespace gpl = grid_puzzle_localization;

TEST(PoseCovariance, WellConditionedHessianGivesScaledInversePlusFloor) {
  // A random SPD Hessian: its inverse is the truth.
  Eigen::Matrix<double, 6, 6> a;
  a << 3, 1, 0, 0, 2, 0, 1, 4, 1, 0, 0, 0, 0, 1, 5, 1, 0, 0, 0, 0, 1, 6, 1, 0, 2, 0, 0, 1, 7, 1, 0, 0, 0, 0, 1, 8;
  const gpl::Matrix6d h = 100.0 * a.transpose() * a;
  gpl::CovarianceConfig cfg;
  cfg.scale = 2.0;
  cfg.min_translation_std = 0.0;
  cfg.min_rotation_std = 0.0;
  const gpl::Matrix6d cov = gpl::covarianceFromHessian(h, cfg);
  EXPECT_LT((cov - 2.0 * h.inverse()).norm(), 1e-12 * h.inverse().norm());
  cfg.min_translation_std = 0.1;
  cfg.min_rotation_std = 0.01;
  const gpl::Matrix6d floored = gpl::covarianceFromHessian(h, cfg);
  EXPECT_NEAR(floored(0, 0) - cov(0, 0), 0.01, 1e-12);
  EXPECT_NEAR(floored(5, 5) - cov(5, 5), 1e-4, 1e-12);
}

TEST(PoseCovariance, FlatDirectionGetsTheMaxVarianceNotInfinity) {
  // A corridor along x + y: no curvature in that direction.
  gpl::Matrix6d h = gpl::Matrix6d::Identity() * 1e4;
  h.topLeftCorner<2, 2>() << 0.5e4, -0.5e4, -0.5e4, 0.5e4;
  gpl::CovarianceConfig cfg;
  const gpl::Matrix6d cov = gpl::covarianceFromHessian(h, cfg);
  ASSERT_TRUE(cov.allFinite());
  const Eigen::Vector2d along(1 / std::sqrt(2.0), 1 / std::sqrt(2.0));
  const double var_along = along.dot(cov.topLeftCorner<2, 2>() * along);
  EXPECT_GT(var_along, 0.5 * cfg.max_translation_std * cfg.max_translation_std);
  EXPECT_LE(cov(0, 0), cfg.max_translation_std * cfg.max_translation_std + 1e-4 + 1e-9);
  EXPECT_GT(Eigen::SelfAdjointEigenSolver<gpl::Matrix6d>(cov).eigenvalues().minCoeff(), 0.0);
}

TEST(PoseCovariance, NonFiniteOrNegativeHessianNeverGivesNaN) {
  gpl::CovarianceConfig cfg;
  gpl::Matrix6d h = gpl::Matrix6d::Identity();
  h(2, 3) = std::numeric_limits<double>::quiet_NaN();
  gpl::Matrix6d cov = gpl::covarianceFromHessian(h, cfg);
  EXPECT_TRUE(cov.allFinite());
  EXPECT_DOUBLE_EQ(cov(0, 0), cfg.max_translation_std * cfg.max_translation_std);
  cov = gpl::covarianceFromHessian(-gpl::Matrix6d::Identity(), cfg);  // a maximum, not a minimum
  EXPECT_TRUE(cov.allFinite());
  EXPECT_NEAR(cov(4, 4), cfg.max_rotation_std * cfg.max_rotation_std + 1e-6, 1e-9);
  cov = gpl::covarianceFromHessian(gpl::Matrix6d::Zero(), cfg);
  EXPECT_TRUE(cov.allFinite());
}

TEST(PoseCovariance, ValidateNamesTheBadValue) {
  gpl::CovarianceConfig cfg;
  EXPECT_EQ(cfg.validate(), "");
  cfg.scale = 0.0;
  EXPECT_NE(cfg.validate().find("covariance/scale"), std::string::npos);
}

namespace {

// The NDT's parametrisation T = t * Rx(a) Ry(b) Rz(c) (ndt.hpp).
Eigen::Matrix3d ndtRotation(double a, double b, double c) {
  return (Eigen::AngleAxisd(a, Eigen::Vector3d::UnitX()) * Eigen::AngleAxisd(b, Eigen::Vector3d::UnitY()) *
          Eigen::AngleAxisd(c, Eigen::Vector3d::UnitZ()))
      .toRotationMatrix();
}

Eigen::Vector3d logSo3(const Eigen::Matrix3d& r) {
  const Eigen::AngleAxisd aa(r);
  return aa.angle() * aa.axis();
}

}  // namespace

// A cost that is quadratic in the rotation about the fixed axes, 1/2 dtheta^T W dtheta: in the NDT's angles its
// Hessian is J^T W J (J by finite differences of the rotation, independent of the closed form under test), and
// the covariance ROS expects is W^-1 exactly.
TEST(PoseCovariance, FixedAxisCovarianceIsTheInverseCurvatureAboutTheFixedAxes) {
  const double a = 0.3, b = -0.4, c = 1.2;
  const Eigen::Matrix3d r0 = ndtRotation(a, b, c);
  Eigen::Matrix3d j;
  const double h = 1e-6;
  for (int k = 0; k < 3; ++k) {
    Eigen::Vector3d p(a, b, c), m(a, b, c);
    p(k) += h;
    m(k) -= h;
    j.col(k) = (logSo3(ndtRotation(p(0), p(1), p(2)) * r0.transpose()) -
                logSo3(ndtRotation(m(0), m(1), m(2)) * r0.transpose())) /
               (2 * h);
  }
  Eigen::Matrix3d w;
  w << 4, 1, 0.5, 1, 3, 0.2, 0.5, 0.2, 2;
  gpl::Matrix6d hessian = gpl::Matrix6d::Zero();
  hessian.topLeftCorner<3, 3>() = Eigen::Vector3d(9, 16, 25).asDiagonal();
  hessian.bottomRightCorner<3, 3>() = j.transpose() * w * j;
  const gpl::Matrix6d cov = gpl::fixedAxisCovariance(hessian.inverse(), a, b);
  EXPECT_LT((cov.bottomRightCorner<3, 3>() - w.inverse()).norm(), 1e-6);
  EXPECT_LT(
      (cov.topLeftCorner<3, 3>() - Eigen::Vector3d(1.0 / 9, 1.0 / 16, 1.0 / 25).asDiagonal().toDenseMatrix()).norm(),
      1e-12);
}

// A body turned 90 deg about z: the map's x uncertainty is the body's y.
TEST(PoseCovariance, BodyFrameCovarianceRotatesBothBlocks) {
  gpl::Matrix6d cov = gpl::Matrix6d::Zero();
  cov.diagonal() << 4, 1, 0.25, 0.09, 0.04, 0.01;
  const Eigen::Matrix3d r = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const gpl::Matrix6d body = gpl::bodyFrameCovariance(cov, r);
  gpl::Matrix6d expected = gpl::Matrix6d::Zero();
  expected.diagonal() << 1, 4, 0.25, 0.04, 0.09, 0.01;
  EXPECT_LT((body - expected).norm(), 1e-12);
}
