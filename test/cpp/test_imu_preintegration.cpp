// IMU preintegration against closed-form motion, its bias Jacobians against finite differences and its
// covariance against the closed form of a body at rest.
#include <gtest/gtest.h>

#include <cmath>

#include "grid_puzzle_localization/fusion/imu_preintegration.hpp"
#include "grid_puzzle_localization/fusion/so3.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

constexpr double kRate = 200.0;  // [Hz]
constexpr double kG = 9.80665;

Eigen::Vector3d rotationError(const Eigen::Quaterniond& a, const Eigen::Quaterniond& b) {
  return gpl::quatLog(Eigen::Quaterniond(a.conjugate() * b));
}

// A varied motion for the Jacobian checks: rates and forces change from sample to sample.
gpl::ImuPreintegration integrateWobble(const gpl::ImuBias& bias) {
  gpl::ImuPreintegration pre(bias);
  const double dt = 1.0 / kRate;
  for (int k = 0; k < 200; ++k) {
    const double t = k * dt;
    const Eigen::Vector3d w(0.3 * std::sin(2.0 * t), -0.2 + 0.1 * std::cos(3.0 * t), 0.5 * std::sin(t));
    const Eigen::Vector3d a(1.0 + std::sin(t), 0.5 * std::cos(2.0 * t), kG + 0.3 * std::sin(5.0 * t));
    pre.integrate(dt, w, a, 1e-6, 1e-4);
  }
  return pre;
}

}  // namespace

TEST(ImuPreintegration, ConstantAccelerationWithoutRotationMatchesTheClosedForm) {
  const Eigen::Vector3d a(1.5, -2.0, 0.5);
  gpl::ImuPreintegration pre;
  const int n = 400;
  for (int k = 0; k < n; ++k) pre.integrate(1.0 / kRate, Eigen::Vector3d::Zero(), a, 1e-6, 1e-4);
  const double t = n / kRate;
  EXPECT_NEAR(pre.duration(), t, 1e-12);
  EXPECT_LT((pre.deltaVelocity() - a * t).norm(), 1e-6);
  EXPECT_LT((pre.deltaPosition() - 0.5 * a * t * t).norm(), 1e-6);
  EXPECT_LT(rotationError(pre.deltaRotation(), Eigen::Quaterniond::Identity()).norm(), 1e-6);
}

TEST(ImuPreintegration, ConstantRotationRateMatchesTheClosedForm) {
  const Eigen::Vector3d w(0.4, -0.7, 1.1);
  gpl::ImuPreintegration pre;
  const int n = 600;
  for (int k = 0; k < n; ++k) pre.integrate(1.0 / kRate, w, Eigen::Vector3d::Zero(), 1e-6, 1e-4);
  const double t = n / kRate;
  const Eigen::Quaterniond expected(Eigen::AngleAxisd(w.norm() * t, w.normalized()));
  EXPECT_LT(rotationError(pre.deltaRotation(), expected).norm(), 1e-6);
  EXPECT_LT(pre.deltaVelocity().norm(), 1e-6);
  EXPECT_LT(pre.deltaPosition().norm(), 1e-6);
}

TEST(ImuPreintegration, BodySpinningInPlaceFeelsOnlyGravityAndGoesNowhere) {
  // Spinning about the vertical at a constant rate while resting: the specific force is (0, 0, g) in the body,
  // so the gravity-free deltas are a free fall in reverse, Delta v = (0, 0, g t), Delta p = (0, 0, g t^2 / 2),
  // and the rotation is Rz(w t).
  const double w = 0.8;
  gpl::ImuPreintegration pre;
  const int n = 300;
  for (int k = 0; k < n; ++k)
    pre.integrate(1.0 / kRate, Eigen::Vector3d(0, 0, w), Eigen::Vector3d(0, 0, kG), 1e-6, 1e-4);
  const double t = n / kRate;
  EXPECT_LT((pre.deltaVelocity() - Eigen::Vector3d(0, 0, kG * t)).norm(), 1e-6);
  EXPECT_LT((pre.deltaPosition() - Eigen::Vector3d(0, 0, 0.5 * kG * t * t)).norm(), 1e-6);
  const Eigen::Quaterniond expected(Eigen::AngleAxisd(w * t, Eigen::Vector3d::UnitZ()));
  EXPECT_LT(rotationError(pre.deltaRotation(), expected).norm(), 1e-6);
}

