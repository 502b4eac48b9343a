// A closed-form drive and its IMU samples for the fusion tests and benchmark: the samples are the trajectory's
// exact derivatives plus seeded MEMS-like noise and a fixed bias; the NDT stand-in is the true pose plus noise.
#pragma once

#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <random>

#include "grid_puzzle_localization/fusion/sliding_window.hpp"
#include "grid_puzzle_localization/fusion/so3.hpp"

namespace grid_puzzle_localization::imu_drive {

constexpr double kG = 9.80665;
constexpr double kImuRate = 200.0;  // [Hz]
constexpr double kScanRate = 10.0;  // [Hz]

struct Truth {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  Eigen::Vector3d velocity = Eigen::Vector3d::Zero();
  Eigen::Vector3d gyro = Eigen::Vector3d::Zero();   // body [rad/s]
  Eigen::Vector3d accel = Eigen::Vector3d::Zero();  // body specific force [m/s^2]
};

// A car weaving along x at 8 m/s with a slowly varying heading and small vertical motion.
inline Truth drive(double t) {
  Truth s;
  const double yaw = 0.05 * t + 0.3 * std::sin(0.2 * t);
  const Eigen::Matrix3d r = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  s.pose.linear() = r;
  s.pose.translation() << 8.0 * t, 3.0 * std::sin(0.4 * t), 0.1 * std::sin(0.7 * t);
  s.velocity << 8.0, 1.2 * std::cos(0.4 * t), 0.07 * std::cos(0.7 * t);
  const Eigen::Vector3d a(0.0, -0.48 * std::sin(0.4 * t), -0.049 * std::sin(0.7 * t));
  s.gyro << 0.0, 0.0, 0.05 + 0.06 * std::cos(0.2 * t);
  s.accel = r.transpose() * (a + Eigen::Vector3d(0, 0, kG));
  return s;
}

inline Truth standStill(double) {
  Truth s;
  s.pose = Eigen::Translation3d(1.0, 2.0, 0.0) * Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitZ());
  s.accel = s.pose.rotation().transpose() * Eigen::Vector3d(0, 0, kG);
  return s;
}

// Stands still for a second, then sets off along its heading at a constant 1.5 m/s^2: a smooth start, whose
// specific force barely varies, as a car's from a stop.
inline Truth startFromRest(double t) {
  constexpr double kStart = 1.0, kAccel = 1.5;
  Truth s = standStill(t);
  const double moving = std::max(0.0, t - kStart);
  const Eigen::Vector3d heading = s.pose.rotation().col(0);
  s.pose.translation() += 0.5 * kAccel * moving * moving * heading;
  s.velocity = kAccel * moving * heading;
  if (t > kStart) s.accel += Eigen::Vector3d(kAccel, 0.0, 0.0);
  return s;
}

struct ImuErrors {
  double gyro_sigma = 0.0, accel_sigma = 0.0;  // per sample
  Eigen::Vector3d gyro_bias = Eigen::Vector3d::Zero(), accel_bias = Eigen::Vector3d::Zero();
};

// MEMS-like errors (the simulator's defaults at 200 Hz) with a fixed turn-on bias.
inline ImuErrors mems() {
  ImuErrors e;
  e.gyro_sigma = 1.7e-4 * std::sqrt(kImuRate);
  e.accel_sigma = 2.0e-3 * std::sqrt(kImuRate);
  e.gyro_bias << 0.002, -0.001, 0.0015;
  e.accel_bias << 0.03, -0.02, 0.02;
  return e;
}

inline ImuSample imuSample(Truth (*motion)(double), double t, const ImuErrors& e, std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  const Truth s = motion(t);
  ImuSample m;
  m.stamp = t;
  m.gyro = s.gyro + e.gyro_bias + e.gyro_sigma * Eigen::Vector3d(n(rng), n(rng), n(rng));
  m.accel = s.accel + e.accel_bias + e.accel_sigma * Eigen::Vector3d(n(rng), n(rng), n(rng));
  return m;
}

inline Eigen::Isometry3d noisyPose(const Eigen::Isometry3d& truth, double sp, double sr, std::mt19937& rng) {
  std::normal_distribution<double> n(0.0, 1.0);
  Eigen::Isometry3d m = truth;
  m.translation() += sp * Eigen::Vector3d(n(rng), n(rng), n(rng));
  m.linear() =
      truth.linear() * quatExp(Eigen::Vector3d(sr * Eigen::Vector3d(n(rng), n(rng), n(rng)))).toRotationMatrix();
  return m;
}

/// Information of the NDT stand-in: position std `sp` [m], rotation std `sr` [rad].
inline Matrix6d information(double sp, double sr) {
  Matrix6d info = Matrix6d::Zero();
  info.diagonal() << Eigen::Vector3d::Constant(1.0 / (sp * sp)), Eigen::Vector3d::Constant(1.0 / (sr * sr));
  return info;
}

}  // namespace grid_puzzle_localization::imu_drive
