// Map-based LiDAR localizer: preprocessing, prediction, NDT against the current target snapshot,
// match quality gate and covariance, with the map prepared in the background. No ROS: the nodelet and
// the benchmark drive the same class.
#pragma once

#include <Eigen/Geometry>
#include <cstdint>
#include <future>
#include <limits>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "grid_puzzle_localization/deskew.hpp"
#include "grid_puzzle_localization/fusion/fusion_tracker.hpp"
#include "grid_puzzle_localization/global_localization.hpp"
#include "grid_puzzle_localization/map_update_worker.hpp"
#include "grid_puzzle_localization/ndt.hpp"
#include "grid_puzzle_localization/point_cloud.hpp"
#include "grid_puzzle_localization/pose_covariance.hpp"
#include "grid_puzzle_localization/pose_prediction.hpp"
#include "grid_puzzle_localization/pose_search.hpp"
#include "grid_puzzle_localization/preprocess.hpp"
#include "grid_puzzle_localization/scan_odometry.hpp"

namespace grid_puzzle_localization {

/// The gate a match must pass to be used as the pose.
struct MatchConfig {
  /// NVTL >= this (dimensionless, the mean best-voxel likelihood; 0 disables the check) ...
  double min_nvtl = 0.5;
  /// ... and transformation probability >= this (dimensionless; 0 disables the check) ...
  double min_transformation_probability = 0.0;
  /// ... and, when true, NDT converged (a match that hit max_iterations is rejected).
  bool require_converged = false;

  std::string validate() const;
};

struct ImuConfig {
  bool use_gyro = true;   ///< use gyro samples for the rotation prediction when they cover the interval
  double max_gap = 0.05;  ///< [s] >= 0, samples may end this far short of a scan and still cover it

  std::string validate() const;
};

/// Extra matches tried when the match from the prediction is poor (fails the gate, or its NVTL is below
/// poor_nvtl_ratio times the last accepted one's), never when it is good: the last accepted pose and, when
/// the rotation is uncertain (no gyro), yaw offsets +-k * yaw_step (k = 1..yaw_count) around it and around
/// the prediction. They are screened by the NDT cost (cheap), the best `refine` are aligned, and the best
/// acceptable one by NVTL is kept; when it is still poor the bounded search runs too.
struct HypothesesConfig {
  /// [rad] > 0; NDT converges from about 0.05-0.1 rad of yaw error at 1 m voxels (tens of metres of range
  /// turn the points by metres), so the offsets are that fine and screened rather than all aligned.
  double yaw_step = 0.05;
  int yaw_count = 12;            ///< >= 0
  int refine = 4;                ///< >= 1, alignments run
  int screen_points = 300;       ///< >= 10, scan points that screen the offsets by the NDT cost
  double poor_nvtl_ratio = 0.9;  ///< [0, 1]; 0 = only a match failing the gate is poor

  std::string validate() const;
};

/// After the last accepted match the localizer publishes its bounded prediction for at most
/// max_coast_time [s] > 0, and only while a gyro measures the rotation since that match (without one the
/// predicted heading is not measured); after that LocalizerOutput::publish is false until a match is accepted
/// again.
/// Once the prediction is no longer extrapolated, scans that nothing else matched run the branch-and-bound
/// global search around the last accepted pose (the bounded region, every yaw when the rotation is not
/// known), at most once per search_period [s] > 0 of scan time (a search takes about a second).
/// A given initial pose that the first scan does not fit (once the map around it has arrived) is wrong: the
/// square of side initial_pose_search_size [m] >= 0 around it is searched at once over every yaw (0 = only the
/// bounded region, which grows with the time since). With a window of tiles that search runs only when the window
/// holds all of its square: a look-alike place inside the window would otherwise win over the true one outside it.
/// When it does not run or finds nothing, the later scans search the bounded region around the refused pose.
/// With background_search the search runs on a thread of its own, one at a time, over the newest scan that needs
/// it: the scans go on being processed (and are reported lost) meanwhile, and the pose found is taken up at the
/// first scan after it finishes as the match of the scan it searched, so that scan is matched from it. Without
/// it the search runs within processScan and answers for that scan (offline replays that need the same answer
/// every time).
struct LostConfig {
  double max_coast_time = 2.0;
  double search_period = 1.0;
  double initial_pose_search_size = 60.0;
  bool background_search = true;

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
  MatchConfig match;
  ImuConfig imu;
  PredictionConfig prediction;
  HypothesesConfig hypotheses;
  LostConfig lost;
  FusionConfig fusion;
  /// The branch-and-bound search of recovery and globalLocalize. Its NDT refinement uses `ndt` above (the
  /// target is shared) with its own transformation_epsilon; one thread, like the matching.
  GlobalLocalizationConfig global = [] {
    GlobalLocalizationConfig c;
    c.threads = 1;
    return c;
  }();
  double time_jump_back = 0.5;  ///< [s] a scan this much older than the last one resets the localizer
  /// [m] > 0: with a window of tiles that is still arriving (a slow map store), a start, a search, a track and a
  /// failed match wait for the window's tiles in flight within the square of this half side around the pose (a search:
  /// around its region) instead of running on a partial map or counting as lost.
  double map_wait_half_side = 20.0;
  bool output_aligned = false;  ///< fill LocalizerOutput::aligned (costs a copy per scan)

