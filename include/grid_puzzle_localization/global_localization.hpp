// Global localization without an initial guess: branch-and-bound search (BBS) over x, y and yaw on a
// multi-resolution 2D pyramid of the map's structure, then NDT refinement (block map paper, section III-C).
// No ROS includes here.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>
#include <cstddef>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "grid_puzzle_localization/ndt.hpp"
#include "grid_puzzle_localization/point_cloud.hpp"
#include "grid_puzzle_localization/voxel_map.hpp"

namespace grid_puzzle_localization {

/// Every parameter of the search. Units in the comments; check with validate().
struct GlobalLocalizationConfig {
  /// [m] cell of the finest search grid and translation step of the search.
  double resolution = 0.5;
  /// [m] edge of the cells in which the lowest point is taken as the ground (map and scan alike).
  double ground_cell = 2.0;
  /// [m] edges of the height bands above the ground (strictly increasing, >= 2 values): a structure point of the
  /// scan is matched only against map structure of its own band, which tells a hedge from a wall behind it. Points
  /// below the first edge (the ground) or above the last one are not used.
  std::vector<double> height_bands = {0.5, 1.5, 3.0, 6.0, 12.0};
  /// [m] map structure this close to a band counts in it too (the ground under the map and under the scan are
  /// estimated from different points), >= 0.
  double band_overlap = 0.3;
  /// [m] scan points farther than this (horizontally) from the sensor are not used by the search.
  double max_range = 40.0;
  /// Structure points of the scan used by the search after the 2D thinning (evenly chosen), >= 10.
  int max_scan_points = 800;
  /// A scan with fewer structure points than this is refused ("too few points"), >= 3.
  int min_scan_points = 30;
  /// [m] spread of the likelihood around each occupied map cell (0 = plain occupancy).
  double blur_sigma = 0.25;
  /// [rad] yaw step; 0 = automatic, resolution / (the farthest scan point used), which moves it by <= 1 cell.
  double yaw_step = 0.0;
  /// Pyramid levels above the finest one, 1..12; a coarse cell covers 2^levels fine cells.
  int levels = 6;
  /// Work budget of one search: base positions times yaws at the finest level, (cells per side)^2 * yaws, in
  /// [1000, 2^31 - 1]. A request over it (a larger square) is searched at resolution * 2^k with the smallest k that
  /// fits, the yaw step and blur_sigma scaled by 2^k too (the same search in cells). The best 4 * (refine_candidates
  /// + 1) coarse places (2 coarse cells or yaw steps apart) are then brought down to full resolution one level at a
  /// time, searching 9 x 9 positions x 9 yaws (2 cells and 2 yaw steps of the level above on each side) per level,
  /// and chosen among at full resolution before the NDT refinement. The default holds a 40 m square with the full
  /// circle of yaw at 0.5 m (81^2 positions x at most 503 yaws, a scan reaching max_range: 3.3e6 poses), which runs
  /// at full resolution, a wrong start's 60 m square at 1 m, a 200 m to 400 m square at 2 m, and a square of up to
  /// 1.2 km (the bounding box of a 1 km^2 map) at 4 m. At 8 m, a real 0.9 km^2 map defeated the search: the true place
  /// was often not among its coarse candidates (docs/global_localization.md).
  int max_poses = 6000000;
  /// The block map paper's adapted initial score S0: greedy descents from the best coarse candidates set the
  /// pruning bound before the search. false = plain BBS (Hess et al. 2016) starting from min_score.
  bool adapted_initial_score = true;
  /// Greedy descents (from the best coarse candidates) whose best leaf is S0, >= 1.
  int initial_descents = 4;
  /// Fraction of the scan's structure points on the map's structure (likelihood-weighted) that a pose needs
  /// to be considered, in [0, 1].
  double min_score = 0.3;
  /// The search explores the candidates scoring within this fraction of the best, in (0, 1]; the distinct ones among
  /// them are refined, and an answer whose runner-up's NDT fit is at least this fraction of its own is refused as
  /// ambiguous.
  double max_runner_up_ratio = 0.9;
  /// [m] a runner-up must be at least this far from the winner in position ...
  double runner_up_distance = 2.0;
  /// [rad] ... or in yaw.
  double runner_up_yaw = 0.35;
  /// Distinct candidates (runner_up_distance / runner_up_yaw apart) within max_runner_up_ratio of the best that
  /// are refined by NDT, >= 1: candidates that converge to one pose are one answer, so the slope of one peak is
  /// not taken for a second place. More distinct candidates than this make the answer ambiguous.
  int refine_candidates = 4;
  /// [m] refined poses closer than this ...
  double same_pose_distance = 0.5;
  /// [rad] ... and turned less than this are the same answer.
  double same_pose_yaw = 0.035;
  /// NDT used to refine the candidates (its resolution is also the voxel size of the target built from the map
  /// points when no target is given to setMap). The package's NDT defaults, but iterated down to 1 mm steps: the
  /// refined pose is the final answer, not the first guess of a tracker.
  NdtConfig ndt = [] {
    NdtConfig c;
    c.transformation_epsilon = 0.001;
    return c;
  }();
  /// The refined pose must have at least this fraction of the scan points that land on the map's area (x-y cells of
  /// ground_cell holding map points) within the NDT inlier gate, in [0, 1]. Points beyond the map (a window of
  /// tiles that ends short of the sensor's range) say nothing against the pose.
  double min_inlier_fraction = 0.5;
  /// [m] the refinement may move the search's answer at most this far (else it is refused).
  double max_refinement_shift = 2.0;
  /// OpenMP threads, 0 = all cores. The result does not depend on it.
  int threads = 0;

