// Local pose search around a known pose when the prediction cannot be trusted (start-up without a
// velocity, a gap in the data, a lost track): candidate poses on an x, y, yaw grid are screened by the
// NDT cost at the candidate (one pass over a subsample of the scan), the best few are refined by NDT,
// and the winner is kept only when no distinct pose scores nearly as well. No ROS.
#pragma once

#include <Eigen/Geometry>
#include <optional>
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
  int refine = 10;            ///< >= 1; best-screened candidates refined by NDT
  /// [0, 1]: the answer is refused when a refined pose farther than 2 * step from the best has NVTL >= this
  /// fraction of the best's (two places fit the scan about equally: a guess would be a coin toss).
  double ambiguity_ratio = 0.99;

  std::string validate() const;
};

/// The candidate guesses of a region, nearest the centre first: x y on a square grid of spacing
/// >= config.step inside the disc (coarsened so that positions x yaws <= max_candidates), yaw offsets
/// 0, +-yaw_step, +-2 yaw_step ... within yaw_range (a full circle when yaw_range >= pi).
std::vector<Eigen::Isometry3d> searchCandidates(const SearchRegion& region, const SearchConfig& config);

struct SearchResult {
  std::optional<NdtResult> best;  ///< the refined winner when acceptable and unambiguous
  double best_nvtl = 0.0;         ///< of the best acceptable refined pose (0 if none)
  double runner_up_nvtl = 0.0;    ///< of the best refined pose distinct from it (0 if none)
  int candidates = 0;             ///< screened
  int refined = 0;                ///< NDT alignments run
  bool ambiguous = false;         ///< an acceptable winner was refused for its runner-up
};

/// Runs the search of `region` for `source` (base frame) in `target`; `acceptable` says whether a
/// refined match may be used at all (the localizer's match gate).
template <class Acceptable>
SearchResult searchPose(const NdtAligner& aligner, const VoxelMap& target, const PointCloud& source,
                        const SearchRegion& region, const SearchConfig& config, const Acceptable& acceptable);

/// Implementation detail of searchPose: the screened candidates, best (lowest NDT cost) first, at most
/// config.refine of them.
std::vector<Eigen::Isometry3d> screenCandidates(const NdtAligner& aligner, const VoxelMap& target,
                                                const PointCloud& source, const std::vector<Eigen::Isometry3d>& all,
                                                const SearchConfig& config);

/// Picks the winner among refined results (acceptable ones only) and applies the ambiguity rule.
SearchResult pickUnambiguous(std::vector<NdtResult> refined, const std::vector<bool>& acceptable,
                             const SearchConfig& config);

template <class Acceptable>
SearchResult searchPose(const NdtAligner& aligner, const VoxelMap& target, const PointCloud& source,
                        const SearchRegion& region, const SearchConfig& config, const Acceptable& acceptable) {
  const std::vector<Eigen::Isometry3d> all = searchCandidates(region, config);
  const std::vector<Eigen::Isometry3d> best = screenCandidates(aligner, target, source, all, config);
  std::vector<NdtResult> refined;
  std::vector<bool> ok;
  for (const Eigen::Isometry3d& guess : best) {
    refined.push_back(aligner.align(target, source, guess.cast<float>()));
    ok.push_back(acceptable(refined.back()));
  }
  SearchResult out = pickUnambiguous(std::move(refined), ok, config);
  out.candidates = static_cast<int>(all.size());
  out.refined = static_cast<int>(best.size());
  return out;
}

}  // namespace grid_puzzle_localization