  /// Empty when usable, else every bad value with its allowed range (includes the nested configs).
  std::string validate() const;
};

/// The localizer's branch-and-bound search: `config.global` refined on the localizer's own NDT target (its voxel
/// parameters and search method), with a likelihood spread of at least half a voxel (the search's map is the
/// target's voxel means).
GlobalLocalizationConfig globalSearchConfig(const LocalizerConfig& config);

/// The judged answer of an automatic start's search (Localizer::searchForStart).
struct StartSearch {
  GlobalLocalizationResult search;  ///< found: the start was taken
  bool held = false;                ///< the search answered and its answer is held for the next one to confirm
  /// The search did not run: this many tiles of its region are still in flight (on a window still arriving it would
  /// call the place ambiguous, or find a look-alike). It is asked for again later.
  std::size_t tiles_awaited = 0;
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
  /// The prediction the match started from (map_T_base): the constant-velocity one while it is trusted,
  /// else the last accepted pose (rotated by the gyro when it covers the interval). While a given start waits for
  /// its map (start_pending): that start, carried to this scan.
  Eigen::Isometry3d prediction = Eigen::Isometry3d::Identity();
  /// Waiting for the map with a given start (initial pose): the vehicle may drive on meanwhile, so the start is
  /// carried by the scans' own motion (ScanOdometry, each scan matched against the one before) and is matched where
  /// the vehicle is once the tiles around it have arrived. Tiles load nearest it first; a provider's window should
  /// follow it.
  bool start_pending = false;
  /// A step of that motion was not measured (two scans that did not match): the start is then not known to the
  /// NDT's reach, and is searched around (lost/initial_pose_search_size) instead of matched from.
  bool start_motion_guessed = false;
  Twist twist = Twist::Zero();  ///< body twist (base frame) [m/s, rad/s]
  /// Of the pose, in ROS's order and frames: x y z in the map frame, then rotation about the map's fixed
  /// X Y Z axes (a perturbation R' = exp(dtheta) R) [m^2, rad^2]. Grows with the time since the last
  /// accepted match while the prediction is published.
  Matrix6d covariance = Matrix6d::Zero();
  /// Of the body twist (base frame): 2 * (pose covariance in the base frame) / dt^2 for two independent poses
  /// dt apart; the max-std diagonal when the twist is not measured.
  Matrix6d twist_covariance = Matrix6d::Zero();
  bool match_accepted = false;  ///< false: pose is the prediction
  /// No match was accepted on this scan, after the hypotheses and the search: the pose is not measured.
  bool lost = false;
  /// When lost: the region the pose can be in (around the last accepted pose, radius growing with the time since),
  /// which a map source should cover for the search to find the pose. Radius 0 otherwise.
  SearchRegion search_region;
  /// The pose may be published: a match was accepted, or the last accepted one is at most
  /// lost.max_coast_time old and a gyro covers the time since.
  bool publish = false;
  /// [s] from the last accepted match (or initial pose) before this scan; on an accepted scan that took up a
  /// background search's pose, the time without a match that the search ended.
  double since_last_match = 0.0;
  int hypotheses = 0;      ///< candidates the hypotheses descended from on this scan (after a poor match)
  bool recovered = false;  ///< accepted after lost.max_coast_time without a match
  /// The branch-and-bound search answered on this scan: it ran within it, or (lost.background_search) one
  /// started on an earlier scan finished and was taken up.
  bool global_search = false;
  std::string global_search_reason;  ///< why its answer was refused (empty when taken or not run)
  bool search_started = false;       ///< a background search of this scan was started (lost.background_search)
  /// A start search beside the scan thread (startSearchForStart) finished before this scan: its answer, judged as
  /// searchForStart judges it (found: the track starts there, and this scan is matched from it).
  std::optional<StartSearch> start_search;
  NdtResult ndt;  ///< the match; when none was accepted, the last one tried (status INVALID_INPUT: none was tried)
  PreprocessReport preprocess;
  double align_ms = 0.0;  ///< NDT only
  double scan_ms = 0.0;   ///< whole processScan, including preprocessing and the swap
  std::size_t target_voxels = 0;
  std::size_t target_points = 0;
  std::size_t tiles_in_flight = 0;  ///< tiles of the provider's window not in the map yet (loading, fetching)
  /// Of those, the tiles near the pose this scan waited for (map_wait_half_side): the start waits for them; a match
  /// that failed meanwhile is not lost and starts no search. 0 when nothing was waited for.
  std::size_t tiles_awaited = 0;
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
  /// A full IMU sample (IMU frame, see fusion.window.base_T_imu): its rate feeds the gyro prediction and, with
  /// the window running (fusion sliding_window, or auto with a specific force), the sample feeds it. Scan thread only.
  void addImu(const ImuSample& sample);
  /// The fusion: IMU extrinsic from TF, wheel odometry, block switches, warnings. Scan thread only.
  FusionTracker& fusion() { return fusion_; }

