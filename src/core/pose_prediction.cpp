#include "grid_puzzle_localization/pose_prediction.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>

namespace grid_puzzle_localization {
namespace {

Eigen::Matrix3d skew(const Eigen::Vector3d& v) {
  Eigen::Matrix3d m;
  m << 0, -v.z(), v.y(), v.z(), 0, -v.x(), -v.y(), v.x(), 0;
  return m;
}

// Left Jacobian of SO(3): maps the body velocity integrated over a constant-twist motion to the
// translation it produces. Series below 1e-4 rad, where the closed form loses digits.
Eigen::Matrix3d leftJacobian(const Eigen::Vector3d& phi) {
  const double theta2 = phi.squaredNorm();
  const double theta = std::sqrt(theta2);
  double a;
  double b;
  if (theta < 1e-4) {
    a = 0.5 - theta2 / 24.0;
    b = 1.0 / 6.0 - theta2 / 120.0;
  } else {
    a = (1.0 - std::cos(theta)) / theta2;
    b = (theta - std::sin(theta)) / (theta2 * theta);
  }
  const Eigen::Matrix3d k = skew(phi);
  return Eigen::Matrix3d::Identity() + a * k + b * k * k;
}

Eigen::Quaterniond rotationVectorToQuaternion(const Eigen::Vector3d& phi) {
  const double theta = phi.norm();
  if (theta < 1e-12) return Eigen::Quaterniond(1.0, 0.5 * phi.x(), 0.5 * phi.y(), 0.5 * phi.z()).normalized();
  return Eigen::Quaterniond(Eigen::AngleAxisd(theta, phi / theta));
}

}  // namespace

Eigen::Isometry3d expTwist(const Twist& twist, double dt) {
  const Eigen::Vector3d rho = twist.head<3>() * dt;
  const Eigen::Vector3d phi = twist.tail<3>() * dt;
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.linear() = rotationVectorToQuaternion(phi).toRotationMatrix();
  out.translation() = leftJacobian(phi) * rho;
  return out;
}

Twist logTwist(const Eigen::Isometry3d& delta) {
  const Eigen::AngleAxisd aa(delta.rotation());
  const Eigen::Vector3d phi = aa.angle() * aa.axis();
  Twist out;
  out.tail<3>() = phi;
  out.head<3>() = leftJacobian(phi).lu().solve(delta.translation());
  return out;
}

void GyroIntegrator::add(double stamp, const Eigen::Vector3d& angular_velocity) {
  if (!samples_.empty() && stamp < samples_.back().stamp) samples_.clear();
  samples_.push_back({stamp, angular_velocity});
}

bool GyroIntegrator::covers(double t0, double t1, double max_gap) const {
  return !samples_.empty() && samples_.front().stamp <= t0 + max_gap && samples_.back().stamp >= t1 - max_gap;
}

Eigen::Vector3d GyroIntegrator::rateAt(double t) const {
  if (t <= samples_.front().stamp) return samples_.front().rate;
  if (t >= samples_.back().stamp) return samples_.back().rate;
  std::size_t i = 1;
  while (samples_[i].stamp < t) ++i;
  const Sample& a = samples_[i - 1];
  const Sample& b = samples_[i];
  const double span = b.stamp - a.stamp;
  const double w = span > 0.0 ? (t - a.stamp) / span : 1.0;
  return (1.0 - w) * a.rate + w * b.rate;
}

Eigen::Quaterniond GyroIntegrator::integrate(double t0, double t1) const {
  Eigen::Quaterniond q = Eigen::Quaterniond::Identity();
  if (samples_.empty() || !(t1 > t0)) return q;
  // Break points: t0, every sample strictly inside (t0, t1), t1. Each piece is a trapezoid of the
  // linearly interpolated rate, composed in the body frame (right multiplication).
  double prev_t = t0;
  Eigen::Vector3d prev_w = rateAt(t0);
  auto step = [&](double t) {
    const Eigen::Vector3d w = rateAt(t);
    q = q * rotationVectorToQuaternion(0.5 * (prev_w + w) * (t - prev_t));
    prev_t = t;
    prev_w = w;
  };
  for (const Sample& s : samples_)
    if (s.stamp > t0 && s.stamp < t1) step(s.stamp);
  step(t1);
  return q.normalized();
}

void GyroIntegrator::dropBefore(double stamp) {
  // Keep the last sample at or before `stamp`: it anchors the interpolation there.
  while (samples_.size() >= 2 && samples_[1].stamp <= stamp) samples_.pop_front();
}

void PosePredictor::reset(const Eigen::Isometry3d& pose, double stamp) {
  initialized_ = true;
  stamp_ = stamp;
  pose_ = pose;
  twist_.setZero();
  smoothed_twist_.setZero();
  twist_measured_ = false;
}

Eigen::Isometry3d PosePredictor::predict(double stamp, const Eigen::Quaterniond* gyro_rotation) const {
  const double dt = stamp - stamp_;
  Eigen::Isometry3d delta = expTwist(twist_, dt);
  if (gyro_rotation) delta.linear() = gyro_rotation->toRotationMatrix();
  Eigen::Isometry3d out = pose_ * delta;
  out.linear() = Eigen::Quaterniond(out.rotation()).normalized().toRotationMatrix();
  return out;
}

void PosePredictor::update(const Eigen::Isometry3d& pose, double stamp, double smoothing) {
  const double dt = stamp - stamp_;
  if (dt > 0.0) {
    twist_ = logTwist(pose_.inverse() * pose) / dt;
    const double keep = twist_measured_ && smoothing > 0.0 ? std::exp(-dt / smoothing) : 0.0;
    smoothed_twist_ = keep * smoothed_twist_ + (1.0 - keep) * twist_;
    twist_measured_ = true;
  }
  pose_ = pose;
  stamp_ = stamp;
}

std::string PredictionConfig::validate() const {
  std::ostringstream err;
  if (!(max_extrapolation > 0.0))
    err << "prediction/max_extrapolation must be > 0 s (got " << max_extrapolation << "); ";
  if (!(max_speed > 0.0)) err << "prediction/max_speed must be > 0 m/s (got " << max_speed << "); ";
  if (!(max_yaw_rate > 0.0)) err << "prediction/max_yaw_rate must be > 0 rad/s (got " << max_yaw_rate << "); ";
  if (!(margin >= 1.0)) err << "prediction/margin must be >= 1 (got " << margin << "); ";
  if (!(min_radius >= 0.0)) err << "prediction/min_radius must be >= 0 m (got " << min_radius << "); ";
  if (!(max_radius >= min_radius))
    err << "prediction/max_radius must be >= prediction/min_radius (got " << max_radius << "); ";
  if (!(min_yaw_range >= 0.0)) err << "prediction/min_yaw_range must be >= 0 rad (got " << min_yaw_range << "); ";
  return err.str();
}

void MotionBounds::add(const Twist& twist) {
  if (!twist.allFinite()) return;
  speed = std::max(measured ? speed : 0.0, twist.head<3>().norm());
  yaw_rate = std::max(measured ? yaw_rate : 0.0, std::abs(twist(5)));
  measured = true;
}

SearchRegion boundedSearchRegion(const Eigen::Isometry3d& last, double elapsed, const MotionBounds& seen,
                                 bool rotation_known, const PredictionConfig& config) {
  const double t = std::max(0.0, elapsed);
  const double speed = seen.measured ? config.margin * seen.speed : config.max_speed;
  const double yaw_rate = seen.measured ? config.margin * seen.yaw_rate : config.max_yaw_rate;
  SearchRegion r;
  r.centre = last;
  r.radius = std::min(config.max_radius, config.min_radius + speed * t);
  r.yaw_range = rotation_known ? 0.0 : std::min(M_PI, config.min_yaw_range + yaw_rate * t);
  return r;
}

}  // namespace grid_puzzle_localization
