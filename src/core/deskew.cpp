#include "grid_puzzle_localization/deskew.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace grid_puzzle_localization {

SweepMotion::SweepMotion(const std::function<Eigen::Isometry3d(double)>& base_motion,
                         const Eigen::Isometry3d& base_T_sensor, double t_begin, double t_end, double max_rate)
    : t_begin_(t_begin), step_(0.0) {
  const double span = std::max(0.0, t_end - t_begin);
  const double wanted = std::ceil(span * std::abs(max_rate) / kMaxNodeRotation);
  const int intervals = span > 0.0 ? static_cast<int>(std::clamp(wanted, 1.0, double(kMaxNodes - 1))) : 0;
  if (intervals > 0) step_ = span / intervals;
  const Eigen::Isometry3d sensor_T_base = base_T_sensor.inverse();
  nodes_.reserve(intervals + 1);
  for (int k = 0; k <= intervals; ++k) {
    const Eigen::Isometry3d s = sensor_T_base * base_motion(t_begin + k * step_) * base_T_sensor;
    nodes_.push_back(s.matrix().topRows<3>().cast<float>());
  }
}

SweepMotion SweepMotion::fromTwist(const Twist& twist, const Eigen::Isometry3d& base_T_sensor, double t_begin,
                                   double t_end) {
  return SweepMotion([&twist](double t) { return expTwist(twist, t); }, base_T_sensor, t_begin, t_end,
                     twist.tail<3>().norm());
}

Eigen::Isometry3f SweepMotion::at(double t) const {
  Eigen::Isometry3f out = Eigen::Isometry3f::Identity();
  if (step_ <= 0.0) {  // a single node
    out.matrix().topRows<3>() = nodes_.front();
    return out;
  }
  const double u = std::clamp((t - t_begin_) / step_, 0.0, double(nodes_.size() - 1));
  const auto k = std::min(static_cast<std::size_t>(u), nodes_.size() - 2);
  const auto w = static_cast<float>(u - static_cast<double>(k));
  out.matrix().topRows<3>() = (1.0f - w) * nodes_[k] + w * nodes_[k + 1];
  return out;
}

void SweepMotion::apply(PointCloud& points, const PointTimes& times) const {
  if (times.size() != points.size())
    throw std::invalid_argument("deskew: " + std::to_string(times.size()) + " point times for " +
                                std::to_string(points.size()) + " points");
  for (std::size_t i = 0; i < points.size(); ++i) {
    if (!std::isfinite(times[i])) continue;  // no usable time: the point stays as measured
    // The interpolated matrix is a near-rotation (off by < 1e-8 at the node spacing); it is applied as is.
    const Eigen::Isometry3f s = at(times[i]);
    points[i] = s.linear() * points[i] + s.translation();
  }
}

std::pair<double, double> timeSpan(const PointTimes& times) {
  double lo = std::numeric_limits<double>::infinity();
  double hi = -lo;
  for (float t : times) {
    if (!std::isfinite(t)) continue;
    lo = std::min(lo, double(t));
    hi = std::max(hi, double(t));
  }
  return lo <= hi ? std::make_pair(lo, hi) : std::make_pair(0.0, 0.0);
}

}  // namespace grid_puzzle_localization