  /// Localises one scan taken at `stamp` [s]: `scan` in the sensor frame, `base_T_sensor` the mounting.
  /// `times` (optional, one per point) are the capture times [s] after `stamp`; with them and
  /// config.preprocess.deskew the points are moved to the stamp along the predicted motion, so the pose is
  /// the one at `stamp` exactly. Times of another size than the scan are ignored. Scan thread only. Never
  /// throws for bad data; the output pose is always finite.
  LocalizerOutput processScan(double stamp, const PointCloud& scan, const Eigen::Isometry3d& base_T_sensor,
                              const PointTimes* times = nullptr);

  /// Forgets the motion and the pose (the map stays); the default initial pose, if any, is re-armed.
  void reset();

  /// Searches `region` (map frame; the square of side 2 * radius, yaws within +-yaw_range, a full circle from pi)
  /// by branch and bound for the pose of the last scan given to processScan (its preprocessed points) and,
  /// when an acceptable unambiguous pose is found, makes it the pose at that scan's stamp (the next scans search
  /// around it, as after a pose without a velocity). Scan thread only. With no scan or no map yet: not found,
  /// with the reason.
  GlobalLocalizationResult globalLocalize(const SearchRegion& region);
  /// The automatic start of a localizer without a pose (an initialpose_hint's square, the whole map): searches as
  /// globalLocalize does, but takes an answer only when the answer of an earlier scan's search agrees with it: the
  /// two are no farther apart than the motion bound between their scans (prediction/max_speed and max_yaw_rate,
  /// boundedSearchRegion) plus the search's own distance between distinct places (runner_up_distance and
  /// runner_up_yaw); the motion between the two is then the track's velocity. An answer that no held one agrees
  /// with is held for the next searches (the last four) and reported not found, with the reason, and `held`. One
  /// search alone is never taken: on a large map the search can miss the true place, and another place may then fit
  /// the scan well enough to pass every gate. Searches on every core (nothing is tracked meanwhile). Scan thread only.
  using StartSearch = grid_puzzle_localization::StartSearch;
  StartSearch searchForStart(const SearchRegion& region);
  /// searchForStart beside the scan thread (lost.background_search): the search of `region` on the last scan runs on
  /// a thread of its own, on every core but niced below the scan thread, and returns at once; the scans go on
  /// meanwhile, each reported waiting for a pose (not queued behind the search), and the first scan after it
  /// finishes judges its answer (LocalizerOutput::start_search). The search's work budget
  /// (GlobalLocalizationConfig::max_poses) bounds its time. Without background_search it is searchForStart. Returns
  /// the judged answer when it searched within the call or did not search (StartSearch::tiles_awaited), nullopt when
  /// the search runs beside (or one already runs: it is not started twice). Scan thread only.
  std::optional<StartSearch> startSearchForStart(const SearchRegion& region);
  /// A search started by this localizer (a start's, a recovery's) is still running. Scan thread only.
  bool searching() const { return search_.has_value(); }
  /// An automatic start's answer is held, waiting for a search of a later scan to agree with it.
  bool startAwaitsConfirmation() const { return !start_candidates_.empty(); }
  /// The x y z extent of the current target's Gaussians (voxel means); empty without a map.
  std::optional<Eigen::AlignedBox3d> mapBounds() const;
  /// Whether the map held reaches around the square of half side `half` [m] about `centre` (x y, map frame):
  /// always with a whole map (nothing lies outside it); with a window of tiles when the provider's window holds the
  /// square (where it has no tile the map has no point), or without that window when the tiles' extent holds it.
  bool mapHolds(const Eigen::Vector3d& centre, double half) const;
  /// Tiles of the window still in flight that meet the square of half side `half` [m] about `centre` (x y, map
  /// frame), as of the map the last scan was matched on.
  std::size_t tilesAwaited(const Eigen::Vector2d& centre, double half) const { return in_flight_.within(centre, half); }
  /// The pose of the last accepted match, if any since the last reset.
  std::optional<Eigen::Isometry3d> lastAcceptedPose() const;
  /// Blocks until a background search that is running has finished, so that the next scan takes up its answer
  /// (offline callers that process scans faster than real time). Scan thread only.
  void waitForSearch() const;
  /// True while the global search's structures (built by the last search) are held. They are released when a new
  /// map snapshot arrives (once taken up when a background search ran then), with the snapshot they were built
  /// from, and rebuilt by the next search. Not while a background search runs (it builds them): waitForSearch first.
  bool holdsSearchMap() const { return global_target_ != nullptr; }

