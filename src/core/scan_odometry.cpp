#include "grid_puzzle_localization/scan_odometry.hpp"

namespace grid_puzzle_localization {

ScanOdometry::ScanOdometry(const NdtConfig& ndt, double min_nvtl, double max_speed)
    : aligner_(ndt), previous_(ndt), min_nvtl_(min_nvtl), max_speed_(max_speed) {}

Eigen::Isometry3d ScanOdometry::add(double stamp, const PointCloud& base_points, OdometryStep* step) {
  const std::optional<double> before = previous_stamp_;
  const double dt = before ? stamp - *before : 0.0;
  Eigen::Isometry3d motion = Eigen::Isometry3d::Identity();
  OdometryStep kind = OdometryStep::kFirst;
  if (before && dt > 0.0) {
    // From the last velocity: a car drives on. The coarse stage widens the basin for a guess metres off (a speed that
    // changed between keyframes).
    const Eigen::Isometry3d guess = motionTo(stamp);
    const NdtResult r = aligner_.align(*previous_.snapshot(), base_points, guess.cast<float>(), true);
    const Eigen::Isometry3d found = toIsometry(r.transform);
    const bool usable = (r.status == NdtResultStatus::OK || r.status == NdtResultStatus::MAX_ITERATIONS) &&
                        r.nvtl >= min_nvtl_ && found.matrix().allFinite() &&
                        found.translation().norm() <= max_speed_ * dt;
    if (usable) {
      motion = found;
      velocity_ = logTwist(found) / dt;
      kind = OdometryStep::kMeasured;
    } else {
      motion = guess;
      kind = OdometryStep::kGuessed;
    }
  }
  previous_.setTarget(base_points);
  previous_stamp_ = stamp;
  if (step) *step = kind;
  return motion;
}

Eigen::Isometry3d ScanOdometry::motionTo(double stamp) const {
  return previous_stamp_ && stamp > *previous_stamp_ ? expTwist(velocity_, stamp - *previous_stamp_)
                                                     : Eigen::Isometry3d::Identity();
}

void ScanOdometry::reset(const Twist& velocity) {
  previous_stamp_.reset();
  velocity_ = velocity;
}

}  // namespace grid_puzzle_localization
