#include <algorithm>
#include <sstream>
#include <string>

#include "grid_puzzle_localization/localizer.hpp"

namespace grid_puzzle_localization {

// The search's NDT refinement runs on the localizer's target: same voxel parameters and search method. Its map is
// the target's voxel means, one point per NDT voxel: a search grid finer than the voxels would leave most cells of
// a wall empty between the means, so the grid is at least as coarse as the voxels (and blurred in proportion).
GlobalLocalizationConfig globalSearchConfig(const LocalizerConfig& config) {
  GlobalLocalizationConfig g = config.global;
  const double epsilon = g.ndt.transformation_epsilon;
  g.ndt = config.ndt;
  g.ndt.transformation_epsilon = epsilon;
  g.blur_sigma = std::max(g.blur_sigma, 0.5 * config.ndt.resolution);
  return g;
}

std::string MatchConfig::validate() const {
  std::ostringstream err;
  if (!(min_nvtl >= 0.0)) err << "match/min_nvtl must be >= 0 (got " << min_nvtl << "); ";
  if (!(min_transformation_probability >= 0.0))
    err << "match/min_transformation_probability must be >= 0 (got " << min_transformation_probability << "); ";
  return err.str();
}

std::string ImuConfig::validate() const {
  return max_gap >= 0.0 ? "" : "imu/max_gap must be >= 0 s (got " + std::to_string(max_gap) + "); ";
}

std::string HypothesesConfig::validate() const {
  std::ostringstream err;
  if (!(yaw_step > 0.0)) err << "hypotheses/yaw_step must be > 0 rad (got " << yaw_step << "); ";
  if (!(yaw_count >= 0)) err << "hypotheses/yaw_count must be >= 0 (got " << yaw_count << "); ";
  if (!(refine >= 1)) err << "hypotheses/refine must be >= 1 (got " << refine << "); ";
  if (!(screen_points >= 10)) err << "hypotheses/screen_points must be >= 10 (got " << screen_points << "); ";
  if (!(poor_nvtl_ratio >= 0.0 && poor_nvtl_ratio <= 1.0))
    err << "hypotheses/poor_nvtl_ratio must be in [0, 1] (got " << poor_nvtl_ratio << "); ";
  return err.str();
}

std::string LostConfig::validate() const {
  std::ostringstream err;
  if (!(max_coast_time > 0.0)) err << "lost/max_coast_time must be > 0 s (got " << max_coast_time << "); ";
  if (!(search_period > 0.0)) err << "lost/search_period must be > 0 s (got " << search_period << "); ";
  if (!(initial_pose_search_size >= 0.0))
    err << "lost/initial_pose_search_size must be >= 0 m (got " << initial_pose_search_size << "); ";
  return err.str();
}

std::string LocalizerConfig::validate() const {
  std::ostringstream err;
  err << preprocess.validate() << ndt.validate() << covariance.validate() << match.validate() << imu.validate()
      << prediction.validate() << hypotheses.validate() << lost.validate();
  err << fusion.validate();
  const std::string global_problem = globalSearchConfig(*this).validate();
  if (!global_problem.empty()) err << "global_localization: " << global_problem << "; ";
  if (!(map_update_threads >= 0)) err << "map_update_threads must be >= 0 (0 = all cores); ";
  if (!(time_jump_back > 0.0)) err << "time_jump_back must be > 0 s (got " << time_jump_back << "); ";
  if (!(map_wait_half_side > 0.0)) err << "map_wait_half_side must be > 0 m (got " << map_wait_half_side << "); ";
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

}  // namespace grid_puzzle_localization