 private:
  bool acceptable(const NdtResult& r) const;
  /// Holds `map_T_base` (none: nothing) as the start of the next scan, with no motion carried yet (the vehicle's body
  /// twist `velocity` [m/s, rad/s] until one is measured), its tiles first.
  void holdStart(const std::optional<Eigen::Isometry3d>& map_T_base, const Twist& velocity = Twist::Zero());
  /// source_ from `scan`, not deskewed (no motion is known), in the base frame.
  void prepareUndeskewed(const PointCloud& scan, const Eigen::Isometry3d& base_T_sensor, double stamp,
                         LocalizerOutput& out);
  /// Carries the held start by the motion from the last scan to source_ (the scan at `stamp`), and loads its tiles
  /// first.
  void carryStart(double stamp, LocalizerOutput& out);
  /// Ends the track, if any, and reports this scan waiting for `awaited` tiles of the map, the held start carried to
  /// it (holdStart first).
  void waitForMapCarried(double stamp, std::size_t awaited, LocalizerOutput& out);
  /// The branch-and-bound search of `region` on the current source and target (the map given to it first
  /// when the target changed); found only when its refinement also passes the match gate.
  GlobalLocalizationResult searchGlobally(const GlobalSearchRequest& request);
  /// The request that searches `region` (at least a voxel either way, a few yaw steps either side) on `threads`
  /// (GlobalSearchRequest::threads).
  GlobalSearchRequest searchRequest(const SearchRegion& region, int threads = -1) const;
  /// Runs `request` on `source` in `target` (the search's map rebuilt when it was another target); found only when
  /// the refinement also passes the match gate. On the background search's thread while one runs.
  GlobalLocalizationResult runSearch(const std::shared_ptr<const VoxelMap>& target, const PointCloud& source,
                                     const GlobalSearchRequest& request);
  /// Where a pose found for a scan may lie: within `radius` [m] (x y) of `centre`, the last accepted position. A
  /// pose farther than the motion bound allows is a false minimum, however well it scores.
  struct Reach {
    Eigen::Vector2d centre = Eigen::Vector2d::Zero();
    double radius = std::numeric_limits<double>::infinity();  // the default reaches anywhere
    bool holds(const Eigen::Isometry3d& pose) const { return (pose.translation().head<2>() - centre).norm() <= radius; }
  };
  /// Starts the search of `region` for the scan at `stamp` (source_) on its own thread; its pose is taken up within
  /// `reach` (anywhere by default), as a restart of the track when `restarts_track`.
  void startBackgroundSearch(double stamp, const SearchRegion& region, bool restarts_track, const Reach& reach);
  /// Releases the search's structures when they were built for a target swapped out while the search ran.
  void releaseStaleSearchMap();
  /// Judges a start search's answer `r` for the scan at `stamp` against the held ones (searchForStart).
  StartSearch judgeStart(GlobalLocalizationResult r, double stamp);
  /// The finished start search beside the scan thread, judged; nullopt while it runs or when none was started.
  std::optional<StartSearch> takeStartSearch();
  /// Takes up a finished background search: its pose becomes the match of the scan it searched when the track has
  /// not moved since it started and the pose lies within its reach. Returns the time [s] from the last accepted
  /// match to this scan when it was taken up.
  std::optional<double> takeFinishedSearch(double stamp, LocalizerOutput& out);
  /// Records `match` as the last accepted one: its covariance and NVTL, and the twist the predictor measured.
  void noteAccepted(const NdtResult& match);
  /// Tracks from `pose` at `stamp` with no motion known yet (an initial pose, a global search's answer).
  void startFrom(const Eigen::Isometry3d& pose, double stamp, const Matrix6d& covariance, double reference_nvtl);
  /// Starts the track at the answer of a global search of the last scan.
  void startFromSearch(const GlobalLocalizationResult& found);
  /// The wait for a background search and the search of `request` for the last scan, common to globalLocalize and
  /// searchForStart.
  GlobalLocalizationResult searchLastScan(const GlobalSearchRequest& request);
  /// The best acceptable match among the hypotheses: `held` (the last accepted pose) and yaw offsets around
  /// `guess` (the prediction) when the rotation is not known.
  std::optional<NdtResult> tryHypotheses(const Eigen::Isometry3d& guess, const Eigen::Isometry3d& held,
                                         bool rotation_known, LocalizerOutput& out);
  /// The predicted sensor motion over the sweep [stamp + t_begin, stamp + t_end]; gyro rotation when covered;
  /// no translation when `velocity_unknown`, else `fused` (the window's prediction) gives the linear velocity if any.
  SweepMotion sweepMotion(double stamp, double t_begin, double t_end, const Eigen::Isometry3d& base_T_sensor,
                          bool velocity_unknown, const std::optional<FusedState>& fused) const;

