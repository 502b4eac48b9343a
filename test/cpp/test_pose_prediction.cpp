#include <gtest/gtest.h>

#include <cmath>

#include "grid_puzzle_localization/pose_prediction.hpp"

namespace gpl = grid_puzzle_localization;

namespace {

// Closed form: a car at speed v [m/s] with yaw rate w [rad/s] starting at the origin heading +x.
Eigen::Isometry3d carOnCircle(double v, double w, double t) {
  Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
  const double yaw = w * t;
  p.translation() << v / w * std::sin(yaw), v / w * (1.0 - std::cos(yaw)), 0.0;
  p.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  return p;
}

void expectPoseNear(const Eigen::Isometry3d& a, const Eigen::Isometry3d& b, double tol) {
  EXPECT_LT((a.translation() - b.translation()).norm(), tol);
  EXPECT_LT(Eigen::AngleAxisd(a.rotation().transpose() * b.rotation()).angle(), tol);
}

}  // namespace

TEST(PosePrediction, ExpLogRoundTripOnAGeneralTwist) {
  gpl::Twist xi;
  xi << 1.0, -0.4, 0.3, 0.2, -0.7, 1.1;
  const Eigen::Isometry3d delta = gpl::expTwist(xi, 0.8);
  EXPECT_LT((gpl::logTwist(delta) - 0.8 * xi).norm(), 1e-12);
  // Tiny rotation takes the series branch.
  xi.tail<3>() << 1e-7, 0, -2e-7;
  EXPECT_LT((gpl::logTwist(gpl::expTwist(xi, 1.0)) - xi).norm(), 1e-12);
}

TEST(PosePrediction, ConstantVelocityFollowsACircularArcExactly) {
  const double v = 8.0;
  const double w = 0.3;
  gpl::PosePredictor pred;
  pred.reset(carOnCircle(v, w, 0.0), 10.0);
  pred.update(carOnCircle(v, w, 0.1), 10.1);
  EXPECT_NEAR(pred.twist()(0), v, 1e-9);
  EXPECT_NEAR(pred.twist()(1), 0.0, 1e-9);
  EXPECT_NEAR(pred.twist()(5), w, 1e-9);
  // 0.25 s ahead, not one step: the se(3) model keeps the arc.
  expectPoseNear(pred.predict(10.35), carOnCircle(v, w, 0.35), 1e-9);
}

TEST(PosePrediction, ResetZeroesVelocityAndNonPositiveStepKeepsTwist) {
  gpl::PosePredictor pred;
  Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
  pred.reset(p, 1.0);
  expectPoseNear(pred.predict(2.0), p, 1e-12);
  p.translation().x() = 1.0;
  pred.update(p, 1.5);
  EXPECT_NEAR(pred.twist()(0), 2.0, 1e-12);
  pred.update(p, 1.5);  // same stamp: no division by zero, twist kept
  EXPECT_NEAR(pred.twist()(0), 2.0, 1e-12);
  EXPECT_TRUE(pred.predict(1.5).matrix().allFinite());
}

TEST(PosePrediction, GyroConstantRateAboutATiltedAxisIntegratesExactly) {
  const Eigen::Vector3d axis = Eigen::Vector3d(1, -2, 3).normalized();
  const double rate = 0.9;
  gpl::GyroIntegrator gyro;
  for (int i = 0; i <= 20; ++i) gyro.add(0.01 * i, rate * axis);
  const Eigen::Quaterniond q = gyro.integrate(0.033, 0.187);
  const Eigen::Quaterniond truth(Eigen::AngleAxisd(rate * (0.187 - 0.033), axis));
  EXPECT_LT(q.angularDistance(truth), 1e-12);
  EXPECT_TRUE(gyro.covers(0.0, 0.2, 1e-9));
  EXPECT_FALSE(gyro.covers(0.0, 0.3, 0.05));
}

TEST(PosePrediction, GyroRateLinearInTimeIntegratesExactly) {
  // w(t) = a + b t about z: angle = a dt + b (t1^2 - t0^2) / 2; samples are uneven on purpose.
  const double a = 0.2;
  const double b = 1.5;
  gpl::GyroIntegrator gyro;
  for (double t : {0.0, 0.013, 0.04, 0.051, 0.09, 0.12, 0.2}) gyro.add(t, Eigen::Vector3d(0, 0, a + b * t));
  const double t0 = 0.02;
  const double t1 = 0.15;
  const double angle = a * (t1 - t0) + 0.5 * b * (t1 * t1 - t0 * t0);
  const Eigen::Quaterniond truth(Eigen::AngleAxisd(angle, Eigen::Vector3d::UnitZ()));
  EXPECT_LT(gyro.integrate(t0, t1).angularDistance(truth), 1e-12);
}

TEST(PosePrediction, GyroReplacesTheRotationOfThePrediction) {
  gpl::PosePredictor pred;
  pred.reset(Eigen::Isometry3d::Identity(), 0.0);
  Eigen::Isometry3d moved = Eigen::Isometry3d::Identity();
  moved.translation().x() = 1.0;
  pred.update(moved, 0.1);  // 10 m/s straight
  const Eigen::Quaterniond yaw(Eigen::AngleAxisd(0.05, Eigen::Vector3d::UnitZ()));
  const Eigen::Isometry3d out = pred.predict(0.2, &yaw);
  EXPECT_NEAR(out.translation().x(), 2.0, 1e-12);
  EXPECT_LT(Eigen::Quaterniond(out.rotation()).angularDistance(yaw), 1e-12);
}

TEST(PosePrediction, GyroDropBeforeKeepsTheAnchorAndOlderSampleRestarts) {
  gpl::GyroIntegrator gyro;
  for (int i = 0; i < 10; ++i) gyro.add(0.1 * i, Eigen::Vector3d(0, 0, 1));
  gyro.dropBefore(0.45);
  EXPECT_EQ(gyro.size(), 6u);  // 0.4 .. 0.9
  EXPECT_TRUE(gyro.covers(0.45, 0.9, 0.0));
  gyro.add(0.05, Eigen::Vector3d::Zero());  // bag loop
  EXPECT_EQ(gyro.size(), 1u);
}

TEST(PosePrediction, SmoothedTwistTakesTheFirstMeasurementThenLowPassesSteps) {
  // Straight line along x: 5 m/s for the first step, then 7 m/s. With time constant tau the smoothed speed
  // after n steps of dt at the new speed is 7 - 2 exp(-n dt / tau) (a first-order low-pass of a step).
  const double dt = 0.1;
  const double tau = 0.15;
  gpl::PosePredictor pred;
  pred.reset(Eigen::Isometry3d::Identity(), 0.0);
  EXPECT_EQ(pred.smoothedTwist(), gpl::Twist::Zero());
  double x = 5.0 * dt;
  pred.update(Eigen::Isometry3d(Eigen::Translation3d(x, 0, 0)), dt, tau);
  EXPECT_NEAR(pred.smoothedTwist()(0), 5.0, 1e-12);  // no history: taken as is
  for (int n = 1; n <= 5; ++n) {
    x += 7.0 * dt;
    pred.update(Eigen::Isometry3d(Eigen::Translation3d(x, 0, 0)), dt * (n + 1), tau);
    EXPECT_NEAR(pred.twist()(0), 7.0, 1e-9);
    EXPECT_NEAR(pred.smoothedTwist()(0), 7.0 - 2.0 * std::exp(-n * dt / tau), 1e-9) << "step " << n;
  }
  pred.reset(Eigen::Isometry3d::Identity(), 1.0);
  EXPECT_EQ(pred.smoothedTwist(), gpl::Twist::Zero());
}
