// Map-based LiDAR localizer: preprocessing, prediction, NDT against the current target snapshot,
// match quality gate and covariance, with the map prepared in the background. No ROS: the nodelet and
// the benchmark drive the same class.
#pragma once

#include <Eigen/Geometry>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "grid_puzzle_localization/deskew.hpp"
#include "grid_puzzle_localization/map_update_worker.hpp"
#include "grid_puzzle_localization/ndt.hpp"
#include "grid_puzzle_localization/point_cloud.hpp"
#include "grid_puzzle_localization/pose_covariance.hpp"
#include "grid_puzzle_localization/pose_prediction.hpp"
#include "grid_puzzle_localization/preprocess.hpp"

namespace grid_puzzle_localization {

/// Re-acquisition after a loss: once `after_rejections` scans in a row had their match rejected, each
/// further scan is also matched from `candidates_per_scan` guesses on a grid of `step` around the
/// prediction (map-frame x y offsets up to `radius`, nearest first, cycling over scans); the best
/// acceptable match (highest NVTL) is taken.
struct RecoveryConfig {
  int after_rejections = 3;     ///< >= 0; 0 disables re-acquisition (the localizer coasts on the prediction)
  double radius = 4.0;          ///< [m] >= 0, largest offset tried
  double step = 2.0;            ///< [m] > 0, grid spacing of the offsets
  int candidates_per_scan = 4;  ///< >= 1; each costs one more alignment while lost

  std::string validate() const;
};

struct LocalizerConfig {
  PreprocessConfig preprocess;  ///< applied in the sensor frame (ranges are from the sensor)
  /// Matching; its resolution is also the target's. One OpenMP thread by default, unlike NdtConfig's "all
  /// cores": a 10 Hz scan takes ~10 ms on one core, and a team of two that shares its cores with the
  /// driver and the map worker waits for its slowest thread (measured 4x the median latency on a loaded
  /// 2-core machine, see README "Benchmark").
  NdtConfig ndt = [] {
    NdtConfig c;
    c.threads = 1;
    return c;
  }();
  CovarianceConfig covariance;
  int map_update_threads = 1;  ///< OpenMP threads of background target updates (0 = all cores)
  /// A match is accepted only when NVTL >= min_nvtl (dimensionless, the mean best-voxel likelihood;
  /// 0 disables the check) ...
  double min_nvtl = 0.5;
  /// ... and transformation probability >= this (dimensionless; 0 disables the check) ...
  double min_transformation_probability = 0.0;
  /// ... and, when true, NDT converged (a match that hit max_iterations is rejected).
  bool require_converged = false;
  /// [s] >= 0: time constant of the low-pass filter on the twist that deskews scans. The twist is the
  /// difference of two matched poses, and each matched pose depends on the twist its scan was deskewed
  /// with: unfiltered (0), that loop is marginally stable and the speed oscillates scan to scan.
  double deskew_twist_smoothing = 0.15;
  bool use_gyro = true;         ///< use gyro samples for the rotation prediction when they cover the interval
  double gyro_max_gap = 0.05;   ///< [s] samples may end this far short of a scan and still cover it
  double time_jump_back = 0.5;  ///< [s] a scan this much older than the last one resets the localizer
  bool output_aligned = false;  ///< fill LocalizerOutput::aligned (costs a copy per scan)
  RecoveryConfig recovery;

