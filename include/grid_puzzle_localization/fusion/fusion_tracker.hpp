// The localizer's hook-up of the sliding window: which fusion runs, the fused prediction that seeds the next
// scan (initial guess and deskew velocity), the window update after each match, and the window's life cycle
// (shrunk when the map source switches blocks, restarted with a new initial pose or a global search). Kept
// apart from localizer.cpp so the NDT tracking logic does not grow with it. No ROS.
#pragma once

#include <Eigen/Geometry>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "grid_puzzle_localization/fusion/sliding_window.hpp"
#include "grid_puzzle_localization/pose_covariance.hpp"

namespace grid_puzzle_localization {

/// Pose tracking past the NDT match: none (NDT with the constant-velocity prediction), the sliding-window factor
/// graph with IMU preintegration (fusion/sliding_window.hpp), or auto: the window from the first IMU sample that
/// carries a specific force (a 6-axis IMU is configured), NDT alone until then.
enum class FusionMode { kNone, kSlidingWindow, kAuto };
const char* toString(FusionMode mode);
/// "none", "sliding_window" or "auto"; nothing for anything else.
std::optional<FusionMode> parseFusionMode(const std::string& name);

struct FusionConfig {
  FusionMode mode = FusionMode::kAuto;
  SlidingWindowConfig window;  ///< used when the window runs; window.base_T_imu also turns the gyro
  /// > 0: multiplies covariance.scale for the NDT covariance that weighs a match in the window (ndtCovariance).
  /// The Hessian overstates what a scan fixes where the scene is degenerate: a voxel's Gaussian on a wall spans
  /// the voxel along it, so every wall point adds curvature along a tunnel that nothing constrains. Measured in
  /// the simulated corridor (docs/fusion.md): 1 lets matches that repeat the prediction pin the window.
  double ndt_covariance_scale = 100.0;

  /// Empty when usable (the window is checked only when it may run).
  std::string validate() const;
};

class FusionTracker {
 public:
  /// Throws std::invalid_argument naming the bad values when config.validate() is not empty.
  explicit FusionTracker(const FusionConfig& config);
  ~FusionTracker();
  /// The window runs (sliding_window, or auto once an IMU sample with a specific force came).
  bool enabled() const { return window_ != nullptr; }
  /// The window runs or may start (auto): odometry input is worth subscribing to.
  bool mayRun() const { return mode_ != FusionMode::kNone; }
  /// The IMU's pose in base_link (from TF once the IMU frame is known); applies to the samples that follow.
  const Eigen::Isometry3d& baseTImu() const { return window_config_.base_T_imu; }
  void setBaseTImu(const Eigen::Isometry3d& base_T_imu);

  /// A sample without a specific force or without rates (ImuSample::has_accel or has_gyro false) is not the
  /// window's: auto does not start the window with it, and a running window skips it with a warning.
  void addImu(const ImuSample& sample);
  /// Wheel odometry odom_T_base at `stamp` [s] (relative pose factors between consecutive states).
  void addOdometry(double stamp, const Eigen::Isometry3d& odom_T_base);

  /// The newest fused state propagated to `stamp` [s]; nothing when disabled or the window is empty.
  std::optional<FusedState> predict(double stamp) const;
  /// The covariance of the NDT parameters that weighs a match with Hessian `hessian` in the window: `config`
  /// with its scale times ndt_covariance_scale (the clamps of `config` apply to the scaled inverse).
  Matrix6d ndtCovariance(const Matrix6d& hessian, CovarianceConfig config) const;
  /// Adds the scan at `stamp` [s]: `match` is the accepted NDT pose (nullptr when none was accepted) with the
  /// covariance of the NDT parameters `ndt_covariance` (see ndtInformation). `restart` begins a new window (a
  /// new initial pose, a jump found by the global search). Returns the fused pose at `stamp` when a match was
  /// accepted and the window solved for it; nothing otherwise (the caller keeps its own pose).
  std::optional<Eigen::Isometry3d> update(double stamp, bool restart, const Eigen::Isometry3d* match,
                                          const Matrix6d& ndt_covariance);
  /// The map source switched blocks: the window keeps its reset_states newest states.
  void mapSwitched();
  /// Forgets the states (localizer reset, initial pose, global localization); buffered IMU samples stay.
  void reset();
  /// The warnings since the last call (IMU dropouts, refused stamps, no IMU covariance, no specific force...).
  std::vector<std::string> takeWarnings();
  /// States in the window (0 when disabled).
  std::size_t states() const { return window_ ? window_->size() : 0; }
  /// What the last update did; nothing when disabled.
  const WindowUpdateReport* lastReport() const { return window_ ? &window_->lastReport() : nullptr; }

 private:
  FusionMode mode_;
  SlidingWindowConfig window_config_;  // base_T_imu kept current: a window started later (auto) gets it
  double ndt_covariance_scale_;
  std::unique_ptr<SlidingWindow> window_;
  std::vector<std::string> warnings_;  ///< the tracker's own, before the window's
};

}  // namespace grid_puzzle_localization
