// Factors of the sliding-window graph and the pose manifold they share. State blocks: a pose of 7 doubles
// (position x y z [m] in the map frame, then the body-to-map rotation as an Eigen quaternion x y z w) and a
// speed-bias block of 9 (map-frame velocity [m/s], gyro bias [rad/s], accelerometer bias [m/s^2]). The pose's
// tangent is (map-frame position change [m], body-frame rotation vector [rad]); every information matrix below
// is in that tangent. No ROS.
#pragma once

#include <ceres/ceres.h>
#include <ceres/version.h>

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <vector>

#include "grid_puzzle_localization/fusion/imu_preintegration.hpp"
#include "grid_puzzle_localization/fusion/so3.hpp"
#include "grid_puzzle_localization/pose_covariance.hpp"

namespace grid_puzzle_localization {

constexpr int kPoseSize = 7;
constexpr int kPoseTangentSize = 6;
constexpr int kSpeedBiasSize = 9;

using Matrix15d = Eigen::Matrix<double, 15, 15>;

/// d(pose)/d(tangent) at `pose` (7 x 6, row-major as Ceres wants it).
Eigen::Matrix<double, 7, 6, Eigen::RowMajor> posePlusJacobian(const double* pose);

/// Ceres 2.1 replaced LocalParameterization (Ceres 1.14 on Ubuntu 20.04, and 2.0) by Manifold.
#define GPL_CERES_HAS_MANIFOLD (CERES_VERSION_MAJOR > 2 || (CERES_VERSION_MAJOR == 2 && CERES_VERSION_MINOR >= 1))

/// Plus(x, d) = (p + d_p, q * Exp(d_theta)): a Manifold from Ceres 2.1 on, else a LocalParameterization.
#if GPL_CERES_HAS_MANIFOLD
class PoseManifold : public ceres::Manifold {
 public:
  int AmbientSize() const override { return kPoseSize; }
  int TangentSize() const override { return kPoseTangentSize; }
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override;
  bool PlusJacobian(const double* x, double* jacobian) const override;
  bool Minus(const double* y, const double* x, double* y_minus_x) const override;
  bool MinusJacobian(const double* x, double* jacobian) const override;
};
#else
class PoseManifold : public ceres::LocalParameterization {
 public:
  int GlobalSize() const override { return kPoseSize; }
  int LocalSize() const override { return kPoseTangentSize; }
  bool Plus(const double* x, const double* delta, double* x_plus_delta) const override;
  bool ComputeJacobian(const double* x, double* jacobian) const override;
};
#endif

/// The square root of an information matrix (upper factor U with U^T U = information), symmetrised first.
template <int N>
Eigen::Matrix<double, N, N> sqrtInformation(const Eigen::Matrix<double, N, N>& information) {
  const Eigen::Matrix<double, N, N> sym = 0.5 * (information + information.transpose());
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix<double, N, N>> eig(sym);
  const Eigen::Matrix<double, N, 1> s = eig.eigenvalues().cwiseMax(0.0).cwiseSqrt();
  return s.asDiagonal() * eig.eigenvectors().transpose();
}

/// Absolute pose measurement (NDT against the map): residual (p - p_m, Log(q_m^-1 q)).
struct PoseFactor {
  PoseFactor(const Eigen::Isometry3d& measured, const Matrix6d& information)
      : position(measured.translation()), rotation(measured.rotation()), sqrt_info(sqrtInformation<6>(information)) {}
  template <typename T>
  bool operator()(const T* pose, T* residual) const {
    Eigen::Map<const Eigen::Matrix<T, 3, 1>> p(pose);
    Eigen::Map<const Eigen::Quaternion<T>> q(pose + 3);
    Eigen::Matrix<T, 6, 1> r;
    r.template head<3>() = p - position.cast<T>();
    r.template tail<3>() = quatLog(Eigen::Quaternion<T>(rotation.conjugate().cast<T>() * q));
    Eigen::Map<Eigen::Matrix<T, 6, 1>>{residual} = sqrt_info.cast<T>() * r;
    return true;
  }
  static ceres::CostFunction* create(const Eigen::Isometry3d& measured, const Matrix6d& information) {
    return new ceres::AutoDiffCostFunction<PoseFactor, 6, kPoseSize>(new PoseFactor(measured, information));
  }
  Eigen::Vector3d position;
  Eigen::Quaterniond rotation;
  Matrix6d sqrt_info;
};

/// Relative pose between two states (wheel odometry, or zero motion when standing still): residual
/// (R_i^T (p_j - p_i) - dp, Log(dq^-1 q_i^-1 q_j)).
struct RelativePoseFactor {
  RelativePoseFactor(const Eigen::Isometry3d& i_T_j, const Matrix6d& information)
      : translation(i_T_j.translation()), rotation(i_T_j.rotation()), sqrt_info(sqrtInformation<6>(information)) {}
  template <typename T>
  bool operator()(const T* pose_i, const T* pose_j, T* residual) const {
    Eigen::Map<const Eigen::Matrix<T, 3, 1>> p_i(pose_i), p_j(pose_j);
    Eigen::Map<const Eigen::Quaternion<T>> q_i(pose_i + 3), q_j(pose_j + 3);
    Eigen::Matrix<T, 6, 1> r;
    r.template head<3>() = q_i.conjugate() * (p_j - p_i) - translation.cast<T>();
    r.template tail<3>() = quatLog(Eigen::Quaternion<T>(rotation.conjugate().cast<T>() * q_i.conjugate() * q_j));
    Eigen::Map<Eigen::Matrix<T, 6, 1>>{residual} = sqrt_info.cast<T>() * r;
    return true;
  }
  static ceres::CostFunction* create(const Eigen::Isometry3d& i_T_j, const Matrix6d& information) {
    return new ceres::AutoDiffCostFunction<RelativePoseFactor, 6, kPoseSize, kPoseSize>(
        new RelativePoseFactor(i_T_j, information));
  }
  Eigen::Vector3d translation;
  Eigen::Quaterniond rotation;
  Matrix6d sqrt_info;
};

/// Gaussian prior on a speed-bias block: residual sqrt_info (x - mean).
struct SpeedBiasPrior {
  template <typename T>
  bool operator()(const T* speed_bias, T* residual) const {
    Eigen::Map<const Eigen::Matrix<T, 9, 1>> x(speed_bias);
    Eigen::Map<Eigen::Matrix<T, 9, 1>>{residual} = sqrt_info.cast<T>() * (x - mean.cast<T>());
    return true;
  }
  static ceres::CostFunction* create(const Eigen::Matrix<double, 9, 1>& mean, const Eigen::Matrix<double, 9, 1>& std) {
    auto* f = new SpeedBiasPrior;
    f->mean = mean;
    f->sqrt_info = std.cwiseInverse().asDiagonal();
    return new ceres::AutoDiffCostFunction<SpeedBiasPrior, 9, kSpeedBiasSize>(f);
  }
  Eigen::Matrix<double, 9, 1> mean;
  Eigen::Matrix<double, 9, 9> sqrt_info;
};

/// Preintegrated IMU between states i and j (Forster eq. 45) and the bias random walk. Residual: rotation
/// [rad], velocity [m/s], position [m], gyro bias change, accel bias change. `gravity` is the map-frame
/// gravity vector [m/s^2] (0, 0, -9.81 for REP 103).
struct ImuFactor {
  ImuFactor(const ImuPreintegration& preintegration, const Eigen::Vector3d& gravity, double gyro_random_walk,
            double accel_random_walk);
  template <typename T>
  bool operator()(const T* pose_i, const T* sb_i, const T* pose_j, const T* sb_j, T* residual) const {
    using V3 = Eigen::Matrix<T, 3, 1>;
    Eigen::Map<const V3> p_i(pose_i), p_j(pose_j), v_i(sb_i), v_j(sb_j), bg_i(sb_i + 3), bg_j(sb_j + 3), ba_i(sb_i + 6),
        ba_j(sb_j + 6);
    Eigen::Map<const Eigen::Quaternion<T>> q_i(pose_i + 3), q_j(pose_j + 3);
    const V3 dbg = bg_i - pre.bias().gyro.cast<T>();
    const V3 dba = ba_i - pre.bias().accel.cast<T>();
    const T dt = T(pre.duration());
    const V3 g = gravity.cast<T>();
    const Eigen::Quaternion<T> d_rot =
        pre.deltaRotation().cast<T>() * quatExp(V3(pre.rotationByGyroBias().cast<T>() * dbg));
    const V3 d_vel = pre.deltaVelocity().cast<T>() + pre.velocityByGyroBias().cast<T>() * dbg +
                     pre.velocityByAccelBias().cast<T>() * dba;
    const V3 d_pos = pre.deltaPosition().cast<T>() + pre.positionByGyroBias().cast<T>() * dbg +
                     pre.positionByAccelBias().cast<T>() * dba;
    const Eigen::Quaternion<T> q_i_inv = q_i.conjugate();
    Eigen::Matrix<T, 15, 1> r;
    r.template segment<3>(0) = quatLog(Eigen::Quaternion<T>(d_rot.conjugate() * q_i_inv * q_j));
    r.template segment<3>(3) = q_i_inv * (v_j - v_i - g * dt) - d_vel;
    r.template segment<3>(6) = q_i_inv * (p_j - p_i - v_i * dt - T(0.5) * g * dt * dt) - d_pos;
    r.template segment<3>(9) = bg_j - bg_i;
    r.template segment<3>(12) = ba_j - ba_i;
    Eigen::Map<Eigen::Matrix<T, 15, 1>>{residual} = sqrt_info.cast<T>() * r;
    return true;
  }
  static ceres::CostFunction* create(const ImuPreintegration& preintegration, const Eigen::Vector3d& gravity,
                                     double gyro_random_walk, double accel_random_walk) {
    return new ceres::AutoDiffCostFunction<ImuFactor, 15, kPoseSize, kSpeedBiasSize, kPoseSize, kSpeedBiasSize>(
        new ImuFactor(preintegration, gravity, gyro_random_walk, accel_random_walk));
  }
  ImuPreintegration pre;
  Eigen::Vector3d gravity;
  Matrix15d sqrt_info;
};

/// One block of a marginalization prior: where it lives and its value when the prior was made.
struct PriorBlock {
  double* data = nullptr;
  bool is_pose = false;  ///< 7 values with a 6-d tangent; else 9 Euclidean values
  std::vector<double> linearization_point;
};

/// The prior that marginalization leaves on the blocks that shared factors with the removed ones:
/// 0.5 |J dx + r|^2, dx the tangent difference from the linearization point (Schur complement, paper eq. 11-13).
class MarginalizationPrior : public ceres::CostFunction {
 public:
  MarginalizationPrior(std::vector<PriorBlock> blocks, Eigen::MatrixXd jacobian, Eigen::VectorXd residual);
  bool Evaluate(double const* const* parameters, double* residuals, double** jacobians) const override;
  const std::vector<PriorBlock>& blocks() const { return blocks_; }

 private:
  std::vector<PriorBlock> blocks_;
  std::vector<int> tangent_offsets_;
  Eigen::MatrixXd jacobian_;
  Eigen::VectorXd residual_;
};

}  // namespace grid_puzzle_localization
