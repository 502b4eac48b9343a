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
