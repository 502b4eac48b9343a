// Candidate poses around a known pose and their screening by the NDT cost (one pass over a subsample of the
// scan), for the localizer's hypotheses when a match is poor: yaw offsets around the last pose and the
// prediction. The region a pose can have reached is searched by branch and bound (global_localization.hpp).
// No ROS.
#pragma once

#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "grid_puzzle_localization/ndt.hpp"
#include "grid_puzzle_localization/point_cloud.hpp"

namespace grid_puzzle_localization {

/// Where to look: a disc of `radius` [m] around centre's x y (map frame) and yaws within +-yaw_range
/// [rad] of centre's yaw (about the map's z axis); z, roll and pitch are the centre's.
struct SearchRegion {
  Eigen::Isometry3d centre = Eigen::Isometry3d::Identity();
  double radius = 0.0;
  double yaw_range = 0.0;
};

struct SearchConfig {
  double step = 1.0;          ///< [m] > 0, grid spacing of the x y candidates (about the NDT basin at 1 m voxels)
  double yaw_step = 0.1;      ///< [rad] > 0, spacing of the yaw candidates (NDT converges from ~0.05-0.1 rad)
  int max_candidates = 3000;  ///< >= 1; a larger region is sampled with a coarser x y step
  int screen_points = 300;    ///< >= 10; scan points used to screen candidates (evenly subsampled)
  int refine = 10;            ///< >= 1; best-screened candidates kept
};

/// The candidate guesses of a region, nearest the centre first: x y on a square grid of spacing
/// >= config.step inside the disc (coarsened so that positions x yaws <= max_candidates), yaw offsets
/// 0, +-yaw_step, +-2 yaw_step ... within yaw_range (a full circle when yaw_range >= pi).
std::vector<Eigen::Isometry3d> searchCandidates(const SearchRegion& region, const SearchConfig& config);

/// The screened candidates, best (lowest NDT cost at the candidate) first, at most config.refine of them.
std::vector<Eigen::Isometry3d> screenCandidates(const NdtAligner& aligner, const VoxelMap& target,
                                                const PointCloud& source, const std::vector<Eigen::Isometry3d>& all,
                                                const SearchConfig& config);

/// Whether `candidate` adds nothing to an NDT coarse stage started at `start`: it lies at start's x y (within
/// `position_tolerance` [m]) and its rotation within `yaw_probe` [rad] of start's. The coarse stage also tries its
/// start turned by +-NdtConfig::coarse_yaw_probe, so with that probe it reaches such a candidate's basin as well.
bool coveredByYawProbe(const Eigen::Isometry3d& start, const Eigen::Isometry3d& candidate, double position_tolerance,
                       double yaw_probe);

}  // namespace grid_puzzle_localization