  /// Empty when usable, else a message naming each bad value and its allowed range.
  std::string validate() const;
};

/// Where to search: a square in the map frame and a yaw interval.
struct GlobalSearchRequest {
  double center_x = 0.0;                            ///< [m] map frame
  double center_y = 0.0;                            ///< [m] map frame
  double size = 40.0;                               ///< [m] edge of the square of base positions searched, > 0
  double yaw_center = 0.0;                          ///< [rad] map frame, yaw of the base
  double yaw_range = 2.0 * 3.14159265358979323846;  ///< [rad] full width of the yaw interval; >= 2 pi = full circle
  int threads = -1;  ///< OpenMP threads of this search, 0 = all cores; -1 = the config's `threads`
};

/// Outcome of one search. All numbers finite whatever `found`.
struct GlobalLocalizationResult {
  bool found = false;  ///< a pose was found and accepted (unambiguous, refined, above min_score)
  Eigen::Isometry3d map_T_base = Eigen::Isometry3d::Identity();  ///< the refined pose (the best guess when refused)
  /// Search score of the answer: likelihood-weighted fraction of the scan's structure points on map structure of
  /// their height band, in [0, 1].
  double score = 0.0;
  /// Search score of the runner-up: the best other answer (a distinct candidate that refines to another pose).
  /// Without one, max_runner_up_ratio times the best search score: an upper bound, since the search proved that no
  /// other place scores more.
  double runner_up_score = 0.0;
  /// NDT fit of the answer (transformation probability: -NDT score per scan point, higher is better). Answers are
  /// chosen by it.
  double fit = 0.0;
  /// NDT fit of the runner-up; without one, max_runner_up_ratio * fit (an upper bound, see runner_up_score).
  double runner_up_fit = 0.0;
  /// 1 - runner_up_fit / fit, in [0, 1]; 0 = two places explain the scan equally well. Answers with a confidence
  /// below 1 - max_runner_up_ratio are refused.
  double confidence = 0.0;
  std::string reason;                    ///< empty when found, else why it was refused and what to do
  double seconds = 0.0;                  ///< wall time of localize()
  double grid_seconds = 0.0;             ///< of which: likelihood grids and pyramid of the search area
  double search_seconds = 0.0;           ///< of which: the branch-and-bound search
  double refine_seconds = 0.0;           ///< of which: the NDT refinement of the candidates
  std::size_t candidates_evaluated = 0;  ///< search nodes scored (all levels, all stages); varies with threads
  /// [m] translation step of the search over the whole square: resolution * 2^k, the smallest k whose poses fit
  /// max_poses (0 when the search did not run).
  double search_resolution = 0.0;
  /// Poses (positions x yaws) at the finest level of the search over the whole square, <= max_poses.
  std::size_t search_poses = 0;
  /// Poses of the searches that bring the coarse places down to full resolution (0 when the square was searched at
  /// full resolution): 729 per place and level, at most 4 * (refine_candidates + 1) * 729 * k.
  std::size_t local_poses = 0;
  std::size_t scan_points_used = 0;  ///< structure points of the scan the search matched
  NdtResult refinement;              ///< the NDT refinement of the winner (status INVALID_INPUT if not run)
  /// Of the refined scan's points that land on the map's area, the fraction within the NDT inlier gate, in [0, 1].
  double explained_fraction = 0.0;
};

/// Holds a map and answers global localization requests. Not thread-safe for setMap(); localize() is const and
/// may be called concurrently.
class GlobalLocalizer {
 public:
  /// Throws std::invalid_argument when config.validate() is not empty.
  explicit GlobalLocalizer(const GlobalLocalizationConfig& config = GlobalLocalizationConfig());
  ~GlobalLocalizer();
  GlobalLocalizer(GlobalLocalizer&&) noexcept;
  GlobalLocalizer& operator=(GlobalLocalizer&&) noexcept;

  const GlobalLocalizationConfig& config() const { return config_; }

  /// Sets the map: points in the map frame [m] (raw map points, tile points or NDT voxel means). The NDT target
  /// for the refinement is `ndt_target` when given (it must use config().ndt.resolution), else built from
  /// `map_points` (which then need >= ndt.min_points_per_voxel points per voxel, i.e. not voxel means).
  void setMap(const PointCloud& map_points, std::shared_ptr<const VoxelMap> ndt_target = nullptr);
  bool hasMap() const;
  /// Forgets the map and its search structures (and releases the NDT target it held).
  void clearMap();
  /// [m] x-y bounding box of the map's structure points (both zero without a map); lets a caller search the whole
  /// map.
  Eigen::AlignedBox2d mapBounds() const;

  /// Searches for map_T_base given `scan` in the base frame [m]. `up_in_base` is the direction opposite to gravity
  /// in the base frame (e.g. an IMU's acceleration at rest); without it the base is assumed level. Never throws
  /// for bad data: see GlobalLocalizationResult::found and reason.
  GlobalLocalizationResult localize(const PointCloud& scan, const GlobalSearchRequest& request,
                                    const std::optional<Eigen::Vector3d>& up_in_base = std::nullopt) const;

 private:
  struct Map;
  GlobalLocalizationConfig config_;
  std::unique_ptr<Map> map_;
};

}  // namespace grid_puzzle_localization
