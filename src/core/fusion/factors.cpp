#include "grid_puzzle_localization/fusion/factors.hpp"

namespace grid_puzzle_localization {

namespace {

using RowMajor3x4 = Eigen::Matrix<double, 3, 4, Eigen::RowMajor>;

/// d(2 vec(a * q))/dq for quaternions in Eigen's (x y z w) storage: the vector rows of a's left product.
RowMajor3x4 twiceVectorOfLeftProduct(const Eigen::Quaterniond& a) {
  RowMajor3x4 m;
  m << a.w(), -a.z(), a.y(), a.x(),  //
      a.z(), a.w(), -a.x(), a.y(),   //
      -a.y(), a.x(), a.w(), a.z();
  return 2.0 * m;
}

void posePlus(const double* x, const double* delta, double* out) {
  Eigen::Map<const Eigen::Vector3d> p(x), dp(delta), dtheta(delta + 3);
  Eigen::Map<const Eigen::Quaterniond> q(x + 3);
  Eigen::Map<Eigen::Vector3d>{out} = p + dp;
  Eigen::Map<Eigen::Quaterniond>{out + 3} = (q * quatExp(Eigen::Vector3d(dtheta))).normalized();
}

}  // namespace

Eigen::Matrix<double, 7, 6, Eigen::RowMajor> posePlusJacobian(const double* pose) {
  Eigen::Map<const Eigen::Quaterniond> q(pose + 3);
  Eigen::Matrix<double, 7, 6, Eigen::RowMajor> j = Eigen::Matrix<double, 7, 6, Eigen::RowMajor>::Zero();
  j.topLeftCorner<3, 3>().setIdentity();
  // d(q * (theta/2, 1))/dtheta, rows x y z w.
  j.bottomRightCorner<4, 3>() << q.w(), -q.z(), q.y(),  //
      q.z(), q.w(), -q.x(),                             //
      -q.y(), q.x(), q.w(),                             //
      -q.x(), -q.y(), -q.z();
  j.bottomRightCorner<4, 3>() *= 0.5;
  return j;
}

#if GPL_CERES_HAS_MANIFOLD
bool PoseManifold::Plus(const double* x, const double* delta, double* x_plus_delta) const {
  posePlus(x, delta, x_plus_delta);
  return true;
}

bool PoseManifold::PlusJacobian(const double* x, double* jacobian) const {
  Eigen::Map<Eigen::Matrix<double, 7, 6, Eigen::RowMajor>>{jacobian} = posePlusJacobian(x);
  return true;
}

bool PoseManifold::Minus(const double* y, const double* x, double* y_minus_x) const {
  Eigen::Map<const Eigen::Quaterniond> qx(x + 3), qy(y + 3);
  Eigen::Map<Eigen::Vector3d>{y_minus_x} = Eigen::Map<const Eigen::Vector3d>(y) - Eigen::Map<const Eigen::Vector3d>(x);
  Eigen::Map<Eigen::Vector3d>{y_minus_x + 3} = quatLog(Eigen::Quaterniond(qx.conjugate() * qy));
  return true;
}

bool PoseManifold::MinusJacobian(const double* x, double* jacobian) const {
  Eigen::Map<Eigen::Matrix<double, 6, 7, Eigen::RowMajor>> j(jacobian);
  j.setZero();
  j.topLeftCorner<3, 3>().setIdentity();
  j.bottomRightCorner<3, 4>() = twiceVectorOfLeftProduct(Eigen::Map<const Eigen::Quaterniond>(x + 3).conjugate());
  return true;
}
#else
bool PoseManifold::Plus(const double* x, const double* delta, double* x_plus_delta) const {
  posePlus(x, delta, x_plus_delta);
  return true;
}

bool PoseManifold::ComputeJacobian(const double* x, double* jacobian) const {
  Eigen::Map<Eigen::Matrix<double, 7, 6, Eigen::RowMajor>>{jacobian} = posePlusJacobian(x);
  return true;
}
#endif

ImuFactor::ImuFactor(const ImuPreintegration& preintegration, const Eigen::Vector3d& gravity_vector,
                     double gyro_random_walk, double accel_random_walk)
    : pre(preintegration), gravity(gravity_vector) {
  Matrix15d covariance = Matrix15d::Zero();
  covariance.topLeftCorner<9, 9>() = pre.covariance();
  const double dt = pre.duration();
  covariance.block<3, 3>(9, 9).diagonal().setConstant(gyro_random_walk * gyro_random_walk * dt);
  covariance.block<3, 3>(12, 12).diagonal().setConstant(accel_random_walk * accel_random_walk * dt);
  // A floor keeps a very short interval (or a noise-free configuration) from giving an infinite weight.
  covariance.diagonal() += Eigen::Matrix<double, 15, 1>::Constant(1e-12);
  sqrt_info = sqrtInformation<15>(Matrix15d(covariance.inverse()));
}

MarginalizationPrior::MarginalizationPrior(std::vector<PriorBlock> blocks, Eigen::MatrixXd jacobian,
                                           Eigen::VectorXd residual)
    : blocks_(std::move(blocks)), jacobian_(std::move(jacobian)), residual_(std::move(residual)) {
  int offset = 0;
  for (const auto& b : blocks_) {
    tangent_offsets_.push_back(offset);
    offset += b.is_pose ? kPoseTangentSize : kSpeedBiasSize;
    mutable_parameter_block_sizes()->push_back(b.is_pose ? kPoseSize : kSpeedBiasSize);
  }
  set_num_residuals(static_cast<int>(residual_.size()));
}

bool MarginalizationPrior::Evaluate(double const* const* parameters, double* residuals, double** jacobians) const {
  Eigen::VectorXd dx(jacobian_.cols());
  // Per pose block, d(dx_rotation)/dq: dx_rotation = 2 vec(q0^-1 q), linear in q, equal to the tangent to first order.
  std::vector<RowMajor3x4> rotation_jacobians(blocks_.size());
  for (std::size_t k = 0; k < blocks_.size(); ++k) {
    const PriorBlock& b = blocks_[k];
    const double* x = parameters[k];
    const double* x0 = b.linearization_point.data();
    const int o = tangent_offsets_[k];
    if (!b.is_pose) {
      for (int i = 0; i < kSpeedBiasSize; ++i) dx[o + i] = x[i] - x0[i];
      continue;
    }
    for (int i = 0; i < 3; ++i) dx[o + i] = x[i] - x0[i];
    const Eigen::Quaterniond q0_inv = Eigen::Map<const Eigen::Quaterniond>(x0 + 3).conjugate();
    const Eigen::Quaterniond d = q0_inv * Eigen::Map<const Eigen::Quaterniond>(x + 3);
    const double sign = d.w() < 0.0 ? -1.0 : 1.0;
    dx.segment<3>(o + 3) = 2.0 * sign * d.vec();
    rotation_jacobians[k] = sign * twiceVectorOfLeftProduct(q0_inv);
  }
  Eigen::Map<Eigen::VectorXd>(residuals, residual_.size()) = jacobian_ * dx + residual_;
  if (jacobians == nullptr) return true;
  const int m = static_cast<int>(residual_.size());
  for (std::size_t k = 0; k < blocks_.size(); ++k) {
    if (jacobians[k] == nullptr) continue;
    const int o = tangent_offsets_[k];
    if (!blocks_[k].is_pose) {
      Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>(
          jacobians[k], m, kSpeedBiasSize) = jacobian_.middleCols(o, kSpeedBiasSize);
      continue;
    }
    Eigen::Map<Eigen::Matrix<double, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>> j(jacobians[k], m, kPoseSize);
    j.leftCols<3>() = jacobian_.middleCols(o, 3);
    j.rightCols<4>() = jacobian_.middleCols(o + 3, 3) * rotation_jacobians[k];
  }
  return true;
}

}  // namespace grid_puzzle_localization