  /// Empty when usable, else every bad value with its allowed range (includes the nested configs).
  std::string validate() const;
};

enum class LocalizerState { kWaitingForMap, kWaitingForInitialPose, kTracking };
const char* toString(LocalizerState state);

struct LocalizerOutput {
  LocalizerState state = LocalizerState::kWaitingForMap;
  bool reset = false;               ///< this scan was older than the last one by > time_jump_back: state was reset
  bool map_swapped = false;         ///< a new target snapshot was swapped in before this scan
  bool map_update_pending = false;  ///< a target update was queued or in progress when the scan started
  /// Valid when state == kTracking: map_T_base at the scan stamp, always finite.
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  /// The prediction the match started from (map_T_base); the initial pose on the first scan after one.
  Eigen::Isometry3d prediction = Eigen::Isometry3d::Identity();
  Twist twist = Twist::Zero();             ///< body twist (base frame) [m/s, rad/s]
  Matrix6d covariance = Matrix6d::Zero();  ///< of (x y z roll pitch yaw) [m^2, rad^2]
  /// Of the twist: 2 * covariance / dt^2 for two independent poses dt apart; the max-std diagonal when the
  /// twist is not measured (first scan after an initial pose, or a prediction).
  Matrix6d twist_covariance = Matrix6d::Zero();
  bool match_accepted = false;  ///< false: pose is the prediction
  /// This scan came after recovery.after_rejections rejected matches in a row: re-acquisition was tried.
  bool lost = false;
  int recovery_candidates = 0;  ///< extra alignments tried for re-acquisition on this scan
  bool reacquired = false;      ///< one of them was accepted: the pose jumped to it (not motion)
  NdtResult ndt;                ///< the match (status INVALID_INPUT when no match was tried)
  PreprocessReport preprocess;
  double align_ms = 0.0;  ///< NDT only
  double scan_ms = 0.0;   ///< whole processScan, including preprocessing and the swap
  std::size_t target_voxels = 0;
  std::size_t target_points = 0;
  PointCloud aligned;  ///< map frame, when config.output_aligned and tracking
};

class Localizer {
 public:
  /// Throws std::invalid_argument naming the bad values when config.validate() is not empty.
  explicit Localizer(const LocalizerConfig& config);
  const LocalizerConfig& config() const { return config_; }

  /// Map input: thread-safe, returns at once; the change is applied in the background and swapped in at
  /// the first scan after it is ready.
  MapUpdateWorker& map() { return worker_; }

  /// The pose (map_T_base) to start from at the next scan, e.g. from rviz. Scan thread only.
  void setInitialPose(const Eigen::Isometry3d& map_T_base);
  /// The start pose used after construction and after every reset (from parameters). Scan thread only.
  void setDefaultInitialPose(const Eigen::Isometry3d& map_T_base);
  /// Angular velocity of the base [rad/s, base frame] at `stamp` [s]. Scan thread only.
  void addGyro(double stamp, const Eigen::Vector3d& angular_velocity);

  /// Localises one scan taken at `stamp` [s]: `scan` in the sensor frame, `base_T_sensor` the mounting.
  /// `times` (optional, one per point) are the capture times [s] after `stamp`; with them and
  /// config.preprocess.deskew the points are moved to the stamp along the predicted motion, so the pose is
  /// the one at `stamp` exactly. Times of another size than the scan are ignored. Scan thread only. Never
  /// throws for bad data; the output pose is always finite.
  LocalizerOutput processScan(double stamp, const PointCloud& scan, const Eigen::Isometry3d& base_T_sensor,
                              const PointTimes* times = nullptr);

  /// Forgets the motion and the pose (the map stays); the default initial pose, if any, is re-armed.
  void reset();

 private:
  bool acceptable(const NdtResult& r) const;
  /// Matches from the next recovery guesses around `guess` (their number in `tries`); the best acceptable
  /// result, if any.
  std::optional<NdtResult> reacquire(const Eigen::Isometry3d& guess, int tries);
  /// The predicted sensor motion over the sweep [stamp + t_begin, stamp + t_end]; gyro rotation when covered.
  SweepMotion sweepMotion(double stamp, double t_begin, double t_end, const Eigen::Isometry3d& base_T_sensor,
                          bool fresh) const;

  LocalizerConfig config_;
  Preprocessor preprocessor_;
  PointCloud source_;  // the preprocessed scan in base_link, reused between scans
  NdtAligner aligner_;
  MapUpdateWorker worker_;
  std::shared_ptr<const VoxelMap> target_;
  PosePredictor predictor_;
  GyroIntegrator gyro_;
  std::optional<Eigen::Isometry3d> pending_initial_pose_;
  std::optional<Eigen::Isometry3d> default_initial_pose_;
  std::optional<double> last_stamp_;
  int rejected_in_a_row_ = 0;
  std::vector<Eigen::Vector3d> recovery_offsets_;  // map frame, nearest first
  std::size_t next_recovery_offset_ = 0;
};

}  // namespace grid_puzzle_localization
