#include "grid_puzzle_localization/fusion/fusion_tracker.hpp"

#include <cmath>
#include <stdexcept>
#include <utility>

namespace grid_puzzle_localization {

namespace {

// The parameter value of each mode, for both directions.
constexpr std::pair<FusionMode, const char*> kModeNames[] = {
    {FusionMode::kNone, "none"}, {FusionMode::kSlidingWindow, "sliding_window"}, {FusionMode::kAuto, "auto"}};

}  // namespace

const char* toString(FusionMode mode) {
  for (const auto& [m, name] : kModeNames)
    if (m == mode) return name;
  return "none";
}

std::optional<FusionMode> parseFusionMode(const std::string& text) {
  for (const auto& [mode, name] : kModeNames)
    if (text == name) return mode;
  return std::nullopt;
}

std::string FusionConfig::validate() const {
  std::string err;
  if (!(ndt_covariance_scale > 0.0) || !std::isfinite(ndt_covariance_scale))
    err += "fusion/ndt_covariance_scale must be > 0 (got " + std::to_string(ndt_covariance_scale) + "); ";
  if (mode != FusionMode::kNone) return err + window.validate();
  return err + (window.base_T_imu.matrix().allFinite() ? "" : "fusion/window/base_T_imu must be finite; ");
}

FusionTracker::FusionTracker(const FusionConfig& config)
    : mode_(config.mode),
      window_config_(config.window),
      ndt_covariance_scale_(config.ndt_covariance_scale),
      window_(config.mode == FusionMode::kSlidingWindow ? std::make_unique<SlidingWindow>(config.window) : nullptr) {
  const std::string err = config.validate();
  if (!err.empty()) throw std::invalid_argument("fusion config: " + err);
}

FusionTracker::~FusionTracker() = default;

void FusionTracker::setBaseTImu(const Eigen::Isometry3d& base_T_imu) {
  if (!base_T_imu.matrix().allFinite()) throw std::invalid_argument("the IMU extrinsic base_T_imu must be finite");
  window_config_.base_T_imu = base_T_imu;
  if (window_) window_->setBaseTImu(base_T_imu);
}

void FusionTracker::addImu(const ImuSample& sample) {
  if (!sample.has_accel || !sample.has_gyro) {
    const std::string missing = sample.has_accel ? "angular velocity (angular_velocity_covariance[0] = -1)"
                                                 : "specific force (linear_acceleration_covariance[0] = -1)";
    if (window_)
      warnings_.push_back("IMU sample at " + std::to_string(sample.stamp) + " s has no " + missing +
                          ": the window needs a 6-axis IMU; sample skipped");
    return;
  }
  if (!window_ && mode_ == FusionMode::kAuto) window_ = std::make_unique<SlidingWindow>(window_config_);
  if (window_) window_->addImu(sample);
}

void FusionTracker::addOdometry(double stamp, const Eigen::Isometry3d& odom_T_base) {
  if (window_) window_->addOdometry(stamp, odom_T_base);
}

std::optional<FusedState> FusionTracker::predict(double stamp) const {
  return window_ ? window_->predict(stamp) : std::nullopt;
}

std::optional<Eigen::Isometry3d> FusionTracker::update(double stamp, bool restart, const Eigen::Isometry3d* match,
                                                       const Matrix6d& ndt_covariance) {
  if (!window_) return std::nullopt;
  if (restart) window_->reset();
  const Matrix6d information = match ? ndtInformation(*match, ndt_covariance) : Matrix6d::Zero();
  const std::optional<FusedState> fused = window_->addScan(stamp, match, information);
  if (!match || !fused || fused->stamp != stamp) return std::nullopt;
  return fused->pose;
}

Matrix6d FusionTracker::ndtCovariance(const Matrix6d& hessian, CovarianceConfig config) const {
  config.scale *= ndt_covariance_scale_;
  return covarianceFromHessian(hessian, config);
}

void FusionTracker::mapSwitched() {
  if (window_) window_->shrink();
}

void FusionTracker::reset() {
  if (window_) window_->reset();
}

std::vector<std::string> FusionTracker::takeWarnings() {
  std::vector<std::string> out = std::exchange(warnings_, {});
  if (window_)
    for (std::string& warning : window_->takeWarnings()) out.push_back(std::move(warning));
  return out;
}

}  // namespace grid_puzzle_localization
