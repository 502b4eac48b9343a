#include <Eigen/Geometry>
#include <algorithm>
#include <cctype>
#include <cmath>
#include <sstream>

#include "grid_puzzle_localization/ndt.hpp"

namespace grid_puzzle_localization {

bool parseSearchMethod(const std::string& text, NdtSearchMethod* method) {
  std::string t = text;
  std::transform(t.begin(), t.end(), t.begin(), [](unsigned char c) { return static_cast<char>(std::toupper(c)); });
  for (const NdtSearchMethod m :
       {NdtSearchMethod::DIRECT1, NdtSearchMethod::DIRECT7, NdtSearchMethod::DIRECT27, NdtSearchMethod::RADIUS}) {
    if (t == toString(m)) {
      *method = m;
      return true;
    }
  }
  return false;
}

const char* toString(NdtSearchMethod method) {
  switch (method) {
    case NdtSearchMethod::DIRECT1:
      return "DIRECT1";
    case NdtSearchMethod::DIRECT7:
      return "DIRECT7";
    case NdtSearchMethod::DIRECT27:
      return "DIRECT27";
    case NdtSearchMethod::RADIUS:
      return "RADIUS";
  }
  return "?";
}

Eigen::Isometry3d toIsometry(const Eigen::Matrix4f& m) {
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.translation() = m.topRightCorner<3, 1>().cast<double>();
  out.linear() = Eigen::Quaterniond(m.topLeftCorner<3, 3>().cast<double>()).normalized().toRotationMatrix();
  return out;
}

const char* toString(NdtResultStatus status) {
  switch (status) {
    case NdtResultStatus::OK:
      return "OK";
    case NdtResultStatus::MAX_ITERATIONS:
      return "MAX_ITERATIONS";
    case NdtResultStatus::EMPTY_TARGET:
      return "EMPTY_TARGET";
    case NdtResultStatus::TOO_FEW_POINTS:
      return "TOO_FEW_POINTS";
    case NdtResultStatus::NO_CORRESPONDENCE:
      return "NO_CORRESPONDENCE";
    case NdtResultStatus::DEGENERATE:
      return "DEGENERATE";
    case NdtResultStatus::INVALID_INPUT:
      return "INVALID_INPUT";
  }
  return "?";
}

std::string NdtConfig::validate() const {
  std::ostringstream err;
  err << VoxelMapParams::validate();
  if (!(step_size > 0.0 && std::isfinite(step_size))) err << "step_size must be > 0 (got " << step_size << "); ";
  if (!(max_step_size >= step_size && std::isfinite(max_step_size)))
    err << "max_step_size must be >= step_size (" << step_size << ") (got " << max_step_size << "); ";
  if (!(transformation_epsilon >= 0.0))
    err << "transformation_epsilon must be >= 0 (got " << transformation_epsilon << "); ";
  if (coarse_points < 0) err << "coarse_points must be >= 0 (got " << coarse_points << "); ";
  if (!(coarse_yaw_probe >= 0.0 && coarse_yaw_probe < M_PI))
    err << "coarse_yaw_probe must be in [0, pi) rad (got " << coarse_yaw_probe << "); ";
  if (max_iterations < 1) err << "max_iterations must be >= 1 (got " << max_iterations << "); ";
  if (!(outlier_ratio > 0.0 && outlier_ratio < 1.0))
    err << "outlier_ratio must be in (0, 1) (got " << outlier_ratio << "); ";
  return err.str();
}

Eigen::Matrix4d poseToMatrix(const Vector6d& p) {
  Eigen::Affine3d t = Eigen::Translation3d(p(0), p(1), p(2)) * Eigen::AngleAxisd(p(3), Eigen::Vector3d::UnitX()) *
                      Eigen::AngleAxisd(p(4), Eigen::Vector3d::UnitY()) *
                      Eigen::AngleAxisd(p(5), Eigen::Vector3d::UnitZ());
  return t.matrix();
}

Vector6d matrixToPose(const Eigen::Matrix4d& m) {
  // R = Rx(a) Ry(b) Rz(c): R(0,2) = sin b, R(1,2) = -sin a cos b, R(2,2) = cos a cos b,
  // R(0,0) = cos b cos c, R(0,1) = -cos b sin c.
  Vector6d p;
  p.head<3>() = m.block<3, 1>(0, 3);
  p(3) = std::atan2(-m(1, 2), m(2, 2));
  p(4) = std::atan2(m(0, 2), std::hypot(m(0, 0), m(0, 1)));
  p(5) = std::atan2(-m(0, 1), m(0, 0));
  return p;
}

}  // namespace grid_puzzle_localization
