#include "grid_puzzle_localization/localizer.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <sstream>
#include <stdexcept>
#include <utility>

namespace grid_puzzle_localization {
namespace {

using Clock = std::chrono::steady_clock;

double msSince(Clock::time_point start) {
  return std::chrono::duration<double, std::milli>(Clock::now() - start).count();
}

VoxelMapParams workerParams(const LocalizerConfig& config) {
  VoxelMapParams p = config.ndt;
  p.threads = config.map_update_threads;
  return p;
}

const LocalizerConfig& validated(const LocalizerConfig& config) {
  const std::string problem = config.validate();
  if (!problem.empty()) throw std::invalid_argument("localizer parameters: " + problem);
  return config;
}

// Float round-off in the NDT transform leaves the rotation slightly non-orthonormal; a quaternion
// round trip fixes that before the pose is chained with others.
Eigen::Isometry3d toIsometry(const Eigen::Matrix4f& m) {
  Eigen::Isometry3d out = Eigen::Isometry3d::Identity();
  out.translation() = m.topRightCorner<3, 1>().cast<double>();
  out.linear() = Eigen::Quaterniond(m.topLeftCorner<3, 3>().cast<double>()).normalized().toRotationMatrix();
  return out;
}

// Grid offsets (x y, map frame) with 0 < |offset| <= radius, nearest first.
std::vector<Eigen::Vector3d> recoveryOffsets(const RecoveryConfig& c) {
  std::vector<Eigen::Vector3d> out;
  const int n = static_cast<int>(std::floor(c.radius / c.step));
  for (int i = -n; i <= n; ++i)
    for (int j = -n; j <= n; ++j) {
      const Eigen::Vector3d o(i * c.step, j * c.step, 0.0);
      if ((i != 0 || j != 0) && o.norm() <= c.radius + 1e-9) out.push_back(o);
    }
  std::stable_sort(out.begin(), out.end(), [](const auto& a, const auto& b) { return a.norm() < b.norm(); });
  return out;
}

}  // namespace

std::string RecoveryConfig::validate() const {
  std::ostringstream err;
  if (!(after_rejections >= 0))
    err << "recovery/after_rejections must be >= 0, 0 = off (got " << after_rejections << "); ";
  if (!(radius >= 0.0)) err << "recovery/radius must be >= 0 m (got " << radius << "); ";
  if (!(step > 0.0)) err << "recovery/step must be > 0 m (got " << step << "); ";
  if (!(candidates_per_scan >= 1))
    err << "recovery/candidates_per_scan must be >= 1 (got " << candidates_per_scan << "); ";
  return err.str();
}

std::string LocalizerConfig::validate() const {
  std::ostringstream err;
  err << preprocess.validate() << ndt.validate() << covariance.validate() << recovery.validate();
  if (!(map_update_threads >= 0)) err << "map_update_threads must be >= 0 (0 = all cores); ";
  if (!(min_nvtl >= 0.0)) err << "min_nvtl must be >= 0 (got " << min_nvtl << "); ";
  if (!(min_transformation_probability >= 0.0))
    err << "min_transformation_probability must be >= 0 (got " << min_transformation_probability << "); ";
  if (!(deskew_twist_smoothing >= 0.0))
    err << "preprocess/deskew_twist_smoothing must be >= 0 s (got " << deskew_twist_smoothing << "); ";
  if (!(gyro_max_gap >= 0.0)) err << "gyro_max_gap must be >= 0 s (got " << gyro_max_gap << "); ";
  if (!(time_jump_back > 0.0)) err << "time_jump_back must be > 0 s (got " << time_jump_back << "); ";
  return err.str();
}

const char* toString(LocalizerState state) {
  switch (state) {
    case LocalizerState::kWaitingForMap:
      return "waiting_for_map";
    case LocalizerState::kWaitingForInitialPose:
      return "waiting_for_initial_pose";
    case LocalizerState::kTracking:
      return "tracking";
  }
  return "unknown";
}

Localizer::Localizer(const LocalizerConfig& config)
    : config_(validated(config)),
      preprocessor_(config.preprocess),
      aligner_(config.ndt),
      worker_(workerParams(config)),
      recovery_offsets_(recoveryOffsets(config.recovery)) {}

void Localizer::setInitialPose(const Eigen::Isometry3d& map_T_base) { pending_initial_pose_ = map_T_base; }

void Localizer::setDefaultInitialPose(const Eigen::Isometry3d& map_T_base) {
  default_initial_pose_ = map_T_base;
  if (!predictor_.initialized()) pending_initial_pose_ = map_T_base;
}

void Localizer::addGyro(double stamp, const Eigen::Vector3d& angular_velocity) {
  if (angular_velocity.allFinite()) gyro_.add(stamp, angular_velocity);
}

void Localizer::reset() {
  predictor_ = PosePredictor();
  gyro_.clear();
  pending_initial_pose_ = default_initial_pose_;
  last_stamp_.reset();
  rejected_in_a_row_ = 0;
}

std::optional<NdtResult> Localizer::reacquire(const Eigen::Isometry3d& guess, int tries) {
  std::optional<NdtResult> best;
  for (int k = 0; k < tries; ++k) {
    Eigen::Isometry3d candidate = guess;
    candidate.translation() += recovery_offsets_[next_recovery_offset_++ % recovery_offsets_.size()];
    NdtResult r = aligner_.align(*target_, source_, candidate.cast<float>());
    if (acceptable(r) && (!best || r.nvtl > best->nvtl)) best = std::move(r);
  }
  return best;
}

bool Localizer::acceptable(const NdtResult& r) const {
  if (r.status != NdtResultStatus::OK && r.status != NdtResultStatus::MAX_ITERATIONS) return false;
  if (config_.require_converged && !r.converged) return false;
  if (r.nvtl < config_.min_nvtl) return false;
  if (r.transformation_probability < config_.min_transformation_probability) return false;
  return r.transform.allFinite();
}

SweepMotion Localizer::sweepMotion(double stamp, double t_begin, double t_end, const Eigen::Isometry3d& base_T_sensor,
                                   bool fresh) const {
  // Right after an initial pose there is no motion estimate: the scan is taken as if the sensor stood still.
  const Twist twist = fresh ? Twist::Zero() : predictor_.smoothedTwist();
  if (fresh || !config_.use_gyro || !gyro_.covers(stamp + t_begin, stamp + t_end, config_.gyro_max_gap))
    return SweepMotion::fromTwist(twist, base_T_sensor, t_begin, t_end);
  auto rotation = [&](double t) {
    return t >= 0.0 ? gyro_.integrate(stamp, stamp + t) : gyro_.integrate(stamp + t, stamp).inverse();
  };
  auto motion = [&](double t) {
    Eigen::Isometry3d m = expTwist(twist, t);
    m.linear() = rotation(t).toRotationMatrix();
    return m;
  };
  const double span = t_end - t_begin;
  const double rate =
      span > 0.0 ? Eigen::AngleAxisd(rotation(t_begin).inverse() * rotation(t_end)).angle() / span : 0.0;
  return SweepMotion(motion, base_T_sensor, t_begin, t_end, std::max(rate, twist.tail<3>().norm()));
}

LocalizerOutput Localizer::processScan(double stamp, const PointCloud& scan, const Eigen::Isometry3d& base_T_sensor,
                                       const PointTimes* times) {
  const Clock::time_point start = Clock::now();
  LocalizerOutput out;
  if (last_stamp_ && stamp < *last_stamp_ - config_.time_jump_back) {
    reset();
    out.reset = true;
  }
  last_stamp_ = stamp;
  out.map_update_pending = worker_.busy();
  if (std::shared_ptr<const VoxelMap> next = worker_.takeReady()) {
    // The old snapshot may hold the last reference to thousands of voxel buffers: the worker frees them.
    worker_.retire(std::exchange(target_, std::move(next)));
    out.map_swapped = true;
  }
  if (target_) {
    out.target_voxels = target_->gaussianCount();
    out.target_points = target_->pointCount();
  }
  if (!target_ || target_->gaussianCount() == 0) {
    out.state = LocalizerState::kWaitingForMap;
    out.scan_ms = msSince(start);
    return out;
  }
  const bool fresh = pending_initial_pose_.has_value();
  if (fresh) {
    predictor_.reset(*pending_initial_pose_, stamp);
    pending_initial_pose_.reset();
    rejected_in_a_row_ = 0;
  }
  if (!predictor_.initialized()) {
    out.state = LocalizerState::kWaitingForInitialPose;
    out.scan_ms = msSince(start);
    return out;
  }
  out.state = LocalizerState::kTracking;

  if (config_.preprocess.deskew && times && times->size() == scan.size()) {
    const auto [t_begin, t_end] = timeSpan(*times);
    const SweepMotion motion = sweepMotion(stamp, t_begin, t_end, base_T_sensor, fresh);
    preprocessor_.apply(scan, source_, &out.preprocess, times, &motion);
  } else {
    preprocessor_.apply(scan, source_, &out.preprocess);
  }
  const Eigen::Isometry3f base_T_sensor_f = base_T_sensor.cast<float>();
  for (Point& p : source_) p = base_T_sensor_f * p;

  Eigen::Isometry3d guess = predictor_.pose();
  if (!fresh) {
    std::optional<Eigen::Quaterniond> gyro_rotation;
    if (config_.use_gyro && gyro_.covers(predictor_.stamp(), stamp, config_.gyro_max_gap))
      gyro_rotation = gyro_.integrate(predictor_.stamp(), stamp);
    guess = predictor_.predict(stamp, gyro_rotation ? &*gyro_rotation : nullptr);
  }

  out.prediction = guess;
  const Clock::time_point align_start = Clock::now();
  out.ndt = aligner_.align(*target_, source_, guess.cast<float>());
  out.match_accepted = acceptable(out.ndt);
  out.lost = config_.recovery.after_rejections > 0 && rejected_in_a_row_ >= config_.recovery.after_rejections;
  if (!out.match_accepted && out.lost) {
    out.recovery_candidates =
        std::min<int>(config_.recovery.candidates_per_scan, static_cast<int>(recovery_offsets_.size()));
    if (std::optional<NdtResult> found = reacquire(guess, out.recovery_candidates)) {
      out.ndt = std::move(*found);
      out.match_accepted = out.reacquired = true;
    }
  }
  out.pose = out.match_accepted ? toIsometry(out.ndt.transform) : guess;
  out.align_ms = msSince(align_start);  // with the re-acquisition attempts
  if (!out.pose.matrix().allFinite()) {
    out.pose = guess;
    out.match_accepted = false;
  }
  rejected_in_a_row_ = out.match_accepted ? 0 : rejected_in_a_row_ + 1;
  const double dt = stamp - predictor_.stamp();
  // After a new initial pose or a re-acquisition the match may move far from the guess: that jump is a
  // correction, not motion.
  if (fresh || out.reacquired)
    predictor_.reset(out.pose, stamp);
  else
    predictor_.update(out.pose, stamp, config_.deskew_twist_smoothing);
  gyro_.dropBefore(stamp);
  out.twist = predictor_.twist();
  out.covariance = out.match_accepted ? covarianceFromHessian(out.ndt.hessian, config_.covariance)
                                      : predictionCovariance(config_.covariance);
  out.twist_covariance = out.match_accepted && !fresh && !out.reacquired && dt > 0.0
                             ? out.covariance * (2.0 / (dt * dt))
                             : predictionCovariance(config_.covariance);
  if (config_.output_aligned) {
    const Eigen::Isometry3f map_T_base = out.pose.cast<float>();
    out.aligned.reserve(source_.size());
    for (const Point& p : source_) out.aligned.push_back(map_T_base * p);
  }
  out.scan_ms = msSince(start);
  return out;
}

}  // namespace grid_puzzle_localization