TEST(ImuPreintegration, BiasJacobiansMatchFiniteDifferencesOfReintegration) {
  gpl::ImuBias b0;
  b0.gyro << 0.01, -0.02, 0.005;
  b0.accel << 0.1, 0.05, -0.2;
  const gpl::ImuPreintegration pre = integrateWobble(b0);
  const double h = 1e-6;
  for (int k = 0; k < 6; ++k) {
    gpl::ImuBias plus = b0, minus = b0;
    (k < 3 ? plus.gyro : plus.accel)[k % 3] += h;
    (k < 3 ? minus.gyro : minus.accel)[k % 3] -= h;
    const gpl::ImuPreintegration p = integrateWobble(plus), m = integrateWobble(minus);
    const Eigen::Vector3d d_rot = rotationError(m.deltaRotation(), p.deltaRotation()) / (2 * h);
    const Eigen::Vector3d d_vel = (p.deltaVelocity() - m.deltaVelocity()) / (2 * h);
    const Eigen::Vector3d d_pos = (p.deltaPosition() - m.deltaPosition()) / (2 * h);
    SCOPED_TRACE("bias component " + std::to_string(k));
    if (k < 3) {
      EXPECT_LT((d_rot - pre.rotationByGyroBias().col(k)).norm(), 1e-5);
      EXPECT_LT((d_vel - pre.velocityByGyroBias().col(k)).norm(), 1e-5);
      EXPECT_LT((d_pos - pre.positionByGyroBias().col(k)).norm(), 1e-5);
    } else {
      EXPECT_LT(d_rot.norm(), 1e-6);  // the accelerometer bias does not rotate anything
      EXPECT_LT((d_vel - pre.velocityByAccelBias().col(k - 3)).norm(), 1e-5);
      EXPECT_LT((d_pos - pre.positionByAccelBias().col(k - 3)).norm(), 1e-5);
    }
  }
}

TEST(ImuPreintegration, BiasCorrectionApproximatesReintegrationToSecondOrder) {
  gpl::ImuBias b0;
  const gpl::ImuPreintegration pre = integrateWobble(b0);
  gpl::ImuBias b1;
  b1.gyro << 0.003, -0.002, 0.004;  // a few times a MEMS turn-on bias
  b1.accel << 0.03, -0.02, 0.05;
  const gpl::ImuPreintegration truth = integrateWobble(b1);
  // Without correction the deltas are off by ~|J db| (centimetres); with it, by O(db^2).
  EXPECT_GT((pre.deltaPosition() - truth.deltaPosition()).norm(), 1e-2);
  EXPECT_LT((pre.correctedPosition(b1) - truth.deltaPosition()).norm(), 1e-4);
  EXPECT_LT((pre.correctedVelocity(b1) - truth.deltaVelocity()).norm(), 1e-4);
  EXPECT_LT(rotationError(pre.correctedRotation(b1), truth.deltaRotation()).norm(), 1e-5);
}

TEST(ImuPreintegration, CovarianceOfABodyAtRestMatchesTheRandomWalkClosedForm) {
  // At rest (no rotation, zero bias-free force) the errors are random walks: rotation and velocity variance
  // grow as density^2 t, position variance as density^2 t^3 / 3 (the integral of a random walk).
  const double sg = 1.7e-4, sa = 2.0e-3, dt = 1.0 / kRate;
  gpl::ImuPreintegration pre;
  const int n = 2000;
  for (int k = 0; k < n; ++k)
    pre.integrate(dt, Eigen::Vector3d::Zero(), Eigen::Vector3d::Zero(), sg * sg / dt, sa * sa / dt);
  const double t = n * dt;
  for (int i = 0; i < 3; ++i) {
    EXPECT_NEAR(pre.covariance()(i, i), sg * sg * t, 1e-9 * sg * sg * t);
    EXPECT_NEAR(pre.covariance()(3 + i, 3 + i), sa * sa * t, 1e-9 * sa * sa * t);
    EXPECT_NEAR(pre.covariance()(6 + i, 6 + i), sa * sa * t * t * t / 3.0, 0.01 * sa * sa * t * t * t / 3.0);
  }
}