  LocalizerConfig config_;
  Preprocessor preprocessor_;
  PointCloud source_;  // the preprocessed scan in base_link, reused between scans
  NdtAligner aligner_;
  NdtAligner carried_aligner_;         // aligner_ with at most kCarriedMatchIterations (localizer.cpp)
  ScanOdometry start_odometry_;        // carries pending_initial_pose_ while its map arrives
  bool start_motion_guessed_ = false;  // a step of that motion was not measured
  MapUpdateWorker worker_;
  std::shared_ptr<const VoxelMap> target_;
  TilesInFlight in_flight_;  // the window's tiles target_ does not hold yet
  PosePredictor predictor_;
  std::optional<Twist> last_twist_;  // the last measured body twist; a recovery's predictor reset keeps it
  GyroIntegrator gyro_;
  FusionTracker fusion_;
  std::optional<Eigen::Isometry3d> pending_initial_pose_;
  std::optional<Eigen::Isometry3d> default_initial_pose_;
  std::optional<double> last_stamp_;
  MotionBounds motion_seen_;                     // fastest accepted motion since the initial pose
  Matrix6d last_covariance_ = Matrix6d::Zero();  // of the last accepted match (ROS order)
  double reference_nvtl_ = 0.0;                  // of the last accepted match
  std::optional<double> source_stamp_;           // source_ holds the scan of this stamp (for globalLocalize)
  GlobalLocalizer global_;
  std::shared_ptr<const VoxelMap> global_target_;  // the target global_ was given (rebuilt when it changes)
  std::optional<double> last_global_search_;       // scan stamp of the last recovery search
  std::uint64_t track_version_ = 0;                // counts the changes of the last accepted pose
  bool start_refused_ = false;                     // the given pose held was refused by its first scan
  struct StartCandidate {
    Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  // an automatic start's answer (searchForStart) ...
    double stamp = 0.0;                                      // ... for the scan of this stamp
  };
  std::vector<StartCandidate> start_candidates_;  // held until the search of a later scan agrees with one, oldest first
  // A recovery search running on its own thread (lost.background_search). Declared last: its destructor waits for
  // the thread, which uses global_ and global_target_.
  struct BackgroundSearch {
    std::future<GlobalLocalizationResult> result;
    double stamp = 0.0;               // of the scan searched
    std::uint64_t track_version = 0;  // when it started: a change since makes its answer stale
    bool restarts_track = false;      // a start's or a gap's search: its pose is a correction, not a motion
    bool start = false;               // an automatic start's search (startSearchForStart), judged by judgeStart
    Reach reach;                      // where its pose may lie; by default anywhere in a wrong start's square
  };
  std::optional<BackgroundSearch> search_;
};

}  // namespace grid_puzzle_localization
